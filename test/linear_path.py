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
Linearly timed paths for the tests: the message shape other clients of JTC send.

Positions only, linear between via points (JTC's "discouraged" linear segments); the
planner itself sends ``profiles.Motion`` (jerk-limited, every sample with velocities and
accelerations).  A trajectory here is via points ``(M, n)`` with ``times`` (seconds from
its start, strictly increasing, ``times[0] = 0`` at the first point, where the arm is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from probdis_ros.motion.jtc import TrajectoryCommand

#: Shortest duration of any segment [s].
MIN_SEGMENT_S = 0.05


@dataclass(frozen=True)
class TimedPath:
    """Via points and their times from the start of the motion."""

    points: np.ndarray
    times: np.ndarray

    @property
    def duration(self) -> float:
        """Return the time of the last point [s]."""
        return float(self.times[-1])

    def at(self, t: float) -> np.ndarray:
        """Return the desired configuration t seconds after the start (linear in time)."""
        if t <= 0.0:
            return self.points[0].copy()
        if t >= self.times[-1]:
            return self.points[-1].copy()
        k = int(np.searchsorted(self.times, t, side='right')) - 1
        frac = (t - self.times[k]) / (self.times[k + 1] - self.times[k])
        return self.points[k] + frac * (self.points[k + 1] - self.points[k])

    def command(self) -> TrajectoryCommand:
        """
        Return the command that makes JTC run this path from where the arm is.

        The first via point is where the arm is (JTC starts from the measured state), so it
        is not sent; the last point carries zero velocities: the arm ends at rest.
        """
        n = self.points.shape[1]
        velocities = np.full((len(self.points) - 1, n), np.nan)
        velocities[-1] = 0.0
        return TrajectoryCommand(self.times[1:], self.points[1:], velocities)

    def segment_at(self, t: float) -> int:
        """Return the index of the segment being executed at time t."""
        k = int(np.searchsorted(self.times, t, side='right')) - 1
        return int(np.clip(k, 0, len(self.points) - 2))


def time_path(points: np.ndarray, velocity_limits: np.ndarray, scaling: float) -> TimedPath:
    """
    Time via points so that no joint exceeds scaling x its velocity limit.

    Each segment moves every joint linearly and takes as long as its slowest joint needs
    (at least MIN_SEGMENT_S), so joint speeds stay within the limit everywhere.
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    if not 0.0 < scaling <= 1.0:
        raise ValueError(f'velocity scaling must be in (0, 1], got {scaling}')
    speeds = scaling * np.asarray(velocity_limits, dtype=float)
    durations = np.abs(np.diff(points, axis=0)) / speeds
    segment = np.maximum(durations.max(axis=1, initial=0.0), MIN_SEGMENT_S)
    return TimedPath(points, np.concatenate([[0.0], np.cumsum(segment)]))
