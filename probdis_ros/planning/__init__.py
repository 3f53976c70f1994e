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

"""Planning (no rclpy): objectives, the tree, ProbRRT, the baselines, methods, the loop."""

from __future__ import annotations

from probdis_ros.planning.disentangle import Disentangler, State
from probdis_ros.planning.epsilon import DEFAULT_EPSILON, EpsilonPlanner
from probdis_ros.planning.methods import make_planner, Method, METHODS
from probdis_ros.planning.objectives import (
    DEFAULT_THRESHOLD,
    FailureProbabilityObjective,
    HARD_C_FAIL,
    HardThresholdObjective,
    Objective,
)
from probdis_ros.planning.prob_rrt import Plan, ProbRRT, RRTSettings

__all__ = [
    'DEFAULT_EPSILON',
    'DEFAULT_THRESHOLD',
    'HARD_C_FAIL',
    'METHODS',
    'Disentangler',
    'EpsilonPlanner',
    'FailureProbabilityObjective',
    'HardThresholdObjective',
    'Method',
    'Objective',
    'Plan',
    'ProbRRT',
    'RRTSettings',
    'State',
    'make_planner',
]
