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
The ``probdis`` command: one entry point, one subcommand per job.

Heavy modules are imported inside each handler so that ``probdis --help`` stays fast.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Collection, Iterator
import contextlib
from dataclasses import replace
import json
import math
import os
from pathlib import Path
import sys
from typing import TYPE_CHECKING

from probdis_ros.ros import (  # plain names: no rclpy
    DEFAULT_REAL_TIME_FACTOR,
    DETECTOR_FIELDS,
    JOINT_STATES_TOPIC,
    TRAJECTORY_TOPIC,
)

if TYPE_CHECKING:
    from probdis_ros.planning.methods import Method

SETTINGS = ('2d', '3d', '3d-orient')
DEFAULT_C_FAIL = 100.0   # the model's default (probdis_ros.model.failure_map), without its imports
#: The method strings of the sweep and the robot experiment (IDEAS: planning.informed.IDEAS)
METHODS_HELP = ('comma-separated probabilistic[:C_FAIL], hard:Y[:C_HARD], epsilon:X, '
                'informed[:IDEAS] (IDEAS: letters of abcdefghij)')


class UsageError(Exception):
    """Bad input from the user: reported as one line, exit status 2."""


def _positive(value: float, flag: str) -> float:
    """Return value if finite and above 0 (NaN passes ``<= 0`` checks, so test it outright)."""
    if not (math.isfinite(value) and value > 0):
        raise UsageError(f'{flag} must be a positive number, got {value:g}')
    return value


def _not_negative(value: float, flag: str) -> float:
    """Return value if finite and at least 0."""
    if not (math.isfinite(value) and value >= 0):
        raise UsageError(f'{flag} must be a number >= 0, got {value:g}')
    return value


def _check_output(path: str | Path, flag: str = '', folder: bool = False) -> None:
    """
    Refuse an output that cannot be written before the work that would fill it.

    ``folder``: the output is a directory (created if missing), else a file (its folders
    are created if missing).  ``flag`` names the option that gave the path, if one did.
    """
    target = Path(path)
    where = f'{flag} {path}' if flag else str(path)
    if folder and target.exists() and not target.is_dir():
        raise UsageError(f'{where}: not a directory')
    if not folder and target.is_dir():
        raise UsageError(f'{where}: is a directory')
    existing = target if folder and target.is_dir() else target.parent
    while not existing.exists():       # the missing folders are created on writing
        existing = existing.parent
    if not existing.is_dir():
        raise UsageError(f'{where}: {existing} is not a directory')
    if not os.access(existing, os.W_OK | os.X_OK) or \
            (not folder and target.exists() and not os.access(target, os.W_OK)):
        raise UsageError(f'{where}: not writable')


def _print_json(doc: dict) -> None:
    print(json.dumps(doc))


def _print_doc(doc: dict, as_json: bool) -> None:
    """Print a document as one JSON object, or as aligned 'key: value' lines."""
    if as_json:
        _print_json(doc)
        return
    width = max(map(len, doc), default=0)
    for key, value in doc.items():
        print(f'{key:>{width}}: {value}')


def cmd_info(args: argparse.Namespace) -> int:
    """Print the version and where the config and URDF files were found."""
    from probdis_ros import __version__
    from probdis_ros.resources import share_dir

    how, share = share_dir()
    doc = {'version': __version__, 'share': str(share), 'found_by': how,
           'config': str(share / 'config'), 'urdf': str(share / 'urdf' / 'iiwa14.urdf')}
    _print_doc(doc, args.json)
    return 0


def cmd_fk(args: argparse.Namespace) -> int:
    """Print the forward kinematics of one configuration."""
    from probdis_ros.model import arm_for_setting

    arm = arm_for_setting(args.setting)
    if len(args.joints) != arm.n_joints:
        raise UsageError(f'{args.setting} arm has {arm.n_joints} joints '
                         f'({", ".join(arm.joint_names)}); got {len(args.joints)} values')
    config = _joint_values(args.joints, 'joint')
    inside = bool(arm.within_limits(config)[0])
    pose = arm.fk(config)
    doc = {'setting': args.setting, 'joints': config.tolist(), 'within_limits': inside,
           'position': pose.positions[0].tolist()}
    if pose.orientations is not None:
        doc['quaternion_wxyz'] = pose.orientations[0].tolist()
    if args.json:
        _print_json(doc)
    else:
        print('position  ' + ' '.join(f'{v: .6f}' for v in doc['position']))
        if 'quaternion_wxyz' in doc:
            print('quat wxyz ' + ' '.join(f'{v: .6f}' for v in doc['quaternion_wxyz']))
        if not inside:
            print('warning: configuration is outside the joint limits', file=sys.stderr)
    return 0


def _joint_values(values: list[float], what: str):
    """Return joint positions as an array, refusing NaN and infinities (FK divides by them)."""
    import numpy as np

    bad = [v for v in values if not math.isfinite(v)]
    if bad:
        raise UsageError(f'{what} values must be finite numbers [rad], got {bad[0]:g}')
    return np.array(values, dtype=float)


def cmd_bench_fk(args: argparse.Namespace) -> int:
    """Measure batched FK throughput."""
    from probdis_ros.bench import bench_fk

    result = bench_fk(args.setting, args.configs, args.repeats, args.seed)
    if args.json:
        _print_json({'configs_per_s': result['configs_per_s']})
    else:
        print(f'FK {result["setting"]}: {result["configs_per_s"] / 1e6:.2f} M configurations/s '
              f'(median of {result["repeats"]} x {result["configs"]}, one thread)')
        print(f'machine: {result["machine"]}')
    return 0


def cmd_experiment_sweep(args: argparse.Namespace) -> int:
    """Run (or resume) a sweep of simulated episodes: the paper's settings or families."""
    from probdis_ros.experiments.sweep import (
        episode_keys,
        family_keys,
        progress_line,
        run_sweep,
        SETTINGS,
    )

    methods = _methods(args.methods)
    _check_output(args.out, '--out', folder=True)
    if args.worlds < 1 or args.max_paths < 1 or \
            (args.workers is not None and args.workers < 1):
        raise UsageError('--worlds, --max-paths and --workers must be positive')
    if args.family is not None:
        if args.setting is not None or args.obstacles is not None:
            raise UsageError('--family runs entanglement families; it takes no --setting '
                             'or --obstacles')
        families = _families(args.family)
        _not_negative(args.seed, '--seed')        # the first world seed
        keys = family_keys(families, args.worlds, methods, args.seed)
    else:
        settings = _split(args.setting or '2d,3d,3d-orient')
        unknown = [s for s in settings if s not in SETTINGS]
        if unknown:
            raise UsageError(f'unknown setting {unknown[0]!r}; choose from '
                             f'{", ".join(SETTINGS)}')
        try:
            obstacles = [int(n) for n in _split(args.obstacles or '1,10,30,50')]
        except ValueError:
            raise UsageError('--obstacles takes comma-separated integers, not '
                             f'{args.obstacles!r}') from None
        if any(n < 1 for n in obstacles):     # a world needs one: every episode failed
            raise UsageError('obstacle counts must be at least 1')
        keys = episode_keys(settings, obstacles, args.worlds, methods, args.seed)
    rrt = {}
    if args.iterations is not None:
        if args.iterations < 1:
            raise UsageError('--iterations must be positive')
        rrt['iterations'] = args.iterations
    if args.plan_time is not None:
        rrt['plan_time'] = _positive(args.plan_time, '--plan-time')
    progress = progress_line if sys.stderr.isatty() else None
    try:
        report = run_sweep(keys, Path(args.out), args.max_paths, args.scheduler, args.workers,
                           progress, rrt or None)
    except KeyboardInterrupt:
        print(f'\nprobdis experiment sweep: the finished episodes are kept in {args.out}; '
              'the same command resumes with the others', file=sys.stderr)
        raise
    print(f'{args.out}: {report.total} episodes, {report.skipped} already done, '
          f'{report.ran} run in {report.seconds:.0f} s')
    return 0


def cmd_experiment_report(args: argparse.Namespace) -> int:
    """Write the report of a sweep directory."""
    from probdis_ros.experiments.report import markdown_tables, write_report

    for name in ('summary.json', 'summary.md'):
        _check_output(Path(args.dir) / name)
    summary = write_report(args.dir, args.others or ())
    print(markdown_tables(summary), end='')
    print(f'wrote {", ".join(summary["files"])} in {args.dir}')
    return 0


def cmd_experiment_bound(args: argparse.Namespace) -> int:
    """Bound the plate_hole success of any search; compare sweeps' methods with the bounds."""
    import time
    import warnings

    from probdis_ros.experiments.hole_search import (
        LABELS,
        mean_curves,
        mean_paths,
        method_curves,
        plot_bounds,
        PRIORS,
        world_bound,
    )
    from probdis_ros.experiments.report import check_records
    from probdis_ros.experiments.sweep import EPISODES_FILE, progress_line, read_episodes

    if args.worlds < 1 or args.seed < 0 or args.max_paths < 1:
        raise UsageError('--worlds and --max-paths must be positive, --seed not negative')
    records = []
    for directory in args.episodes or ():
        path = Path(directory) / EPISODES_FILE
        if not path.is_file():
            raise UsageError(f'--episodes {directory}: no {EPISODES_FILE} there')
        records += check_records(read_episodes(path), path)
    if args.out:
        _check_output(args.out, '--out', folder=True)
    seeds = list(range(args.seed, args.seed + args.worlds))
    paths = args.max_paths
    with warnings.catch_warnings(record=True) as caught:     # (refuses before the bounds)
        warnings.simplefilter('always')
        methods = method_curves(records, seeds, paths)
    bounds, t0 = [], time.monotonic()
    for done, seed in enumerate(seeds, start=1):
        bounds.append(world_bound(seed))
        if sys.stderr.isatty():
            progress_line(done, len(seeds), time.monotonic() - t0, 'worlds')
    curves = mean_curves(bounds, paths)
    for warning in caught:
        print(f'note: {warning.message}', file=sys.stderr)
    if records and not methods:
        print(f'note: no method of {", ".join(args.episodes)} has a plate_hole episode on '
              f'every world of seeds {seeds[0]}-{seeds[-1]} (was it swept with --seed '
              f'{args.seed}?)', file=sys.stderr)
    worlds = f'seeds {seeds[0]}-{seeds[-1]}'
    doc = {'family': 'plate_hole', 'seeds': [seeds[0], seeds[-1]], 'max_paths': paths,
           'bounds': {p: {'within': curves[p], 'mean_paths': mean_paths(bounds, p, paths)}
                      for p in PRIORS},
           'methods': methods}
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        with (out / 'hole_bound.jsonl').open('w') as f:
            for bound in bounds:
                f.write(json.dumps(bound.to_dict()) + '\n')
        (out / 'hole_bound.json').write_text(json.dumps(doc, indent=1) + '\n')
        doc['files'] = ['hole_bound.jsonl', 'hole_bound.json',
                        plot_bounds(curves, methods, worlds, out / 'hole_bound.png').name]
    if args.json:
        _print_json(doc)
        return 0
    marks = [n for n in (1, 2, 5, 10, 20, paths) if n <= paths]
    marks = sorted(set(marks))
    print(f'plate_hole, {worlds} ({len(seeds)} worlds): share of worlds out within n paths')
    print('| searcher or method | ' + ' | '.join(f'n = {n}' for n in marks) +
          ' | mean paths when out |')
    print('| --- |' + ' --- |' * (len(marks) + 1))
    for prior in PRIORS:
        row = ' | '.join(f'{curves[prior][n - 1]:.2f}' for n in marks)
        print(f'| {LABELS[prior]} | {row} | {doc["bounds"][prior]["mean_paths"]:.1f} |')
    for method, found in methods.items():
        row = ' | '.join(f'{found["within"][n - 1]:.2f}' for n in marks)
        print(f'| {method} | {row} | {found["mean_paths"]:.1f} |')
    if args.out:
        print(f'wrote {", ".join(doc["files"])} in {args.out}')
    return 0


def _name_values(flag: str, items: list[str] | None, known: Collection[str],
                 what: str) -> dict[str, float]:
    """Parse repeated ``NAME=VALUE`` options, refusing unknown names and values not numbers."""
    out = {}
    for item in items or []:
        name, _, value = item.partition('=')
        if name not in known:
            raise UsageError(f'{flag} {item!r}: not {what} (one of {", ".join(known)})')
        try:
            out[name] = float(value)
        except ValueError:
            raise UsageError(f'{flag} {item!r}: {value!r} is not a number') from None
    return out


def _detection_overrides(items: list[str] | None) -> dict[str, float]:
    """Parse ``--detection NAME=VALUE`` detector thresholds, refusing what the detector would."""
    from dataclasses import fields

    from probdis_ros.motion.detector import DetectorSettings

    known = sorted(f.name for f in fields(DetectorSettings) if f.type in ('float', float))
    out = _name_values('--detection', items, known, 'a detector threshold')
    try:
        DetectorSettings(**out)
    except ValueError as err:
        raise UsageError(f'--detection: {err}') from None
    return out


def _fault_overrides(items: list[str] | None) -> dict[str, float]:
    """Parse ``--fault NAME=VALUE`` faults of the mock, refusing what the mock would."""
    from probdis_ros.physics.simulated_robot import FAULTS, with_faults

    out = _name_values('--fault', items, FAULTS, 'a fault of the mock')
    try:
        with_faults(out)
    except ValueError as err:
        raise UsageError(f'--fault: {err}') from None
    return out


def _families(text: str) -> list[str]:
    """Return the families of ``--family`` (comma-separated, or all); refuse unknown ones."""
    from probdis_ros.sim.families import FAMILIES

    families = list(FAMILIES) if text == 'all' else _split(text)
    unknown = [f for f in families if f not in FAMILIES]
    if unknown or not families:
        raise UsageError(f'unknown family {(unknown or [text])[0]!r}; choose from '
                         f'{", ".join(FAMILIES)} or all')
    return families


def _family_groups(args: argparse.Namespace, default_worlds: int
                   ) -> dict[str, list[str]] | None:
    """Return the scene names of --family's worlds by family (--worlds, --seed), or None."""
    from probdis_ros.physics.family_scenes import family_scene_name

    if args.family is None:
        if args.worlds is not None or args.seed is not None:
            raise UsageError('--worlds and --seed choose the worlds of --family')
        return None
    families = _families(args.family)
    worlds = default_worlds if args.worlds is None else args.worlds
    seed = 0 if args.seed is None else args.seed
    if worlds < 1 or seed < 0:
        raise UsageError('--worlds must be positive and --seed not negative')
    return {f: [family_scene_name(f, seed + w) for w in range(worlds)] for f in families}


def _robot_worlds(args: argparse.Namespace) -> tuple[list[str], dict[str, list[str]] | None]:
    """Return the robot experiment's scenes (or scenarios) and, for families, their groups."""
    from probdis_ros.physics.scene import scene_path
    from probdis_ros.resources import scenario_path

    physics = args.engine == 'physics'
    if args.family is not None and args.scenarios is not None:
        raise UsageError('give --scenarios or --family, not both')
    if args.family is not None and not physics:
        raise UsageError('--family runs the families as physical scenes (--engine physics)')
    groups = _family_groups(args, 5)
    if groups is None:
        scenarios = _split(args.scenarios or 'robot_waste,robot_maze,robot_bunny')
        missing = [s for s in scenarios
                   if not (scene_path(s) if physics else scenario_path(s)).is_file()]
        if missing:
            kind = 'scene' if physics else 'scenario'
            raise UsageError(f'no {kind} file {missing[0]!r} (a path, or a name in '
                             f'config/{kind}s/)')
        return scenarios, None
    # world by world across the families, so that a partial run has as many of each
    worlds = len(next(iter(groups.values())))
    return [groups[f][w] for w in range(worlds) for f in groups], groups


def cmd_experiment_robot(args: argparse.Namespace) -> int:
    """Run the robot scenarios through the ROS nodes against the mock iiwa (Table I)."""
    from probdis_ros.experiments.sweep import read_episodes
    from probdis_ros.physics.simulated_robot import PHYSICS_FAULTS
    from probdis_ros.ros.robot_experiment import (
        paired_table,
        robot_table,
        run_robot_experiment,
        RUNS_FILE,
    )
    from probdis_ros.run import MAX_VELOCITY_SCALING, MIN_VELOCITY_SCALING

    scenarios, groups = _robot_worlds(args)
    baseline = None
    if args.against is not None:
        if not (Path(args.against) / RUNS_FILE).is_file():
            raise UsageError(f'--against {args.against}: no {RUNS_FILE} there (the --out of '
                             'another robot experiment)')
        baseline = read_episodes(Path(args.against) / RUNS_FILE)
    physics = args.engine == 'physics'
    methods = _methods(args.methods)
    _positive(args.timeout, '--timeout')
    _not_negative(args.real_time_factor, '--real-time-factor')
    _check_output(args.out, '--out', folder=True)
    runs = args.runs if args.runs is not None else (10 if groups is None else 1)
    if runs < 1 or not MIN_VELOCITY_SCALING <= args.velocity_scaling <= MAX_VELOCITY_SCALING:
        raise UsageError(f'--runs must be positive and --velocity-scaling in '
                         f'[{MIN_VELOCITY_SCALING}, {MAX_VELOCITY_SCALING}]')
    if args.offline and not physics:
        raise UsageError('--offline runs the physics scenes (--engine physics)')
    _not_negative(args.restarts, '--restarts')
    if args.restarts and not args.offline:
        raise UsageError('--restarts needs --offline (the mock node does not restart its '
                         'driver)')
    detection = _detection_overrides(args.detection)
    beyond = sorted(set(detection) - set(DETECTOR_FIELDS))
    if beyond and not args.offline:
        raise UsageError(f'--detection {beyond[0]}: not a parameter of the planner node '
                         '(--offline runs take it)')
    faults = _fault_overrides(args.fault)
    physical = set(PHYSICS_FAULTS) & set(faults)
    if physical and not physics:
        raise UsageError(f'--fault {sorted(physical)[0]}: a fault of the physics arm '
                         '(--engine physics)')
    say = None if args.json else (lambda line: print(line, file=sys.stderr, flush=True))
    records = run_robot_experiment(Path(args.out), scenarios, methods, runs,
                                   args.velocity_scaling, args.timeout, say,
                                   engine=args.engine, sim_time=args.sim_time,
                                   real_time_factor=args.real_time_factor,
                                   offline=args.offline, detection=detection,
                                   jtc_start=args.jtc_start, faults=faults,
                                   cartesian_speed_limit=_cartesian_speed(args),
                                   restarts=args.restarts, guard_holds=args.guard_holds)
    # the runs asked for only: a DIR may hold more runs (an earlier --runs), other scenes
    # or methods
    wanted = {(s, str(m), r) for s in scenarios for m in methods for r in range(runs)}
    records = [r for r in records if (r['scenario'], r['method'], r.get('run')) in wanted]
    if args.json:
        _print_json(records)
    else:
        print(robot_table(records, scenarios, [str(m) for m in methods], groups), end='')
        if baseline is not None:
            print(f'\nagainst the same runs in {args.against}:')
            print(paired_table(records, baseline, [str(m) for m in methods]), end='')
        print(f'runs in {args.out}' if args.offline else f'runs and bags in {args.out}')
    return 0


def _split(text: str) -> list[str]:
    """Return the comma-separated parts of text, each once (a name twice is run once)."""
    return list(dict.fromkeys(part.strip() for part in text.split(',') if part.strip()))


def _methods(text: str) -> list[Method]:
    """Return the methods of ``--methods``; refuse a list that names none (nothing to run)."""
    from probdis_ros.planning.methods import Method

    # each method once, however spelled (informed and informed:adfhij are one)
    methods = list({str(m): m for m in map(Method.parse, _split(text))}.values())
    if not methods:
        raise UsageError(f'--methods {text!r} names no method ({METHODS_HELP})')
    return methods


def cmd_map_plot(args: argparse.Namespace) -> int:
    """Draw a 2-D failure probability map as a PNG."""
    from probdis_ros.model import FailureMap
    from probdis_ros.plots import example_map, plot_map

    _check_output(args.out, '--out')
    fmap = FailureMap.load(args.map) if args.map else example_map(args.c_fail)
    extent = tuple(args.extent) if args.extent else None
    title = f'{args.map}' if args.map else 'Failure probability around three failures'
    out = plot_map(fmap, args.out, extent, title=title)
    print(f'wrote {out} ({len(fmap)} failures)')
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    """Run one simulated disentangling episode."""
    if args.engine == 'physics':
        return _sim_physics(args)
    from probdis_ros.motion.jtc import DEFAULT_JTC_START

    if args.jtc_start != DEFAULT_JTC_START:
        raise UsageError('--jtc-start needs --engine physics (the kinematic sweeps run no JTC)')
    if args.cartesian_speed_limit:
        raise UsageError('--cartesian-speed-limit needs --engine physics (the kinematic '
                         'sweeps time no motion)')

    from probdis_ros.planning import Method
    from probdis_ros.resources import scenario_path
    from probdis_ros.sim.episode import run_episode
    from probdis_ros.sim.worlds import load_world, random_world

    method = Method.resolve(args.method, args.threshold, args.epsilon)
    _check_sim_args(args)
    if args.family and (args.scenario or args.setting):
        raise UsageError('--family draws its own world (3d-orient): no --scenario or --setting')
    if args.family:
        from probdis_ros.sim.families import FAMILIES, random_family_world

        if args.family not in FAMILIES:
            raise UsageError(f'unknown family {args.family!r}; choose from '
                             f'{", ".join(FAMILIES)}')
        world = random_family_world(args.family, args.seed or 0)
    elif args.scenario:
        world = load_world(scenario_path(args.scenario))
        if args.setting and args.setting != world.setting:
            raise UsageError(f'--setting {args.setting} does not match the scenario '
                             f'({world.setting})')
    else:
        world = random_world(args.setting or '2d', args.obstacles, args.seed or 0)
    if args.plot and world.setting != '2d':
        raise UsageError('--plot draws 2-D episodes; use --setting 2d')
    if args.no_table:
        world = replace(world, table=None)
    seed = args.seed or 0
    result = run_episode(world, method, seed=seed, max_paths=args.max_paths,
                         c_fail=method.map_c_fail(args.c_fail))
    # the result first: a plot that cannot be written after all must not lose the episode
    if args.json:
        _print_json(result.summary())
    else:
        _print_episode(result, method, world, args)
    if args.plot:
        from probdis_ros.plots import plot_episode

        plot_episode(result, args.plot)
        if not args.json:
            print(f'wrote {args.plot}')
    return 0


def _check_sim_args(args: argparse.Namespace) -> None:
    """Refuse sim's bad numbers and an unwritable --plot before the episode runs."""
    if args.seed is not None:
        _not_negative(args.seed, '--seed')
    if args.plot:
        _check_output(args.plot, '--plot')


def _print_episode(result, method: Method, world, args: argparse.Namespace) -> None:
    """Print a kinematic episode's outcome, planning times and world."""
    import statistics

    outcome = 'disentangled' if result.success else 'NOT disentangled'
    times = result.plan_times_s
    empty = f' ({result.empty_plans} of them empty plans)' if result.empty_plans else ''
    name = world.name or args.scenario or f'{args.family} world {args.seed or 0}'
    print(f'{name}: {method}: {outcome} after {result.paths} '
          f'path(s){empty}, {result.failures} failure(s) learned')
    if times:
        print(f'planning time per path: median {statistics.median(times):.3f} s, '
              f'max {max(times):.3f} s')
    if world.rejected_draws:
        print(f'(world drawn after {world.rejected_draws} rejected unsolvable draws)')


def _sim_physics(args: argparse.Namespace) -> int:
    """Run one episode against the physics arm offline (``--engine physics``)."""
    import numpy as np
    from probdis_ros.model import iiwa_arm
    from probdis_ros.physics.episode import run_physics_episode
    from probdis_ros.physics.picture import plot_scene_run
    from probdis_ros.planning import Method

    if args.scenario or args.setting or args.no_table:
        raise UsageError('--engine physics runs a --scene or a --family, not a --scenario '
                         'or --setting, on its table')
    _check_sim_args(args)
    scene = args.scene or 'demo_hook'
    if args.family:
        from probdis_ros.physics.family_scenes import draw_family_scene
        from probdis_ros.sim.families import FAMILIES

        if args.scene:
            raise UsageError('give --scene or --family, not both')
        if args.family not in FAMILIES:
            raise UsageError(f'unknown family {args.family!r}; choose from '
                             f'{", ".join(FAMILIES)}')
        scene = draw_family_scene(args.family, args.seed or 0)
    method = Method.resolve(args.method, args.threshold, args.epsilon)
    from probdis_ros.run import RunSettings

    episode = run_physics_episode(scene, method, seed=args.seed or 0,
                                  max_paths=args.max_paths,
                                  c_fail=method.map_c_fail(args.c_fail),
                                  run_settings=RunSettings(
                                      jtc_start=args.jtc_start,
                                      cartesian_speed_limit=_cartesian_speed(args)))
    summary = episode.summary()
    # the result first: a plot that cannot be written after all must not lose the episode
    if args.json:
        _print_json(summary)
    else:
        outcome = 'disentangled' if episode.success else f'NOT disentangled ({episode.message})'
        print(f'{episode.scene.name}: {method}: {outcome} after {episode.paths} path(s), '
              f'{len(episode.failures)} failure(s) learned; {summary["sim_time_s"]} s '
              f'simulated in {summary["wall_time_s"]} s ({summary["real_time_factor"]}x real '
              f'time), peak contact force {summary["peak_contact_force_n"]} N; fastest '
              f"command change {summary['command_speed_peak']:.2f} x a joint's velocity "
              f'limit (JTC), {summary["sent_speed_peak"]:.2f} x (after the driver\'s filter); '
              f'fastest point of the arm {summary["point_speed_peak_mps"]:.3f} m/s')
    if args.plot:
        arm = iiwa_arm()
        failures = [(np.array(f['x']), np.array(f['v'])) for f in episode.failures]
        outcome = 'disentangled' if episode.success else 'not disentangled'
        plot_scene_run(episode.scene, arm.fk(episode.configs[::2]).positions, failures,
                       arm.fk(episode.scene.goal[None]).positions[0], args.plot,
                       f'{episode.scene.name}: {method}: {outcome} after {episode.paths} '
                       f'path(s), {len(failures)} failure(s)')
        if not args.json:
            print(f'wrote {args.plot}')
    return 0


def cmd_bench_physics(args: argparse.Namespace) -> int:
    """Measure the physics mock: speed, free-motion tracking, a block."""
    from dataclasses import asdict

    from probdis_ros.bench import machine
    from probdis_ros.physics import measure
    from probdis_ros.run import MAX_VELOCITY_SCALING

    _positive(args.seconds, '--seconds')
    fastest = MAX_VELOCITY_SCALING
    figures = {'machine': machine(),
               'real_time_factor': measure.real_time_factor(args.scene, args.seconds),
               'free_tracking': [asdict(measure.free_tracking(v, args.scene))
                                 for v in (0.2, fastest)],
               'long_edge': {v: asdict(measure.long_edge(v)) for v in (0.2, 0.6, 0.7, 1.0)},
               'block': [asdict(measure.straight_block(args.scene, v))
                         for v in (0.2, fastest)]}
    if args.json:
        _print_json(figures)
        return 0
    rtf = figures['real_time_factor']
    print(f'physics mock on {figures["machine"]}, scene {args.scene}')
    print(f'real-time factor: arm alone {rtf["arm_alone"]:.0f}x, with JTC and the driver '
          f'filter {rtf["command_path"]:.0f}x (time step {rtf["timestep_s"] * 1e3:.0f} ms)')
    for t in figures['free_tracking']:
        print(f'free motion at velocity scaling {t["velocity_scaling"]}: L1 gap peak '
              f'{t["peak_gap"]:.3f} rad, {t["final_gap"]:.3f} rad when judged {t["verdict"]} '
              f'{t["settle_s"]:.2f} s after the planned end')
    edges = figures['long_edge'].items()
    errors = ', '.join(f'{e["jtc_error"]:.3f} rad at {v}' for v, e in edges)
    print(f"JTC's error on a long free edge (what its path tolerance checks), one joint's "
          f'peak by velocity scaling: {errors}')
    speeds = ', '.join(f'{e["speed_over_limit"]:.2f} at {v}' for v, e in edges)
    print(f"the same edge's fastest measured joint speed over its URDF limit (the driver's "
          f'command guard stops at 1; the planner takes at most {fastest}): {speeds}')
    for b, v in zip(figures['block'], (0.2, fastest)):
        contact = 'no contact' if b['contact_s'] is None else f'contact at {b["contact_s"]:.2f} s'
        detected = 'not detected' if b['detected_s'] is None else \
            f'detected at {b["detected_s"]:.2f} s'
        print(f'straight path into the obstacle at velocity scaling {v}: {contact}, '
              f'{detected} (planned end {b["planned_s"]:.2f} s); gap then '
              f'{b["gap_at_detection"]:.3f} rad, contact force '
              f'{b["force_at_detection_n"]:.0f} N (peak {b["peak_force_n"]:.0f} N); the flange '
              f'moved {b["flange_moved_m"] * 100:.1f} cm from contact to detection ({b["reason"]})'
              + ('' if b['onset_error_m'] is None else
                 f'; the onset is {b["onset_error_m"] * 100:.1f} cm from the contact'))
    return 0


def cmd_scene_check(args: argparse.Namespace) -> int:
    """Check physical scenes: entangled at the start, and a way out exists (exit 1 if not)."""
    import numpy as np
    from probdis_ros.physics import load_scene
    from probdis_ros.physics.oracle import CHECK_ITERATIONS, check_scene
    from probdis_ros.physics.scene import shipped_scenes

    iterations = CHECK_ITERATIONS if args.iterations is None else args.iterations
    _positive(iterations, '--iterations')
    _not_negative(args.clearance, '--clearance')
    groups = _family_groups(args, 20)
    names = args.scenes if groups is not None else args.scenes or shipped_scenes()
    drawn = [] if groups is None else [name for group in groups.values() for name in group]
    # a bad file is refused before any work; family worlds are drawn as their turn comes
    scenes = [load_scene(name) for name in names] + [None] * len(drawn)
    fit = 0
    for name, scene in zip(names + drawn, scenes):
        scene = scene or load_scene(name)
        # each scene's own stream, so that a scene checks the same alone as in a list
        check = check_scene(scene, np.random.default_rng(args.oracle_seed), iterations,
                            args.clearance)
        fit += check.ok
        way = check.way_out
        if args.json:
            _print_json({'scene': name, 'ok': check.ok, 'problems': check.problems,
                         'start_free': check.start_free, 'goal_free': check.goal_free,
                         'blocked_after_m': check.blocked_after_m,
                         'way_out': None if way is None else way.tolist(),
                         'seconds': round(check.seconds, 3)})
            sys.stdout.flush()         # a line per scene as it is checked: the progress
            continue
        if check.ok:
            length = float(np.linalg.norm(np.diff(way, axis=0), axis=1).sum())
            print(f'{name}: ok: the straight move is blocked {100 * check.blocked_after_m:.1f} '
                  f'cm from the start; a way out of {len(way) - 1} straight moves '
                  f'({length:.2f} rad of joint motion) found in {check.seconds:.1f} s',
                  flush=True)
        else:
            print(f'{name}: NOT FIT: {"; ".join(check.problems)}', flush=True)
    if not args.json:
        print(f'{fit} of {len(scenes)} scenes entangled and solvable')
    return 0 if fit == len(scenes) else 1


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan one path on a saved failure map and print it."""
    from probdis_ros.model import arm_for_setting, FailureMap
    from probdis_ros.model.path_cost import path_success_probability
    from probdis_ros.model.table import ROBOT_TABLE
    from probdis_ros.planning import Method, RRTSettings
    from probdis_ros.planning.prob_rrt import ROBOT_JOINT_MARGIN
    from probdis_ros.planning.seeds import PLANNER, stream
    from probdis_ros.run import goal_problem

    if args.plan_time is not None:
        _positive(args.plan_time, '--plan-time')
    _positive(args.delta, '--delta')
    _not_negative(args.length_weight, '--length-weight')
    _not_negative(args.seed, '--seed')
    method = Method.parse(args.method).checked_for_map_file('probdis plan')
    if method.name == 'epsilon':
        raise UsageError('epsilon does not plan on a map; use probabilistic, hard:Y or '
                         'informed')
    fmap = FailureMap.load(args.map)
    # probabilistic:C_FAIL plans with its C_FAIL, as sim does (not the one the map was saved with)
    fmap.c_fail = method.map_c_fail(fmap.c_fail)
    setting = {'point2': '2d', 'point3': '3d', 'pose3': '3d-orient'}[fmap.task_space.value]
    arm = arm_for_setting(setting)
    _not_negative(args.object_radius, '--object-radius')
    if setting != '2d' and not args.no_table:
        # the planner node's default: no plan takes the arm (or the object) through its table
        arm = arm.on_table(ROBOT_TABLE, args.object_radius)
    ends = []
    for name in ('start', 'goal'):
        config = _joint_values(getattr(args, name), f'--{name}')
        if len(config) != arm.n_joints:
            raise UsageError(f'--{name} needs {arm.n_joints} joint values for a '
                             f'{fmap.task_space.value} map, got {len(config)}')
        ends.append(config)
    # the iiwa keeps the planner node's margin from its limits (a via point on a limit ends
    # the driver's session); the 2-D simulator's arm, as sim, none
    settings = RRTSettings(iterations=args.iterations, delta=args.delta,
                           plan_time=args.plan_time or 0.0,
                           joint_margin=0.0 if setting == '2d' else ROBOT_JOINT_MARGIN)
    problem = goal_problem(arm, ends[1], settings.joint_margin)      # as the node refuses it
    if problem:
        raise UsageError(f'--goal {problem}')
    planner = method.planner(arm, settings, args.length_weight)
    plan = planner.plan(ends[0], ends[1], fmap, stream(args.seed, PLANNER))
    if plan is None:
        doc = {'path': None, 'cost': None, 'success_probability': 0.0, 'plan_time_s': None}
    else:
        success = path_success_probability(arm, fmap, plan.path, args.delta)
        doc = {'path': plan.path.tolist(), 'cost': plan.cost, 'success_probability': success,
               'plan_time_s': plan.plan_time_s}
    doc['arm'] = arm.name                   # a 2-D map plans for the simulator's planar arm
    if args.json:
        _print_json(doc)
        return 0 if plan is not None else 1
    if plan is None:
        print(f'{args.map}: {method}: no feasible path')
        return 1
    print(f'{args.map}: {len(fmap)} failures, the {arm.name} arm ({fmap.task_space.value} '
          f'map), {method}: {len(plan.path)} via points, cost '
          f'{plan.cost:.4f}, success probability {doc["success_probability"]:.3f}, planned '
          f'in {plan.plan_time_s:.3f} s')
    for q in plan.path:
        print(' '.join(f'{v: .5f}' for v in q))
    return 0


def cmd_node(args: argparse.Namespace) -> int:
    """Run the planner or the mock iiwa node; ROS arguments pass through."""
    if args.command == 'planner':
        from probdis_ros.ros.planner_node import main as node_main
    else:
        from probdis_ros.ros.mock_iiwa_node import main as node_main
    return node_main([sys.argv[0], *args.ros_args])


def cmd_service(args: argparse.Namespace) -> int:
    """Call a planner service; exit 1 on refusal, 3 on timeout."""
    from probdis_ros.ros.client import PlannerClient

    service = {'start': 'start', 'stop': 'stop', 'reset-map': 'reset_map',
               'confirm': 'confirm_path', 'decline': 'decline_path'}[args.command]
    _positive(args.timeout, '--timeout')      # NaN would wait forever
    with PlannerClient(args.planner) as client:
        try:
            ok, message = client.call(service, args.timeout)
        except TimeoutError as err:
            print(f'probdis {args.command}: {err}', file=sys.stderr)
            return 3
    print(message)
    return 0 if ok else 1


def cmd_param(args: argparse.Namespace) -> int:
    """Read, list or set the planner's parameters; exit 1 on refusal, 3 on timeout."""
    from probdis_ros.ros.client import PlannerClient
    import yaml

    _positive(args.timeout, '--timeout')      # NaN would wait forever
    with PlannerClient(args.planner) as client:
        try:
            if args.action == 'list':
                print('\n'.join(client.parameter_names(args.timeout)))
                return 0
            if args.action == 'get':
                value = client.parameters([args.name], args.timeout)[args.name]
                print(json.dumps(value))
                return 0
            try:
                value = yaml.safe_load(args.value)      # as ros2 param set reads it
            except yaml.YAMLError as err:
                raise UsageError(f'{args.value!r} is not a value ({err.problem})') from None
            ok, reason = client.set_parameter(args.name, value, args.timeout)
        except KeyError as err:
            print(f'probdis param: {err.args[0]}', file=sys.stderr)
            return 1
        except TimeoutError as err:
            print(f'probdis param: {err}', file=sys.stderr)
            return 3
    print(f'set {args.name}' if ok else f'refused: {reason}')
    return 0 if ok else 1


def cmd_status(args: argparse.Namespace) -> int:
    """Print the planner's latest status (JSON)."""
    from probdis_ros.ros.client import PlannerClient

    _positive(args.timeout, '--timeout')      # NaN would wait forever
    with PlannerClient(args.planner) as client:
        try:
            doc = client.status(args.timeout)
        except TimeoutError as err:
            print(f'probdis status: {err}', file=sys.stderr)
            return 3
    _print_doc(doc, args.json)
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """Disentangle against the mock iiwa: two processes over DDS on localhost."""
    from probdis_ros.ros.demo import DEFAULT_SCENE, run_demo

    world = args.scenario or (DEFAULT_SCENE if args.engine == 'physics' else 'demo_iiwa')
    if args.plot and args.engine != 'physics':
        raise UsageError('--plot draws a physics scene; use --engine physics')
    _positive(args.timeout, '--timeout')      # before the nodes start
    if args.plot:
        _check_output(args.plot, '--plot')
    if not abs(args.arm_clock_offset) <= 1e6:
        raise UsageError(f'--arm-clock-offset must be within +-1e6 s, got '
                         f'{args.arm_clock_offset:g}')
    limit = _cartesian_speed(args)
    result = run_demo(world, args.timeout, quiet=args.json, engine=args.engine,
                      sim_time=args.sim_time, jtc_start=args.jtc_start,
                      extra_mock_args=('-p', f'clock_offset:={args.arm_clock_offset!r}'),
                      extra_planner_args=('-p', f'cartesian_speed_limit:={float(limit)!r}'),
                      confirm=args.confirm)
    summary = {k: result[k] for k in ('success', 'paths', 'failures', 'replan_latency_s',
                                      'bag')}
    if args.json:
        _print_json(summary)
    else:
        outcome = 'disentangled' if result['success'] else 'NOT disentangled'
        latency = result['replan_latency_s']
        print(f'demo: {outcome} after {result["paths"]} path(s), {result["failures"]} '
              f'failure(s); replan latency median {latency["median"]:.3f} s, '
              f'max {latency["max"]:.3f} s')
        if result['bag']:
            print(f'recorded to {result["bag"]} (probdis replay {result["bag"]})')
    if args.plot and result['bag']:
        out = _plot_bag(world, result['bag'], args.plot)
        if not args.json:
            print(f'wrote {out}')
    return 0 if result['success'] else 1


def _plot_bag(scene_name: str, bag: str, out: str) -> Path:
    """Draw a physics scene with the flange path and the blocks a recorded run shows."""
    import numpy as np
    from probdis_ros.model import iiwa_arm
    from probdis_ros.physics import load_scene
    from probdis_ros.physics.picture import plot_scene_run
    from probdis_ros.ros.replay import replay

    scene = load_scene(scene_name)
    result = replay(Path(bag))
    arm = iiwa_arm()
    flange = arm.fk(np.array(result.configs)).positions
    failures = list(zip(result.fmap.points, result.fmap.directions))
    outcome = 'disentangled' if result.success else 'not disentangled'
    return plot_scene_run(scene, flange, failures, arm.fk(scene.goal[None]).positions[0], out,
                          f'{scene.name}: {outcome} after {result.paths} path(s), '
                          f'{len(result.blocks)} block(s)')


def cmd_replay(args: argparse.Namespace) -> int:
    """Rerun the blocked-motion detector on a bag; rebuild the failure map."""
    if args.calibrate:
        clash = [flag for flag, given in (('--motion-delay', args.motion_delay is not None),
                                          ('--save-map', args.save_map),
                                          ('--publish', args.publish)) if given]
        if clash:
            raise UsageError(f'--calibrate tries every motion_delay itself: not with '
                             f'{" or ".join(clash)}')
    if args.publish:
        return _publish_bag(args)
    if args.rate is not None or args.wait is not None:
        raise UsageError('--rate and --wait go with --publish')
    overrides = _replay_overrides(args)
    for flag, out in (('--save-map', args.save_map), ('--plot', args.plot)):
        if out:
            _check_output(out, flag)
    if args.calibrate:
        return _calibrate_bag(args, overrides)
    with _map_held(args.save_map):
        return _replay_bag(args, overrides)


def _settings_refused(overrides: dict[str, float], err: Exception) -> UsageError:
    """Return the usage error of detector flags the detector's other settings refuse."""
    given = ' '.join(f'--{k.replace("_", "-")} {v:g}' for k, v in overrides.items())
    return UsageError(f'{given}: {err}')


def _calibrate_bag(args: argparse.Namespace, overrides: dict[str, float]) -> int:
    """Replay a free move at every motion delay; print (and draw) the one that fits best."""
    import time

    from probdis_ros.experiments.sweep import progress_line
    from probdis_ros.ros.replay import calibrate, ReplayError, SettingsError

    t0 = time.monotonic()
    progress = (lambda done, total: progress_line(done, total, time.monotonic() - t0,
                                                  'motion delays')) \
        if sys.stderr.isatty() else None
    try:
        fit = calibrate(args.bag, args.joint_states, args.trajectory, overrides, progress=progress)
    except SettingsError as err:
        raise _settings_refused(overrides, err) from None
    except ReplayError as err:
        raise UsageError(str(err)) from None
    if args.plot:
        from probdis_ros.plots import plot_calibration

        plot_calibration(fit, args.plot)
    if args.json:
        _print_json(fit.summary())
        return 0
    low, high = fit.equal
    equal = f' (the middle of {low:g}-{high:g} s, all as good)' if high > low else ''
    print(f'{args.bag}: motion_delay {fit.best:g} s fits this arm best{equal}: peak gap '
          f'{fit.best_gap:.3f} rad ({fit.peak_gaps[0]:.3f} rad at {fit.delays[0]:g} s); at rest '
          f'after a command {fit.rest_gap:.3f} rad (d_dist {fit.d_dist:g})')
    print('  motion_delay [s]  peak gap [rad]  blocks')
    for delay, gap, blocks in zip(fit.delays, fit.peak_gaps, fit.blocks):
        mark = '  <- best' if delay == fit.best else '  <- as good' if low <= delay <= high \
            else ''
        print(f'  {delay:16.2f}  {gap:14.3f}  {blocks:6d}{mark}')
    if fit.rest_gap > 0.5 * fit.d_dist:
        print(f'  note: the arm rests {fit.rest_gap:.3f} rad off its command, more than half of '
              f'd_dist {fit.d_dist:g}: a free path ending above d_dist reads as blocked; raise '
              f'd_dist, or mend the load data (load_mass, load_com)')
    if high == fit.delays[-1]:
        print(f'  note: the least gap lies at the end of the range: the arm lags its command '
              f'by {high:g} s or more, or the bag is not of a free move')
    print(f'set it: probdis param set motion_delay {fit.best:g} (or motion_delay in the '
          f"planner's parameter file)")
    if args.plot:
        print(f'wrote {args.plot}')
    return 0


def _replay_bag(args: argparse.Namespace, overrides: dict[str, float]) -> int:
    """Replay the bag, save and draw what it asks for, and print the outcome."""
    from probdis_ros.ros.replay import replay, ReplayError, SettingsError

    status = 0
    try:
        result = replay(args.bag, args.joint_states, args.trajectory, overrides=overrides)
    except SettingsError as err:
        raise _settings_refused(overrides, err) from None
    except ReplayError as err:
        if err.partial is None:
            raise UsageError(str(err)) from None
        # what came before the damage is shown, but not saved over a map file
        kept = ' (--save-map not written: the bag is damaged)' if args.save_map else ''
        print(f'probdis replay: error: {err}{kept}', file=sys.stderr)
        result, status = err.partial, 1
    if args.save_map and status == 0:
        result.fmap.save(args.save_map)
    if args.plot:
        from probdis_ros.plots import plot_replay

        plot_replay(result, args.plot, result.settings.d_dist)
    if args.json:
        _print_json(result.summary())
        return status
    print(f'{args.bag}: {result.runs} run(s), {result.paths} path(s), {len(result.blocks)} '
          f'block(s), {"disentangled" if result.success else "not disentangled"}; peak gap '
          f'{result.peak_gap:.3f} rad (motion_delay {result.settings.motion_delay:g} s), at '
          f'rest after a command {result.rest_gap:.3f} rad (d_dist {result.settings.d_dist:g}); '
          f'fastest point of the arm {result.peak_point_speed:.3f} m/s' + (
              '' if result.torque_peak is None else
              f'; peak external torque {result.torque_peak.max():.1f} Nm at '
              f'A{int(result.torque_peak.argmax()) + 1}'))
    for block in result.blocks:
        x = ', '.join(f'{v:.3f}' for v in block.x)
        during = 'a retreat' if block.retreat else 'a path'
        print(f'  block at {block.t:8.3f} s, flange at ({x}) m, during {during}')
    for problem in result.problems[:10]:
        print(f'  note: {problem}')
    if args.save_map and status == 0:
        print(f'wrote {args.save_map} ({len(result.fmap)} failures)')
    if args.plot:
        print(f'wrote {args.plot}')
    return status


@contextlib.contextmanager
def _map_held(path: str | None) -> Iterator[None]:
    """
    Hold a map file's lock while a map is made to be saved there (None: nothing to hold).

    A running planner keeps its map in memory and holds the file's lock: written over, the
    file lost the replayed failures at the planner's next write, or the planner's at once.
    """
    if not path:
        yield
        return
    from probdis_ros.model.failure_map import lock_map, MapInUseError

    try:
        lock = lock_map(path, {'by': 'probdis replay --save-map', 'pid': os.getpid()})
    except MapInUseError as err:
        raise UsageError(f'--save-map: {err}: a planner keeps this map; stop it first or '
                         f'save elsewhere') from None
    except OSError as err:
        raise UsageError(f'--save-map {path}: {err.strerror or err}') from None
    try:
        yield
    finally:
        os.close(lock)


def _replay_overrides(args: argparse.Namespace) -> dict[str, float]:
    """Return the detector settings of --d-dist and --motion-delay, checked before any reading."""
    overrides = {}
    if args.d_dist is not None:
        overrides['d_dist'] = _positive(args.d_dist, '--d-dist')
    if args.motion_delay is not None:
        overrides['motion_delay'] = _not_negative(args.motion_delay, '--motion-delay')
    return overrides


def _publish_bag(args: argparse.Namespace) -> int:
    """``probdis replay BAG --publish``: the bag's messages back on their topics."""
    from probdis_ros.ros.bag_player import play
    from probdis_ros.ros.bag_source import BagError

    rate = _positive(1.0 if args.rate is None else args.rate, '--rate')
    wait = _not_negative(2.0 if args.wait is None else args.wait, '--wait')
    try:
        result = play(args.bag, rate, wait, progress=sys.stderr.isatty())
    except BagError as err:
        raise UsageError(str(err)) from None
    if args.json:
        _print_json({'published': result.published, 'skipped': result.skipped,
                     'seconds': round(result.seconds, 3)})
    else:
        print(f'{args.bag}: published {result.published} message(s) in '
              f'{result.seconds:.1f} s' + (' (interrupted)' if result.interrupted else ''))
    if result.damage:
        print(f'probdis replay: error: {args.bag}: {result.damage}', file=sys.stderr)
        return 1
    return 130 if result.interrupted else 0


def _jtc_start_argument(parser: argparse.ArgumentParser, where: str = '') -> None:
    from probdis_ros.motion.jtc import DEFAULT_JTC_START, JTC_STARTS

    parser.add_argument('--jtc-start', choices=JTC_STARTS, default=DEFAULT_JTC_START,
                        help="where the mock's joint_trajectory_controller starts each new "
                        'command, as the planner models it: the measured state, or its last '
                        f'command (interpolate_from_desired_state: true){where} (default: '
                        f'{DEFAULT_JTC_START})')


def _cartesian_speed_argument(parser: argparse.ArgumentParser, where: str = '') -> None:
    parser.add_argument('--cartesian-speed-limit', type=float, default=0.0, metavar='M/S',
                        help='the fastest any point of the arm (its collision shapes, the '
                        "object's ball, the flange) may move on a path or retreat, as the "
                        f"planner's cartesian_speed_limit{where} (default 0: the joint limits "
                        'only)')


def _cartesian_speed(args: argparse.Namespace) -> float:
    if not 0.0 <= args.cartesian_speed_limit <= 10.0:
        raise UsageError(f'--cartesian-speed-limit must be in [0, 10] m/s, got '
                         f'{args.cartesian_speed_limit:g}')
    return args.cartesian_speed_limit


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be at least 1, got {value}')
    return value


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser of every subcommand."""
    parser = argparse.ArgumentParser(
        prog='probdis', description='Probabilistic disentangling for the KUKA LBR iiwa.')
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')

    info = sub.add_parser('info', help='version and where config/ and urdf/ were found')
    info.add_argument('--json', action='store_true', help='print one JSON object')
    info.set_defaults(handler=cmd_info)

    fk = sub.add_parser('fk', help='forward kinematics of one configuration')
    fk.add_argument('joints', nargs='+', type=float, metavar='Q', help='joint positions [rad]')
    fk.add_argument('--setting', choices=SETTINGS, default='3d-orient',
                    help='arm and task space (default: iiwa with orientation)')
    fk.add_argument('--json', action='store_true', help='print one JSON object')
    fk.set_defaults(handler=cmd_fk)

    bench = sub.add_parser('bench', help='measured benchmarks')
    bench_sub = bench.add_subparsers(dest='bench', required=True, metavar='BENCH')
    bfk = bench_sub.add_parser('fk', help='batched forward kinematics, configurations/s')
    bfk.add_argument('--setting', choices=SETTINGS, default='3d-orient')
    bfk.add_argument('--configs', type=_positive_int, default=200_000)
    bfk.add_argument('--repeats', type=_positive_int, default=5)
    bfk.add_argument('--seed', type=int, default=0)
    bfk.add_argument('--json', action='store_true', help='print {"configs_per_s": float}')
    bfk.set_defaults(handler=cmd_bench_fk)

    from probdis_ros.bench import add_plan_command, add_quality_command

    add_plan_command(bench_sub)
    add_quality_command(bench_sub)
    bphys = bench_sub.add_parser('physics', help='the physics mock: real-time factor, '
                                 'free-motion tracking gap, a block (contact force, delay)')
    bphys.add_argument('--scene', default='demo_hook', help='scene file or name')
    bphys.add_argument('--seconds', type=float, default=5.0,
                       help='simulated seconds timed for the real-time factor')
    bphys.add_argument('--json', action='store_true', help='print one JSON object')
    bphys.set_defaults(handler=cmd_bench_physics)

    from probdis_ros.model.path_cost import DEFAULT_DELTA, DEFAULT_LENGTH_WEIGHT

    plan = sub.add_parser('plan', help='plan one path on a saved failure map')
    plan.add_argument('--map', required=True, help='a failure map file (README format)')
    plan.add_argument('--start', required=True, nargs='+', type=float, metavar='Q',
                      help='start joint positions [rad]')
    plan.add_argument('--goal', required=True, nargs='+', type=float, metavar='Q',
                      help='goal joint positions [rad]')
    budget = plan.add_mutually_exclusive_group()
    budget.add_argument('--plan-time', type=float, metavar='S',
                        help='anytime: keep improving the path for S seconds (rounds of K)')
    budget.add_argument('--iterations', type=_positive_int, default=100,
                        help='K, iterations per tree (default 100, the paper)')
    plan.add_argument('--seed', type=int, default=0, help='seed of the planner')
    plan.add_argument('--delta', type=float, default=DEFAULT_DELTA, help='Delta [rad]')
    plan.add_argument('--length-weight', type=float, default=DEFAULT_LENGTH_WEIGHT,
                      help='lambda: weight of joint-space length')
    plan.add_argument('--method', default='probabilistic',
                      help='a method string: probabilistic[:C_FAIL] (C_FAIL replaces the '
                      "map's), hard:Y[:C_HARD] or informed[:IDEAS] (default probabilistic)")
    plan.add_argument('--json', action='store_true', help='print {"path", "cost", '
                      '"success_probability", "plan_time_s"}')
    plan.add_argument('--no-table', action='store_true', help='iiwa maps: plan as if the arm '
                      "stood on no table (by default no path takes it below the robot's table "
                      'top + 5 cm, and a goal below it is refused, as in the planner node)')
    plan.add_argument('--object-radius', type=float, default=0.0, metavar='R',
                      help='radius [m] of a ball about the flange that holds the grasped '
                      'object, kept above the table too (default 0, as the planner node)')
    plan.set_defaults(handler=cmd_plan)

    from probdis_ros.planning import DEFAULT_EPSILON, DEFAULT_THRESHOLD, METHODS

    sim = sub.add_parser('sim', help='one simulated disentangling episode')
    sim.add_argument('--setting', choices=SETTINGS, help='2d, 3d or 3d-orient (default 2d)')
    sim.add_argument('--obstacles', type=_positive_int, default=10,
                     help='hidden obstacles of a random world')
    sim.add_argument('--method', default='informed',
                     help=f'{", ".join(METHODS)}, or a method string: probabilistic[:C_FAIL], '
                     'hard:Y[:C_HARD], epsilon:X, informed[:IDEAS] (default informed)')
    sim.add_argument('--threshold', type=float, default=DEFAULT_THRESHOLD,
                     help='Y of the hard method')
    sim.add_argument('--epsilon', type=float, default=DEFAULT_EPSILON,
                     help='X of the epsilon method')
    sim.add_argument('--seed', type=int, help='seed of the random world and the planner '
                     '(independent streams of it); with --scenario of the planner only '
                     '(default 0)')
    sim.add_argument('--scenario', help='a scenario YAML file, or the name of one in '
                     'config/scenarios/')
    sim.add_argument('--family', help='an entanglement family (open_box, closed_box, '
                     'plate_hole, hook_bar, clutter): the world of --seed, as the family '
                     'sweeps draw it (README "Entanglement families"); with --engine physics '
                     'as a physical scene')
    sim.add_argument('--max-paths', type=_positive_int, default=20, help='N_ITER')
    sim.add_argument('--c-fail', type=float, default=DEFAULT_C_FAIL,
                     help='C_FAIL of the failure map [1/m^2] (probabilistic:C overrides it)')
    sim.add_argument('--json', action='store_true', help='print one JSON object')
    sim.add_argument('--plot', metavar='OUT.png', help='draw the episode (2-D, or the physics '
                     'scene with the flange path and the failures)')
    sim.add_argument('--engine', choices=('kinematic', 'physics'), default='kinematic',
                     help="the simulated arm: the kinematic one of the paper's settings, or "
                     'MuJoCo in joint impedance through JTC (with --scene or --family)')
    _jtc_start_argument(sim, ' (with --engine physics)')
    _cartesian_speed_argument(sim, ', with --engine physics')
    sim.add_argument('--scene', help='with --engine physics: a scene file, or the name of one '
                     'in config/scenes/ (default demo_hook)')
    sim.add_argument('--no-table', action='store_true', help='kinematic: no table under the '
                     "arm (the family worlds and the robot scenarios have one; the JSON's "
                     'lowest_m shows how low the arm went)')
    sim.set_defaults(handler=cmd_sim)

    for name, text, example in (
            ('planner', 'run the planner node (ROS arguments pass through)',
             '--ros-args --params-file config/planner.yaml -p "goal:=[...]"'),
            ('mock', 'run the mock iiwa node (ROS arguments pass through)',
             '--ros-args -p scene:=robot_maze')):
        node = sub.add_parser(name, help=text)
        node.add_argument('ros_args', nargs='*', metavar='--ros-args ...',
                          help=f'ROS arguments, e.g. {example}')
        node.set_defaults(handler=cmd_node)
    for name, text in (('start', 'start a disentangling (~/start)'),
                       ('stop', 'stop: the arm decelerates to rest (~/stop)'),
                       ('reset-map', 'clear the failure map (~/reset_map)'),
                       ('confirm', 'send the planned path that awaits confirmation '
                        '(confirm_paths; ~/confirm_path)'),
                       ('decline', 'drop the planned path that awaits confirmation and plan '
                        'another (~/decline_path)'),
                       ('status', "print the planner's status")):
        call = sub.add_parser(name, help=text)
        call.add_argument('--planner', default='/probdis_planner', help='planner node name')
        call.add_argument('--timeout', type=float, default=10.0, help='seconds to wait')
        if name == 'status':
            call.add_argument('--json', action='store_true', help='print one JSON object')
            call.set_defaults(handler=cmd_status)
        else:
            call.set_defaults(handler=cmd_service)
    param = sub.add_parser('param', help="read or set the planner's parameters (what ros2 "
                           'param get/set/list do)')
    actions = param.add_subparsers(dest='action', metavar='ACTION', required=True)
    for action, text in (('get', 'print one parameter (JSON)'), ('list', 'print their names'),
                         ('set', 'set one parameter: the planner refuses a bad value with '
                          'the reason (exit 1)')):
        sub_action = actions.add_parser(action, help=text)
        if action != 'list':
            sub_action.add_argument('name', help='a parameter, e.g. goal or method')
        if action == 'set':
            sub_action.add_argument('value', help='YAML, e.g. "[0.3, 0.2, 0, -1.1, 0, 0.6, '
                                    '0]" or informed')
        sub_action.add_argument('--planner', default='/probdis_planner',
                                help='planner node name')
        sub_action.add_argument('--timeout', type=float, default=10.0,
                                help='seconds to wait')
        sub_action.set_defaults(handler=cmd_param)
    demo = sub.add_parser('demo', help='disentangle against the mock iiwa (two processes)')
    demo.add_argument('--scenario', help='physics scene (config/scenes/; default demo_hook) '
                      'or, with --engine kinematic, scenario (config/scenarios/; default '
                      'demo_iiwa): a file or a name')
    demo.add_argument('--engine', choices=('physics', 'kinematic'), default='physics',
                      help='the mock arm: MuJoCo in joint impedance, or the idealised one')
    demo.add_argument('--sim-time', action='store_true',
                      help='run the mock on simulated time (/clock), at most at the wall '
                      "clock's pace")
    demo.add_argument('--plot', metavar='OUT.png',
                      help='draw the scene with the flange path and the blocks of the run')
    demo.add_argument('--timeout', type=float, default=300.0, help='seconds for the run')
    demo.add_argument('--arm-clock-offset', type=float, default=0.0, metavar='S',
                      help="the mock arm's clock less this machine's [s]: a driver on a "
                      'computer whose clock is not synchronised (default 0)')
    _jtc_start_argument(demo)
    _cartesian_speed_argument(demo)
    demo.add_argument('--confirm', action='store_true',
                      help="the planner's confirm_paths, as in a first session in T1: each "
                      'planned path waits for your answer on the terminal (Enter: send it, '
                      'n: plan another, s: stop)')
    demo.add_argument('--json', action='store_true',
                      help='print {"success", "paths", "failures", "replan_latency_s", '
                      '"bag"}')
    demo.set_defaults(handler=cmd_demo)

    rp = sub.add_parser('replay', help='rerun the blocked-motion detector on a rosbag2 bag')
    rp.add_argument('bag', help='a rosbag2 bag: folder, .mcap or .db3 file')
    rp.add_argument('--joint-states', default=JOINT_STATES_TOPIC, help='joint-state topic')
    rp.add_argument('--trajectory', default=TRAJECTORY_TOPIC,
                    help='commanded trajectory topic')
    rp.add_argument('--d-dist', type=float, help='d_dist of the detector [rad] (default: the '
                    'detector settings the recording planner ran with, or the defaults)')
    rp.add_argument('--motion-delay', type=float, help='how far the arm lags its command [s] '
                    '(default: as the recording planner ran)')
    rp.add_argument('--json', action='store_true',
                    help='print {"paths", "blocks": [{"t", "x", "retreat"}], "failures", '
                    '"success", "peak_gap_rad", "peak_point_speed_mps", '
                    '"peak_external_torque_nm" (per joint, efforts less gravity and '
                    'dynamics; null without efforts)}')
    rp.add_argument('--plot', metavar='OUT.png', help='joint gaps and the flange path (with '
                    '--calibrate: the peak gap at each motion delay)')
    rp.add_argument('--calibrate', action='store_true',
                    help='on a bag of a free move: replay it at every motion_delay from 0 to '
                    '0.4 s and print the one with the least peak gap, the lag of the arm '
                    '(--json: {"motion_delay_s", "peak_gap_rad", "equally_good_s", '
                    '"rest_gap_rad", "d_dist_rad", "tried": [{"motion_delay_s", "peak_gap_rad", '
                    '"blocks"}]})')
    rp.add_argument('--save-map', metavar='FILE', help='write the rebuilt failure map')
    rp.add_argument('--publish', action='store_true',
                    help='republish the messages on their topics with their recorded timing')
    rp.add_argument('--rate', type=float,
                    help='with --publish: speed factor of the recorded timing (default 1)')
    rp.add_argument('--wait', type=float,
                    help='with --publish: seconds to wait for subscribers before starting '
                    '(default 2)')
    rp.set_defaults(handler=cmd_replay)

    fmap = sub.add_parser('map', help='failure maps')
    map_sub = fmap.add_subparsers(dest='map_command', required=True, metavar='ACTION')
    plot = map_sub.add_parser('plot', help='draw a 2-D probability map as a PNG')
    plot.add_argument('--map', help='a 2-D failure map file (default: an example map)')
    plot.add_argument('--out', default='failure_map.png', help='PNG to write')
    plot.add_argument('--c-fail', type=float, default=DEFAULT_C_FAIL,
                      help='C_FAIL of the example map [1/m^2]')
    plot.add_argument('--extent', type=float, nargs=4, metavar=('X0', 'X1', 'Y0', 'Y1'))
    plot.set_defaults(handler=cmd_map_plot)

    scene = sub.add_parser('scene', help='physical scenes (config/scenes/, your files)')
    scene_sub = scene.add_subparsers(dest='scene_command', required=True, metavar='ACTION')
    check = scene_sub.add_parser(
        'check', help='is a scene fit to measure a method: start and goal free, the '
        'straight move blocked, a way out found by a planner that sees the scene (exit '
        'status 1 if any is not)')
    check.add_argument('scenes', nargs='*', metavar='SCENE', help='scene files or names '
                       '(config/scenes/, or FAMILY-seedS; default: every shipped scene)')
    check.add_argument('--family', help='comma-separated entanglement families (or all): '
                       'their worlds of seeds SEED..SEED+WORLDS-1 as physical scenes too')
    check.add_argument('--worlds', type=int, help='with --family: worlds per family (20)')
    check.add_argument('--seed', type=int, help='with --family: the first world seed (0)')
    check.add_argument('--iterations', type=int,
                       help='RRT-Connect iterations per attempt, three attempts (10,000)')
    check.add_argument('--clearance', type=float, default=0.0,
                       help='[m] the way out keeps this far from the scene')
    check.add_argument('--oracle-seed', type=int, default=0, help='seed of the planner')
    check.add_argument('--json', action='store_true', help='one JSON object per scene')
    check.set_defaults(handler=cmd_scene_check)

    experiment = sub.add_parser('experiment', help="the paper's evaluation: sweeps, report")
    exp_sub = experiment.add_subparsers(dest='experiment_command', required=True,
                                        metavar='ACTION')
    sweep = exp_sub.add_parser('sweep', help='run simulated episodes on Dask, resumably')
    sweep.add_argument('--setting', help='comma-separated settings (2d, 3d, 3d-orient; '
                       'default: all three)')
    sweep.add_argument('--obstacles', help='comma-separated counts (default: 1,10,30,50)')
    sweep.add_argument('--family', help='comma-separated entanglement families instead of '
                       'the settings (open_box, closed_box, plate_hole, hook_bar, clutter; '
                       'all): world w is the family world of seed SEED + w')
    sweep.add_argument('--methods',
                       default='probabilistic,hard:0.01,hard:0.02,epsilon:0.2,epsilon:0.4',
                       help=METHODS_HELP)
    sweep.add_argument('--worlds', type=int, default=100,
                       help='worlds per obstacle count or family')
    sweep.add_argument('--max-paths', type=int, default=20, help='N_ITER of each episode')
    sweep.add_argument('--iterations', type=int, help='K of the RRT planners (default: the '
                       "paper's 100; an ablation, kept in each record)")
    sweep.add_argument('--plan-time', type=float, help='anytime budget per plan [s]: more '
                       'rounds of K while it lasts (default: one round; wall-clock, so not '
                       'reproducible across machines)')
    sweep.add_argument('--seed', type=int, default=0, help='seed of the sweep (its worlds; '
                       'with --family the first world seed)')
    sweep.add_argument('--out', required=True, help='directory of episodes.jsonl')
    sweep.add_argument('--scheduler', help='address of a running Dask scheduler '
                       '(default: a LocalCluster on this machine)')
    sweep.add_argument('--workers', type=int, help='LocalCluster worker processes '
                       '(default: one per core)')
    sweep.set_defaults(handler=cmd_experiment_sweep)
    report = exp_sub.add_parser('report', help='success curves, CIs, figures and tables')
    report.add_argument('dir', help='the --out directory of a sweep')
    report.add_argument('--with', dest='others', action='append', metavar='DIR',
                        help="another sweep's directory: its methods on the same worlds, "
                        "compared world by world with the paper's (repeatable; the report "
                        'is written into the first directory)')
    report.set_defaults(handler=cmd_experiment_report)
    bound = exp_sub.add_parser('bound', help='plate_hole: bounds on what a search that feels '
                               'blocks could do within n paths, a search that knows the box, '
                               'and the methods of sweeps beside them')
    bound.add_argument('--worlds', type=int, default=100, help='plate_hole worlds (100)')
    bound.add_argument('--seed', type=int, default=0, help='the first world seed (0)')
    bound.add_argument('--max-paths', type=int, default=20, help='paths per episode (20)')
    bound.add_argument('--episodes', action='append', metavar='DIR',
                       help="a sweep's directory: its methods' plate_hole episodes on these "
                       'worlds beside the bounds (repeatable)')
    bound.add_argument('--out', help='directory for hole_bound.jsonl (per world), '
                       'hole_bound.json and hole_bound.png')
    bound.add_argument('--json', action='store_true', help='print the curves as JSON')
    bound.set_defaults(handler=cmd_experiment_bound)
    robot = exp_sub.add_parser('robot', help='the robot scenarios through the ROS nodes '
                               "against the mock iiwa, like the paper's Table I")
    robot.add_argument('--runs', type=int, help='runs per scenario and method (run r uses '
                       'planner seed r; default 10, with --family 1 per world)')
    robot.add_argument('--scenarios', help='comma-separated scene files or names '
                       '(config/scenes/; config/scenarios/ with --engine kinematic; default '
                       'robot_waste,robot_maze,robot_bunny)')
    robot.add_argument('--family', help='comma-separated entanglement families (open_box, '
                       'closed_box, plate_hole, hook_bar, clutter; all) instead of '
                       '--scenarios: their worlds of seeds SEED..SEED+WORLDS-1 as physical '
                       'scenes')
    robot.add_argument('--worlds', type=int, help='with --family: worlds per family (5)')
    robot.add_argument('--seed', type=int, help='with --family: the first world seed (0)')
    robot.add_argument('--engine', choices=('physics', 'kinematic'), default='physics',
                       help='the mock arm: MuJoCo in joint impedance, or the idealised one')
    robot.add_argument('--sim-time', action=argparse.BooleanOptionalAction, default=True,
                       help='run the mock on simulated time (/clock), at most '
                       '--real-time-factor times the wall clock')
    robot.add_argument('--real-time-factor', type=float, default=DEFAULT_REAL_TIME_FACTOR,
                       help='with --sim-time: speed over the wall clock (at most); 0: as fast '
                       'as the mock can (commands may then be taken late)')
    robot.add_argument('--methods', default='epsilon:0.2,hard:0.01,probabilistic,informed',
                       help=METHODS_HELP)
    robot.add_argument('--out', default='out/robot', help='directory of robot_runs.jsonl '
                       'and the bags; runs already there are skipped')
    robot.add_argument('--velocity-scaling', type=float, default=0.2,
                       help='of the planner (0.2, its default on the real arm; at most 0.7)')
    robot.add_argument('--timeout', type=float, default=600.0, help='seconds per run')
    robot.add_argument('--offline', action='store_true',
                       help="run the physics scenes without the nodes (the planner node's "
                       'run against JTC and MuJoCo): deterministic and blind to the load')
    robot.add_argument('--detection', action='append', metavar='NAME=VALUE',
                       help='a detector threshold for every run, e.g. gap_ceiling=0 '
                       '(repeatable; README "Parameters")')
    robot.add_argument('--fault', action='append', metavar='NAME=VALUE',
                       help="a fault of the mock in every run, by its node parameter's name: "
                       'noise [rad], effort_noise [Nm], latency [s], command_latency [s], '
                       "speed_monitor [m/s], collision_torque [Nm: KUKA's collision "
                       'detection], object_mass_error [kg], '
                       'armature [kg m^2], grasp_stiffness [Nm/rad], joint_friction [Nm]; '
                       'or the robot '
                       "application's joint impedance: stiffness [Nm/rad], damping_ratio "
                       '(repeatable; README '
                       '"Parameters")')
    robot.add_argument('--restarts', type=int, default=0, metavar='N',
                       help='with --offline: when the driver stops the arm (its command '
                       "guard, KUKA's speed monitoring) or its guard holds it as the run ends "
                       '(--guard-holds), restart it and start the planner '
                       'again, as an operator would, at most N times per run (its map kept; '
                       'all starts together plan at most 20 paths; default 0)')
    robot.add_argument('--guard-holds', action='store_true',
                       help="the mock driver's command guard sends the measured position in "
                       'place of a command it refuses and runs on, as lbr releases that log '
                       '"Overriding invalid command to neutral command." do (default: it '
                       'stops the driver)')
    robot.add_argument('--against', metavar='DIR', help='compare with the same runs in '
                       "another experiment's DIR (another setting, fault or commit): paired "
                       'by scene, method and run, with a bootstrap interval')
    _jtc_start_argument(robot)
    _cartesian_speed_argument(robot)
    robot.add_argument('--json', action='store_true', help='print every run as JSON')
    robot.set_defaults(handler=cmd_experiment_robot)
    return parser


def _command_name(args: argparse.Namespace) -> str:
    """Return the subcommand as typed (``experiment sweep``), to head its error lines."""
    words = [args.command] + [getattr(args, name) for name in
                              ('experiment_command', 'map_command', 'scene_command',
                               'bench')
                              if getattr(args, name, None)]
    return ' '.join(words)


def _describe(err: Exception) -> str:
    """Return an error as one line: an OSError as its file and reason, without ``[Errno]``."""
    if isinstance(err, OSError) and err.filename is not None:
        # of a rename, the target (a temporary file's name would tell the user nothing)
        name = err.filename if err.filename2 is None else err.filename2
        return f'{name}: {err.strerror or err}'
    return str(err)


def _run(argv: list[str] | None) -> int:
    """Parse the arguments and run the subcommand; errors as one line, exit status 2."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] in ('planner', 'mock') and not {'-h', '--help'} & set(argv[1:2]):
        # everything after the command belongs to ROS (argparse would take --ros-args)
        args = argparse.Namespace(command=argv[0], ros_args=argv[1:], handler=cmd_node)
    else:
        args = parser.parse_args(argv)
    handler: Callable[[argparse.Namespace], int] = args.handler
    from probdis_ros.model import FailureMapError
    from probdis_ros.sim.worlds import ScenarioError

    try:
        return handler(args)
    except BrokenPipeError:
        raise                 # the reader left: main() ends quietly
    except (UsageError, FailureMapError, ScenarioError, OSError, ValueError,
            RuntimeError) as err:
        print(f'probdis {_command_name(args)}: error: {_describe(err)}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('probdis: interrupted', file=sys.stderr)
        return 130


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit status (1, quietly, when stdout's reader left)."""
    try:
        try:
            return _run(argv)
        finally:
            sys.stdout.flush()     # here, not at exit, where a closed pipe cannot be caught
    except BrokenPipeError:
        # `probdis plan ... | head`: what is still buffered goes nowhere (Python docs, SIGPIPE)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


if __name__ == '__main__':
    sys.exit(main())
