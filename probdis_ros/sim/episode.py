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

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from probdis_ros.planning import Disentangler, Method, RRTSettings, State
from probdis_ros.sim.compliant_arm import CompliantArm
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
    empty_plans: int = 0

    def summary(self) -> dict:
        """
        Return the JSON summary printed by ``probdis sim --json``.

        With an arm of known shape (the iiwa), ``lowest_m``: the lowest height [m] any part
        of it reached along the executed paths (their ways back retrace them), against
        the base's plane, whether or not the world has a table.
        """
        out = {'success': self.success, 'paths': self.paths, 'failures': self.failures,
               'empty_plans': self.empty_plans, 'plan_times_s': self.plan_times_s}
        if getattr(self.world.arm, 'shapes', None) is not None and self.traces:
            out['lowest_m'] = round(float(min(self.world.arm.lowest_heights(t).min()
                                              for t in self.traces)), 4)
        return out


def drive(loop: Disentangler, sim: CompliantArm, current: np.ndarray,
          until: Callable[[Disentangler], bool] | None = None
          ) -> tuple[np.ndarray, list[np.ndarray]]:
    """
    Run the loop against the simulated arm until it finishes, or until ``until(loop)``.

    Plan, execute; a blocked path is reported and its retreat executed.  Returns where the
    arm ended and the joint trace of every executed path.  (The one loop of the simulator:
    episodes and the benchmark's map-making both drive it.)
    """
    traces = []
    while until is None or not until(loop):
        path = loop.next_path(current)
        if path is None:
            break
        run = sim.execute(path)
        traces.append(run.trace)
        current = run.config
        if not run.blocked:
            loop.report_completed(current)
            continue
        current = sim.execute(loop.report_blocked(current, run.segment)).config
        loop.report_retreated(current)
    return current, traces


def run_episode(world: World, method: str | Method = 'probabilistic', seed: int = 0,
                max_paths: int = 20, settings: RRTSettings | None = None,
                c_fail: float | None = None) -> EpisodeResult:
    """
    Disentangle world.start -> world.goal with a method; reproducible from seed.

    method is a :class:`Method` or its string (``hard:0.02``; a bare name takes its default
    parameter); c_fail, if given, overrides the C_FAIL of the map the method would use.
    """
    if isinstance(method, str):
        method = Method.resolve(method)
    arm = world.arm
    planner = method.planner(arm, settings)
    fmap = method.failure_map(arm.task_space, c_fail)
    loop = method.disentangler(arm, planner, world.goal, fmap, max_paths=max_paths, seed=seed)
    _, traces = drive(loop, world.compliant_arm(), world.start.copy())
    return EpisodeResult(loop.state is State.SUCCEEDED, loop.paths_tried, len(loop.fmap),
                         loop.plan_times, loop, world, traces, loop.empty_plans)
