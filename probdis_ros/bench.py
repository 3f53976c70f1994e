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

from itertools import pairwise
import json
import math
import os
import platform
import statistics
import sys
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


def learned_failure_map(failures: int = 19, seed: int = 0,
                        across_episodes: bool = False):
    """
    Return (start, goal, map) with ``failures`` failures learned in real simulated episodes.

    The Epsilon method (fast: no planning) runs in the demo's closed box (``demo_iiwa``, 3-D
    with orientation), where it rarely gets out, and every block it meets is recorded.  The
    first episode (loop seeds seed, seed + 1, ...) that reaches ``failures`` gives the map
    or, with ``across_episodes``, one map persists across episodes until it holds
    ``failures`` (as a robot's map grows across runs).  Start is where the arm then is.
    (Random 90-obstacle worlds no longer serve: since an arm pressed into an obstacle can pull back
    out, Epsilon leaves most of them within 19 blocks.)
    """
    from probdis_ros.model import FailureMap
    from probdis_ros.planning import Disentangler, EpsilonPlanner
    from probdis_ros.resources import scenario_path
    from probdis_ros.sim.episode import drive
    from probdis_ros.sim.worlds import load_world

    world = load_world(scenario_path('demo_iiwa'))
    fmap = FailureMap(world.arm.task_space)
    for loop_seed in range(seed, seed + 1000):
        loop = Disentangler(world.arm, EpsilonPlanner(world.arm, 0.2), world.goal, fmap,
                            max_paths=200, seed=loop_seed)
        current, _ = drive(loop, world.compliant_arm(), world.start,
                           until=lambda loop: len(loop.fmap) >= failures)
        if len(fmap) == failures:
            return current, world.goal, fmap
        if not across_episodes:
            fmap = FailureMap(world.arm.task_space)
    raise RuntimeError(f'no run of episodes produced {failures} failures')


def nineteen_failure_map(seed: int = 0):
    """Return (start, goal, map) of 19 failures learned in one episode (``bench plan``'s)."""
    return learned_failure_map(19, seed)


def straight_path_map(failures: int = 19):
    """
    Return (start, goal, map): failures spread along the straight joint-space path.

    The demo's start and goal, and a failure at each of ``failures`` evenly spaced points
    of the straight edge between them, blocked along the flange's motion there: the
    straight path is the worst way, and a planner must find its way around all of them.
    """
    from probdis_ros.model import FailureMap
    from probdis_ros.resources import scenario_path
    from probdis_ros.sim.worlds import load_world

    world = load_world(scenario_path('demo_iiwa'))
    arm, start, goal = world.arm, world.start, world.goal
    fractions = (np.arange(failures) + 1.0) / (failures + 1.0)
    poses = arm.fk(start + fractions[:, None] * (goal - start))
    ahead = arm.fk(start + (fractions[:, None] + 1e-3) * (goal - start)).positions
    fmap = FailureMap(arm.task_space)
    for i in range(failures):
        fmap.add(poses.positions[i], ahead[i] - poses.positions[i], poses.orientations[i])
    return start, goal, fmap


def bench_plan(seeds: int = 20, large: int = 400, reach: float = math.inf,
               table: bool = False) -> dict:
    """
    Median ProbRRT planning time (paper parameters, iiwa with orientation, one thread).

    ``reach`` [m]: failures taper to 0 this far away (the informed method's idea h, whose
    effect on plans is measured by the family and paper sweeps); inf: the paper's kernel.
    ``table``: the arm on the robot's table (the planner node's default), which every edge
    point then checks.

    Wall time (``median_s_*``) and this process's CPU time (``cpu_median_s_*``: on a
    shared, loaded machine the wall time also counts the time others hold the cores).

    On an empty map, on 19 failures of one episode and on ``large`` failures of a map
    grown over episodes (0: skip it); also the mean number of RRT* re-parentings per plan.
    """
    from probdis_ros.model import FailureMap
    from probdis_ros.model.table import ROBOT_TABLE
    from probdis_ros.planning import FailureProbabilityObjective, ProbRRT

    start, goal, fmap = nineteen_failure_map()
    arm = arm_for_setting('3d-orient')
    if table:
        arm = arm.on_table(ROBOT_TABLE)
    maps = [('empty_map', start, goal, FailureMap(arm.task_space)),
            ('19_failures', start, goal, fmap)]
    if large:
        maps.append((f'{large}_failures',
                     *learned_failure_map(large, across_episodes=True)))
    planner = ProbRRT(arm, None, FailureProbabilityObjective(reach=reach))
    planner.plan(start, goal, fmap, np.random.default_rng(0))   # compile the kernels
    result = {'machine': machine(), 'seeds': seeds, 'load_average': os.getloadavg()[0],
              'reach': reach, 'table': table}
    for key, begin, end, the_map in maps:
        result[f'least_s_{key}'] = least_probability_seconds(arm, the_map, reach)
        times, cpu_times, rewires = [], [], []
        for seed in range(seeds):
            t0, c0 = time.perf_counter(), time.process_time()
            plan = planner.plan(begin, end, the_map, np.random.default_rng(seed))
            times.append(time.perf_counter() - t0)
            cpu_times.append(time.process_time() - c0)
            rewires.append(plan.rewires)
        result[f'median_s_{key}'] = statistics.median(times)
        result[f'cpu_median_s_{key}'] = statistics.median(cpu_times)
        result[f'rewires_per_plan_{key}'] = statistics.fmean(rewires)
    return result


def least_probability_seconds(arm, fmap, reach: float) -> float:
    """
    Return the seconds of one search of the map's least probability (0: none made).

    A planner searches it once for a map, and again only once the map has grown by a
    quarter (:mod:`probdis_ros.model.least_probability`): ``bench plan``'s medians, many
    plans on one map, leave it out; a run, adding a failure a plan, pays it again each time
    its map has grown by a quarter.
    """
    from probdis_ros.model.least_probability import least_probability, tip_ball
    from probdis_ros.planning import FailureProbabilityObjective

    failures = FailureProbabilityObjective(reach=reach).coster(arm, fmap).failure_arrays
    ball = tip_ball(arm)
    if failures[3][2] == 0.0 or ball is None:
        return 0.0
    began = time.perf_counter()
    least_probability(*failures[:2], failures[3][:2], failures[4], *ball)
    return time.perf_counter() - began


# -- path quality beside OMPL's BIT* (probdis bench quality) ----------------------------------

#: Wall-time budgets [s] at which the planners are compared.
QUALITY_BUDGETS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)
#: How to get the optional benchmark extra.
OMPL_HINT = ('OMPL is an optional benchmark extra, not a dependency of probdis: '
             'pip install -r .ci/requirements/bench.txt (the ompl wheel 2.0.1)')


def quality_maps() -> list[tuple]:
    """
    Return the maps of ``bench quality``: (name, start, goal, map) each.

    Two 19-failure maps learned in real episodes (the first is ``bench plan``'s) and 19
    failures on the straight path from the demo's start to its goal.
    """
    return [('episode-19a', *learned_failure_map(19, 0)),
            ('episode-19b', *learned_failure_map(19, 50)),
            ('straight-19', *straight_path_map(19))]


def path_quality(arm, fmap, path: np.ndarray, delta: float, length_weight: float
                 ) -> tuple[float, float]:
    """
    Return (cost, success probability) of a path, by the project's one edge cost.

    Both planners' paths are scored here, by the same compiled coster, so that neither's own
    bookkeeping is trusted.
    """
    from probdis_ros.planning.objectives import FailureProbabilityObjective

    path = np.asarray(path, dtype=float)
    cost = risk = 0.0
    for weight in (length_weight, 0.0):
        coster = FailureProbabilityObjective(weight).coster(arm, fmap, delta)
        total = float(sum(coster.cost(a, b) for a, b in pairwise(path)))
        if weight:
            cost = total
        else:
            risk = total
    return cost, float(np.exp(-risk))


class BitStar:
    """
    OMPL's BIT* on the project's cost: its OptimizationObjective calls our edge coster.

    The motion cost of two states is ``EdgeCoster.cost`` (one compiled call per edge, from
    Python); the heuristic is the length term alone, a lower bound, so BIT* stays
    admissible.  Built once per map; each :meth:`solve` is a fresh planner.
    """

    def __init__(self, arm, fmap, delta: float, length_weight: float) -> None:
        try:
            from ompl import base as ob
            from ompl import geometric as og
            from ompl import util as ou
        except ImportError as err:
            raise ImportError(OMPL_HINT) from err
        from probdis_ros.planning.objectives import FailureProbabilityObjective

        ou.setLogLevel(ou.LOG_ERROR)    # not its notes on the missing cost-to-go heuristic
        self.ob, self.og, self.n = ob, og, arm.n_joints
        coster = FailureProbabilityObjective(length_weight).coster(arm, fmap, delta)
        self.space = ob.RealVectorStateSpace(self.n)
        bounds = ob.RealVectorBounds(self.n)
        for j in range(self.n):
            bounds.setLow(j, float(arm.lower[j]))
            bounds.setHigh(j, float(arm.upper[j]))
        self.space.setBounds(bounds)
        self.si = ob.SpaceInformation(self.space)
        self.si.setStateValidityChecker(ob.AllValidStateValidityChecker(self.si))
        self.si.setup()
        n, si = self.n, self.si

        def config(state) -> np.ndarray:
            return np.array([state[j] for j in range(n)])

        class Objective(ob.OptimizationObjective):
            def stateCost(self, state):          # noqa: N802 (OMPL's names)
                return ob.Cost(0.0)

            def motionCost(self, a, b):          # noqa: N802
                return ob.Cost(coster.cost(config(a), config(b)))

            def motionCostHeuristic(self, a, b):  # noqa: N802
                return ob.Cost(length_weight * si.distance(a, b))

        self.objective = Objective(self.si)
        self._config = config

    def solve(self, start: np.ndarray, goal: np.ndarray, budget: float) -> np.ndarray | None:
        """Return BIT*'s best path within ``budget`` seconds of solving, or None."""
        ob = self.ob
        pdef = ob.ProblemDefinition(self.si)
        begin, end = self.space.allocState(), self.space.allocState()
        for j in range(self.n):
            begin[j], end[j] = float(start[j]), float(goal[j])
        pdef.setStartAndGoalStates(begin, end)
        pdef.setOptimizationObjective(self.objective)
        planner = self.og.BITstar(self.si)
        planner.setProblemDefinition(pdef)
        planner.setup()
        planner.solve(budget)
        if not pdef.hasExactSolution():
            return None
        path = pdef.getSolutionPath()
        return np.array([self._config(path.getState(i)) for i in range(path.getStateCount())])


def bench_quality(budgets: tuple[float, ...] = QUALITY_BUDGETS, seeds: int = 5,
                  maps: list[tuple] | None = None, planners: tuple[str, ...] = (
                      'probrrt', 'bitstar')) -> dict:
    """
    Median path cost and success probability per map, planner and wall-time budget.

    ProbRRT runs anytime (``plan_time`` = the budget: its trees grow in slices of 1, 2, 4, ...
    iterations, ``ProbRRT.grow``); BIT* solves for the budget.  Both are timed from the call
    to the returned path (set-up included), and both paths are scored by
    :func:`path_quality`.  The paper's configuration (K = 100, no budget) is reported
    beside, with its own time.  Seeds: ProbRRT's generator; OMPL's global generator is
    seeded once (its runs differ by timing anyway).
    """
    from probdis_ros.model.path_cost import DEFAULT_DELTA, DEFAULT_LENGTH_WEIGHT
    from probdis_ros.planning import ProbRRT, RRTSettings

    delta, weight = DEFAULT_DELTA, DEFAULT_LENGTH_WEIGHT
    arm = arm_for_setting('3d-orient')
    if 'bitstar' in planners:
        try:
            from ompl import util as ou
        except ImportError as err:
            raise ImportError(OMPL_HINT) from err
        ou.RNG.setSeed(1)
    maps = quality_maps() if maps is None else maps
    result = {'machine': machine(), 'seeds': seeds, 'budgets_s': list(budgets),
              'delta': delta, 'length_weight': weight, 'maps': []}
    for name, start, goal, fmap in maps:
        straight = path_quality(arm, fmap, np.array([start, goal]), delta, weight)
        entry = {'map': name, 'failures': len(fmap), 'c_fail': fmap.c_fail,
                 'straight_cost': straight[0], 'planners': {}}
        entry['paper'] = _quality_runs(ProbRRT(arm, RRTSettings()), start, goal, fmap, 0.0,
                                       seeds, weight)
        for planner_name in planners:
            planner = BitStar(arm, fmap, delta, weight) if planner_name == 'bitstar' else None
            rows = []
            for budget in budgets:
                if planner_name != 'bitstar':
                    planner = ProbRRT(arm, RRTSettings(plan_time=budget))
                runs = _quality_runs(planner, start, goal, fmap, budget, seeds, weight)
                rows.append({'budget_s': budget, **runs})
            entry['planners'][planner_name] = rows
        entry['verdict'] = _verdict(entry)
        result['maps'].append(entry)
    return result


def _quality_runs(planner, start: np.ndarray, goal: np.ndarray, fmap, budget: float,
                  seeds: int, weight: float) -> dict:
    """Run a planner once per seed; return medians of cost, success and wall time."""
    from probdis_ros.model.path_cost import DEFAULT_DELTA

    arm = arm_for_setting('3d-orient')
    costs, successes, times = [], [], []
    for seed in range(seeds):
        t0 = time.perf_counter()
        if isinstance(planner, BitStar):
            path = planner.solve(start, goal, budget)
        else:
            plan = planner.plan(start, goal, fmap, np.random.default_rng(seed))
            path = None if plan is None else plan.path
        times.append(time.perf_counter() - t0)
        cost, success = (np.inf, 0.0) if path is None else \
            path_quality(arm, fmap, path, DEFAULT_DELTA, weight)
        costs.append(cost)
        successes.append(success)
    return {'median_cost': statistics.median(costs),
            'median_success_probability': statistics.median(successes),
            'median_time_s': statistics.median(times), 'costs': costs}


def _verdict(entry: dict) -> dict:
    """
    Check the target on one map: ProbRRT's median at or below BIT*'s at every budget.

    And the first budget at which ProbRRT reaches BIT*'s cost at its longest budget (the
    target: within 50 ms of BIT*'s 1 s).
    """
    planners = entry['planners']
    if 'probrrt' not in planners or 'bitstar' not in planners:
        return {}
    ours, theirs = planners['probrrt'], planners['bitstar']
    every = all(a['median_cost'] <= b['median_cost'] for a, b in zip(ours, theirs))
    best = theirs[-1]['median_cost']
    reached = [a['budget_s'] for a in ours if a['median_cost'] <= best]
    return {'at_or_below_every_budget': every,
            'budgets_at_or_below': [a['budget_s'] for a, b in zip(ours, theirs)
                                    if a['median_cost'] <= b['median_cost']],
            'bitstar_longest_budget_cost': best,
            'first_budget_reaching_it_s': reached[0] if reached else None}


def _quality_table(result: dict) -> str:
    """Return the result of :func:`bench_quality` as text tables, one per map."""
    lines = [f'Path quality on the iiwa with orientation, same cost for both (delta '
             f'{result["delta"]:g}, lambda {result["length_weight"]:g}); median of '
             f'{result["seeds"]} runs per cell: cost / success probability / wall time [s]']
    for entry in result['maps']:
        paper = entry['paper']
        lines.append(f'\n{entry["map"]}: {entry["failures"]} failures, C_FAIL '
                     f'{entry["c_fail"]:g}, straight path cost {entry["straight_cost"]:.3f}; '
                     f'paper ProbRRT (K = 100) {paper["median_cost"]:.3f} / '
                     f'{paper["median_success_probability"]:.3f} in '
                     f'{paper["median_time_s"]:.3f} s')
        names = list(entry['planners'])
        lines.append(f'{"budget [s]":>10}' + ''.join(f'{n:>26}' for n in names))
        for i, budget in enumerate(result['budgets_s']):
            cells = []
            for n in names:
                row = entry['planners'][n][i]
                cells.append(f'{row["median_cost"]:9.3f} / {row["median_success_probability"]:.3f}'
                             f' / {row["median_time_s"]:.3f}')
            lines.append(f'{budget:>10g}' + ''.join(f'{c:>26}' for c in cells))
        verdict = entry['verdict']
        if verdict:
            lines.append(f'ProbRRT at or below BIT* at every budget: '
                         f'{"yes" if verdict["at_or_below_every_budget"] else "no"}; reaches '
                         f'BIT*\'s {result["budgets_s"][-1]:g} s cost '
                         f'({verdict["bitstar_longest_budget_cost"]:.3f}) at '
                         f'{verdict["first_budget_reaching_it_s"]} s')
    lines.append(f'machine: {result["machine"]}')
    return '\n'.join(lines)


def _budgets(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(','))
    except ValueError:
        raise ValueError(f'--budgets: {text!r} is not a comma-separated list of seconds') \
            from None
    if not values or min(values) <= 0:
        raise ValueError('--budgets must be positive seconds')
    return values


def cmd_bench_quality(args) -> int:
    """Run ``probdis bench quality``: ProbRRT beside OMPL's BIT* at equal wall-time budgets."""
    try:
        import ompl  # noqa: F401 (only whether it is there)
    except ImportError:
        print(f'probdis: error: {OMPL_HINT}', file=sys.stderr)
        return 2
    if args.seeds < 1:
        raise ValueError('--seeds must be at least 1')
    result = bench_quality(_budgets(args.budgets), args.seeds)
    if args.json:
        print(json.dumps(result))
    else:
        print(_quality_table(result))
    return 0


def add_quality_command(bench_subparsers) -> None:
    """Add ``probdis bench quality`` to the subparsers of ``probdis bench``."""
    quality = bench_subparsers.add_parser(
        'quality', help="path cost and success probability of ProbRRT and OMPL's BIT* "
        'at equal wall-time budgets (needs the optional ompl wheel)')
    quality.add_argument('--budgets', default=','.join(f'{b:g}' for b in QUALITY_BUDGETS),
                         help='comma-separated wall-time budgets [s] (default: %(default)s)')
    quality.add_argument('--seeds', type=int, default=5, help='runs per planner, map and '
                         'budget (default: %(default)s)')
    quality.add_argument('--json', action='store_true', help='print one JSON object')
    quality.set_defaults(handler=cmd_bench_quality)


def cmd_bench_plan(args) -> int:
    """Time ProbRRT on the iiwa with orientation: empty map, 19 and 400 failures."""
    if args.seeds < 1 or args.large < 0:
        raise ValueError('--seeds must be at least 1 and --large at least 0')
    if not args.reach > 0:
        raise ValueError("--reach must be > 0 (inf: the paper's kernel)")
    result = bench_plan(args.seeds, args.large, args.reach, args.table)
    keys = [k for k in result if k.startswith('median_s_')]
    if args.json:
        print(json.dumps({k: result[k] for k in keys}))
        return 0
    kernel = "the paper's kernel" if math.isinf(args.reach) else \
        f'failures reaching {args.reach:g} m (idea h)'
    on = ', on its table' if args.table else ''
    print(f'ProbRRT plan, iiwa with orientation{on}, paper parameters, {kernel}, one thread, '
          f'median of {args.seeds} seeds:')
    for key in keys:
        name = key.removeprefix('median_s_')
        print(f'  {name.replace("_", " ") + ":":14s}{result[key]:.4f} s wall, '
              f'{result["cpu_median_s_" + name]:.4f} s CPU   (RRT* re-parentings per plan: '
              f'{result["rewires_per_plan_" + name]:.1f})')
        if result['least_s_' + name]:
            print(f'{"":16s}its least probability searched once: '
                  f'{1e3 * result["least_s_" + name]:.1f} ms')
    print(f'machine: {result["machine"]}; load average {result["load_average"]:.1f}')
    return 0


def add_plan_command(bench_subparsers) -> None:
    """Add ``probdis bench plan`` to the subparsers of ``probdis bench``."""
    plan = bench_subparsers.add_parser(
        'plan', help='ProbRRT planning time: empty map, 19 failures, 400 failures')
    plan.add_argument('--seeds', type=int, default=20, help='plans per map')
    plan.add_argument('--large', type=int, default=400,
                      help='failures of the large map, grown over episodes (0: skip it)')
    plan.add_argument('--reach', type=float, default=math.inf,
                      help="[m] failures taper to 0 this far away (the informed method's "
                      "idea h; 0.5 there); default inf, the paper's kernel")
    plan.add_argument('--table', action='store_true',
                      help="the arm on the robot's table (the planner node's default)")
    plan.add_argument('--json', action='store_true',
                      help='print {"median_s_empty_map": float, "median_s_19_failures": float, '
                      '"median_s_400_failures": float}')
    plan.set_defaults(handler=cmd_bench_plan)
