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
Joint states checked against the arm before anything is built from them (no rclpy).

A joint state is refused, with the reason, when it cannot be the arm's:

* its shape: a missing joint, a name given twice, arrays of the wrong length, a NaN or inf;
* a velocity the arm cannot have: above ``JUMP_SPEED`` x its URDF limit (a glitch; every stop
  and every path would start from it);
* a position outside the joint limits by more than ``LIMIT_TOLERANCE`` (within it, the
  position is clamped to the limit: nothing outside the limits is ever built from a state);
* time going backwards: a header stamp not later than the last accepted one (a stream that
  repeats one message, a replayed recording), an unstamped state after stamped ones (a
  second publisher), or the host's time base running back;
* a jump: a joint moved further since the last accepted state than the arm can
  (``JUMP_SPEED`` x its velocity limit, plus ``JUMP_SLACK`` for noise): an old configuration
  repeated by a second publisher, or a mixed-up joint order;
* a second source: the publication sequence number (counted by each DDS publisher) not
  after the last accepted one's: two publishers interleave on the topic, whatever they send;
* staleness (with ``late`` set): a state that arrives more than ``late`` seconds later after
  its stamp than the stream's quickest (a backlog delivered late: the arm was there then,
  not now), or, on simulated time (``clock`` given), stamped more than ``late`` from the
  clock (not on the simulated time at all); and one stamped more than ``late`` ahead of the
  stream's time (it would date the stream ahead, and open the jump check to any step).

After ``SILENCE`` seconds without an accepted state the stream counts as new (a restarted
driver): stamps and jumps are judged from its first state again.  But where the stamps say
the stream went on (the state stamped within ``SILENCE`` of the last one, and received later
by more than ``late``, else half the silence), the receiver's clock jumped or its process
was held up: that state is refused, and the next starts the new stream.

An accepted state is dated (:meth:`StateCheck.measured_at`) by its stamp moved onto the
receiver's clock by the stream's quickest delivery, not by when it arrived: arrival jitters
whenever the receiver's or the sender's threads are starved (a burst of states held up for
half a second and then delivered at once read as an arm lagging its command by half a
second), the stamp does not; and the quickest delivery takes out any offset between the
two clocks.  The two clocks drift apart (quartz: tens of ppm; NTP slews at up to 500 ppm),
and a plain minimum never rises to follow a clock that falls behind: beside an arm clock
100 ppm slow, after an hour every state was dated 0.36 s early and a command stamped for
the arm 0.36 s in its future, and after 83 min every state was refused as stale.  So the
quickest delivery rises to the quickest of each ``DRIFT_SPAN`` of stamps when that lies
above it by more than rounding (``DRIFT_NOISE``), by at most ``CLOCK_DRIFT`` a second: a
backlog still reads as one, a rise of half a second taking over eight minutes; and below
``DRIFT_NOISE`` the estimate stays put, so that a replay dates each state as the live node
did (where the clocks drift, within one span's rise).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: How far past a joint limit a measured position is still taken (clamped to it) [rad].
LIMIT_TOLERANCE = 0.002
#: A joint may move this many times its URDF velocity limit between two states ...
JUMP_SPEED = 1.5
#: ... plus this much (noise, rounding) [rad].
JUMP_SLACK = 0.05
#: Without an accepted state for this long, the next one starts a new stream [s].
SILENCE = 1.0
#: The quickest delivery rises at most this fast, the clocks drifting apart [s/s] (NTP's
#: largest slew is 5e-4; quartz 2e-5 to 5e-5) ...
CLOCK_DRIFT = 1e-3
#: ... to the quickest of each span of this many seconds of stamps ...
DRIFT_SPAN = 1.0
#: ... when that lies above it by more than this (rounding of stamps and receive times) [s].
DRIFT_NOISE = 1e-4
#: [s] A stream begun anew (:meth:`StateCheck.restart`) begins again, instead of refusing,
#: at a break in its stamps this soon: states stamped before a step of the clock that
#: stamps them, waiting in a queue, began it.
RESTART_SPAN = 0.5


class BadJointStateError(ValueError):
    """A joint state that cannot be used, with the reason."""


def positions_by_name(names: Sequence[str], positions: Sequence[float],
                      joint_names: Sequence[str]) -> np.ndarray:
    """Return the positions of joint_names, matched by name; raise BadJointStateError."""
    if len(positions) != len(names):
        raise BadJointStateError(f'{len(names)} names but {len(positions)} positions')
    index: dict[str, int] = {}
    for i, name in enumerate(names):
        if name in index:
            raise BadJointStateError(f'joint {name} is named twice')
        index[name] = i
    missing = [name for name in joint_names if name not in index]
    if missing:
        raise BadJointStateError(f'missing joints {", ".join(missing)} (it names '
                                 f'{", ".join(names) or "none"}: set joint_names to the '
                                 f"arm's)")
    q = np.array([positions[index[name]] for name in joint_names], dtype=float)
    if not np.all(np.isfinite(q)):
        raise BadJointStateError(f'non-finite positions {q.tolist()}')
    return q


def values_by_name(names: Sequence[str], values: Sequence[float],
                   joint_names: Sequence[str]) -> np.ndarray | None:
    """Return joint_names' velocities (or efforts), None where the state carries none usable."""
    if len(values) != len(names) or len(set(names)) != len(names):
        return None
    index = {name: i for i, name in enumerate(names)}
    v = np.array([values[index[name]] for name in joint_names], dtype=float)
    return v if np.all(np.isfinite(v)) else None


def _worst(excess: np.ndarray, allowed: float = 0.0) -> int | None:
    """Return the joint of the largest excess if it is beyond what is allowed, else None."""
    return int(excess.argmax()) if excess.max() > allowed else None


@dataclass
class StateCheck:
    """The gate every joint state passes: feed it each message in arrival order."""

    joint_names: Sequence[str]
    lower: np.ndarray
    upper: np.ndarray
    velocity_limits: np.ndarray
    tolerance: float = LIMIT_TOLERANCE
    silence: float = SILENCE
    late: float | None = None        # seconds of lateness that make a state stale; None: off

    def __post_init__(self) -> None:
        """Start with no stream heard."""
        self.lower = np.asarray(self.lower, dtype=float)
        self.upper = np.asarray(self.upper, dtype=float)
        self.velocity_limits = np.asarray(self.velocity_limits, dtype=float)
        self.last_q: np.ndarray | None = None
        self.last_stamp = 0.0            # header stamp of the last accepted state; 0: none
        self.last_time = -np.inf         # host time of the last accepted state
        self.last_sequence = 0           # its publication sequence number; 0: unknown
        self.quickest = np.inf           # the stream's quickest receive time - stamp [s]
        self.span_quickest = np.inf      # ... within the span of stamps that began at
        self.span_start = 0.0            # this stamp
        self.refused_at = -np.inf        # host time of the last refusal
        self.refusal = ''                # its reason
        self.refused = 0
        self.streams = 0                 # streams heard: a restarted driver starts a new one
        self.restarted_at = -np.inf      # host time of the last restart

    def check(self, now: float, names: Sequence[str], positions: Sequence[float],
              velocities: Sequence[float] = (), stamp: float = 0.0, sequence: int = 0,
              clock: float | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """
        Return the (positions, velocities or None) of a joint state received at now.

        ``stamp`` is its header stamp [s] (0: unstamped), ``sequence`` its publisher's
        publication sequence number (0: unknown), ``clock`` the simulated time it arrived at
        (None: on wall time, ``now`` is the receive time).  Raises BadJointStateError, and
        remembers the refusal (``refused_at``, ``refusal``), for a state that cannot be the arm's.
        """
        try:
            q = self._check(now, names, positions, stamp)
            v = self._velocities(names, velocities)
            self._check_source(now, stamp, sequence, clock)
        except BadJointStateError as err:
            self.refuse(now, str(err))
            raise
        self.last_q, self.last_time = q, now
        if stamp > 0:
            self.last_stamp = stamp
            if clock is None:
                self._follow_the_clocks(now - stamp, stamp)
        if sequence > 0:
            self.last_sequence = sequence
        return q, v

    def _velocities(self, names: Sequence[str], velocities: Sequence[float]
                    ) -> np.ndarray | None:
        """Return the state's velocities (None if it has none); refuse impossible ones."""
        if len(velocities) and len(velocities) != len(names):
            raise BadJointStateError(f'{len(names)} names but {len(velocities)} velocities')
        v = values_by_name(names, velocities, self.joint_names)
        if v is None:
            finite = np.isfinite(np.asarray(velocities, dtype=float))
            if finite.any() and not finite.all():
                # a glitch: dropped, a stop would take the arm for at rest and hold it dead
                raise BadJointStateError(f'non-finite velocities {list(velocities)}')
            return None     # none, or none yet (lbr_ros2_control's first state: all NaN)
        j = _worst(np.abs(v) - JUMP_SPEED * self.velocity_limits)
        if j is not None:
            raise BadJointStateError(
                f'A{j + 1} velocity {v[j]:.4g} rad/s is beyond {JUMP_SPEED:g} x its limit '
                f'{self.velocity_limits[j]:.3f}: a glitch in the driver?')
        return v

    def _follow_the_clocks(self, delivery: float, stamp: float) -> None:
        """Take the delivery of a state stamped at stamp into the quickest delivery."""
        self.quickest = min(self.quickest, delivery)
        self.span_quickest = min(self.span_quickest, delivery)
        span = stamp - self.span_start
        if span >= DRIFT_SPAN:
            rise = self.span_quickest - self.quickest
            if rise > DRIFT_NOISE:       # the arm's clock fell behind (or a backlog)
                self.quickest += min(rise, CLOCK_DRIFT * span)
            self.span_quickest, self.span_start = np.inf, stamp

    def measured_at(self, now: float, stamp: float) -> float:
        """
        Return when the state just accepted at now was measured, on the receiver's clock [s].

        Its stamp plus the stream's quickest delivery (never later than now, and later than
        the state before it, since stamps increase, the quickest only falls to a state dated
        now, and a rise only dates it later); unstamped, and on simulated time, the state is
        dated now.
        """
        if stamp > 0 and np.isfinite(self.quickest):
            return min(now, stamp + self.quickest)
        return now

    @property
    def clock_offset(self) -> float:
        """
        Return the receiver's clock less the clock that stamps the states [s].

        The stream's quickest delivery (what :meth:`measured_at` adds to a stamp): the two
        clocks' offset plus the shortest delivery, a millisecond or less.  A message stamped
        for the arm's controller, which runs on the clock that stamps its joint states, is
        stamped with this node's time less it.  0 before a stamped state was heard, and on
        simulated time (the states' stamps are the clock's time).
        """
        return self.quickest if np.isfinite(self.quickest) else 0.0

    def _check_source(self, now: float, stamp: float, sequence: int,
                      clock: float | None) -> None:
        """Refuse a state from a second publisher, or a stale one."""
        if sequence > 0 and 0 < self.last_sequence and sequence <= self.last_sequence:
            raise BadJointStateError(
                f'publication sequence number {sequence} after {self.last_sequence}: a second '
                f'publisher of joint states interleaves with the arm?')
        if self.late is None or stamp <= 0:
            return
        if clock is not None:
            if abs(stamp - clock) > self.late:
                raise BadJointStateError(
                    f'stamped {stamp - clock:+.3f} s from the simulated clock: not on its time, '
                    f'or stale')
        elif now - stamp - self.quickest > self.late:
            raise BadJointStateError(
                f'arrived {now - stamp - self.quickest:.3f} s later after its stamp than the '
                f'quickest of its stream: stale (a backlog delivered late)')
        elif np.isfinite(self.quickest) and self.quickest - (now - stamp) > self.late:
            raise BadJointStateError(
                f"stamped {self.quickest - (now - stamp):.3f} s ahead of its stream's time: "
                f'a second publisher, or a clock that jumped?')

    def refuse(self, now: float, reason: str) -> None:
        """Note a state refused at now (also one refused before it got here: undecodable)."""
        self.refused_at, self.refusal = now, reason
        self.refused += 1

    def refused_within(self, now: float, span: float) -> str:
        """Return the reason of a refusal in the last span seconds before now, else ''."""
        return self.refusal if now - self.refused_at <= span else ''

    def restart(self, now: float, reason: str) -> None:
        """
        Judge the states from now on as a new stream, for a reason noted as a refusal.

        After a step of this host's clock: a driver on this computer stamps its states by the
        stepped clock, and the stream's quickest delivery, its last stamp and the dates built
        on them belong to the old one.  States stamped before the step may still wait in a
        queue and begin the new stream: a break in the stamps within RESTART_SPAN (back, or
        ahead of the receipts by more than ``late``) begins it again.
        """
        self.refuse(now, reason)
        self._new_stream(now)
        self.restarted_at = now

    def _new_stream(self, now: float) -> None:
        """Judge the states from now on as a new stream (stamps, jumps, deliveries)."""
        self.last_q, self.last_stamp, self.last_time = None, 0.0, now
        self.streams += 1
        self.last_sequence, self.quickest = 0, np.inf
        self.span_quickest, self.span_start = np.inf, 0.0

    def _check(self, now: float, names: Sequence[str], positions: Sequence[float],
               stamp: float) -> np.ndarray:
        q = positions_by_name(names, positions, self.joint_names)
        j = _worst(np.maximum(self.lower - q, q - self.upper), self.tolerance)
        if j is not None:
            raise BadJointStateError(
                f'A{j + 1} at {q[j]:.4g} rad is outside its limits [{self.lower[j]:.3f}, '
                f'{self.upper[j]:.3f}]')
        q = np.clip(q, self.lower, self.upper)
        if not np.isfinite(now):
            raise BadJointStateError('no receive time')
        if now < self.last_time:
            # this host's clock stepped back: refused (a run stops), and the states after it
            # start a new stream (else each was refused until the clock caught up again)
            back = self.last_time - now
            self._new_stream(now)
            raise BadJointStateError(f'time went backwards by {back:.3f} s')
        if now - self.last_time > self.silence:
            # silent on this host's clock; stamped within the silence of the last state, and
            # received later by more than a stale state is (``late``, else half the silence):
            # the stream went on meanwhile, this host's clock jumped or this process was held
            # up, and the arm was not where a state dated now says (taken, a run saw its
            # command seconds ahead of the arm, and learned a failure)
            stamps = stamp - self.last_stamp if stamp > 0 and self.last_stamp > 0 else None
            silent = now - self.last_time
            self._new_stream(now)
            later = self.late if self.late is not None else 0.5 * self.silence
            if stamps is not None and 0 < stamps <= self.silence and silent - stamps > later:
                raise BadJointStateError(
                    f'arrived {silent:.3f} s after the joint state before it but '
                    f"stamped {stamps:.3f} s after it: this host's clock jumped, or this "
                    f'process was held up (the states after it start a new stream)')
        if self.last_stamp > 0 < stamp and now - self.restarted_at <= RESTART_SPAN:
            ahead = (stamp - self.last_stamp) - (now - self.last_time)
            if stamp <= self.last_stamp or ahead > (self.late if self.late is not None
                                                    else 0.5 * self.silence):
                self._new_stream(now)    # the states before were stamped before the step
        if self.last_stamp > 0:
            if stamp <= 0:
                raise BadJointStateError('unstamped after stamped joint states: a second '
                                         'publisher?')
            if stamp <= self.last_stamp:
                raise BadJointStateError(
                    f'stamp {self.last_stamp - stamp:.3f} s older than the last one: a '
                    f'repeated or replayed stream?' if stamp < self.last_stamp else
                    'repeats the stamp of the last joint state: a repeated stream?')
        if self.last_q is not None:
            dt = stamp - self.last_stamp if stamp > 0 and self.last_stamp > 0 else \
                now - self.last_time
            step = np.abs(q - self.last_q)
            j = _worst(step - (JUMP_SPEED * self.velocity_limits * max(dt, 0.0) + JUMP_SLACK))
            if j is not None:
                raise BadJointStateError(
                    f'A{j + 1} jumped {step[j]:.3f} rad in {dt:.3f} s, faster than the arm '
                    f'can: a second joint-state publisher or an old configuration?')
        return q
