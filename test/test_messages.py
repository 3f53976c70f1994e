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


"""Trajectory commands through their ROS message and back: every point, every field."""

from dataclasses import replace
import math

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.jtc import TrajectoryCommand
from probdis_ros.ros.messages import command_from_msg, duration, trajectory_msg
import pytest

JOINTS = [f'lbr_A{i}' for i in range(1, 8)]


def test_a_command_goes_through_its_message_unchanged_point_by_point():
    arm = iiwa_arm()
    rng = np.random.default_rng(3)
    n = 1300                                  # a 13 s motion, a point every 10 ms
    times = np.arange(1, n + 1) * 0.01
    times[-1] = times[-2] + 0.0099999999997    # rounds to the nanosecond, as duration() does
    positions = rng.uniform(arm.lower, arm.upper, size=(n, 7))
    velocities = rng.normal(size=(n, 7))
    velocities[5] = np.nan                     # a point that carries no velocities
    velocities[-1] = 0.0                       # JTC takes only a trajectory ending at rest
    command = TrajectoryCommand(times, positions, velocities, None)
    msg = trajectory_msg(command, JOINTS)
    assert msg.joint_names == JOINTS and len(msg.points) == n
    assert all(point.time_from_start == duration(t) for point, t in zip(msg.points, times))
    assert len(msg.points[5].velocities) == 0 and len(msg.points[6].velocities) == 7
    assert all(len(point.accelerations) == 0 for point in msg.points)
    back = command_from_msg(msg, JOINTS)
    assert np.array_equal(back.positions, positions)
    assert np.allclose(back.times, times, rtol=0, atol=1e-9)
    assert np.array_equal(back.velocities, velocities, equal_nan=True)
    assert back.accelerations is None or np.isnan(back.accelerations).all()
    assert back.stamp == 0.0 and msg.header.stamp.sec == 0 == msg.header.stamp.nanosec
    # a desired start stamps its commands: JTC runs them on its own time line from then
    stamped = command_from_msg(trajectory_msg(replace(command, stamp=1796369963.125), JOINTS),
                               JOINTS)
    assert abs(stamped.stamp - 1796369963.125) < 1e-6


def test_a_position_at_a_limit_is_sent_within_the_drivers_limits():
    # the lbr stack's guard takes A1, A3 and A5's limits as 170 degrees exactly, 2.7e-7 rad
    # inside the URDF's: a stop held at the URDF's limit would end the FRI session
    arm = iiwa_arm()
    positions = np.array([arm.upper, arm.lower, (arm.lower + arm.upper) / 2 + 0.1])
    command = TrajectoryCommand(np.array([0.1, 0.2, 0.3]), positions)
    sent = command_from_msg(trajectory_msg(command, JOINTS, arm.lower, arm.upper),
                            JOINTS).positions
    driver = math.radians(170.0)
    assert sent[0, 0] <= driver and sent[0, 2] <= driver and sent[0, 4] <= driver
    assert sent[1, 0] >= -driver and sent[1, 4] >= -driver
    assert np.abs(sent[:2] - positions[:2]).max() <= 1.001e-6
    assert np.array_equal(sent[2], positions[2])        # inside the limits: unchanged
    assert arm.upper[0] > driver                        # why: the URDF's is beyond it


def five_points():
    """Return a valid message of five points with positions, velocities and accelerations."""
    arm = iiwa_arm()
    rng = np.random.default_rng(5)
    positions = rng.uniform(arm.lower, arm.upper, size=(5, 7))
    velocities = rng.normal(size=(5, 7))
    velocities[-1] = 0.0
    command = TrajectoryCommand(np.arange(1, 6) * 0.1, positions, velocities,
                                rng.normal(size=(5, 7)))
    return trajectory_msg(command, JOINTS)


def bad(k, name, values):
    return lambda msg: setattr(msg.points[k], name, values)


NAN7 = [math.nan] * 7


@pytest.mark.parametrize('changes, reason', [
    ([bad(0, 'positions', [0.0] * 6)], 'point 0 has 6 positions for 7 joints'),
    ([bad(3, 'positions', [0.0] * 6), bad(1, 'velocities', NAN7)],
     'point 1 has non-finite velocities'),
    ([bad(2, 'velocities', [0.0] * 3), bad(2, 'positions', NAN7)], 'point 2 is not finite'),
    ([bad(4, 'accelerations', [0.0] * 8), bad(2, 'effort', [0.0] * 3)],
     'point 2 has efforts for other than 7 joints'),
    ([bad(4, 'velocities', [0.0] * 6 + [0.5])],
     'the last point still moves (lbr_A7 at 0.5 rad/s): JTC takes only a trajectory that ends '
     'at rest'),
    ([bad(4, 'velocities', [0.0] * 6 + [1e-7])], None),      # within a float's epsilon
    ([bad(2, 'positions', [3.0] * 7)], None),   # beyond the limits: JTC passes, the driver clamps
    ([bad(4, 'accelerations', [0.0] * 8)], 'point 4 has 8 accelerations for 7 joints'),
    ([bad(1, 'positions', [])], 'point 1 has 0 positions for 7 joints'),   # none: refused
    ([bad(3, 'accelerations', [math.inf] * 7), bad(3, 'velocities', [0.0] * 2)],
     'point 3 has 2 velocities for 7 joints'),
])
def test_a_command_is_refused_as_jtc_refuses_it_for_its_first_problem(changes, reason):
    msg = five_points()
    for change in changes:
        change(msg)
    if reason is None:
        assert command_from_msg(msg, JOINTS).positions.shape == (5, 7)
        return
    with pytest.raises(ValueError) as refused:
        command_from_msg(msg, JOINTS)
    assert str(refused.value) == reason


def test_joints_are_taken_by_name_in_any_order_and_no_others():
    msg = five_points()
    expected = command_from_msg(msg, JOINTS)
    order = [6, 0, 5, 1, 4, 2, 3]
    msg.joint_names = [JOINTS[j] for j in order]
    for point in msg.points:
        for name in ('positions', 'velocities', 'accelerations'):
            values = list(getattr(point, name))
            setattr(point, name, [values[j] for j in order])
    msg.points[2].velocities = []                  # a point without velocities
    back = command_from_msg(msg, JOINTS)
    assert np.array_equal(back.positions, expected.positions)
    assert np.isnan(back.velocities[2]).all()
    assert np.array_equal(np.delete(back.velocities, 2, axis=0),
                          np.delete(expected.velocities, 2, axis=0))
    with pytest.raises(ValueError, match='lacks joints lbr_A7'):
        msg.joint_names = ['other', *msg.joint_names[1:]]       # lbr_A7 was first
        command_from_msg(msg, JOINTS)
    # JTC (allow_partial_joints_goal off) refuses joints beyond its own: a gripper's too
    msg.joint_names = [*JOINTS, 'gripper']
    for point in msg.points:
        for name in ('positions', 'velocities', 'accelerations'):
            if len(getattr(point, name)):
                setattr(point, name, [*getattr(point, name), 0.0])
    with pytest.raises(ValueError, match=r"names 8 joints for the controller's 7 \(gripper"):
        command_from_msg(msg, JOINTS)


def test_a_command_naming_a_joint_twice_is_refused():
    # all the controller's joints and one of them again: JTC refuses it, as the planner must
    msg = five_points()
    msg.joint_names = [*JOINTS, 'lbr_A1']
    for point in msg.points:
        for name in ('positions', 'velocities', 'accelerations'):
            setattr(point, name, [*getattr(point, name), 0.0])
    with pytest.raises(ValueError, match=r"^trajectory names 8 joints for the controller's 7$"):
        command_from_msg(msg, JOINTS)
