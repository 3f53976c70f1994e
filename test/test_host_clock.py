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

"""The planner node's time base on wall time: this host's clock without its steps."""

from itertools import pairwise
import time

from probdis_ros.motion.host_clock import HOST_CLOCK_STEP, HostClock, READ_SLACK
import pytest


class FakeClocks:
    """A monotonic clock and a wall clock 1000 s ahead of it, whose offset a test steps."""

    def __init__(self) -> None:
        self.steady, self.offset, self.gap = 5.0, 1000.0, 0.0

    def advance(self, seconds: float) -> None:
        self.steady += seconds

    def read(self) -> tuple[float, float, float]:
        # the wall clock read between two monotonic reads ``gap`` apart, at the second one
        return self.steady - self.gap, self.steady + self.offset, self.steady


def fake_clock() -> tuple[FakeClocks, HostClock]:
    """Return fake clocks and a HostClock that reads them."""
    clocks = FakeClocks()
    return clocks, HostClock(clocks.read)


def test_without_a_step_the_time_is_the_wall_clock():
    clocks, clock = fake_clock()
    for _ in range(100):
        clocks.advance(0.01)
        clocks.offset += 1e-6          # an NTP slew of 100 ppm would show as nothing at all
        assert clock.now() == pytest.approx(clocks.steady + clocks.offset)
    assert clock.count == 0 and clock.steps == pytest.approx(0.0)


@pytest.mark.parametrize('step', [0.4, -0.3, 2.0 * HOST_CLOCK_STEP, 3600.0])
def test_a_step_of_the_wall_clock_is_taken_out_of_the_time_and_the_receipts(step):
    # before the step and after it the time runs on as the monotonic clock does
    clocks, clock = fake_clock()
    t0 = clock.now()
    clocks.advance(0.01)
    clocks.offset += step
    t1 = clock.now()
    assert t1 - t0 == pytest.approx(0.01)
    assert (clock.count, clock.last_step) == (1, pytest.approx(step))
    # a message received now, stamped by DDS with the stepped wall clock
    assert clock.receipt(clocks.steady + clocks.offset) == pytest.approx(t1)
    clocks.advance(0.01)
    assert clock.now() - t1 == pytest.approx(0.01) and clock.count == 1


def test_steps_add_up():
    # a second step (ahead 0.4 s, then back 0.1 s): the time runs on without both
    clocks, clock = fake_clock()
    t0 = clock.now()
    for step in (0.4, -0.1):
        clocks.advance(0.01)
        clocks.offset += step
        clock.now()
    clocks.advance(0.01)
    assert clock.now() - t0 == pytest.approx(0.03)
    assert clock.count == 2 and clock.steps == pytest.approx(0.3)


def test_a_step_below_the_threshold_is_rounding_not_a_step():
    clocks, clock = fake_clock()
    clock.now()
    clocks.offset += 0.5 * HOST_CLOCK_STEP
    clocks.advance(0.01)
    clock.now()
    assert clock.count == 0


def test_a_read_preempted_between_the_monotonic_reads_is_not_judged():
    # the thread held 0.2 s between reading the monotonic clock and the wall clock: the
    # wall clock then seems 0.1 s ahead of the monotonic clock's middle, no step was made
    clocks, clock = fake_clock()
    clock.now()
    clocks.advance(0.2)
    clocks.gap = 0.2
    assert abs(clock.now() - (clocks.steady + clocks.offset)) <= 0.1 + 1e-9
    clocks.gap = 0.5 * READ_SLACK
    clocks.advance(0.01)
    clock.now()
    assert clock.count == 0


def test_a_step_made_during_a_preempted_read_leaves_the_time_as_the_monotonic_clock_runs():
    # the read that could not be judged must not give the stepped wall clock either: the
    # next judged read would take the step out again, and the time would run back by it
    clocks, clock = fake_clock()
    t0 = clock.now()
    clocks.advance(0.01)
    clocks.offset += 0.4
    clocks.gap = 0.01
    t1 = clock.now()
    assert abs(t1 - t0 - 0.01) <= 0.5 * clocks.gap + 1e-9 and clock.count == 0
    clocks.gap = 0.0
    clocks.advance(0.01)
    assert clock.now() - t0 == pytest.approx(0.02) and clock.count == 1


def test_a_receipt_takes_out_a_step_made_since_the_clock_was_last_read():
    # a joint state received on the stepped clock, its receipt read before anything else
    # read the time: moved by the step all the same
    clocks, clock = fake_clock()
    t0 = clock.now()
    clocks.advance(0.01)
    clocks.offset += 0.4
    received = clocks.steady + clocks.offset - 0.002
    assert clock.receipt(received) == pytest.approx(t0 + 0.008)
    assert clock.count == 1


def test_this_hosts_clocks_read_as_one_time_without_steps():
    clock = HostClock()
    times = [clock.now() for _ in range(2000)]
    assert clock.count == 0
    assert all(b >= a for a, b in pairwise(times))
    assert abs(clock.now() - time.time()) < 0.01
