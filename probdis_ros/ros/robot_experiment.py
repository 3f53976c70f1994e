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

On simulated time the mock does not wait for the planner: a planner that falls behind (a
busy machine, too high a ``real_time_factor``) loses joint states, and the run is then no
longer a run of the real arm's timing (a retreat goes unwatched, a stale gap reads as a
block).  Each run's bag tells: the joint states the planner recorded are checked for holes,
and a run with a hole longer than ``MAX_STATE_GAP`` is marked not valid, left out of the
table, and run again by the next invocation (README "Experiments").
"""

from __future__ import annotations

from collections.abc import Callable
import json
import os
from pathlib import Path
import statistics
import time

import numpy as np
from probdis_ros.experiments.sweep import Method, read_episodes
from probdis_ros.motion.jtc import DEFAULT_JTC_START

RUNS_FILE = 'robot_runs.jsonl'

#: [s] a longer hole in the planner's joint states makes a run not valid: 10 controller
#: periods, the span over which the detector judges a gap's rise (RISE_WINDOW, motion_delay)
MAX_STATE_GAP = 0.1

JOINT_STATE_TYPE = 'sensor_msgs/msg/JointState'


def state_gaps(bag: str | Path) -> tuple[int, float]:
    """
    Return how many joint states the planner missed in a run's bag, and the longest hole [s].

    The planner records every joint state it takes, stamped with its sample time on
    simulated time: a hole between two stamps is states it never saw.
    """
    from probdis_ros.ros.bag_source import Bag

    with Bag(bag) as reader:
        topics = [t for t, kind in reader.topics.items() if kind == JOINT_STATE_TYPE]
        stamps = [m.stamp_ns * 1e-9 for m in reader.messages(topics)]
    if len(stamps) < 2:
        return 0, 0.0
    steps = np.diff(stamps)
    period = float(np.median(steps))             # the mock's, whatever its rate
    missed = np.maximum(np.round(steps / period) - 1, 0).sum() if period > 0 else 0
    return int(missed), float(steps.max())


def valid(record: dict) -> bool:
    """Tell whether a run kept the real arm's timing (records without the check count)."""
    return record.get('max_state_gap_s', 0.0) <= MAX_STATE_GAP


def planner_arguments(method: Method, seed: int, velocity_scaling: float) -> list[str]:
    """Return the planner node's ROS arguments that select a method and seed."""
    try:
        method.checked_for_node()
    except ValueError as err:
        raise ValueError(f'{err}; run these with --offline') from None
    name = str(method) if method.name == 'informed' else method.name
    params = {'method': name, 'seed': seed, 'velocity_scaling': velocity_scaling}
    if method.value is not None:
        params[{'probabilistic': 'c_fail', 'hard': 'threshold',
                'epsilon': 'epsilon'}[method.name]] = method.value
    args: list[str] = []
    for name, value in params.items():
        args += ['-p', f'{name}:={value}']
    return args


def float_arguments(values: dict[str, float]) -> list[str]:
    """Return ROS arguments that set a node's float parameters (detector thresholds, faults)."""
    args: list[str] = []
    for name, value in values.items():
        args += ['-p', f'{name}:={float(value)}']
    return args


#: What an offline run's record keeps of its physics episode's summary (a run through the
#: nodes has only what its bag tells).
PHYSICS_FIGURES = ('message', 'peak_contact_force_n', 'peak_table_force_n', 'lowest_m',
                   'peak_external_torque_nm', 'command_speed_peak', 'sent_speed_peak',
                   'point_speed_peak_mps', 'sim_time_s', 'driver_restarts')


def offline_run(scenario: str, method: Method, run: int, velocity_scaling: float,
                detection: dict[str, float], jtc_start: str = DEFAULT_JTC_START,
                faults: dict[str, float] | None = None,
                cartesian_speed_limit: float = 0.0, restarts: int = 0,
                guard_holds: bool = False) -> dict:
    """
    Run one disentangling without DDS: the planner node's Run against JTC, filter and MuJoCo.

    Deterministic (the run index seeds the planner and the joint-state noise; simulated time
    stands still while it plans) and blind to the machine's load: the honest table when the
    nodes cannot keep up.  ``faults``: the mock's
    (:data:`~probdis_ros.physics.simulated_robot.FAULTS`), as its node takes them;
    ``restarts``: how often the operator restarts a driver that stopped the arm and starts
    the planner again (:func:`~probdis_ros.physics.episode.run_physics_episode`);
    ``guard_holds``: the driver's guard sends the measured position and runs on
    (``RobotSettings.guard_holds``).
    """
    from probdis_ros.motion.detector import DetectorSettings
    from probdis_ros.physics.episode import run_physics_episode
    from probdis_ros.physics.simulated_robot import RobotSettings, with_faults
    from probdis_ros.run import RunSettings

    settings = RunSettings(velocity_scaling=velocity_scaling,
                           detection=DetectorSettings(**detection), jtc_start=jtc_start,
                           cartesian_speed_limit=cartesian_speed_limit)
    robot, physics = with_faults(faults or {}, RobotSettings(jtc_start=jtc_start, seed=run,
                                                             guard_holds=guard_holds))
    episode = run_physics_episode(scenario, str(method), seed=run, run_settings=settings,
                                  robot_settings=robot, physics_settings=physics,
                                  restarts=restarts)
    summary = episode.summary()
    return {'success': summary['success'], 'paths': summary['paths'],
            'failures': summary['failures'], 'bag': None,
            **{name: summary[name] for name in PHYSICS_FIGURES}}


#: The value of a run setting (engine, velocity_scaling, offline, detection, jtc_start,
#: faults, cartesian_speed_limit, restarts, guard_holds) in records written before it was
#: kept (none: not compared).
LEGACY_SETTINGS = {'offline': False, 'detection': {}, 'jtc_start': 'measured', 'faults': {},
                   'cartesian_speed_limit': 0.0, 'restarts': 0, 'guard_holds': False}


def check_settings(path: Path, records: list[dict], settings: dict) -> None:
    """
    Refuse a directory whose runs were made with other settings (ValueError, naming them).

    A resumed experiment skips the runs it finds: runs of other settings would fill its
    table, as the sweep's directories refuse episodes of another sweep.
    """
    for record in records:
        theirs = {k: record.get(k, LEGACY_SETTINGS.get(k, settings[k])) for k in settings}
        if theirs != settings:
            differ = ', '.join(f'{k} {theirs[k]!r}, not {settings[k]!r}' for k in settings
                               if theirs[k] != settings[k])
            raise ValueError(f'{path} holds runs of another experiment ({differ}); use '
                             'another --out')


def run_robot_experiment(out: Path, scenarios: list[str], methods: list[Method], runs: int,
                         velocity_scaling: float = 1.0, timeout: float = 600.0,
                         progress: Callable[[str], None] | None = None,
                         engine: str = 'physics', sim_time: bool = True,
                         real_time_factor: float = 1.0, offline: bool = False,
                         detection: dict[str, float] | None = None,
                         jtc_start: str = DEFAULT_JTC_START,
                         faults: dict[str, float] | None = None,
                         cartesian_speed_limit: float = 0.0, restarts: int = 0,
                         guard_holds: bool = False) -> list[dict]:
    """
    Run what is missing of scenarios x methods x runs; return every record of DIR.

    scenarios are physics scenes (engine ``physics``) or kinematic scenarios; with sim_time
    the mock runs on simulated time, real_time_factor times faster than the wall clock.
    ``offline`` runs each physics scene without the nodes (:func:`offline_run`);
    ``detection`` overrides detector thresholds (``DetectorSettings`` fields) either way;
    ``jtc_start`` is where the controller starts a command (and the planner models it);
    ``faults`` are the mock's (by the names of
    :data:`~probdis_ros.physics.simulated_robot.FAULTS`) in every run;
    ``cartesian_speed_limit`` [m/s] is the planner's (0: off); ``restarts`` (offline only)
    how often a driver that stopped the arm is restarted and the planner started again;
    ``guard_holds``: the mock driver's guard sends the measured position in place of a
    command it refuses and runs on, as some lbr releases do.
    """
    if restarts and not offline:
        raise ValueError('restarts are simulated offline only (the mock node does not '
                         'restart its driver)')
    detection = dict(detection or {})
    faults = dict(faults or {})
    settings = {'engine': engine, 'velocity_scaling': velocity_scaling, 'offline': offline,
                'detection': detection, 'jtc_start': jtc_start, 'faults': faults,
                'cartesian_speed_limit': cartesian_speed_limit, 'restarts': restarts,
                'guard_holds': guard_holds}

    out.mkdir(parents=True, exist_ok=True)
    path = out / RUNS_FILE
    records = read_episodes(path, repair=True)
    check_settings(path, records, settings)
    # a run that was not valid is run again (its record stays, marked)
    done = {(r['scenario'], r['method'], r['run']) for r in records if valid(r)}
    todo = [(s, m, r) for s in scenarios for m in methods for r in range(runs)
            if (s, str(m), r) not in done]
    world_args = {'engine': engine, 'sim_time': sim_time,
                  'real_time_factor': real_time_factor}

    def one_run(scenario: str, method: Method, run: int) -> dict:
        """Run once, offline or through the nodes: a retry goes the same way."""
        if offline:     # any method: no planner node, whose parameters limit it
            return offline_run(scenario, method, run, velocity_scaling, detection, jtc_start,
                               faults, cartesian_speed_limit, restarts, guard_holds)
        from probdis_ros.ros.demo import run_demo

        args = (*planner_arguments(method, run, velocity_scaling),
                *float_arguments({**detection, 'cartesian_speed_limit': cartesian_speed_limit}),
                '-p', f'bag_dir:={out / "bags"}')
        return run_demo(scenario, timeout, quiet=True, extra_planner_args=args,
                        extra_mock_args=(*float_arguments(faults),
                                         *(('-p', 'guard_holds:=true') if guard_holds else ())),
                        jtc_start=jtc_start,
                        **world_args)

    with path.open('a') as stream:
        for number, (scenario, method, run) in enumerate(todo, start=1):
            t0 = time.monotonic()
            try:
                result = one_run(scenario, method, run)
            except (RuntimeError, TimeoutError) as err:
                # the nodes did not come up or answer (DDS, a busy machine): the run did not
                # happen; try it once more, the same way, then stop (a rerun resumes here)
                if progress:
                    progress(f'{scenario} {method} run {run}: {err}; trying again')
                t0 = time.monotonic()
                result = one_run(scenario, method, run)
            record = {'scenario': scenario, 'method': str(method), 'run': run, 'seed': run,
                      'engine': engine, 'velocity_scaling': velocity_scaling,
                      'success': result['success'], 'paths': result['paths'],
                      'failures': result['failures'], 'wall_s': time.monotonic() - t0,
                      'bag': result['bag'], 'offline': offline, 'detection': detection,
                      'jtc_start': jtc_start, 'faults': faults,
                      'cartesian_speed_limit': cartesian_speed_limit, 'restarts': restarts,
                      'guard_holds': guard_holds}
            for name in PHYSICS_FIGURES:
                if name in result:
                    record[name] = result[name]
            if result['bag'] and sim_time:
                record['missed_states'], record['max_state_gap_s'] = state_gaps(result['bag'])
            stream.write(json.dumps(record) + '\n')
            stream.flush()
            os.fsync(stream.fileno())
            records.append(record)
            if progress:
                outcome = 'disentangled' if record['success'] else 'NOT disentangled'
                progress(f'[{number}/{len(todo)}] {scenario} {method} run {run}: {outcome} '
                         f'after {record["paths"]} path(s) ({record["wall_s"]:.0f} s)')
                if not valid(record):
                    progress(f'  not valid: the planner missed {record["missed_states"]} joint '
                             f'states (a hole of {record["max_state_gap_s"]:.2f} s); left out '
                             f"of the table: lower --real-time-factor or the machine's load")
    return records


def robot_table(records: list[dict], scenarios: list[str], methods: list[str],
                groups: dict[str, list[str]] | None = None) -> str:
    """
    Return Table I as Markdown: successes per scenario and method, totals, mean paths.

    Mean paths are over the successful runs of a method, as in the paper.  Runs that did not
    keep the real arm's timing (:func:`valid`) are left out and counted below the table.
    With ``groups`` (a row's name: its scenarios, e.g. a family's worlds) a row sums a group.
    """
    kept = [r for r in records if valid(r)]
    runs = {(r['scenario'], r['method'], r.get('run')) for r in kept}
    left_out = {(r['scenario'], r['method'], r.get('run')) for r in records
                if not valid(r)} - runs
    records = kept

    label = 'scenario' if groups is None else 'family'
    groups = groups or {s: [s] for s in scenarios}

    def cell(row: str | None, method: str) -> list[dict]:
        return [r for r in records if r['method'] == method and
                (row is None or r['scenario'] in groups[row])]

    lines = [f'| {label} | ' + ' | '.join(methods) + ' |',
             '| --- |' + ' --- |' * len(methods)]
    for scenario in [*groups, None]:
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
    if any('peak_contact_force_n' in r for r in records):
        peaks = []
        for method in methods:
            forces = [r['peak_contact_force_n'] for r in cell(None, method)
                      if 'peak_contact_force_n' in r]
            peaks.append(f'{statistics.median(forces):.0f}' if forces else '-')
        lines.append('| peak contact force per run, median [N] | ' + ' | '.join(peaks) + ' |')
    if any('point_speed_peak_mps' in r for r in records):
        speeds = []
        for method in methods:
            peaks = [r['point_speed_peak_mps'] for r in cell(None, method)
                     if 'point_speed_peak_mps' in r]
            speeds.append(f'{statistics.median(peaks):.3f} / {max(peaks):.3f}' if peaks
                          else '-')
        lines.append('| fastest point of the arm per run, median / max [m/s] | ' +
                     ' | '.join(speeds) + ' |')
    from probdis_ros.physics.simulated_robot import DRIVER_STOPPED, GUARD_HELD

    def stops(record: dict) -> int:
        message = record.get('message', '')
        return message.count(DRIVER_STOPPED) + message.count(GUARD_HELD)

    if any(stops(r) for r in records):
        cells = []
        for method in methods:
            counts = [stops(r) for r in cell(None, method)]
            cells.append(f'{sum(c > 0 for c in counts)} / {sum(counts)}')
        lines.append('| runs the driver stopped or held / its stops and holds | ' +
                     ' | '.join(cells) + ' |')
    if left_out:
        lines.append(f'\n{len(left_out)} run(s) left out: the planner fell behind the '
                     f'simulation (joint states missed)')
    return '\n'.join(lines) + '\n'


def paired_table(records: list[dict], baseline: list[dict], methods: list[str]) -> str:
    """
    Return Markdown comparing each method's runs with the same runs of ``baseline``.

    Runs pair by (scenario, method, run), valid ones only; per method: the runs both hold,
    the share disentangled in each, the mean difference with a paired 95 % percentile-
    bootstrap interval (the pairs resampled, as the sweeps' reports do: ``paired_ci``), the
    runs won and lost, and the mean paths over the runs both got out of.
    """
    from probdis_ros.experiments.report import paired_ci

    def key(record: dict) -> tuple:
        return record['scenario'], record['method'], record.get('run')

    theirs = {key(r): r for r in baseline if valid(r)}
    lines = ['| method | runs in both | disentangled: these / baseline | difference (paired 95 % '
             'CI) | won / lost | mean paths where both got out: these / baseline |',
             '| --- | --- | --- | --- | --- | --- |']
    for method in methods:
        pairs = sorted(((key(r), r, theirs[key(r)]) for r in records
                        if valid(r) and r['method'] == method and key(r) in theirs),
                       key=lambda pair: pair[0])
        if not pairs:
            lines.append(f'| {method} | 0 | - | - | - | - |')
            continue
        diffs = np.array([float(a['success']) - float(b['success']) for _, a, b in pairs])
        low, high = paired_ci(diffs)
        both = [(a['paths'], b['paths']) for _, a, b in pairs if a['success'] and b['success']]
        paths = (f'{statistics.fmean(a for a, _ in both):.1f} / '
                 f'{statistics.fmean(b for _, b in both):.1f}') if both else '-'
        ours = sum(a['success'] for _, a, _ in pairs)
        base = sum(b['success'] for _, _, b in pairs)
        lines.append(f'| {method} | {len(pairs)} | {ours} / {base} | {diffs.mean():+.3f} '
                     f'({low:+.3f} to {high:+.3f}) | {int((diffs > 0).sum())} / '
                     f'{int((diffs < 0).sum())} | {paths} |')
    return '\n'.join(lines) + '\n'
