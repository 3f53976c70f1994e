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
The blocked-motion detector (the paper's test, and what a compliant arm needs beside it).

While a trajectory runs, the detector compares where the controller commands the arm (the
command as JTC runs it, :mod:`probdis_ros.motion.jtc`, ``motion_delay`` earlier: an arm in
joint impedance follows its command with a lag) with where it is.  The L1 gap
``sum_j |desired_j - actual_j|`` decides:

* **blocked** when the gap exceeds ``d_dist`` and the arm has stalled (moved less than
  ``stall_motion`` (L1) over the last ``stall_time`` seconds) or the trajectory ended
  ``settle_time`` ago (the paper's test); or at once when the gap exceeds ``gap_ceiling`` in
  total or ``joint_gap_ceiling`` at one joint: with joint stiffness K the arm then presses
  with about K x gap, and a compliant arm whose unblocked joints keep moving may never stall
  before the trajectory ends (DESIGN.md "Facts: a physics-simulated iiwa"); but not where
  the efforts show the arm still slowing down and pressing on nothing (``COAST_WAIT``,
  below);
* **blocked** at once, where the joint states carry the measured torques, when the
  external-torque estimate (:class:`ExternalTorqueObserver`: the efforts less the arm's
  gravity and dynamics) exceeds ``torque_ceiling`` at a joint (0: off; it needs the load
  data right, as KUKA's does); the observer lags a sudden contact by its time constant
  (40 ms to 63 %), and the lbr stack's filter of the torques by 0.1 s more, so the arm
  presses somewhat past the ceiling before it trips; the same lag carries a block's torque
  into the retreat after it, so a command that need not move the arm (``expect_motion``
  false) judges a joint by the ceiling only once its torque has come below it (the gap
  tests judge it meanwhile);
* **blocked** at once when a joint is pushed toward its limit (``limits`` given): measured
  within ``limit_room`` of it (or so near that it would be there :data:`LIMIT_HORIZON` on
  at its speed toward it), and nearer to it by more than :data:`LIMIT_PUSH` than both
  its command (beyond the speed allowance) and where it stood when the command began.  The
  planner keeps its paths ``joint_margin`` from every limit, and an arm in joint impedance
  that presses on something while its other joints move on is bent past its command by tens
  of milliradians before a gap ceiling passes; pressed past an axis limit, KUKA's axis range
  monitoring stops the robot (RESULTS "A joint pushed to its limit");
* **done** when the trajectory has ended, the gap to its last point is at most ``d_dist``,
  and the arm has come to rest (or ``settle_time`` has passed since the end);
* **echo** when the measured positions have followed the moving command as the driver
  sends it for ``echo_time`` seconds: a driver that reports the position it commands (the
  lbr stack's ``open_loop``) does, and it would hide every block.  It reports the command
  after its filter (:class:`~probdis_ros.motion.jtc.FirstOrderFilter`), which lags the
  path by tens of milliseconds, so each state is held against the command passed through
  the driver's filter (``driver_tau``) and against the command itself, a few controller
  periods either way, while the joints A1-A4 move (:data:`ECHO_JOINTS`): in joint impedance
  they lag the command by tens of milliseconds;
* **not executed**, where the caller expects the arm to move (``expect_motion``: a path from
  a free arm), when a gap-based block is seen, ``START_WAIT`` has passed (or a gap exceeds
  its ceiling: the force stays bounded while a late controller is waited for), and the arm
  has not moved at all since the command began: nothing executes the command (an inactive
  controller), or something else holds the arm; that is no block to learn.  Where the joint
  states carry efforts, an arm whose external torque rose by ``HELD_TORQUE_RISE`` toward the
  command meanwhile, beyond its noise, and presses toward it by as much now (a block's torque
  that fades after the command began rises too), is held where it stood (the command runs and
  pulls it): blocked.  An arm that begins to move later than the command said (a large
  message delivered late, a busy controller) was started late by its controller: the command
  is judged from when it began (the trajectory's ``taken_at`` moves on by the delay), not
  taken for a block.  A command that need not move the arm (a retreat, a path from an arm
  pressed against something) is waited for alike, but for ``RETREAT_START_WAIT`` at most and
  not once its external torque shows it held, and is **blocked** if the arm has not moved by
  then: a retreat taken late is no block (it was called one, and the late retreat then moved
  the arm the run held at rest).  But where the joint states carry efforts, one whose arm
  presses on nothing (below ``HELD_TORQUE_RISE`` either way on the joints it pulls: neither
  its spring nor the command before it presses the arm) is waited for as a path is, and not
  executed if the arm has not moved by ``START_WAIT``.  A command that starts pressed in is
  not waited for.  A short path whose gap never passes ``d_dist`` is not executed if it has
  not moved the arm by ``START_WAIT``.  Nor is a command the arm **let go of**: it moved,
  then came to rest short of the command (a gap block) while pressing toward it by less than
  ``HELD_TORQUE_RISE``, where the joint states carry efforts: a blocked arm presses with its
  spring, stiffness x the gap; an arm its driver holds (the lbr guard that sends the measured
  position) presses on nothing.  That is no block to learn either; it is waited for until
  ``START_WAIT`` has passed since the command began (a controller that took the command late,
  unseen because the arm still settled from the command before, leaves such a gap).  An arm
  whose gap block (a ceiling, the stall's or the end's test) comes while it still moves,
  pressing by less than that, is waited for while it slows down, up to ``COAST_WAIT``, to
  come to rest and judged there: a held arm coasts on.

A command that starts **pressed in** (``pressed_start``: JTC started it from its last
command, ``interpolate_from_desired_state``, while the arm was held short of that command
by more than ``d_dist``, as right after a block) cannot be followed until the command comes
back to the arm: its gap is no block until then.  The gap tests (and the torque ceiling)
wait until the delayed command's position has come back to the measured one at every joint
that started pressed by more than :data:`PRESS_TOLERANCE` (each in the direction it was
pressed), or the gap is within ``d_dist``, or the command has ended; they then start afresh
(stall history and onset trace from that moment).

Motion is judged through the noise (:func:`motion_over`): a straight line fitted to each
joint over the window gives the motion, and the joint-state noise (estimated from the
samples' second differences, none across a gap in the stream: ``STATE_GAP``) widens the
threshold by ``NOISE_SIGMAS`` standard errors, so that 0.005 rad of noise at 1 kHz neither
hides a stall nor looks like motion.

The ceilings and ``onset_gap`` grow by ``speed_allowance`` x the commanded speed (per joint,
or L1; the largest over the last ``speed_allowance`` seconds of the command the arm is
compared with): the lag that remains in fast free motion, for an arm that lags its command
by up to ``speed_allowance`` more than ``motion_delay``.  The **onset** of a block is where
the gap last began to rise before it crossed that threshold: the arm touched the obstacle
there, earlier than where it is when the block is declared (it swings and slides on while
the unblocked joints follow the command).  No rclpy: plain seconds and arrays.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from functools import lru_cache
import math

import numpy as np
from probdis_ros.motion.jtc import CONTROLLER_RATE, DRIVER_FILTER_TAU, FirstOrderFilter

#: The span over which the gap's growth is judged when tracing a block back to its onset [s].
RISE_WINDOW = 0.1
#: Motion within this many standard errors of the noise is no motion.
NOISE_SIGMAS = 3.0
#: The arm's position at the start of a command, and now, are averaged over this long [s].
ENDS = 0.05
#: A free arm that has not moved this long [s] after a command began is not executing it
#: (or sooner, once a gap passes its ceiling: an arm held from rest presses no harder while
#: the controller may still be taking the command late than a blocked one does).
START_WAIT = 2.0
#: A retreat (or a path from an arm pressed against something), which need not move the
#: arm, is waited for this long [s] at most: an arm pressed from two sides after a block
#: is pressed the longer the longer it is waited for (a stall is seen after stall_time);
#: one that presses on nothing (with efforts) is waited for as a path, ``START_WAIT``.
RETREAT_START_WAIT = 0.5
#: [Nm, L1 over the joints] an arm that has not moved while its external-torque estimate rose
#: this much toward the command since the command began (means over ENDS) is held by
#: something: JTC runs the command and the impedance's spring pulls the arm toward it
#: (200 Nm/rad x the gap: 20 Nm at d_dist), where a controller that runs nothing leaves the
#: torques as they were, but for their noise.  Likewise an arm that moved, then came to rest
#: short of its command: blocked, it presses toward the command at least this hard (18 Nm and
#: more in every block of the training worlds, RESULTS "An arm that lets go"); a driver
#: that holds it presses nowhere.
HELD_TORQUE_RISE = 5.0
#: An arm that moved and passed a gap block while still moving, pressing toward its command
#: by less than ``HELD_TORQUE_RISE``, is waited for this long [s] at most, while it slows
#: down, to come to rest (where the let-go test judges it): a driver that holds the arm
#: lets it coast on.
COAST_WAIT = 1.0
#: [1/s] the external-torque observer follows a change at this rate (time constant 40 ms):
#: quick beside a block's build-up, slow enough to smooth the efforts' noise
OBSERVER_GAIN = 25.0
#: [s] after a longer pause between joint states the observer keeps its estimate and takes
#: the momentum afresh (a difference over the pause says little of the torque)
OBSERVER_RESTART = 0.1
#: The held test compares means of at least this many torque samples per window (fewer
#: give no spread to judge their noise by: no held arm is then seen)
HELD_SAMPLES = 2
#: A controller that took a command later than this [s] after it was sent took it late.
LATE_TAKE = 0.05
#: An arm that moved no more than noise and ``stall_motion`` over this long [s] has come to
#: rest: a command is done once its end is reached and the arm rests there.
SETTLE_WINDOW = 0.1
#: ... judged on at least this many states (fewer: not at rest)
SETTLE_SAMPLES = 4
#: Two states further apart than this many periods of the stream (:class:`StateStream`),
#: and than ``MIN_STATE_GAP`` [s], have a gap between them: states lost or held up on their
#: way.  A second difference across a gap holds the arm's motion over it, so the noise is
#: judged on the others alone (a mock catching up sent states 0.1 s apart: an arm that moved
#: 0.2 rad in 0.3 s read as stalled, one still as started).
STATE_GAP = 4.0
MIN_STATE_GAP = 0.03
#: An echo is looked for this far [s] either way of a state's time (the controller's phase
#: and the state's delivery are not known), in steps of ECHO_STEP [s].
ECHO_WINDOW = 0.03
ECHO_STEP = 0.001
#: The joints whose motion an echo is judged on: the iiwa's A1-A4 carry the arm's inertia and
#: lag their command by tens of milliseconds in joint impedance, where a wrist joint moving
#: alone can follow it within a tenth of a millisecond (the physics mock's A5-A7), as an
#: echo does.
ECHO_JOINTS = slice(0, 4)
#: A joint whose command starts more than this [rad] beyond the measured position is pressed
#: in; it is back within reach when its command has come to within this of the arm.
PRESS_TOLERANCE = 0.01
#: A joint within ``limit_room`` of its limit is pushed toward it when it is nearer to the limit
#: than its command (less the speed allowance) and than where it stood when the command began,
#: by more than this [rad]: well above the joint states' noise, and more than an arm that
#: lags its command by ``motion_delay`` leaves at a turn near the limit.
LIMIT_PUSH = 0.01
#: ... and within ``limit_room`` of it once pushed on this long [s] at the speed at which it
#: moves toward it beyond its command (over ``SETTLE_WINDOW``): a blocked arm comes to rest
#: that much further on (A3 pushed at 0.14 rad/s past a command at rest on the physics mock
#: went 13 mrad on after its block, as the retreat braked the arm).
LIMIT_HORIZON = 0.15
#: Only joints this near [rad] their limits are judged so (the rest cost nothing).
LIMIT_NEAR = 0.3


def noise_of(positions: np.ndarray) -> np.ndarray:
    """
    Return each joint's noise (std. dev.) in consecutive samples (N, n), from second differences.

    A smooth motion adds next to nothing to a second difference; white noise of std. dev. s
    gives second differences of variance 6 s^2.
    """
    return _second_difference_noise(np.asarray(positions, dtype=float))[1]


def _second_difference_noise(positions: np.ndarray, times: np.ndarray | None = None,
                             longest: float = math.inf) -> tuple[int, np.ndarray]:
    """Return how many second differences judged the noise, and the noise (0: none)."""
    if len(positions) < 3:
        return 0, np.zeros(positions.shape[1:])
    second = positions[2:] - 2.0 * positions[1:-1] + positions[:-2]
    if times is not None:
        spacing = np.diff(times)
        second = second[(spacing[1:] <= longest) & (spacing[:-1] <= longest)]
        if not len(second):
            return 0, np.zeros(positions.shape[1:])
    return len(second), np.sqrt(np.mean(second ** 2, axis=0) / 6.0)


def motion_over(times: np.ndarray, positions: np.ndarray,
                noise: np.ndarray | None = None) -> tuple[float, float]:
    """
    Return the L1 motion over samples (times, positions (N, n)) and what noise could fake.

    The motion is each joint's least-squares slope times the span (an endpoint-to-endpoint
    measure that averages the noise out); the second value is ``NOISE_SIGMAS`` times the sum
    of those estimates' standard errors.  noise: each joint's (default :func:`noise_of`).
    """
    times = np.asarray(times, dtype=float)
    positions = np.asarray(positions, dtype=float)
    slope, spread = _line_fit(times, positions)
    if spread == 0.0:
        return 0.0, 0.0
    span = times[-1] - times[0]
    error = (noise_of(positions) if noise is None else noise) * span / np.sqrt(spread)
    return float(np.abs(slope).sum() * span), NOISE_SIGMAS * float(error.sum())


def slope_of(times: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Return each joint's least-squares slope over samples (times, positions (N, n))."""
    return _line_fit(np.asarray(times, dtype=float), np.asarray(positions, dtype=float))[0]


def _line_fit(times: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, float]:
    """Return each joint's least-squares slope and the times' sum of squares about their mean."""
    if len(times) < 2 or times[-1] <= times[0]:
        return np.zeros(positions.shape[1:]), 0.0
    t = times - times.mean()
    spread = float(np.sum(t * t))
    return (t @ (positions - positions.mean(axis=0))) / spread, spread


class Verdict(str, Enum):
    """What the detector says about the running motion."""

    MOVING = 'moving'
    DONE = 'done'
    BLOCKED = 'blocked'
    ECHO = 'echo'
    NOT_EXECUTED = 'not_executed'


#: [m] the farthest a grasped load's centre of mass may lie from the flange, per coordinate
LOAD_COM_REACH = 1.0


@dataclass
class DetectorSettings:
    """Thresholds of the detector; every default in one place (README "Detection")."""

    d_dist: float = 0.1             # the paper's d_DIST: L1 gap of a blocked motion [rad]
    stall_time: float = 0.3         # without progress for this long counts as stalled [s]
    stall_motion: float = 0.005     # L1 motion over stall_time below which it is stalled [rad]
    settle_time: float = 0.5        # after the end, the gap must close within this [s]
    motion_delay: float = 0.1       # how far the arm lags its command [s]
    gap_ceiling: float = 0.3        # L1 gap that is a block at once [rad]; 0: off
    joint_gap_ceiling: float = 0.15  # one joint's gap that is a block at once [rad]; 0: off
    onset_gap: float = 0.06         # the block began where the gap last rose above this [rad]
    speed_allowance: float = 0.1    # ceilings and onset_gap grow by this x commanded speed [s]
    onset_window: float = 1.0       # the rise is traced back at most this far [s]
    onset_rate: float = 0.1         # L1 gap growth [rad/s] over 0.1 s that is still a rise
    echo_time: float = 0.5          # seconds of motion as the driver sends it: an echo; 0: off
    echo_speed: float = 0.05        # commanded L1 speed [rad/s] that counts as moving
    driver_tau: float = DRIVER_FILTER_TAU  # the driver's command filter [s], for the echo
    torque_ceiling: float = 0.0     # external torque [Nm] at a joint that is a block; 0: off
    limit_room: float = 0.02        # a joint pushed to within this of its limit: a block [rad]
    load_mass: float = 0.0          # the grasped load for that estimate [kg] ...
    load_com: tuple[float, float, float] = (0.0, 0.0, 0.0)  # ... at this point [m], flange frame

    def __post_init__(self) -> None:
        """Refuse thresholds that cannot work, naming them."""
        for name in ('d_dist', 'stall_time', 'stall_motion', 'settle_time', 'onset_gap',
                     'echo_speed', 'onset_window', 'onset_rate'):
            if not 0 < getattr(self, name) < math.inf:
                raise ValueError(f'{name} must be a positive number, got {getattr(self, name)}')
        for name in ('motion_delay', 'gap_ceiling', 'joint_gap_ceiling', 'echo_time',
                     'speed_allowance', 'torque_ceiling', 'limit_room', 'load_mass',
                     'driver_tau'):
            if not 0 <= getattr(self, name) < math.inf:
                raise ValueError(f'{name} must be a number >= 0, got {getattr(self, name)}')
        if len(self.load_com) != 3:
            raise ValueError(f'load_com must be 3 coordinates [m], got {list(self.load_com)}')
        self.load_com = tuple(float(c) for c in self.load_com)
        # NaN made every torque estimate NaN, and the torque ceiling never fired
        if not all(abs(c) <= LOAD_COM_REACH for c in self.load_com):
            raise ValueError(f'load_com must be within {LOAD_COM_REACH:g} m of the flange in '
                             f'each coordinate, got {list(self.load_com)}')
        if 0 < self.gap_ceiling <= self.d_dist:
            raise ValueError(f'gap_ceiling {self.gap_ceiling} must exceed d_dist {self.d_dist}')


@lru_cache(maxsize=8)
def gravity_model(load_mass: float, load_com: tuple[float, float, float]
                  ) -> Callable[[np.ndarray], np.ndarray]:
    """Return the iiwa's g(q) with a load (one per load: pinocchio reads the URDF once)."""
    from probdis_ros.motion.gravity import GravityModel

    return GravityModel(load_mass=load_mass, load_com=load_com)


def external_torque(settings: DetectorSettings, q: np.ndarray, effort: np.ndarray | None
                    ) -> np.ndarray | None:
    """
    Return the external-torque estimate [Nm]: measured efforts minus g(q) of arm and load.

    None where the efforts give none: absent, not one per joint of q, or not finite (a
    driver's glitch must not read as a push, nor hide one as NaN would in comparisons).
    """
    effort = _per_joint(effort, q)
    if effort is None:
        return None
    gravity = gravity_model(settings.load_mass, tuple(settings.load_com))
    return effort - gravity(q)


def _per_joint(values: np.ndarray | None, q: np.ndarray) -> np.ndarray | None:
    """Return values as floats if finite and one per joint of q, else None."""
    if values is None:
        return None
    values = np.asarray(values, dtype=float)
    return values if values.shape == np.shape(q) and np.all(np.isfinite(values)) else None


class ExternalTorqueObserver:
    """
    The external-torque estimate with the arm's dynamics, from a stream of joint states.

    ``effort - g(q)`` (:func:`external_torque`) also holds the torques that accelerate the
    arm, ``M(q) q'' + C(q, q') q'``: on the physics mock at velocity scaling 0.2, up to 14 Nm
    at A2 in free motion, as much as a light contact.  A momentum observer (De Luca's, as
    robot controllers use) needs no acceleration: the momentum ``p = M(q) q'`` obeys
    ``p' = tau + tau_ext + C^T q' - g``, so ``p'`` less the known terms, low-passed at
    ``OBSERVER_GAIN``, is the external torque.  The estimate keeps external_torque()'s sign
    and equals it at rest; it starts from there (at the first state, after one without
    velocities, or should it stop being finite).  After a pause of more than
    ``OBSERVER_RESTART`` it keeps its estimate and takes the momentum afresh: starting
    again from effort - g(q) mid-motion would count the arm's inertia as a push.  A
    state stamped no later than the last is skipped.

    ``static``: effort - g(q) at the last state (None without efforts): exact for an arm
    at rest, and its noise is the driver's, sample by sample, where the estimate's is
    low-passed (the held test judges noise by the samples' spread).
    """

    def __init__(self, settings: DetectorSettings, gain: float = OBSERVER_GAIN) -> None:
        """Observe with settings' load data at gain [1/s]."""
        if not (math.isfinite(gain) and gain > 0):
            raise ValueError(f'the observer gain must be positive, got {gain}')
        self.settings = settings
        self.gain = gain
        self.estimate: np.ndarray | None = None
        self.static: np.ndarray | None = None
        self._last: tuple[float, np.ndarray] | None = None     # time, momentum

    def update(self, now: float, q: np.ndarray, velocity: np.ndarray | None,
               effort: np.ndarray | None) -> np.ndarray | None:
        """Return the estimate [Nm] after a joint state at now [s]; None without efforts."""
        velocity = _per_joint(velocity, q)
        if velocity is None or _per_joint(effort, q) is None:
            self._last = None
            self.estimate = self.static = external_torque(self.settings, q, effort)
            return self.estimate
        model = gravity_model(self.settings.load_mass, tuple(self.settings.load_com))
        momentum, coriolis, gravity = model.momentum(q, velocity)
        effort = np.asarray(effort, dtype=float)
        self.static = effort - gravity
        last = self._last
        dt = None if last is None else now - last[0]
        if dt is not None and dt <= 0.0:
            return self.estimate                        # not a later state: nothing to add
        self._last = (now, momentum)
        if dt is None or self.estimate is None:
            self.estimate = self.static                 # as at rest: external_torque()
            return self.estimate
        if dt > OBSERVER_RESTART:
            return self.estimate
        # the external torque this step alone shows (sign as external_torque: -tau_ext)
        seen = effort + coriolis - gravity - (momentum - last[1]) / dt
        estimate = self.estimate + (1.0 - math.exp(-self.gain * dt)) * (seen - self.estimate)
        self.estimate = estimate if np.all(np.isfinite(estimate)) else self.static
        return self.estimate


class SentCommand:
    """
    The command as a driver sends it on, once per controller period, through its filter.

    JTC commands the path one period ahead at each update; the driver's first-order filter
    passes that on, starting from where the path starts (for an echoing driver, the
    position it reported when JTC took the path).  Sampled at the updates, linear between.
    """

    def __init__(self, path, tau: float, period: float = 1.0 / CONTROLLER_RATE) -> None:
        self.path = path
        self.period = period
        self.filter = FirstOrderFilter(tau, period)
        self.filter.reset(path.at(0.0))
        # the commands sent so far, one row per period: a buffer that doubles as it fills
        # (rebuilt from a list at every state, it took 60 % of a replay's time)
        self._values = self.filter.value[None].repeat(64, axis=0)
        self._count = 1

    def at(self, times: np.ndarray) -> np.ndarray:
        """Return the commands sent at times [s from the path's start] (N, n)."""
        steps = np.maximum(np.asarray(times, dtype=float), 0.0) / self.period
        needed = int(steps.max()) + 2
        if needed > len(self._values):
            grown = np.empty((max(needed, 2 * len(self._values)), self._values.shape[1]))
            grown[:self._count] = self._values[:self._count]
            self._values = grown
        while self._count < needed:
            self._values[self._count] = self.filter(self.path.at(self._count * self.period))
            self._count += 1
        values = self._values
        k = np.floor(steps).astype(int)
        w = (steps - k)[:, None]
        return values[k] * (1.0 - w) + values[k + 1] * w


@dataclass(frozen=True)
class Onset:
    """Where a block began: the time, the measured configuration, the commanded velocity."""

    time: float
    config: np.ndarray
    velocity: np.ndarray


class StateStream:
    """
    What the joint states' stream has shown: its period, and its noise where last judged.

    One per stream (the run's, handed to each path's detector), so that a path that begins
    in a gap knows the stream was denser, and its noise, before it.  The period is the 10th
    percentile of the last ``size`` spacings, not their median: a mock stopped most of the
    time sent four fifths of its states 0.1 s apart, and those gaps became the period.
    """

    def __init__(self, size: int = 200) -> None:
        self._spacings: deque[float] = deque(maxlen=size)
        self._last: float | None = None
        self._period: float | None = None       # computed when asked, after a new spacing
        self.noise: np.ndarray | None = None    # each joint's, where last judged [rad]

    def add(self, now: float) -> None:
        """Note a state at now [s] (a repeated or earlier time adds nothing)."""
        if self._last is not None and now > self._last:
            self._spacings.append(now - self._last)
            self._period = None
        self._last = now if self._last is None else max(self._last, now)

    @property
    def period(self) -> float:
        """Return the stream's period; inf before two states."""
        if self._period is None:
            self._period = float(np.quantile(self._spacings, 0.1)) if self._spacings \
                else math.inf
        return self._period

    @property
    def longest(self) -> float:
        """Return the longest spacing that is no gap [s]."""
        return max(STATE_GAP * self.period, MIN_STATE_GAP)


class BlockDetector:
    """
    Watches one trajectory: feed it (time, measured configuration) samples.

    ``path`` is anything with ``at(t)`` / ``sample(t)`` and ``duration`` in seconds from
    ``start_time`` (a :class:`~probdis_ros.motion.jtc.JtcTrajectory`).  ``limits``: the
    arm's (lower, upper) joint limits [rad], for the test of a joint pushed toward one (None:
    no such test).
    """

    def __init__(self, path, start_time: float, settings: DetectorSettings | None = None,
                 expect_motion: bool = False,
                 pressed_start: tuple[np.ndarray, np.ndarray] | None = None,
                 limits: tuple[np.ndarray, np.ndarray] | None = None,
                 stream: StateStream | None = None) -> None:
        self.path = path
        # the stream's period and noise; given one, its owner notes the states, else this
        self._own_stream = stream is None
        self.stream = StateStream() if stream is None else stream
        self._limits = None if limits is None else \
            (np.asarray(limits[0], dtype=float), np.asarray(limits[1], dtype=float))
        # (the command's start position, the measured one) of a command that starts pressed
        # in: which joints, and in which direction, must come back before the gap counts
        self._pressed: np.ndarray | None = None
        if pressed_start is not None:
            offset = np.asarray(pressed_start[0], dtype=float) - np.asarray(
                pressed_start[1], dtype=float)
            sign = np.where(np.abs(offset) > PRESS_TOLERANCE, np.sign(offset), 0.0)
            if np.any(sign):
                self._pressed = sign
        self.released_at: float | None = None
        self.expect_motion = expect_motion      # a block without any motion: not executed
        # the arm has been seen to move; a command that starts pressed in is not waited for
        # (it starts the press gap away from the arm: a late take cannot be told from it)
        self.started = self._pressed is not None
        self.late = 0.0                         # how late the controller took the command [s]
        self._first: list[np.ndarray] = []     # the samples of the first ENDS seconds
        self.settings = settings or DetectorSettings()
        self.start_time = start_time
        self._history: deque[tuple[float, np.ndarray]] = deque()
        self._rising: tuple[float, np.ndarray, np.ndarray] | None = None
        self._recent: deque[tuple[float, float, np.ndarray, np.ndarray]] = deque()
        self._echo_since: float | None = None
        taus = dict.fromkeys((self.settings.driver_tau, 0.0))
        self._sent = [SentCommand(path, tau) for tau in taus] if self.settings.echo_time \
            else []
        self.gap = 0.0
        self.joint_gaps = np.zeros(0)
        self.external_torque: np.ndarray | None = None
        # the joints the torque ceiling judges: a command that need not move the arm (a
        # retreat, a path from a pressed arm) may begin with the press's torque still above
        # the ceiling (the driver's torque filter, the observer lag it by 0.1 s and more), so
        # such a joint is judged once its torque has come below the ceiling
        self._ceiling_armed: np.ndarray | None = None
        # external-torque estimates of the first and of the last ENDS seconds (with efforts)
        self._first_torques: list[np.ndarray] = []
        self._torques: deque[tuple[float, np.ndarray]] = deque()
        self._pull = np.zeros(0)        # the command less the arm at the last sample [rad]
        # a gap block waited for while the arm coasts: (since, last seen, L1 speed [rad/s] at
        # the last judgement, judged at) [s]
        self._coast: tuple[float, float, float, float] | None = None
        self.onset: Onset | None = None
        self.reason = ''

    def _desired(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Return the commanded position the arm should be at t, and the command's velocity."""
        q, v, _ = self.path.sample(t - self.settings.motion_delay)
        return q, v

    def update(self, now: float, measured: np.ndarray, external: np.ndarray | None = None,
               static: np.ndarray | None = None) -> Verdict:
        """
        Return the verdict after a new measurement at now [s].

        ``external``: the external-torque estimate at this state (the caller's
        :class:`ExternalTorqueObserver`, or :func:`external_torque`), where the joint states
        carry efforts; the caller computes it once for every use.  ``static``: effort - g(q)
        at this state (the observer's ``static``; default ``external``), which the held test
        takes: its arm has not moved, and its noise is judged by the samples' spread, which
        the observer's low-pass would hide.
        """
        s = self.settings
        t = now - self.start_time
        measured = np.asarray(measured, dtype=float)
        desired, velocity = self._desired(t)
        self._pull = desired - measured
        self.joint_gaps = np.abs(self._pull)
        self.gap = float(self.joint_gaps.sum())
        # the lag left in fast free motion: an arm lagging up to speed_allowance more than
        # motion_delay still moves as fast as the command did then (as a path ends, the
        # command's speed at one instant fell while such an arm's gap had not: a false block)
        lagging = t - s.motion_delay
        allowance = s.speed_allowance * np.maximum(
            np.abs(velocity), self.path.peak_speed(lagging - s.speed_allowance, lagging))
        self._track_onset(now, measured, velocity, s.onset_gap + float(allowance.sum()))
        if self._own_stream:
            self.stream.add(now)
        self._history.append((now, measured.copy()))
        if t <= ENDS or not self._first:
            self._first.append(measured.copy())
        while self._history and self._history[0][0] < now - s.stall_time:
            self._history.popleft()
        ended = t >= self.path.duration + s.motion_delay
        # the echo on the time the command was sent, not moved on for a late take: an arm that
        # lags its command looks taken late, and that shift would line its lag up with the path
        if self._echoes(now, t + self.late, measured, velocity):
            self.reason = (f'the measured positions followed the command as the driver '
                           f'sends it for {s.echo_time:.1f} s')
            return Verdict.ECHO
        if not self.started and self._begins_late(now):
            return Verdict.MOVING           # judged from when it began, from the next sample
        if self._pressed is not None:
            if not self._released(now, t, desired, measured, ended):
                return Verdict.MOVING
        if external is not None:
            self.external_torque = external
            at_rest = external if static is None else static
            if t <= ENDS or not self._first_torques:
                self._first_torques.append(at_rest)
            self._torques.append((now, at_rest))
            while self._torques[0][0] < now - ENDS:
                self._torques.popleft()
        if s.torque_ceiling and self.external_torque is not None:
            magnitude = np.abs(self.external_torque)
            below = magnitude <= s.torque_ceiling
            self._ceiling_armed = below | self.expect_motion if self._ceiling_armed is None \
                else self._ceiling_armed | below
            over = np.where(self._ceiling_armed, magnitude - s.torque_ceiling, -np.inf)
            if over.max() > 0:
                joint = int(over.argmax())
                return self._blocked(f'joint A{joint + 1} external torque '
                                     f'{abs(self.external_torque[joint]):.1f} Nm above '
                                     f'{s.torque_ceiling:.1f} Nm')
        pushed = self._pushed_to_limit(measured, desired, velocity, allowance)
        if pushed:
            return self._blocked(pushed)
        if ended and self.gap <= s.d_dist:
            if self._should_move():
                if self._history[-1][0] - self.start_time < START_WAIT:
                    return Verdict.MOVING       # a short path the controller may take late
                return self._gap_block(f'gap {self.gap:.3f} rad, within d_dist, at its end')
            if self._settled() or t >= self.path.duration + s.motion_delay + s.settle_time:
                return Verdict.DONE
            return Verdict.MOVING       # on its way still: the run takes where it comes to rest
        if self.gap <= s.d_dist:
            return Verdict.MOVING
        ceiling = s.gap_ceiling + float(allowance.sum())
        if s.gap_ceiling and self.gap > ceiling:
            return self._gap_block(f'gap {self.gap:.4f} rad above the ceiling {ceiling:.4f}')
        over = self.joint_gaps - (s.joint_gap_ceiling + allowance)
        if s.joint_gap_ceiling and over.max() > 0:
            joint = int(over.argmax())
            limit = s.joint_gap_ceiling + allowance[joint]
            return self._gap_block(f'joint A{joint + 1} gap {self.joint_gaps[joint]:.4f} rad '
                                   f'above its ceiling {limit:.4f}')
        if ended and t >= self.path.duration + s.motion_delay + s.settle_time:
            return self._gap_block(f'gap {self.gap:.3f} rad {s.settle_time} s after the end')
        if now - self._history[0][0] >= s.stall_time * 0.9 and \
                (sigma := self._noise()) is not None:
            times = np.array([when for when, _ in self._history])
            motion, noise = motion_over(times, np.array([q for _, q in self._history]), sigma)
            if motion < s.stall_motion + noise:
                return self._gap_block(f'stalled with gap {self.gap:.3f} rad (moved {motion:.3f} '
                                       f'rad in {times[-1] - times[0]:.2f} s)')
        return Verdict.MOVING

    def _pushed_to_limit(self, measured: np.ndarray, desired: np.ndarray,
                         velocity: np.ndarray, allowance: np.ndarray) -> str:
        """
        Name a joint pushed to within ``limit_room`` of its limit ('' if none).

        Or one that would be there ``LIMIT_HORIZON`` on, pushed on as fast as it moves toward
        it beyond its command's velocity (``velocity``: the command stops, the push need not
        at once).

        Nearer to the limit than its command, beyond the lag that fast motion leaves (an arm
        that lags is ahead of a command that turns back from near the limit), and than where
        it stood when the command began (an arm at rest near a limit, whose command leaves it
        late, is pushed by nothing), each by more than ``LIMIT_PUSH`` beyond ``NOISE_SIGMAS``
        standard deviations of the joint's noise: one state's noise is no push (its room is
        taken as measured: the push guards it, and a noisy arm near a limit is judged no
        later).
        """
        room_limit = self.settings.limit_room
        if not room_limit or self._limits is None:
            return ''
        lower, upper = self._limits
        room = np.minimum(measured - lower, upper - measured)
        near = room < LIMIT_NEAR
        if not near.any():          # as nearly always: nothing more to compute per state
            return ''
        outward = np.where(upper - measured < measured - lower, 1.0, -1.0)
        beyond = np.minimum((measured - desired) * outward - allowance,
                            (measured - np.mean(self._first, axis=0)) * outward)
        if not np.any(near & (beyond > LIMIT_PUSH)):
            return ''
        times, positions = self._last_window()
        speed = np.maximum((slope_of(times, positions) - velocity) * outward, 0.0)
        sigma = self._noise()
        noise = NOISE_SIGMAS * (np.zeros(len(measured)) if sigma is None else sigma)
        pushed = (room - speed * LIMIT_HORIZON < room_limit) & (beyond - noise > LIMIT_PUSH)
        if not pushed.any():
            return ''
        joint = int(np.argmin(np.where(pushed, room, np.inf)))
        return (f'joint A{joint + 1} pushed toward its limit: {room[joint]:.4f} rad from it, '
                f'{(measured[joint] - desired[joint]) * outward[joint]:.4f} rad past its '
                f'command')

    def _should_move(self) -> bool:
        """
        Tell whether a path that should visibly move the arm has not moved it yet.

        Its gap may never pass ``d_dist`` (a short path), so nothing else would wait for a
        controller that takes it late, or tell that nothing runs it.
        """
        if self.started or not self.expect_motion:
            return False
        first = np.mean(self._first, axis=0)
        _, allowance = self.moved()
        return float(np.abs(self.path.at(self.path.duration) - first).sum()) > 2.0 * allowance

    def _settled(self) -> bool:
        """
        Tell whether the arm has come to rest: moved no more than noise over ``SETTLE_WINDOW``.

        A command taken late (or an arm that lags) is within ``d_dist`` of its end before the
        arm gets there: taken as done then, the run saw the arm short of the goal, planned
        from there and sent a path back to where it had been, again and again (a command
        latency of 0.25 s on the physics demo: 18 paths, 13 of them ended short of the goal
        without a block).  Fewer than ``SETTLE_SAMPLES`` states within the window (slow
        joint states, or just after a release) tell nothing: not at rest (``settle_time``
        after the end bounds the wait); over a longer window the noise estimate would take
        the arm's deceleration for noise.
        """
        times, positions = self._last_window()
        if len(times) < SETTLE_SAMPLES:
            return False
        motion, noise = motion_over(times, positions)
        return motion <= self.settings.stall_motion + noise

    def _last_window(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the times and positions of the states of the last ``SETTLE_WINDOW``."""
        now = self._history[-1][0]
        recent = [sample for sample in self._history if sample[0] >= now - SETTLE_WINDOW]
        return np.array([when for when, _ in recent]), np.array([q for _, q in recent])

    def _released(self, now: float, t: float, desired: np.ndarray, measured: np.ndarray,
                  ended: bool) -> bool:
        """
        Tell whether a command that started pressed in has come back within the arm's reach.

        On release the stall history and the onset trace start afresh from this sample.
        """
        ahead = self._pressed * (desired - measured)      # > 0: still pressed in
        back = ahead[self._pressed != 0] <= PRESS_TOLERANCE
        if not (back.all() or self.gap <= self.settings.d_dist or ended):
            return False
        self._pressed = None
        self.released_at = now
        self._history.clear()
        self._history.append((now, measured.copy()))
        self._recent.clear()
        self._recent.append((now, self.gap, measured.copy(), self._desired(t)[1].copy()))
        self._rising = None
        return True

    @property
    def pressed(self) -> bool:
        """Tell whether the command began pressed in and has not yet come back to the arm."""
        return self._pressed is not None

    def _noise(self) -> np.ndarray | None:
        """
        Return each joint's noise in the history, judged apart from its gaps (None: unknown).

        Judged on no second difference (fewer than three states, or all across gaps), it is
        the stream's where last judged, unknown before: as zero, two states 0.1 s apart
        told a path that had not begun from its noise as begun.
        """
        history = self._history
        count, sigma = _second_difference_noise(
            np.array([q for _, q in history]), np.array([when for when, _ in history]),
            self.stream.longest)
        if count:
            self.stream.noise = sigma
            return sigma
        return self.stream.noise

    def moved(self) -> tuple[float, float]:
        """
        Return how far (L1) the arm has moved since the command began, and the noise allowance.

        The mean of the first ``ENDS`` seconds' samples against the mean of the last ``ENDS``
        seconds'; the allowance is ``NOISE_SIGMAS`` standard errors of that difference plus
        ``stall_motion``.
        """
        now = self._history[-1][0]
        last = np.array([q for when, q in self._history if when >= now - ENDS])
        first = np.array(self._first)
        sigma = self._noise()
        if sigma is None:       # no noise to judge by yet: no motion is told from it
            return float(np.abs(last.mean(axis=0) - first.mean(axis=0)).sum()), math.inf
        error = sigma * np.sqrt(1.0 / len(first) + 1.0 / len(last))
        return (float(np.abs(last.mean(axis=0) - first.mean(axis=0)).sum()),
                self.settings.stall_motion + NOISE_SIGMAS * float(error.sum()))

    def _begins_late(self, now: float) -> bool:
        """
        Tell whether the arm, still until now, has begun to move later than the command said.

        If so, the command's start moves on to match (the controller took it late), unless
        the command is stamped (a desired start's from a moving command): JTC then runs it
        from its stamp whenever it takes it.
        """
        if not self._first or len(self._history) < 2:
            return False
        moved, allowance = self.moved()
        if moved <= allowance:
            return False
        self.started = True
        if getattr(getattr(self.path, 'command', None), 'stamp', 0.0) > 0:
            return False        # stamped: JTC runs it on its own time line, late or not
        # when the command had moved as far from its start as the arm has from its own (the
        # arm: its mean over the last ENDS seconds, at their mean time), the last time it
        # reached that distance up to where the command is now (an arm lagging it less than
        # motion_delay is ahead of the detector's desired position): a command that first
        # brakes from the noise of a measured velocity at rest and comes back reaches it
        # twice, and the first time read an arm on time as 0.2 s late (its gap as it moved
        # on was called a block).  By distance, not by position: when motion is first seen,
        # the noise of the means at the joints that do not move is as large as it (a match
        # of positions failed at 5 mrad of noise)
        recent = [when for when, _ in self._history if when >= now - ENDS]
        at = float(np.mean(recent)) - self.start_time
        steps = np.arange(0.0, max(at + self.settings.motion_delay, 0.0) + 0.005, 0.005)
        origin = self._desired(0.0)[0]
        short = np.array([float(np.abs(self._desired(tau)[0] - origin).sum())
                          for tau in steps]) < moved
        last = len(steps) - 1 - int(np.argmax(short[::-1]))     # the last still short of it
        late = at - steps[min(last + 1, len(steps) - 1)]
        if late <= LATE_TAKE:
            return False
        self.late += late
        self.start_time += late
        if hasattr(self.path, 'taken_at'):
            self.path.taken_at += late          # the caller's model of the command too
        self._recent.clear()
        self._rising = None
        self._echo_since = None
        return True

    def _gap_block(self, reason: str) -> Verdict:
        """
        Return a block seen in the gap, NOT_EXECUTED (the arm never moved, or let go), or MOVING.

        MOVING: waited for, a controller that may take the command late, an arm that coasts.
        """
        if not self.started:
            s = self.settings
            within = (not s.gap_ceiling or self.gap <= s.gap_ceiling) and \
                (not s.joint_gap_ceiling or self.joint_gaps.max() <= s.joint_gap_ceiling)
            waited = self._history[-1][0] - self.start_time
            if not self.expect_motion:      # a retreat, or a path from a pressed arm
                # held (its torque pulls toward the command) or waited for long enough
                if waited < RETREAT_START_WAIT and within and \
                        self._held_rise().sum() < HELD_TORQUE_RISE:
                    return Verdict.MOVING         # the controller may take it late
                torque = self._pressing(either_way=True)
                if torque is None or torque >= HELD_TORQUE_RISE:
                    return self._blocked(f'{reason}; the arm has not moved in {waited:.2f} s '
                                         f'since the command began')
                # the arm presses on nothing, by this command's spring or the one's before:
                # waited for longer it is pressed no harder, and nothing holds it
                if waited < START_WAIT and within:
                    return Verdict.MOVING
                self.reason = (f'{reason}; the arm has not moved in {waited:.2f} s since the '
                               f'command began, pressing on nothing (its external torque on '
                               f'the joints the command pulls is {torque:.1f} Nm, L1)')
                return Verdict.NOT_EXECUTED
            if waited < START_WAIT and within:
                return Verdict.MOVING             # the controller may take it late
            moved, _ = self.moved()
            still = (f'the arm has not moved since the command began ({moved:.3f} rad L1 in '
                     f'{self._history[-1][0] - self.start_time:.2f} s, {reason})')
            rise = self._held_rise()
            # and presses toward the command now: a block's torque fading after the
            # command began (a driver that holds the arm) rises toward it by as much
            if rise.sum() >= HELD_TORQUE_RISE and (self._pressing() or 0.0) >= HELD_TORQUE_RISE:
                joint = int(rise.argmax())
                return self._blocked(f'held where it stood: {still}, while its external '
                                     f'torque rose by {rise.sum():.1f} Nm toward the command '
                                     f'(L1; A{joint + 1} {rise[joint]:.1f} Nm)')
            self.reason = still
            return Verdict.NOT_EXECUTED
        pressing = self._pressing()
        if pressing is not None and pressing < HELD_TORQUE_RISE:
            now = self._history[-1][0]
            if not self._settled():
                # coasting on, pressing on nothing: a driver that holds the arm lets its gap
                # pass a ceiling before it comes to rest, and a moving arm's torque shows
                # its acceleration besides any press; judged where it rests
                if self._coasting(now):
                    return Verdict.MOVING
                return self._blocked(reason)
            if now - self.start_time < START_WAIT:
                # the controller may have taken it late, after the arm moved on a command
                # before (settling from a block): its gap is then the delay, not a block
                return Verdict.MOVING
            self.reason = (f'{reason}, but the arm rests without pressing on anything: its '
                           f'external torque toward the command is {pressing:.1f} Nm (L1), '
                           f'where a block in joint impedance presses with the stiffness x the '
                           f'gap; it let go of the command')
            return Verdict.NOT_EXECUTED
        return self._blocked(reason)

    def _coasting(self, now: float) -> bool:
        """
        Tell whether an arm past a gap block, pressing on nothing, may coast on to rest.

        Only while it slows down, its L1 speed (over ``SETTLE_WINDOW``) lower at each
        window than at the one before, and for ``COAST_WAIT`` at most: an arm that keeps its
        speed is driven on, and should its efforts not show a contact (a sensor that reads
        nothing), the command would press on for the whole wait.  A wait broken for longer
        than a window (the gap back under its ceiling, the arm at rest) starts afresh.
        """
        speed = float(np.abs(slope_of(*self._last_window())).sum())
        if self._coast is None or now - self._coast[1] > SETTLE_WINDOW:
            self._coast = (now, now, speed, now)    # since, last seen, speed, judged at
            return True
        since, _, before, judged = self._coast
        if now - since >= COAST_WAIT:
            return False
        if now - judged >= SETTLE_WINDOW:
            if speed >= before:
                return False
            before, judged = speed, now
        self._coast = (since, now, before, judged)
        return True

    def _pressing(self, either_way: bool = False) -> float | None:
        """
        Return how hard the arm presses toward the command now [Nm, L1]; None without efforts.

        The mean effort - g(q) of the last ``ENDS`` seconds, on the joints the command pulls
        (beyond ``PRESS_TOLERANCE``), in the pull's direction only (``either_way``: both
        directions, as the arm presses on anything there).  An arm blocked in joint
        impedance presses on what holds it with its spring, stiffness x the gap; one that
        stopped without touching anything presses on nothing: a driver whose guard holds
        the arm sends its measured position, which pulls nowhere.  Judged absolutely, not as
        a rise: a path that begins while a block's torque still fades (the driver's torque
        filter, 0.1 s) would read that fading as a rise toward its command.
        """
        if len(self._torques) < HELD_SAMPLES:
            return None
        pull = self._pulled()
        pulled = pull * np.mean([torque for _, torque in self._torques], axis=0)
        return float(np.abs(pulled).sum() if either_way else np.clip(pulled, 0.0, None).sum())

    def _pulled(self) -> np.ndarray:
        """Return per joint which way the command pulls the arm (0: within PRESS_TOLERANCE)."""
        return np.where(np.abs(self._pull) > PRESS_TOLERANCE, np.sign(self._pull), 0.0)

    def _held_rise(self) -> np.ndarray:
        """
        Return per joint how far the external torque rose toward the command [Nm] (zeros: none).

        The mean of the last ``ENDS`` seconds against the first's, on the joints the command
        pulls (beyond ``PRESS_TOLERANCE``), counted in the pull's direction only: the spring
        of a held arm pulls toward the command; noise and an arm pushed by hand need not.  A
        joint's rise counts only beyond ``NOISE_SIGMAS`` standard errors of the two means
        (the samples' spread about them): an idle arm's torque noise summed over seven
        joints would otherwise pass ``HELD_TORQUE_RISE`` (1.5 Nm per sample: 8 % of idle
        arms called held).  Fewer than ``HELD_SAMPLES`` samples in a window: zeros.
        """
        if min(len(self._first_torques), len(self._torques)) < HELD_SAMPLES:
            return np.zeros(len(self._pull))
        first = np.array(self._first_torques)
        last = np.array([torque for _, torque in self._torques])
        pull = self._pulled()
        rise = pull * (last.mean(axis=0) - first.mean(axis=0))
        n_first, n_last = len(first), len(last)
        spread = (n_first * first.var(axis=0) + n_last * last.var(axis=0)) / \
            (n_first + n_last - 2)
        error = np.sqrt(spread * (1.0 / n_first + 1.0 / n_last))
        return np.where(rise > NOISE_SIGMAS * error, rise, 0.0)

    def _blocked(self, reason: str) -> Verdict:
        self.reason = reason
        if self.onset is None and self._rising is not None:
            self.onset = Onset(*self._rising)
        return Verdict.BLOCKED

    def _track_onset(self, now: float, measured: np.ndarray, velocity: np.ndarray,
                     threshold: float) -> None:
        """
        When the gap crosses the onset threshold, trace the rise back to where it began.

        Walking back from the crossing (at most ``onset_window``) while the gap grew faster
        than ``onset_rate`` over the 0.1 s before each sample ends where it began to rise:
        the arm was still tracking there (its gap steady), then touched, and the gap grew.
        """
        s = self.settings
        self._recent.append((now, self.gap, measured.copy(), velocity.copy()))
        while self._recent[0][0] < now - s.onset_window:
            self._recent.popleft()
        if self.gap <= threshold:
            self._rising = None
        elif self._rising is None:
            times = np.array([sample[0] for sample in self._recent])
            gaps = np.array([sample[1] for sample in self._recent])
            before = np.searchsorted(times, times - RISE_WINDOW)     # ~0.1 s earlier
            k = len(times) - 1
            while k > 0 and times[k] - times[before[k]] > 0 and \
                    (gaps[k] - gaps[before[k]]) / (times[k] - times[before[k]]) > s.onset_rate:
                k -= 1
            when, _, config, commanded = self._recent[k]
            self._rising = (when, config, commanded)

    def _echoes(self, now: float, t: float, measured: np.ndarray, velocity: np.ndarray
                ) -> bool:
        s = self.settings
        if not s.echo_time:
            return False
        speed = float(np.abs(velocity).sum())
        if float(np.abs(velocity[ECHO_JOINTS]).sum()) < s.echo_speed:
            self._echo_since = None
            return False
        # the command as the driver sends it, a few controller periods either way
        times = t + np.arange(-ECHO_WINDOW, ECHO_WINDOW + ECHO_STEP / 2, ECHO_STEP)
        closest = min(float(np.abs(sent.at(times) - measured).sum(axis=1).min())
                      for sent in self._sent)
        if closest >= 1e-4 + 0.002 * speed:
            self._echo_since = None
            return False
        if self._echo_since is None:
            self._echo_since = now
        return now - self._echo_since >= s.echo_time

    def segment(self, now: float) -> int:
        """Return the index of the segment commanded at time now."""
        return self.path.segment_at(now - self.start_time)


class MotionWatch:
    """The arm's recent motion, judged through the noise: feed it every accepted state."""

    def __init__(self, window: float = 0.3) -> None:
        self.window = window
        self._samples: deque[tuple[float, np.ndarray]] = deque()

    def add(self, now: float, q: np.ndarray) -> None:
        """Take a measured configuration at now [s]."""
        self._samples.append((now, np.asarray(q, dtype=float).copy()))
        while self._samples and self._samples[0][0] < now - self.window:
            self._samples.popleft()

    def moving(self, now: float, threshold: float) -> float:
        """
        Return the L1 motion over the last window when the arm still moves, else 0.

        It moves when the motion over the window exceeds threshold and the noise, and over
        its second half half the threshold and the noise (an arm that has just come to rest
        does not move).  Nothing heard for a window (or the samples not yet spanning most of
        one): 0.
        """
        samples = [(t, q) for t, q in self._samples if t >= now - self.window]
        if len(samples) < 4 or samples[-1][0] - samples[0][0] < 0.5 * self.window:
            return 0.0
        times = np.array([t for t, _ in samples])
        positions = np.array([q for _, q in samples])
        motion, noise = motion_over(times, positions)
        recent = times >= times[-1] - 0.5 * (times[-1] - times[0])
        lately, noise_lately = motion_over(times[recent], positions[recent])
        return motion if motion > threshold + noise and \
            lately > 0.5 * threshold + noise_lately else 0.0
