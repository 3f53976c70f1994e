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

"""One simulated disentangling episode: the loop, a planner and the compliant arm."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from probdis_ros.model.failure_map import DEFAULT_C_FAIL, FailureMap
from probdis_ros.planning import (
    DEFAULT_EPSILON,
    DEFAULT_THRESHOLD,
    Disentangler,
    make_planner,
    RRTSettings,
    State,
)
from probdis_ros.sim.worlds import World


@dataclass
class EpisodeResult:
    """Outcome of an episode, and the loop itself for plots."""

    success: bool
    paths: int
    failures: int
    plan_times_s: list[float]
    loop: Disentangler
    world: World
    traces: list[np.ndarray]

    def summary(self) -> dict:
        """Return the JSON summary printed by ``probdis sim --json``."""
        return {'success': self.success, 'paths': self.paths, 'failures': self.failures,
                'plan_times_s': self.plan_times_s}


def run_episode(world: World, method: str = 'probabilistic', seed: int = 0,
                max_paths: int = 20, threshold: float = DEFAULT_THRESHOLD,
                epsilon: float = DEFAULT_EPSILON, settings: RRTSettings | None = None,
                c_fail: float = DEFAULT_C_FAIL) -> EpisodeResult:
    """Disentangle world.start -> world.goal with a method; reproducible from seed."""
    arm = world.arm
    sim = world.compliant_arm()
    planner = make_planner(method, arm, settings, threshold, epsilon)
    loop = Disentangler(arm, planner, world.goal, FailureMap(arm.task_space, c_fail),
                        max_paths=max_paths, seed=seed)
    current = world.start.copy()
    traces = []
    while True:
        path = loop.next_path(current)
        if path is None:
            break
        run = sim.execute(path)
        traces.append(run.trace)
        current = run.config
        if not run.blocked:
            loop.report_completed(current)
            continue
        back = sim.execute(loop.report_blocked(current, run.segment))
        current = back.config
        loop.report_retreated(current)
    return EpisodeResult(loop.state is State.SUCCEEDED, loop.paths_tried, len(loop.fmap),
                         loop.plan_times, loop, world, traces)
