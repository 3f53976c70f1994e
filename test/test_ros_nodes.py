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

"""The planner and mock iiwa nodes as real rclpy nodes: runs, refusals, faults, safety."""

import itertools
import json
import math
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

import numpy as np
from probdis_ros.model import FailureMap, iiwa_arm
from probdis_ros.motion.jtc import TrajectoryCommand
from probdis_ros.physics import load_scene
from probdis_ros.plots import plot_replay
from probdis_ros.resources import scenario_path
from probdis_ros.ros import MOCK_NODE
from probdis_ros.ros.messages import trajectory_msg
from probdis_ros.ros.mock_iiwa_node import MockIiwa
from probdis_ros.ros.planner_node import PlannerNode
from probdis_ros.ros.replay import replay
from probdis_ros.run import Learned
from probdis_ros.sim.worlds import load_world
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from ros_harness import JOINTS, RosTest, wait_for
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

pytestmark = pytest.mark.ros
WORLD = load_world(scenario_path('demo_iiwa'))
START, GOAL = WORLD.start, WORLD.goal
FINISHED = ('succeeded', 'gave_up', 'stopped')


@pytest.fixture
def ros():
    test = RosTest()
    yield test
    test.close()


def planner(ros, tmp_path, **params):
    """Start a planner node in-process (fast motions; nodes share one interpreter)."""
    params = {'velocity_scaling': 0.7, 'state_timeout': 2.0, 'bag_dir': str(tmp_path / 'bags'),
              **params}
    goal = params.pop('goal', GOAL)           # None: not given
    overrides = [Parameter('map_file', value=str(tmp_path / 'map.json'))]
    if goal is not None:
        overrides.append(Parameter('goal', value=np.asarray(goal, dtype=float).tolist()))
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    return ros.add(PlannerNode(context=ros.context, parameter_overrides=overrides))


def mock(ros, scenario=None, **params):
    overrides = [Parameter('engine', value='kinematic'),
                 Parameter('scenario', value=str(scenario or scenario_path('demo_iiwa')))]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    return ros.add(MockIiwa(context=ros.context, parameter_overrides=overrides))


def test_the_mock_arms_time_starts_at_its_first_tick_not_at_its_construction(ros):
    # what ran between (start-up's garbage collection) put the first tick 0.1 s behind the
    # wall clock: it caught up at once and warned that the machine could not keep up
    overrides = [Parameter('engine', value='kinematic'),
                 Parameter('scenario', value=str(scenario_path('demo_iiwa')))]
    node = MockIiwa(context=ros.context, parameter_overrides=overrides)    # not spun yet
    try:
        time.sleep(0.3)
        assert node._steps_due() <= 1          # not 0.3 s of periods at once (10: CATCH_UP)
        assert abs(node.epoch - time.time()) < 0.05    # its stamps: the wall clock from there
    finally:
        node.destroy_node()


def test_a_starved_mock_takes_a_command_at_the_wall_clock_not_its_lagging_time(ros):
    # a real JTC takes a message at its first update after it arrives; the mock, behind the
    # wall clock (its executor starved by a plan in the same interpreter), queued it at its
    # own lagging time: the arm ran ahead of the planner's model by up to CATCH_UP and,
    # matching the raw command, a run stopped as an echoing driver (a CI failure)
    overrides = [Parameter('engine', value='kinematic'),
                 Parameter('scenario', value=str(scenario_path('demo_iiwa')))]
    node = MockIiwa(context=ros.context, parameter_overrides=overrides)    # not spun
    try:
        node._tick()                            # its time starts
        began = time.monotonic()
        time.sleep(0.06)                        # starved: no tick for 60 ms
        start = node.q.copy()
        node._on_trajectory(trajectory_msg(TrajectoryCommand(np.array([0.0, 1.0]), np.array(
            [start, start + 0.1])), list(JOINTS)))
        taken = node.robot._in_flight[-1][0]     # the arm's time JTC takes it at
        assert 0.05 <= taken <= time.monotonic() - began + 0.011, taken
    finally:
        node.destroy_node()


class SteadyStates:
    """Publishes q from the probe at rate Hz until cancel() (a flag: no timer races)."""

    def __init__(self, ros, q, rate):
        self.on = True
        ros.probe.create_timer(1.0 / rate, lambda: self.on and ros.publish_state(q))

    def cancel(self):
        self.on = False


def steady_states(ros, q=START, rate=100.0):
    """Publish q from the probe at rate Hz."""
    return SteadyStates(ros, q, rate)


def free_scenario(tmp_path) -> Path:
    doc = WORLD.to_dict()
    doc['obstacles'] = []
    path = tmp_path / 'free.yaml'
    path.write_text(json.dumps(doc))     # JSON is YAML
    return path


def finished(ros):
    return ros.status.get('state') in FINISHED


def stop_while_moving(ros) -> list:
    """Start a run, call ~/stop 0.3 s into its motion; return the commands sent from then."""
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(lambda: ros.status.get('state') == 'executing', 20, 'motion')
    time.sleep(0.3)
    count = len(ros.trajectories)
    assert ros.call('stop').success
    wait_for(lambda: ros.status.get('state') == 'stopped', 2, 'the stop')
    return ros.trajectories[count:]


def test_start_is_refused_without_joint_states(ros, tmp_path):
    planner(ros, tmp_path)
    response = ros.call('start')
    assert not response.success and 'no fresh joint state' in response.message
    assert '/lbr/joint_states' in response.message     # where it listens
    assert not ros.trajectories


def test_the_bag_message_types_are_loaded_before_the_first_start(ros, tmp_path):
    # importing them at the first ~/start (0.5 s with cold files) held the executor while the
    # run started; the joint states queued behind it tripped the state timeout at once
    from probdis_ros.ros.recorder import message_types

    message_types.cache_clear()
    planner(ros, tmp_path)
    assert message_types.cache_info().currsize == 1


def test_a_second_start_is_refused(ros, tmp_path):
    planner(ros, tmp_path)
    steady_states(ros)
    wait_for(lambda: ros.call('start').success, 10, 'first start')
    second = ros.call('start')
    assert not second.success and 'already active' in second.message


def test_start_is_refused_while_the_controller_starts_commands_elsewhere_than_modelled(
        ros, tmp_path):
    # the mock plays JTC with its default (each command from the measured state); a planner
    # that models the last command would release a block into what it hit
    mock(ros)
    node = planner(ros, tmp_path, interpolate_from_desired_state=True,
                   controller_node='/mock_iiwa')
    wait_for(lambda: node.controller_setting.value is False, 10, "the controller's setting")
    response = ros.call('start')
    assert not response.success and 'from its measured state' in response.message
    assert not ros.trajectories
    node.set_parameters([Parameter('interpolate_from_desired_state', value=False)])
    wait_for(lambda: ros.call('start').success, 10, 'start once they agree')


def test_a_start_before_the_controller_answered_is_checked_once_it_answers(ros, tmp_path):
    # the demo starts its fresh planner moments after it came up: the start warned that the
    # controller could not be read (not asked yet), and a controller that starts commands
    # elsewhere than modelled, answering a moment later, went unchecked for the whole run
    import rclpy

    # (at the default speed: faster, the start warns of the driver's guard in clutter)
    node = planner(ros, tmp_path, controller_node='/lbr/joint_trajectory_controller',
                   velocity_scaling=0.2)
    steady_states(ros)
    wait_for(lambda: node.measured is not None, 10, 'joint states')
    assert node.controller_setting.first_answer_due()
    response = ros.call('start')
    assert response.success and 'warning' not in response.message, response.message
    assert 'has not answered yet' in response.message
    jtc = rclpy.create_node('joint_trajectory_controller', namespace='/lbr',
                            context=ros.context)
    jtc.declare_parameter('interpolate_from_desired_state', True)
    ros.add(jtc)
    wait_for(lambda: node.run.outcome == 'stopped', 10, 'the run stopped')
    assert 'starts each command from its last command' in node.run.message, node.run.message


def test_a_start_faster_than_clutter_allows_warns_of_the_drivers_guard(ros, tmp_path):
    # at 0.5, 21 of 100 family runs on the physics mock ended on the driver's guard
    node = planner(ros, tmp_path, velocity_scaling=0.5)
    steady_states(ros)
    wait_for(lambda: node.measured is not None, 10, 'joint states')
    response = ros.call('start')
    assert response.success, response.message
    assert 'warning: velocity_scaling 0.5: in clutter, impacts this fast spike a joint past ' \
        "its velocity limit and the driver's command guard ends the session" in \
        response.message, response.message
    assert '1, 9 and 21 of 100 family runs at 0.3, 0.4 and 0.5, none at 0.2); near ' \
        'clutter keep 0.2' in response.message


def test_a_planner_that_models_the_last_command_starts_only_once_the_controller_agrees(
        ros, tmp_path):
    node = planner(ros, tmp_path, interpolate_from_desired_state=True,
                   controller_node='/lbr/joint_trajectory_controller')
    steady_states(ros)
    wait_for(lambda: node.measured is not None, 10, 'joint states')
    response = ros.call('start')
    assert not response.success and 'could not read' in response.message
    # a controller that agrees but holds the measured position by itself on a path
    # tolerance (the README's settings for the measured start) would be unseen
    import rclpy

    jtc = rclpy.create_node('joint_trajectory_controller', namespace='/lbr',
                            context=ros.context)
    jtc.declare_parameter('interpolate_from_desired_state', True)
    jtc.declare_parameter('constraints.goal_time', 0.0)
    for joint in JOINTS:
        jtc.declare_parameter(f'constraints.{joint}.trajectory', 0.0)
    ros.add(jtc)
    wait_for(lambda: node.controller_setting.value is True, 10, "the controller's setting")
    assert node.controller_setting.holds == {}
    jtc.set_parameters([Parameter('constraints.lbr_A2.trajectory', value=0.3)])
    wait_for(lambda: node.controller_setting.holds, 10, 'the new constraint')
    response = ros.call('start')
    assert not response.success and 'constraints.lbr_A2.trajectory 0.3' in response.message
    jtc.set_parameters([Parameter('constraints.lbr_A2.trajectory', value=0.0)])
    wait_for(lambda: ros.call('start').success, 10, 'start')


def test_a_planner_that_models_the_measured_state_starts_unconfirmed(ros, tmp_path):
    # the measured start needs no confirmation (the node warns): a controller that starts
    # from its last command then steps back to the arm, as JTC's default does
    node = planner(ros, tmp_path, controller_node='/lbr/joint_trajectory_controller')
    steady_states(ros)
    # (moments after the node came up the controller may just not be found yet: below)
    wait_for(lambda: not node.controller_setting.first_answer_due(), 10, 'the first answer')
    answers = []
    wait_for(lambda: answers.append(ros.call('start')) or answers[-1].success, 10, 'start')
    # the user who started it hears of it, not the log alone
    assert 'warning: could not read' in answers[-1].message, answers[-1].message


def test_planner_sizes_that_would_exhaust_memory_are_refused(ros, tmp_path):
    # a round draws K x |C_RAND| samples at once, about 80 B each: the node took 1e5 x 1e5
    node = planner(ros, tmp_path, method='probabilistic')
    result = node.set_parameters_atomically([Parameter('iterations', value=100000),
                                             Parameter('n_random', value=1000)])
    assert not result.successful and 'iterations x n_random must be at most' in result.reason
    assert node.set_parameters([Parameter('iterations', value=20000)])[0].successful
    # informed runs 8 K per tree: the same K is too much with it
    result = node.set_parameters([Parameter('method', value='informed')])[0]
    assert not result.successful and 'planner: iterations x n_random' in result.reason
    assert node.get_parameter('method').value == 'probabilistic'


def test_bad_goals_are_refused(ros, tmp_path):
    node = planner(ros, tmp_path)
    outside = GOAL.copy()
    outside[1] = 3.0
    in_the_table = [0.0, 1.9, 0.0, -0.5, 0.0, -1.5, 0.0]      # 0.14 m into the table top
    for bad in (outside.tolist(), GOAL[:6].tolist(), in_the_table):
        result = node.set_parameters([Parameter('goal', value=bad)])[0]
        assert not result.successful and 'goal' in result.reason
    assert 'below the table' in result.reason
    assert np.allclose(node.get_parameter('goal').value, GOAL)
    # 1 mrad inside A1's limit: the arm coming to rest there in joint impedance overshoots it
    near = GOAL.copy()
    near[0] = node.arm.lower[0] + 0.001
    result = node.set_parameters([Parameter('goal', value=near.tolist())])[0]
    assert not result.successful and 'A1' in result.reason
    assert 'nearer than 0.035 (joint_margin): an arm in joint impedance overshoots' in \
        result.reason
    # the margin and the goal set in one call: the goal is judged by the new margin
    assert node.set_parameters_atomically([Parameter('joint_margin', value=0.0005),
                                           Parameter('goal', value=near.tolist())]).successful
    far = GOAL.copy()
    far[0] = node.arm.upper[0] - 0.05
    result = node.set_parameters_atomically([Parameter('joint_margin', value=0.06),
                                             Parameter('goal', value=far.tolist())])
    assert not result.successful and 'nearer than 0.06 (joint_margin)' in result.reason


def test_a_joint_range_narrows_the_planner_and_refuses_goals_and_ranges_outside(ros, tmp_path):
    # the cell's room: A1 within [-0.3, 0.5] (the goal's A1 is 0.3); NaN: the joint's limit
    nan = math.nan
    node = planner(ros, tmp_path, joint_lower=[-0.3] + [nan] * 6,
                   joint_upper=[0.5] + [nan] * 6)
    made = node._make_planner()
    assert (made.low[0], made.high[0]) == (-0.3, 0.5)
    np.testing.assert_allclose(made.high[1:], node.arm.upper[1:] - 0.035)
    for name, value, said in (('goal', [-0.5, *GOAL[1:].tolist()], 'outside [-0.3, 0.5]'),
                              ('joint_upper', [3.5] + [nan] * 6, 'outside its limits'),
                              ('joint_lower', [0.6] + [nan] * 6, 'is not below joint_upper'),
                              ('joint_lower', [0.0] * 6, 'needs 7 values'),
                              # A2 within its limits, but not within joint_margin of them
                              ('joint_lower', [-0.3, float(node.arm.upper[1]) - 0.01] +
                               [nan] * 5, 'A2: joint_lower and joint_upper leave no room')):
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and said in result.reason, result.reason
    # narrowed past the goal: ~/start says so
    assert node.set_parameters([Parameter('joint_upper', value=[0.2] + [nan] * 6)])[0].successful
    steady_states(ros)
    wait_for(lambda: node.measured is not None, 10, 'joint states')
    response = ros.call('start')
    assert not response.success and '(joint_lower, joint_upper)' in response.message


def test_a_joint_margin_that_leaves_the_joint_range_no_room_is_refused_when_set(ros, tmp_path):
    # accepted, it broke the planner ~/start builds (the error escaped the service)
    node = planner(ros, tmp_path)
    margin = node.get_parameter('joint_margin').value
    # A1 from 0.1 rad inside its upper limit: room for the margin, but not for 0.2
    lower = [float(node.arm.upper[0]) - 0.1] + [math.nan] * 6
    assert node.set_parameters([Parameter('joint_lower', value=lower)])[0].successful
    result = node.set_parameters([Parameter('joint_margin', value=0.2)])[0]
    assert not result.successful and 'A1: joint_lower and joint_upper leave no room' in \
        result.reason, result.reason
    assert node.get_parameter('joint_margin').value == margin


def test_every_parameter_start_up_built_on_is_refused_when_set_later(ros, tmp_path):
    # taken, the node would say it uses them while it goes on with the old ones
    node = planner(ros, tmp_path)
    for name, value in (('joint_names', [f'iiwa_joint_{i}' for i in range(1, 8)]),
                        ('joint_states_topic', '/elsewhere'), ('orientation', False),
                        ('table', False), ('table_clearance', 0.2), ('object_radius', 0.1)):
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and 'fixed at start-up' in result.reason, name
        assert node.get_parameter(name).value != value, name


def test_the_method_parameter_takes_the_planners_informed_ideas_and_refuses_the_maps(
        ros, tmp_path):
    from probdis_ros.planning.probes import ProbeRRT

    node = planner(ros, tmp_path, method='informed:adfhi')
    built = node._make_planner()
    # the probes of d, f and i on the budget of a: what a run plans with from now on
    assert isinstance(built, ProbeRRT) and built.settings.iterations == 800
    assert (built.straight, built.turning, built.rolling) == (True, True, True)
    for bad, words in (('informed:abf', ('b', 'map')), ('informed:x', ('informed:x',)),
                       ('sideways', ('sideways',))):
        result = node.set_parameters([Parameter('method', value=bad)])[0]
        assert not result.successful and all(w in result.reason for w in words), result.reason
    assert node.get_parameter('method').value == 'informed:adfhi'
    assert node.set_parameters([Parameter('method', value='hard')])[0].successful
    assert type(node._make_planner()) is not ProbeRRT


def test_the_robot_experiment_hands_the_node_its_informed_ideas():
    from probdis_ros.planning import Method
    from probdis_ros.planning.informed import DEFAULT_IDEAS
    from probdis_ros.ros.robot_experiment import planner_arguments

    def params(text):
        args = planner_arguments(Method.parse(text), 3, 0.2)
        return dict(arg.split(':=') for arg in args[1::2])

    assert params('informed:adfhi')['method'] == 'informed:adfhi'
    # a bare informed names its (default) ideas, as its records do
    assert params('informed')['method'] == f'informed:{DEFAULT_IDEAS}'
    assert params('hard:0.02') == {'method': 'hard', 'threshold': '0.02', 'seed': '3',
                                   'velocity_scaling': '0.2'}
    with pytest.raises(ValueError, match='--offline'):
        params('informed:abf')


@pytest.mark.parametrize('a1, reason', [
    (4.0, r'lbr_A1 at 4 rad is outside its limits \[-2.9671, 2.9671\]'),
    # at the URDF's limit: 2.7e-7 rad past KUKA's 170 degrees, which the driver refuses
    (2.96706, 'lbr_A1 at 2.967060 rad is outside the joint limits as KUKA has them'),
])
def test_a_goal_outside_the_limits_given_at_start_up_ends_the_node_naming_the_joint(
        ros, tmp_path, a1, reason):
    # it was a warning, and the node ran on (a ValueError out of the node: exit 2, one line)
    outside = GOAL.copy()
    outside[0] = a1
    with pytest.raises(ValueError, match=reason):
        planner(ros, tmp_path, goal=outside.tolist())


def test_a_planner_given_no_goal_refuses_to_start_until_one_is_set(ros, tmp_path):
    # the goal's default was all zeros, and a goal lost on the command line sent the arm there
    node = planner(ros, tmp_path, goal=None)
    steady_states(ros)
    wait_for(lambda: ros.status.get('state') == 'idle', 10, 'planner status')
    time.sleep(0.2)
    response = ros.call('start')
    assert not response.success and 'goal parameter is not set' in response.message
    assert ros.trajectories == []
    assert node.set_parameters([Parameter('goal', value=GOAL.tolist())])[0].successful
    assert ros.call('start').success


@pytest.mark.parametrize('names, positions, reason', [
    (JOINTS[:6], START[:6], 'missing joints'),
    (JOINTS, START[:5], 'names but'),
    (JOINTS, [math.nan, *START[1:].tolist()], 'non-finite'),
    (JOINTS, [math.inf, *START[1:].tolist()], 'non-finite'),
])
def test_malformed_joint_states_stop_the_run_safely(ros, tmp_path, names, positions, reason):
    node = planner(ros, tmp_path)
    timer = steady_states(ros)
    wait_for(lambda: ros.call('start').success, 10, 'start')
    timer.cancel()
    ros.publish_state(None, names=names, positions=positions)
    wait_for(lambda: finished(ros), 5, 'run to stop')
    assert ros.status['state'] == 'stopped'
    assert 'joint state refused' in ros.status['message'] and reason in ros.status['message']
    for q in ros.positions_commanded():
        assert np.all(np.isfinite(q)) and node.arm.within_limits(q)[0]
    # the stop: from the last accepted state (or the command, had one begun), to rest
    last = ros.trajectories[-1][1]
    assert np.abs(np.array(last.points[0].positions) - START).max() < 0.02
    assert np.allclose(last.points[-1].velocities, 0.0)


def test_joint_states_out_of_order_with_extra_joints_are_matched_by_name(ros, tmp_path):
    node = planner(ros, tmp_path)
    order = [3, 0, 6, 1, 5, 2, 4]
    names = ['gripper'] + [JOINTS[i] for i in order]
    positions = [0.5] + [START[i] for i in order]
    ros.probe.create_timer(0.01, lambda: ros.publish_state(None, names, positions))
    wait_for(lambda: node.measured is not None, 5, 'a joint state')
    np.testing.assert_allclose(node.measured, START)


def test_joint_states_waiting_behind_one_are_taken_with_it_oldest_first(ros, tmp_path):
    # an executor kept from running resumes with a queue of states: they are taken in one go
    # (the run answers a block seen in one from the newest, where the arm is by then)
    node = planner(ros, tmp_path)
    taken, held, go = [], threading.Event(), threading.Event()
    take = node._take_joint_state
    node._take_joint_state = lambda data, info, newest, **rest: (
        taken.append(newest), take(data, info, newest, **rest))

    def hold_the_executor():
        held.set()
        go.wait(5.0)
    timer = ros.probe.create_timer(0.01, hold_the_executor)
    wait_for(held.is_set, 5, 'the executor held')
    timer.cancel()
    states = [START + 0.001 * k for k in range(5)]
    for q in states:
        ros.publish_state(q)
    time.sleep(0.5)                       # delivered meanwhile, behind the held executor
    go.set()
    wait_for(lambda: len(taken) == len(states), 5, 'the states taken')
    # in one go, the newest last (on a loaded machine DDS may deliver the last ones later)
    assert not taken[0] and taken[-1]
    np.testing.assert_allclose(node.measured, states[-1])


def test_joint_states_that_stop_arriving_stop_the_run(ros, tmp_path):
    planner(ros, tmp_path, state_timeout=0.3)
    timer = steady_states(ros)
    wait_for(lambda: ros.call('start').success, 10, 'start')
    timer.cancel()
    wait_for(lambda: finished(ros), 5, 'run to stop')
    assert ros.status['state'] == 'stopped'
    assert 'stopped arriving' in ros.status['message']


@pytest.mark.parametrize('answer', ['start', 'stop'])
@pytest.mark.parametrize('desired', [False, True], ids=['measured_start', 'desired_start'])
def test_after_the_speed_monitoring_stops_the_arm_a_restart_resumes_with_the_map(
        ros, tmp_path, desired, answer):
    # T1: KUKA's monitoring stops the arm (here at 0.2 m/s, soon on the first path), the
    # driver goes silent and the run stops; the operator restarts the driver, and the next
    # ~/start plans from where the arm holds, with the failures learned before.  The
    # restarted controller holds the measured position, also where JTC starts each command
    # from its last one: the planner must not take the command it sent before the stop for
    # what JTC holds (its first command went there in one period, 34 x the velocity limit);
    # nor must the operator's ~/stop then, which the ended run would have built from it
    jtc = {'interpolate_from_desired_state': desired}
    node = planner(ros, tmp_path, **jtc, controller_node=f'/{MOCK_NODE}')
    fmap = FailureMap(node.arm.task_space)
    fmap.add(np.array([0.5, 0.0, 0.5]), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0, 0, 0]))
    node.fmap = fmap
    arm = mock(ros, free_scenario(tmp_path), speed_monitor=0.2, **jtc)
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(lambda: arm.robot.stopped is not None, 20, 'the monitoring to stop the arm')
    assert 'speed monitoring' in arm.robot.stopped
    wait_for(lambda: finished(ros), 10, 'the run to stop')
    said = ros.status['message']
    assert ros.status['state'] == 'stopped' and 'stopped arriving' in said
    assert 'speed monitoring' in said and 'the next start goes on' in said
    assert ros.call(f'/{MOCK_NODE}/restart_driver').success
    assert not ros.call(f'/{MOCK_NODE}/restart_driver').success   # running again
    held = np.array(arm.q)
    # it had moved before the stop, by more than the tolerance below tells apart (a mock
    # that caught up after a stall tripped the monitoring 4.7 mrad out, in CI)
    assert np.abs(held - START).max() > 0.003
    sent = len(ros.trajectories)
    arm.robot.command_speed_peak = 0.0
    if answer == 'stop':        # the operator's stop, no run active: a hold where the arm is
        assert ros.call('stop').success
    else:
        wait_for(lambda: ros.call('start').success, 10, 'start after the restart')
        assert ros.status['failures'] == 1
    wait_for(lambda: len(ros.trajectories) > sent, 10, 'the first command after the restart')
    first = ros.trajectories[sent][1].points[0]
    np.testing.assert_allclose(first.positions, held, atol=1e-3)
    time.sleep(0.3)
    # JTC's command moved on from the arm within the velocity limits (one period each)
    assert arm.robot.command_speed_peak <= 1.0
    assert ros.call('stop').success


def test_the_mock_runs_a_trajectory_stamped_on_its_own_clock(ros, tmp_path):
    # JTC counts a stamped trajectory's times from its stamp; the mock's arm time starts at
    # 0 while its clock reads the wall clock's date, so a stamp of "now" waited 56 years
    arm = mock(ros, free_scenario(tmp_path))
    start = arm.q.copy()
    goal = start.copy()
    goal[0] += 0.3
    msg = trajectory_msg(TrajectoryCommand(np.array([1.0]), goal[None]), list(JOINTS))
    msg.header.stamp = arm.get_clock().now().to_msg()
    publisher = ros.probe.create_publisher(
        JointTrajectory, '/lbr/joint_trajectory_controller/joint_trajectory', 10)
    wait_for(lambda: publisher.get_subscription_count() > 0, 10, 'the mock')
    publisher.publish(msg)
    wait_for(lambda: abs(arm.q[0] - goal[0]) < 0.01, 10, 'the arm at the goal')


def test_the_mock_names_its_joints_as_told_and_refuses_commands_to_others(ros, tmp_path):
    # a robot_name other than lbr names the joints after it; the mock plays that arm
    names = [f'iiwa_A{i}' for i in range(1, 8)]
    arm = mock(ros, free_scenario(tmp_path), joint_names=names)
    seen = []
    ros.probe.create_subscription(JointState, '/lbr/joint_states',
                                  lambda msg: seen.append(list(msg.name)),
                                  qos_profile_sensor_data)
    wait_for(lambda: seen, 10, 'a joint state')
    assert seen[-1] == names
    publisher = ros.probe.create_publisher(
        JointTrajectory, '/lbr/joint_trajectory_controller/joint_trajectory', 10)
    wait_for(lambda: publisher.get_subscription_count() > 0, 10, 'the mock')
    start = arm.q.copy()
    goal = start.copy()
    goal[0] += 0.3
    command = TrajectoryCommand(np.array([0.5]), goal[None])
    publisher.publish(trajectory_msg(command, list(JOINTS)))     # the lbr names: refused
    time.sleep(1.0)
    np.testing.assert_array_equal(arm.q, start)
    publisher.publish(trajectory_msg(command, names))
    wait_for(lambda: abs(arm.q[0] - goal[0]) < 0.01, 10, 'the arm at the goal')
    with pytest.raises(ValueError, match='joint_names must name 7 different joints'):
        MockIiwa(context=ros.context, parameter_overrides=[
            Parameter('engine', value='kinematic'), Parameter('joint_names', value=names[:6])])


def test_the_physics_mock_takes_its_faults_from_its_parameters(ros):
    arm = ros.add(MockIiwa(context=ros.context, parameter_overrides=[
        Parameter('engine', value='physics'), Parameter('scene', value='demo_hook'),
        Parameter('armature', value=0.3), Parameter('object_mass_error', value=0.1),
        Parameter('latency', value=0.02), Parameter('noise', value=0.001),
        Parameter('effort_noise', value=0.5), Parameter('joint_friction', value=0.7),
        Parameter('grasp_stiffness', value=20.0), Parameter('stiffness', value=400.0),
        Parameter('damping_ratio', value=1.0)]))
    # what the planner cannot see, for RViz started later (latched): the hidden obstacles
    # and the grasped object
    drawn = []
    ros.probe.create_subscription(
        MarkerArray, f'/{MOCK_NODE}/scene', lambda m: drawn.append({k.ns for k in m.markers}),
        QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    robot = arm.robot
    assert robot.engine.settings.joint_friction == 0.7
    np.testing.assert_array_equal(robot.engine.model.dof_armature[:7], [0.3] * 7)
    np.testing.assert_array_equal(robot.engine.model.jnt_stiffness[-3:], [20.0] * 3)
    # the robot application's impedance: the actuators' gains and the damping law's ratio
    np.testing.assert_array_equal(robot.engine.model.actuator_gainprm[:7, 0], [400.0] * 7)
    assert robot.engine.settings.damping_ratio == 1.0
    assert robot.engine.settings.object_mass_error == 0.1
    assert (robot.settings.latency, robot.settings.noise) == (0.02, 0.001)
    assert robot.settings.effort_noise == 0.5
    wait_for(lambda: drawn, 5, 'the scene markers')
    assert drawn[-1] == {'obstacles', 'grasped_object'}


def test_a_full_run_against_the_physics_mock_learns_and_persists_failures(ros, tmp_path):
    # on simulated time: the planner follows the mock's /clock, so a busy machine slows the
    # run down instead of making the arm look late
    scene = load_scene('demo_hook')
    node = planner(ros, tmp_path, goal=scene.goal, velocity_scaling=0.5, use_sim_time=True)
    ros.add(MockIiwa(context=ros.context, parameter_overrides=[
        Parameter('engine', value='physics'), Parameter('scene', value='demo_hook'),
        Parameter('sim_time', value=True), Parameter('real_time_factor', value=0.0)]))
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(lambda: finished(ros), 120, 'the run to end')
    status = ros.status
    assert status['state'] == 'succeeded', status
    assert status['paths'] >= 2 and status['failures'] >= 1
    # the physics arm's efforts: how hard it pressed (the hook on the bar, about 30 Nm), and
    # the replay of its bag finds the same from the recorded efforts
    peak = np.array(status['peak_external_torque_nm'])
    assert 10.0 < peak.max() < 100.0
    wait_for(lambda: (Path(status['bag']) / 'metadata.yaml').exists(), 5, 'the bag')
    replayed = replay(status['bag'])
    np.testing.assert_allclose(replayed.torque_peak, peak, atol=0.06)
    # its plot draws the estimate over time: every state's, the peak among them
    drawn = np.abs([tau for _, tau in replayed.torques])
    assert len(drawn) > 100 and np.all(drawn.max(axis=0) >= replayed.torque_peak - 1e-9)
    picture = plot_replay(replayed, tmp_path / 'replay.png', 0.1)
    assert picture.stat().st_size > 20_000
    # a finished run leaves its map beside its bag; the next run starts from an empty one
    beside = Path(status['bag']) / 'failure_map.json'
    wait_for(lambda: beside.exists(), 5, 'the map beside the bag')
    assert len(FailureMap.load(beside)) == status['failures']
    wait_for(lambda: len(FailureMap.load(tmp_path / 'map.json')) == 0, 5,
             'the emptied map file (written by the I/O thread)')
    for _, msg in ros.trajectories:
        times = [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points]
        assert all(b > a for a, b in itertools.pairwise(times))
        assert list(msg.points[-1].velocities) == [0.0] * 7
        assert list(msg.joint_names) == JOINTS
    assert all(node.arm.within_limits(q)[0] for q in ros.positions_commanded())


def test_a_finished_run_without_a_bag_keeps_its_map_beside_the_map_file(ros, tmp_path):
    # with no bag to leave it beside, the finished run's map was emptied and kept nowhere
    fmap = FailureMap(iiwa_arm().task_space)
    for k in range(3):
        fmap.add([0.2 * k, -0.6, 0.3], [0, 0, 1], [1, 0, 0, 0])
    fmap.save(tmp_path / 'map.json')
    planner(ros, tmp_path, bag_dir='')
    mock(ros, free_scenario(tmp_path))
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(lambda: finished(ros), 60, 'the run to end')
    assert ros.status['state'] == 'succeeded' and not ros.status['bag'], ros.status
    wait_for(lambda: list(tmp_path.glob('map.json.finished-*')), 5, 'the map kept aside')
    kept, = tmp_path.glob('map.json.finished-*')
    assert len(FailureMap.load(kept)) == 3
    wait_for(lambda: len(FailureMap.load(tmp_path / 'map.json')) == 0, 5, 'the emptied map')


def test_a_run_that_gave_up_keeps_its_map_aside_and_the_next_starts_empty(ros, tmp_path):
    # the map of a run that gave up is the one most wanted; the next run starts afresh
    planner(ros, tmp_path, bag_dir='', max_paths=1)
    mock(ros)
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(lambda: finished(ros), 60, 'the run to end')
    assert ros.status['state'] == 'gave_up' and ros.status['failures'] >= 1, ros.status
    wait_for(lambda: list(tmp_path.glob('map.json.finished-*')), 5, 'the map kept aside')
    kept, = tmp_path.glob('map.json.finished-*')
    assert len(FailureMap.load(kept)) == ros.status['failures']
    wait_for(lambda: len(FailureMap.load(tmp_path / 'map.json')) == 0, 5, 'the emptied map')


def test_stop_during_motion_decelerates_to_rest_within_the_limits(ros, tmp_path):
    planner(ros, tmp_path)
    arm = mock(ros, free_scenario(tmp_path))
    stops = stop_while_moving(ros)
    assert len(stops) == 1, 'one command: the stop'
    points = stops[0][1].points
    times = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in points])
    positions = np.array([p.positions for p in points])
    velocities = np.array([p.velocities for p in points])
    accelerations = np.array([p.accelerations for p in points])
    # a deceleration, not a jump: sampled every 10 ms, within the acceleration limit, at rest
    assert len(points) > 1 and np.allclose(np.diff(times), 0.01)
    assert np.abs(accelerations).max() <= 10.0 * 1.01
    assert np.abs(velocities[0]).max() > 0.0 and np.allclose(velocities[-1], 0.0)
    assert np.abs(np.diff(positions, axis=0)).max() <= 0.01 * iiwa_arm().velocity_limits.max()
    # waited for on the arm's clock: a starved mock runs behind the wall clock (CI, on a
    # loaded machine: 1e-4 rad still to settle after 0.3 s of wall time)
    stopped = arm.robot.time
    wait_for(lambda: arm.robot.time > stopped + times[-1] + 0.3, 10, 'the end of the stop')
    np.testing.assert_allclose(arm.q, positions[-1], atol=0.01)
    held, settled = np.array(arm.q), arm.robot.time
    wait_for(lambda: arm.robot.time > settled + 0.3, 10, '0.3 s more on the arm')
    np.testing.assert_allclose(arm.q, held, atol=1e-4)     # the driver filter settling
    assert ros.status['state'] == 'stopped'


def test_a_start_while_the_arm_still_brakes_from_a_stop_is_no_foreign_motion(ros, tmp_path):
    # the stop this node sent is still slowing the arm down: its way to rest is the node's
    # own motion, not something else driving the arm
    planner(ros, tmp_path)
    mock(ros, free_scenario(tmp_path))
    stops = stop_while_moving(ros)
    assert len(stops) == 1
    response = ros.call('start')
    assert response.success, response.message
    time.sleep(1.0)
    assert 'something other than this planner' not in ros.status.get('message', ''), ros.status


def test_a_cartesian_speed_limit_caps_every_point_of_the_arm_in_what_is_sent(ros, tmp_path):
    from probdis_ros.model.table import ROBOT_TABLE
    from probdis_ros.motion.cartesian_speed import point_speeds

    limit = 0.15        # at velocity scaling 0.7 the joint limits alone allow far more
    planner(ros, tmp_path, cartesian_speed_limit=limit)
    mock(ros)
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(lambda: ros.trajectories, 20, 'a path')
    points = ros.trajectories[0][1].points
    positions = np.array([p.positions for p in points])
    velocities = np.array([p.velocities for p in points])
    fastest = point_speeds(iiwa_arm().on_table(ROBOT_TABLE), positions, velocities).max()
    assert 0.9 * limit <= fastest <= limit
    assert ros.status['cartesian_speed_limit'] == limit     # and the bag says so
    assert ros.call('stop').success


def test_the_objects_ball_is_the_arms_without_a_table_too(ros, tmp_path):
    # the Cartesian speed limit keeps the object's points whether a table is known or not
    node = planner(ros, tmp_path, table=False, object_radius=0.2)
    assert node.arm.table is None and node.arm.shapes[-1, -1] == 0.2


@pytest.mark.parametrize('offset', [3.0, -3.0])
def test_a_stamped_stop_reaches_an_arm_whose_clock_is_off(ros, tmp_path, offset):
    # a desired start stamps a command made while JTC's command moves, and JTC runs it on
    # the clock that stamps the arm's joint states: 3 s ahead, a stop stamped on this
    # node's clock was dropped as past (the arm ran its path on, 0.68 rad off the stop's
    # course); 3 s behind, JTC bridged the 3 s to it with a spline that swung 0.47 rad off
    node = planner(ros, tmp_path, interpolate_from_desired_state=True,
                   controller_node='/mock_iiwa')
    arm = mock(ros, free_scenario(tmp_path), interpolate_from_desired_state=True,
               clock_offset=offset)
    # the mock's arm counts from its start, and a stamp before that reads as none
    wait_for(lambda: arm.robot.time > abs(offset) + 1.0, 20, "the mock's clock")
    stop = stop_while_moving(ros)[0][1]
    stamp = stop.header.stamp.sec + stop.header.stamp.nanosec * 1e-9
    assert abs(stamp - (arm.epoch + arm.robot.time)) < 0.5       # on the arm's clock
    assert abs(node.state_check.clock_offset + offset) < 0.1
    points = np.array([p.positions for p in stop.points])
    assert np.abs(points[-1] - GOAL).max() > 0.05          # the path would have gone on
    # the arm lags its command by 0.09 rad here: on its own clock, past the stop's start
    wait_for(lambda: arm.epoch + arm.robot.time > stamp + 0.15, 5, 'the stop under way')
    course = []
    for _ in range(100):                # 2 s: the stop (1 s) and after it
        course.append(np.array(arm.q))
        time.sleep(0.02)
    # the arm goes where the stop goes, and nowhere else
    off = [np.abs(points - q).max(axis=1).min() for q in course]
    assert max(off) < 0.05
    np.testing.assert_allclose(arm.q, points[-1], atol=0.01)


def test_a_clock_step_on_the_arm_stops_the_run_with_a_stop_jtc_takes(ros, tmp_path):
    # the arm's clock steps 3 s ahead mid-motion (NTP): its states are refused as stamped
    # ahead of their stream and the run stops; stamped by the old offset, JTC dropped that
    # stop as past and ran the path on
    planner(ros, tmp_path, interpolate_from_desired_state=True, controller_node='/mock_iiwa')
    arm = mock(ros, free_scenario(tmp_path), interpolate_from_desired_state=True)
    wait_for(lambda: arm.robot.time > 4.0, 20, "the mock's clock")
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(lambda: ros.status.get('state') == 'executing', 20, 'motion')
    time.sleep(0.3)
    count = len(ros.trajectories)
    arm.set_parameters([Parameter('clock_offset', value=3.0)])
    wait_for(lambda: ros.status.get('state') == 'stopped', 2, 'the stop')
    assert 'ahead of its stream' in ros.status['message']
    stop = ros.trajectories[count][1]
    assert (stop.header.stamp.sec, stop.header.stamp.nanosec) == (0, 0)
    end = np.array(stop.points[-1].positions)
    time.sleep(2.0)
    np.testing.assert_allclose(arm.q, end, atol=0.01)


def test_a_step_of_this_hosts_clock_stops_the_run_from_where_the_arm_is(ros, tmp_path):
    # this computer's clock steps 0.4 s ahead mid-motion (an NTP step), seen as the node
    # reads it: the node's time goes on without the step, and the run stops, decelerating
    # from where the arm is, learning nothing (before, commands were timed by the new clock
    # and states dated by the old one: in a review's script a false block was learned)
    node = planner(ros, tmp_path)
    arm = mock(ros, free_scenario(tmp_path))
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(lambda: ros.status.get('state') == 'executing', 20, 'motion')
    time.sleep(0.3)
    count, streams = len(ros.trajectories), node.state_check.streams
    refused = node.state_check.refused
    read, receipt = node.host_clock.read, node.host_clock.receipt

    def stepped():
        before, wall, after = read()
        return before, wall + 0.4, after

    # DDS's receipts step with the wall clock (a driver on another computer: its stamps
    # do not); set first, so that no state is taken between the two on the old clock
    node.host_clock.receipt = lambda wall: receipt(wall + 0.4)
    node.host_clock.read = stepped
    wait_for(lambda: ros.status.get('state') == 'stopped', 2, 'the stop')
    q_then = np.array(arm.q)
    restart = ros.call('start')          # refused for a second after the step
    assert "this host's clock stepped +0.400 s" in ros.status['message']
    assert ros.status['failures'] == 0
    assert node.host_clock.steps == pytest.approx(0.4, abs=0.002)
    # the joint states begin a new stream (a driver on this computer stamps by the
    # stepped clock)
    assert node.state_check.streams > streams
    assert not restart.success and 'stepped +0.400 s' in restart.message
    stop = ros.trajectories[count][1]
    points = np.array([p.positions for p in stop.points])
    assert np.abs(points[-1] - GOAL).max() > 0.05          # the path would have gone on
    # from the arm's state then (read here a few ms later); with the node's time and the
    # receipts stepped along (a mutant) the stop began 1.77 rad (L1) away, ahead on the path
    assert np.abs(points[0] - q_then).sum() < 0.3
    time.sleep(1.5)
    np.testing.assert_allclose(arm.q, points[-1], atol=0.01)
    # the states taken since, on the node's time, were all good: only the step was noted
    assert node.state_check.refused == refused + 1
    assert node.measured_at == pytest.approx(node._now(), abs=0.1)


def test_the_latched_markers_draw_the_map_as_it_is_from_start_up_to_a_reset(ros, tmp_path):
    # drawn only before a command: RViz showed nothing of a map loaded at start-up, and the
    # failures of a map cleared by ~/reset_map (or emptied by a finished run) stayed drawn
    fmap = FailureMap(iiwa_arm().task_space)
    for k in range(3):
        fmap.add([0.2 * k, -0.6, 0.3], [0, 0, 1], [1, 0, 0, 0])
    fmap.save(tmp_path / 'map.json')
    planner(ros, tmp_path)
    drawn = []          # per markers message: how many failures it draws
    ros.probe.create_subscription(
        MarkerArray, '/probdis_planner/markers',
        lambda m: drawn.append(sum(k.ns == 'failures' for k in m.markers)),
        QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    wait_for(lambda: drawn, 5, 'the markers of the loaded map')
    assert drawn[-1] == 3
    assert ros.call('reset_map').success
    wait_for(lambda: drawn[-1] == 0, 5, 'the cleared map drawn')


def test_with_confirm_paths_each_path_waits_for_the_operator(ros, tmp_path):
    # robot_waste (the demo's start and goal): the method gets out of it in 1-3 paths for
    # every planner seed 0-11 (probdis sim --scenario robot_waste --seed S); the demo world
    # gives up for some (2 of seeds 0-19), and the declined proposal and the timing change
    # the run's draws: it gave up or stopped in 18 of 55 runs of this test on 2026-12-05
    # (6 of 22 on be6d827, 12 of 33 on the commits after it)
    planner(ros, tmp_path, confirm_paths=True)
    arm = mock(ros, scenario_path('robot_waste'))
    drawn = []          # per markers message: does it draw a path?
    ros.probe.create_subscription(
        MarkerArray, '/probdis_planner/markers',
        lambda m: drawn.append(any(k.ns == 'planned_path' for k in m.markers)),
        QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))

    def awaiting():
        return ros.status.get('state') == 'awaiting_confirmation'

    assert not ros.call('confirm_path').success       # no run yet
    wait_for(lambda: ros.call('start').success, 20, 'start')
    wait_for(awaiting, 20, 'the first path proposed')
    first = ros.status
    assert first['paths'] == 1 and 'confirm_path' in first['message']
    proposed = np.array(first['proposed_path'])
    np.testing.assert_allclose(proposed[0], START, atol=0.05)
    time.sleep(0.5)
    assert not ros.trajectories, 'nothing is sent while the path waits'
    np.testing.assert_allclose(arm.q, START, atol=1e-3)
    wait_for(lambda: drawn and drawn[-1], 5, 'the proposal drawn')
    # declined: another plan from the same start, not counted as a path tried
    shown = len(drawn)
    declined = ros.call('decline_path')
    assert declined.success and 'declined' in declined.message
    wait_for(lambda: awaiting() and ros.status['proposed_path'] is not None
             and ros.status['message'].startswith('proposal 2'), 20,
             'a second proposal')
    assert ros.status['paths'] == 1 and not ros.trajectories
    wait_for(lambda: drawn[-1], 5, 'the second proposal drawn')
    assert False in drawn[shown:], 'the declined path was not taken off the markers'
    confirms = 0
    while not finished(ros):
        if awaiting():
            count = len(ros.trajectories)
            answer = ros.call('confirm_path')
            if not answer.success:      # the arm settled on since: planned again, not sent
                assert 'not sent' in answer.message, answer.message
                continue
            confirms += 1
            wait_for(lambda n=count: len(ros.trajectories) > n, 5, 'the confirmed path sent')
        time.sleep(0.05)
        assert confirms <= 20
    status = ros.status
    assert status['state'] == 'succeeded', status
    assert confirms == status['paths'] >= 1 and status['proposed_path'] is None
    assert status['peak_external_torque_nm'] is None     # the kinematic arm has no efforts


def test_stop_during_planning_sends_no_path(ros, tmp_path):
    planner(ros, tmp_path)
    steady_states(ros)
    wait_for(lambda: ros.call('start').success, 10, 'start')
    assert ros.call('stop').success
    count = len(ros.trajectories)
    time.sleep(1.5)
    assert all(len(msg.points) == 1 for _, msg in ros.trajectories[count - 1:])
    assert ros.status['state'] == 'stopped'


def mock_process(ros, *params):
    """Run the mock iiwa as its own process in the test's domain."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
    args = [a for p in ('engine:=kinematic', *params) for a in ('-p', p)]
    return subprocess.Popen([sys.executable, '-m', 'probdis_ros.ros.mock_iiwa_node',
                             '--ros-args', *args], env=env)


def serving(node, timeout=60.0):
    """
    Wait until a mock process answers the planner node's parameter requests.

    A run started at the mock's first joint states meets a mock still starting up: its
    services not yet found, its executor busy.  The node's controller_node must be the
    mock's (``/mock_iiwa``).
    """
    wait_for(lambda: node.controller_setting.value is not None, timeout,
             "the mock's controller to answer")


def test_joint_state_noise_gives_no_false_blocks(ros, tmp_path):
    node = planner(ros, tmp_path, velocity_scaling=0.5, controller_node=f'/{MOCK_NODE}')
    arm = mock_process(ros, f'scenario:={free_scenario(tmp_path)}', 'noise:=0.001', 'seed:=3')
    try:
        serving(node)
        wait_for(lambda: ros.call('start', timeout=30).success, 30, 'start')
        wait_for(lambda: finished(ros), 60, 'the run to end')
        assert ros.status['state'] == 'succeeded'
        assert ros.status['failures'] == 0 and ros.status['paths'] == 1
    finally:
        arm.send_signal(signal.SIGINT)
        arm.wait(10)


def test_the_planner_keeps_up_with_joint_states_at_1khz(ros, tmp_path):
    """The mock runs in its own process at 1 kHz; the planner must not fall behind."""
    # the kinematic arm lags its command by the driver's filter alone (0.04 s); at full speed
    # a block during the acceleration is traced back to the motion's start (a known limit of
    # the onset, README), so this runs at 0.3
    node = planner(ros, tmp_path, state_timeout=2.0, motion_delay=0.04, velocity_scaling=0.3,
                   controller_node=f'/{MOCK_NODE}')
    arm = mock_process(ros, 'rate:=1000.0')
    serving(node)
    ages = []
    # how long ago the newest accepted state arrived (its stamp may be older: a starved
    # mock runs late; the planner's own backlog is what this test is about)
    ros.probe.create_timer(0.02, lambda: node.measured is not None and ages.append(
        node._now() - node.state_check.last_time))
    try:
        wait_for(lambda: ros.call('start', timeout=30).success, 30, 'start')
        wait_for(lambda: ros.status.get('failures', 0) >= 1 or finished(ros), 60,
                 'the first block')
        assert ros.status['state'] not in ('stopped', 'gave_up'), ros.status
        # the block was detected at a hidden disc, not traced back to the start 0.18 m from
        # every disc (the map reaches the disk from the planner's I/O thread, just after the
        # status).  The states are dated by their stamps: dated by arrival, a burst held up
        # in a starved mock (it takes a long command message for half a second on a slow
        # 2-core machine) read as a lagging arm and the block was traced back to the start.
        # A mock that takes the command up to LATE_TAKE late (sharing the cores) lags the
        # planner's model of it by that much, and the gap's rise in the acceleration moves
        # the onset before the touch: 0 to 29 mm from the disc in 36 runs on an idle
        # machine (2026-12-05, code of then and of the session before alike)
        wait_for(lambda: (tmp_path / 'map.json').exists(), 5, 'the map file')
        x = FailureMap.load(tmp_path / 'map.json').points[0]
        gaps = [abs((x - o.center) @ o.normal) + max(0.0, np.linalg.norm(x - o.center) - o.radius)
                for o in WORLD.obstacles]
        assert min(gaps) < 0.05, gaps
        # no growing queue: the newest state stays fresh to the end (a backlog of 1 kHz
        # messages would age steadily, by seconds); single late samples are the scheduler,
        # not a queue, and a mock sharing the cores with another process publishes only
        # every 20-30 ms (one state per timer tick, after catching up; the median age was
        # 0.11 s in a CI run on 2026-12-05 while this machine ran at a third of its speed)
        late = ages[len(ages) // 2:]
        assert np.median(late) < 0.2 and np.percentile(late, 95) < 0.5, ages
    finally:
        arm.send_signal(signal.SIGINT)
        arm.wait(10)


def test_reset_map_clears_the_file_and_is_refused_during_a_run(ros, tmp_path):
    fmap = FailureMap(iiwa_arm().task_space)
    fmap.add([0.5, 0, 0.4], [0, 0, 1], [1, 0, 0, 0])
    fmap.save(tmp_path / 'map.json')
    planner(ros, tmp_path)
    wait_for(lambda: ros.status.get('failures') == 1, 10, 'the map to load')
    response = ros.call('reset_map')
    assert response.success and 'cleared 1' in response.message
    wait_for(lambda: len(FailureMap.load(tmp_path / 'map.json')) == 0, 5,
             'the emptied map file (written by the I/O thread)')
    steady_states(ros)
    wait_for(lambda: ros.call('start').success, 10, 'start')
    assert not ros.call('reset_map').success


def test_a_killed_planner_gets_its_map_back(ros, tmp_path):
    mock(ros)
    map_file = tmp_path / 'map.json'
    command = [sys.executable, '-m', 'probdis_ros.ros.planner_node', '--ros-args',
               '-p', f'goal:={GOAL.tolist()}', '-p', f'map_file:={map_file}',
               '-p', 'state_timeout:=2.0', '-p', f'bag_dir:={tmp_path / "bags"}']
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
    first = subprocess.Popen(command, env=env)
    try:
        wait_for(lambda: ros.call('start', timeout=60).success, 60, 'start')
        wait_for(lambda: ros.status.get('failures', 0) >= 1, 60, 'a failure')
        wait_for(map_file.exists, 5, 'the map file')      # written by the I/O thread
    finally:
        first.send_signal(signal.SIGKILL)
        first.wait()
    saved = len(FailureMap.load(map_file))
    assert saved >= 1
    ros.statuses.clear()
    second = subprocess.Popen(command, env=env)
    try:
        wait_for(lambda: ros.status.get('state') == 'idle', 60, 'the restarted planner')
        assert ros.status['failures'] == saved
    finally:
        second.send_signal(signal.SIGINT)
        assert second.wait(10) == 0


def test_a_fault_inside_the_run_stops_the_arm_and_the_node_lives_on(ros, tmp_path):
    node = planner(ros, tmp_path)
    steady_states(ros)
    wait_for(lambda: ros.call('start').success, 10, 'start')

    on_joint_state, faults = node.run.on_joint_state, []

    def broken(*args):          # after a failure was learned: it is kept all the same
        if faults:              # one fault (the next states reach the stopped run as ever;
            return on_joint_state(*args)     # a fault at each added a failure at each)
        faults.append(args)
        run = node.run
        run.loop.learn(START, np.eye(7)[0])
        run.actions.append(Learned({'t': 0.0, 'x': run.loop.fmap.points[-1].tolist()}))
        raise ValueError('injected fault')
    node.run.on_joint_state = broken
    wait_for(lambda: finished(ros), 5, 'the run to stop')
    assert ros.status['state'] == 'stopped' and 'internal error' in ros.status['message']
    saved = tmp_path / 'map.json'         # by the I/O thread, maybe after the status: waited for
    wait_for(lambda: saved.exists() and len(FailureMap.load(saved)) == 1, 5, 'the map saved')
    last = ros.trajectories[-1][1]        # the stop: at most where the command had begun
    assert np.allclose(last.points[-1].positions, START, atol=1e-3) and \
        np.allclose(last.points[-1].velocities, 0.0)
    assert ros.call('start').success          # alive, and ready for the next run


def test_an_interrupted_run_keeps_its_map_for_the_next_start(ros, tmp_path):
    node = planner(ros, tmp_path)
    fmap = FailureMap(node.arm.task_space)
    fmap.add(np.array([0.5, 0.0, 0.5]), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0, 0, 0]))
    node.fmap = fmap
    steady_states(ros)
    wait_for(lambda: ros.call('start').success, 10, 'start')
    assert ros.call('stop').success
    wait_for(lambda: finished(ros), 5, 'the stop')
    assert ros.call('start').success and ros.status['failures'] == 1


FROZEN_NODE = """
import gc
import sys
from probdis_ros.ros.node_main import run_node
from rclpy.node import Node


def factory():
    node = Node('frozen_check')

    def look():
        print(gc.get_freeze_count(), len(gc.get_objects()), flush=True)
        raise KeyboardInterrupt

    node.create_timer(0.01, look)
    return node


sys.exit(run_node('frozen_check', factory))
"""


def test_a_node_process_spins_with_its_start_up_objects_left_out_of_collections(ros):
    """
    What start-up built is frozen: a full collection no longer walks it.

    In the planner a full collection walked the kernels and libraries for 50-110 ms when a
    long path's message was built; on simulated time at 5x the mock ran half a second on
    meanwhile, and the arm, which had not yet received the path, was judged never to move.
    """
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
    done = subprocess.run([sys.executable, '-c', FROZEN_NODE], capture_output=True, text=True,
                          env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    frozen, walked = map(int, done.stdout.split())
    assert frozen > 10 * walked, (frozen, walked)
