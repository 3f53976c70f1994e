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

"""The disentangling loop, the compliant simulated arm, worlds and scenario files."""

import numpy as np
from probdis_ros.model import arm_for_setting
from probdis_ros.planning import Disentangler, EpsilonPlanner, State
from probdis_ros.sim.compliant_arm import CompliantArm
from probdis_ros.sim.episode import run_episode
from probdis_ros.sim.obstacles import Obstacle
from probdis_ros.sim.worlds import load_world, random_world, ScenarioError, World
import pytest

PLANAR = arm_for_setting('2d')
IIWA = arm_for_setting('3d')
# the stretched-out planar arm swings its base joint: the tip runs along a circle of 0.7 m
START = np.array([np.pi / 2 + 0.6, 0, 0, 0, 0, 0, 0])
GOAL = np.array([np.pi / 2 - 0.6, 0, 0, 0, 0, 0, 0])
BLOCKER = Obstacle('disc', [0.0, 0.7], 0.03)


def test_a_thin_disc_between_two_far_via_points_still_blocks():
    """The iiwa flange sweeps a long arc; a flat disc 1 mm from nothing must stop it."""
    a = np.array([-1.2, 0.6, 0.0, -1.0, 0.0, 0.8, 0.0])
    b = np.array([1.2, 0.6, 0.0, -1.0, 0.0, 0.8, 0.0])
    middle = IIWA.fk((a + b) / 2).positions[0]
    normal = IIWA.fk(a + 0.51 * (b - a)).positions[0] - middle
    disc = Obstacle('disc', middle, 0.01, normal=normal)
    for check_step in (0.01, 0.05):
        run = CompliantArm(IIWA, [disc], check_step=check_step).execute(np.array([a, b]))
        assert run.blocked and run.segment == 0
        stop = IIWA.fk(run.config).positions[0]
        assert np.linalg.norm(stop - middle) < 0.02


def test_a_small_disc_between_far_via_points_blocks_the_planar_arm():
    run = CompliantArm(PLANAR, [BLOCKER]).execute(np.array([START, GOAL]))
    assert run.blocked
    tip = PLANAR.fk(run.config).positions[0]
    assert 0.029 < np.linalg.norm(tip - BLOCKER.center) < 0.035
    assert tip[0] < 0   # stopped on the side it came from


def test_free_paths_run_to_the_end():
    far = Obstacle('disc', [-0.5, -0.5], 0.05)
    run = CompliantArm(PLANAR, [far]).execute(np.array([START, GOAL]))
    assert not run.blocked
    np.testing.assert_array_equal(run.config, GOAL)


def test_orientation_gated_obstacles_let_a_turned_flange_pass():
    a = np.array([-1.2, 0.6, 0.0, -1.0, 0.0, 0.8, 0.0])
    b = np.array([1.2, 0.6, 0.0, -1.0, 0.0, 0.8, 0.0])
    pose = arm_for_setting('3d-orient').fk((a + b) / 2)
    ball = Obstacle('ball', pose.positions[0], 0.05, orientation=pose.orientations[0])
    arm = arm_for_setting('3d-orient')
    assert CompliantArm(arm, [ball]).execute(np.array([a, b])).blocked
    turned = a.copy(), b.copy()
    for q in turned:
        q[6] += np.pi     # flange turned half a turn: D_ORIENT = 1 > tolerance
    assert not CompliantArm(arm, [ball]).execute(np.array(turned)).blocked


def test_inside_a_ball_going_deeper_is_blocked_at_once_and_pulling_out_is_free():
    """An end-effector that got into a ball turned away and then turned into it."""
    ball = Obstacle('ball', [0.0, 0.0, 0.0], 1.0)
    inside = np.array([[0.5, 0.0, 0.0]] * 3)
    ends = np.array([[0.1, 0.0, 0.0], [0.9, 0.0, 0.0], [0.5, 2.0, 0.0]])
    np.testing.assert_array_equal(ball.first_hit(inside, ends), [0.0, np.inf, np.inf])
    # from outside, entering is still found where the segment meets the surface
    t = ball.first_hit(np.array([[-2.0, 0.0, 0.0]]), np.array([[2.0, 0.0, 0.0]]))
    np.testing.assert_allclose(t, [0.25])


def straight_loop(max_paths=20, **kwargs) -> Disentangler:
    """Return a loop whose planner always goes straight to the goal, into the blocker."""
    return Disentangler(PLANAR, EpsilonPlanner(PLANAR, epsilon=1.0), GOAL, max_paths=max_paths,
                        **kwargs)


def test_a_blocked_path_adds_exactly_one_failure_and_retreats_to_the_last_via_point():
    loop = straight_loop()
    sim = CompliantArm(PLANAR, [BLOCKER])
    via = np.array([START, START + np.array([-0.1, 0, 0, 0, 0, 0, 0]), GOAL])
    loop.next_path(START)
    loop.attempts[-1].path = via          # execute a path with an intermediate via point
    run = sim.execute(via)
    assert run.blocked and run.segment == 1
    retreat = loop.report_blocked(run.config, run.segment)
    assert len(loop.fmap) == 1 and loop.state is State.RETREATING
    np.testing.assert_array_equal(retreat[0], run.config)
    np.testing.assert_array_equal(retreat[-1], via[1])
    x, v = loop.fmap.points[0], loop.fmap.directions[0]
    np.testing.assert_allclose(x, PLANAR.fk(run.config).positions[0])
    assert v[0] > 0.9     # the tip was moving in +x (clockwise over the top) when blocked
    with pytest.raises(RuntimeError, match='retreating'):
        loop.report_blocked(run.config, 0)
    loop.report_retreated(sim.execute(retreat).config)
    assert loop.state is State.READY and len(loop.fmap) == 1


def test_a_path_blocked_where_it_started_retreats_along_the_way_the_arm_came():
    sim = CompliantArm(PLANAR, [BLOCKER])
    near = START.copy()
    near[0] = np.pi / 2 + 0.06           # the tip 1.2 cm before the blocker
    for min_retreat, expected in ((0.1, [near, START]), (0.0, [near])):
        loop = straight_loop(min_retreat=min_retreat)
        loop.next_path(START)
        loop.attempts[-1].path = np.array([START, near])   # a path that stops short of it
        loop.report_completed(sim.execute(loop.attempts[-1].path).config)
        run = sim.execute(loop.next_path(near))             # straight on: blocked at once
        assert run.blocked and np.linalg.norm(run.config - near) < 0.1
        retreat = loop.report_blocked(run.config, run.segment)
        np.testing.assert_array_equal(retreat, [run.config, *expected])
        assert not sim.execute(retreat).blocked             # retracing is free
        loop.report_retreated(retreat[-1])
        assert len(loop.fmap) == 1 and loop.state is State.READY


def test_after_a_blocked_retreat_the_next_retreat_skips_the_target_it_did_not_reach():
    loop = straight_loop()
    a, b = START - [0.3, 0, 0, 0, 0, 0, 0], START - [0.6, 0, 0, 0, 0, 0, 0]
    loop.next_path(START)
    loop.attempts[-1].path = np.array([START, a, b, GOAL])
    blocked = b - [0.3, 0, 0, 0, 0, 0, 0]                     # on the last edge
    retreat = loop.report_blocked(blocked, 2)
    np.testing.assert_array_equal(retreat, [blocked, b])
    loop.report_retreated(b)
    loop.next_path(b)                      # planned from the target while the arm moves back
    stuck = (blocked + b) / 2              # the retreat was blocked halfway
    loop.withdraw()                        # the arm is not where that plan starts
    assert loop.state is State.READY and loop.paths_tried == 1
    loop.next_path(stuck)
    retreat = loop.report_blocked(stuck, 0)                    # blocked at once
    np.testing.assert_array_equal(retreat[-1], a)              # not back towards b again
    assert not any(np.array_equal(q, b) for q in retreat)
    # the start of the run is never dropped: a run blocked on its first edge, its retreat
    # blocked too, still retreats to the start
    loop = straight_loop()
    loop.next_path(START)
    loop.report_retreated(loop.report_blocked(a, 0)[-1])
    loop.next_path(START)
    loop.withdraw()
    loop.next_path(a)
    np.testing.assert_array_equal(loop.report_blocked(a, 0)[-1], START)


def test_the_loop_stops_after_n_iter_paths():
    loop = straight_loop(max_paths=5)
    sim = CompliantArm(PLANAR, [BLOCKER])
    current, paths = START, 0
    while (path := loop.next_path(current)) is not None:
        paths += 1
        run = sim.execute(path)
        back = sim.execute(loop.report_blocked(run.config, run.segment))
        current = back.config
        loop.report_retreated(current)
    assert paths == 5 and loop.paths_tried == 5 and len(loop.fmap) == 5
    assert loop.state is State.GAVE_UP
    assert loop.next_path(current) is None


class NoPlanner:
    def plan(self, start, goal, fmap, rng):
        return None


def test_the_last_path_gives_up_however_it_ends_and_empty_plans_count():
    # N_ITER counts every path, an empty plan too: never one more
    loop = Disentangler(PLANAR, NoPlanner(), GOAL, max_paths=4)
    assert loop.next_path(START) is None
    assert loop.paths_tried == 4 and loop.state is State.GAVE_UP
    # the last path ran to its end short of the goal, or was blocked and retreated
    loop = straight_loop(max_paths=1)
    loop.next_path(START)
    loop.report_completed(START)
    assert loop.state is State.GAVE_UP
    loop = straight_loop(max_paths=1)
    loop.next_path(START)
    loop.report_retreated(loop.report_blocked(START, 0)[-1])
    assert loop.state is State.GAVE_UP
    with pytest.raises(ValueError):
        Disentangler(PLANAR, NoPlanner(), GOAL, max_paths=0)


def test_a_retreat_goes_back_the_way_the_arm_came_through_earlier_paths_via_points():
    # a path that ran to its end short of the goal, through a via point; then two blocks:
    # each retreat retraces the arm's own way, and what a retreat retraced leaves the route
    step = np.array([0.05, 0, 0, 0, 0, 0, 0])
    loop = straight_loop(min_retreat=0.12)
    a, b = START - step, START - 2 * step
    loop.next_path(START)
    loop.attempts[-1].path = np.array([START, a, b])
    loop.report_completed(b)
    loop.next_path(b)
    blocked = b - 0.5 * step
    retreat = loop.report_blocked(blocked, 0)
    np.testing.assert_array_equal(retreat, [blocked, b, a, START])     # through a
    loop.report_retreated(START)
    loop.next_path(START)
    blocked = START - 0.5 * step
    retreat = loop.report_blocked(blocked, 0)
    np.testing.assert_array_equal(retreat, [blocked, START])           # not back to a or b


def test_success_when_a_path_reaches_the_goal_and_stop_ends_the_run():
    loop = straight_loop()
    path = loop.next_path(START)
    loop.report_completed(path[-1])
    assert loop.state is State.SUCCEEDED
    other = straight_loop()
    other.next_path(START)
    other.stop()
    assert other.state is State.STOPPED and other.next_path(START) is None


def test_random_worlds_are_reproducible_entangled_and_solvable():
    for setting, n in (('2d', 10), ('3d', 10), ('3d-orient', 30)):
        a = random_world(setting, n, seed=5)
        b = random_world(setting, n, seed=5)
        assert a.to_dict() == b.to_dict()
        assert len(a.obstacles) == n and a.rejected_draws >= 0
        sim = a.compliant_arm()
        assert sim.execute(np.array([a.start, a.goal])).blocked   # the straight way is shut
        assert not sim.collides(a.start) and not sim.collides(a.goal)


def test_scenario_files_round_trip_and_refuse_bad_input(tmp_path):
    world = random_world('3d-orient', 30, seed=2)
    world.save(tmp_path / 'w.yaml')
    again = load_world(tmp_path / 'w.yaml')
    assert again.to_dict() == world.to_dict()
    bad = {
        'a: [1': 'not valid YAML',
        'setting: 2d\nstart: [0,0,0,0,0,0,0]\ngoal: [0,0,0,0,0,0,0]\n': 'missing obstacles',
        'setting: 4d\nstart: []\ngoal: []\nobstacles: []\n': 'setting must be one of',
        'setting: 2d\nstart: [0,0]\ngoal: [0,0,0,0,0,0,0]\nobstacles: []\n': 'start must be 7',
        ('setting: 2d\nstart: [0,0,0,0,0,0,0]\ngoal: [0,0,0,0,0,0,0]\nobstacles:\n'
         '  - {type: ball, center: [0, 0], radius: 0.1}\n'): 'obstacle 0: a ball is 3-D',
        ('setting: 2d\nstart: [0,0,0,0,0,0,0]\ngoal: [0,0,0,0,0,0,0]\nobstacles:\n'
         '  - {type: disc, center: [0, 0], radius: -1}\n'): 'radius must be positive',
    }
    for text, message in bad.items():
        (tmp_path / 'bad.yaml').write_text(text)
        with pytest.raises(ScenarioError, match=message):
            load_world(tmp_path / 'bad.yaml')
    (tmp_path / 'bad.yaml').write_bytes(b'\x99\xaf binary')    # not text: named, not a trace
    with pytest.raises(ScenarioError, match=r'bad\.yaml: not valid YAML'):
        load_world(tmp_path / 'bad.yaml')


def test_an_episode_in_a_hand_made_world():
    world = World('2d', START, GOAL, [BLOCKER], name='blocker')
    result = run_episode(world, 'probabilistic', seed=0)
    assert result.success and result.paths <= 20
    assert result.failures == result.paths - 1
    assert len(result.plan_times_s) == result.paths


def test_an_episode_that_gives_up_counts_its_paths_and_failures():
    # one path allowed, blocked: given up after that one, with its one failure learned
    world = World('2d', START, GOAL, [BLOCKER], name='blocker')
    result = run_episode(world, 'probabilistic', seed=0, max_paths=1)
    assert not result.success and result.loop.state is State.GAVE_UP
    assert (result.paths, result.failures, result.empty_plans) == (1, 1, 0)
    assert len(result.traces) == 1 and len(result.plan_times_s) == 1


def test_an_episode_counts_empty_plans_and_passes_on_its_planner_settings_and_c_fail(
        monkeypatch):
    from probdis_ros.planning import Method, RRTSettings

    world = World('2d', START, GOAL, [BLOCKER], name='blocker')
    settings = RRTSettings(iterations=321)
    result = run_episode(world, 'probabilistic', seed=0, max_paths=2, settings=settings,
                         c_fail=7.0)
    assert result.loop.planner.settings is settings and result.loop.fmap.c_fail == 7.0
    # a planner that never finds a path: every path an empty plan, the arm never moves
    monkeypatch.setattr(Method, 'planner', lambda self, arm, settings=None: NoPlanner())
    result = run_episode(world, 'probabilistic', seed=0, max_paths=3)
    assert not result.success and (result.paths, result.empty_plans) == (3, 3)
    assert result.summary()['empty_plans'] == 3 and result.failures == 0


def test_world_and_planner_draw_from_independent_streams_of_one_seed():
    from probdis_ros.planning.seeds import PLANNER, stream, WORLD

    for seed in range(5):
        world, planner = stream(seed, WORLD).random(8), stream(seed, PLANNER).random(8)
        shared = np.random.default_rng(seed).random(8)
        assert not np.array_equal(world, planner)
        assert not np.array_equal(world, shared) and not np.array_equal(planner, shared)
        np.testing.assert_array_equal(stream(seed, PLANNER).random(8), planner)   # reproducible
    loop = straight_loop(seed=3)
    np.testing.assert_array_equal(loop.rng.random(4), stream(3, PLANNER).random(4))
    # the episode's planner draws are its own: the same world, another seed, other plans
    world = random_world('2d', 10, seed=5)
    a = run_episode(world, 'epsilon:0.5', seed=5, max_paths=5)
    b = run_episode(world, 'epsilon:0.5', seed=6, max_paths=5)
    assert [x.path.tolist() for x in a.loop.attempts] != [x.path.tolist() for x in b.loop.attempts]
