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
This host's wall clock without its steps: the planner node's time base on wall time (no rclpy).

DDS stamps each message's receipt with the wall clock, and the node times its commands by
it; the detector compares the two.  When the wall clock steps (an NTP client correcting a
large offset at once: ntpd by default above 0.128 s, chrony's ``makestep``,
systemd-timesyncd's "large offsets"; a clock set by hand; a resume), commands sent after it
were dated by the new clock and joint states by the old one (their stamps, moved onto this
clock by their quickest delivery): a step of 0.35-0.5 s ahead read as an arm late by that
much, and a run learned a failure that was never there.

The monotonic clock never steps and runs at the wall clock's rate (NTP slews both alike),
so the wall clock less the monotonic clock changes only when the wall clock steps.  The
node's time is the wall clock less the sum of the steps seen (:meth:`HostClock.now`), and a
receipt is moved by the same sum (:meth:`HostClock.receipt`): one time base that goes on
through a step as if none had been made (with a driver on another computer; one on this
computer stamps its states by the stepped clock, and the node begins their stream anew).  A
message received before a step but taken after it was seen carries a receipt on the old
clock: the node dates the joint states of such a batch as taken.  It stops a run at a step
(``PlannerNode._host_clock_stepped``).  Its time then stays off the wall clock by the steps
seen, for the life of the process (the bags' timestamps too).
"""

from __future__ import annotations

from collections.abc import Callable
import threading
import time

#: [s] A change of the wall clock less the monotonic clock beyond this is a step.  Between
#: steps it is 0 but for how the two are read (within READ_SLACK / 2).
HOST_CLOCK_STEP = 0.005
#: [s] Two monotonic reads around the wall clock's further apart than this (the thread was
#: preempted between them) leave the difference unjudged.
READ_SLACK = 0.001


def read_clocks() -> tuple[float, float, float]:
    """Return the monotonic clock, the wall clock and the monotonic clock again [s]."""
    return time.monotonic(), time.time(), time.monotonic()


class HostClock:
    """The wall clock less its steps; read it at every use, so that a step is seen at once."""

    def __init__(self, read: Callable[[], tuple[float, float, float]] = read_clocks,
                 threshold: float = HOST_CLOCK_STEP) -> None:
        """Start with no step seen; ``read`` returns (monotonic, wall, monotonic) [s]."""
        self.read = read
        self.threshold = threshold
        self.steps = 0.0          # the sum of the steps seen [s]
        self.count = 0            # how many
        self.last_step = 0.0      # the latest [s]: ahead > 0, back < 0
        self._offset: float | None = None   # the wall clock less the monotonic clock
        self._lock = threading.Lock()       # cheap, and any thread may read the time

    def now(self) -> float:
        """Return the wall clock's time less the steps seen, noting a new one [s]."""
        with self._lock:
            before, wall, after = self.read()
            steady = 0.5 * (before + after)
            if after - before > READ_SLACK:     # unjudged: the monotonic clock tells the time
                return wall - self.steps if self._offset is None else \
                    steady + self._offset - self.steps
            offset = wall - steady
            if self._offset is not None and abs(offset - self._offset) > self.threshold:
                self.last_step = offset - self._offset
                self.steps += self.last_step
                self.count += 1
            self._offset = offset
            return wall - self.steps

    def receipt(self, wall: float) -> float:
        """
        Return when a message was received, read from the wall clock at ``wall`` [s].

        On :meth:`now`'s base, the clock read first so that a step made since is taken out;
        a receipt read before a step and taken after it was seen is off by the step (the
        node dates the joint states of such a batch as taken).
        """
        self.now()
        return wall - self.steps
