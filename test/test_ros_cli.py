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

"""The ROS commands of ``probdis`` as a user runs them: real processes over DDS."""

import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from conftest import next_domain, probdis_command
from probdis_ros.resources import scenario_path
from probdis_ros.ros.robot_experiment import valid
from probdis_ros.sim.worlds import load_world
import pytest
from ros_harness import wait_for

pytestmark = pytest.mark.ros
GOAL = load_world(scenario_path('demo_iiwa')).goal


@pytest.fixture
def env():
    return dict(os.environ, ROS_DOMAIN_ID=str(next_domain()),
                ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')


def run(env, *args, timeout=60):
    return subprocess.run(probdis_command() + list(args), env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_service_commands_against_a_running_planner(env, tmp_path):
    planner = subprocess.Popen([*probdis_command(), 'planner', '--ros-args',
                                '-p', f'goal:={GOAL.tolist()}',
                                '-p', f'map_file:={tmp_path / "map.json"}'], env=env)
    try:
        status = {}

        def idle():
            result = run(env, 'status', '--json', '--timeout', '5')
            status.update(json.loads(result.stdout) if result.returncode == 0 else {})
            return status.get('state') == 'idle'

        wait_for(idle, 60, 'the planner status')
        assert status['failures'] == 0 and status['paths'] == 0
        refused = run(env, 'start')
        assert refused.returncode == 1 and 'no fresh joint state' in refused.stdout
        nothing = run(env, 'confirm')
        assert nothing.returncode == 1 and 'no path awaits confirmation' in nothing.stdout
        cleared = run(env, 'reset-map')
        assert cleared.returncode == 0 and 'cleared 0 failures' in cleared.stdout
        # parameters without the ros2 CLI: the goal can be read and changed between runs
        assert json.loads(run(env, 'param', 'get', 'goal').stdout) == GOAL.tolist()
        assert 'goal' in run(env, 'param', 'list').stdout.split()
        changed = run(env, 'param', 'set', 'goal', '[0.3, 0.2, 0, -1.1, 0, 0.6, 0]')
        assert changed.returncode == 0, changed.stdout + changed.stderr     # whole numbers too
        assert json.loads(run(env, 'param', 'get', 'goal').stdout) == \
            [0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0]
        refused = run(env, 'param', 'set', 'goal', '[4, 0.2, 0, -1.1, 0, 0.6, 0]')
        assert refused.returncode == 1 and 'lbr_A1 at 4 rad is outside' in refused.stdout
        unknown = run(env, 'param', 'get', 'no_such')
        assert unknown.returncode == 1 and 'no parameter no_such' in unknown.stderr
        stop = run(env, 'stop')
        assert stop.returncode == 0
    finally:
        planner.send_signal(signal.SIGINT)
        assert planner.wait(10) == 0
    timeout = run(env, 'start', '--timeout', '1')
    assert timeout.returncode == 3 and 'is the planner running' in timeout.stderr


def test_bad_timeouts_and_planner_names_are_one_line_errors(env):
    # a NaN timeout never passes its deadline: it would wait forever
    for command, args, text in [
            ('status', ('--timeout', 'nan'), '--timeout must be a positive number, got nan'),
            ('start', ('--timeout', 'nan'), '--timeout must be a positive number, got nan'),
            ('stop', ('--timeout', '-1'), '--timeout must be a positive number, got -1'),
            ('reset-map', ('--timeout', '0'), '--timeout must be a positive number, got 0'),
            ('start', ('--planner', 'bad name!', '--timeout', '1'),
             "'bad name!' is not a valid planner node name")]:
        result = run(env, command, *args, timeout=30)
        assert result.returncode == 2, result.stderr
        assert result.stderr.count('\n') == 1 and result.stderr.startswith(
            f'probdis {command}: error: ') and text in result.stderr, result.stderr


def test_the_demo_waits_for_a_planner_still_coming_up_and_stops_when_it_dies(env, monkeypatch):
    # a fresh install's planner compiles its kernels for 20-50 s before its
    # service is up: the demo waits for it while it lives, and says why
    from probdis_ros.ros.client import PlannerClient
    from probdis_ros.ros.demo import start_disentangling

    for name in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE'):
        monkeypatch.setenv(name, env[name])
    alive = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])
    dead = subprocess.Popen([sys.executable, '-c', 'raise SystemExit(3)'])
    dead.wait(30)
    said = []
    try:
        with PlannerClient() as client:
            began = time.monotonic()
            with pytest.raises(RuntimeError, match='did not come up within 4 s'):
                start_disentangling(client, alive, alive, said.append, startup_limit=4.0,
                                    call_timeout=1.0, tell_after=1.0)
            assert time.monotonic() - began >= 4.0
            assert any('waiting for the planner' in line for line in said)
            with pytest.raises(RuntimeError, match=r'the planner exited \(code 3\)'):
                start_disentangling(client, dead, alive, said.append, call_timeout=1.0)
    finally:
        alive.kill()
        alive.wait(10)


@pytest.mark.parametrize('status_after, calls_expected', [(1.5, 1), (6.5, 2)])
def test_the_demo_takes_a_start_whose_answer_was_lost_from_the_status(env, monkeypatch,
                                                                      status_after,
                                                                      calls_expected):
    # DDS may drop the answer of a service that has only just come up: the start took effect
    # (the status shows the run a moment later) and asking again would only be refused; a
    # status later than the demo waits for shows the run at the refusal
    import threading

    from probdis_ros.ros.client import PlannerClient
    from probdis_ros.ros.demo import start_disentangling
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    for name in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE'):
        monkeypatch.setenv(name, env[name])
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('probdis_planner', context=context)
    status = node.create_publisher(String, '~/status', QoSProfile(
        depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    status.publish(String(data=json.dumps({'state': 'idle'})))
    calls = []

    def publish_planning():
        status.publish(String(data=json.dumps({'state': 'planning'})))

    def on_start(request, response):
        calls.append(time.monotonic())
        if len(calls) > 1:
            response.success, response.message = False, 'a run is already active'
            return response
        # the run starts, but its status comes after the client gave up on the answer
        threading.Timer(status_after, publish_planning).start()
        time.sleep(3.0)
        response.success, response.message = True, 'disentangling'
        return response

    node.create_service(Trigger, '~/start', on_start)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    alive = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])
    try:
        with PlannerClient() as client:
            assert client.status(timeout=10.0)['state'] == 'idle'    # seen before the start
            message = start_disentangling(client, alive, alive, lambda *a: None,
                                          startup_limit=30.0, call_timeout=1.0)
        assert 'answer was lost' in message
        time.sleep(3.0)        # a further request would be served once the first one is done
        assert len(calls) == calls_expected  # started once, asked again only without a status
    finally:
        alive.kill()
        alive.wait(10)
        executor.shutdown()
        spinner.join(timeout=5.0)          # no callback running when the node goes
        node.destroy_node()
        context.try_shutdown()


def test_demo_disentangles_through_two_processes_and_its_bag_replays_the_same(env, tmp_path):
    env['ROS_HOME'] = str(tmp_path)              # where the planner records its bags
    picture = tmp_path / 'demo.png'
    result = run(env, 'demo', '--json', '--plot', str(picture), timeout=400)
    assert result.returncode == 0, result.stderr[-2000:]
    assert picture.stat().st_size > 10_000          # the scene, the flange path, the blocks
    doc = json.loads(result.stdout.strip().splitlines()[-1])
    assert list(doc) == ['success', 'paths', 'failures', 'replan_latency_s', 'bag']
    assert doc['success'] is True
    assert doc['paths'] >= 2 and doc['failures'] >= 1     # blocked retreats add failures
    assert set(doc['replan_latency_s']) == {'median', 'max'}
    assert 0 <= doc['replan_latency_s']['median'] <= doc['replan_latency_s']['max']
    bags = list((tmp_path / 'probdis' / 'bags').iterdir())
    assert bags == [Path(doc['bag'])]                  # the bag the JSON names, for a script
    replayed = run(env, 'replay', doc['bag'], '--json')
    assert replayed.returncode == 0, replayed.stderr
    summary = json.loads(replayed.stdout)
    assert (summary['success'], summary['paths'], summary['failures']) == \
        (doc['success'], doc['paths'], doc['failures'])
    assert len(summary['blocks']) == doc['failures']
    assert summary['blocks'][0]['retreat'] is False          # the first path was blocked
    text = run(env, 'replay', str(bags[0])).stdout
    assert text.count(' block at ') == doc['failures'] and 'during a path' in text


def test_demo_with_confirm_asks_before_each_path_and_takes_the_answers(env, tmp_path):
    # the operator declines the first path, then sends every path with Enter; in robot_waste,
    # which the method gets out of for every planner seed (test_ros_nodes' confirm test)
    env['ROS_HOME'] = str(tmp_path)
    result = subprocess.run([*probdis_command(), 'demo', '--engine', 'kinematic', '--confirm',
                             '--scenario', 'robot_waste'],
                            env=env, capture_output=True, text=True, timeout=400,
                            input='n\n' + '\n' * 30)
    assert result.returncode == 0, result.stderr[-2000:]
    log = result.stderr
    assert 'demo: decline_path: proposal 1 declined: planning another' in log
    sent = log.count('demo: confirm_path: proposal ')
    assert sent >= 1 and log.count('send this path?') == sent + 1
    assert f'disentangled after {sent} path(s)' in result.stdout


def test_robot_experiment_runs_through_the_nodes_and_resumes(env, tmp_path):
    out = tmp_path / 'robot'
    args = ('experiment', 'robot', '--runs', '1', '--scenarios', 'robot_maze',
            '--methods', 'probabilistic,hard:0.01', '--real-time-factor', '3', '--out', str(out))
    first = run(env, *args, timeout=600)
    assert first.returncode == 0, first.stderr[-2000:]
    records = [json.loads(line) for line in (out / 'robot_runs.jsonl').read_text().splitlines()]
    assert [(r['scenario'], r['method'], r['run']) for r in records] == \
        [('robot_maze', 'probabilistic', 0), ('robot_maze', 'hard:0.01', 0)]
    # each run went through the nodes: planned paths, an outcome, a bag to replay
    assert all(1 <= r['paths'] <= 20 and isinstance(r['success'], bool) for r in records)
    assert all(os.path.isdir(r['bag']) for r in records)
    # every run's bag was checked for joint states the planner missed (a run that missed
    # some is left out of the table)
    assert all(r['missed_states'] >= 0 and r['max_state_gap_s'] > 0 for r in records)
    cells = ' | '.join(f'{int(r["success"])} / 1' if valid(r) else '0 / 0' for r in records)
    assert f'| robot_maze | {cells} |' in first.stdout
    # a rerun finds every valid run done: only a run the planner fell behind in is run
    # again; with none, the same table is printed
    not_valid = [r for r in records if not valid(r)]
    again = run(env, *args, timeout=600)
    assert again.returncode == 0
    assert len((out / 'robot_runs.jsonl').read_text().splitlines()) == 2 + len(not_valid)
    if not not_valid:
        assert '[1/' not in again.stderr and again.stdout == first.stdout
    refused = run(env, 'experiment', 'robot', '--scenarios', 'no_such_world', '--out', str(out))
    assert refused.returncode == 2 and "no scene file 'no_such_world'" in refused.stderr
