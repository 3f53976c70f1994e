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
Joint-state messages in and trajectories out, checked before anything moves.

Incoming joint states are matched by name, in any order, extra joints ignored; a message
with a missing joint, arrays of the wrong length, or a NaN/inf position is refused with the
reason, never turned into a configuration.
"""

from __future__ import annotations

from builtin_interfaces.msg import Duration
import numpy as np
from probdis_ros.ros.trajectory import TimedPath
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint


class BadJointStateError(ValueError):
    """A joint-state message that cannot be used, with the reason."""


def joint_positions(msg: JointState, joint_names: list[str]) -> np.ndarray:
    """Return the positions of joint_names from msg, or raise BadJointStateError."""
    if len(msg.position) != len(msg.name):
        raise BadJointStateError(f'{len(msg.name)} names but {len(msg.position)} positions')
    index = {name: i for i, name in enumerate(msg.name)}
    missing = [name for name in joint_names if name not in index]
    if missing:
        raise BadJointStateError(f'missing joints {", ".join(missing)}')
    q = np.array([msg.position[index[name]] for name in joint_names], dtype=float)
    if not np.all(np.isfinite(q)):
        raise BadJointStateError(f'non-finite positions {q.tolist()}')
    return q


def duration(seconds: float) -> Duration:
    """Return a builtin_interfaces Duration."""
    sec = int(np.floor(seconds))
    return Duration(sec=sec, nanosec=round((seconds - sec) * 1e9) % 1_000_000_000)


def to_seconds(d: Duration) -> float:
    """Return a Duration in seconds."""
    return d.sec + d.nanosec * 1e-9


def trajectory_msg(path: TimedPath, joint_names: list[str]) -> JointTrajectory:
    """Build a JointTrajectory: every joint, increasing times, last point at rest."""
    msg = JointTrajectory()
    msg.joint_names = list(joint_names)
    for k, (point, t) in enumerate(zip(path.points, path.times)):
        if k == 0:
            continue          # the first via point is where the arm is now
        p = JointTrajectoryPoint()
        p.positions = [float(v) for v in point]
        if k == len(path.points) - 1:
            p.velocities = [0.0] * len(joint_names)
        p.time_from_start = duration(float(t))
        msg.points.append(p)
    return msg


def hold_msg(config: np.ndarray, joint_names: list[str], after: float) -> JointTrajectory:
    """Build a one-point trajectory that holds config, reached after seconds."""
    msg = JointTrajectory()
    msg.joint_names = list(joint_names)
    p = JointTrajectoryPoint()
    p.positions = [float(v) for v in config]
    p.velocities = [0.0] * len(joint_names)
    p.time_from_start = duration(after)
    msg.points.append(p)
    return msg


def timed_path_from_msg(msg: JointTrajectory, joint_names: list[str], current: np.ndarray,
                        lower: np.ndarray, upper: np.ndarray) -> TimedPath:
    """
    Return the motion a trajectory command asks for, starting from current.

    Raises ValueError for a command that must not be executed: unknown or missing joints,
    no points, wrong lengths, non-finite or out-of-limit positions, times not increasing.
    """
    if not msg.points:
        raise ValueError('trajectory has no points')
    index = {name: i for i, name in enumerate(msg.joint_names)}
    missing = [name for name in joint_names if name not in index]
    if missing:
        raise ValueError(f'trajectory lacks joints {", ".join(missing)}')
    points = [current]
    times = [0.0]
    for k, point in enumerate(msg.points):
        if len(point.positions) != len(msg.joint_names):
            raise ValueError(f'point {k} has {len(point.positions)} positions for '
                             f'{len(msg.joint_names)} joints')
        q = np.array([point.positions[index[name]] for name in joint_names], dtype=float)
        if not np.all(np.isfinite(q)):
            raise ValueError(f'point {k} is not finite')
        if np.any(q < lower - 1e-9) or np.any(q > upper + 1e-9):
            raise ValueError(f'point {k} is outside the joint limits')
        t = to_seconds(point.time_from_start)
        if t <= times[-1] and not (k == 0 and t == 0.0):
            raise ValueError('time_from_start must increase')
        points.append(q)
        times.append(max(t, 1e-3) if k == 0 else t)
    return TimedPath(np.array(points), np.array(times))
