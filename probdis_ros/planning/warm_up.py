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
Compile every kernel a disentangling run calls before the run needs it.

numba compiles (or loads from its cache) a kernel at its first call, holding the GIL for up
to seconds.  In the planner node that first call would come when the arm is first blocked,
while the executor must watch the retreat: the joint states of those seconds are lost (on
simulated time the mock runs on meanwhile; on the real arm the state timeout fires).  So the
node drives one throwaway loop through everything a run does (plan, block, retreat, plan,
learn, plan again) at start-up.
"""

from __future__ import annotations

import time

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.planning.disentangle import Disentangler, Planner


def warm_up(arm: Arm, planner: Planner, c_fail: float) -> float:
    """Run one throwaway plan-block-retreat-learn-replan loop; return its seconds."""
    began = time.perf_counter()
    middle = (arm.lower + arm.upper) / 2
    goal = middle + 0.25 * (arm.upper - middle)
    loop = Disentangler(arm, planner, goal, FailureMap(arm.task_space, c_fail), max_paths=3)
    path = loop.next_path(middle)
    if path is not None and len(path) > 1:
        blocked_at = path[0] + 0.5 * (path[1] - path[0])
        back = loop.report_blocked(blocked_at, 0)
        loop.report_retreated(back[-1])
        # a map of one failure and one of several: both share one compiled kernel (the
        # failure arrays' layout does not change with the map's size), planned on as a run does
        if loop.next_path(back[-1]) is not None:
            loop.withdraw()
        loop.learn(blocked_at, path[1] - path[0])
        loop.next_path(back[-1])
    arm.fk(middle)                   # one configuration, as well as the batches above
    arm.fk(np.array([middle, goal]))
    return time.perf_counter() - began
