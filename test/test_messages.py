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

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.jtc import TrajectoryCommand
from probdis_ros.ros.messages import command_from_msg, duration, trajectory_msg

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
    command = TrajectoryCommand(times, positions, velocities, None)
    msg = trajectory_msg(command, JOINTS)
    assert msg.joint_names == JOINTS and len(msg.points) == n
    assert all(point.time_from_start == duration(t) for point, t in zip(msg.points, times))
    assert len(msg.points[5].velocities) == 0 and len(msg.points[6].velocities) == 7
    assert all(len(point.accelerations) == 0 for point in msg.points)
    back = command_from_msg(msg, JOINTS, arm.lower, arm.upper)
    assert np.array_equal(back.positions, positions)
    assert np.allclose(back.times, times, rtol=0, atol=1e-9)
    assert np.array_equal(back.velocities, velocities, equal_nan=True)
    assert back.accelerations is None or np.isnan(back.accelerations).all()
