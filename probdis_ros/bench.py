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

"""Benchmarks behind ``probdis bench``: measured figures anyone can rerun."""

from __future__ import annotations

import os
import platform
import statistics
import time

import numpy as np
from probdis_ros.model import arm_for_setting


def machine() -> str:
    """Name the CPU, core count and Python in one line, for reports of measured figures."""
    cpu = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as info:
            for line in info:
                if line.startswith('model name'):
                    cpu = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    return f'{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}'


def bench_fk(setting: str = '3d-orient', configs: int = 200_000, repeats: int = 5,
             seed: int = 0) -> dict:
    """
    Measure batched FK: median configurations per second over repeats, one thread.

    The first call (which compiles the kernel) is excluded.
    """
    if configs < 1 or repeats < 1:
        raise ValueError('configs and repeats must be at least 1')
    arm = arm_for_setting(setting)
    batch = arm.random_configurations(np.random.default_rng(seed), configs)
    arm.fk(batch[:8])
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        arm.fk(batch)
        rates.append(configs / (time.perf_counter() - start))
    return {'configs_per_s': statistics.median(rates), 'setting': setting,
            'configs': configs, 'repeats': repeats, 'machine': machine()}


def nineteen_failure_map(seed: int = 0):
    """
    Return (start, goal, map) with 19 failures learned in a real simulated episode.

    The Epsilon method (fast: no planning) runs in the demo's closed box (``demo_iiwa``, 3-D
    with orientation), where it rarely gets out, until 19 blocks are recorded; start is where
    the arm then is.  (Random 90-obstacle worlds no longer serve: since an arm pressed into
    an obstacle can pull back out, Epsilon leaves most of them within 19 blocks.)
    """
    from probdis_ros.model import FailureMap
    from probdis_ros.planning import Disentangler, EpsilonPlanner
    from probdis_ros.resources import scenario_path
    from probdis_ros.sim.episode import drive
    from probdis_ros.sim.worlds import load_world

    world = load_world(scenario_path('demo_iiwa'))
    for loop_seed in range(seed, seed + 100):
        loop = Disentangler(world.arm, EpsilonPlanner(world.arm, 0.2),
                            world.goal, FailureMap(world.arm.task_space), max_paths=200,
                            seed=loop_seed)
        current, _ = drive(loop, world.compliant_arm(), world.start,
                           until=lambda loop: len(loop.fmap) >= 19)
        if len(loop.fmap) == 19:
            return current, world.goal, loop.fmap
    raise RuntimeError('no episode produced 19 failures')


def bench_plan(seeds: int = 20) -> dict:
    """
    Median ProbRRT planning time (paper parameters, iiwa with orientation, one thread).

    Also the mean number of RRT* re-parentings per plan on each map.
    """
    from probdis_ros.model import FailureMap
    from probdis_ros.planning import ProbRRT

    start, goal, fmap = nineteen_failure_map()
    arm = arm_for_setting('3d-orient')
    planner = ProbRRT(arm)
    planner.plan(start, goal, fmap, np.random.default_rng(0))   # compile the kernels
    result = {'machine': machine(), 'seeds': seeds}
    for key, the_map in (('empty_map', FailureMap(arm.task_space)),
                         ('19_failures', fmap)):
        times, rewires = [], []
        for seed in range(seeds):
            t0 = time.perf_counter()
            plan = planner.plan(start, goal, the_map, np.random.default_rng(seed))
            times.append(time.perf_counter() - t0)
            rewires.append(plan.rewires)
        result[f'median_s_{key}'] = statistics.median(times)
        result[f'rewires_per_plan_{key}'] = statistics.fmean(rewires)
    return result
