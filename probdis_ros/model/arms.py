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
Arms and batched forward kinematics, free of ROS.

Planning evaluates hundreds of thousands of configurations per plan, so every arm maps a
whole batch of joint configurations ``(N, n_joints)`` to task space at once.  Two arms:

* :class:`PlanarArm`, the paper's 2-D setting: a planar chain whose task space is the
  end-effector point in the plane.
* :class:`SerialChainArm`, a serial revolute chain read from a URDF through pinocchio (the
  iiwa 14 in ``urdf/iiwa14.urdf``).  Pinocchio parses the model, but one pinocchio call per
  configuration from Python is far slower than the planner needs, so a compiled loop over
  constant matrices (:func:`probdis_ros.model.kinematics.chain_kernel`) evaluates the batch.
  The tests check it against pinocchio and yourdfpy.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
import copy
from dataclasses import dataclass
from enum import Enum
import math
from pathlib import Path

import numpy as np
from probdis_ros.model.kinematics import (
    AXIS_CHAIN,
    CHAIN,
    chain_kernel,
    lowest_heights_kernel,
    PLANAR,
    positions_kernel,
    quaternion_kernel,
    sample_positions_kernel,
)
from probdis_ros.model.table import collision_shapes, SHAPE_COLUMNS, Table

#: [rad] how far inside its URDF limits a goal must lie, and every position the planner node
#: sends is held: KUKA's limits are whole degrees, which the URDF's six decimals round outward
#: by up to 2.7e-7 rad (A1, A3, A5), and the driver's command guard ends the FRI session on a
#: command past its limits.
DRIVER_LIMIT_INSET = 1e-6


class TaskSpace(str, Enum):
    """What part of the end-effector pose the failure map sees."""

    POINT2 = 'point2'
    POINT3 = 'point3'
    POSE3 = 'pose3'

    @property
    def dim(self) -> int:
        """Return the number of position coordinates."""
        return 2 if self is TaskSpace.POINT2 else 3

    @property
    def has_orientation(self) -> bool:
        """Tell whether a unit quaternion accompanies the position."""
        return self is TaskSpace.POSE3


@dataclass(frozen=True)
class TaskPoints:
    """
    End-effector poses of a batch: positions ``(N, d)``, quaternions ``(N, 4)`` or None.

    Quaternions are ``(w, x, y, z)`` with ``w >= 0``.
    """

    positions: np.ndarray
    orientations: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.positions)


class Arm(ABC):
    """A robot arm: joint names, limits and batched forward kinematics."""

    name: str
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity_limits: np.ndarray
    task_space: TaskSpace
    #: the table the arm stands on (:mod:`probdis_ros.model.table`); None: none is known
    table: Table | None = None

    @property
    def n_joints(self) -> int:
        """Return the number of joints (the dimension of configuration space)."""
        return len(self.joint_names)

    @abstractmethod
    def fk(self, configs: np.ndarray) -> TaskPoints:
        """Map configurations ``(N, n_joints)`` (or one ``(n_joints,)``) to task space."""

    def positions(self, configs: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """
        Return only the end-effector positions ``(N, d)`` (planning needs no more).

        With a boolean mask ``rows``, only those rows are computed; the others are zero.
        """
        if rows is None:
            return self.fk(configs).positions
        batch = self.as_batch(configs)
        out = np.zeros((len(batch), self.task_space.dim))
        if rows.any():
            out[rows] = self.fk(batch[rows]).positions
        return out

    def sample_positions(self, configs: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """
        Return :meth:`positions` of the rows in ``rows``, where the last bits do not matter.

        The planner's random samples (only the one farthest from a tree is kept); an arm
        may compute them faster, to within rounding.
        """
        return self.positions(configs, rows)

    def as_batch(self, configs: np.ndarray) -> np.ndarray:
        """Return configs as a float ``(N, n_joints)`` array, or raise ValueError."""
        batch = np.atleast_2d(np.asarray(configs, dtype=float))
        if batch.ndim != 2 or batch.shape[1] != self.n_joints:
            raise ValueError(
                f'{self.name}: expected configurations with {self.n_joints} joints, '
                f'got an array of shape {np.shape(configs)}')
        return batch

    def within_limits(self, configs: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Return a boolean mask of the configurations inside the position limits."""
        batch = self.as_batch(configs)
        return np.all((batch >= self.lower - tol) & (batch <= self.upper + tol), axis=1)

    def joint_outside(self, config: np.ndarray, tol: float = 1e-9) -> int | None:
        """Return the first joint of config not finite or outside its limits (None: none)."""
        config = self.as_batch(config)[0]
        for j, value in enumerate(config):
            if not (self.lower[j] - tol <= value <= self.upper[j] + tol):
                return j
        return None

    def limit_problem(self, config: np.ndarray, room: float = 0.0) -> str:
        """
        Return which joint of config is not finite or outside its limits, or '' if none.

        With ``room`` > 0, also a joint nearer than that to one of its limits.
        """
        j = self.joint_outside(config)
        config = self.as_batch(config)[0]
        if j is not None:
            return (f'{self.joint_names[j]} at {config[j]:.4g} rad is outside '
                    f'its limits [{self.lower[j]:.4f}, {self.upper[j]:.4f}]')
        if room <= 0:
            return ''
        below, above = config - self.lower, self.upper - config
        near = np.minimum(below, above)
        j = int(np.argmin(near))
        if near[j] >= room - 1e-12:         # (a configuration clipped to the room is in it)
            return ''
        limit = self.lower[j] if below[j] <= above[j] else self.upper[j]
        return (f'{self.joint_names[j]} at {config[j]:.5f} rad lies {near[j]:.5f} rad from its '
                f'limit {limit:.5f}, nearer than {room:g}')

    def random_configurations(self, rng: np.random.Generator, n: int,
                              margin: float = 0.0) -> np.ndarray:
        """
        Draw n configurations uniformly within the position limits (shrunk by margin).

        The same numbers as ``rng.uniform(lower, upper, (n, n_joints))`` (``low + (high -
        low) u``, one draw per value), in a third of the time.
        """
        return self.random_within(rng, n, self.lower + margin, self.upper - margin)

    def random_within(self, rng: np.random.Generator, n: int, low: np.ndarray,
                      high: np.ndarray) -> np.ndarray:
        """Draw n configurations uniformly within [low, high] (``low + (high - low) u``)."""
        out = rng.random((n, self.n_joints))
        out *= high - low
        out += low
        return out

    @abstractmethod
    def kernel_params(self) -> tuple:
        """Return the arm as the plain arrays the compiled edge kernels take."""

    def table_params(self) -> tuple[np.ndarray, float]:
        """Return (collision shapes, floor) as the edge kernels take them; -inf: no table."""
        return np.zeros((0, SHAPE_COLUMNS)), -np.inf

    def above_table(self, configs: np.ndarray) -> np.ndarray:
        """Return a boolean mask of the configurations the table allows (all without one)."""
        return np.ones(len(self.as_batch(configs)), dtype=bool)

    def table_problem(self, config: np.ndarray) -> str:
        """Return why the table does not allow config (a goal, a start), or '' if it does."""
        if self.above_table(config)[0]:
            return ''
        return (f'takes the arm below the table (lowest point '
                f'{self.lowest_heights(config)[0]:.3f} m, floor {self.table.floor:.3f} m)')


class PlanarArm(Arm):
    """
    Planar chain of revolute joints; the task space is the 2-D tip point.

    Joint i turns link i relative to link i-1, so the tip is
    ``sum_i l_i (cos, sin)(q_1 + ... + q_i)``.
    """

    def __init__(self, link_lengths: tuple[float, ...] = (0.1,) * 7,
                 limit: float = np.pi * 5 / 6, velocity_limit: float = 1.0) -> None:
        n = len(link_lengths)
        self.name = 'planar'
        self.link_lengths = np.asarray(link_lengths, dtype=float)
        self.joint_names = tuple(f'joint_{i + 1}' for i in range(n))
        self.lower = np.full(n, -limit)
        self.lower[0] = -np.pi
        self.upper = -self.lower
        self.velocity_limits = np.full(n, velocity_limit)
        self.task_space = TaskSpace.POINT2

    def fk(self, configs: np.ndarray) -> TaskPoints:
        """Return the tip points ``(N, 2)`` of the planar chain."""
        angles = np.cumsum(self.as_batch(configs), axis=1)
        # an explicit row sum, not BLAS, so that a batch and a single row agree to the bit
        tip = np.stack([(np.cos(angles) * self.link_lengths).sum(axis=1),
                        (np.sin(angles) * self.link_lengths).sum(axis=1)], axis=1)
        return TaskPoints(tip)

    def kernel_params(self) -> tuple:
        """Return ``(PLANAR, link_lengths, <unused chain arrays>)`` for the edge kernels."""
        return (PLANAR, self.link_lengths, np.zeros((0, 3)), np.zeros((0, 3, 3, 3)),
                np.zeros(3), np.eye(3))

    def link_points(self, config: np.ndarray) -> np.ndarray:
        """Return base, joint and tip points ``(n + 1, 2)`` of one configuration, for drawing."""
        angles = np.cumsum(self.as_batch(config)[0])
        steps = self.link_lengths[:, None] * np.stack([np.cos(angles), np.sin(angles)], axis=1)
        return np.vstack([np.zeros(2), np.cumsum(steps, axis=0)])


@dataclass(frozen=True)
class _Joint:
    """
    One revolute joint: parent-frame offset, and rotation as constant matrices.

    The child frame's rotation relative to the parent is ``A0 + cos(q) A1 + sin(q) A2``
    (origin rotation times Rodrigues' formula), stacked as ``basis = [A0 | A1 | A2]``.
    """

    offset: np.ndarray
    basis: np.ndarray


def _revolute(origin_rotation: np.ndarray, origin_offset: np.ndarray, axis: np.ndarray) -> _Joint:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    outer = np.outer(axis, axis)
    cross = np.array([[0.0, -axis[2], axis[1]],
                      [axis[2], 0.0, -axis[0]],
                      [-axis[1], axis[0], 0.0]])
    parts = [origin_rotation @ m for m in (outer, np.eye(3) - outer, cross)]
    return _Joint(np.asarray(origin_offset, dtype=float), np.hstack(parts))


def quaternion_to_rotation(quat: np.ndarray) -> np.ndarray:
    """Convert unit quaternions ``(N, 4)`` ``(w, x, y, z)`` to rotation matrices ``(N, 3, 3)``."""
    w, x, y, z = np.asarray(quat, dtype=float).reshape(-1, 4).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)


def rotation_to_quaternion(rot: np.ndarray) -> np.ndarray:
    """Convert rotations ``(N, 3, 3)`` to unit quaternions ``(w, x, y, z)``, ``w >= 0``."""
    rot = np.ascontiguousarray(rot, dtype=float).reshape(-1, 3, 3)
    quat = np.empty((len(rot), 4))
    quaternion_kernel(rot, quat)
    return quat


class SerialChainArm(Arm):
    """A serial chain of revolute joints, read from a URDF with pinocchio."""

    def __init__(self, name: str, joint_names: tuple[str, ...], joints: list[_Joint],
                 tip_offset: np.ndarray, tip_rotation: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, velocity_limits: np.ndarray,
                 with_orientation: bool, shapes: np.ndarray | None = None) -> None:
        self.name = name
        self.joint_names = joint_names
        self._offsets = np.array([j.offset for j in joints])
        self._bases = np.array([j.basis.reshape(3, 3, 3).transpose(1, 0, 2) for j in joints])
        self._tip_offset = tip_offset
        self._tip_rotation = tip_rotation
        self.lower, self.upper, self.velocity_limits = lower, upper, velocity_limits
        self.task_space = TaskSpace.POSE3 if with_orientation else TaskSpace.POINT3
        self._kernel_params: tuple | None = None
        #: collision shapes of the moving links (:func:`collision_shapes`), None if unknown
        self.shapes = shapes

    @classmethod
    def from_urdf(cls, urdf: str | Path, tip_frame: str,
                  with_orientation: bool = True) -> SerialChainArm:
        """Build the chain from a URDF whose movable joints are all revolute."""
        import pinocchio as pin

        model = pin.buildModelFromUrdf(str(urdf))
        joints = []
        zero = pin.neutral(model)
        for jmodel, placement in zip(model.joints[1:], model.jointPlacements[1:]):
            revolute = jmodel.shortname().startswith(('JointModelR', 'JointModelRevolute'))
            if jmodel.nq != 1 or not revolute:
                raise ValueError(f'{urdf}: only revolute joints are supported, '
                                 f'found {jmodel.shortname()}')
            jdata = jmodel.createData()
            jmodel.calc(jdata, zero)
            axis = np.asarray(jdata.S).reshape(6)[3:]
            joints.append(_revolute(placement.rotation, placement.translation, axis))
        if not model.existFrame(tip_frame):
            raise ValueError(f'{urdf}: no frame named {tip_frame!r}')
        frame = model.frames[model.getFrameId(tip_frame)]
        if frame.parentJoint != model.njoints - 1:
            raise ValueError(f'{urdf}: frame {tip_frame!r} is not attached to the last joint')
        return cls(model.name, tuple(model.names[1:]), joints,
                   np.array(frame.placement.translation), np.array(frame.placement.rotation),
                   np.array(model.lowerPositionLimit), np.array(model.upperPositionLimit),
                   np.array(model.velocityLimit), with_orientation,
                   collision_shapes(model, str(urdf)))

    def on_table(self, table: Table | None, object_radius: float = 0.0) -> SerialChainArm:
        """
        Return this arm standing on table (None: on none known), sharing the rest.

        ``object_radius`` [m]: the grasped object lies within a ball of this radius about
        the tip, which the table check then keeps above the floor too (a shape of its own).
        """
        if table is not None and self.shapes is None:
            raise ValueError(f'{self.name}: no collision shapes known, so no table check')
        if not (math.isfinite(object_radius) and object_radius >= 0):
            raise ValueError(f'object_radius must be >= 0, got {object_radius}')
        arm = copy.copy(self)
        arm.table = table
        if object_radius > 0:
            ball = [self.n_joints, *self._tip_offset, 0.0, 0.0, 0.0, 0.0, object_radius]
            arm.shapes = np.ascontiguousarray(np.vstack([self.shapes, ball]))
        return arm

    def table_params(self) -> tuple[np.ndarray, float]:
        """Return (collision shapes, floor) as the edge kernels take them; -inf: no table."""
        if self.table is None:
            return super().table_params()
        return self.shapes, float(self.table.floor)

    def lowest_heights(self, configs: np.ndarray) -> np.ndarray:
        """Return the lowest height [m] of the collision shapes and the tip, per config."""
        if self.shapes is None:
            raise ValueError(f'{self.name}: no collision shapes known')
        batch = np.ascontiguousarray(self.as_batch(configs))
        kind, codes, offsets, bases, tip_offset, _ = self.kernel_params()
        out = np.empty(len(batch))
        lowest_heights_kernel(batch, kind, codes, offsets, bases, tip_offset, self.shapes, out)
        return out

    def above_table(self, configs: np.ndarray) -> np.ndarray:
        """Return a boolean mask of the configurations the table allows (all without one)."""
        if self.table is None:
            return super().above_table(configs)
        return self.lowest_heights(configs) >= self.table.floor

    def joint_frames(self, configs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the joint frames' positions (N, J, 3) and rotations (N, J, 3, 3), numpy."""
        batch = self.as_batch(configs)
        n = len(batch)
        positions = np.empty((n, self.n_joints, 3))
        rotations = np.empty((n, self.n_joints, 3, 3))
        p = np.zeros((n, 3))
        r = np.broadcast_to(np.eye(3), (n, 3, 3))
        for j in range(self.n_joints):
            p = p + r @ self._offsets[j]
            c, s = np.cos(batch[:, j]), np.sin(batch[:, j])
            m = self._bases[j, 0] + c[:, None, None] * self._bases[j, 1] + \
                s[:, None, None] * self._bases[j, 2]
            r = r @ m
            positions[:, j], rotations[:, j] = p, r
        return positions, rotations

    def kernel_params(self) -> tuple:
        """
        Return ``(kind, joint params, offsets, bases, tip offset, tip rotation)``.

        AXIS_CHAIN (with signed axis codes) where every joint frame is parallel to the base
        at zero and turns about a coordinate axis, as in the iiwa URDF; CHAIN otherwise.
        """
        if self._kernel_params is None:
            codes = self._axis_codes()
            kind = CHAIN if codes is None else AXIS_CHAIN
            # C-contiguous, as every other arm's: one numba type, one compile per kernel
            arrays = (np.zeros(0) if codes is None else codes, self._offsets, self._bases,
                      self._tip_offset, self._tip_rotation)
            self._kernel_params = (kind, *(np.ascontiguousarray(a) for a in arrays))
        return self._kernel_params

    def _axis_codes(self) -> np.ndarray | None:
        codes = []
        for basis in self._bases:           # basis[0] = origin rotation @ axis axis^T
            outer = basis[0]
            axis = np.flatnonzero(np.abs(np.diag(outer) - 1.0) < 1e-12)
            if len(axis) != 1 or np.abs(outer).sum() > 1.0 + 1e-12:
                return None
            cross = basis[2]                 # origin rotation @ [axis]x
            sign = cross[(axis[0] + 2) % 3, (axis[0] + 1) % 3]
            identity = basis[0] + basis[1]   # origin rotation @ I
            if not np.allclose(identity, np.eye(3), atol=1e-12) or abs(abs(sign) - 1) > 1e-12:
                return None
            codes.append(np.sign(sign) * (axis[0] + 1))
        return np.array(codes, dtype=float)

    def tip_frames(self, configs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return tip positions ``(N, 3)`` and rotation matrices ``(N, 3, 3)``."""
        batch = self.as_batch(configs)
        positions = np.empty((len(batch), 3))
        rotations = np.empty((len(batch), 3, 3))
        chain_kernel(batch, *self.kernel_params(), positions, rotations)
        return positions, rotations

    def positions(self, configs: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """
        Return the tip positions ``(N, 3)`` (no quaternions): of the rows in ``rows`` if given.

        The positions of :meth:`tip_frames` with less work (:func:`positions_kernel`); rows
        left out are zero.
        """
        batch = np.ascontiguousarray(self.as_batch(configs))
        out = np.zeros((len(batch), 3))
        mask = np.ones(len(batch), dtype=np.bool_) if rows is None else \
            np.ascontiguousarray(rows, dtype=np.bool_)
        positions_kernel(batch, mask, *self.kernel_params(), out)
        return out

    def sample_positions(self, configs: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """
        Return :meth:`positions` of the rows in ``rows``, within a few 1e-16 m, fast.

        An AXIS_CHAIN (the iiwa) poses them with vectorised sines and cosines
        (:func:`sample_positions_kernel`, about ten times faster: a fifth of a plan's time
        on a 19-failure map went to the 18,000 samples' positions); others as positions.
        """
        kind, codes, offsets, _, tip_offset, _ = self.kernel_params()
        if kind != AXIS_CHAIN:
            return self.positions(configs, rows)
        batch = np.ascontiguousarray(self.as_batch(configs))
        out = np.zeros((len(batch), 3))
        sample_positions_kernel(batch, np.ascontiguousarray(rows, dtype=np.bool_), codes,
                                offsets, tip_offset, out)
        return out

    def fk(self, configs: np.ndarray) -> TaskPoints:
        """Return tip positions, with quaternions when the task space has orientation."""
        positions, rotations = self.tip_frames(configs)
        if self.task_space.has_orientation:
            return TaskPoints(positions, rotation_to_quaternion(rotations))
        return TaskPoints(positions)
