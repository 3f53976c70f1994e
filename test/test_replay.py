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

"""Recording and replay: bags in both storage formats, a recorded mock run, killed nodes."""

import json
import os
from pathlib import Path
import signal
import subprocess
import sys

from conftest import probdis_command
from linear_path import time_path
import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.model.failure_map import lock_map
from probdis_ros.motion.cartesian_speed import point_speeds
from probdis_ros.motion.detector import DetectorSettings
from probdis_ros.planning.disentangle import failure_from_block
from probdis_ros.resources import scenario_path
from probdis_ros.ros.mock_iiwa_node import MockIiwa
from probdis_ros.ros.planner_node import PlannerNode
from probdis_ros.ros.replay import calibrate, replay, ReplayError
from probdis_ros.sim.worlds import load_world
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from ros_harness import RosTest, wait_for
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from rosbags.typesys.base import Nodetype
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory

WORLD = load_world(scenario_path('demo_iiwa'))
JS, TRAJ = '/lbr/joint_states', '/lbr/joint_trajectory_controller/joint_trajectory'
STORE = get_typestore(Stores.ROS2_JAZZY)
JS_TYPE, TRAJ_TYPE = 'sensor_msgs/msg/JointState', 'trajectory_msgs/msg/JointTrajectory'
RATE = 100.0
JOINTS = [f'lbr_A{i}' for i in range(1, 8)]


def js_message(names, q, stamp):
    """Return a sensor_msgs/JointState as plain fields (for any writer)."""
    return {'header': {'stamp': {'sec': int(stamp), 'nanosec': int((stamp % 1) * 1e9)},
                       'frame_id': ''},
            'name': list(names), 'position': [float(v) for v in q], 'velocity': [],
            'effort': []}


def traj_message(timed, names):
    """Return a trajectory_msgs/JointTrajectory as plain fields (for any writer)."""
    points = [{'positions': [float(v) for v in q], 'velocities': [], 'accelerations': [],
               'effort': [], 'time_from_start': {'sec': int(s), 'nanosec': int((s % 1) * 1e9)}}
              for q, s in zip(timed.points[1:], timed.times[1:])]
    return {'header': {'stamp': {'sec': 0, 'nanosec': 0}, 'frame_id': ''},
            'joint_names': list(names), 'points': points}


def rosbags_bytes(fields, msgtype):
    """Serialize plain fields with rosbags (nested dicts become rosbags message objects)."""
    def build(value, typename):
        cls = STORE.types[typename]
        kwargs = {}
        for name, (kind, spec) in STORE.fielddefs[typename][1]:
            item = value[name]
            if kind == Nodetype.NAME:
                kwargs[name] = build(item, spec)
            elif kind == Nodetype.SEQUENCE and spec[0][0] == Nodetype.NAME:
                kwargs[name] = [build(x, spec[0][1]) for x in item]
            elif kind == Nodetype.SEQUENCE and spec[0][1][0] == 'float64':
                kwargs[name] = np.asarray(item, dtype=float)
            else:
                kwargs[name] = item
        return cls(**kwargs)
    return STORE.serialize_cdr(build(fields, msgtype), msgtype)


def js_bytes(names, q, stamp):
    return rosbags_bytes(js_message(names, q, stamp), JS_TYPE)


def simulated_run(names_order=None, extra=False):
    """
    Joint states of the arm following the straight move into the box, until it stops.

    Returns the messages as (stamp [ns], topic, plain fields), the stop configuration and
    the time of the stop after the first message [s].
    """
    arm = iiwa_arm()
    path = np.array([WORLD.start, WORLD.goal])
    timed = time_path(path, arm.velocity_limits, 0.5)
    stop = WORLD.compliant_arm().execute(path).config
    fraction = np.linalg.norm(stop - path[0]) / np.linalg.norm(path[1] - path[0])
    t_stop = fraction * timed.duration
    events = [(0.0, 'js', WORLD.start), (0.05, 'traj', timed)]
    for k in range(1, int(3.0 * RATE)):
        t = 0.05 + k / RATE
        events.append((t, 'js', timed.at(min(t - 0.05, t_stop))))
    order = names_order or list(range(7))
    names = [f'lbr_A{i + 1}' for i in order] + (['gripper_finger'] if extra else [])
    out = []
    for t, kind, value in events:
        stamp = int((1.0 + t) * 1e9)
        if kind == 'js':
            q = [value[i] for i in order] + ([0.01] if extra else [])
            out.append((stamp, JS, js_message(names, q, 1.0 + t)))
        else:
            out.append((stamp, TRAJ, traj_message(value, [f'lbr_A{i}' for i in range(1, 8)])))
    return out, stop, 0.05 + t_stop


def write_bag(path, messages, version, plugin, types=None, store=STORE):
    """Write (stamp, topic, fields or bytes) messages with rosbags."""
    types = types or {JS: JS_TYPE, TRAJ: TRAJ_TYPE}
    with Writer(path, version=version, storage_plugin=plugin) as writer:
        conns = {topic: writer.add_connection(topic, types[topic], typestore=store)
                 for topic in {m[1] for m in messages}}
        for stamp, topic, fields in messages:
            data = rosbags_bytes(fields, types[topic]) if isinstance(fields, dict) else fields
            writer.write(conns[topic], stamp, data)


FORMATS = [(9, StoragePlugin.MCAP), (8, StoragePlugin.SQLITE3), (9, StoragePlugin.SQLITE3)]


@pytest.mark.parametrize('version, plugin', FORMATS)
def test_replay_finds_the_block_in_both_storage_formats(tmp_path, version, plugin):
    messages, stop, t_stop = simulated_run(names_order=[3, 0, 6, 1, 5, 2, 4], extra=True)
    write_bag(tmp_path / 'bag', messages, version, plugin)
    result = replay(tmp_path / 'bag')
    assert result.paths == 1 and not result.success
    assert len(result.blocks) == 1 and len(result.fmap) == 1
    block = result.blocks[0]
    np.testing.assert_allclose(block.config, stop, atol=1e-9)
    assert np.linalg.norm(block.x - iiwa_arm().fk(stop).positions[0]) < 1e-3
    # stalled for stall_time (0.3 s) after the stop, give or take a control period
    assert t_stop + 0.3 - 0.02 <= block.t <= t_stop + 0.3 + 0.02


def test_an_arm_of_another_robot_name_is_replayed_by_the_names_its_commands_give(tmp_path):
    # a planner run with joint_names iiwa7_A1..: every state was refused for lacking lbr_A1..,
    # and the replay said "0 path(s)", exit 0, with --save-map an empty map
    messages, stop, _ = simulated_run()
    for _, _, fields in messages:
        key = 'name' if 'name' in fields else 'joint_names'
        fields[key] = [n.replace('lbr_', 'iiwa7_') for n in fields[key]]
    write_bag(tmp_path / 'bag', messages, *FORMATS[0])
    result = replay(tmp_path / 'bag')
    assert result.paths == 1 and len(result.blocks) == 1
    np.testing.assert_allclose(result.blocks[0].config, stop, atol=1e-9)
    # states of joints the commands do not name are all refused: an error, not a success
    commands = [m for m in simulated_run()[0] if m[1] == TRAJ]
    write_bag(tmp_path / 'other', [m for m in messages if m[1] == JS] + commands, *FORMATS[0])
    with pytest.raises(ReplayError, match=r'every joint state was refused .* lbr_A1'):
        replay(tmp_path / 'other')


def test_the_statuses_of_two_planners_recorded_by_ros2_bag_are_told_from_the_commands(tmp_path):
    # ros2 bag record -a in a cell of two arms: the other arm's "succeeded" ended this arm's
    # run in the replay, its commands were then holds, and its block was missed
    messages, _, _ = simulated_run()
    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE}
    t0 = messages[0][0]
    for arm in ('left', 'right'):
        status = f'/{arm}/probdis_planner/status'
        types[status] = 'std_msgs/msg/String'
        messages.append((t0 - 1, status, {'data': json.dumps({'state': 'succeeded'})}))
    write_bag(tmp_path / 'bag', messages, *FORMATS[0], types=types)
    result = replay(tmp_path / 'bag')
    assert result.paths == 1 and len(result.blocks) == 1
    assert any('statuses of 2 planners' in p for p in result.problems)


@pytest.mark.parametrize('command_first', [False, True])
def test_a_stamped_command_from_an_arm_whose_clock_is_off_is_replayed_on_the_bags_clock(
        tmp_path, command_first):
    # the planner stamps a desired start's command on the arm's clock (its joint states'),
    # 3 s ahead of its own here; the replay moves the stamp back by the states' offset, and
    # finds the block where it finds it for the same command unstamped; recorded before the
    # first joint state too (by the offset that state then shows, not by none)
    messages, _, t_stop = simulated_run()
    if command_first:
        assert messages[0][1] == JS and messages[1][1] == TRAJ
        messages = messages[1:]

    def stamped(fields, seconds):
        sec = int(seconds // 1)
        return dict(fields, header={'stamp': {'sec': sec, 'nanosec': int((seconds - sec) * 1e9)},
                                    'frame_id': ''})

    off = [(ns, topic, stamped(fields, ns * 1e-9 + 3.0)) for ns, topic, fields in messages]
    write_bag(tmp_path / 'bag', off, *FORMATS[0])
    result = replay(tmp_path / 'bag')
    assert result.paths == 1 and len(result.blocks) == 1, result.problems
    t_stop -= 0.05 if command_first else 0.0            # the recording starts at the command
    assert t_stop + 0.3 - 0.02 <= result.blocks[0].t <= t_stop + 0.3 + 0.02


def test_joint_states_held_up_in_delivery_are_dated_by_their_stamps(tmp_path):
    # a free move recorded by `ros2 bag record` on a busy machine: half a second of joint
    # states held up and written at once; the live planner dates them by their stamps
    arm = iiwa_arm()
    path = np.array([WORLD.start, WORLD.start + np.array([0.8, -0.4, 0.0, 0.6, 0.0, -0.5, 1.2])])
    timed = time_path(path, arm.velocity_limits, 0.5)
    messages = [(int(1e9), JS, js_message(JOINTS, path[0], 1.0)),
                (int(1.05e9), TRAJ, traj_message(timed, JOINTS))]
    for t in np.arange(0.05, timed.duration + 1.0, 1.0 / RATE):
        received = max(t, 1.0) if 0.5 <= t < 1.0 else t
        messages.append((int((1.0 + received) * 1e9) + 500_000 + len(messages), JS,
                         js_message(JOINTS, timed.at(t - 0.05), 1.0 + t)))
    write_bag(tmp_path / 'bag', messages, *FORMATS[0])
    result = replay(tmp_path / 'bag')
    assert result.paths == 1 and result.blocks == [] and result.success, result.problems


@pytest.mark.parametrize('recorder', ['ros2 bag', 'ros2 bag -a', 'probdis'])
def test_states_are_replayed_at_the_times_the_planner_dated_them(tmp_path, recorder):
    # the planner records each state at the time it dated it, from a delivery it learned
    # long before the bag began; re-dated from the bag alone, a live block at a gap 3e-5 rad
    # past its ceiling came a millisecond early and was missed. Another recorder's bag holds
    # receive times: those are dated by stamp, as the planner dates them, also where it
    # recorded the planner's status too (ros2 bag record -a: read as the planner's own bag,
    # a burst of states held up in delivery was a false block)
    delivery = [0.001] + [0.005] * 99          # one state delivered quicker than the rest
    messages = [(round((2.0 + k / RATE + d) * 1e9), JS,
                 js_message(JOINTS, WORLD.start, 2.0 + k / RATE))
                for k, d in enumerate(delivery)]
    move = time_path(np.array([WORLD.start, WORLD.start + 0.1]), iiwa_arm().velocity_limits,
                     0.5)
    messages.append((round(3.1e9), TRAJ, traj_message(move, JOINTS)))
    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE}
    if recorder != 'ros2 bag':                 # the planner's status is recorded
        status = '/probdis_planner/status'
        types[status] = 'std_msgs/msg/String'
        messages.insert(0, (round(1.9e9), status,
                            {'data': json.dumps({'state': 'idle', 'paths': 0})}))
    by_probdis = recorder == 'probdis'
    if by_probdis:                             # and the planner says the bag is its own
        marker = '/probdis_planner/recording'
        types[marker] = 'std_msgs/msg/String'
        messages.insert(0, (round(1.9e9), marker, {'data': json.dumps({'status': status})}))
    write_bag(tmp_path / 'bag', messages, *FORMATS[0], types=types)
    result = replay(tmp_path / 'bag')
    t0 = messages[0][0] * 1e-9
    stamps = 2.0 + np.arange(100) / RATE
    recorded = stamps + np.array(delivery)
    expected = recorded if by_probdis else stamps + 0.001
    np.testing.assert_allclose(np.array(result.times) + t0, expected, atol=1e-6)


SHORT_MOVE = np.array([0.5, -0.3, 0.0, 0.4, 0.0, -0.3, 0.6])


def free_move(lag, rest=0.0, move=SHORT_MOVE, begin=1.0, start=WORLD.start):
    """
    Return the messages of a free move by an arm lag [s] behind its command, and its timing.

    ``rest``: the L1 gap [rad] at which the arm comes to rest (friction, load-data error),
    growing along the way; ``begin``: the bag time of its first state [s].
    """
    arm = iiwa_arm()
    timed = time_path(np.array([start, start + move]), arm.velocity_limits, 0.5)
    offset = np.array([rest / 2, 0.0, rest / 2, 0.0, 0.0, 0.0, 0.0])
    messages = [(int(begin * 1e9), JS, js_message(JOINTS, start, begin)),
                (int((begin + 0.05) * 1e9), TRAJ, traj_message(timed, JOINTS))]
    for t in np.arange(0.05, timed.duration + 1.5, 1.0 / RATE):
        share = min(max(t - 0.05, 0.0) / timed.duration, 1.0)
        messages.append((int((begin + t) * 1e9), JS, js_message(
            JOINTS, timed.at(max(t - 0.05 - lag, 0.0)) - share * offset, begin + t)))
    return messages, timed


def free_move_bag(path, lag, rest=0.0, move=SHORT_MOVE):
    """Write a bag of one free move (:func:`free_move`); return its timing."""
    messages, timed = free_move(lag, rest, move)
    write_bag(path, messages, *FORMATS[0])
    return timed


def test_a_free_move_gives_the_least_peak_gap_at_the_arms_own_lag_and_its_top_speed(
        tmp_path):
    # README: motion_delay is measured on the arm by replaying a free move with several
    arm = iiwa_arm()
    lag = 0.08
    move = np.array([0.8, -0.4, 0.0, 0.6, 0.0, -0.5, 1.2])
    timed = free_move_bag(tmp_path / 'bag', lag, move=move)
    peaks = {delay: replay(tmp_path / 'bag', overrides={'motion_delay': delay}).peak_gap
             for delay in (0.0, 0.04, lag, 0.12, 0.16)}
    assert min(peaks, key=peaks.get) == lag, peaks
    assert peaks[lag] < 0.2 * peaks[0.0], peaks
    # and the fastest point of the arm, what KUKA's Cartesian speed monitoring would see
    # (README, T1): from the positions (these states carry no velocities), against the
    # move's own points differenced every millisecond
    fine = np.array([timed.at(t) for t in np.arange(0.0, timed.duration, 1e-3)])
    truth = point_speeds(arm, fine[:-1], np.diff(fine, axis=0) / 1e-3).max()
    assert truth > 0.3
    fastest = replay(tmp_path / 'bag').summary()['peak_point_speed_mps']
    assert fastest == pytest.approx(truth, rel=0.03)


@pytest.mark.parametrize('lag, rest', [(0.03, 0.0), (0.17, 0.06)])
def test_calibrate_finds_the_arms_lag_in_a_free_move(tmp_path, lag, rest):
    # README, first session: one command instead of a replay per motion_delay by hand
    free_move_bag(tmp_path / 'free', lag, rest)
    result = run_replay(tmp_path / 'free', '--calibrate', '--json', '--plot',
                        str(tmp_path / 'lag.png'))
    assert result.returncode == 0, result.stderr
    fit = json.loads(result.stdout)
    assert fit['motion_delay_s'] == pytest.approx(lag, abs=0.011), fit
    low, high = fit['equally_good_s']
    assert low <= fit['motion_delay_s'] <= high and high - low <= 0.02, fit
    gaps = {row['motion_delay_s']: row['peak_gap_rad'] for row in fit['tried']}
    assert len(gaps) == 41 and min(gaps.values()) == fit['peak_gap_rad']
    assert fit['peak_gap_rad'] < 0.3 * max(gaps[0.0], gaps[0.4]), fit
    assert fit['rest_gap_rad'] == pytest.approx(rest, abs=0.002)
    assert (tmp_path / 'lag.png').stat().st_size > 10_000
    if rest:    # the text says what to set, and that the arm rests near d_dist
        text = run_replay(tmp_path / 'free', '--calibrate').stdout
        assert f'probdis param set motion_delay {fit["motion_delay_s"]:g}' in text
        assert 'rests 0.060 rad off its command, more than half of d_dist 0.1' in text


def test_calibrate_refuses_a_bag_that_is_no_free_move(tmp_path):
    # the arm stopped by a block, at every delay
    messages, _, _ = simulated_run()
    write_bag(tmp_path / 'blocked', messages, *FORMATS[0])
    with pytest.raises(ReplayError, match='not one free move at any motion_delay'):
        calibrate(tmp_path / 'blocked', delays=(0.0, 0.2, 0.4))
    # two moves, free at a delay (the demo's bag read so at long delays: a block unseen
    # there, the retreat a second path): no lag to tell from a path that was blocked
    first, _ = free_move(0.05)
    second, _ = free_move(0.05, begin=first[-1][0] * 1e-9 + 0.01,
                          start=WORLD.start + SHORT_MOVE, move=-SHORT_MOVE)
    write_bag(tmp_path / 'two', first + second, *FORMATS[0])
    both = replay(tmp_path / 'two', overrides={'motion_delay': 0.05})
    assert both.paths == 2 and not both.blocks
    with pytest.raises(ReplayError, match='not one free move at any motion_delay'):
        calibrate(tmp_path / 'two', delays=(0.0, 0.05, 0.1))


@pytest.mark.parametrize('short', [0.03, 0.12])
def test_the_gap_at_rest_after_a_free_move_is_told_and_above_d_dist_reads_as_a_block(
        tmp_path, short):
    # joint friction and load-data error hold the arm off its command at rest (3 Nm a joint
    # ended free moves of the physics mock blocked): the user must see how far, to keep
    # d_dist above it (README, first session)
    free_move_bag(tmp_path / 'bag', 0.1, short)
    result = replay(tmp_path / 'bag')
    if short < result.settings.d_dist:
        assert result.success and not result.blocks
        assert result.rest_gap == pytest.approx(short, abs=0.002)
        assert result.summary()['rest_gap_rad'] == result.rest_gap
    else:
        assert len(result.blocks) == 1 and result.rest_gap == 0.0


def test_a_command_recorded_before_the_first_joint_state_starts_from_the_first_one(tmp_path):
    messages, stop, _ = simulated_run()
    assert messages[0][1] == JS and messages[1][1] == TRAJ
    write_bag(tmp_path / 'bag', messages[1:], *FORMATS[0])     # the command comes first
    result = replay(tmp_path / 'bag')
    assert result.paths == 1 and len(result.blocks) == 1
    assert any('before any joint state' in p for p in result.problems)
    assert np.linalg.norm(result.blocks[0].x - iiwa_arm().fk(stop).positions[0]) < 0.02


def test_a_run_stopped_as_not_executed_is_not_replayed_as_disentangled(tmp_path):
    # the live run stops when a path is never followed; its stop comes before the status
    # that says so, and replayed as a new path that ran to its end, it counted as success
    arm = iiwa_arm()
    start = WORLD.start
    away = start + np.array([0.4, -0.2, 0.0, 0.3, 0.0, -0.2, 0.5])
    path = time_path(np.array([start, away]), arm.velocity_limits, 0.5)
    stop = time_path(np.array([start, start + (away - start) * 0.2]), arm.velocity_limits, 0.5)
    messages = [(int(1e9), JS, js_message(JOINTS, start, 1.0)),
                (int(1.05e9), TRAJ, traj_message(path, JOINTS))]
    t, stop_sent = 0.05, None
    while t < 6.0:
        t += 1.0 / RATE
        if stop_sent is None and t > 0.05 + 2.5:         # past START_WAIT: stopped live
            stop_sent = t
            messages.append((int((1.0 + t) * 1e9) + 1, TRAJ, traj_message(stop, JOINTS)))
        q = start if stop_sent is None else stop.at(min(t - stop_sent, stop.duration))
        messages.append((int((1.0 + t) * 1e9), JS, js_message(JOINTS, q, 1.0 + t)))
    write_bag(tmp_path / 'bag', sorted(messages, key=lambda m: m[0]), *FORMATS[0])
    result = replay(tmp_path / 'bag')
    assert any('nothing executed the command' in p for p in result.problems)
    assert result.paths == 1 and not result.success and result.blocks == []


def test_a_block_seen_after_a_gap_in_the_states_is_learned_along_the_edge_the_arm_was_on(
        tmp_path):
    # the arm stops dead on the first edge; no states reach the recording until the command
    # runs the second (a planner that could not run): the failure moves the way the first
    # edge does, as the live run now learns it (Motion.edge_reached), not the second's way
    arm = iiwa_arm()
    q0 = WORLD.start
    via, goal = q0 + np.r_[0.3, [0.0] * 6], q0 + np.r_[0.3, 0.3, [0.0] * 5]
    timed = time_path(np.array([q0, via, goal]), arm.velocity_limits, 0.5)
    delay = DetectorSettings().motion_delay
    at_via = float(timed.times[1])
    stop = 0.5 * at_via

    def state(t):
        return timed.at(min(max(t - delay, 0.0), stop))
    messages = [(int(1e9), JS, js_message(JOINTS, q0, 1.0)),
                (int(1.05e9), TRAJ, traj_message(timed, JOINTS))]
    for t in np.arange(0.06, at_via + delay + 0.8, 1.0 / RATE):
        if not stop + delay + 0.02 < t - 0.05 < at_via + delay + 0.3:     # the gap
            q = state(t - 0.05)
            messages.append((int((1.05 + t) * 1e9), JS, js_message(JOINTS, q, 1.05 + t)))
    write_bag(tmp_path / 'bag', messages, *FORMATS[0])
    result = replay(tmp_path / 'bag')
    assert len(result.blocks) == 1
    block = result.blocks[0]
    assert block.t > at_via + 1.05 - 1.0 + delay                 # seen on the second edge
    _, v, _ = failure_from_block(arm, block.config, via - q0)
    assert np.dot(result.fmap.directions[0], v / np.linalg.norm(v)) > 0.99


def test_a_stop_sent_as_a_run_ends_is_no_path_of_it(tmp_path):
    # a run that gave up: its last path blocked, the planner retreated and then stopped the
    # arm, moving, before its status said so; the stop, taken for a new path that ran to its
    # end, replayed the run as disentangled
    messages, held, t_stop = simulated_run()
    t_block = 1.0 + t_stop + 0.35
    arm = iiwa_arm()
    retreat = time_path(np.array([held, WORLD.start]), arm.velocity_limits, 0.5)
    brake = time_path(np.array([held, held + 0.05]), arm.velocity_limits, 0.5)
    status = '/probdis_planner/status'
    messages = [m for m in messages if m[0] <= t_block * 1e9]
    messages += [(int(t_block * 1e9) + 1, TRAJ, traj_message(retreat, JOINTS)),
                 (int(t_block * 1e9) + 2, TRAJ, traj_message(brake, JOINTS)),
                 (int(t_block * 1e9) + 3, status,
                  {'data': json.dumps({'state': 'gave_up', 'paths': 1})})]
    for k in range(1, int(2.0 * RATE)):
        t = t_block + k / RATE
        messages.append((int(t * 1e9), JS, js_message(JOINTS, brake.at(k / RATE), t)))
    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE, status: 'std_msgs/msg/String'}
    write_bag(tmp_path / 'bag', sorted(messages, key=lambda m: m[0]), *FORMATS[0], types=types)
    result = replay(tmp_path / 'bag')
    assert len(result.blocks) == 1 and not result.success


def test_a_path_the_run_ended_on_as_done_is_done_though_the_status_came_a_state_earlier(
        tmp_path):
    # the live planner judged the path done at a state the replay judges a state later:
    # "succeeded" says nothing of a stop to come, and the replay keeps judging the path
    arm = iiwa_arm()
    path = time_path(np.array([WORLD.start, WORLD.start + 0.1]), arm.velocity_limits, 0.5)
    status = '/probdis_planner/status'
    messages = followed(path)
    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE, status: 'std_msgs/msg/String'}
    done = replay_of(tmp_path / 'free', messages, types)
    assert done.success
    t_done = 1.01 + path.duration + DetectorSettings().motion_delay
    messages.append((int(t_done * 1e9), status,
                     {'data': json.dumps({'state': 'succeeded', 'paths': 1})}))
    assert replay_of(tmp_path / 'ended', messages, types).success


def followed(path) -> list:
    """Return the messages of an arm at WORLD.start sent path at 1.01 s, motion_delay behind it."""
    messages = [(int(1e9), JS, js_message(JOINTS, WORLD.start, 1.0)),
                (int(1.01e9), TRAJ, traj_message(path, JOINTS))]
    for k in range(1, int((path.duration + 1.0) * RATE)):
        t = 1.01 + k / RATE
        q = path.at(max(k / RATE - DetectorSettings().motion_delay, 0.0))
        messages.append((int(t * 1e9), JS, js_message(JOINTS, q, t)))
    return messages


def replay_of(bag, messages, types):
    """Write the messages (in time order) as a bag and replay it."""
    write_bag(bag, sorted(messages, key=lambda m: m[0]), *FORMATS[0], types=types)
    return replay(bag)


def test_replay_refuses_bad_bags_clearly(tmp_path):
    with pytest.raises(ReplayError, match='no such bag'):
        replay(tmp_path / 'missing')
    (tmp_path / 'notabag').mkdir()
    with pytest.raises(ReplayError, match=r'not a readable rosbag2 bag \(a folder without '
                       r'metadata\.yaml or an \.mcap file\)'):
        replay(tmp_path / 'notabag')
    messages, _, _ = simulated_run()
    write_bag(tmp_path / 'nojs', [m for m in messages if m[1] == TRAJ], 9, StoragePlugin.MCAP)
    with pytest.raises(ReplayError, match='no /lbr/joint_states topic'):
        replay(tmp_path / 'nojs')


def test_a_path_whose_first_point_lies_near_the_arm_is_a_path_not_a_hold(tmp_path):
    # the planner's commands have a point every controller period, the first a hair from
    # the arm: only a command that goes nowhere (one point at the arm) is a hold
    arm = iiwa_arm()
    near = WORLD.start + 0.01 * SHORT_MOVE
    path = time_path(np.array([WORLD.start, near, WORLD.start + SHORT_MOVE]),
                     arm.velocity_limits, 0.5)
    messages = followed(path)
    result = replay_of(tmp_path / 'bag', messages, {JS: JS_TYPE, TRAJ: TRAJ_TYPE})
    assert result.paths == 1 and result.success and not result.blocks, result.problems


def test_a_bag_of_holds_alone_is_no_run(tmp_path):
    # a recording without statuses is one run only where it holds a path
    hold = time_path(np.array([WORLD.start, WORLD.start]), iiwa_arm().velocity_limits, 0.5)
    messages = [(int(1e9), JS, js_message(JOINTS, WORLD.start, 1.0)),
                (int(1.01e9), TRAJ, traj_message(hold, JOINTS))]
    messages += [(int((1.01 + k / RATE) * 1e9), JS,
                  js_message(JOINTS, WORLD.start, 1.01 + k / RATE)) for k in range(1, 100)]
    result = replay_of(tmp_path / 'bag', messages, {JS: JS_TYPE, TRAJ: TRAJ_TYPE})
    assert (result.runs, result.paths, result.success, result.blocks) == (0, 0, False, [])


def test_two_runs_told_by_the_planners_status_count_the_paths_of_both(tmp_path):
    # the status starts a run at "planning" with no paths after "idle" or an outcome; the
    # paths of the bag are the last word of every run, summed
    status = '/probdis_planner/status'
    first, _ = free_move(0.05)
    second, _ = free_move(0.05, begin=first[-1][0] * 1e-9 + 0.01,
                          start=WORLD.start + SHORT_MOVE, move=-SHORT_MOVE)

    def said(ns, state, paths):
        return (ns, status, {'data': json.dumps({'state': state, 'paths': paths})})
    messages = first + second + [
        said(first[0][0] - 3, 'idle', 0), said(first[0][0] - 2, 'planning', 0),
        said(first[-1][0] - 1, 'succeeded', 1), said(first[-1][0] + 1, 'idle', 1),
        said(second[0][0] - 1, 'planning', 0), said(second[-1][0] - 1, 'succeeded', 1)]
    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE, status: 'std_msgs/msg/String'}
    result = replay_of(tmp_path / 'bag', messages, types)
    assert (result.runs, result.paths, result.success) == (2, 2, True), result.problems


def test_a_path_after_a_blocked_retreat_is_a_path(tmp_path):
    # only a blocked path is followed by a retreat; a retreat that is blocked too is
    # followed by the next path, which counts, and ends the run disentangled here
    messages, held, t_stop = simulated_run()
    t_block = 1.0 + t_stop + 0.35
    arm = iiwa_arm()
    retreat = time_path(np.array([held, WORLD.start]), arm.velocity_limits, 0.5)
    messages = [m for m in messages if m[0] <= t_block * 1e9]
    messages.append((int(t_block * 1e9) + 1, TRAJ, traj_message(retreat, JOINTS)))
    for k in range(1, int(1.5 * RATE)):             # the arm does not move back either
        t = t_block + k / RATE
        messages.append((int(t * 1e9), JS, js_message(JOINTS, held, t)))
    t_path = t_block + 1.5
    away = time_path(np.array([held, held - 0.2 * (WORLD.goal - WORLD.start)]),
                     arm.velocity_limits, 0.5)
    messages.append((int(t_path * 1e9) + 1, TRAJ, traj_message(away, JOINTS)))
    delay = DetectorSettings().motion_delay
    for k in range(1, int((away.duration + 1.0) * RATE)):
        t = t_path + k / RATE
        messages.append((int(t * 1e9), JS,
                         js_message(JOINTS, away.at(max(k / RATE - delay, 0.0)), t)))
    result = replay_of(tmp_path / 'bag', messages, {JS: JS_TYPE, TRAJ: TRAJ_TYPE})
    assert [b.retreat for b in result.blocks] == [False, True]
    assert result.paths == 2 and result.success, result.problems


def test_the_gap_at_rest_told_is_the_largest_after_any_command(tmp_path):
    # two free moves, resting 0.06 rad and then 0.02 rad off their commands: what d_dist
    # must stay above is the larger, not the last
    offset = np.array([0.03, 0.0, 0.03, 0.0, 0.0, 0.0, 0.0])
    first, _ = free_move(0.05, rest=0.06)
    second, _ = free_move(0.05, rest=0.02, begin=first[-1][0] * 1e-9 + 0.01,
                          start=WORLD.start + SHORT_MOVE - offset, move=-SHORT_MOVE)
    write_bag(tmp_path / 'two', first + second, *FORMATS[0])
    result = replay(tmp_path / 'two', overrides={'motion_delay': 0.05})
    assert result.paths == 2 and result.success and not result.blocks, result.problems
    assert result.rest_gap == pytest.approx(0.06, abs=0.002)


def test_the_peak_external_torque_is_the_runs_not_the_stops_after_it(tmp_path):
    # the run gave up: the efforts of the states after (its stop, the arm handled) are
    # plotted, but the peak told is the run's, as the live run's
    messages, held, t_stop = simulated_run()
    t_end = 1.0 + t_stop + 0.35
    status = '/probdis_planner/status'
    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE, status: 'std_msgs/msg/String'}
    messages = [m for m in messages if m[0] <= t_end * 1e9]
    messages.append((int(t_end * 1e9) + 1, status,
                     {'data': json.dumps({'state': 'gave_up', 'paths': 1})}))
    for k in range(1, 50):
        t = t_end + k / RATE
        messages.append((int(t * 1e9), JS, js_message(JOINTS, held, t)))

    def with_efforts(after):
        return [(ns, topic, dict(fields, effort=[after if ns > t_end * 1e9 else 1.0] * 7)
                 if topic == JS else fields) for ns, topic, fields in messages]
    calm = replay_of(tmp_path / 'calm', with_efforts(1.0), types)
    pushed = replay_of(tmp_path / 'pushed', with_efforts(300.0), types)
    assert calm.torque_peak is not None and len(pushed.torques) == len(calm.torques)
    assert max(abs(e).max() for _, e in pushed.torques) > calm.torque_peak.max() + 100
    np.testing.assert_array_equal(pushed.torque_peak, calm.torque_peak)


@pytest.mark.ros
@pytest.mark.parametrize('desired', [False, True])
def test_replay_of_a_recorded_mock_run_finds_the_live_blocks(tmp_path, desired):
    # desired: JTC starts each command from its last one (interpolate_from_desired_state),
    # and the replay must start them where the live planner did
    ros = RosTest()
    try:
        ros.add(PlannerNode(context=ros.context, parameter_overrides=[
            Parameter('goal', value=WORLD.goal.tolist()),
            Parameter('map_file', value=str(tmp_path / 'map.json')),
            Parameter('bag_dir', value=str(tmp_path / 'bags')),
            Parameter('velocity_scaling', value=0.7), Parameter('state_timeout', value=2.0),
            Parameter('max_paths', value=6),
            # the kinematic arm lags its command by the driver's filter alone (0.04 s)
            Parameter('motion_delay', value=0.04),
            Parameter('interpolate_from_desired_state', value=desired),
            Parameter('controller_node', value='/mock_iiwa'),
            # on the mock's clock: a mock that falls behind the wall clock on a busy machine
            # catches up in bursts, which read as motions of something else
            Parameter('use_sim_time', value=True)]))
        env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
        arm = subprocess.Popen([sys.executable, '-m', 'probdis_ros.ros.mock_iiwa_node',
                                '--ros-args', '-p', 'engine:=kinematic', '-p',
                                f'interpolate_from_desired_state:={str(desired).lower()}',
                                '-p', 'sim_time:=true', '-p', 'real_time_factor:=1.0'],
                               env=env)
        try:
            wait_for(lambda: ros.call('start', timeout=30).success, 30, 'start')
            wait_for(lambda: ros.status.get('state') in ('succeeded', 'gave_up', 'stopped'),
                     120, 'the run to end')
            wait_for(lambda: (Path(ros.status['bag']) / 'metadata.yaml').exists(), 5, 'the bag')
            live = ros.status
        finally:
            arm.send_signal(signal.SIGINT)
            arm.wait(10)
    finally:
        ros.close()
    bag = Path(live['bag'])
    with AnyReader([bag]) as reader:
        failures = [(t, json.loads(reader.deserialize(raw, c.msgtype).data))
                    for c, t, raw in reader.messages() if c.topic.endswith('/failures')]
        t0 = reader.start_time
    assert live['jtc_start'] == ('desired' if desired else 'measured')
    result = replay(bag)
    assert result.success == (live['state'] == 'succeeded'), live.get('message')
    assert result.paths == live['paths'] and len(result.blocks) == live['failures']
    assert len(failures) == len(result.blocks) >= 1
    for (_, failure), block in zip(failures, result.blocks):
        assert abs(failure['t'] - t0 * 1e-9 - block.t) < 0.01     # one control period
        assert np.linalg.norm(np.array(failure['x']) - block.x) < 1e-3
        assert block.retreat == (failure['segment'] == -1)    # the live run's retreat blocks


@pytest.mark.ros
@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGINT])
def test_the_bag_is_readable_after_the_node_is_killed_mid_run(tmp_path, sig):
    ros = RosTest()
    try:
        ros.add(MockIiwa(context=ros.context, parameter_overrides=[
            Parameter('engine', value='kinematic'),
            Parameter('scenario', value=str(scenario_path('demo_iiwa')))]))
        env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
        node = subprocess.Popen([sys.executable, '-m', 'probdis_ros.ros.planner_node',
                                 '--ros-args', '-p', f'goal:={WORLD.goal.tolist()}',
                                 '-p', f'map_file:={tmp_path / "map.json"}',
                                 '-p', f'bag_dir:={tmp_path / "bags"}',
                                 '-p', 'state_timeout:=2.0'], env=env)
        try:
            wait_for(lambda: ros.call('start', timeout=60).success, 60, 'start')
            wait_for(lambda: ros.status.get('failures', 0) >= 1, 60, 'a block')
        finally:
            node.send_signal(sig)
            code = node.wait(20)
    finally:
        ros.close()
    assert code == 0
    bags = list((tmp_path / 'bags').iterdir())
    assert len(bags) == 1 and (bags[0] / 'metadata.yaml').exists()
    result = replay(bags[0])
    assert result.paths >= 1 and len(result.blocks) >= 1


def test_nan_joint_states_are_reported_and_skipped(tmp_path):
    messages, _, _ = simulated_run()
    nan = js_bytes([f'lbr_A{i}' for i in range(1, 8)], [float('nan')] * 7, 1.5)
    write_bag(tmp_path / 'bag', [*messages, (int(1.5e9) + 1, JS, nan)], 9, StoragePlugin.MCAP)
    result = replay(tmp_path / 'bag')
    assert len(result.blocks) == 1
    assert any('non-finite' in p for p in result.problems)


def test_states_a_hair_past_a_limit_are_replayed_clipped_as_the_live_run_takes_them(tmp_path):
    # the state check lets positions up to LIMIT_TOLERANCE past a limit through, clipped:
    # the replay's detector and observer see them as the live run's do (a review thought
    # the replay's were not clipped; the shared state check clips them for both)
    messages, _, _ = simulated_run()
    upper = iiwa_arm().upper[1]

    def past_the_limit(fields):
        position = list(fields['position'])
        position[1] = upper + 0.001
        return dict(fields, position=position)
    past = [(stamp, topic, past_the_limit(fields) if topic == JS else fields)
            for stamp, topic, fields in messages]
    write_bag(tmp_path / 'bag', past, 9, StoragePlugin.MCAP)
    result = replay(tmp_path / 'bag')
    assert not any('refused' in p for p in result.problems)
    assert max(q[1] for q in result.configs) == upper


def test_a_state_with_some_velocities_nan_is_refused_as_the_live_planner_refuses_it(tmp_path):
    # a glitch: the live gate refuses it (a stop would take the arm for at rest); the replay
    # passed the gate no velocities and took it
    messages, _, _ = simulated_run()
    stamp, _, fields = [m for m in messages if m[1] == JS and m[0] < 1.5e9][-1]
    glitch = dict(fields, velocity=[float('nan')] + [0.0] * 6)
    glitch['header'] = {'stamp': {'sec': stamp // 10**9, 'nanosec': stamp % 10**9 + 1000},
                        'frame_id': ''}
    write_bag(tmp_path / 'bag', [*messages, (stamp + 1000, JS, glitch)], 9, StoragePlugin.MCAP)
    result = replay(tmp_path / 'bag')
    assert len(result.blocks) == 1
    assert any('non-finite velocities' in p for p in result.problems), result.problems


TIME_DEF = 'int32 sec\nuint32 nanosec\n'
HEADER_DEF = 'builtin_interfaces/Time stamp\nstring frame_id\n'
SEP = '=' * 80 + '\n'
MCAP_DEFS = {
    JS_TYPE: ('std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n'
              f'float64[] effort\n{SEP}MSG: std_msgs/Header\n{HEADER_DEF}{SEP}'
              f'MSG: builtin_interfaces/Time\n{TIME_DEF}'),
    TRAJ_TYPE: ('std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points\n'
                f'{SEP}MSG: std_msgs/Header\n{HEADER_DEF}{SEP}MSG: builtin_interfaces/Time\n'
                f'{TIME_DEF}{SEP}MSG: trajectory_msgs/JointTrajectoryPoint\n'
                'float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\n'
                'float64[] effort\nbuiltin_interfaces/Duration time_from_start\n'
                f'{SEP}MSG: builtin_interfaces/Duration\n{TIME_DEF}'),
}


def write_mcap_library_bag(path, messages, chunk_size=1 << 20):
    """Write a bare .mcap file with the mcap / mcap-ros2-support libraries (zstd chunks)."""
    from mcap_ros2.writer import Writer as Ros2Writer

    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE}
    with open(path, 'wb') as stream:
        writer = Ros2Writer(stream, chunk_size=chunk_size)
        schemas = {t: writer.register_msgdef(t, MCAP_DEFS[t]) for t in MCAP_DEFS}
        for stamp, topic, fields in messages:
            writer.write_message(topic, schemas[types[topic]], fields, log_time=stamp,
                                 publish_time=stamp)
        writer.finish()


def test_a_bag_from_the_mcap_libraries_with_shuffled_and_extra_joints(tmp_path):
    messages, stop, t_stop = simulated_run(names_order=[6, 2, 0, 4, 1, 3, 5], extra=True)
    write_mcap_library_bag(tmp_path / 'arm.mcap', messages)
    result = replay(tmp_path / 'arm.mcap')
    assert result.paths == 1 and len(result.blocks) == 1 and not result.success
    np.testing.assert_allclose(result.blocks[0].config, stop, atol=1e-9)
    assert t_stop + 0.3 - 0.02 <= result.blocks[0].t <= t_stop + 0.3 + 0.02


def test_a_bag_cut_in_its_summary_is_read_whole_and_noted(tmp_path):
    messages, stop, _ = simulated_run()
    write_bag(tmp_path / 'bag', messages, 9, StoragePlugin.MCAP)
    mcap = tmp_path / 'bag' / 'bag.mcap'
    mcap.write_bytes(mcap.read_bytes()[:-100])          # footer and part of the summary lost
    result = replay(tmp_path / 'bag')
    assert any('read record by record' in p for p in result.problems)
    assert len(result.times) == sum(1 for m in messages if m[1] == JS)
    assert len(result.blocks) == 1
    np.testing.assert_allclose(result.blocks[0].config, stop, atol=1e-9)


def test_a_split_bag_whose_recorder_died_is_read_file_by_file(tmp_path):
    # ros2 bag record --max-bag-size writes metadata.yaml at its end: a crash leaves the
    # files alone, and the first of them only was read (the block, in the last, was missed)
    messages, stop, _ = simulated_run()
    bag = tmp_path / 'bag'
    bag.mkdir()
    parts = np.array_split(np.arange(len(messages)), 3)
    for k, part in zip((0, 2, 10), parts):      # numbered as rosbag2 numbers them
        write_bag(tmp_path / f'part{k}', [messages[i] for i in part], 9, StoragePlugin.MCAP)
        (tmp_path / f'part{k}' / f'part{k}.mcap').rename(bag / f'bag_{k}.mcap')
    result = replay(bag)
    assert len(result.times) == sum(1 for m in messages if m[1] == JS)
    assert len(result.blocks) == 1
    np.testing.assert_allclose(result.blocks[0].config, stop, atol=1e-9)
    assert any('bag_0.mcap, bag_2.mcap, bag_10.mcap: read record by record' in p
               for p in result.problems), result.problems


def test_a_bag_cut_midway_reports_what_came_before_the_damage(tmp_path):
    messages, _, _ = simulated_run()
    write_mcap_library_bag(tmp_path / 'arm.mcap', messages, chunk_size=4096)
    data = (tmp_path / 'arm.mcap').read_bytes()
    (tmp_path / 'arm.mcap').write_bytes(data[: len(data) * 6 // 10])
    (tmp_path / 'map.json').write_text('the map of another run\n')
    result = run_replay(tmp_path / 'arm.mcap', '--json', '--save-map', str(tmp_path / 'map.json'))
    assert result.returncode == 1
    error = result.stderr.strip().splitlines()
    assert len(error) == 1 and 'arm.mcap is damaged at byte' in error[0], result.stderr
    assert json.loads(result.stdout)['paths'] == 1        # the command came before the cut
    # what came before the damage is shown, not saved over a map file
    assert '--save-map not written' in error[0]
    assert (tmp_path / 'map.json').read_text() == 'the map of another run\n'
    with pytest.raises(ReplayError) as err:
        replay(tmp_path / 'arm.mcap')
    total = sum(1 for m in messages if m[1] == JS)
    assert 0 < len(err.value.partial.times) < total


def test_a_damaged_bag_written_out_of_time_order_is_read_in_time_order(tmp_path):
    # a recorder writes messages in the order it handles them, not always in that of their
    # receive times; read record by record, they are replayed in time order (as rosbags
    # reads a whole bag), not as states that went back in time and were refused
    messages, stop, _ = simulated_run()
    written = list(messages)
    written[1], written[3] = written[3], written[1]
    write_mcap_library_bag(tmp_path / 'arm.mcap', written)
    data = (tmp_path / 'arm.mcap').read_bytes()
    (tmp_path / 'arm.mcap').write_bytes(data[:-100])
    result = replay(tmp_path / 'arm.mcap')
    assert [p for p in result.problems if 'read record by record' not in p] == []
    assert len(result.times) == sum(1 for m in messages if m[1] == JS)
    assert len(result.blocks) == 1
    np.testing.assert_allclose(result.blocks[0].config, stop, atol=1e-9)


def test_a_truncated_sqlite_bag_is_a_one_line_error(tmp_path):
    messages, _, _ = simulated_run()
    write_bag(tmp_path / 'bag', messages, 9, StoragePlugin.SQLITE3)
    db3 = tmp_path / 'bag' / 'bag.db3'
    db3.write_bytes(db3.read_bytes()[:3000])
    result = run_replay(tmp_path / 'bag')
    assert result.returncode != 0 and result.stdout == ''
    assert len(result.stderr.strip().splitlines()) == 1 and 'bag' in result.stderr


def test_unknown_types_are_ignored_unless_needed(tmp_path):
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg('float64 torque\nstring label\n', 'lab_msgs/msg/Gizmo'))
    gizmo = store.serialize_cdr(store.types['lab_msgs/msg/Gizmo'](torque=1.5, label='x'),
                                'lab_msgs/msg/Gizmo')
    messages, _, _ = simulated_run()
    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE, '/lab/gizmo': 'lab_msgs/msg/Gizmo'}
    write_bag(tmp_path / 'extra', [*messages, (messages[5][0] + 1, '/lab/gizmo', gizmo)], 9,
              StoragePlugin.MCAP, types, store)
    assert len(replay(tmp_path / 'extra').blocks) == 1
    result = run_replay(tmp_path / 'extra', '--joint-states', '/lab/gizmo')
    assert result.returncode != 0
    assert 'probdis replay: error:' in result.stderr and \
        '/lab/gizmo carries lab_msgs/msg/Gizmo, not sensor_msgs/msg/JointState' in result.stderr


def test_bad_replay_flags_are_refused_before_the_bag_is_read(tmp_path):
    messages, _, _ = simulated_run()
    write_bag(tmp_path / 'bag', messages, 9, StoragePlugin.MCAP)
    keep = tmp_path / 'keep_map.json'
    keep.write_text('the map of another run\n')
    for args, text in [
            (('--d-dist', '-1', '--save-map', str(keep)), '--d-dist must be a positive number'),
            (('--d-dist', 'nan'), '--d-dist must be a positive number, got nan'),
            (('--motion-delay', '-0.1'), '--motion-delay must be a number >= 0'),
            (('--motion-delay', 'inf'), '--motion-delay must be a number >= 0, got inf'),
            # not damage of the bag: a d_dist the detector's other thresholds do not allow
            (('--d-dist', '0.5', '--save-map', str(keep)), '--d-dist 0.5: gap_ceiling 0.3 '
             'must exceed d_dist 0.5'),
            (('--save-map', str(tmp_path)), f'--save-map {tmp_path}: is a directory'),
            (('--plot', str(keep / 'x.png')), f'{keep} is not a directory'),
            (('--rate', '2'), '--rate and --wait go with --publish'),
            (('--calibrate', '--motion-delay', '0.1'), '--calibrate tries every motion_delay '
             'itself: not with --motion-delay'),
            (('--calibrate', '--save-map', str(keep), '--publish'),
             'not with --save-map or --publish')]:
        result = run_replay(tmp_path / 'bag', *args)
        assert result.returncode == 2 and result.stdout == '', (args, result.stderr)
        assert result.stderr.count('\n') == 1 and result.stderr.startswith(
            'probdis replay: error: ') and text in result.stderr, (args, result.stderr)
        assert 'damaged' not in result.stderr
    assert keep.read_text() == 'the map of another run\n'
    # a running planner holds its map file's lock: the replayed map went over its map
    held = lock_map(keep, {'node': '/probdis_planner', 'pid': 4242})
    try:
        result = run_replay(tmp_path / 'bag', '--save-map', str(keep))
    finally:
        os.close(held)
    assert result.returncode == 2 and result.stderr.count('\n') == 1, result.stderr
    assert "in use by {'node': '/probdis_planner', 'pid': 4242}" in result.stderr
    assert keep.read_text() == 'the map of another run\n'
    assert run_replay(tmp_path / 'bag', '--save-map', str(keep)).returncode == 0
    assert json.loads(keep.read_text())['failures']     # the block, in place of the old map


def run_replay(bag, *args):
    return subprocess.run([*probdis_command(), 'replay', str(bag), *args], capture_output=True,
                          text=True, timeout=120)


@pytest.mark.ros
def test_publish_mode_delivers_every_message_in_order_with_its_timing(tmp_path):
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg('float64 torque\n', 'lab_msgs/msg/Gizmo'))
    status = '/probdis_planner/status'
    types = {JS: JS_TYPE, TRAJ: TRAJ_TYPE, status: 'std_msgs/msg/String',
             '/lab/gizmo': 'lab_msgs/msg/Gizmo'}
    messages, _, _ = simulated_run()
    extra = [(messages[0][0] + 1, status, store.serialize_cdr(
                 store.types['std_msgs/msg/String'](data=f'{{"n": {k}}}'), types[status]))
             for k in range(3)]
    extra.append((messages[9][0] + 1, '/lab/gizmo', store.serialize_cdr(
        store.types['lab_msgs/msg/Gizmo'](torque=2.0), 'lab_msgs/msg/Gizmo')))
    write_bag(tmp_path / 'bag', messages + extra, 9, StoragePlugin.MCAP, types, store)
    recorded = {}
    for _, topic, fields in sorted(messages + extra, key=lambda m: m[0]):
        data = rosbags_bytes(fields, types[topic]) if isinstance(fields, dict) else fields
        recorded.setdefault(topic, []).append(bytes(data))
    commands_recorded = len(recorded[TRAJ])

    ros = RosTest()
    received = {}
    try:
        listener = ros.add(rclpy.create_node('bag_listener', context=ros.context))
        for topic, cls in ((JS, JointState), (TRAJ, JointTrajectory), (status, String)):
            qos = QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL
                             if topic == status else DurabilityPolicy.VOLATILE)
            # timed on arrival in DDS, not when this process's executor gets to the message
            listener.create_subscription(
                cls, topic, lambda raw, info, topic=topic: received.setdefault(topic, []).append(
                    (info['received_timestamp'] * 1e-9, bytes(raw))), qos, raw=True)
        env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
        rate = 4.0
        result = subprocess.run([*probdis_command(), 'replay', str(tmp_path / 'bag'),
                                 '--publish', '--rate', str(rate), '--wait', '20', '--json'],
                                env=env, capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
        wait_for(lambda: sum(map(len, received.values())) >= 304 - commands_recorded, 10,
                 'every message')
    finally:
        ros.close()
    doc = json.loads(result.stdout)
    assert doc['published'] == len(messages) + 3 - commands_recorded
    assert sorted(doc['skipped']) == ['/lab/gizmo', TRAJ]
    assert 'lab_msgs/msg/Gizmo is not installed' in result.stderr
    # the commands to the arm stay out: a controller listening would execute them
    assert 'commands to the arm' in doc['skipped'][TRAJ] and TRAJ not in received
    for topic in (JS, status):     # DDS pads the payload to 4 bytes
        assert [raw for _, raw in received[topic]] == [
            raw + bytes(-len(raw) % 4) for raw in recorded[topic]], topic
    arrivals = [t for t, _ in received[JS]]
    span = (messages[-1][0] - messages[0][0]) * 1e-9 / rate
    assert 0.8 * span < arrivals[-1] - arrivals[0] < 2.0 * span


@pytest.mark.ros
def test_publish_mode_with_nothing_to_publish_publishes_nothing(tmp_path):
    # a bag of the commands alone: rosbags reads an empty selection of topics as every
    # message, and the player looked up a publisher it never made (KeyError, a traceback)
    messages, _, _ = simulated_run()
    write_bag(tmp_path / 'bag', [m for m in messages if m[1] == TRAJ], 9, StoragePlugin.MCAP)
    ros = RosTest()             # the test's own domain
    try:
        env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
        result = subprocess.run([*probdis_command(), 'replay', str(tmp_path / 'bag'),
                                 '--publish', '--wait', '0', '--json'],
                                env=env, capture_output=True, text=True, timeout=120)
    finally:
        ros.close()
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout)
    assert doc['published'] == 0 and list(doc['skipped']) == [TRAJ]
