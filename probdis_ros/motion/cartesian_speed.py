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
How fast the points of the arm move, and a limit on it for every commanded motion.

KUKA's operating mode T1 (manual reduced velocity) is meant to keep the robot under 250 mm/s,
and a safety configuration may monitor Cartesian speeds of points on the robot and its tool
and stop the arm when one passes its limit, whatever commands it (README, "Pointing it at the
real arm").  Joint velocity limits do not keep such a limit: at the default velocity scaling
0.2 the fastest point of the arm and the object on the demo's physics scene moved at 0.59 m/s.
So a run may limit the speed of every point of the arm as the planner models it: the URDF's
collision shapes (spheres, cylinders and capsules on the links), the ball of
``object_radius`` about the tip that holds the grasped object, and the tip.  A point of a
shape moves at most as fast as the ends of the shape's axis segment plus its radius times
the link's angular speed, which is the bound taken.

Each straight joint-space edge of a path is timed with one scalar profile of its edge
parameter (:func:`probdis_ros.motion.profiles.time_parameterize`); along it every point's
speed is the edge's speed times a ratio that depends on where on the edge the arm is.  The
largest ratio, sampled every ``EDGE_SPACING`` and widened by ``SAMPLING_MARGIN`` for the
stretches between samples, caps the edge's speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from probdis_ros.model.arms import SerialChainArm

#: [rad] the largest joint's step between the configurations sampled along an edge
EDGE_SPACING = 0.05
#: the largest ratio of the samples is widened by this much for the stretches between them
#: (a review found at most 1.6e-4 missed at this spacing on 200 random edges of the iiwa,
#: and the test samples ten times as dense)
SAMPLING_MARGIN = 0.02
#: [rad] the finite-difference step of the joint motion that gives the points' velocities
DIFFERENCE_STEP = 1e-6
#: configurations evaluated at once (a long episode's trace in blocks: bounded memory)
BLOCK = 2048


def _points(arm: SerialChainArm) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return the monitored points: link index (0-based), local position, radius about it.

    Every collision shape's axis ends (a sphere's centre twice) with the shape's radius,
    and the tip with radius 0.
    """
    shapes = np.zeros((0, 9)) if arm.shapes is None else arm.shapes
    links, local, radii = [], [], []
    for joint, cx, cy, cz, ax, ay, az, half, radius in shapes:
        for sign in (1.0, -1.0):
            links.append(int(joint) - 1)
            local.append(np.array([cx, cy, cz]) + sign * half * np.array([ax, ay, az]))
            radii.append(radius)
    links.append(arm.n_joints - 1)
    local.append(arm.kernel_params()[4])            # the tip offset in the last link
    radii.append(0.0)
    return np.array(links), np.array(local), np.array(radii)


def point_speeds(arm: SerialChainArm, configs: np.ndarray, velocities: np.ndarray
                 ) -> np.ndarray:
    """
    Return, per configuration, the highest speed [m/s] of any monitored point of the arm.

    ``configs`` and ``velocities`` are ``(N, n_joints)``: the arm at each configuration
    moving with each joint velocity [rad/s].
    """
    q = arm.as_batch(configs)
    qdot = np.asarray(velocities, dtype=float).reshape(q.shape)
    points = _points(arm)
    return np.concatenate([_point_speeds(arm, q[k:k + BLOCK], qdot[k:k + BLOCK], points)
                           for k in range(0, len(q), BLOCK)] or [np.zeros(0)])


def _point_speeds(arm: SerialChainArm, q: np.ndarray, qdot: np.ndarray,
                  points: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    size = np.linalg.norm(qdot, axis=1)
    moving = size > 0
    out = np.zeros(len(q))
    if not moving.any():
        return out
    direction = qdot[moving] / size[moving, None]
    p0, r0 = arm.joint_frames(q[moving])
    p1, r1 = arm.joint_frames(q[moving] + DIFFERENCE_STEP * direction)
    links, local, radii = points
    x0 = p0[:, links] + np.einsum('nkab,kb->nka', r0[:, links], local)
    x1 = p1[:, links] + np.einsum('nkab,kb->nka', r1[:, links], local)
    linear = np.linalg.norm(x1 - x0, axis=2) / DIFFERENCE_STEP           # (N, points)
    turn = np.einsum('nkab,nkcb->nkac', r1, r0)                          # R1 R0^T per link
    spin = 0.5 * np.stack([turn[..., 2, 1] - turn[..., 1, 2], turn[..., 0, 2] - turn[..., 2, 0],
                           turn[..., 1, 0] - turn[..., 0, 1]], axis=-1)
    angular = np.linalg.norm(spin, axis=2) / DIFFERENCE_STEP             # (N, links)
    out[moving] = (linear + radii * angular[:, links]).max(axis=1) * size[moving]
    return out


def edge_ratios(arm: SerialChainArm, path: np.ndarray, spacing: float = EDGE_SPACING
                ) -> np.ndarray:
    """
    Return per edge of ``path`` (M, n) the largest point speed per unit of its parameter's.

    The edge parameter is the largest joint's angle (as the edge's profile times it), so
    an edge run at parameter speed ``v`` moves no monitored point faster than ``v`` times
    the ratio.  Zero-length edges give 0.
    """
    path = np.asarray(path, dtype=float)
    deltas = np.diff(path, axis=0)
    lengths = np.abs(deltas).max(axis=1)
    ratios = np.zeros(len(deltas))
    configs, rates, owner = [], [], []
    for k, (length, delta) in enumerate(zip(lengths, deltas)):
        if length == 0:
            continue
        count = int(np.ceil(length / spacing)) + 1
        fractions = np.linspace(0.0, 1.0, count)[:, None]
        configs.append(path[k] + fractions * delta)
        rates.append(np.broadcast_to(delta / length, (count, len(delta))))
        owner.append(np.full(count, k))
    if configs:
        speeds = point_speeds(arm, np.vstack(configs), np.vstack(rates))
        np.maximum.at(ratios, np.concatenate(owner), speeds)
    return ratios * (1.0 + SAMPLING_MARGIN)


@dataclass(frozen=True, eq=False)
class CartesianSpeedLimit:
    """The fastest [m/s] any monitored point of ``arm`` may move in a commanded motion."""

    arm: SerialChainArm
    speed: float

    def __post_init__(self) -> None:
        """Refuse a limit no motion could keep, and an arm whose points are not known."""
        if not (np.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f'the Cartesian speed limit must be positive, got {self.speed}')
        if not isinstance(self.arm, SerialChainArm):
            raise ValueError('a Cartesian speed limit needs a serial chain arm (its links)')

    def edge_speeds(self, path: np.ndarray) -> np.ndarray:
        """Return per edge the fastest its parameter may move [1/s] (inf: no motion)."""
        ratios = edge_ratios(self.arm, path)
        with np.errstate(divide='ignore'):
            return np.where(ratios > 0, self.speed / ratios, np.inf)
