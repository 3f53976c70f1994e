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

"""The informed method: its parsing, each idea doing what it says, and that it does better."""

import numpy as np
from probdis_ros.model import arm_for_setting, FailureMap, TaskSpace
from probdis_ros.model.arms import quaternion_to_rotation, rotation_to_quaternion, TaskPoints
from probdis_ros.model.informed_map import InformedMap, MapIdeas
from probdis_ros.planning import Disentangler, Method, RRTSettings
from probdis_ros.planning.informed import BUDGET_FACTOR, DEFAULT_IDEAS, InformedDisentangler
from probdis_ros.planning.prob_rrt import ProbRRT
from probdis_ros.planning.probes import (
    _vee,
    even_directions,
    last_joint_axis,
    probe_chains,
    ProbeRRT,
    ProbeSettings,
    rotations,
)
import pytest

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
ORIGIN = np.zeros(3)
PUSH = np.array([1.0, 0.0, 0.0])        # the blocked motion: along +x, wall in the y-z plane


def poses(*points) -> TaskPoints:
    """Return task-space poses at points, all with the identity orientation."""
    points = np.array(points, dtype=float)
    return TaskPoints(points, np.tile(IDENTITY, (len(points), 1)))


def one_failure(ideas: MapIdeas | None = None) -> FailureMap:
    """Return a map with one failure at the origin, moving along +x."""
    fmap = FailureMap(TaskSpace.POSE3) if ideas is None else InformedMap(TaskSpace.POSE3,
                                                                         ideas=ideas)
    fmap.add(ORIGIN, PUSH, IDENTITY)
    return fmap


# -- parsing -----------------------------------------------------------------------------

@pytest.mark.parametrize('text, ideas, shown', [
    ('informed', DEFAULT_IDEAS, f'informed:{DEFAULT_IDEAS}'),
    ('informed:b', 'b', 'informed:b'),
    ('informed:eba', 'abe', 'informed:abe'),
    (' informed:abce ', 'abce', 'informed:abce'),
])
def test_informed_parses_its_ideas(text, ideas, shown):
    method = Method.parse(text)
    assert (method.name, method.ideas, str(method)) == ('informed', ideas, shown)
    assert Method.parse(str(method)) == method
    assert method.idea_letters == (ideas or DEFAULT_IDEAS)
    assert method.map_c_fail() == Method.parse('probabilistic').map_c_fail()


@pytest.mark.parametrize('text', ['informed:x', 'informed:aa', 'informed:a:3',
                                  'informed:hh', 'informed:g', 'informed:eg',
                                  'informed:i', 'informed:adi', 'informed:1',
                                  'informed:aj', 'informed:adj', 'informed:afj'])
def test_informed_refuses_unknown_ideas(text):
    with pytest.raises(ValueError, match='informed'):
        Method.parse(text)


def test_the_planner_node_takes_the_planners_ideas_and_the_bare_names_parameters():
    assert Method.for_node('informed:adfhi').idea_letters == 'adfhi'
    assert Method.for_node('informed') == Method('informed')
    assert Method.for_node('hard', threshold=0.02) == Method('hard', 0.02)
    assert Method.for_node('hard:0.03', threshold=0.02) == Method('hard', 0.03)
    for bad in ('informed:ab', 'informed:cf', 'informed:e'):
        with pytest.raises(ValueError, match='map'):
            Method.for_node(bad)
    with pytest.raises(ValueError, match='unknown'):
        Method.for_node('sideways')
    # the node's C_FAIL is its c_fail parameter: probabilistic:50 was taken and its 50 dropped
    with pytest.raises(ValueError, match='takes C_FAIL from its c_fail parameter'):
        Method.for_node('probabilistic:50')
    # a threshold or epsilon of 0 (the node's parameter ranges allow it) as hard:0 is refused
    for name, values in (('hard', {'threshold': 0.0}), ('epsilon', {'epsilon': 0.0})):
        with pytest.raises(ValueError, match=rf'{name} takes a parameter in \(0, 1\]'):
            Method.for_node(name, **values)


def test_bare_names_resolve_to_informed_with_its_default_ideas():
    assert Method.resolve('informed') == Method('informed')
    assert Method.from_parameters('informed').idea_letters == DEFAULT_IDEAS


def test_probabilistic_keeps_the_papers_map_and_loop():
    method = Method.parse('probabilistic')
    arm = arm_for_setting('2d')
    fmap = method.failure_map(arm.task_space)
    assert type(fmap) is FailureMap
    loop = method.disentangler(arm, method.planner(arm), np.zeros(7), fmap)
    assert type(loop) is Disentangler


@pytest.mark.parametrize('ideas, expected', [
    ('b', MapIdeas(surface=True)), ('c', MapIdeas(free=True)), ('e', MapIdeas(adaptive=True)),
    ('abce', MapIdeas(surface=True, free=True, adaptive=True))])
def test_each_map_idea_is_switched_by_its_own_letter(ideas, expected):
    fmap = Method.parse(f'informed:{ideas}').failure_map(TaskSpace.POSE3)
    assert isinstance(fmap, InformedMap) and fmap.ideas == expected
    assert type(Method.parse('informed:adfhij').failure_map(TaskSpace.POSE3)) is FailureMap


# -- idea a: budget ------------------------------------------------------------------------

def test_idea_a_multiplies_the_iterations_and_nothing_else():
    arm = arm_for_setting('2d')
    settings = RRTSettings(iterations=30, n_random=20)
    budget = Method.parse('informed:a').planner(arm, settings).settings
    assert budget.iterations == BUDGET_FACTOR * 30
    assert budget.n_random == 20
    assert Method.parse('informed:b').planner(arm, settings).settings.iterations == 30


# -- idea b: failures on one wall spread along the surface they reveal ------------------------

# three blocks a few cm apart on the wall x = 0, hit at different angles
HITS = ((ORIGIN, np.array([1.0, 0.4, 0.0])),
        (np.array([0.0, 0.04, 0.0]), np.array([1.0, -0.3, 0.0])),
        (np.array([0.0, 0.02, 0.03]), np.array([0.8, 0.0, -0.5])))


def wall(ideas: MapIdeas | None = None) -> FailureMap:
    """Return a map of the three blocks on the wall x = 0."""
    fmap = FailureMap(TaskSpace.POSE3) if ideas is None else InformedMap(TaskSpace.POSE3,
                                                                         ideas=ideas)
    for x, v in HITS:
        fmap.add(x, v, IDENTITY)
    return fmap


def lone_spot(fmap: InformedMap) -> np.ndarray:
    """Return the virtual failure farthest from every real one."""
    virtual = fmap.points[fmap.virtual]
    gaps = np.linalg.norm(virtual[:, None] - fmap.points[~fmap.virtual], axis=2).min(axis=1)
    return virtual[int(np.argmax(gaps))]


def test_idea_b_one_failure_stays_a_point():
    assert one_failure(MapIdeas(surface=True)).virtual.sum() == 0


def test_idea_b_spreads_along_the_wall_and_stays_narrow_across_it():
    paper = wall()
    surface = wall(MapIdeas(surface=True))
    assert len(surface) == 3                        # three real failures, the rest virtual
    virtual = surface.points[surface.virtual]
    assert len(virtual) > 10
    np.testing.assert_allclose(virtual @ PUSH, 0.0, atol=1e-12)     # on the wall's plane
    # facing the wall, whatever angle the blocks came at
    np.testing.assert_allclose(surface.directions[surface.virtual] @ PUSH, 1.0)
    reach = np.linalg.norm(virtual[:, None] - [x for x, _ in HITS], axis=2).min(axis=1)
    assert reach.max() <= MapIdeas().surface_radius + 1e-9
    beyond = poses([0.03, -0.02, 0.0], [0.03, 0.06, 0.01], [0.02, 0.02, 0.05],
                   [0.03, 0.02, -0.03])      # 2-3 cm beyond the wall, around the blocks
    assert np.all(surface.probability(beyond) > 0.6)
    assert np.all(paper.probability(beyond) < 0.4)
    # in front of the wall (where the arm came from) the map stays low, as the paper's
    behind = poses([-0.05, 0.0, 0.0], [-0.04, 0.03, 0.0])
    assert np.all(surface.probability(behind) < 0.1)
    far = poses([0.01, 0.3, 0.0])                   # the wall is not assumed to go on forever
    assert surface.probability(far)[0] < 0.1


def test_idea_b_needs_one_wall():
    # two blocks, the second moving along the first one's wall: no surface
    fmap = InformedMap(TaskSpace.POSE3, ideas=MapIdeas(surface=True))
    fmap.add(ORIGIN, PUSH, IDENTITY)
    fmap.add([0.0, 0.04, 0.0], [0.1, 1.0, 0.0], IDENTITY)
    assert fmap.virtual.sum() == 0


def test_idea_b_off_keeps_the_papers_probabilities():
    points = poses(*np.random.default_rng(0).normal(scale=0.05, size=(50, 3)))
    np.testing.assert_array_equal(wall(MapIdeas()).probability(points),
                                  wall().probability(points))


# -- idea c: free motion refutes the virtual failures it went beyond -------------------------

def test_idea_c_drops_virtual_failures_where_the_object_moved_freely():
    fmap = wall(MapIdeas(surface=True, free=True))
    count = fmap.virtual.sum()
    spot = lone_spot(fmap)
    beyond = poses(spot + 0.01 * PUSH)
    before = fmap.probability(beyond)[0]
    # the object passed through the wall's plane there: the wall does not reach that far
    fmap.observe_free(spot + np.outer([-0.02, 0.0, 0.01], PUSH), np.tile(IDENTITY, (3, 1)))
    assert len(fmap) == 3                            # the real failures stay
    assert 0 < count - fmap.virtual.sum() < count / 2
    assert fmap.probability(beyond)[0] < 0.5 * before


def test_idea_c_ignores_motion_in_front_of_the_wall_or_turned_otherwise():
    fmap = wall(MapIdeas(surface=True, free=True))
    count = fmap.virtual.sum()
    spot = lone_spot(fmap)
    turned = np.array([np.cos(0.5), np.sin(0.5), 0.0, 0.0])     # 1 rad about x
    fmap.observe_free(spot - np.outer([0.01, 0.02], PUSH), np.tile(IDENTITY, (2, 1)))  # front
    fmap.observe_free((spot + 0.01 * PUSH)[None], turned[None])                # beyond, turned
    assert fmap.virtual.sum() == count


def test_idea_c_keeps_a_refuted_spot_free_of_later_virtual_failures():
    surface = wall(MapIdeas(surface=True))
    count, spot = surface.virtual.sum(), lone_spot(surface)
    fmap = InformedMap(TaskSpace.POSE3, ideas=MapIdeas(surface=True, free=True))
    fmap.observe_free((spot + 0.01 * PUSH)[None], IDENTITY[None])
    for x, v in HITS:
        fmap.add(x, v, IDENTITY)
    assert 0 < count - fmap.virtual.sum() < count / 2


def test_informed_loop_reports_the_free_part_of_a_blocked_path():
    arm = arm_for_setting('2d')
    method = Method.parse('informed:bc')
    fmap = method.failure_map(arm.task_space)
    start = np.array([np.pi / 2 + 0.6, 0, 0, 0, 0, 0, 0])
    goal = np.array([np.pi / 2 - 0.6, 0, 0, 0, 0, 0, 0])
    loop = method.disentangler(arm, method.planner(arm, RRTSettings(iterations=20)), goal,
                               fmap)
    assert isinstance(loop, InformedDisentangler)
    path = loop.next_path(start)
    blocked = path[0] + 0.5 * (path[1] - path[0])
    loop.report_blocked(blocked, 0)
    assert len(fmap) == 1 and len(fmap.free_points) > 10
    np.testing.assert_allclose(fmap.free_points[-1], arm.fk(blocked).positions[0])


# -- idea e: repeated failures widen the map ---------------------------------------------------

def test_idea_e_widens_the_map_when_failures_repeat():
    fmap = one_failure(MapIdeas(adaptive=True))
    c0 = fmap.c_fail
    fmap.add([0.3, 0.0, 0.0], PUSH, IDENTITY)            # far away: no repeat
    fmap.add([0.0, 0.0, 0.02], -PUSH, IDENTITY)          # near, opposite way: no repeat
    assert fmap.c_fail == c0
    fmap.add([0.0, 0.006, 0.0], PUSH, IDENTITY)          # 6 mm aside, same way: a repeat
    assert fmap.c_fail < c0
    far = poses([0.1, 0.05, 0.0])
    assert fmap.probability(far)[0] > one_failure().probability(far)[0]
    for k in range(30):
        fmap.add([0.0, 0.001 * k, 0.0], PUSH, IDENTITY)
    assert fmap.c_fail == MapIdeas().c_fail_min


# -- ideas d and f: straight probes around the start, turning first with f ------------------

# an iiwa configuration with room to move (its flange ~0.5 m out, 0.5 m up)
IIWA_START = np.array([0.3, 0.6, -0.2, -1.4, 0.2, 0.9, 0.1])


def test_idea_d_probes_follow_straight_lines_from_the_start():
    arm = arm_for_setting('3d-orient')
    settings = ProbeSettings()
    directions = even_directions(12, 3)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0)
    chains = probe_chains(arm, IIWA_START, directions, settings)
    x0 = arm.positions(IIWA_START)[0]
    long = 0
    for direction, chain in zip(directions, chains):
        if not len(chain):
            continue
        offsets = arm.positions(chain) - x0
        along = offsets @ direction
        aside = np.linalg.norm(offsets - np.outer(along, direction), axis=1)
        assert aside.max() < settings.tolerance
        assert np.all(np.diff(along) > 0) and along[-1] <= settings.length + settings.tolerance
        assert np.all(np.linalg.norm(np.diff(np.vstack([IIWA_START, chain]), axis=0),
                                     axis=1) <= settings.joint_step + 0.1)
        long += along[-1] > 0.3
    assert long >= 6
    # from a cramped start most chains stray before their end: each ends there, and none
    # goes on farther along its line once the arm can follow it again (a gap, then a jump)
    cramped = np.array([0.813, -0.964, -2.724, -2.025, 1.859, 1.729, 0.651])
    x0 = arm.positions(cramped)[0]
    directions = even_directions(32, 3)
    for direction, chain in zip(directions, probe_chains(arm, cramped, directions, settings)):
        along = np.concatenate([[0.0], (arm.positions(chain) - x0) @ direction])
        assert np.all(np.diff(along) <= settings.spacing + 2 * settings.tolerance), along


def test_idea_f_probes_turn_in_place_then_go_straight():
    arm = arm_for_setting('3d-orient')
    directions = even_directions(8, 3)
    axes = np.roll(directions, 1, axis=1)
    chains = probe_chains(arm, IIWA_START, directions, ProbeSettings(), axes=axes)
    start = arm.fk(IIWA_START)
    turned = 0
    for chain in chains:
        if not len(chain):
            continue
        pose = arm.fk(chain)
        turn = 2 * np.arccos(np.clip(np.abs(pose.orientations @ start.orientations[0]), 0, 1))
        away = np.linalg.norm(pose.positions - start.positions[0], axis=1)
        # it turns where it stands, then goes without turning back
        standing = away < 0.01
        assert standing[0] and np.all(np.diff(standing.astype(int)) <= 0)
        assert np.all(turn[~standing] >= turn[standing].max() - 0.2)
        turned += turn[-1] > np.pi / 3 and away[-1] > 0.2
    assert turned >= 3


def test_idea_i_turns_the_probes_about_the_wrist_each_way_where_f_turns_about_any_axis():
    arm = arm_for_setting('3d-orient')
    settings = RRTSettings(iterations=1, n_random=5)
    start = arm.fk(IIWA_START)
    axis = last_joint_axis(arm, IIWA_START)
    np.testing.assert_allclose(axis, arm.tip_frames(IIWA_START)[1][0][:, 2], atol=1e-6)

    def turns_in_place(ideas: str) -> np.ndarray:
        """Return the unit rotation vectors of the start tree's nodes still at the start."""
        planner = Method.parse(f'informed:{ideas}').planner(arm, settings)
        coster = planner.objective.coster(arm, FailureMap(arm.task_space), settings.delta)
        tree = planner.grow(IIWA_START, -0.5 * IIWA_START, coster, np.random.default_rng(0))[0]
        rot = arm.tip_frames(tree.nodes[1:tree.size])[1]
        near = np.linalg.norm(arm.positions(tree.nodes[1:tree.size]) - start.positions[0],
                              axis=1) < 0.005
        vectors = _vee(rot[near] @ arm.tip_frames(IIWA_START)[1][0].T)
        turned = np.linalg.norm(vectors, axis=1) > 0.3
        return vectors[turned] / np.linalg.norm(vectors[turned], axis=1, keepdims=True)

    rolls = turns_in_place('fi') @ axis
    assert len(rolls) >= 8
    assert np.all(np.abs(rolls) > 0.99)                 # about the wrist's axis ...
    assert (rolls > 0).sum() >= 4 and (rolls < 0).sum() >= 4      # ... each way
    assert np.median(np.abs(turns_in_place('f') @ axis)) < 0.9    # f: about random axes


def test_idea_j_offers_straight_probes_only_once_a_turned_object_was_blocked_nearby():
    arm = arm_for_setting('3d-orient')
    settings = RRTSettings(iterations=1, n_random=5)
    pose = arm.fk(IIWA_START)
    x0, q0 = pose.positions[0], pose.orientations[0]
    ahead = np.array([0.0, 0.0, 1.0])
    turn = rotations(np.array([[1.0, 0.0, 0.0]]), np.deg2rad(45.0))[0]   # 45 degrees
    turned = rotation_to_quaternion(turn @ quaternion_to_rotation(q0)[0])[0]
    assert np.isclose(2 * np.arccos(min(1.0, abs(turned @ q0))), np.deg2rad(45.0))

    def start_tree(ideas: str, *failures) -> np.ndarray:
        fmap = FailureMap(arm.task_space)
        for x, q in failures:
            fmap.add(x, ahead, q)
        planner = Method.parse(f'informed:{ideas}').planner(arm, settings)
        coster = planner.objective.coster(arm, fmap, settings.delta)
        tree = planner.grow(IIWA_START, -0.5 * IIWA_START, coster, np.random.default_rng(0))[0]
        return tree.nodes[:tree.size]

    near_held, near_turned = (x0 + 0.1 * ahead, q0), (x0 + 0.1 * ahead, turned)
    far_turned = (x0 + 0.6 * ahead, turned)             # beyond the probes' reach
    # the same draws either way: without the straight probes, the tree of f and i alone
    for failures in ((), (near_held,), (far_turned,)):
        np.testing.assert_array_equal(start_tree('adfij', *failures),
                                      start_tree('afi', *failures))
    # a turned object blocked within reach: the straight probes too, as d, f and i offer them
    np.testing.assert_array_equal(start_tree('adfij', near_turned, far_turned),
                                  start_tree('adfi', near_turned, far_turned))
    assert len(start_tree('adfi', near_turned)) > len(start_tree('afi', near_turned))


def test_ideas_d_and_f_hang_probes_from_the_start_tree_only():
    arm = arm_for_setting('3d-orient')
    settings = RRTSettings(iterations=5, n_random=5)
    assert type(Method.parse('probabilistic').planner(arm, settings)) is ProbRRT
    assert type(Method.parse('informed:a').planner(arm, settings)) is ProbRRT
    sizes = {}
    for ideas in ('d', 'f', 'df'):
        planner = Method.parse(f'informed:{ideas}').planner(arm, settings)
        assert isinstance(planner, ProbeRRT)
        coster = planner.objective.coster(arm, FailureMap(arm.task_space), settings.delta)
        start, goal = planner.grow(IIWA_START, -0.5 * IIWA_START, coster,
                                   np.random.default_rng(0))
        assert goal.size <= 6 < start.size
        sizes[ideas] = start.size
        np.testing.assert_array_equal(start.nodes[0], IIWA_START)
        assert len(start.children[0]) > 16            # each chain hangs from the root
    assert sizes['df'] > max(sizes['d'], sizes['f'])
    # without orientation a turn is no turn: f alone offers the straight probes
    arm = arm_for_setting('3d')
    planner = Method.parse('informed:f').planner(arm, settings)
    coster = planner.objective.coster(arm, FailureMap(arm.task_space), settings.delta)
    assert planner.grow(IIWA_START, -0.5 * IIWA_START, coster,
                        np.random.default_rng(0))[0].size > 6 + 16


def test_the_probes_point_elsewhere_at_every_plan():
    """The lattice of directions is turned by a draw per plan, not the same at every plan."""
    arm = arm_for_setting('3d-orient')
    planner = Method.parse('informed:d').planner(arm, RRTSettings(iterations=1, n_random=1))
    coster = planner.objective.coster(arm, FailureMap(arm.task_space))
    trees = [planner.grow(IIWA_START, -0.5 * IIWA_START, coster, np.random.default_rng(seed))[0]
             for seed in (0, 1)]
    first = [tree.nodes[tree.children[0]] for tree in trees]
    assert not np.array_equal(first[0][:10], first[1][:10])


def test_idea_d_offers_a_straight_way_out_in_almost_every_direction():
    # a start tree of one iteration: what it holds beyond the root are the probes
    arm = arm_for_setting('3d-orient')
    settings = RRTSettings(iterations=1, n_random=1)
    x0 = arm.positions(IIWA_START)[0]
    asked = even_directions(40, 3) @ np.array([[0.0, 0.6, 0.8], [1.0, 0.0, 0.0],
                                              [0.0, 0.8, -0.6]])

    def covered(method: str) -> int:
        planner = Method.parse(method).planner(arm, settings)
        coster = planner.objective.coster(arm, FailureMap(arm.task_space), settings.delta)
        tree, _ = planner.grow(IIWA_START, -0.5 * IIWA_START, coster, np.random.default_rng(1))
        out = tree.positions[:tree.size] - x0
        reach = np.linalg.norm(out, axis=1)
        out = out[reach > 0.2] / reach[reach > 0.2, None]
        return int(np.sum(np.max(asked @ out.T, axis=1, initial=-1.0) > np.cos(0.4)))

    assert covered('informed:d') >= 30 > 5 >= covered('probabilistic')


def test_idea_g_offers_no_probe_toward_a_failure_within_reach():
    arm = arm_for_setting('3d-orient')
    planner = Method.parse('informed:dg').planner(arm, RRTSettings(iterations=1, n_random=1))
    pose = arm.fk(IIWA_START)
    x0, q0 = pose.positions[0], pose.orientations[0]
    directions = even_directions(32, 3)
    ahead = directions[5]
    fmap = FailureMap(arm.task_space)
    fmap.add(x0 + 0.1 * ahead, ahead, q0)
    keep = planner._untried(directions, x0, fmap)
    assert not keep[5] and keep.sum() >= len(directions) - 3
    far = FailureMap(arm.task_space)
    far.add(x0 + 0.6 * ahead, ahead, q0)                    # beyond the probes' reach
    assert planner._untried(directions, x0, far).all()
    # two failures in two directions: neither direction keeps its probe
    fmap.add(x0 + 0.2 * directions[20], directions[20], q0)
    keep = planner._untried(directions, x0, fmap)
    assert not keep[5] and not keep[20] and keep.sum() >= len(directions) - 6
    # without g every direction keeps its probe
    straight = Method.parse('informed:d').planner(arm, RRTSettings(iterations=1, n_random=1))
    assert straight._untried(directions, x0, fmap).all()


# -- the method does better than the paper's on family worlds ---------------------------------

# training worlds (seeds 1000 and up, never the evaluation seeds 0-99) on which the sweep of
# training worlds saw the paper's method take many paths, one or two of each family (the
# paper's method within 20 paths: hook_bar 1027 in 12, plate_hole 1025 and 1028 not at
# all; informed in 2 each): a regression check, not a measure
BEATEN = (('closed_box', 1004), ('closed_box', 1008), ('clutter', 1008), ('open_box', 1007),
          ('hook_bar', 1027), ('plate_hole', 1025), ('plate_hole', 1028))
MAX_PATHS = 8


def test_informed_beats_probabilistic_on_a_few_family_worlds():
    from probdis_ros.sim.episode import run_episode
    from probdis_ros.sim.families import random_family_world

    def score(method: str) -> tuple[int, int]:
        solved, paths = 0, 0
        for family, seed in BEATEN:
            result = run_episode(random_family_world(family, seed), method, seed=seed,
                                 max_paths=MAX_PATHS)
            solved += result.success
            paths += result.paths if result.success else MAX_PATHS + 1
        return solved, paths

    informed, paper = score('informed'), score('probabilistic')
    assert informed[0] > paper[0]
    assert informed[1] < paper[1]


# evaluation episodes whose records RESULTS.md's tables are made of: the paper's settings
# (sweep seed 0) and the families (seeds 0-99 of each), of episodes that end within seconds
# (the families since the robot's table: results/families_table/)
RECORDS = {'probabilistic': 'results/families_table/episodes.jsonl',
           'informed:adfhij': 'results/families_table/informed_eval/episodes.jsonl',
           'settings': 'results/sweep/episodes.jsonl'}


def assert_recorded_episodes_rerun_alike(path: str, method: str, keys) -> None:
    """Run the episodes again and compare what the tables count with the records."""
    import json
    from pathlib import Path

    from probdis_ros.experiments.sweep import EpisodeKey, run_episode_record

    text = (Path(__file__).resolve().parents[1] / path).read_text()
    records = {(r['family'] or r['setting'], r['obstacles'], r['world']): r
               for r in map(json.loads, text.splitlines()) if r['method'] == method}
    for where, obstacles, world in keys:
        recorded = records[(where, obstacles, world)]
        key = EpisodeKey(recorded['setting'], obstacles, world, method, recorded['sweep_seed'],
                         recorded['family'])
        again = run_episode_record(key, recorded['max_paths'])
        fields = ('success', 'paths', 'failures', 'empty_plans')
        assert [again[f] for f in fields] == [recorded[f] for f in fields], (where, world)


@pytest.mark.parametrize('family', ['open_box', 'closed_box', 'plate_hole', 'hook_bar',
                                    'clutter'])
def test_the_recorded_family_episodes_come_out_the_same_again(family):
    """The paper's method path for path as recorded, and the default method as evaluated."""
    for method in ('probabilistic', 'informed:adfhij'):
        assert_recorded_episodes_rerun_alike(RECORDS[method], method,
                                             [(family, 0, 1), (family, 0, 2)])


@pytest.mark.parametrize('setting', ['2d', '3d', '3d-orient'])
def test_the_recorded_paper_settings_come_out_the_same_again(setting):
    """The paper's method and Hard in the paper's settings (30 obstacles) as recorded."""
    for method in ('probabilistic', 'hard:0.01'):
        assert_recorded_episodes_rerun_alike(RECORDS['settings'], method,
                                             [(setting, 30, w) for w in range(3)])


def test_idea_g_with_every_direction_tried_plans_without_probes():
    # failures all around the start leave idea g no untried direction: the plan crashed
    # reshaping an empty set of probes
    for setting, method in (('3d-orient', 'informed:dg'), ('3d', 'informed:adfghij')):
        arm = arm_for_setting(setting)
        start = np.array([0.3, 0.5, 0.1, -1.2, 0.2, 0.6, 0.1])
        pose = arm.fk(start)
        fmap = FailureMap(arm.task_space)
        q = None if pose.orientations is None else pose.orientations[0]
        for d in even_directions(24, arm.task_space.dim):
            fmap.add(pose.positions[0] + 0.1 * d, d, q)
        planner = Method.parse(method).planner(arm, RRTSettings(iterations=10))
        plan = planner.plan(start, np.zeros(7), fmap, np.random.default_rng(0))
        assert plan is not None and np.array_equal(plan.path[0], start)
