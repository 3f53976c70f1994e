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

"""The tools around the planner node: its client, the demo's steps, the bag player, the table."""

import json
import subprocess
import sys
import threading
import time

import numpy as np
from probdis_ros.ros import demo
from probdis_ros.ros.bag_player import play
from probdis_ros.ros.client import check_timeout, PlannerClient
from probdis_ros.ros.robot_experiment import paired_table, run_robot_experiment, state_gaps, valid
import pytest
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile
from ros_harness import RosTest, wait_for
from std_msgs.msg import String
from std_srvs.srv import Trigger

STRING = 'std_msgs/msg/String'


def test_a_timeout_that_never_passes_is_refused():
    # an infinite or NaN deadline never passes: a call to a planner that is not there
    # would wait forever
    for bad in (float('inf'), float('nan'), -float('inf')):
        with pytest.raises(ValueError, match='timeout must be a finite number'):
            check_timeout(bad)
    assert check_timeout(0.5) == 0.5 and check_timeout(0.0) == 0.0


def test_the_player_refuses_a_rate_that_is_not_positive():
    # a rate of 0 divides the recorded offsets by zero; a negative one plays nothing in time
    for rate in (0.0, -1.0):
        with pytest.raises(ValueError, match='--rate must be positive'):
            play('no_such_bag', rate=rate)


def test_a_hole_in_the_joint_states_just_over_the_limit_makes_a_run_not_valid():
    # 0.15 s without joint states is more than the detector's rise window: the run no
    # longer had the real arm's timing
    assert valid({'max_state_gap_s': 0.1}) and valid({})
    assert not valid({'max_state_gap_s': 0.15})


def record(run, success, gap=0.01, paths=3):
    return {'scenario': 'demo_hook', 'method': 'probabilistic', 'run': run,
            'success': success, 'paths': paths, 'max_state_gap_s': gap}


def test_the_paired_table_pairs_only_runs_that_kept_the_arms_timing():
    # a run the planner fell behind in says nothing of the method, on either side
    ours = [record(0, True), record(1, True), record(2, True, gap=0.5)]
    theirs = [record(0, False), record(1, False, gap=0.5), record(2, False)]
    table = paired_table(ours, theirs, ['probabilistic'])
    assert '| probabilistic | 1 | 1 / 0 | +1.000' in table, table


def write_string_bag(path, topics, count, spacing_s=0.01, cut=False):
    """Write a bare .mcap file of String messages on topics; cut: its second half lost."""
    from mcap_ros2.writer import Writer

    with open(path, 'wb') as stream:
        writer = Writer(stream, chunk_size=256)
        schema = writer.register_msgdef(STRING, 'string data')
        for k in range(count):
            for topic in topics:
                stamp = 10**9 + round(k * spacing_s * 1e9)
                writer.write_message(topic, schema, {'data': f'{topic} {k}'}, log_time=stamp,
                                     publish_time=stamp)
        writer.finish()
    if cut:
        path.write_bytes(path.read_bytes()[:path.stat().st_size // 2])


def fake_run(bag):
    """Return a run_demo that records its arguments and answers as a finished run."""
    calls = []

    def run_demo(scenario, timeout, **kwargs):
        calls.append({'scenario': scenario, 'timeout': timeout, **kwargs})
        return {'success': True, 'paths': 2, 'failures': 1, 'bag': str(bag)}

    return calls, run_demo


def write_joint_state_bag(bag, times):
    """Write a bag of empty joint states received at times [s]."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import get_typestore, Stores

    store = get_typestore(Stores.ROS2_JAZZY)
    kind = 'sensor_msgs/msg/JointState'
    with Writer(bag, version=9) as writer:
        conn = writer.add_connection('/lbr/joint_states', kind, typestore=store)
        for t in times:
            header = store.types['std_msgs/msg/Header'](
                stamp=store.types['builtin_interfaces/msg/Time'](sec=0, nanosec=0),
                frame_id='')
            msg = store.types[kind](header=header, name=[], position=np.zeros(0),
                                    velocity=np.zeros(0), effort=np.zeros(0))
            writer.write(conn, round((5.0 + t) * 1e9), store.serialize_cdr(msg, kind))
    return bag


def test_a_bag_with_one_joint_state_or_none_has_no_hole(tmp_path):
    # a planner that ended at once recorded a single state: its run is checked, not a crash
    assert state_gaps(write_joint_state_bag(tmp_path / 'one', [0.0])) == (0, 0.0)
    assert state_gaps(write_joint_state_bag(tmp_path / 'none', [])) == (0, 0.0)


def test_a_robot_run_hands_the_nodes_its_settings_and_checks_its_bag(tmp_path, monkeypatch):
    # the planner's seed, its bag folder, the mock's faults and the clock must reach the
    # nodes (a whole number as a decimal: the node's parameters are); a run without them is
    # not the run its record says
    bag = write_joint_state_bag(tmp_path / 'bag', [k * 0.01 for k in range(10)] +
                                [0.3 + k * 0.01 for k in range(10)])
    calls, run_demo = fake_run(bag)
    monkeypatch.setattr(demo, 'run_demo', run_demo)
    from probdis_ros.planning import Method

    out = tmp_path / 'out'
    said = []
    records = run_robot_experiment(out, ['demo_hook'], [Method.parse('probabilistic')], 2,
                                   progress=said.append,
                                   velocity_scaling=0.2, faults={'latency': 0.02},
                                   cartesian_speed_limit=0.3, real_time_factor=2.0,
                                   detection={'gap_ceiling': 1}, timeout=900.0)
    assert [c['scenario'] for c in calls] == ['demo_hook'] * 2
    planner = [dict(a.split(':=', 1) for a in c['extra_planner_args'][1::2]) for c in calls]
    assert [p['seed'] for p in planner] == ['0', '1']
    assert planner[0]['bag_dir'] == str(out / 'bags')
    assert planner[0]['gap_ceiling'] == '1.0' and planner[0]['cartesian_speed_limit'] == '0.3'
    assert calls[0]['extra_mock_args'] == ('-p', 'latency:=0.02')
    assert calls[0]['sim_time'] is True and calls[0]['real_time_factor'] == 2.0
    assert calls[0]['timeout'] == 900.0
    # the bag's hole of 0.21 s: 20 states missed, the run not valid, run again next time
    assert [(r['missed_states'], r['max_state_gap_s']) for r in records] == \
        [(20, pytest.approx(0.21))] * 2
    assert not any(valid(r) for r in records)
    assert sum('not valid: the planner missed 20 joint states (a hole of 0.21 s)' in line
               for line in said) == 2
    run_robot_experiment(out, ['demo_hook'], [Method.parse('probabilistic')], 2,
                         velocity_scaling=0.2, faults={'latency': 0.02},
                         cartesian_speed_limit=0.3, real_time_factor=2.0,
                         detection={'gap_ceiling': 1})
    assert len(calls) == 4
    # the driver guard that holds reaches the mock as its parameter
    run_robot_experiment(tmp_path / 'holds', ['demo_hook'], [Method.parse('probabilistic')], 1,
                         faults={'latency': 0.02}, guard_holds=True)
    assert calls[-1]['extra_mock_args'] == ('-p', 'latency:=0.02', '-p', 'guard_holds:=true')


def test_a_robot_run_that_timed_out_is_tried_again_and_timed_alone(tmp_path, monkeypatch):
    # nodes that did not answer in time (a busy machine) did not run: the run is tried once
    # more, its reason said, and the record's wall time is that of the run that happened
    from probdis_ros.planning import Method

    calls, answer = fake_run('')
    said = []

    def run_demo(scenario, timeout, **kwargs):
        if not calls:
            calls.append('timed out')
            time.sleep(0.5)
            raise TimeoutError('no outcome within 600 s')
        return answer(scenario, timeout, **kwargs)

    monkeypatch.setattr(demo, 'run_demo', run_demo)
    records = run_robot_experiment(tmp_path, ['demo_hook'], [Method.parse('probabilistic')], 1,
                                   progress=said.append)
    assert len(calls) == 2 and records[0]['success'] and records[0]['wall_s'] < 0.4
    assert 'no outcome within 600 s; trying again' in said[0]


def test_the_demo_keeps_the_users_ros_domain_on_this_machine(monkeypatch):
    # RViz or ros2 topic on the user's domain must see the demo; an unset range stays local
    monkeypatch.setenv('ROS_DOMAIN_ID', '42')
    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    env = demo.ros_environment()
    assert env['ROS_DOMAIN_ID'] == '42' and env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'SUBNET')
    assert demo.ros_environment()['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SUBNET'


def test_stopping_a_node_interrupts_it_and_kills_one_that_does_not_end():
    # a node that ignores SIGINT must not keep the demo from ending
    code = ('import signal, sys, time\n'
            'signal.signal(signal.SIGINT, {})\n'
            'print("ready", flush=True)\n'
            'time.sleep(30)\n')
    polite = subprocess.Popen([sys.executable, '-c', code.format(
        'lambda *a: sys.exit(7)')], stdout=subprocess.PIPE, text=True)
    stubborn = subprocess.Popen([sys.executable, '-c', code.format('signal.SIG_IGN')],
                                stdout=subprocess.PIPE, text=True)
    try:
        for process in (polite, stubborn):
            assert process.stdout.readline() == 'ready\n'
        assert demo.stop_process(polite, timeout=5.0) == 7
        began = time.monotonic()
        assert demo.stop_process(stubborn, timeout=0.5) == -9
        assert time.monotonic() - began < 3.0
    finally:
        for process in (polite, stubborn):
            process.kill()
            process.wait(10)
            process.stdout.close()


def test_the_demo_tells_the_planner_the_reach_of_the_grasped_object():
    # the planner keeps the object's ball clear of the obstacles: a reach of 0 would let it
    # plan the object through them
    from probdis_ros.physics import load_scene

    reach = demo.world_of('demo_hook', 'physics')[3]
    assert reach == load_scene('demo_hook').object_reach and reach > 0.05
    assert demo.world_of('demo_iiwa', 'kinematic')[3] == 0.0


class FakePlanner:
    """A node named like the planner: its status, its parameters, a start that refuses."""

    def __init__(self, ros: RosTest, refusal: str = 'no fresh joint state') -> None:
        self.node = ros.add(rclpy.create_node('probdis_planner', context=ros.context))
        self.node.declare_parameter('velocity_scaling', 0.2)
        self.node.declare_parameter('goal', [0.1] * 7)
        self.node.add_on_set_parameters_callback(self._check)
        self.status = self.node.create_publisher(String, '~/status', QoSProfile(
            depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.starts = 0

        def start(request, response):
            self.starts += 1
            response.success, response.message = False, refusal
            return response

        self.node.create_service(Trigger, '~/start', start)

    def _check(self, params):
        for param in params:
            if param.name == 'velocity_scaling' and param.value > 0.7:
                return SetParametersResult(successful=False,
                                           reason='velocity_scaling in [0.01, 0.7]')
        return SetParametersResult(successful=True)

    def publish(self, state: str) -> None:
        self.status.publish(String(data=json.dumps({'state': state})))


@pytest.fixture
def ros(monkeypatch):
    ros = RosTest()
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros.domain))     # the client's domain
    yield ros
    ros.close()


@pytest.mark.ros
def test_the_client_reads_and_sets_parameters_keeping_their_type(ros):
    # `probdis param set velocity_scaling 0` must set 0.0: the node refuses an integer for a
    # decimal parameter; a refusal is a refusal, with the node's reason
    planner = FakePlanner(ros)
    with PlannerClient() as client:
        assert client.parameters(['velocity_scaling']) == {'velocity_scaling': 0.2}
        with pytest.raises(KeyError, match='no parameter no_such'):
            client.parameters(['no_such'])
        with pytest.raises(KeyError, match='no parameter among velocity_scaling, no_such'):
            client.parameters(['velocity_scaling', 'no_such'])
        assert client.set_parameter('velocity_scaling', 0) == (True, '')
        assert planner.node.get_parameter('velocity_scaling').value == 0.0
        assert client.set_parameter('velocity_scaling', 1) == \
            (False, 'velocity_scaling in [0.01, 0.7]')
        names = client.parameter_names()
        assert names == sorted(names) and {'goal', 'velocity_scaling'} <= set(names)


@pytest.mark.ros
def test_the_client_waits_for_a_newer_status_and_else_gives_the_latest(ros):
    # the demo follows the run by asking for a status newer than the one it has: none newer
    # within the timeout gives the latest again (not an error), a newer one comes at once
    planner = FakePlanner(ros)
    with PlannerClient() as client:
        # no status at all: nothing says that a start whose answer was lost took effect
        assert not demo._started(client, wait=0.3)
        planner.publish('idle')
        idle = client.status(timeout=10.0)
        assert idle == {'state': 'idle'}
        began = time.monotonic()
        assert client.status(timeout=0.5, newer_than=idle) == idle
        assert time.monotonic() - began >= 0.5
        threading.Timer(0.3, planner.publish, ('planning',)).start()
        began = time.monotonic()
        assert client.status(timeout=5.0, newer_than=idle) == {'state': 'planning'}
        assert time.monotonic() - began < 3.0
        # a start whose answer was lost took effect if the status shows a run, or its end
        planner.publish('gave_up')
        assert client.status(timeout=5.0, newer_than={'state': 'planning'}) == \
            {'state': 'gave_up'}
        assert demo._started(client, wait=3.0)
        planner.publish('idle')
        assert client.status(timeout=5.0, newer_than={'state': 'gave_up'}) == idle
        assert not demo._started(client, wait=0.5)


@pytest.mark.ros
def test_the_demo_gives_up_on_a_planner_that_keeps_refusing_and_says_why(ros, monkeypatch):
    # a planner that answers is up: the demo does not say it waits for it to come up, asks
    # again for REFUSALS_FOR, then stops with the planner's reason
    FakePlanner(ros, refusal='no fresh joint state on /lbr/joint_states')
    monkeypatch.setattr(demo, 'REFUSALS_FOR', 1.0)
    alive = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])
    dead = subprocess.Popen([sys.executable, '-c', 'raise SystemExit(3)'])
    dead.wait(30)
    said = []
    try:
        with PlannerClient() as client:
            with pytest.raises(RuntimeError, match='planner refused to start: no fresh joint '
                               'state on /lbr/joint_states'):
                demo.start_disentangling(client, alive, alive, said.append, startup_limit=30.0,
                                         call_timeout=5.0, tell_after=0.3)
            assert said == []
            with pytest.raises(RuntimeError, match=r'the mock iiwa exited \(code 3\) before '
                               'the run started: no fresh joint state'):
                demo.start_disentangling(client, alive, dead, said.append, call_timeout=5.0)
    finally:
        alive.kill()
        alive.wait(10)


@pytest.mark.ros
def test_the_player_waits_for_every_topic_to_be_listened_to(ros, tmp_path):
    # a listener on a second topic that comes up later must get the beginning too: the
    # player waits (up to --wait) for a subscriber on every topic
    bag = tmp_path / 'two.mcap'
    write_string_bag(bag, ['/a', '/b'], 5)
    listener = ros.add(rclpy.create_node('listener', context=ros.context))
    received = {'/a': [], '/b': []}
    listener.create_subscription(String, '/a', lambda m: received['/a'].append(m.data), 10)

    def listen_to_b():
        listener.create_subscription(String, '/b', lambda m: received['/b'].append(m.data), 10)

    threading.Timer(0.6, listen_to_b).start()
    result = play(str(bag), wait=5.0, progress=False)
    assert result.published == 10 and result.damage is None and not result.skipped
    wait_for(lambda: len(received['/b']) == 5, 5.0, 'the messages on /b')
    assert received['/b'] == [f'/b {k}' for k in range(5)]


@pytest.mark.ros
def test_the_player_reports_the_damage_of_a_cut_bag(ros, tmp_path):
    # what came before the cut is played; the cut is said, so the command exits 1
    bag = tmp_path / 'cut.mcap'
    write_string_bag(bag, ['/a'], 20, cut=True)
    result = play(str(bag), wait=0.0, progress=False)
    assert 0 < result.published < 20
    assert result.damage and 'cut.mcap is damaged at byte' in result.damage


@pytest.mark.ros
def test_a_planner_that_comes_up_late_still_has_the_time_to_answer(ros):
    # the timeout counts twice: for the service to come up, then for its answer; a planner
    # found late in the first must not be cut off in the second (a start it then ran would
    # be reported as not answered)
    node = ros.add(rclpy.create_node('probdis_planner', context=ros.context))

    def reset_map(request, response):
        time.sleep(1.0)
        response.success, response.message = True, 'cleared 0 failures'
        return response

    threading.Timer(1.0, node.create_service, (Trigger, '~/reset_map', reset_map)).start()
    with PlannerClient() as client:
        assert client.call('reset_map', timeout=2.0) == (True, 'cleared 0 failures')


def test_a_robot_experiment_killed_while_writing_a_run_resumes(tmp_path, monkeypatch):
    # Ctrl-C while a run's record was being written leaves half a line: the resumed
    # experiment must write its runs on lines of their own, or the next resume fails on a
    # damaged line in the middle of the file
    from probdis_ros.planning import Method

    calls, run_demo = fake_run('')
    monkeypatch.setattr(demo, 'run_demo', run_demo)
    methods = [Method.parse('probabilistic')]
    run_robot_experiment(tmp_path, ['demo_hook'], methods, 1)
    runs = tmp_path / 'robot_runs.jsonl'
    runs.write_text(runs.read_text() + '{"scenario": "demo_hook", "meth')
    records = run_robot_experiment(tmp_path, ['demo_hook'], methods, 2)
    assert [r['run'] for r in records] == [0, 1]
    records = run_robot_experiment(tmp_path, ['demo_hook'], methods, 2)
    assert [r['run'] for r in records] == [0, 1] and len(calls) == 2
