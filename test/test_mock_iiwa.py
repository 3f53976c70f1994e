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
The mock iiwa node as the arm's driver and JTC: its settings, clock, catch-up and states.

Its nodes are never spun: the test calls its callbacks on a wall clock moved by hand, so
what it runs and publishes is exact whatever the machine's load.
"""

from conftest import next_domain
import numpy as np
from probdis_ros.motion.jtc import CONTROLLER_RATE, DRIVER_TORQUE_TAU, TrajectoryCommand
from probdis_ros.ros import JOINT_NAMES, mock_iiwa_node
from probdis_ros.ros.messages import trajectory_msg
from probdis_ros.ros.mock_iiwa_node import CATCH_UP, MockIiwa
import pytest
import rclpy
from rclpy.context import Context
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

pytestmark = pytest.mark.ros
T0 = 1.8e9        # the fake wall clock's date at the start of each test [s]


class FakeClock:
    """The mock module's ``time``: a wall clock that moves only when told."""

    def __init__(self) -> None:
        self.now = 0.0

    def monotonic(self) -> float:
        return 500.0 + self.now

    def time(self) -> float:
        return T0 + self.now


class Recorder:
    """Stands in for a publisher or a logger: keeps what it was given."""

    def __init__(self) -> None:
        self.messages, self.errors = [], []

    def publish(self, msg) -> None:
        self.messages.append(msg)

    def error(self, text: str, **_) -> None:
        self.errors.append(text)

    def info(self, text: str, **_) -> None:
        pass

    warning = info


@pytest.fixture
def clock(monkeypatch) -> FakeClock:
    fake = FakeClock()
    monkeypatch.setattr(mock_iiwa_node, 'time', fake)
    return fake


@pytest.fixture
def make():
    """Make mock nodes (kinematic, demo_iiwa unless told) in a context of their own."""
    context = Context()
    rclpy.init(context=context, domain_id=next_domain())
    made = []

    def node(**params) -> MockIiwa:
        params = {'engine': 'kinematic', 'scenario': 'demo_iiwa', **params}
        made.append(MockIiwa(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in params.items()]))
        return made[-1]
    yield node
    for made_node in made:
        made_node.destroy_node()
    context.try_shutdown()


def stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_the_mock_hands_the_driver_and_controller_settings_to_its_arm(make):
    # each is a setting of the real arm's stack that the planner must cope with: one the
    # node dropped ran every test of it against the default instead
    arm = make()
    settings = arm.robot.settings
    assert settings.period == 1.0 / CONTROLLER_RATE     # the lbr stack's 100 Hz
    assert (settings.echo, settings.limiter, settings.jtc_start) == (False, True, 'measured')
    assert not settings.guard_holds
    assert settings.torque_tau == DRIVER_TORQUE_TAU and arm.robot.limiter is not None
    arm = make(rate=250.0, echo=True, seed=5, enforce_command_limits=False,
               measured_torque_tau=0.2, command_latency=0.03, latency=0.01,
               collision_torque=40.0, speed_monitor=0.3, interpolate_from_desired_state=True,
               guard_holds=True)
    settings = arm.robot.settings
    assert settings.guard_holds
    assert settings.period == 1.0 / 250.0 and settings.seed == 5
    assert (settings.echo, settings.limiter, settings.jtc_start) == (True, False, 'desired')
    assert arm.robot.limiter is None
    assert (settings.torque_tau, settings.command_latency, settings.latency) == (0.2, 0.03, 0.01)
    assert (settings.collision_torque, settings.speed_monitor) == (40.0, 0.3)


def test_the_mock_refuses_settings_out_of_range_and_changes_after_start_up(make):
    # a value beyond its range ran as given (10 cm of noise and more); one set while
    # running was taken and then ignored: only the arm's clock may be set then
    with pytest.raises(InvalidParameterValueException):
        make(noise=0.5)
    with pytest.raises(InvalidParameterValueException):
        make(latency=-0.1)
    arm = make()
    result, = arm.set_parameters([Parameter('noise', value=0.01)])
    assert not result.successful and arm.robot.settings.noise == 0.0


def test_the_mock_listens_and_publishes_on_the_topics_it_is_given(make):
    # a driver of another robot_name or namespace: states to, commands from its topics
    arm = make(joint_states_topic='/cell/joint_states',
               trajectory_topic='/cell/jtc/joint_trajectory')
    assert arm.pub.topic_name == '/cell/joint_states'
    assert [s.topic_name for s in arm.subscriptions] == ['/cell/jtc/joint_trajectory']


@pytest.mark.parametrize('params, most', [
    ({}, 0.01),                                     # wall time: one period
    ({'rate': 1000.0}, 0.001),
    ({'sim_time': True, 'real_time_factor': 0.5}, 0.02),     # half the wall clock's speed
    ({'sim_time': True, 'real_time_factor': 4.0}, 0.0025),
    ({'sim_time': True, 'real_time_factor': 0.0}, 0.001),    # as fast as it can
])
def test_the_mock_ticks_at_its_rate_and_on_simulated_time_at_its_speed(make, params, most):
    # a tick of two periods published half the joint states a driver does; on simulated
    # time one period a tick, so the timer's period sets the speed over the wall clock
    timer, = make(**params).timers
    if params.get('real_time_factor') == 0.0:
        assert timer.timer_period_ns <= most * 1e9
    else:
        assert timer.timer_period_ns == round(most * 1e9)


def test_the_mock_runs_the_periods_the_wall_clock_owes_and_no_more(make, clock):
    arm = make()
    arm.pub = published = Recorder()
    clock.now += 0.3          # start-up work between its construction and its first tick
    arm._tick()
    # the arm's time (and its stamps' date) start at the first tick, with nothing yet due
    assert arm.robot.time == 0.0 and not published.messages
    assert arm.epoch == pytest.approx(T0 + 0.3, abs=1e-6)
    clock.now += 0.035
    arm._tick()
    assert arm.robot.time == pytest.approx(0.03)       # the whole periods owed, not ahead
    assert len(published.messages) == 1                 # the newest state, once a tick
    assert stamp(published.messages[-1]) == pytest.approx(T0 + 0.3 + 0.03, abs=1e-6)
    clock.now += 0.004        # less than a period more: nothing is due
    arm._tick()
    assert arm.robot.time == pytest.approx(0.03) and len(published.messages) == 1
    clock.now += 1.0          # a starved mock catches up at most CATCH_UP at once
    arm._tick()
    assert arm.robot.time == pytest.approx(0.03 + CATCH_UP)


def test_a_starved_1khz_mock_catches_up_every_period_it_owes(make, clock):
    # capped at ten periods a tick, a 1 kHz mock ticking every 20 ms ran at half speed
    arm = make(rate=1000.0)
    arm._tick()
    clock.now += 0.05
    arm._tick()
    assert arm.robot.time == pytest.approx(0.05)


def test_the_joint_states_are_stamped_when_measured_with_the_fields_asked_for(make, clock):
    # with latency the driver reports a state measured that long ago, stamped then; its
    # positions are the reported ones (encoder noise here), not the simulated arm's truth
    arm = make(latency=0.05, noise=0.001, publish_velocities=False, joint_names=[
        f'iiwa_A{i}' for i in range(1, 8)])
    arm.pub = published = Recorder()
    arm._tick()
    clock.now += 0.1
    arm._tick()
    msg, = published.messages
    assert stamp(msg) == pytest.approx(T0 + 0.05, abs=1e-6)
    np.testing.assert_array_equal(msg.position, arm.robot.joint_state().position)
    assert np.abs(np.array(msg.position) - arm.q).max() > 1e-4
    assert list(msg.name) == [f'iiwa_A{i}' for i in range(1, 8)]
    assert list(msg.velocity) == [] and list(msg.effort) == []    # the kinematic arm: none
    assert len(make().robot.joint_state().velocity) == 7
    arm = make()
    arm.pub = published = Recorder()
    arm._tick()
    clock.now += 0.01
    arm._tick()
    assert len(published.messages[-1].velocity) == 7 and list(published.messages[-1].name) == \
        list(JOINT_NAMES)


def test_a_step_of_the_arms_clock_moves_its_stamps_by_the_step(make, clock):
    # an NTP step on the arm's computer: set twice, the second moved the clock by its new
    # value instead of the difference
    arm = make(clock_offset=2.0)
    start = arm.epoch
    assert start == pytest.approx(T0 + 2.0, abs=1e-6)
    for offset in (5.0, -1.0):
        result, = arm.set_parameters([Parameter('clock_offset', value=offset)])
        assert result.successful
        assert arm.epoch == pytest.approx(start + offset - 2.0, abs=1e-6)


def test_a_command_stamped_to_end_in_the_past_is_refused_and_the_arm_holds(make, clock):
    # JTC refuses it; taken, the mock's arm ran it (or failed in the callback)
    arm = make()
    arm.get_logger = lambda: logger
    logger = Recorder()
    arm._tick()
    clock.now += 0.5
    arm._tick()
    start = arm.q.copy()
    msg = trajectory_msg(TrajectoryCommand(np.array([1.0]), (start + 0.2)[None]),
                         list(JOINT_NAMES))
    msg.header.stamp.sec = int(T0 - 10.0)
    arm._on_trajectory(msg)
    assert 'ends in the past' in logger.errors[-1]
    for _ in range(20):
        clock.now += 0.1
        arm._tick()
    np.testing.assert_array_equal(arm.q, start)


def test_a_stopped_driver_publishes_nothing_until_restarted_and_says_so_each_time(make, clock):
    arm = make(speed_monitor=0.01)
    arm.pub = published = Recorder()
    arm.get_logger = lambda: logger
    logger = Recorder()
    arm._tick()

    def move_until_stopped():
        start = arm.q.copy()
        arm._on_trajectory(trajectory_msg(TrajectoryCommand(np.array([1.0]), (
            start + 0.2)[None]), list(JOINT_NAMES)))
        for _ in range(20):
            clock.now += 0.05
            arm._tick()
            if arm.robot.stopped is not None:
                return
        raise AssertionError('the speed monitoring never stopped the arm')
    move_until_stopped()
    count = len(published.messages)
    for _ in range(3):
        clock.now += 0.05
        arm._tick()
    assert len(published.messages) == count      # no state while the driver is down
    assert len(logger.errors) == 1 and 'speed monitoring' in logger.errors[0]
    response = arm._on_restart_driver(Trigger.Request(), Trigger.Response())
    assert response.success
    clock.now += 0.05
    arm._tick()
    assert len(published.messages) == count + 1
    move_until_stopped()               # stopped again: the operator hears of it again
    assert len(logger.errors) == 2
