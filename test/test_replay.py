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

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.resources import scenario_path
from probdis_ros.ros.mock_iiwa_node import MockIiwa
from probdis_ros.ros.planner_node import PlannerNode
from probdis_ros.ros.replay import replay, ReplayError
from probdis_ros.ros.trajectory import time_path
from probdis_ros.sim.worlds import load_world
import pytest
from rclpy.parameter import Parameter
from ros_harness import RosTest, wait_for
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

WORLD = load_world(scenario_path('demo_iiwa'))
JS, TRAJ = '/lbr/joint_states', '/lbr/joint_trajectory_controller/joint_trajectory'
STORE = get_typestore(Stores.ROS2_JAZZY)
RATE = 100.0


def js_bytes(names, q, stamp):
    t = STORE.types
    msg = t['sensor_msgs/msg/JointState'](
        header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
            sec=int(stamp), nanosec=int((stamp % 1) * 1e9)), frame_id=''),
        name=list(names), position=np.asarray(q, dtype=float), velocity=np.zeros(0),
        effort=np.zeros(0))
    return STORE.serialize_cdr(msg, 'sensor_msgs/msg/JointState')


def traj_bytes(timed, names):
    t = STORE.types
    points = []
    for q, s in zip(timed.points[1:], timed.times[1:]):
        points.append(t['trajectory_msgs/msg/JointTrajectoryPoint'](
            positions=np.asarray(q, dtype=float), velocities=np.zeros(0),
            accelerations=np.zeros(0), effort=np.zeros(0),
            time_from_start=t['builtin_interfaces/msg/Duration'](
                sec=int(s), nanosec=int((s % 1) * 1e9))))
    msg = t['trajectory_msgs/msg/JointTrajectory'](
        header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
            sec=0, nanosec=0), frame_id=''), joint_names=list(names), points=points)
    return STORE.serialize_cdr(msg, 'trajectory_msgs/msg/JointTrajectory')


def simulated_run(names_order=None, extra=False):
    """Joint states of the arm following the straight move into the box, until it stops."""
    arm = iiwa_arm()
    path = np.array([WORLD.start, WORLD.goal])
    timed = time_path(path, arm.velocity_limits, 0.5)
    stop = WORLD.compliant_arm().execute(path).config
    fraction = np.linalg.norm(stop - path[0]) / np.linalg.norm(path[1] - path[0])
    t_stop = fraction * timed.duration
    messages = [(0.0, 'js', WORLD.start), (0.05, 'traj', timed)]
    for k in range(1, int(3.0 * RATE)):
        t = 0.05 + k / RATE
        q = timed.at(min(t - 0.05, t_stop))
        messages.append((t, 'js', q))
    order = names_order or list(range(7))
    names = [f'lbr_A{i + 1}' for i in order] + (['gripper_finger'] if extra else [])
    out = []
    for t, kind, value in messages:
        if kind == 'js':
            q = [value[i] for i in order] + ([0.01] if extra else [])
            out.append((int((1.0 + t) * 1e9), JS, js_bytes(names, q, 1.0 + t)))
        else:
            joints = [f'lbr_A{i}' for i in range(1, 8)]
            out.append((int((1.0 + t) * 1e9), TRAJ, traj_bytes(value, joints)))
    return out, stop, 0.05 + t_stop


def write_bag(path, messages, version, plugin):
    types = {JS: 'sensor_msgs/msg/JointState', TRAJ: 'trajectory_msgs/msg/JointTrajectory'}
    with Writer(path, version=version, storage_plugin=plugin) as writer:
        conns = {topic: writer.add_connection(topic, types[topic], typestore=STORE)
                 for topic in {m[1] for m in messages}}
        for stamp, topic, data in messages:
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


def test_replay_refuses_bad_bags_clearly(tmp_path):
    with pytest.raises(ReplayError, match='no such bag'):
        replay(tmp_path / 'missing')
    (tmp_path / 'notabag').mkdir()
    with pytest.raises(ReplayError, match='not a readable rosbag2 bag'):
        replay(tmp_path / 'notabag')
    messages, _, _ = simulated_run()
    write_bag(tmp_path / 'nojs', [m for m in messages if m[1] == TRAJ], 9, StoragePlugin.MCAP)
    with pytest.raises(ReplayError, match='no /lbr/joint_states topic'):
        replay(tmp_path / 'nojs')


@pytest.mark.ros
def test_replay_of_a_recorded_mock_run_finds_the_live_blocks(tmp_path):
    ros = RosTest()
    try:
        ros.add(PlannerNode(context=ros.context, parameter_overrides=[
            Parameter('goal', value=WORLD.goal.tolist()),
            Parameter('map_file', value=str(tmp_path / 'map.json')),
            Parameter('bag_dir', value=str(tmp_path / 'bags')),
            Parameter('velocity_scaling', value=1.0), Parameter('state_timeout', value=2.0)]))
        env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
        arm = subprocess.Popen([sys.executable, '-m', 'probdis_ros.ros.mock_iiwa_node'], env=env)
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
    result = replay(bag)
    assert live['state'] == 'succeeded' and result.success
    assert result.paths == live['paths'] and len(result.blocks) == live['failures']
    assert len(failures) == len(result.blocks) >= 1
    for (_, failure), block in zip(failures, result.blocks):
        assert abs(failure['t'] - t0 * 1e-9 - block.t) < 0.01     # one control period
        assert np.linalg.norm(np.array(failure['x']) - block.x) < 1e-3


@pytest.mark.ros
@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGINT])
def test_the_bag_is_readable_after_the_node_is_killed_mid_run(tmp_path, sig):
    ros = RosTest()
    try:
        ros.add(MockIiwa(context=ros.context, parameter_overrides=[
            Parameter('scenario', value=str(scenario_path('demo_iiwa')))]))
        env = dict(os.environ, ROS_DOMAIN_ID=str(ros.domain))
        node = subprocess.Popen([sys.executable, '-m', 'probdis_ros.ros.planner_node',
                                 '--ros-args', '-p', f'goal:={WORLD.goal.tolist()}',
                                 '-p', f'map_file:={tmp_path / "map.json"}',
                                 '-p', f'bag_dir:={tmp_path / "bags"}'], env=env)
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


def test_a_truncated_bag_is_a_clear_error(tmp_path):
    messages, _, _ = simulated_run()
    write_bag(tmp_path / 'bag', messages, 9, StoragePlugin.MCAP)
    data = (tmp_path / 'bag' / 'bag.mcap').read_bytes()
    (tmp_path / 'bag' / 'bag.mcap').write_bytes(data[: len(data) // 2])
    with pytest.raises(ReplayError, match='not a readable rosbag2 bag'):
        replay(tmp_path / 'bag')
