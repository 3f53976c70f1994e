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
The blocked-motion detector (the paper's test), shared by the planner node and replay.

While a trajectory runs, the detector compares where the arm should be (the commanded
trajectory interpolated at the current time) with where it is.  The motion is

* **blocked** when the L1 gap ``sum_j |desired_j - actual_j|`` exceeds ``d_dist`` and the arm
  has stalled (moved less than ``stall_motion`` (L1) over the last ``stall_time`` seconds)
  or the trajectory has ended ``settle_time`` ago;
* **done** when the trajectory has ended and the gap to its last point is at most
  ``d_dist``.

No rclpy: it takes plain times (seconds) and configurations.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import Enum

import numpy as np
from probdis_ros.motion.timing import TimedPath


class Verdict(str, Enum):
    """What the detector says about the running motion."""

    MOVING = 'moving'
    DONE = 'done'
    BLOCKED = 'blocked'


@dataclass
class DetectorSettings:
    """Thresholds of the detector; d_dist is the paper's (L1 over joints, rad)."""

    d_dist: float = 0.04
    stall_time: float = 0.3
    stall_motion: float = 0.005
    settle_time: float = 0.5


class BlockDetector:
    """Watches one trajectory: feed it (time, measured configuration) samples."""

    def __init__(self, path: TimedPath, start_time: float,
                 settings: DetectorSettings | None = None) -> None:
        self.path = path
        self.start_time = start_time
        self.settings = settings or DetectorSettings()
        self._history: deque[tuple[float, np.ndarray]] = deque()
        self.gap = 0.0

    def update(self, now: float, measured: np.ndarray) -> Verdict:
        """Return the verdict after a new measurement at time now [s]."""
        s = self.settings
        t = now - self.start_time
        desired = self.path.at(t)
        self.gap = float(np.abs(desired - measured).sum())
        self._history.append((now, np.asarray(measured, dtype=float).copy()))
        while self._history and self._history[0][0] < now - s.stall_time:
            self._history.popleft()
        ended = t >= self.path.duration
        if ended and self.gap <= s.d_dist:
            return Verdict.DONE
        if self.gap <= s.d_dist:
            return Verdict.MOVING
        if ended and t >= self.path.duration + s.settle_time:
            return Verdict.BLOCKED
        oldest_time, oldest = self._history[0]
        watched = now - oldest_time >= s.stall_time * 0.9
        if watched and float(np.abs(measured - oldest).sum()) < s.stall_motion:
            return Verdict.BLOCKED
        return Verdict.MOVING

    def segment(self, now: float) -> int:
        """Return the index of the path segment commanded at time now."""
        return self.path.segment_at(now - self.start_time)
