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
The iiwa in KUKA's joint impedance control, simulated with MuJoCo.

:class:`PhysicsIiwa` holds an impedance setpoint for a stretch of simulated time: the law
``tau = K (q_set - q) - D qdot + g(q)`` runs inside MuJoCo (see
:mod:`probdis_ros.physics.model`), so :meth:`PhysicsIiwa.advance` is one call of
``mj_step(model, data, n)`` per damping update (10 ms), not a Python loop per step.  What the
real arm's setpoint goes through before (JTC, the driver's filter) is the caller's business.

Gated obstacles (:class:`~probdis_ros.physics.scene.Gate`) are opened and closed every 10 ms
for the flange orientation then: solid while the object is held within the gate's tolerance,
open to an object turned further.  A gate that would close while the object is inside the
obstacle (it entered turned, then turned back) stays open until the object is out of it, so
the simulation never finds the object buried in a wall it could not have entered.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from probdis_ros.physics.model import (
    build_model,
    FLANGE,
    OBJECT_BODY,
    obstacle_name,
    ROBOT_CONTYPE,
)
from probdis_ros.physics.scene import Scene
from probdis_ros.physics.settings import PhysicsSettings

__all__ = ['Contact', 'PhysicsIiwa', 'PhysicsSettings']


@dataclass(frozen=True)
class Contact:
    """One contact between the robot (or the grasped object) and the scene."""

    #: Contact point in the base frame ``lbr_link_0`` (= the world) [m].
    position: np.ndarray
    #: Unit normal, pointing from the scene into the robot.
    normal: np.ndarray
    #: Normal force [N] (>= 0).
    force: float
    #: Penetration depth [m] (>= 0).
    depth: float
    robot_geom: str
    robot_body: str
    scene_geom: str
    scene_body: str


class PhysicsIiwa:
    """
    The LBR iiwa 14 holding an object among a scene's obstacles, in joint impedance.

    Joint order is ``lbr_A1``..``lbr_A7``.  ``time`` is simulated seconds since the last
    :meth:`reset`.
    """

    def __init__(self, scene: Scene | None = None,
                 settings: PhysicsSettings | None = None) -> None:
        self.scene = scene
        self.settings = settings or PhysicsSettings()
        self.model = build_model(scene, self.settings)
        self.data = mujoco.MjData(self.model)
        self._probe = mujoco.MjData(self.model)   # kinematic checks, never stepped
        m = self.model
        self.joint_names = tuple(f'lbr_A{i}' for i in range(1, 8))
        joints = [m.joint(name).id for name in self.joint_names]
        self._qadr = np.array([m.jnt_qposadr[j] for j in joints])
        self._vadr = np.array([m.jnt_dofadr[j] for j in joints])
        self._mdiag = (m.M_rowadr + m.M_rownnz - 1)[self._vadr]
        self._stiffness = np.asarray(self.settings.stiffness, dtype=float)
        robot = (m.geom_contype & ROBOT_CONTYPE) != 0
        self._robot_geom = robot
        self._scene_geom = (m.geom_conaffinity > 0) & ~robot
        self._init_gates()
        self.lower = m.jnt_range[joints, 0].copy()
        self.upper = m.jnt_range[joints, 1].copy()
        self.effort = m.jnt_actfrcrange[joints, 1].copy()
        self._flange = m.site(FLANGE).id
        self._chunk = max(1, round(self.settings.damping_update / m.opt.timestep))
        self._steps_done = 0
        self._time_target = 0.0
        self.reset(np.zeros(7) if scene is None else scene.start)

    # -- state ---------------------------------------------------------------------------------

    @property
    def time(self) -> float:
        """Return the simulated time [s] since the last reset."""
        return self._steps_done * self.model.opt.timestep

    @property
    def q(self) -> np.ndarray:
        """Return the measured joint positions [rad]."""
        return self.data.qpos[self._qadr].copy()

    @property
    def qdot(self) -> np.ndarray:
        """Return the measured joint velocities [rad/s]."""
        return self.data.qvel[self._vadr].copy()

    @property
    def setpoint(self) -> np.ndarray:
        """Return the impedance setpoint being held [rad]."""
        return self.data.ctrl.copy()

    @property
    def tau_measured(self) -> np.ndarray:
        """Return the joint torques [Nm] the drives apply (impedance + gravity, clipped)."""
        return self.data.qfrc_actuator[self._vadr].copy()

    @property
    def tau_external(self) -> np.ndarray:
        """
        Return the joint torques [Nm] that contacts with the scene exert on the arm.

        Computed from the contact forces (``J^T f`` at each contact point), so joint limits
        and the controller do not leak into it; a perfect external-torque estimator.
        """
        m, d = self.model, self.data
        tau = np.zeros(m.nv)
        jacp = np.zeros((3, m.nv))
        force = np.zeros(6)
        for i in self._robot_contacts():
            con = d.contact[i]
            mujoco.mj_contactForce(m, d, i, force)
            frame = con.frame.reshape(3, 3)
            on_geom2 = frame.T @ force[:3]
            robot_is_2 = self._robot_geom[con.geom[1]]
            on_robot = on_geom2 if robot_is_2 else -on_geom2
            body = m.geom_bodyid[con.geom[1] if robot_is_2 else con.geom[0]]
            mujoco.mj_jac(m, d, jacp, None, con.pos, body)
            tau += jacp.T @ on_robot
        return tau[self._vadr]

    def reset(self, q: np.ndarray) -> None:
        """Place the arm at rest at q (setpoint q, clutter at rest, time 0)."""
        q = np.asarray(q, dtype=float).reshape(7)
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[self._qadr] = q
        self.data.ctrl[:] = q
        self._steps_done = 0
        self._time_target = 0.0
        self._update_damping()
        self._update_gates(follow=False)
        mujoco.mj_forward(self.model, self.data)

    def advance(self, setpoint: np.ndarray, duration: float) -> None:
        """
        Hold the impedance setpoint for ``duration`` seconds of simulated time.

        Durations that are not whole steps accumulate, so that calling this every 10 ms
        keeps the simulated clock on the caller's.
        """
        setpoint = np.asarray(setpoint, dtype=float).reshape(7)
        if not np.all(np.isfinite(setpoint)):
            raise ValueError(f'setpoint must be 7 finite numbers, got {setpoint}')
        self.data.ctrl[:] = setpoint
        self._time_target += float(duration)
        steps = round(self._time_target / self.model.opt.timestep) - self._steps_done
        while steps > 0:
            n = min(steps, self._chunk)
            self._update_damping()
            self._update_gates()
            mujoco.mj_step(self.model, self.data, n)
            self._steps_done += n
            steps -= n
        mujoco.mj_forward(self.model, self.data)   # positions, contacts, torques of now

    def _update_damping(self) -> None:
        """D_j = 2 zeta sqrt(K_j M_jj(q)) (KUKA's joint impedance), from the current q."""
        m, d = self.model, self.data
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_crb(m, d)
        inertia = d.M[self._mdiag]
        damping = 2.0 * self.settings.damping_ratio * np.sqrt(self._stiffness * inertia)
        m.actuator_biasprm[:, 2] = -damping

    # -- gates -------------------------------------------------------------------------------

    def _init_gates(self) -> None:
        m, scene = self.model, self.scene
        gated = [] if scene is None else [
            (m.geom(obstacle_name(scene, i)).id, o.gate)
            for i, o in enumerate(scene.obstacles) if o.gate is not None]
        self._gate_geom = np.array([g for g, _ in gated], dtype=int)
        self._gate_quat = np.array([gate.orientation for _, gate in gated]).reshape(-1, 4)
        self._gate_tolerance = np.array([gate.tolerance for _, gate in gated])
        self._gate_affinity = m.geom_conaffinity[self._gate_geom].copy()
        body = m.body(OBJECT_BODY).id if scene is not None and scene.grasped else -1
        self._object_geoms = np.flatnonzero(m.geom_bodyid == body)

    def gates_solid(self, data: mujoco.MjData | None = None) -> np.ndarray:
        """Return, per gated obstacle, whether it blocks the object as the flange is held."""
        d = self.data if data is None else data
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, d.site_xmat[self._flange])
        dots = np.clip(np.abs(self._gate_quat @ quat), 0.0, 1.0)
        return (2.0 / np.pi) * np.arccos(dots) < self._gate_tolerance

    def _update_gates(self, follow: bool = True) -> None:
        """Open or close the gated obstacles for the orientation now (kinematics current)."""
        if not len(self._gate_geom):
            return
        m = self.model
        solid = self.gates_solid()
        if follow:
            closing = solid & (m.geom_conaffinity[self._gate_geom] == 0)
            for k in np.flatnonzero(closing):
                if self._object_inside(int(self._gate_geom[k])):
                    solid[k] = False     # closes once the object is out of it
        m.geom_conaffinity[self._gate_geom] = np.where(solid, self._gate_affinity, 0)

    def _object_inside(self, geom: int) -> bool:
        return any(mujoco.mj_geomDistance(self.model, self.data, geom, int(g), 1e-3, None) < 0
                   for g in self._object_geoms)

    # -- geometry ------------------------------------------------------------------------------

    def flange_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the flange (lbr_link_ee) position (3,) and rotation (3, 3) in the base frame."""
        return (self.data.site_xpos[self._flange].copy(),
                self.data.site_xmat[self._flange].reshape(3, 3).copy())

    def _robot_contacts(self, data: mujoco.MjData | None = None) -> list[int]:
        d = self.data if data is None else data
        if d.ncon == 0:
            return []
        geoms = d.contact.geom[:d.ncon]
        robot = self._robot_geom[geoms]
        scene = self._scene_geom[geoms]
        mask = (robot[:, 0] & scene[:, 1]) | (robot[:, 1] & scene[:, 0])
        return [int(i) for i in np.flatnonzero(mask)]

    def contacts(self) -> list[Contact]:
        """Return the contacts between the robot (or object) and the scene, now."""
        m, d = self.model, self.data
        out = []
        force = np.zeros(6)
        for i in self._robot_contacts():
            con = d.contact[i]
            mujoco.mj_contactForce(m, d, i, force)
            g1, g2 = int(con.geom[0]), int(con.geom[1])
            robot, other, sign = (g2, g1, 1.0) if self._robot_geom[g2] else (g1, g2, -1.0)
            out.append(Contact(con.pos.copy(), sign * con.frame[:3].copy(), float(force[0]),
                               max(0.0, -float(con.dist)), m.geom(robot).name,
                               m.body(m.geom_bodyid[robot]).name, m.geom(other).name,
                               m.body(m.geom_bodyid[other]).name))
        return out

    def in_collision(self, q: np.ndarray, clearance: float = 0.0) -> bool:
        """
        Tell whether the robot and object at q penetrate the scene (clutter at rest).

        A kinematic check on a separate MjData: the simulation is not disturbed.  With
        ``clearance`` > 0, coming closer than that counts too (a safety margin).
        """
        m, d = self.model, self._probe
        d.qpos[:] = m.qpos0
        d.qpos[self._qadr] = np.asarray(q, dtype=float).reshape(7)
        if clearance > 0:
            m.geom_margin[self._scene_geom] = clearance
        gates = m.geom_conaffinity[self._gate_geom].copy()
        try:
            mujoco.mj_kinematics(m, d)
            if len(self._gate_geom):     # the gates as the object is held at q
                m.geom_conaffinity[self._gate_geom] = np.where(
                    self.gates_solid(d), self._gate_affinity, 0)
            mujoco.mj_collision(m, d)
        finally:
            if clearance > 0:
                m.geom_margin[self._scene_geom] = 0.0
            m.geom_conaffinity[self._gate_geom] = gates
        idx = self._robot_contacts(d)
        return bool(idx) and bool(np.any(d.contact.dist[idx] < clearance))
