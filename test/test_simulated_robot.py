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


"""The simulated robot: JTC, the driver's filter, an engine, and what the driver reports."""

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.jtc import JtcTrajectory
from probdis_ros.motion.timing import time_path
from probdis_ros.physics import load_scene
from probdis_ros.physics.simulated_robot import build_robot, RobotSettings
import pytest

ARM = iiwa_arm()


def free_scene():
    from dataclasses import replace
    return replace(load_scene('demo_hook'), obstacles=())


def command_to(robot, goal, scaling=0.5):
    start = robot.joint_state().position
    timed = time_path(np.array([start, goal]), ARM.velocity_limits, scaling)
    command = timed.command()
    robot.command(command)
    return JtcTrajectory(command, start, np.zeros(7), robot.time), timed.duration


def test_the_kinematic_engine_copies_the_command_and_stops_dead_at_contact():
    robot, text = build_robot('kinematic', 'demo_iiwa')
    assert 'hidden obstacles' in text
    scenario_goal = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
    jtc, duration = command_to(robot, scenario_goal, 1.0)
    lags = []
    while robot.time < duration + 1.0:
        robot.step()
        lags.append(np.abs(jtc.at(robot.time - jtc.taken_at) - robot.engine.q).sum())
    # the demo scenario blocks the straight path: the arm stopped short and stays there
    assert np.abs(robot.engine.q - scenario_goal).sum() > 0.1
    assert lags[0] < 0.05          # before the contact it followed the command closely


def test_the_physics_arm_lags_and_an_echoing_driver_hides_it():
    goal = np.array([0.5, 0.3, 0.2, -1.0, 0.1, 0.7, 0.2])
    gaps = {}
    for echo in (False, True):
        robot, _ = build_robot('physics', free_scene(), RobotSettings(echo=echo))
        jtc, duration = command_to(robot, goal, 0.5)
        worst, truth = 0.0, 0.0
        while robot.time < duration * 0.8:
            robot.step()
            reported = robot.joint_state()
            desired = jtc.at(reported.time - jtc.taken_at)
            worst = max(worst, float(np.abs(desired - reported.position).sum()))
            truth = max(truth, float(np.abs(reported.position - robot.engine.q).sum()))
        gaps[echo] = (worst, truth)
    # a measuring driver shows the impedance lag; an echoing one shows none while the arm
    # itself is elsewhere
    assert gaps[False][0] > 0.02 and gaps[False][1] == 0.0
    assert gaps[True][0] < 1e-9 and gaps[True][1] > 0.02


def test_latency_delays_and_noise_perturbs_the_reported_state_reproducibly():
    goal = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
    runs = []
    for settings in (RobotSettings(), RobotSettings(latency=0.05),
                     RobotSettings(noise=0.01, seed=4), RobotSettings(noise=0.01, seed=4)):
        robot, _ = build_robot('kinematic', 'demo_iiwa', settings)
        command_to(robot, goal, 1.0)
        states = []
        for _ in range(30):
            robot.step()
            states.append(robot.joint_state())
        runs.append(states)
    plain, late, noisy, again = runs
    assert late[-1].time == pytest.approx(plain[-1].time - 0.05)
    np.testing.assert_allclose(late[-1].position, plain[-6].position)
    assert np.std(noisy[-1].position - plain[-1].position) > 0.003
    np.testing.assert_array_equal(noisy[-1].position, again[-1].position)


def test_an_unknown_engine_is_refused():
    with pytest.raises(ValueError, match='engine must be one of'):
        build_robot('teleport', 'demo_iiwa')
    with pytest.raises(ValueError, match='latency'):
        RobotSettings(latency=-1.0)
