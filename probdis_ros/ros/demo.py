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

"""
``probdis demo``: the mock iiwa and the planner as two processes over DDS on localhost.

Starts both nodes as separate processes, starts a disentangling, follows it on the
planner's status topic with a progress line per change, shuts both down with SIGINT and
reports the outcome.
"""

from __future__ import annotations

import os
from pathlib import Path
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
from probdis_ros.motion.jtc import DEFAULT_JTC_START
from probdis_ros.physics import load_scene
from probdis_ros.resources import data_file, scenario_path
from probdis_ros.ros import DEFAULT_REAL_TIME_FACTOR, MOCK_NODE
from probdis_ros.ros.operator_prompt import OperatorPrompt
from probdis_ros.sim.worlds import load_world

#: The scene of ``probdis demo`` and ``make demo``.
DEFAULT_SCENE = 'demo_hook'
FINISHED = ('succeeded', 'gave_up', 'stopped')
RUNNING = ('planning', 'executing', 'retreating', 'awaiting_confirmation')


def ros_environment() -> dict:
    """Return this environment with ROS 2 kept on this machine (set where unset)."""
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('ROS_DOMAIN_ID', str(random.randint(10, 99)))
    return env


def node_command(module: str, *ros_args: str) -> list[str]:
    """Return the command that runs a node module with ROS arguments."""
    return [sys.executable, '-m', module, '--ros-args', *ros_args]


def stop_process(process: subprocess.Popen, timeout: float = 10.0) -> int:
    """SIGINT a node, then SIGKILL it if it does not end in time; return its exit code."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            return process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
    return process.wait()


def _started(client, wait: float = 5.0) -> bool:
    """
    Tell whether the planner's status shows a run (going, or already over) within wait [s].

    For a start whose answer was lost: the planner publishes its status at every change, so
    a start that took effect shows within a moment.  The demo's planner is its own, fresh:
    a run on it, or the end of one, can only be the demo's.
    """
    deadline = time.monotonic() + wait
    seen = None
    while time.monotonic() < deadline:
        try:
            seen = client.status(timeout=deadline - time.monotonic(), newer_than=seen)
        except TimeoutError:
            return False
        if seen.get('state') in RUNNING + FINISHED:
            return True
    return False


#: [s] how long the planner may take to come up: its first start after an install compiles
#: the planning kernels (20-50 s on two cores; later starts load them in seconds)
STARTUP_LIMIT = 600.0
#: [s] how long a planner that answers but refuses (no joint states yet) is asked again
REFUSALS_FOR = 60.0


def start_disentangling(client, planner: subprocess.Popen, mock: subprocess.Popen, say,
                        startup_limit: float = STARTUP_LIMIT, call_timeout: float = 10.0,
                        tell_after: float = 5.0) -> str:
    """
    Start the disentangling on the planner's service; return its answer.

    Waits while the planner process is alive and its service is not up yet (up to
    startup_limit [s], saying why after tell_after), asks again for REFUSALS_FOR while it
    refuses, and raises RuntimeError if a node exits or the planner keeps refusing.
    """
    from probdis_ros.ros.client import FIRST_START, NoAnswerError

    began = time.monotonic()
    answered_at = None
    told = lost = False
    while True:
        try:
            ok, message = client.call('start', timeout=call_timeout)
            answered_at = answered_at or time.monotonic()
        except NoAnswerError as err:
            ok, message, lost = False, str(err), True
            answered_at = answered_at or time.monotonic()
        except TimeoutError as err:
            ok, message = False, str(err)
        if ok:
            return message
        # DDS can drop an answer while it still matches the new client: whether that start
        # took effect, the status says (asked again, the planner refuses: a run is active)
        if lost and _started(client):
            return 'started (its answer was lost; the status says so)'
        for name, process in (('planner', planner), ('mock iiwa', mock)):
            if process.poll() is not None:
                raise RuntimeError(f'the {name} exited (code {process.returncode}) before the '
                                   f'run started: {message}')
        now = time.monotonic()
        if answered_at is not None and now - answered_at > REFUSALS_FOR:
            raise RuntimeError(f'planner refused to start: {message}')
        if now - began > startup_limit:
            raise RuntimeError(f'planner did not come up within {startup_limit:.0f} s: {message}')
        if not told and answered_at is None and now - began > tell_after:
            say(f'demo: waiting for the planner to come up ({FIRST_START})')
            told = True
        time.sleep(0.2)


def world_of(world: str, engine: str) -> tuple[Path, str, np.ndarray, float]:
    """
    Return a world's file, name, goal and the reach of its grasped object about the flange.

    A physics scene, or a kinematic scenario (whose object is the flange point: reach 0).
    """
    if engine == 'physics':
        scene = load_scene(world)
        return Path(scene.source or world), scene.name, scene.goal, scene.object_reach
    path = scenario_path(world)
    scenario = load_world(path)
    return path, scenario.name or str(path), scenario.goal, 0.0


def run_demo(world: str = DEFAULT_SCENE, timeout: float = 300.0, quiet: bool = False,
             extra_planner_args: tuple[str, ...] = (), engine: str = 'physics',
             sim_time: bool = False, real_time_factor: float = DEFAULT_REAL_TIME_FACTOR,
             extra_mock_args: tuple[str, ...] = (), jtc_start: str = DEFAULT_JTC_START,
             confirm: bool = False) -> dict:
    """
    Run a disentangling against the mock iiwa; return the outcome summary.

    world is a physics scene (engine ``physics``) or a kinematic scenario (``kinematic``).
    With sim_time the mock runs on simulated time at real_time_factor (0: as fast as it
    can) and the planner follows its /clock; timeout stays in wall-clock seconds.
    jtc_start: where the mock's controller starts a command, and the planner models it
    (``interpolate_from_desired_state``: 'desired'), checked by the planner against the mock.
    confirm: the planner's ``confirm_paths``; each path waits for an answer on standard input
    (:class:`OperatorPrompt`), whose time the run's timeout does not count: each answer has a
    timeout of its own, as long.
    """
    from probdis_ros.ros.client import PlannerClient

    path, name, goal_config, object_radius = world_of(world, engine)
    env = ros_environment()
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    with tempfile.TemporaryDirectory(prefix='probdis_demo_') as tmp:
        goal = '[' + ', '.join(f'{v:.9f}' for v in goal_config) + ']'
        world_param = 'scene' if engine == 'physics' else 'scenario'
        clock = ('-p', 'sim_time:=true', '-p', f'real_time_factor:={real_time_factor}') \
            if sim_time else ()
        desired = ('-p', f'interpolate_from_desired_state:={str(jtc_start == "desired").lower()}')
        mock = subprocess.Popen(node_command(
            'probdis_ros.ros.mock_iiwa_node', '-p', f'engine:={engine}',
            '-p', f'{world_param}:={path}', *clock, *desired, *extra_mock_args), env=env)
        params = str(data_file('config', 'planner.yaml'))
        planner = subprocess.Popen(node_command(
            'probdis_ros.ros.planner_node', '--params-file', params, '-p', f'goal:={goal}',
            '-p', f'map_file:={Path(tmp) / "map.json"}', *desired,
            '-p', f'controller_node:=/{MOCK_NODE}', '-p', f'object_radius:={object_radius}',
            *(('-p', 'use_sim_time:=true') if sim_time else ()),
            '-p', f'confirm_paths:={str(confirm).lower()}', *extra_planner_args), env=env)
        status: dict = {}
        try:
            with PlannerClient() as client:
                say(f'demo: {name} ({engine}): mock iiwa and planner started '
                    f'(ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]})')
                message = start_disentangling(client, planner, mock, say)
                say(f'demo: start: {message}')
                t0 = time.monotonic()           # the run's timeout counts from its start
                asked_for = None
                prompt = OperatorPrompt()

                def still_waiting() -> bool:
                    if planner.poll() is not None or mock.poll() is not None:
                        return False
                    latest = client.status(timeout=0.05, newer_than=status)
                    return latest.get('state') == 'awaiting_confirmation' and \
                        latest.get('proposal') == asked_for
                while status.get('state') not in FINISHED:
                    if time.monotonic() - t0 > timeout:
                        raise TimeoutError(f'no outcome within {timeout:.0f} s')
                    if planner.poll() is not None or mock.poll() is not None:
                        raise RuntimeError('a node exited during the run')
                    new = client.status(timeout=1.0, newer_than=status)
                    if new != status:
                        status = new
                        say(f'[{time.monotonic() - t0:6.1f} s] {status["state"]:<10} '
                            f'paths {status["paths"]:>2}  failures {status["failures"]:>2}  '
                            f'{status["message"]}')
                        if status['state'] == 'awaiting_confirmation' and \
                                status.get('proposal') != asked_for:
                            asked_for = status.get('proposal')     # once per proposal
                            asked = time.monotonic()
                            if quiet:           # no progress lines: say what it asks about
                                prompt.say(f'demo: {status["message"]}\n')
                            service = prompt.ask(still_waiting, patience=timeout)
                            t0 += time.monotonic() - asked
                            if service is not None:
                                _, message = client.call(service)
                                say(f'demo: {service}: {message}')
        finally:
            codes = (stop_process(planner), stop_process(mock))
    latencies = status.get('replan_latencies_s') or [0.0]
    return {'success': status.get('state') == 'succeeded', 'paths': status.get('paths', 0),
            'failures': status.get('failures', 0),
            'replan_latency_s': {'median': statistics.median(latencies),
                                 'max': max(latencies)},
            'exit_codes': codes, 'bag': status.get('bag', '')}
