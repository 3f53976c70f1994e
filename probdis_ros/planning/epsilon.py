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
The Epsilon baseline (epsilon-greedy): no map, no search.

With probability epsilon the path is the straight joint-space move to the goal; otherwise it
is a move of length ``step`` in a uniformly random joint-space direction, cut at the joint
limits.  The failure map is ignored.  An arm on a table (:mod:`probdis_ros.model.table`)
never moves through it: a move that would is drawn again (a goal move replaced by a random
one), up to ``TABLE_TRIES`` times, else the arm stays.
"""

from __future__ import annotations

import time

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.model.edge_costs import edge_above_table
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.planning.prob_rrt import Plan, planning_box, RRTSettings

#: X of the Epsilon baseline when none is given (the paper's Epsilon 0.2).
DEFAULT_EPSILON = 0.2
#: random moves drawn for a move the table allows before the arm stays where it is
TABLE_TRIES = 100


class EpsilonPlanner:
    """Straight to the goal with probability epsilon, else a random direction."""

    def __init__(self, arm: Arm, epsilon: float = DEFAULT_EPSILON, step: float = 1.0,
                 joint_margin: float = 0.0, joint_lower: tuple[float, ...] | None = None,
                 joint_upper: tuple[float, ...] | None = None) -> None:
        if not 0.0 <= epsilon <= 1.0:
            raise ValueError(f'epsilon must be in [0, 1], got {epsilon}')
        if step <= 0:
            raise ValueError(f'step must be > 0, got {step}')
        self.arm = arm
        self.epsilon = epsilon
        self.step = step
        # a random step stays in ProbRRT's box: this far inside the joint limits, within the
        # cell's room
        self.low, self.high = planning_box(arm, RRTSettings(
            joint_margin=joint_margin, joint_lower=joint_lower, joint_upper=joint_upper))

    def plan(self, start: np.ndarray, goal: np.ndarray, fmap: FailureMap,
             rng: np.random.Generator) -> Plan:
        """Return a one-edge path (the map is not used)."""
        t0 = time.perf_counter()
        start = np.asarray(start, dtype=float)
        end = np.asarray(goal, dtype=float) if rng.random() < self.epsilon else self._random(
            start, rng)
        for _ in range(TABLE_TRIES):
            if edge_above_table(self.arm, start, end):
                break
            end = self._random(start, rng)
        else:
            end = start
        path = np.array([start, end])
        return Plan(path, float(np.linalg.norm(end - start)), time.perf_counter() - t0)

    def _random(self, start: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        direction = rng.normal(size=len(start))
        end = start + self.step * direction / np.linalg.norm(direction)
        return np.clip(end, self.low, self.high)
