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

"""The speed-ups change no plan: compiled loop, pruned failures; and the anytime mode."""

import argparse
import json

import numpy as np
from probdis_ros.bench import add_plan_command, straight_path_map
from probdis_ros.model import arm_for_setting, FailureMap
from probdis_ros.model.edge_costs import EdgeCoster
from probdis_ros.model.edge_kernels import padded_count
from probdis_ros.model.tree_kernels import farthest_kernel, nearest_order
from probdis_ros.planning import HardThresholdObjective, ProbRRT, RRTSettings
from probdis_ros.planning.objectives import FailureProbabilityObjective
import pytest
from test_planning import scattered_map

ARM = arm_for_setting('3d-orient')


class UnprunedEdgeCoster(EdgeCoster):
    """The compiled coster evaluating every failure at every point (no bounds)."""

    def __init__(self, arm, fmap, delta=0.04, terms=None) -> None:
        super().__init__(arm, fmap, delta, terms, prune=False)


def same_plans(fast: ProbRRT, slow: ProbRRT, start, goal, fmap, seeds=range(3)) -> None:
    """Assert the same path (bit for bit) and the same cost for each seed."""
    for seed in seeds:
        a = fast.plan(start, goal, fmap, np.random.default_rng(seed))
        b = slow.plan(start, goal, fmap, np.random.default_rng(seed))
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_array_equal(a.path, b.path)
            assert a.cost == b.cost and a.tree_sizes == b.tree_sizes
            assert a.rewires == b.rewires


def clustered_map(arm, rng, n: int, spread: float = 0.05):
    """Return n failures near the poses of a few configurations (a map grown in one place)."""
    centers = arm.random_configurations(rng, 4)
    configs = centers[rng.integers(0, 4, n)] + rng.normal(0.0, spread, (n, arm.n_joints))
    poses = arm.fk(np.clip(configs, arm.lower, arm.upper))
    fmap = FailureMap(arm.task_space, 100.0)
    for i in range(n):
        fmap.add(poses.positions[i], rng.normal(size=3), poses.orientations[i])
    return fmap


@pytest.mark.parametrize('settings', [
    RRTSettings(), RRTSettings(joint_margin=0.035), RRTSettings(rewire_factor=0.0),
    RRTSettings(iterations=30, closest_candidates=0, connect_candidates=0, rewire_radius=1.5)])
def test_the_compiled_loop_plans_exactly_as_the_python_loop(settings):
    rng = np.random.default_rng(21)
    fmap = scattered_map(ARM, rng, 19)
    start, goal = ARM.random_configurations(rng, 2)
    for objective in (FailureProbabilityObjective(), HardThresholdObjective(0.01)):
        compiled = ProbRRT(ARM, settings, objective)
        assert compiled.compiled
        same_plans(compiled, ProbRRT(ARM, settings, objective, compiled=False), start, goal,
                   fmap)


def test_the_compiled_loop_plans_as_the_python_loop_on_large_maps_and_at_the_limits():
    rng = np.random.default_rng(24)
    start, goal = ARM.upper - 0.01, ARM.lower + 0.02      # within the margin of the limits
    for fmap in (clustered_map(ARM, rng, 400), scattered_map(ARM, rng, 150)):
        for settings in (RRTSettings(iterations=40), RRTSettings(iterations=40,
                                                                 joint_margin=0.035)):
            same_plans(ProbRRT(ARM, settings), ProbRRT(ARM, settings, compiled=False),
                       start, goal, fmap, seeds=range(2))


def test_maps_of_every_size_and_both_objectives_share_one_compiled_kernel():
    # numba compiles a kernel once per argument types: failure arrays whose layout changed
    # with the map's size (one failure's both C- and F-contiguous) and literal arguments
    # between kernels compiled each up to six times; a first start took 141 s instead of 40
    from probdis_ros.model import edge_kernels, tree_kernels

    kernels = (tree_kernels.grow_kernel, tree_kernels.connect_kernel,
               edge_kernels.cheapest_edge_kernel, edge_kernels.edge_costs_kernel,
               edge_kernels.edge_cost_kernel, edge_kernels._chunk_probabilities)
    rng = np.random.default_rng(5)
    start, goal = ARM.random_configurations(rng, 2)
    paper = ProbRRT(ARM, RRTSettings(iterations=10))
    paper.plan(start, goal, scattered_map(ARM, rng, 5), rng)
    before = [len(kernel.signatures) for kernel in kernels]
    hard = ProbRRT(ARM, RRTSettings(iterations=10), HardThresholdObjective(0.01))
    for failures in (0, 1, 2, 19):
        fmap = scattered_map(ARM, rng, failures) if failures else FailureMap(ARM.task_space)
        for planner in (paper, hard):
            planner.plan(start, goal, fmap, rng)
    assert [len(kernel.signatures) for kernel in kernels] == before


def test_pruning_far_failures_changes_no_cost_and_no_plan():
    rng = np.random.default_rng(22)
    for failures in (5, 19, 150, 400):
        fmap = scattered_map(ARM, rng, failures) if failures < 400 else \
            clustered_map(ARM, rng, failures)
        sources = ARM.random_configurations(rng, 40)
        target = ARM.random_configurations(rng, 1)[0]
        for objective in (FailureProbabilityObjective(), HardThresholdObjective(0.02),
                          FailureProbabilityObjective(reach=0.25)):
            pruned = objective.coster(ARM, fmap)
            every = objective.coster(ARM, fmap, coster_type=UnprunedEdgeCoster)
            for toward in (True, False):
                np.testing.assert_array_equal(pruned.costs(sources, target, toward),
                                              every.costs(sources, target, toward))
            assert pruned.cheapest(sources, target) == every.cheapest(sources, target)
    start, goal, fmap = straight_path_map(19)       # failures along the way
    same_plans(ProbRRT(ARM), ProbRRT(ARM, coster_type=UnprunedEdgeCoster), start, goal, fmap)
    fmap = scattered_map(ARM, rng, 150)
    same_plans(ProbRRT(ARM, RRTSettings(iterations=40)),
               ProbRRT(ARM, RRTSettings(iterations=40), coster_type=UnprunedEdgeCoster),
               start, goal, fmap, seeds=range(2))


def test_the_anytime_mode_keeps_its_budget_and_its_cost_is_its_path_cost():
    start, goal, fmap = straight_path_map(19)
    objective = FailureProbabilityObjective()
    coster = objective.coster(ARM, fmap)
    paper = ProbRRT(ARM).plan(start, goal, fmap, np.random.default_rng(0))
    budget = max(0.3, 3 * paper.plan_time_s)
    anytime = ProbRRT(ARM, RRTSettings(plan_time=budget)).plan(
        start, goal, fmap, np.random.default_rng(0))
    assert anytime.plan_time_s < budget + 0.1 + paper.plan_time_s
    edges = sum(coster.cost(a, b) for a, b in zip(anytime.path[:-1], anytime.path[1:]))
    assert anytime.cost == pytest.approx(edges, rel=1e-12)
    assert anytime.cost < paper.cost
    assert np.all(ARM.within_limits(anytime.path))
    np.testing.assert_array_equal(anytime.path[[0, -1]], [start, goal])


def test_bench_plan_times_an_empty_a_19_and_a_large_map(capsys):
    parser = argparse.ArgumentParser()
    add_plan_command(parser.add_subparsers())
    args = parser.parse_args(['plan', '--seeds', '1', '--large', '30', '--json'])
    assert args.handler(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert list(doc) == ['median_s_empty_map', 'median_s_19_failures', 'median_s_30_failures']
    assert all(v > 0 for v in doc.values())


def test_the_farthest_sample_is_the_one_of_every_distance():
    rng = np.random.default_rng(23)
    for nodes in (1, 7, 120):
        samples, tree = rng.normal(size=(100, 3)), rng.normal(size=(nodes, 3))
        d2 = ((samples[:, None, :] - tree[None, :, :]) ** 2).sum(axis=2).min(axis=1)
        assert farthest_kernel(samples, tree) == int(np.argmax(d2))


def test_the_k_nearest_are_a_stable_sorts_first_k():
    rng = np.random.default_rng(25)
    for trial in range(300):
        size, k = int(rng.integers(1, 40)), int(rng.integers(0, 45))
        # whole numbers: many equal distances, where the order of ties shows
        nodes = rng.integers(0, 3, size=(size, 7)).astype(float) if trial % 2 else \
            rng.normal(size=(size, 7))
        config = rng.integers(0, 3, size=7).astype(float)
        d2 = ((nodes - config) ** 2).sum(axis=1)
        order = np.argsort(d2, kind='mergesort')
        np.testing.assert_array_equal(nearest_order(nodes, size, config, k),
                                      order[:k] if 0 < k < size else order)


def test_bench_plan_prints_wall_and_cpu_time_and_the_load(capsys):
    parser = argparse.ArgumentParser()
    add_plan_command(parser.add_subparsers())
    args = parser.parse_args(['plan', '--seeds', '1', '--large', '0'])
    assert args.handler(args) == 0
    out = capsys.readouterr().out
    assert out.count('s wall, ') == 2 and out.count('s CPU') == 2
    assert 'load average' in out and "the paper's kernel" in out


def test_bench_plan_times_local_failures_and_refuses_a_reach_that_is_not_positive(capsys):
    parser = argparse.ArgumentParser()
    add_plan_command(parser.add_subparsers())
    args = parser.parse_args(['plan', '--seeds', '1', '--large', '0', '--reach', '0.5'])
    assert args.handler(args) == 0
    assert 'failures reaching 0.5 m (idea h)' in capsys.readouterr().out
    with pytest.raises(ValueError, match='--reach'):
        args = parser.parse_args(['plan', '--reach', '0'])
        args.handler(args)


def test_bench_plan_times_the_arm_on_its_table(capsys):
    parser = argparse.ArgumentParser()
    add_plan_command(parser.add_subparsers())
    args = parser.parse_args(['plan', '--seeds', '1', '--large', '0', '--table'])
    assert args.handler(args) == 0
    assert 'iiwa with orientation, on its table' in capsys.readouterr().out


def test_pruned_chunks_give_every_point_the_same_maximum_bit_for_bit():
    # the chunk bounds skip failures, and the orientation factor's bound skips the factor of
    # most that remain: each point's maximum is still that of every failure evaluated
    from probdis_ros.model import edge_kernels
    from probdis_ros.model.arms import quaternion_to_rotation
    from probdis_ros.model.path_cost import edge_points

    rng = np.random.default_rng(33)
    maps = [(clustered_map(ARM, rng, 400), np.inf), (clustered_map(ARM, rng, 400), 0.25),
            (scattered_map(ARM, rng, 19), np.inf)]
    for fmap, reach in maps:
        pruned = FailureProbabilityObjective(reach=reach).coster(ARM, fmap)
        every = FailureProbabilityObjective(reach=reach).coster(ARM, fmap,
                                                                coster_type=UnprunedEdgeCoster)
        soa = edge_kernels.workspace(len(fmap))
        p_pruned, p_every = np.empty(edge_kernels.CHUNK), np.empty(edge_kernels.CHUNK)
        for _ in range(200):
            a, b = ARM.random_configurations(rng, 2)
            points = edge_points(a, a + rng.uniform(0.05, 0.5) * (b - a), pruned.delta)[0]
            points = points[:edge_kernels.CHUNK]
            poses = ARM.fk(points)
            pos = np.ascontiguousarray(poses.positions)
            rot = quaternion_to_rotation(poses.orientations).reshape(-1, 3, 3).copy()
            for coster, out in ((pruned, p_pruned), (every, p_every)):
                edge_kernels._chunk_probabilities(pos, rot, len(points), *coster._failures, soa,
                                                  out, edge_kernels.ALONG_NEAR2,
                                                  edge_kernels.ALONG_AT_FAILURE)
            np.testing.assert_array_equal(p_pruned[:len(points)], p_every[:len(points)])


def test_the_least_probability_lies_below_every_pose_the_arm_can_take():
    # the bound that spares the best-first search points must hold at every reachable pose
    from probdis_ros.model.least_probability import least_probability, tip_ball

    rng = np.random.default_rng(44)
    center, radius = tip_ball(ARM)
    poses = ARM.fk(ARM.random_configurations(rng, 100_000))
    assert np.linalg.norm(poses.positions - center, axis=1).max() <= radius
    straight = straight_path_map(19)[2]
    maps = [(scattered_map(ARM, rng, 19), np.inf), (clustered_map(ARM, rng, 400), np.inf),
            (straight, np.inf), (scattered_map(ARM, rng, 19), 1.5)]
    leasts = []
    for fmap, reach in maps:
        coster = FailureProbabilityObjective(reach=reach).coster(ARM, fmap)
        points, directions, _, c_fail, use_orient, _ = coster._failures
        least = least_probability(points, directions, c_fail[:2], use_orient, center, radius)
        leasts.append(least)
        assert 0.0 <= least <= fmap.probability(poses, reach=reach).min()
    assert leasts[0] > 1e-4 and leasts[1] > 1e-4       # not a bound of 0 on a real map


def test_the_least_point_cost_changes_no_winner_on_equal_totals():
    # the winning edge twice, before and after it: equal totals, which the search order
    # would decide; the search with the least point cost must give what the plain one gives
    rng = np.random.default_rng(55)
    fmap = scattered_map(ARM, rng, 19)
    floored = FailureProbabilityObjective().coster(ARM, fmap)
    plain = FailureProbabilityObjective().coster(ARM, fmap, coster_type=UnprunedEdgeCoster)
    assert floored._failures[3][2] > 0.0 and plain._failures[3][2] == 0.0
    for _ in range(10):
        sources = ARM.random_configurations(rng, 6)
        target = ARM.random_configurations(rng, 1)[0]
        for base in (np.zeros(6), rng.uniform(0.0, 0.5, 6)):
            for toward in (True, False):
                best, _ = plain.cheapest(sources, target, toward, base)
                for twin in (0, 5):
                    if twin == best:
                        continue
                    copies, bases = sources.copy(), base.copy()
                    copies[twin], bases[twin] = sources[best], base[best]
                    assert floored.cheapest(copies, target, toward, bases) == \
                        plain.cheapest(copies, target, toward, bases)
        limits = plain.costs(sources, target) * rng.uniform(0.8, 1.2, 6)
        np.testing.assert_array_equal(floored.costs(sources, target, limits=limits),
                                      plain.costs(sources, target, limits=limits))


def test_a_least_probability_found_serves_the_maps_grown_from_it(monkeypatch):
    # a run adds a failure a plan: the bound of a map holds for every map with its failures,
    # so it is searched again only once the map has grown by a quarter, or is another map
    from probdis_ros.model import least_probability as least

    searched = []

    def counted(*args):
        searched.append(args[0].shape[1])
        return search(*args)

    search = least.least_probability
    monkeypatch.setattr(least, 'least_probability', counted)
    monkeypatch.setattr(least, '_KNOWN', [])
    rng = np.random.default_rng(66)
    fmap = scattered_map(ARM, rng, 20)

    def least_cost():
        return FailureProbabilityObjective().coster(ARM, fmap)._failures[3][2]

    first = least_cost()
    assert first > 0.0 and len(searched) == 1
    grown = scattered_map(ARM, rng, 10)
    for point, direction, orientation in zip(*grown.arrays()):
        fmap.add(point, direction, orientation)
        cost = least_cost()
        if len(fmap) <= 25:
            assert cost == first and len(searched) == 1       # the first map's bound
        poses = ARM.fk(ARM.random_configurations(rng, 2000))
        assert -np.log1p(-fmap.probability(poses).min()) >= cost     # a bound still
    assert len(searched) == 2 and searched[-1] == padded_count(26)
    FailureProbabilityObjective().coster(ARM, scattered_map(ARM, rng, 20))
    assert len(searched) == 3                                 # another map: searched
