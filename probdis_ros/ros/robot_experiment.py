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
``probdis experiment robot``: the paper's Table I, run through the real ROS nodes.

Every (scenario, method, run) is one disentangling by :func:`probdis_ros.ros.demo.run_demo`:
the mock iiwa with the scenario's hidden obstacles and the planner node as two processes over
DDS on localhost, the planner seeded with the run's index, so a run reproduces up to the
timing of the mock.  Each finished run is appended to ``DIR/robot_runs.jsonl`` at once and
its bag kept under ``DIR/bags``; rerunning the command skips the runs already there.
"""

from __future__ import annotations

from collections.abc import Callable
import json
import os
from pathlib import Path
import statistics
import time

from probdis_ros.experiments.sweep import Method, read_episodes

RUNS_FILE = 'robot_runs.jsonl'


def planner_arguments(method: Method, seed: int, velocity_scaling: float) -> list[str]:
    """Return the planner node's ROS arguments that select a method and seed."""
    params = {'method': method.name, 'seed': seed, 'velocity_scaling': velocity_scaling}
    if method.value is not None:
        params[{'probabilistic': 'c_fail', 'hard': 'threshold',
                'epsilon': 'epsilon'}[method.name]] = method.value
    args: list[str] = []
    for name, value in params.items():
        args += ['-p', f'{name}:={value}']
    return args


def run_robot_experiment(out: Path, scenarios: list[str], methods: list[Method], runs: int,
                         velocity_scaling: float = 1.0, timeout: float = 600.0,
                         progress: Callable[[str], None] | None = None,
                         engine: str = 'physics', sim_time: bool = True,
                         real_time_factor: float = 5.0) -> list[dict]:
    """
    Run what is missing of scenarios x methods x runs; return every record of DIR.

    scenarios are physics scenes (engine ``physics``) or kinematic scenarios; with sim_time
    the mock runs on simulated time, as fast as the planner keeps up.
    """
    from probdis_ros.ros.demo import run_demo

    out.mkdir(parents=True, exist_ok=True)
    path = out / RUNS_FILE
    records = read_episodes(path, repair=True)
    done = {(r['scenario'], r['method'], r['run']) for r in records}
    todo = [(s, m, r) for s in scenarios for m in methods for r in range(runs)
            if (s, str(m), r) not in done]
    world_args = {'engine': engine, 'sim_time': sim_time,
                  'real_time_factor': real_time_factor}
    with path.open('a') as stream:
        for number, (scenario, method, run) in enumerate(todo, start=1):
            t0 = time.monotonic()
            args = (*planner_arguments(method, run, velocity_scaling),
                    '-p', f'bag_dir:={out / "bags"}')
            try:
                result = run_demo(scenario, timeout, quiet=True, extra_planner_args=args,
                                  **world_args)
            except (RuntimeError, TimeoutError) as err:
                # the nodes did not come up or answer (DDS, a busy machine): the run did not
                # happen; try it once more, then stop (a rerun resumes here)
                if progress:
                    progress(f'{scenario} {method} run {run}: {err}; trying again')
                t0 = time.monotonic()
                result = run_demo(scenario, timeout, quiet=True, extra_planner_args=args,
                                  **world_args)
            record = {'scenario': scenario, 'method': str(method), 'run': run, 'seed': run,
                      'engine': engine, 'velocity_scaling': velocity_scaling,
                      'success': result['success'], 'paths': result['paths'],
                      'failures': result['failures'], 'wall_s': time.monotonic() - t0,
                      'bag': result['bag']}
            stream.write(json.dumps(record) + '\n')
            stream.flush()
            os.fsync(stream.fileno())
            records.append(record)
            if progress:
                outcome = 'disentangled' if record['success'] else 'NOT disentangled'
                progress(f'[{number}/{len(todo)}] {scenario} {method} run {run}: {outcome} '
                         f'after {record["paths"]} path(s) ({record["wall_s"]:.0f} s)')
    return records


def robot_table(records: list[dict], scenarios: list[str], methods: list[str]) -> str:
    """
    Return Table I as Markdown: successes per scenario and method, totals, mean paths.

    Mean paths are over the successful runs of a method, as in the paper.
    """
    def cell(scenario: str | None, method: str) -> list[dict]:
        return [r for r in records if r['method'] == method and
                (scenario is None or r['scenario'] == scenario)]

    lines = ['| scenario | ' + ' | '.join(methods) + ' |',
             '| --- |' + ' --- |' * len(methods)]
    for scenario in [*scenarios, None]:
        counts = []
        for method in methods:
            group = cell(scenario, method)
            counts.append(f'{sum(r["success"] for r in group)} / {len(group)}')
        lines.append(f'| {scenario or "**total**"} | ' + ' | '.join(counts) + ' |')
    means = []
    for method in methods:
        paths = [r['paths'] for r in cell(None, method) if r['success']]
        means.append(f'{statistics.fmean(paths):.1f}' if paths else '-')
    lines.append('| mean paths (successful runs) | ' + ' | '.join(means) + ' |')
    return '\n'.join(lines) + '\n'
