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


"""The real arm's behaviour on the physics mock: blocks, forces, free motion, echo, limits."""

from dataclasses import replace

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.detector import Verdict
from probdis_ros.motion.jtc import JtcTrajectory
from probdis_ros.physics import load_scene, measure, PhysicsIiwa, PhysicsSettings
from probdis_ros.physics.episode import run_physics_episode
from probdis_ros.physics.simulated_robot import RobotSettings, SimulatedRobot
from probdis_ros.run import ECHO_MESSAGE, RunSettings
import pytest

ARM = iiwa_arm()


@pytest.mark.parametrize('scene', ['demo_hook', 'robot_bunny'])
def test_a_block_is_located_where_it_began_and_its_force_is_bounded(scene):
    block = measure.straight_block(scene, 0.2)
    assert block.verdict == 'blocked'
    assert block.onset_error_m < 0.02               # the flange where contact happened
    assert block.flange_moved_m > block.onset_error_m
    assert block.force_at_detection_n < 150.0       # a ceiling, not the trajectory's end
    assert block.detected_s < block.planned_s


@pytest.mark.parametrize('scaling', [0.2, 1.0])
@pytest.mark.parametrize('scene', ['demo_hook', 'robot_maze'])
def test_free_motion_with_noise_and_a_load_error_is_never_taken_for_a_block(scene, scaling):
    free = replace(load_scene(scene), obstacles=())
    # the controller assumes 1 kg more than the object weighs; 0.001 rad noise
    arm = PhysicsIiwa(free, PhysicsSettings(object_mass_error=-1.0))
    robot = SimulatedRobot(arm, free.start, RobotSettings(noise=0.001, seed=3))
    motion = measure._motion(np.array([free.start, free.goal]), scaling)
    _, verdict = measure._drive(robot, motion.command, measure._detection(),
                                motion.duration + 3.0)
    assert verdict is Verdict.DONE


def test_a_driver_that_echoes_the_command_is_refused_naming_the_setting():
    episode = run_physics_episode('demo_hook', seed=1, max_paths=3,
                                  robot_settings=RobotSettings(echo=True))
    assert episode.outcome == 'stopped' and episode.message == ECHO_MESSAGE
    assert 'open_loop' in episode.message and not episode.failures


def test_an_episode_commands_only_what_the_limits_allow_and_retreats_stay_clear():
    episode = run_physics_episode('demo_hook', seed=1, max_paths=6)
    assert episode.success and episode.failures
    assert not [f for f in episode.failures if f['why'].startswith('retreat')]
    limits = RunSettings().limits(ARM)
    for _, command, q, v in episode.commands:
        jtc = JtcTrajectory(command, q, v)
        times = np.arange(0.0, jtc.duration + 0.02, 0.002)
        samples = [jtc.sample(t) for t in times]
        positions = np.array([s[0] for s in samples])
        velocities = np.array([s[1] for s in samples])
        accelerations = np.array([s[2] for s in samples])
        assert np.all(np.abs(velocities) <= limits.max_velocity * 1.02 + 1e-6)
        assert np.all(np.abs(accelerations) <= limits.max_acceleration * 1.2 + 1e-6)
        assert np.all(np.abs(np.diff(velocities, axis=0)) <= 0.002 * limits.max_acceleration
                      * 1.2 + 1e-6)
        assert ARM.within_limits(positions).all()
