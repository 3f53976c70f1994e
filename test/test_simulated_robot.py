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

from dataclasses import replace

from linear_path import time_path
import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.jtc import (
    DRIVER_FILTER_TAU,
    DRIVER_TORQUE_TAU,
    FirstOrderFilter,
    JtcTrajectory,
    TrajectoryCommand,
)
from probdis_ros.physics import load_scene, measure
from probdis_ros.physics.simulated_robot import build_robot, RobotSettings
from probdis_ros.run import MAX_VELOCITY_SCALING
import pytest

ARM = iiwa_arm()


def free_scene():
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


def test_the_kinematic_engine_follows_a_far_setpoint_within_the_velocity_limits():
    # the servo lag closes a fifth of the gap per period, but never faster than the URDF's
    # velocity limits: a far setpoint (a driver without the joint limiter) is approached at them
    robot, _ = build_robot('kinematic', 'demo_iiwa', RobotSettings(guard=False))
    engine, period = robot.engine, robot.settings.period
    start = engine.q.copy()
    far = start + np.array([0.0, 0.0, 0.5, 0.0, 0.5, 0.0, 0.5])   # free of the scenario
    engine.advance(far, period)
    np.testing.assert_allclose(np.abs(engine.q - start),
                               np.where(far != start, ARM.velocity_limits * period, 0.0))


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
    assert gaps[True][1] > 0.02


def test_an_echoing_driver_reports_the_command_it_sends_after_its_filter():
    # the lbr stack's set_state_open_loop: the position is the driver's filtered command,
    # the velocity its difference, the torques stay measured
    goal = np.array([0.5, 0.3, 0.2, -1.0, 0.1, 0.7, 0.2])
    robot, _ = build_robot('physics', free_scene(), RobotSettings(echo=True))
    jtc, duration = command_to(robot, goal, 0.5)
    sent = FirstOrderFilter(DRIVER_FILTER_TAU)
    sent.reset(robot.joint_state().position)
    torques = FirstOrderFilter(DRIVER_TORQUE_TAU)
    torques.reset(robot.joint_state().effort)
    before = sent.value.copy()
    while robot.time < duration:
        command = jtc.at(robot.time + robot.settings.period - jtc.taken_at)
        robot.step()
        expected = sent(command)
        reported = robot.joint_state()
        assert np.abs(reported.position - expected).max() < 1e-12
        assert np.abs(reported.velocity - (expected - before) / robot.settings.period
                      ).max() < 1e-9
        np.testing.assert_array_equal(reported.effort, torques(robot.engine.tau_measured))
        before = expected
    assert np.abs(reported.position - robot.engine.q).sum() > 0.02   # the arm lags


def test_latency_delays_and_noise_perturbs_the_reported_state_reproducibly():
    goal = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
    runs = []
    for settings in (RobotSettings(), RobotSettings(latency=0.05),
                     RobotSettings(noise=0.01, seed=4), RobotSettings(noise=0.01, seed=4),
                     RobotSettings(latency=0.055)):
        robot, _ = build_robot('kinematic', 'demo_iiwa', settings)
        command_to(robot, goal, 1.0)
        states = []
        for _ in range(30):
            robot.step()
            states.append(robot.joint_state())
        runs.append(states)
    plain, late, noisy, again, later = runs
    assert late[-1].time == pytest.approx(plain[-1].time - 0.05)
    np.testing.assert_allclose(late[-1].position, plain[-6].position)
    # a latency between two periods: the newest state at least that old, never a newer one
    assert later[-1].time == pytest.approx(plain[-1].time - 0.06)
    np.testing.assert_allclose(later[-1].position, plain[-7].position)
    assert np.std(noisy[-1].position - plain[-1].position) > 0.003
    np.testing.assert_array_equal(noisy[-1].position, again[-1].position)


def test_the_driver_differences_its_measured_positions_into_velocities_and_jtc_reads_them():
    # the lbr stack's compute_hw_velocity_: (measured now - measured a period before) / period,
    # so the encoders' noise reaches the velocity divided by the period; JTC reads the same
    # state interfaces, and starts a command from that noisy state, not from the arm's own
    noise, period = 1e-4, RobotSettings().period
    robot, _ = build_robot('physics', free_scene(), RobotSettings(noise=noise, seed=5))
    before = robot.joint_state()
    assert not before.velocity.any()            # the first measurement: at rest
    idle = []
    for _ in range(200):
        robot.step()
        state = robot.joint_state()
        np.testing.assert_allclose(state.velocity, (state.position - before.position) / period,
                                   rtol=0, atol=1e-12)
        idle.append(state.velocity)
        before = state
    # the arm rests: what the velocities show is the noise, sqrt(2) noise / period
    assert 0.85 < np.std(idle) / (np.sqrt(2) * noise / period) < 1.15
    assert np.abs(robot.engine.qdot).max() < 1e-3
    seen = robot.joint_state()
    command_to(robot, np.array([0.5, 0.3, 0.2, -1.0, 0.1, 0.7, 0.2]))
    robot.step()
    start_q, start_v = robot.controller.trajectory.before[:2]
    np.testing.assert_array_equal(start_q, seen.position)
    np.testing.assert_array_equal(start_v, seen.velocity)
    assert np.abs(start_q - robot.engine.q).max() > noise / 10


def test_the_driver_filters_the_torques_it_reports_so_they_lag_the_arms():
    # the lbr stack's measured_torque_tau: a first-order filter (0.1 s as it ships) between
    # the arm's torque sensors and the effort state interface
    goal = np.array([0.5, 0.3, 0.2, -1.0, 0.1, 0.7, 0.2])
    lags = {}
    for tau in (DRIVER_TORQUE_TAU, 0.0):
        robot, _ = build_robot('physics', free_scene(), RobotSettings(torque_tau=tau))
        expected = FirstOrderFilter(tau)
        expected.reset(robot.engine.tau_measured)
        command_to(robot, goal, 0.5)
        worst = 0.0
        for _ in range(150):
            robot.step()
            effort = robot.joint_state().effort
            np.testing.assert_allclose(effort, expected(robot.engine.tau_measured),
                                       rtol=0, atol=1e-9)
            worst = max(worst, float(np.abs(effort - robot.engine.tau_measured).max()))
        lags[tau] = worst
    assert lags[0.0] == 0.0 and lags[DRIVER_TORQUE_TAU] > 0.5     # [Nm], as the arm speeds up
    with pytest.raises(ValueError, match='torque_tau'):
        RobotSettings(torque_tau=-0.1)


def test_a_command_latency_holds_each_message_back_and_the_newest_one_replaces_the_rest():
    goal = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
    runs = {}
    for latency in (0.0, 0.2):
        robot, _ = build_robot('kinematic', 'demo_iiwa', RobotSettings(command_latency=latency))
        start = robot.engine.q.copy()
        command_to(robot, goal, 1.0)
        moved_at = None
        while robot.time < 0.5:
            robot.step()
            if moved_at is None and np.abs(robot.engine.q - start).sum() > 1e-9:
                moved_at = robot.time
        runs[latency] = moved_at
    # JTC takes it at its first update after it arrives: 0.2 s (20 periods) later
    assert runs[0.0] == pytest.approx(0.01) and runs[0.2] == pytest.approx(0.21)
    # two messages arriving in one period: JTC runs the newer (a new one replaces the last)
    robot, _ = build_robot('kinematic', 'demo_iiwa', RobotSettings(command_latency=0.1))
    start = robot.engine.q.copy()
    command_to(robot, goal, 1.0)
    command_to(robot, start, 1.0)         # hold where it is
    while robot.time < 0.5:
        robot.step()
    assert np.abs(robot.engine.q - start).sum() < 1e-9
    with pytest.raises(ValueError, match='command_latency'):
        RobotSettings(command_latency=-0.1)


def test_torque_noise_perturbs_the_reported_efforts_alone_from_a_stream_of_its_own():
    goal = np.array([0.5, 0.3, 0.2, -1.0, 0.1, 0.7, 0.2])
    runs = []
    for settings in (RobotSettings(noise=0.001, seed=3),
                     RobotSettings(noise=0.001, effort_noise=2.0, seed=3),
                     RobotSettings(noise=0.001, effort_noise=2.0, seed=3)):
        robot, _ = build_robot('physics', free_scene(), settings)
        command_to(robot, goal, 0.5)
        states = []
        for _ in range(60):
            robot.step()
            states.append((robot.joint_state(), robot.engine.tau_measured.copy()))
        runs.append(states)
    plain, noisy, again = runs
    # the positions (and their noise) as without it; the efforts about those without it
    for (quiet, _), (loud, _), (same, _) in zip(plain, noisy, again):
        np.testing.assert_array_equal(loud.position, quiet.position)
        np.testing.assert_array_equal(loud.effort, same.effort)
    errors = np.array([loud.effort - quiet.effort for (quiet, _), (loud, _) in zip(plain, noisy)])
    assert 1.7 < errors.std() < 2.3 and abs(errors.mean()) < 0.3
    with pytest.raises(ValueError, match='effort_noise'):
        RobotSettings(effort_noise=-1.0)


def test_an_unknown_engine_is_refused():
    with pytest.raises(ValueError, match='engine must be one of'):
        build_robot('teleport', 'demo_iiwa')
    with pytest.raises(ValueError, match='latency'):
        RobotSettings(latency=-1.0)


def test_the_command_guard_stops_the_driver_on_a_speed_the_arm_may_not_reach():
    # the lbr stack's guard: a measured joint speed above the URDF limit ends the driver;
    # the arm in joint impedance overshoots its commanded speed as it catches up, so the
    # long edge at the full velocity limits trips it (the planner takes at most 0.8)
    start, goal = measure.LONG_EDGE
    free = replace(load_scene('demo_hook'), obstacles=(), start=start, goal=goal)
    robot, _ = build_robot('physics', free)
    motion = measure._motion(np.array([start, goal]), 1.0)
    robot.command(motion.command)
    while robot.stopped is None and robot.time < motion.duration:
        robot.step()
    assert robot.stopped is not None and 'above its velocity limit' in robot.stopped
    # a stopped driver reports nothing more, and the arm holds
    last, held = robot.joint_state(), robot.engine.q.copy()
    for _ in range(50):
        robot.step()
    assert robot.joint_state() is last and robot.time > last.time + 0.4
    assert np.abs(robot.engine.q - held).max() < 0.05
    # restarted where it holds: no command of before survives, not even in the joint
    # limiter, whose last command ran far ahead of the arm
    for _ in range(100):
        robot.step()
    robot.restart()
    held = robot.engine.q.copy()
    for _ in range(50):
        robot.step()
    assert robot.stopped is None
    np.testing.assert_allclose(robot.engine.q, held, atol=2e-3)
    for scaling in (0.2, MAX_VELOCITY_SCALING):
        assert measure.long_edge(scaling).speed_over_limit < 0.95


def test_kukas_speed_monitoring_stops_a_fast_arm_and_lets_a_capped_motion_run():
    # the long edge at velocity scaling 0.2 moves the arm's points at up to ~0.5 m/s: a
    # monitored 0.25 m/s (T1) stops it; timed under a Cartesian cap of 0.2 it runs to the end
    from probdis_ros.motion.cartesian_speed import CartesianSpeedLimit
    from probdis_ros.motion.profiles import MotionLimits, time_parameterize

    start, goal = measure.LONG_EDGE
    free = replace(load_scene('demo_hook'), obstacles=(), start=start, goal=goal)
    for cap in (None, 0.2):
        robot, _ = build_robot('physics', free, RobotSettings(speed_monitor=0.25))
        limits = MotionLimits(cartesian=cap and CartesianSpeedLimit(ARM, cap))
        motion = time_parameterize(np.array([start, goal]), limits)
        robot.command(motion.command)
        while robot.stopped is None and robot.time < motion.duration + 0.5:
            robot.step()
        if cap is None:
            assert robot.stopped is not None and 'speed monitoring' in robot.stopped
            # the operator's restart: the arm settles, held; the driver comes up where it
            # is, JTC holds there (no command of before survives), joint states flow again
            for _ in range(200):
                robot.step()
            silent = robot.joint_state()
            robot.restart()
            held = robot.engine.q.copy()
            for _ in range(50):
                robot.step()
            assert robot.stopped is None and robot.joint_state().time > silent.time + 2.0
            np.testing.assert_allclose(robot.engine.q, held, atol=1e-3)
            with pytest.raises(RuntimeError, match='nothing to restart'):
                robot.restart()
        else:
            assert robot.stopped is None
            np.testing.assert_allclose(robot.engine.q, goal, atol=0.01)


def test_a_driver_stopped_while_the_arm_presses_on_something_cannot_be_restarted_there():
    # the demo's hook pressed up into its bar (the straight move to the goal), then KUKA's
    # monitoring stops the arm: on its brakes the hook stays pressed, the robot application
    # would not switch to joint impedance with the bar pushing back, so the operator's
    # restart is refused, saying why (the mock's held arm relaxes: the stop's torque counts)
    from probdis_ros.physics.simulated_robot import RESTART_TORQUE

    scene = load_scene('demo_hook')
    robot, _ = build_robot('physics', scene, RobotSettings())
    command_to(robot, scene.goal, 0.2)
    for _ in range(150):
        robot.step()
    assert np.abs(robot.engine.tau_external).max() > 5 * RESTART_TORQUE
    robot.settings = replace(robot.settings, speed_monitor=1e-4)   # any motion trips it
    while robot.stopped is None:
        robot.step()
    for _ in range(200):
        robot.step()
    with pytest.raises(RuntimeError, match='refuses joint impedance: an external torque'):
        robot.restart()
    assert robot.stopped is not None


def test_kukas_collision_detection_stops_the_driver_on_an_external_torque():
    # a safety configuration may stop the arm on its external torque: the driver then goes
    # down as on a speed monitoring stop (the node sees its states stop)
    scene = load_scene('demo_hook')
    robot, _ = build_robot('physics', scene, RobotSettings(collision_torque=15.0))
    command_to(robot, scene.goal, 0.2)
    while robot.stopped is None and robot.time < 10.0:
        robot.step()
    assert robot.stopped is not None and "KUKA's collision detection" in robot.stopped
    assert robot._stop_torque.max() > 15.0
    free, _ = build_robot('physics', free_scene(), RobotSettings(collision_torque=15.0))
    _, duration = command_to(free, free_scene().goal, 0.2)
    while free.time < duration + 0.5:           # free motion stays below it
        free.step()
    assert free.stopped is None


@pytest.mark.parametrize('engine', ['kinematic', 'physics'])
def test_a_command_whose_spline_overflows_is_held_not_a_crash(engine):
    # a finite velocity of 1e308 passes every check and JTC's spline overflows to NaN: the
    # mock raised and its node died, where the driver takes no such target and holds
    robot, _ = build_robot(engine, 'demo_iiwa' if engine == 'kinematic' else free_scene(),
                           RobotSettings())
    held = robot.joint_state().position.copy()
    velocities = np.zeros((2, 7))
    velocities[0, 0] = 1e308
    with np.errstate(over='ignore', invalid='ignore'):
        robot.command(TrajectoryCommand(np.array([0.5, 1.0]), np.vstack([held, held]),
                                        velocities))
        for _ in range(120):
            robot.step()
    assert np.all(np.isfinite(robot.commanded)) and robot.stopped is None
    np.testing.assert_allclose(robot.joint_state().position, held, atol=0.01)


@pytest.mark.parametrize('side', [1, -1])
def test_the_command_guard_stops_the_driver_on_a_command_past_a_limit(side):
    # without ros2_control's joint limiter (enforce_command_limits false) the command
    # reaches the driver's guard, which ends the session; with it (the lbr stack's
    # default) the command is held at the limit and the driver stays up: past the upper
    # limit and past the lower one alike
    limit = ARM.upper[0] if side > 0 else ARM.lower[0]
    for limiter in (False, True):
        robot, _ = build_robot('kinematic', 'demo_iiwa', RobotSettings(limiter=limiter))
        beyond = robot.joint_state().position.copy()
        beyond[0] = limit + side * 0.05
        _, duration = command_to(robot, beyond, 0.5)
        while robot.stopped is None and robot.time < duration + 1.0:
            robot.step()
            assert side * robot.engine.q[0] <= side * limit
        if limiter:
            assert robot.stopped is None and robot.limiter.value[0] == limit
        else:
            assert robot.stopped is not None and 'A1 outside its limits' in robot.stopped


@pytest.mark.parametrize('side', [1, -1])
def test_a_guard_that_holds_sends_the_measured_position_past_a_limit_and_keeps_reporting(side):
    # releases of the lbr stack that log "Overriding invalid command to neutral command."
    # send the measured position in place of a command past a limit, each period, and the
    # driver stays up: the arm stops short of the limit, its states keep coming
    limit = ARM.upper[0] if side > 0 else ARM.lower[0]
    robot, _ = build_robot('physics', free_scene(),
                           RobotSettings(limiter=False, guard_holds=True))
    beyond = robot.joint_state().position.copy()
    beyond[0] = limit + side * 0.05
    _, duration = command_to(robot, beyond, 0.5)
    while robot.time < duration + 1.0:
        robot.step()
        assert side * robot.engine.q[0] <= side * limit
    assert robot.stopped is None and 'A1 outside its limits' in robot.guard_trip
    assert robot.joint_state().time == pytest.approx(robot.time)
    assert robot.guard_trips > 50            # about every period the command stays past it
    assert abs(robot.engine.q[0] - limit) < 0.01


def test_a_holding_guard_tripped_by_a_measured_speed_freezes_the_arm_with_the_driver_up():
    # the long edge at the full velocity limits, whose overshoot stops a driver that throws
    # (above), trips a holding guard instead; its velocity check compares with the last
    # position that passed, which it keeps while it fails, so the arm, held where it is,
    # stays too far from it: the guard trips every period from then on and the arm stays
    # frozen short of the goal, the driver up and reporting, until the driver is restarted
    start, goal = measure.LONG_EDGE
    free = replace(load_scene('demo_hook'), obstacles=(), start=start, goal=goal)
    robot, _ = build_robot('physics', free, RobotSettings(guard_holds=True))
    motion = measure._motion(np.array([start, goal]), 1.0)
    robot.command(motion.command)
    while robot.guard_trips == 0:
        robot.step()
    assert 'above its velocity limit' in robot.guard_trip
    tripped = robot.guard_trips
    for _ in range(100):                     # the arm's damping brings it to rest
        robot.step()
    frozen = robot.engine.q.copy()
    while robot.time < motion.duration + 1.0:
        robot.step()
    assert robot.stopped is None and robot.guard_trips > tripped + 100
    assert robot.joint_state().time == pytest.approx(robot.time)
    np.testing.assert_allclose(robot.engine.q, frozen, atol=1e-3)
    assert np.abs(robot.engine.q - goal).max() > 0.3
    # the operator restarts the driver: its guard starts afresh and the arm moves again
    robot.restart()
    assert robot.guard_trips == 0
    _, duration = command_to(robot, goal, 0.5)
    end = robot.time + duration + 1.0
    while robot.time < end:
        robot.step()
    assert robot.guard_trips == 0
    np.testing.assert_allclose(robot.engine.q, goal, atol=0.01)


def test_the_joint_limiter_ramps_the_step_of_a_new_command_at_the_velocity_limits():
    # the arm stopped dead by an obstacle while JTC's command runs on; a new command from the
    # measured state steps JTC's command back by the gap in one period, and without the
    # limiter the driver's filter passes on a fifth of that per period, above the limits
    for limiter in (False, True):
        robot, _ = build_robot('kinematic', 'demo_iiwa', RobotSettings(limiter=limiter))
        start = robot.joint_state().position.copy()
        far = start.copy()
        far[0] = 2.0
        command_to(robot, far, 0.5)
        for _ in range(150):
            robot.step()
        gap = np.abs(robot.commanded - robot.engine.q).sum()
        assert gap > 0.3                                # blocked: the command ran on
        command_to(robot, start, 0.5)
        for _ in range(30):
            robot.step()
        assert robot.command_speed_peak > 5.0           # JTC's own command stepped back
        if limiter:
            assert robot.sent_speed_peak <= 1.0 + 1e-9
        else:
            assert robot.sent_speed_peak > 1.5


def test_the_faults_reach_the_physics_arm_and_the_driver_that_build_robot_makes():
    # probdis experiment robot --fault NAME=VALUE: each fault must reach MuJoCo's model or
    # the driver, not leave the ideal mock running under its name
    from probdis_ros.physics.simulated_robot import with_faults

    settings, physics = with_faults({'armature': 0.3, 'stiffness': 150.0, 'joint_friction': 2.0,
                                     'damping_ratio': 0.5, 'noise': 0.001})
    robot, _ = build_robot('physics', free_scene(), settings, physics)
    model = robot.engine.model
    np.testing.assert_array_equal(model.dof_armature[:7], 0.3)
    np.testing.assert_array_equal(model.dof_frictionloss[:7], 2.0)
    np.testing.assert_array_equal(model.actuator_gainprm[:, 0], 150.0)
    assert robot.engine.settings.damping_ratio == 0.5 and robot.settings.noise == 0.001


def test_kukas_collision_detection_stops_on_one_joints_torque_not_on_their_sum():
    # the safety configuration's limit is per joint: 10 Nm on each of seven joints stays
    # under 15 Nm; 16 Nm on one of them stops the driver, naming it
    for pushed, stops in ((np.full(7, 10.0), False), (np.eye(7)[3] * -16.0, True)):
        robot, _ = build_robot('kinematic', 'demo_iiwa', RobotSettings(collision_torque=15.0))
        robot.engine.tau_external = pushed
        robot.step()
        assert (robot.stopped is not None) == stops
    assert 'external torque of 16.0 Nm at A4' in robot.stopped


def test_the_kinematic_arm_stops_at_the_table_before_an_obstacle_and_may_rise_from_below():
    # the compliant arm of the kinematic engine: the first contact along the path stops it,
    # the table's or an obstacle's; an arm that starts below the table top may rise
    from probdis_ros.model.table import ROBOT_TABLE
    from probdis_ros.sim.compliant_arm import CompliantArm
    from probdis_ros.sim.obstacles import Obstacle

    arm = ARM.on_table(ROBOT_TABLE)
    high = np.array([0.0, 0.3, 0.0, -1.0, 0.0, 0.8, 0.0])
    low = np.array([0.0, 1.9, 0.0, -0.4, 0.0, 0.8, 0.0])
    table_only = CompliantArm(arm, []).execute(np.array([high, low]))
    assert table_only.blocked and arm.lowest_heights(low)[0] < ROBOT_TABLE.height
    beyond = ARM.fk(low[None]).positions[0]          # a ball past the table's contact
    both = CompliantArm(arm, [Obstacle('ball', beyond, 0.05)]).execute(np.array([high, low]))
    np.testing.assert_array_equal(both.config, table_only.config)
    rise = CompliantArm(arm, []).execute(np.array([low, high]))
    assert not rise.blocked
