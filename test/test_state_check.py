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

"""Joint states checked against the arm (no rclpy): what is refused, what is taken."""

import re

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.state_check import (
    BadJointStateError,
    LIMIT_TOLERANCE,
    RESTART_SPAN,
    SILENCE,
    StateCheck,
)
import pytest

ARM = iiwa_arm()
NAMES = [f'lbr_A{i}' for i in range(1, 8)]
Q = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])


def gate() -> StateCheck:
    return StateCheck(NAMES, ARM.lower, ARM.upper, ARM.velocity_limits)


@pytest.mark.parametrize('names, positions, reason', [
    (NAMES, [*Q[:6], 3.1], 'A7 at 3.1 rad is outside its limits'),
    (NAMES, [1e6, *Q[1:]], 'A1 at 1e+06 rad is outside'),
    ([*NAMES, 'lbr_A1'], [*Q, 0.0], 'lbr_A1 is named twice'),
    (NAMES[:6], Q[:6], 'missing joints lbr_A7'),
    # a driver of another name space: what it names tells the user what to set
    ([f'iiwa_joint_{i}' for i in range(1, 8)], Q, 'it names iiwa_joint_1, iiwa_joint_2'),
    (NAMES, [np.nan, *Q[1:]], 'non-finite'),
])
def test_states_that_cannot_be_the_arms_are_refused_with_the_reason(names, positions, reason):
    check = gate()
    with pytest.raises(BadJointStateError, match=re.escape(reason)):
        check.check(1.0, names, positions)
    assert check.refused == 1 and reason in check.refused_within(1.5, 1.0)
    assert check.refused_within(2.5, 1.0) == ''


def test_a_position_within_the_tolerance_past_a_limit_is_clamped():
    q = Q.copy()
    q[1] = ARM.upper[1] + 0.5 * LIMIT_TOLERANCE
    taken, _ = gate().check(1.0, NAMES, q)
    assert taken[1] == ARM.upper[1]


def test_time_going_backwards_and_repeated_or_missing_stamps_are_refused():
    check = gate()
    check.check(1.0, NAMES, Q, stamp=100.0)
    for stamp, reason in ((99.0, 'older than the last'), (100.0, 'repeats the stamp'),
                          (0.0, 'unstamped after stamped')):
        with pytest.raises(BadJointStateError, match=reason):
            check.check(1.01, NAMES, Q, stamp=stamp)
    check.check(1.02, NAMES, Q, stamp=100.02)
    with pytest.raises(BadJointStateError, match='time went backwards'):
        check.check(1.0, NAMES, Q, stamp=100.03)
    # this host's clock stepped back: the states after it start a new stream (refused until
    # the clock caught up again, a start was refused for as long as the step)
    check.check(1.01, NAMES, Q, stamp=100.04)
    assert check.streams == 2 and check.measured_at(1.01, 100.04) == pytest.approx(1.01)


def test_a_jump_is_refused_and_a_restarted_stream_is_taken():
    check = gate()
    check.check(1.0, NAMES, Q)
    old = Q.copy()
    old[0] += 0.3
    with pytest.raises(BadJointStateError, match=re.escape('A1 jumped 0.300 rad')):
        check.check(1.01, NAMES, old)
    # a joint may move at its velocity limit (and a half) between states
    fast = Q.copy()
    fast[0] += 1.4 * ARM.velocity_limits[0] * 0.2
    check.check(1.2, NAMES, fast)
    # after a silence the stream is new: its first state is taken wherever it is
    check.check(1.2 + SILENCE + 0.1, NAMES, old, stamp=5.0)


def test_a_forward_step_of_the_hosts_clock_is_refused_and_the_stream_starts_afresh():
    # the stamps show the arm's states 10 ms apart, this host received them 2 s apart: taken
    # as a new stream dated now, the run saw its command 2 s ahead of the arm and learned a
    # failure (a restarted driver's stamps moved on with the silence and are taken)
    check = gate()
    check.check(1.0, NAMES, Q, stamp=100.0)
    with pytest.raises(BadJointStateError,
                       match=r'arrived 2\.010 s .* stamped 0\.010 s .* clock jumped'):
        check.check(3.01, NAMES, Q, stamp=100.01)
    assert check.refused == 1
    check.check(3.02, NAMES, Q, stamp=100.02)
    assert check.measured_at(3.02, 100.02) == pytest.approx(3.02)
    check.check(3.02 + SILENCE + 0.5, NAMES, Q, stamp=100.02 + SILENCE + 0.5)
    assert check.refused == 1 and check.streams == 3


def test_a_stream_begun_anew_takes_stamps_stepped_back_with_this_hosts_clock():
    # a driver on this computer stamps its states by a clock that stepped 0.3 s back, while
    # the planner's time goes on without the step: without a new stream its states were
    # refused as older than the last for 0.3 s, then dated 0.3 s early for minutes
    kept, restarted = gate(), gate()
    for check in (kept, restarted):
        for k in range(100):
            check.check(10.0005 + 0.01 * k, NAMES, Q, stamp=10.0 + 0.01 * k)
    restarted.restart(11.0, "this host's clock stepped -0.300 s: a new stream")
    assert 'stepped -0.300 s' in restarted.refused_within(11.5, 1.0)
    with pytest.raises(BadJointStateError, match='older than the last'):
        kept.check(11.0105, NAMES, Q, stamp=10.71)
    for k in range(1, 50):
        restarted.check(11.0005 + 0.01 * k, NAMES, Q, stamp=10.7 + 0.01 * k)
    assert restarted.measured_at(11.4905, 11.19) == pytest.approx(11.4905)
    assert restarted.refused == 1


@pytest.mark.parametrize('step', [-0.3, 0.8])
def test_states_stamped_before_the_step_that_began_a_stream_do_not_hold_it(step):
    # a driver on this computer, 1 kHz: the step is seen while ten states stamped before
    # it still wait in the queue; they begin the new stream, and the states stamped after
    # the step were then refused (0.3 s back: as older than the last, for 0.3 s; 0.8 s
    # ahead, beyond ``late``: as stamped ahead of the stream)
    check = StateCheck(NAMES, ARM.lower, ARM.upper, ARM.velocity_limits, late=0.5)
    for k in range(100):
        check.check(10.0005 + 0.001 * k, NAMES, Q, stamp=10.0 + 0.001 * k)
    check.restart(10.1, "this host's clock stepped: a new stream")
    for k in range(100, 110):                        # taken after the restart
        check.check(10.1005 + 0.0001 * (k - 99), NAMES, Q, stamp=10.0 + 0.001 * k)
    for k in range(110, 700):
        check.check(10.0005 + 0.001 * k, NAMES, Q, stamp=10.0 + step + 0.001 * k)
    assert check.refused == 1
    assert check.measured_at(10.6995, 10.699 + step) == pytest.approx(10.6995)


def test_a_break_in_the_stamps_begins_the_stream_again_for_as_long_as_restart_span():
    # queued states stamped before the step may come in for a while (a busy executor): a
    # break 0.3 s after the restart still begins the stream again; after RESTART_SPAN it is
    # the arm's stream misbehaving
    for after, refused in ((0.3, 1), (RESTART_SPAN + 0.1, 2)):
        check = StateCheck(NAMES, ARM.lower, ARM.upper, ARM.velocity_limits, late=0.5)
        for k in range(100):
            check.check(10.0005 + 0.001 * k, NAMES, Q, stamp=10.0 + 0.001 * k)
        check.restart(10.1, "this host's clock stepped -0.300 s: a new stream")
        now = 10.1005
        check.check(now, NAMES, Q, stamp=10.1)           # stamped before the step
        while now < 10.1 + after:
            now += 0.001
            check.check(now, NAMES, Q, stamp=now - 0.0005 + 0.0001)
        stepped = (now + 0.001, NAMES, Q)                  # stamped by the stepped clock
        if refused == 1:
            check.check(*stepped, stamp=now - 0.3)
        else:
            with pytest.raises(BadJointStateError, match='older than the last'):
                check.check(*stepped, stamp=now - 0.3)
        assert check.refused == refused


def test_noise_of_0_005_rad_at_1_khz_is_never_refused():
    check = gate()
    rng = np.random.default_rng(0)
    for k in range(5000):
        t = k * 0.001
        q = Q + np.sin(t) * 0.2 + rng.normal(0.0, 0.005, 7)
        check.check(t, NAMES, q, stamp=100.0 + t)
    assert check.refused == 0


@pytest.mark.parametrize('velocities, reason', [
    ([3.0, *np.zeros(6)], 'A1 velocity 3 rad/s is beyond 1.5 x its limit'),
    ([0.0, 0.0, 0.0, -1e12, 0.0, 0.0, 0.0], 'A4 velocity -1e+12 rad/s'),
    (np.zeros(5), '7 names but 5 velocities'),
    ([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, np.nan], 'non-finite velocities'),
])
def test_a_velocity_the_arm_cannot_have_is_refused(velocities, reason):
    # every stop and every path starts from the measured velocity: a glitch there would be
    # commanded (a stop from 3 rad/s ran A1 at 3 rad/s, from 1e12 raised inside the stop)
    check = gate()
    with pytest.raises(BadJointStateError, match=re.escape(reason)):
        check.check(1.0, NAMES, Q, velocities)
    assert check.refused == 1


def test_velocities_within_the_limits_or_none_are_taken():
    check = gate()
    fast = 1.4 * ARM.velocity_limits * np.where(np.arange(7) % 2, 1.0, -1.0)
    _, v = check.check(1.0, NAMES, Q, fast)
    assert np.array_equal(v, fast)
    _, v = check.check(1.01, NAMES, Q, [])
    assert v is None
    # the lbr stack's hardware interface reports NaN velocities until its second FRI sample
    _, v = check.check(1.02, NAMES, Q, [np.nan] * 7)
    assert v is None and check.refused == 0


def test_a_state_stamped_ahead_of_its_stream_is_refused():
    # it would date the stream ahead and let the jump check take any step over the
    # stamps' gap: a configuration 3 s ahead, 5 rad away, was taken, and the arm's own
    # states then refused as older
    check = StateCheck(NAMES, ARM.lower, ARM.upper, ARM.velocity_limits, late=0.1)
    for k in range(10):
        check.check(1.0 + 0.01 * k, NAMES, Q, stamp=50.0 + 0.01 * k)
    far = Q + 0.7
    with pytest.raises(BadJointStateError, match='ahead of its stream'):
        check.check(1.1, NAMES, far, stamp=53.1)
    check.check(1.11, NAMES, Q, stamp=50.11)      # the arm's own stream goes on


def test_the_clock_offset_is_the_quickest_delivery_and_zero_until_a_stamped_state():
    # the arm's clock 3 s behind the receiver's, deliveries of 1-4 ms: a message stamped for
    # the arm's controller moves by the offset (early by the quickest delivery, 1 ms)
    check = gate()
    check.check(10.0, NAMES, Q)                   # unstamped: nothing to tell the offset by
    assert check.clock_offset == 0.0
    check = gate()
    for k, delivery in enumerate([0.004, 0.001, 0.003]):
        check.check(10.0 + 0.01 * k + delivery, NAMES, Q, stamp=7.0 + 0.01 * k)
    assert check.clock_offset == pytest.approx(3.001)
    assert check.measured_at(10.033, 7.03) == pytest.approx(10.031)
