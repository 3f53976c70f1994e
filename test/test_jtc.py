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


"""joint_trajectory_controller's interpolation rules on hand-computed cases."""

import numpy as np
from probdis_ros.motion.jtc import (
    CommandLimiter,
    ends_in_the_past,
    FirstOrderFilter,
    JtcTrajectory,
    moved_onto_clock,
    TrajectoryCommand,
    TrajectoryController,
)
import pytest


def one_joint(times, positions, velocities=None, accelerations=None, stamp=0.0):
    def column(values):
        if values is None:
            return None
        return np.array([[np.nan] if v is None else [v] for v in values], dtype=float)
    return TrajectoryCommand(np.array(times, dtype=float), np.array(positions, float)[:, None],
                             column(velocities), column(accelerations), stamp)


def test_positions_only_is_linear_with_a_velocity_step_at_each_point():
    traj = JtcTrajectory(one_joint([1.0, 2.0], [1.0, 3.0]), np.zeros(1), np.zeros(1))
    q, v, a = traj.sample(0.25)
    assert q == pytest.approx([0.25]) and v == pytest.approx([1.0]) and a == pytest.approx([0])
    q, v, _ = traj.sample(1.5)
    assert q == pytest.approx([2.0]) and v == pytest.approx([2.0])   # the step: 1 -> 2 rad/s


def test_peak_speed_is_the_points_velocities_or_the_slopes_into_them():
    # the ceilings' speed allowance: the largest speed at the points within a window
    lines = JtcTrajectory(one_joint([1.0, 2.0], [1.0, 3.0]), np.zeros(1), np.zeros(1))
    assert lines.peak_speed(0.5, 1.5) == pytest.approx([1.0])     # into the first point
    assert lines.peak_speed(0.5, 2.0) == pytest.approx([2.0])
    assert lines.peak_speed(2.0, 3.0) == pytest.approx([0.0])     # no point within
    given = JtcTrajectory(one_joint([1.0, 2.0], [1.0, 3.0], [-0.5, None]), np.zeros(1),
                          np.zeros(1))
    assert given.peak_speed(0.5, 1.5) == pytest.approx([0.5])
    assert given.peak_speed(1.5, 2.5) == pytest.approx([2.0])


def test_velocities_at_both_ends_make_a_cubic():
    # from rest at 0 to rest at 1 in 1 s: q = 3 t^2 - 2 t^3
    traj = JtcTrajectory(one_joint([1.0], [1.0], [0.0]), np.zeros(1), np.zeros(1))
    q, v, a = traj.sample(0.25)
    assert q == pytest.approx([0.15625])
    assert v == pytest.approx([6 * 0.25 - 6 * 0.25 ** 2])
    assert a == pytest.approx([6 - 12 * 0.25])


def test_a_one_point_command_with_a_final_velocity_runs_as_a_cubic_not_a_line():
    # the hold the planner used to send: its peak speed is 1.5x the line's
    traj = JtcTrajectory(one_joint([1.0], [1.0], [0.0]), np.zeros(1), np.zeros(1))
    assert traj.sample(0.5)[1] == pytest.approx([1.5])


def test_accelerations_at_both_ends_make_a_quintic():
    # between two points at rest: minimum jerk 10 t^3 - 15 t^4 + 6 t^5
    cmd = one_joint([0.5, 1.5], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0])
    traj = JtcTrajectory(cmd, np.zeros(1), np.zeros(1))
    q, v, _ = traj.sample(0.75)
    assert q == pytest.approx([0.103515625])
    assert v == pytest.approx([30 * 0.25 ** 2 - 60 * 0.25 ** 3 + 30 * 0.25 ** 4])
    assert traj.sample(1.0)[0] == pytest.approx([0.5])


def test_the_first_segment_is_at_most_cubic_since_the_measured_state_has_no_accelerations():
    cmd = one_joint([1.0], [1.0], [0.0], [0.0])
    traj = JtcTrajectory(cmd, np.zeros(1), np.zeros(1))
    assert traj.sample(0.25)[0] == pytest.approx([0.15625])     # the cubic, not the quintic


def test_a_first_point_without_velocities_makes_the_first_segment_linear():
    traj = JtcTrajectory(one_joint([2.0], [1.0]), np.zeros(1), np.array([5.0]))
    assert traj.sample(1.0)[0] == pytest.approx([0.5])
    assert traj.sample(1.0)[1] == pytest.approx([0.5])


def test_mixed_fields_are_taken_point_by_point():
    cmd = one_joint([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [1.0, None, 0.0])
    traj = JtcTrajectory(cmd, np.zeros(1), np.zeros(1))
    # segment 1 -> 2 lacks a velocity at its end: linear; 0 -> 1 has both: cubic
    assert traj.sample(1.5)[0] == pytest.approx([1.5])
    q = traj.sample(0.5)[0]
    p0, v0, p1, v1, d, t = 0.0, 0.0, 1.0, 1.0, 1.0, 0.5
    c2 = (-3 * p0 + 3 * p1 - 2 * v0 * d - v1 * d) / d ** 2
    c3 = (2 * p0 - 2 * p1 + v0 * d + v1 * d) / d ** 3
    assert q == pytest.approx([c2 * t ** 2 + c3 * t ** 3])


def test_after_the_last_point_the_controller_holds_it():
    traj = JtcTrajectory(one_joint([1.0], [1.0]), np.zeros(1), np.zeros(1))
    q, v, a = traj.sample(7.0)
    assert q == pytest.approx([1.0]) and v == pytest.approx([0]) and a == pytest.approx([0])
    assert traj.duration == 1.0 and traj.segment_at(0.5) == 0 and traj.segment_at(9) == 0


def test_the_command_stands_still_from_the_first_point_of_its_closing_hold():
    # a stamped stop ends with a hold to STAMP_HORIZON: the command stands still from the
    # stop's end, not the hold's, and a point passed on the way (at rest or not) is no end
    stop = one_joint([0.0, 0.1, 0.2, 0.3, 1.0], [0.0, 0.1, 0.2, 0.2, 0.2],
                     [0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0], stamp=5.0)
    assert JtcTrajectory(stop, np.zeros(1), taken_at=5.0).still_from == pytest.approx(0.2)
    assert JtcTrajectory(stop, np.zeros(1), taken_at=4.9).still_from == pytest.approx(0.3)
    through = one_joint([0.1, 0.2, 0.3], [0.2, 0.1, 0.2], [0.0, 0.0, 0.0])
    assert JtcTrajectory(through, np.zeros(1)).still_from == pytest.approx(0.3)
    creeping = one_joint([0.1, 0.2], [0.2, 0.2], [0.01, 0.0])
    assert JtcTrajectory(creeping, np.zeros(1)).still_from == pytest.approx(0.2)
    hold = one_joint([0.1, 0.2], [0.2, 0.2])          # positions only: linear, no motion
    assert JtcTrajectory(hold, np.zeros(1)).still_from == pytest.approx(0.1)


def test_segments_count_from_the_measured_start():
    traj = JtcTrajectory(one_joint([1.0, 2.0, 3.0], [1.0, 2.0, 3.0]), np.zeros(1))
    assert [traj.segment_at(t) for t in (0.0, 0.99, 1.0, 2.5, 3.5)] == [0, 0, 1, 2, 2]


def test_a_stamp_in_the_future_delays_the_start():
    traj = JtcTrajectory(one_joint([1.0], [1.0], stamp=10.5), np.zeros(1), taken_at=10.0)
    assert traj.duration == pytest.approx(1.5)
    assert traj.sample(0.75)[0] == pytest.approx([0.5])


def test_the_controller_commands_one_period_ahead_and_a_new_message_replaces_the_old():
    jtc = TrajectoryController(period=0.01)
    assert jtc.update(0.0, np.array([0.2])) == pytest.approx([0.2])        # holds at start
    jtc.receive(one_joint([1.0], [1.0]))
    assert jtc.update(1.0, np.array([0.0]), np.zeros(1)) == pytest.approx([0.01])
    assert jtc.update(1.5, np.array([0.3])) == pytest.approx([0.51])
    # replaced mid-motion: the new trajectory starts from the measured 0.3, not from 0.51
    jtc.receive(one_joint([1.0], [-0.7]))
    assert jtc.update(1.6, np.array([0.3]), np.zeros(1)) == pytest.approx([0.3 - 0.01])
    assert jtc.update(5.0, np.array([0.0])) == pytest.approx([-0.7])       # holds the end


def test_a_stamped_message_that_ends_before_it_is_taken_is_dropped_as_jtc_does():
    # JTC's validation: a stamped message whose last point is due before now "ends in the
    # past" and is refused; the running command goes on
    jtc = TrajectoryController(period=0.01)
    jtc.update(0.0, np.array([0.0]))
    jtc.receive(one_joint([1.0], [1.0]))
    jtc.update(1.0, np.array([0.0]), np.zeros(1))
    jtc.receive(one_joint([0.1], [0.2], stamp=1.2))            # due at 1.3, taken at 1.5
    assert jtc.update(1.5, np.array([0.5])) == pytest.approx([0.51])   # the old one runs on
    jtc.receive(one_joint([1.0], [0.2], stamp=1.2))            # due at 2.2: taken
    assert jtc.update(1.6, np.array([0.5])) != pytest.approx([0.61])
    assert jtc.update(3.0, np.array([0.2])) == pytest.approx([0.2])


def test_a_stamp_moved_onto_a_clock_that_began_later_stays_a_stamp():
    # the mock's arm and a replay count from their own start, and a stamp of 0 is none: a
    # message dated 10 s before that start ran as if taken now (JTC refuses it: it ends in
    # the past), and one dated 0.5 s before ran late by 0.5 s
    two_seconds = one_joint([1.0, 2.0], [1.0, 3.0], [1.0, 0.0], [0.0, 0.0], stamp=100.0)
    assert moved_onto_clock(two_seconds, -110.0) is None
    assert moved_onto_clock(two_seconds, -90.0).stamp == pytest.approx(10.0)
    assert moved_onto_clock(one_joint([1.0], [1.0]), -110.0).stamp == 0.0    # unstamped
    for before in (0.5, 1.5):           # the zero before the first point, then on a segment
        moved = moved_onto_clock(two_seconds, -100.0 - before)
        assert 0 < moved.stamp <= 1e-9 and not ends_in_the_past(moved, 0.3)
        taken = JtcTrajectory(moved, np.zeros(1), np.zeros(1), 0.3)
        whole = JtcTrajectory(two_seconds, np.zeros(1), np.zeros(1), 100.0 + before + 0.3)
        for t in (0.0, 0.1, 0.45, 1.0, 3.0):
            for mine, jtcs in zip(taken.sample(t), whole.sample(t)):
                assert mine == pytest.approx(jtcs, abs=1e-7)
    assert len(moved_onto_clock(two_seconds, -101.5).times) == 2    # the first point gone


def test_refuses_times_that_do_not_increase_and_shapes_that_do_not_match():
    with pytest.raises(ValueError, match='increasing'):
        one_joint([1.0, 1.0], [0.0, 1.0])
    for bad in (np.nan, np.inf):           # NaN compares false: it passed the order check
        with pytest.raises(ValueError, match='finite'):
            one_joint([1.0, bad], [0.0, 1.0])
    with pytest.raises(ValueError, match='shape'):
        TrajectoryCommand(np.array([1.0]), np.zeros((1, 2)), np.zeros((1, 3)))


def test_the_driver_filter_is_first_order_with_its_time_constant():
    f = FirstOrderFilter(tau=0.04, period=0.01)
    f.reset(np.zeros(1))
    for _ in range(4):
        out = f(np.ones(1))
    assert out == pytest.approx([1 - np.exp(-0.04 / 0.04)])
    assert FirstOrderFilter(tau=0.0)(np.array([3.0])) == pytest.approx([3.0])


def test_the_joint_limiter_ramps_a_step_at_the_velocity_limit_and_keeps_the_limits():
    # ros2_control's enforce_command_limits: within v_max * period of the last limited
    # command and within the position limits; a command within them passes unchanged
    limiter = CommandLimiter(np.array([1.0, 2.0]), np.array([-1.0, -1.0]),
                             np.array([1.0, 1.0]), period=0.01)
    limiter.reset(np.zeros(2))
    assert limiter(np.array([0.005, -0.01])) == pytest.approx([0.005, -0.01])
    out = [limiter(np.array([0.5, 3.0])) for _ in range(3)]
    assert [o[0] for o in out] == pytest.approx([0.015, 0.025, 0.035])
    assert [o[1] for o in out] == pytest.approx([0.01, 0.03, 0.05])
    for _ in range(100):
        last = limiter(np.array([0.5, 3.0]))
    assert last == pytest.approx([0.5, 1.0])       # arrived, and held at the upper limit
    for _ in range(200):
        last = limiter(np.array([-3.0, -3.0]))
    assert last == pytest.approx([-1.0, -1.0])     # and at the lower ones


def test_a_desired_start_continues_the_last_command_where_a_measured_start_steps_back():
    # commanded at 1 rad/s, the arm 0.2 rad behind at 0.5 s; a new message: at 2.0 in 0.5 s
    ramp = one_joint([1.0], [1.0], [1.0], [0.0])
    hold = one_joint([0.5], [2.0], [0.0], [0.0])
    steps = {}
    for start in ('measured', 'desired'):
        jtc = TrajectoryController(0.01, start)
        jtc.receive(ramp)
        commands = [jtc.update(0.01 * k, np.zeros(1), np.ones(1)) for k in range(50)]
        jtc.receive(hold)
        commands.append(jtc.update(0.5, np.array([0.3]), np.ones(1)))
        steps[start] = float(np.max(np.abs(np.diff(np.array(commands)[:, 0]))))
    assert steps['measured'] > 0.18          # back to the lagging arm in one period
    # on from 0.5 at about 1 rad/s: JTC stamps the point before (the command for now) at the
    # previous update, so a first point later than one period ahead adds one period's motion
    assert steps['desired'] < 0.021


def test_a_desired_start_hits_the_first_point_at_its_time():
    # the point before is the last command, stamped one period before the take
    traj = JtcTrajectory(one_joint([0.01], [0.02], [1.0], [0.0]), np.array([0.01]),
                         np.array([1.0]), 0.0, np.zeros(1), -0.01)
    assert traj.sample(0.01)[0] == pytest.approx([0.02])
    assert traj.sample(-0.01)[0] == pytest.approx([0.01])
    assert traj.sample(0.0)[0] == pytest.approx([0.015])   # at 1 rad/s between them


def test_an_unknown_start_is_refused():
    with pytest.raises(ValueError, match='start'):
        TrajectoryController(0.01, 'commanded')


@pytest.mark.parametrize('start, first', [('measured', 0.3), ('desired', 0.0)])
def test_the_first_message_after_activation_starts_from_the_activation_hold(start, first):
    # JTC holds the measured position at activation (0.0 here): with a desired start that
    # hold is its last command, and the first message starts from it, not from the arm
    # (which has sagged to 0.3 since)
    jtc = TrajectoryController(0.01, start)
    assert jtc.update(0.0, np.zeros(1), np.zeros(1)) == pytest.approx([0.0])
    jtc.receive(one_joint([1.0], [1.0], [0.0], [0.0]))
    jtc.update(0.01, np.array([0.3]), np.zeros(1))
    assert jtc.trajectory.before[0] == pytest.approx([first])


def test_before_a_message_that_begins_at_0_the_message_start_is_what_was_desired():
    # JTC never samples before it; the detector looks back past it (motion_delay) and must
    # see the message's own start, not whichever state it was taken from (a replay of the
    # bag cannot know which one the live planner had read)
    message = one_joint([0.0, 1.0], [0.2, 1.0], [0.0, 0.0], [0.0, 0.0])
    for taken_from in (0.0, 0.25):
        traj = JtcTrajectory(message, np.array([taken_from]), np.zeros(1))
        assert traj.sample(-0.05)[0] == pytest.approx([0.2])
        assert traj.sample(0.5)[0] == pytest.approx([0.6])
