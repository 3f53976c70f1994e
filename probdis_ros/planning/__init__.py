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

"""Planning (no rclpy): ProbRRT, the Hard and Epsilon baselines, the disentangling loop."""

from __future__ import annotations

from dataclasses import replace

from probdis_ros.model.arms import Arm
from probdis_ros.planning.disentangle import Disentangler, State
from probdis_ros.planning.epsilon import EpsilonPlanner
from probdis_ros.planning.prob_rrt import Plan, ProbRRT, RRTSettings

METHODS = ('probabilistic', 'hard', 'epsilon')
DEFAULT_THRESHOLD = 0.01
DEFAULT_EPSILON = 0.2


def make_planner(method: str, arm: Arm, settings: RRTSettings | None = None,
                 threshold: float = DEFAULT_THRESHOLD, epsilon: float = DEFAULT_EPSILON):
    """Return the planner of a method: 'probabilistic', 'hard' (threshold) or 'epsilon'."""
    settings = settings or RRTSettings()
    if method == 'probabilistic':
        return ProbRRT(arm, replace(settings, hard_threshold=None))
    if method == 'hard':
        return ProbRRT(arm, replace(settings, hard_threshold=threshold))
    if method == 'epsilon':
        return EpsilonPlanner(arm, epsilon)
    raise ValueError(f'unknown method {method!r}; choose one of {", ".join(METHODS)}')


__all__ = [
    'DEFAULT_EPSILON',
    'DEFAULT_THRESHOLD',
    'METHODS',
    'Disentangler',
    'EpsilonPlanner',
    'Plan',
    'ProbRRT',
    'RRTSettings',
    'State',
    'make_planner',
]
