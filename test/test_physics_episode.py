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


"""Offline episodes against the physics arm, their picture, and a run on simulated time."""

import json
import os
from pathlib import Path
import subprocess
import sys

from conftest import next_domain
import numpy as np
from probdis_ros.physics.episode import run_physics_episode
import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_an_offline_physics_episode_learns_from_a_block_and_is_reproducible():
    first = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=5)
    again = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=5)
    assert first.success and len(first.failures) >= 1
    assert first.paths == len(first.failures) + 1
    # the hook pressed on the bar: a force, and a gap the detector saw
    assert first.contact_force.max() > 10.0 and first.gaps.max() > 0.04
    np.testing.assert_array_equal(first.configs, again.configs)
    assert first.sim_time_s > 1.0      # (its speed: `probdis bench physics`, not a test)


def test_commands_that_reach_the_controller_late_still_get_the_arm_out():
    # every message 0.25 s on its way (a loaded machine or network): paths and retreats are
    # taken late; a path done before the arm got to its end sent the run back and forth
    # (this seed: 18 paths, 13 of them ended short of the goal without a block)
    from probdis_ros.physics.simulated_robot import RobotSettings

    late = run_physics_episode('demo_hook', 'informed', seed=0, max_paths=6,
                               robot_settings=RobotSettings(command_latency=0.25))
    assert late.success and late.paths <= 3, late.message


def test_a_driver_stopped_by_the_speed_monitoring_is_restarted_and_the_run_resumes():
    # KUKA's speed monitoring at 0.1 m/s stops the arm on the demo's first path, before it
    # meets the hook (its points reach about 0.6 m/s at scaling 0.2): every start is stopped
    from probdis_ros.physics.episode import RESTART_AFTER
    from probdis_ros.physics.simulated_robot import DRIVER_STOPPED, RobotSettings

    monitored = RobotSettings(speed_monitor=0.1)
    once = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=5,
                               robot_settings=monitored)
    assert not once.success and once.restarts == 0 and once.paths == 1 and not once.failures
    assert once.message.count(DRIVER_STOPPED) == 1 and 'speed monitoring' in once.message
    # restarted: each start plans from where the arm came to rest, and the starts together
    # plan at most max_paths paths (here 3, before the 5 restarts allowed are used)
    again = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=3,
                                robot_settings=monitored, restarts=5)
    assert not again.success and again.restarts == 2 and again.paths == 3
    assert again.message.count(DRIVER_STOPPED) == 3 and not again.failures
    assert again.summary()['driver_restarts'] == 2 and len(again.restarted_at) == 2
    assert len(again.plan_times_s) == again.paths         # every start's plans
    # allowed one restart: two starts, two paths, stopped twice
    one = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=3,
                              robot_settings=monitored, restarts=1)
    assert (one.restarts, one.paths, one.message.count(DRIVER_STOPPED)) == (1, 2, 2)
    # a time limit that ends the rest before the restart: the episode ends at the limit
    limit = once.sim_time_s + 0.5 * RESTART_AFTER
    late = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=3,
                               robot_settings=monitored, restarts=1, time_limit=limit)
    assert late.restarts == 0 and late.message.endswith(f'time limit of {limit:.0f} s '
                                                        'simulated reached')
    assert limit <= late.sim_time_s < limit + 0.02     # within a controller period
    # the arm rested, held, before each restart; the last start planned from where it was
    stopped, restarted = again.restarted_at[-1] - RESTART_AFTER, again.restarted_at[-1]
    resting = again.configs[(again.times > stopped + 1.0) & (again.times <= restarted)]
    assert np.abs(resting - resting[-1]).sum(axis=1).max() < 0.01
    first_plan = again.loop.attempts[0].path[0]
    np.testing.assert_allclose(first_plan, resting[-1], atol=0.01)
    assert np.abs(first_plan - again.scene.start).sum() > 0.05    # not where the run began
    with pytest.raises(ValueError, match='restarts'):
        run_physics_episode('demo_hook', restarts=-1)


def test_the_runs_external_torque_estimate_is_the_contacts_with_the_load_data_right():
    # the planner's estimate, efforts minus g(q) with the hook's 0.4 kg, against the torques
    # the contacts exerted (MuJoCo's J^T f): the status reports how hard the arm pressed
    from probdis_ros.motion.detector import DetectorSettings
    from probdis_ros.physics.simulated_robot import RobotSettings
    from probdis_ros.run import RunSettings

    load = RunSettings(detection=DetectorSettings(load_mass=0.4, load_com=(0.0, 0.0, 0.12)))
    episode = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=5,
                                  run_settings=load, robot_settings=RobotSettings(torque_tau=0))
    truth = episode.external_torque_peak
    assert truth.max() > 20.0       # the hook pressed on the bar
    np.testing.assert_allclose(episode.estimated_torque_peak, truth, atol=0.05 * truth.max())
    # through the driver's torque filter (0.1 s, as the lbr stack ships it) a press's peak
    # comes out lower, never higher
    filtered = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=5,
                                   run_settings=load)
    truth = filtered.external_torque_peak
    joint = int(truth.argmax())
    assert 0.8 * truth[joint] < filtered.estimated_torque_peak[joint] < truth[joint]
    assert np.all(filtered.estimated_torque_peak <= truth + 0.05 * truth.max())


def test_paths_confirmed_at_once_run_as_unconfirmed_ones_and_a_wait_holds_the_arm():
    from probdis_ros.run import RunSettings

    plain = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=5)
    confirm = RunSettings(confirm_paths=True)
    at_once = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=5,
                                  run_settings=confirm)
    assert at_once.success and len(at_once.proposed_at) == at_once.paths == plain.paths
    np.testing.assert_array_equal(at_once.configs, plain.configs)
    # an operator who looks for a second: every path waits, the arm at rest, nothing sent
    waited = run_physics_episode('demo_hook', 'probabilistic', seed=1, max_paths=5,
                                 run_settings=confirm, confirm_after=1.0)
    assert waited.success and waited.paths == plain.paths
    assert len(waited.proposed_at) == waited.paths >= 2
    sent = np.array([command[0] for command in waited.commands])
    for proposed in waited.proposed_at:
        assert not np.any((sent > proposed) & (sent < proposed + 1.0 - 1e-9))
        held = waited.configs[(waited.times >= proposed) & (waited.times < proposed + 1.0)]
        assert np.abs(held - held[0]).sum(axis=1).max() < 0.03    # settling only
    assert waited.sim_time_s >= plain.sim_time_s + 1.5
    with pytest.raises(ValueError, match='confirm_after'):
        run_physics_episode('demo_hook', confirm_after=-1.0)


def test_probdis_sim_engine_physics_prints_json_and_draws_the_scene(tmp_path):
    picture = tmp_path / 'run.png'
    # the paper's method meets the hook before it gets out (the default, informed, may turn
    # the object free at once, with no block to show)
    done = subprocess.run([sys.executable, '-m', 'probdis_ros.cli', 'sim', '--engine', 'physics',
                           '--scene', 'demo_hook', '--seed', '1', '--max-paths', '5', '--json',
                           '--method', 'probabilistic', '--plot', str(picture)],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    assert doc['success'] and doc['failures'] >= 1 and doc['peak_contact_force_n'] > 0
    # the planner keeps the arm and the object clear of the mock's table top
    assert doc['peak_table_force_n'] == 0.0 and doc['lowest_m'] > 0.05
    # what a real arm's collision detection would compare: the hook's push, on every joint
    # before the wrist's last (a push at the flange point turns A7 little)
    torque = doc['peak_external_torque_nm']
    assert len(torque) == 7 and min(torque[:6]) > 0.5 and max(torque) < 320
    assert picture.stat().st_size > 10_000
    refused = subprocess.run([sys.executable, '-m', 'probdis_ros.cli', 'sim', '--engine',
                              'physics', '--scene', str(tmp_path / 'missing.yaml')],
                             capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert refused.returncode != 0 and 'missing.yaml' in refused.stderr
    # --c-fail was dropped with --engine physics, even a negative one
    refused = subprocess.run([sys.executable, '-m', 'probdis_ros.cli', 'sim', '--engine',
                              'physics', '--c-fail', '-5'],
                             capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert refused.returncode == 2 and 'c_fail must be a positive' in refused.stderr


@pytest.mark.ros
def test_a_demo_on_simulated_time_disentangles_and_records_in_simulated_time(tmp_path):
    env = dict(os.environ, ROS_HOME=str(tmp_path),
               ROS_DOMAIN_ID=str(next_domain()))
    done = subprocess.run([sys.executable, '-m', 'probdis_ros.cli', 'demo', '--sim-time',
                           '--json'], capture_output=True, text=True, timeout=400, env=env,
                          cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    doc = json.loads(done.stdout.strip().splitlines()[-1])
    assert doc['success'] and doc['failures'] >= 1
    from probdis_ros.ros.replay import replay
    bag = next((tmp_path / 'probdis' / 'bags').iterdir())
    result = replay(bag)
    assert result.success and result.paths == doc['paths']
    assert result.times[-1] - result.times[0] > 5.0     # seconds of simulated motion
