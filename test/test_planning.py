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

"""ProbRRT and the baselines: paths, limits, reproducibility, same plans as the reference."""

import numpy as np
from probdis_ros.model import arm_for_setting, FailureMap, TaskSpace
from probdis_ros.model.edge_costs import EdgeCoster, ReferenceEdgeCoster
from probdis_ros.model.path_cost import edge_points, path_success_probability
from probdis_ros.planning import (
    EpsilonPlanner,
    FailureProbabilityObjective,
    HardThresholdObjective,
    make_planner,
    Method,
    ProbRRT,
    RRTSettings,
)
from probdis_ros.planning.informed import LOCAL_REACH
from probdis_ros.planning.prob_rrt import ROBOT_JOINT_MARGIN
import pytest

PLANAR = arm_for_setting('2d')
# the stretched-out arm swings its base joint through 1.2 rad: a 0.84 m arc of the tip
START = np.array([np.pi / 2 + 0.6, 0, 0, 0, 0, 0, 0])
GOAL = np.array([np.pi / 2 - 0.6, 0, 0, 0, 0, 0, 0])


def scattered_map(arm, rng, n: int) -> FailureMap:
    """Return n failures at the end-effector poses of random configurations."""
    fmap = FailureMap(arm.task_space, 100.0)
    poses = arm.fk(arm.random_configurations(rng, n))
    for i in range(n):
        q = None if poses.orientations is None else poses.orientations[i]
        fmap.add(poses.positions[i], rng.normal(size=arm.task_space.dim), q)
    return fmap


def wall_map() -> FailureMap:
    """Failures across the straight move, a fifth of the way along, blocking it."""
    fmap = FailureMap(TaskSpace.POINT2, 100.0)
    angle = np.pi / 2 + 0.6 - 0.24
    tangent = np.array([np.sin(angle), -np.cos(angle)])
    for radius in (0.5, 0.6, 0.7):
        fmap.add(radius * np.array([np.cos(angle), np.sin(angle)]), tangent)
    return fmap


def test_empty_map_path_joins_start_and_goal():
    plan = ProbRRT(PLANAR).plan(START, GOAL, FailureMap(TaskSpace.POINT2),
                                np.random.default_rng(0))
    np.testing.assert_array_equal(plan.path[0], START)
    np.testing.assert_array_equal(plan.path[-1], GOAL)
    assert plan.cost == pytest.approx(0.01 * np.linalg.norm(np.diff(plan.path, axis=0),
                                                            axis=1).sum())


def test_path_goes_around_a_failure_wall():
    fmap = wall_map()
    straight = path_success_probability(PLANAR, fmap, np.array([START, GOAL]))
    around = [path_success_probability(PLANAR, fmap, ProbRRT(PLANAR).plan(
        START, GOAL, fmap, np.random.default_rng(seed)).path) for seed in range(5)]
    assert straight < 1e-3
    assert np.median(around) > 20 * straight


def test_paths_never_leave_the_joint_limits():
    arm = arm_for_setting('3d-orient')
    near_limit = arm.upper - 0.01
    goal = arm.lower + 0.01
    for seed in range(3):
        plan = ProbRRT(arm).plan(near_limit, goal, FailureMap(TaskSpace.POSE3),
                                 np.random.default_rng(seed))
        # via points inside the box of limits keep every straight edge inside it too
        assert arm.within_limits(plan.path, tol=0.0).all()


def test_reproducible_from_its_seed():
    fmap = wall_map()
    a = ProbRRT(PLANAR).plan(START, GOAL, fmap, np.random.default_rng(7))
    b = ProbRRT(PLANAR).plan(START, GOAL, fmap, np.random.default_rng(7))
    c = ProbRRT(PLANAR).plan(START, GOAL, fmap, np.random.default_rng(8))
    np.testing.assert_array_equal(a.path, b.path)
    assert a.cost == b.cost
    assert not np.array_equal(a.path, c.path)


@pytest.mark.parametrize('setting', ['2d', '3d-orient'])
def test_the_first_step_goes_toward_the_sample_farthest_from_the_tree(setting):
    """RandomConfiguration: of |C_RAND| uniform samples, the one farthest in task space."""
    arm = arm_for_setting(setting)
    start, goal = arm.random_configurations(np.random.default_rng(8), 2)
    planner = ProbRRT(arm, RRTSettings(iterations=1, n_random=50, p_goal=0.0, step=0.3))
    tree, _ = planner.grow(start, goal, planner.objective.coster(arm, FailureMap(
        arm.task_space)), np.random.default_rng(0))
    # the start tree's draws come first: its goal-bias coin, then its samples
    rng = np.random.default_rng(0)
    rng.random(1)
    samples = arm.lower + rng.random((50, arm.n_joints)) * (arm.upper - arm.lower)
    gaps = np.linalg.norm(arm.positions(samples) - arm.positions(start)[0], axis=1)
    farthest = samples[np.argmax(gaps)]
    assert tree.size == 2
    np.testing.assert_allclose(tree.nodes[1], start + (farthest - start) * 0.3 / np.linalg.norm(
        farthest - start), rtol=0, atol=1e-12)


@pytest.mark.parametrize('setting', ['2d', '3d-orient'])
def test_the_goal_bias_aims_each_tree_at_the_other_trees_root(setting):
    """P_GOAL = 1: every iteration steps toward the other root, so each tree reaches it."""
    arm = arm_for_setting(setting)
    start, goal = (START, GOAL) if setting == '2d' else \
        arm.random_configurations(np.random.default_rng(5), 2)
    iterations = int(np.ceil(np.linalg.norm(goal - start))) + 1       # steps of 1 rad
    planner = ProbRRT(arm, RRTSettings(iterations=iterations, p_goal=1.0))
    trees = planner.grow(start, goal, planner.objective.coster(arm, FailureMap(arm.task_space)),
                         np.random.default_rng(0))
    for tree, other_root in zip(trees, (goal, start)):
        gaps = np.linalg.norm(tree.nodes[:tree.size] - other_root, axis=1)
        assert gaps.min() < 1e-9, gaps


@pytest.mark.parametrize('setting', ['2d', '3d-orient'])
def test_compiled_costs_give_the_same_plans_as_the_reference(setting):
    """The speed-ups (compiled kernel, stepped trig, exact pruning) change no decision."""
    arm = arm_for_setting(setting)
    rng = np.random.default_rng(3)
    fmap = scattered_map(arm, rng, 19)
    settings = RRTSettings(iterations=25)
    start, goal = arm.random_configurations(rng, 2)
    for seed in range(2):
        fast = ProbRRT(arm, settings).plan(start, goal, fmap, np.random.default_rng(seed))
        slow = ProbRRT(arm, settings, coster_type=ReferenceEdgeCoster).plan(
            start, goal, fmap, np.random.default_rng(seed))
        np.testing.assert_array_equal(fast.path, slow.path)
        assert fast.cost == pytest.approx(slow.cost, rel=1e-9)


def test_the_python_loop_plans_as_the_compiled_one_with_few_neighbours():
    """The planar arm's loop (Python) adds the closest node to few neighbours as the compiled."""
    # with one to three RRT* neighbours the closest node is often not among them
    arm = arm_for_setting('3d-orient')
    rng = np.random.default_rng(3)
    fmap = scattered_map(arm, rng, 19)
    start, goal = arm.random_configurations(rng, 2)
    settings = RRTSettings(iterations=25, rewire_factor=0.2)
    for seed in range(2):
        fast = ProbRRT(arm, settings).plan(start, goal, fmap, np.random.default_rng(seed))
        slow = ProbRRT(arm, settings, compiled=False).plan(start, goal, fmap,
                                                           np.random.default_rng(seed))
        np.testing.assert_array_equal(fast.path, slow.path)
        assert fast.cost == slow.cost and fast.rewires == slow.rewires


def test_compiled_edge_costs_match_the_reference():
    for setting in ('2d', '3d', '3d-orient'):
        arm = arm_for_setting(setting)
        rng = np.random.default_rng(4)
        fmap = scattered_map(arm, rng, 7)
        sources = arm.random_configurations(rng, 30)
        target = arm.random_configurations(rng, 1)[0]
        for toward in (True, False):
            fast = EdgeCoster(arm, fmap).costs(sources, target, toward)
            slow = ReferenceEdgeCoster(arm, fmap).costs(sources, target, toward)
            np.testing.assert_allclose(fast, slow, rtol=1e-9)
        base = np.random.default_rng(5).uniform(0, 1, len(sources))
        index, total = EdgeCoster(arm, fmap).cheapest(sources, target, base=base)
        exact = ReferenceEdgeCoster(arm, fmap).costs(sources, target, base=base)
        assert index == np.argmin(exact) and total == pytest.approx(exact.min(), rel=1e-9)


def test_compiled_edge_costs_match_the_reference_on_edges_that_start_on_failures():
    # every failure at an edge's first point, held as there: distance 0 and the same
    # orientation (the arccos at the end of its range), each point's probability at its
    # largest, and each chunk's bound passes every failure
    for setting in ('3d', '3d-orient'):
        arm = arm_for_setting(setting)
        rng = np.random.default_rng(7)
        sources = arm.random_configurations(rng, 12)
        target = arm.random_configurations(rng, 1)[0]
        fmap = FailureMap(arm.task_space, 100.0)
        poses = arm.fk(sources)
        for i in range(len(sources)):
            q = None if poses.orientations is None else poses.orientations[i]
            fmap.add(poses.positions[i], rng.normal(size=arm.task_space.dim), q)
        assert fmap.probability(poses).min() == pytest.approx(1.0)
        for toward in (True, False):
            fast = EdgeCoster(arm, fmap).costs(sources, target, toward)
            slow = ReferenceEdgeCoster(arm, fmap).costs(sources, target, toward)
            np.testing.assert_allclose(fast, slow, rtol=1e-9)
        index, total = EdgeCoster(arm, fmap).cheapest(sources, target)
        exact = ReferenceEdgeCoster(arm, fmap).costs(sources, target)
        assert index == np.argmin(exact) and total == pytest.approx(exact.min(), rel=1e-9)


def test_compiled_costs_with_a_reach_match_the_reference_and_no_reach_is_the_paper():
    """Idea h's taper in the kernels is the map's, and an infinite reach changes no bit."""
    for setting in ('2d', '3d-orient'):
        arm = arm_for_setting(setting)
        rng = np.random.default_rng(6)
        fmap = scattered_map(arm, rng, 19)
        sources = arm.random_configurations(rng, 30)
        target = arm.random_configurations(rng, 1)[0]
        local = FailureProbabilityObjective(reach=0.25)
        fast = local.coster(arm, fmap).costs(sources, target)
        slow = local.coster(arm, fmap, coster_type=ReferenceEdgeCoster).costs(sources, target)
        np.testing.assert_allclose(fast, slow, rtol=1e-9)
        paper = FailureProbabilityObjective().coster(arm, fmap).costs(sources, target)
        np.testing.assert_array_equal(
            paper, FailureProbabilityObjective(reach=np.inf).coster(arm, fmap).costs(
                sources, target))
        assert (fast <= paper).all() and (fast < paper).any()


def test_hard_refuses_edges_above_its_threshold():
    fmap = wall_map()
    objective = HardThresholdObjective(0.01, c_fail=100.0)
    hard = objective.coster(PLANAR, fmap)
    assert hard.cost(START, GOAL) == np.inf
    away = START + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.2])
    points, _ = edge_points(START, away)
    if fmap.probability(PLANAR.fk(points)).max() <= 0.01:
        assert hard.cost(START, away) == pytest.approx(np.linalg.norm(away - START))
    hard_planner = make_planner('hard:0.3:100', PLANAR)
    plans = [hard_planner.plan(START, GOAL, fmap, np.random.default_rng(seed))
             for seed in range(6)]
    assert sum(plan is not None for plan in plans) >= 4    # 37-38 of 40 seeds plan
    for plan in filter(None, plans):
        for a, b in zip(plan.path[:-1], plan.path[1:]):
            points, _ = edge_points(a, b)
            assert fmap.probability(PLANAR.fk(points)).max() <= 0.3


def test_hard_draws_its_regions_with_its_own_c_fail():
    """Hard's C_FAIL, not the map's, decides how far ahead of a failure is forbidden."""
    fmap = wall_map()
    wide, narrow = HardThresholdObjective(0.01, 100.0), HardThresholdObjective(0.01, 1e4)
    assert wide.reach() == pytest.approx(np.sqrt(99 / 100))
    assert narrow.reach() == pytest.approx(np.sqrt(99 / 1e4))
    rng = np.random.default_rng(6)
    sources = PLANAR.random_configurations(rng, 40)
    for objective in (wide, narrow):
        fast = objective.coster(PLANAR, fmap).costs(sources, GOAL)
        slow = objective.coster(PLANAR, fmap, coster_type=ReferenceEdgeCoster).costs(
            sources, GOAL)
        np.testing.assert_allclose(fast, slow, rtol=1e-12)   # lengths or inf
    wide_ok = np.isfinite(wide.coster(PLANAR, fmap).costs(sources, GOAL))
    narrow_ok = np.isfinite(narrow.coster(PLANAR, fmap).costs(sources, GOAL))
    assert (narrow_ok >= wide_ok).all() and narrow_ok.sum() > wide_ok.sum()


def test_method_strings_are_parsed_and_built_in_one_place():
    assert str(Method.parse('hard:0.02:3000')) == 'hard:0.02:3000'
    assert Method.resolve('hard', threshold=0.05) == Method('hard', 0.05)
    assert Method.parse('probabilistic:300').map_c_fail() == 300.0
    assert Method.parse('epsilon:0.4').map_c_fail() == 100.0
    planner = Method.parse('hard:0.02:3000').planner(PLANAR)
    assert planner.objective == HardThresholdObjective(0.02, 3000.0)
    assert isinstance(Method.parse('epsilon:0.4').planner(PLANAR), EpsilonPlanner)
    with pytest.raises(ValueError, match='only hard takes'):
        Method.parse('epsilon:0.2:5')
    assert Method.parse('informed:ah').objective().reach == LOCAL_REACH
    assert Method.parse('informed:af').objective() == FailureProbabilityObjective()


def test_a_methods_parameters_reach_its_planner_and_its_map():
    """Each parameter of a method string or flag is the one its planner and map use."""
    assert Method.parse('epsilon:0.4').planner(PLANAR).epsilon == 0.4
    # only probabilistic sets the map's C_FAIL: Hard's Y is no C_FAIL
    assert Method.parse('hard:0.02').map_c_fail() == Method.parse('probabilistic').map_c_fail()
    assert Method.resolve('probabilistic', c_fail=300.0).map_c_fail() == 300.0
    settings = RRTSettings(iterations=1)
    for text in ('probabilistic', 'informed:a', 'informed:h'):
        method = Method.parse(text)
        assert method.planner(PLANAR, settings, length_weight=0.5).objective.length_weight == 0.5
        assert method.failure_map(PLANAR.task_space, c_fail=50.0).c_fail == 50.0


def test_an_objective_costs_with_the_planners_delta_and_a_reach_must_be_positive():
    fmap = wall_map()
    objective = FailureProbabilityObjective()
    coarse = objective.coster(PLANAR, fmap, 0.3)
    assert coarse.delta == 0.3
    assert coarse.cost(START, GOAL) != objective.coster(PLANAR, fmap).cost(START, GOAL)
    with pytest.raises(ValueError, match='reach'):
        FailureProbabilityObjective(reach=0.0)


def test_epsilon_ignores_the_map():
    planner = EpsilonPlanner(PLANAR, epsilon=0.5)
    for seed in range(10):
        a = planner.plan(START, GOAL, FailureMap(TaskSpace.POINT2), np.random.default_rng(seed))
        b = planner.plan(START, GOAL, wall_map(), np.random.default_rng(seed))
        np.testing.assert_array_equal(a.path, b.path)
        assert PLANAR.within_limits(a.path).all()
    straight = EpsilonPlanner(PLANAR, epsilon=1.0).plan(START, GOAL, wall_map(),
                                                        np.random.default_rng(0))
    np.testing.assert_array_equal(straight.path, [START, GOAL])


def test_epsilons_random_move_is_a_step_long_or_cut_at_a_limit_and_costs_its_length():
    planner = EpsilonPlanner(PLANAR, epsilon=0.0, step=0.5)
    for start in (START, PLANAR.upper - 0.1):           # the second cut at the limits
        lengths = []
        for seed in range(10):
            plan = planner.plan(start, GOAL, FailureMap(TaskSpace.POINT2),
                                np.random.default_rng(seed))
            lengths.append(np.linalg.norm(plan.path[-1] - start))
            assert plan.cost == pytest.approx(lengths[-1], rel=1e-12)
        assert max(lengths) <= 0.5 + 1e-12
    assert min(lengths) < 0.5


def test_epsilon_stays_where_no_move_keeps_the_arm_above_the_table(monkeypatch):
    from probdis_ros.planning import epsilon

    monkeypatch.setattr(epsilon, 'edge_above_table', lambda *args: False)
    planner = EpsilonPlanner(PLANAR, epsilon=0.5)
    plan = planner.plan(START, GOAL, FailureMap(TaskSpace.POINT2), np.random.default_rng(0))
    np.testing.assert_array_equal(plan.path, [START, START])
    assert plan.cost == 0.0


def test_bad_settings_and_configurations_are_refused():
    with pytest.raises(ValueError, match='p_goal'):
        RRTSettings(p_goal=2.0)
    with pytest.raises(ValueError, match='outside the joint limits'):
        ProbRRT(PLANAR).plan(START + 10, GOAL, FailureMap(TaskSpace.POINT2),
                             np.random.default_rng(0))
    with pytest.raises(ValueError, match='unknown method'):
        make_planner('magic', PLANAR)


def test_a_plan_time_budget_grows_more_and_no_budget_is_the_paper():
    fmap = wall_map()
    paper = ProbRRT(PLANAR).plan(START, GOAL, fmap, np.random.default_rng(4))
    zero = ProbRRT(PLANAR, RRTSettings(plan_time=0.0)).plan(
        START, GOAL, fmap, np.random.default_rng(4))
    np.testing.assert_array_equal(paper.path, zero.path)
    assert paper.tree_sizes[0] <= 101 and paper.tree_sizes[1] <= 101
    # at least 0.3 s: on a loaded machine (a plan in 30 ms, a budget of 0.14 s) the anytime
    # trees once grew 142 nodes against the paper's 185
    budget = max(0.3, 3 * paper.plan_time_s + 0.05)
    anytime = ProbRRT(PLANAR, RRTSettings(plan_time=budget)).plan(
        START, GOAL, fmap, np.random.default_rng(4))
    assert sum(anytime.tree_sizes) > sum(paper.tree_sizes)
    assert anytime.cost <= paper.cost * 1.5
    assert anytime.plan_time_s < 2.5 * budget       # it stops near the budget


def margin_box(arm, margin):
    """Return the joint limits shrunk by margin."""
    return arm.lower + margin, arm.upper - margin


def test_the_joint_margin_keeps_every_via_point_but_the_ends_inside_the_shrunk_limits():
    arm = arm_for_setting('3d-orient')
    margin = ROBOT_JOINT_MARGIN
    low, high = margin_box(arm, margin)
    rng = np.random.default_rng(31)
    fmap = scattered_map(arm, rng, 19)
    # start and goal inside the true limits but within the margin of them, joint by joint
    start = np.where(np.arange(7) % 2 == 0, arm.upper - 0.3 * margin, arm.lower + 0.01)
    goal = np.where(np.arange(7) % 2 == 0, arm.lower + 0.5 * margin, arm.upper - 1e-4)
    planner = ProbRRT(arm, RRTSettings(joint_margin=margin))
    vias = 0
    for seed in range(12):
        plan = planner.plan(start, goal, fmap, np.random.default_rng(seed))
        np.testing.assert_array_equal(plan.path[[0, -1]], [start, goal])
        inner = plan.path[1:-1]
        vias += len(inner)
        assert np.all((inner >= low) & (inner <= high))
        trees = planner.grow(start, goal, planner.objective.coster(arm, fmap),
                             np.random.default_rng(seed))
        for tree in trees:
            nodes = tree.nodes[1:tree.size]
            assert np.all((nodes >= low) & (nodes <= high))
    assert vias > 12                                  # the paths do have via points
    refined = ProbRRT(arm, RRTSettings(plan_time=0.2, joint_margin=margin)).plan(
        start, goal, fmap, np.random.default_rng(0))
    assert np.all((refined.path[1:-1] >= low) & (refined.path[1:-1] <= high))


def test_a_start_at_a_true_joint_limit_plans_into_the_shrunk_box():
    for setting in ('2d', '3d-orient'):
        arm = arm_for_setting(setting)
        low, high = margin_box(arm, ROBOT_JOINT_MARGIN)
        planner = ProbRRT(arm, RRTSettings(joint_margin=ROBOT_JOINT_MARGIN))
        plan = planner.plan(arm.upper, arm.lower, FailureMap(arm.task_space),
                            np.random.default_rng(1))
        assert plan is not None
        np.testing.assert_array_equal(plan.path[[0, -1]], [arm.upper, arm.lower])
        assert np.all((plan.path[1:-1] >= low) & (plan.path[1:-1] <= high))


def test_samples_keep_the_margin_and_no_margin_is_the_plain_uniform_draw():
    arm = arm_for_setting('3d-orient')
    plain = arm.random_configurations(np.random.default_rng(2), 5000)
    np.testing.assert_array_equal(
        plain, np.random.default_rng(2).uniform(arm.lower, arm.upper, (5000, 7)))
    low, high = margin_box(arm, 0.2)
    shrunk = arm.random_configurations(np.random.default_rng(2), 5000, 0.2)
    assert np.all((shrunk >= low) & (shrunk <= high))
    assert np.all(shrunk.min(axis=0) < low + 0.01) and np.all(shrunk.max(axis=0) > high - 0.01)


@pytest.mark.parametrize('method', ['probabilistic', 'informed'])
def test_a_joint_range_keeps_the_trees_probes_and_paths_in_the_cells_room(method):
    # A1 within +-0.6 rad keeps the arm in front of its base: every node of both trees,
    # every probe and every via point of the path stays within the range; a start outside
    # it (the arm where it is) plans into it
    from probdis_ros.planning import Method

    arm = arm_for_setting('3d-orient')
    lower, upper = arm.lower.copy(), arm.upper.copy()
    lower[0], upper[0] = -0.6, 0.6
    settings = RRTSettings(joint_margin=ROBOT_JOINT_MARGIN, joint_lower=tuple(lower),
                           joint_upper=tuple(upper))
    planner = Method.parse(method).planner(arm, settings)
    low, high = np.maximum(lower, arm.lower + ROBOT_JOINT_MARGIN), \
        np.minimum(upper, arm.upper - ROBOT_JOINT_MARGIN)
    np.testing.assert_array_equal((planner.low, planner.high), (low, high))
    fmap = scattered_map(arm, np.random.default_rng(3), 19)
    start = np.array([1.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0])        # A1 outside the range
    goal = np.array([-0.4, 0.3, 0.2, -1.0, 0.1, 0.9, 0.2])
    for seed in range(3):
        plan = planner.plan(start, goal, fmap, np.random.default_rng(seed))
        inner = plan.path[1:]
        assert np.all((inner >= low - 1e-12) & (inner <= high + 1e-12)), inner[:, 0]
        trees = planner.grow(start, goal, planner.objective.coster(arm, fmap),
                             np.random.default_rng(seed))
        for tree in trees:
            nodes = tree.nodes[1:tree.size]
            assert len(nodes) and np.all((nodes >= low - 1e-12) & (nodes <= high + 1e-12))
    # without a range the same planner goes beyond it
    free = Method.parse(method).planner(arm, RRTSettings(joint_margin=ROBOT_JOINT_MARGIN))
    trees = free.grow(start, goal, free.objective.coster(arm, fmap), np.random.default_rng(0))
    assert np.abs(trees[0].nodes[1:trees[0].size, 0]).max() > 0.6
    # Epsilon's random steps keep to it too
    epsilon = Method.parse('epsilon:0.01').planner(arm, settings)
    ends = np.array([epsilon.plan(start, goal, fmap, np.random.default_rng(k)).path[-1]
                     for k in range(50)])
    moved = ends[np.any(ends != start, axis=1)]     # (a step through the table stays put)
    assert len(moved) > 25 and np.all((moved >= low) & (moved <= high))
    with pytest.raises(ValueError, match='no room'):
        ProbRRT(arm, RRTSettings(joint_lower=tuple(upper), joint_upper=tuple(lower)))
    with pytest.raises(ValueError, match='7 values'):
        ProbRRT(arm, RRTSettings(joint_lower=(0.0, 1.0)))


@pytest.mark.parametrize('side', ['lower', 'upper'])
def test_a_joint_range_on_one_side_alone_keeps_the_trees_in_it(side):
    """Without a margin, a range on one side alone still clips the steps from a start outside."""
    arm = arm_for_setting('3d-orient')
    sign = 1.0 if side == 'upper' else -1.0
    bound = (arm.upper if side == 'upper' else arm.lower).copy()
    bound[0] = 0.6 * sign
    planner = ProbRRT(arm, RRTSettings(iterations=20, **{f'joint_{side}': tuple(bound)}))
    start = np.array([1.0 * sign, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0])   # A1 beyond the range
    goal = np.array([-0.4 * sign, 0.3, 0.2, -1.0, 0.1, 0.9, 0.2])
    fmap = scattered_map(arm, np.random.default_rng(3), 19)
    for seed in range(2):
        trees = planner.grow(start, goal, planner.objective.coster(arm, fmap),
                             np.random.default_rng(seed))
        for tree in trees:
            beyond = sign * (tree.nodes[1:tree.size, 0] - bound[0])
            assert tree.size > 1 and np.all(beyond <= 1e-12), beyond.max()


def test_a_margin_without_room_or_below_zero_is_refused():
    with pytest.raises(ValueError, match='joint_margin'):
        RRTSettings(joint_margin=-0.01)
    with pytest.raises(ValueError, match='no room'):
        ProbRRT(PLANAR, RRTSettings(joint_margin=3.0))


def test_a_block_met_while_turning_in_place_is_learned_with_a_direction():
    """Turning the last joint alone leaves the flange point still: the object's lever moves."""
    from probdis_ros.planning.disentangle import failure_from_block

    arm = arm_for_setting('3d-orient')
    config = np.array([0.1, 0.5, 0.2, -1.0, 0.3, 0.8, 0.2])
    turn = np.zeros(7)
    turn[6] = 0.5
    x, v, q = failure_from_block(arm, config, turn)
    assert np.linalg.norm(v) > 1e-6
    fmap = FailureMap(arm.task_space)
    fmap.add(x, v, q)           # refused before: 'a nonzero finite direction'
    assert len(fmap) == 1
    # a motion of the flange point itself keeps its own direction, as before
    step = np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    x, v, _ = failure_from_block(arm, config, step)
    ahead = arm.fk(config[None] + 1e-3 * step / 0.3).positions[0] - x
    assert np.dot(v, ahead) > 0


def test_a_plan_from_the_goal_is_the_goal_alone_and_a_target_of_the_wrong_size_is_refused():
    # Connect joins goal-tree leaves only: from the goal itself it returned a detour of ~2 rad
    arm = arm_for_setting('3d-orient')
    q = np.array([0.3, 0.5, 0.1, -1.2, 0.2, 0.6, 0.1])
    plan = ProbRRT(arm, RRTSettings(iterations=10)).plan(q, q.copy(), FailureMap(
        arm.task_space), np.random.default_rng(0))
    assert plan.cost == 0.0 and np.array_equal(plan.path, q[None])
    # the compiled kernels read a target by the arm's joint count, unchecked
    coster = EdgeCoster(arm, FailureMap(arm.task_space))
    with pytest.raises(ValueError, match='7 joint values, has 6'):
        coster.costs(q[None], q[:6])
