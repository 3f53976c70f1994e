# Copyright 2026 probdis_ros contributors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.


"""
The arm's rigid-body dynamics, for an external-torque estimate from the joint states' efforts.

Where ``/lbr/joint_states`` carries the measured joint torques, the torque the scene exerts on
the arm is the measured torque less what holds the arm and its load against gravity and
what accelerates them (:class:`probdis_ros.motion.detector.ExternalTorqueObserver`).  KUKA's
controller makes the same estimate and needs the same load data.  Pinocchio computes
``g(q)``, ``M(q)`` and ``C(q, v)`` from the URDF's inertials; the grasped object is a point
mass at ``load_com`` in the flange frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from probdis_ros.resources import data_file

#: The flange frame of the iiwa's URDF (where the object is held).
FLANGE_FRAME = 'lbr_link_ee'


class GravityModel:
    """``g(q)``: the joint torques [Nm] that hold the arm and its load still."""

    def __init__(self, urdf: str | Path | None = None, load_mass: float = 0.0,
                 load_com: Sequence[float] = (0.0, 0.0, 0.0), flange: str = FLANGE_FRAME
                 ) -> None:
        import pinocchio as pin

        if load_mass < 0:
            raise ValueError(f'load_mass must be >= 0, got {load_mass}')
        self._pin = pin
        self.model = pin.buildModelFromUrdf(str(urdf or data_file('urdf', 'iiwa14.urdf')))
        if load_mass > 0:
            frame = self.model.frames[self.model.getFrameId(flange)]
            at = frame.placement * pin.SE3(np.eye(3), np.asarray(load_com, dtype=float))
            self.model.appendBodyToJoint(frame.parentJoint, pin.Inertia(
                load_mass, at.translation, np.zeros((3, 3))), pin.SE3.Identity())
        self.data = self.model.createData()

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """Return g(q) [Nm] at a configuration (radians, the URDF's joint order)."""
        return np.array(self._pin.computeGeneralizedGravity(
            self.model, self.data, np.asarray(q, dtype=float)))

    def momentum(self, q: np.ndarray, v: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Return the generalised momentum M(q) v, C(q, v)^T v and g(q) [Nm].

        What a momentum observer needs: p' = tau + tau_ext + C(q, v)^T v - g(q).
        """
        pin = self._pin
        q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
        inertia = np.array(pin.crba(self.model, self.data, q))
        inertia = np.triu(inertia) + np.triu(inertia, 1).T      # crba may fill one half
        coriolis = np.array(pin.computeCoriolisMatrix(self.model, self.data, q, v))
        return inertia @ v, coriolis.T @ v, self(q)
