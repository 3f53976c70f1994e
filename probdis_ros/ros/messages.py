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
with a missing or twice-named joint, arrays of the wrong length, or a NaN/inf position is
refused with the reason, never turned into a configuration (the checks against the arm
itself, limits, time and jumps, are :mod:`probdis_ros.motion.state_check`).
"""

from __future__ import annotations

from array import array
from dataclasses import replace

from builtin_interfaces.msg import Duration, Time
import numpy as np
from probdis_ros.model.arms import DRIVER_LIMIT_INSET
from probdis_ros.motion.jtc import TrajectoryCommand
from probdis_ros.motion.state_check import (  # noqa: F401 (BadJointStateError: re-exported)
    BadJointStateError,
    positions_by_name,
    values_by_name,
)
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

# JTC's test of a last point at rest: |velocity| above a float's epsilon moves
FLOAT_EPSILON = float(np.finfo(np.float32).eps)


def joint_positions(msg: JointState, joint_names: list[str]) -> np.ndarray:
    """Return the positions of joint_names from msg, or raise BadJointStateError."""
    return positions_by_name(msg.name, msg.position, joint_names)


def stamp_seconds(msg: JointState | JointTrajectory) -> float:
    """Return a message's header stamp [s] (0 when unstamped)."""
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def time_msg(seconds: float) -> Time:
    """Return a builtin_interfaces Time (a header stamp)."""
    nanoseconds = round(seconds * 1e9)
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def duration(seconds: float) -> Duration:
    """Return a builtin_interfaces Duration."""
    nanoseconds = round(seconds * 1e9)     # 1.9999999997 s is 2 s, not 1 s
    return Duration(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def to_seconds(d: Duration) -> float:
    """Return a Duration in seconds."""
    return d.sec + d.nanosec * 1e-9


def trajectory_msg(command: TrajectoryCommand, joint_names: list[str],
                   lower: np.ndarray | None = None,
                   upper: np.ndarray | None = None) -> JointTrajectory:
    """
    Build a JointTrajectory of every joint; fields a point lacks are left empty.

    With the arm's limits, every position is held ``DRIVER_LIMIT_INSET`` inside them.

    Built column by column (one conversion per field, arrays the message takes as they
    are): a command has a point every controller period, 1,300 for a 13 s motion, and
    building them value by value held the executor for 26-58 ms.
    """
    if lower is not None and upper is not None:     # a stop at a limit: within the driver's
        command = replace(command, positions=np.clip(
            command.positions, np.asarray(lower) + DRIVER_LIMIT_INSET,
            np.asarray(upper) - DRIVER_LIMIT_INSET))
    msg = JointTrajectory()
    msg.joint_names = list(joint_names)
    if command.stamp > 0:           # JTC starts it then (a desired start), else when taken
        msg.header.stamp = time_msg(command.stamp)
    times = np.asarray(command.times, dtype=float).tolist()
    columns = []
    for name in ('positions', 'velocities', 'accelerations'):
        values = getattr(command, name)
        if values is not None:
            values = np.asarray(values, dtype=float)
            carried = [True] * len(values) if name == 'positions' else \
                (~np.isnan(values).any(axis=1)).tolist()
            columns.append((name, [array('d', row) for row in values.tolist()], carried))
    points = []
    for k, t in enumerate(times):
        point = JointTrajectoryPoint(time_from_start=duration(t))
        for name, rows, carried in columns:
            if carried[k]:
                setattr(point, name, rows[k])
        points.append(point)
    msg.points = points
    return msg


def command_from_msg(msg: JointTrajectory, joint_names: list[str]) -> TrajectoryCommand:
    """
    Return what a trajectory command asks JTC for, in the order of joint_names.

    Raises ValueError for a command Jazzy's JTC refuses (with the lbr stack's parameters:
    ``allow_partial_joints_goal`` and ``allow_nonzero_velocity_at_trajectory_end`` off): no
    points, joints other than the controller's or missing, wrong lengths, non-finite values,
    times not increasing, a last point that still moves.  Positions beyond the limits pass,
    as they pass JTC: the driver clamps them (``enforce_command_limits``).  Of several
    problems at points the first point's is named (positions before velocities before
    accelerations before efforts).  Each check runs over all points at once: the mock takes a
    command in its executor, and point by point a 14 s motion's 1,450 points held it for
    25-40 ms.
    """
    points = msg.points
    if not points:
        raise ValueError('trajectory has no points')
    index = {name: i for i, name in enumerate(msg.joint_names)}
    missing = [name for name in joint_names if name not in index]
    if missing:
        raise ValueError(f'trajectory lacks joints {", ".join(missing)}')
    foreign = [name for name in msg.joint_names if name not in joint_names]
    if foreign or len(msg.joint_names) != len(joint_names):
        raise ValueError(f'trajectory names {len(msg.joint_names)} joints for the '
                         f"controller's {len(joint_names)}"
                         + (f' ({", ".join(foreign)} not among them)' if foreign else ''))
    order = [index[name] for name in joint_names]
    n, m = len(msg.joint_names), len(points)
    problems = []           # (point, rank within the point, message)

    def first(bad: np.ndarray, rank: int, text: str) -> None:
        if bad.any():
            k = int(np.argmax(bad))
            problems.append((k, rank, text.format(k=k)))

    columns = {}
    for field, name in enumerate(('positions', 'velocities', 'accelerations')):
        given = [getattr(point, name) for point in points]
        lengths = np.fromiter(map(len, given), dtype=np.int64, count=m)
        carried = lengths > 0 if field else np.ones(m, dtype=bool)
        wrong = carried & (lengths != n)
        if wrong.any():
            k = int(np.argmax(wrong))
            problems.append((k, 3 * field, f'point {k} has {lengths[k]} {name} for {n} joints'))
        usable = carried & ~wrong
        values = np.full((m, len(joint_names)), np.nan)
        if usable.any():
            rows = np.flatnonzero(usable)
            values[rows] = np.array([given[k] for k in rows], dtype=float)[:, order]
        finite = np.isfinite(values).all(axis=1)
        if field:
            first(usable & ~finite, 3 * field + 1, f'point {{k}} has non-finite {name}')
        else:
            first(usable & ~finite, 1, 'point {k} is not finite')
        columns[name] = values
    efforts = np.fromiter((len(point.effort) for point in points), dtype=np.int64, count=m)
    first((efforts > 0) & (efforts != n), 9, f'point {{k}} has efforts for other than {n} joints')
    if problems:
        raise ValueError(min(problems)[2])
    end = columns['velocities'][-1]
    moving = np.abs(np.nan_to_num(end)) > FLOAT_EPSILON
    if moving.any():
        j = int(np.argmax(moving))
        raise ValueError(f'the last point still moves ({joint_names[j]} at {end[j]:.3g} rad/s):'
                         f' JTC takes only a trajectory that ends at rest')
    times = np.fromiter((to_seconds(point.time_from_start) for point in points), dtype=float,
                        count=m)
    return TrajectoryCommand(times, columns['positions'], columns['velocities'],
                             columns['accelerations'], stamp_seconds(msg))
