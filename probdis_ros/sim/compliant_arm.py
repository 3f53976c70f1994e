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
A compliant simulated arm: it follows a joint path and stops where it first touches.

Each edge of the path is cut into joint-space steps of at most ``check_step``; the
end-effector polyline through them is tested against the hidden obstacles piece by piece
(:func:`probdis_ros.sim.obstacles.first_contact`).  On contact the arm stops just before the
contact point, on the straight joint-space segment it was following, and stays there: that is
what a joint-impedance-controlled arm does when a grasped object catches.  An arm on a table
(:mod:`probdis_ros.model.table`) is stopped the same way where a part of it would go below
the table top (never lower than where the path began: an arm started there may rise).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.sim.obstacles import first_contact, Obstacle

#: Finest joint-space step between contact tests [rad].
DEFAULT_CHECK_STEP = 0.01
#: How far before the contact the arm stops, as a fraction of one check step.
BACK_OFF = 0.05


@dataclass
class Execution:
    """What happened when a path was executed."""

    config: np.ndarray         # where the arm ended
    blocked: bool
    segment: int               # index of the path edge being executed when blocked (else -1)
    trace: np.ndarray          # joint configurations visited (check-step resolution)


def densify(path: np.ndarray, check_step: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the path cut into steps of at most check_step, and each step's edge index."""
    points = [path[:1]]
    edges = []
    for i, (a, b) in enumerate(pairwise(path)):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / check_step)))
        points.append(a + (np.arange(1, n + 1)[:, None] / n) * (b - a))
        edges += [i] * n
    return np.vstack(points), np.asarray(edges, dtype=int)


class CompliantArm:
    """Executes joint paths in a world of hidden obstacles."""

    def __init__(self, arm: Arm, obstacles: list[Obstacle], orientation_tolerance: float = 0.5,
                 check_step: float = DEFAULT_CHECK_STEP) -> None:
        self.arm = arm
        self.obstacles = obstacles
        self.orientation_tolerance = orientation_tolerance
        self.check_step = check_step

    def collides(self, config: np.ndarray) -> bool:
        """Tell whether the end-effector at config is in an obstacle, or the arm in its table."""
        x = self.arm.fk(config).positions
        table = self.arm.table
        return any(bool(o.contains(x)[0]) for o in self.obstacles) or (
            table is not None and self.arm.lowest_heights(config)[0] < table.height)

    def execute(self, path: np.ndarray) -> Execution:
        """Follow path (via points ``(M, n)``, starting where the arm is) until contact."""
        path = self.arm.as_batch(path)
        dense, edges = densify(path, self.check_step)
        pose = self.arm.fk(dense)
        hit = first_contact(self.obstacles, pose.positions, pose.orientations,
                            self.orientation_tolerance)
        table = self._table_contact(dense)
        if table is not None and (hit is None or table < hit):
            hit = table
        if hit is None:
            return Execution(path[-1].copy(), False, -1, dense)
        seg, frac = hit
        stop = dense[seg] + max(0.0, frac - BACK_OFF) * (dense[seg + 1] - dense[seg])
        return Execution(stop, True, int(edges[seg]), np.vstack([dense[:seg + 1], stop]))

    def _table_contact(self, dense: np.ndarray) -> tuple[int, float] | None:
        """Return (step, fraction) where the arm first meets its table on dense, or None."""
        if self.arm.table is None or len(dense) < 2:
            return None
        heights = self.arm.lowest_heights(dense)
        floor = min(self.arm.table.height, heights[0])
        below = np.flatnonzero(heights[1:] < floor)
        if not len(below):
            return None
        i = int(below[0])            # between dense[i] (above) and dense[i + 1] (below)
        return i, float((heights[i] - floor) / (heights[i] - heights[i + 1]))

    def path_is_free(self, path: np.ndarray) -> bool:
        """Tell whether the whole path can be executed without contact."""
        return not self.execute(path).blocked
