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
joint_trajectory_controller's rules, written once (no rclpy).

The mock arm, the planner's blocked-motion detector and ``probdis replay`` all ask "where
does the controller command the arm at time t?" and must get the same answer, so this module
is the only place that answers it.  It follows ros2_controllers' JTC (Jazzy) on its topic
interface, as the lbr stack runs it:

* A new message replaces the running trajectory.  It is taken at the next controller update
  ``t0``: its times count from ``header.stamp``, or from ``t0`` where the stamp is zero.
* The first segment starts from the *measured* state at ``t0`` (positions and velocities;
  ``interpolate_from_desired_state`` is false by default), the "point before" the message.
* Each segment is interpolated from what both of its ends carry: linear where either end
  lacks velocities (a velocity step at every via point), cubic with positions and velocities
  at both ends, quintic with accelerations too.  The measured state carries no accelerations
  (the lbr stack exports position and velocity), so the first segment is cubic (quintic from
  zero acceleration where JTC fills zeros into the point before, ros2_controllers #2043: the
  same on this package's profiles but for rounding).  The run's messages begin with their
  start at time 0, so JTC never runs that segment for them.
* After the last point the controller holds that point.
* Every update at time t commands the sample at ``t + period`` (one period ahead).

With ``interpolate_from_desired_state: true`` (:data:`JTC_STARTS` ``'desired'``) the point
before is instead the controller's last command (``last_commanded_state_``: the previous
update's sample one period ahead, with its position, velocity and acceleration), stamped at
the previous update's time (``last_commanded_time_``): one period before ``t0``.  The
command stays continuous: the new trajectory's first sample is exactly what the message's
first point says, and nothing steps back to the measured position.  After its first
activation JTC holds the measured position (the lbr stack's command interfaces start as NaN),
and that hold is its last command; activated again, it holds the command interfaces' last
value instead (``set_last_command_interface_value_as_state_on_activation``, true by
default), which may lie where the arm pressed.  (Where JTC holds by itself,
on a path or goal tolerance violation, it holds the *measured* position, and that becomes
its last command: the planner does not see that, see the README.)  ``open_loop_control:
true`` starts from the last command as well (JTC ORs the two).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math

import numpy as np

#: The lbr stack's ros2_control update rate [Hz].
CONTROLLER_RATE = 100.0
#: The time constant [s] of the lbr stack driver's command filter (PR #220 on; its
#: ``joint_position_tau`` default), which every position command passes before FRI.
DRIVER_FILTER_TAU = 0.04
#: The time constant [s] of the same first-order filter on the measured joint torques before
#: they reach the effort state interface (``measured_torque_tau`` in the lbr stack's
#: ``lbr_system_config.yaml``, which ships 0.1; its code's default 0.04; releases before
#: PR #220 a 10 Hz low-pass, about 0.016): the efforts in the joint states lag the arm's.
DRIVER_TORQUE_TAU = 0.1
#: Older releases moved the command 0.1 of the way to its target each 10 ms cycle: the same
#: first-order filter with this time constant [s].
OLD_DRIVER_FILTER_TAU = -1.0 / (CONTROLLER_RATE * math.log(0.9))
#: Where JTC starts a new trajectory: ``'measured'`` (``interpolate_from_desired_state:
#: false``, the default) or ``'desired'`` (true: from its last command).
JTC_STARTS = ('measured', 'desired')
#: The start the planner models and the mock's controller runs unless told otherwise: it must
#: be the real controller's (README, "Pointing it at the real arm").
DEFAULT_JTC_START = 'measured'


@dataclass(frozen=True)
class TrajectoryCommand:
    """
    The content of a JointTrajectory in the arm's joint order.

    ``velocities`` and ``accelerations`` are ``(M, n)`` with a row of NaN where a point does
    not carry the field (JTC accepts mixed fields point by point), or None where no point
    does.  ``stamp`` is ``header.stamp`` in seconds; 0 starts the trajectory when the
    controller takes it.
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None
    accelerations: np.ndarray | None = None
    stamp: float = 0.0

    def __post_init__(self) -> None:
        """Check shapes and times; JTC refuses what this refuses."""
        times = np.asarray(self.times, dtype=float).reshape(-1)
        positions = np.atleast_2d(np.asarray(self.positions, dtype=float))
        if len(times) == 0 or len(times) != len(positions):
            raise ValueError(f'{len(times)} times for {len(positions)} points')
        if not np.all(np.isfinite(times)):
            raise ValueError('time_from_start must be finite')
        if np.any(np.diff(times) <= 0) or times[0] < 0:
            raise ValueError('time_from_start must be non-negative and strictly increasing')
        object.__setattr__(self, 'times', times)
        object.__setattr__(self, 'positions', positions)
        for name in ('velocities', 'accelerations'):
            value = getattr(self, name)
            if value is not None:
                value = np.asarray(value, dtype=float)
                if value.shape != positions.shape:
                    raise ValueError(f'{name} of shape {value.shape} for positions '
                                     f'{positions.shape}')
                object.__setattr__(self, name, value)

    def field(self, name: str, k: int) -> np.ndarray | None:
        """Return point k's velocities or accelerations, None where it does not carry them."""
        values = getattr(self, name)
        if values is None or np.isnan(values[k]).any():
            return None
        return values[k]


def interpolate(t: float, duration: float,
                start: tuple[np.ndarray, np.ndarray | None, np.ndarray | None],
                end: tuple[np.ndarray, np.ndarray | None, np.ndarray | None]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return (position, velocity, acceleration) t seconds into a segment, as JTC computes it.

    start and end are (positions, velocities or None, accelerations or None).  Outside the
    segment the sample is clamped to its ends and interpolated linearly, as JTC does.
    """
    p0, v0, a0 = start
    p1, v1, a1 = end
    cubic = v0 is not None and v1 is not None
    quintic = cubic and a0 is not None and a1 is not None
    if t < 0.0:
        t, cubic, quintic = 0.0, False, False
    if t > duration:
        t, cubic, quintic = duration, False, False
    if not cubic:
        slope = (p1 - p0) / duration if duration > 0 else np.zeros_like(p0)
        return p0 + slope * t, slope, np.zeros_like(p0)
    d = duration
    if not quintic:
        c2 = (-3 * p0 + 3 * p1 - 2 * v0 * d - v1 * d) / d ** 2 if d > 0 else 0 * p0
        c3 = (2 * p0 - 2 * p1 + v0 * d + v1 * d) / d ** 3 if d > 0 else 0 * p0
        return (p0 + v0 * t + c2 * t ** 2 + c3 * t ** 3,
                v0 + 2 * c2 * t + 3 * c3 * t ** 2,
                2 * c2 + 6 * c3 * t)
    c2 = 0.5 * a0
    if d > 0:
        c3 = (-20 * p0 + 20 * p1 - 3 * a0 * d ** 2 + a1 * d ** 2 - 12 * v0 * d - 8 * v1 * d) / (
            2 * d ** 3)
        c4 = (30 * p0 - 30 * p1 + 3 * a0 * d ** 2 - 2 * a1 * d ** 2 + 16 * v0 * d
              + 14 * v1 * d) / (2 * d ** 4)
        c5 = (-12 * p0 + 12 * p1 - a0 * d ** 2 + a1 * d ** 2 - 6 * v0 * d - 6 * v1 * d) / (
            2 * d ** 5)
    else:
        c3 = c4 = c5 = 0 * p0
    return (p0 + v0 * t + c2 * t ** 2 + c3 * t ** 3 + c4 * t ** 4 + c5 * t ** 5,
            v0 + 2 * c2 * t + 3 * c3 * t ** 2 + 4 * c4 * t ** 3 + 5 * c5 * t ** 4,
            2 * c2 + 6 * c3 * t + 12 * c4 * t ** 2 + 20 * c5 * t ** 3)


class JtcTrajectory:
    """
    One command as JTC executes it, from the measured state at the update that took it.

    Times here are relative to ``taken_at`` (the controller update that took the message):
    ``sample(0)`` is the measured state then, ``duration`` the time the last point is
    reached.  ``at`` and ``segment_at`` give the detector what it needs.
    """

    def __init__(self, command: TrajectoryCommand, q_measured: np.ndarray,
                 v_measured: np.ndarray | None = None, taken_at: float = 0.0,
                 a_before: np.ndarray | None = None, before_time: float = 0.0) -> None:
        self.command = command
        self.taken_at = float(taken_at)
        self.before = (np.asarray(q_measured, dtype=float).copy(),
                       None if v_measured is None else np.asarray(v_measured, dtype=float),
                       None if a_before is None else np.asarray(a_before, dtype=float))
        # when the point before holds, relative to taken_at: 0 for the measured state, minus
        # one period for the last command (interpolate_from_desired_state)
        self.before_time = float(before_time)
        # times of the message's points relative to taken_at
        offset = command.stamp - self.taken_at if command.stamp > 0 else 0.0
        self.times = command.times + offset
        # each point's speed per joint: its velocities, or where it carries none (JTC takes
        # a row with any NaN as none) the slope of JTC's linear interpolation into it
        ahead = self.times[0] - self.before_time        # the first segment's span
        slopes = np.abs(np.diff(command.positions, axis=0, prepend=self.before[0][None]))
        slopes /= np.concatenate([[ahead if ahead > 0 else np.inf], np.diff(command.times)])[
            :, None]
        given = command.velocities
        self._speeds = slopes if given is None else np.where(
            np.isnan(given).any(axis=1)[:, None], slopes, np.abs(given))

    @property
    def duration(self) -> float:
        """Return when the last point is reached, relative to taken_at [s]."""
        return float(self.times[-1])

    @property
    def points(self) -> np.ndarray:
        """Return the measured start and the message's points, ``(M + 1, n)``."""
        return np.vstack([self.before[0], self.command.positions])

    def _point(self, k: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        c = self.command
        return c.positions[k], c.field('velocities', k), c.field('accelerations', k)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the desired (position, velocity, acceleration) t seconds after taken_at."""
        times = self.times
        if t < times[0] <= 0.0:
            # a message that begins with its own start (at 0): JTC never samples before it,
            # and the planner's detector, looking back past it, sees that start (not the state
            # the message happened to be taken from, which a replay cannot know)
            p = self.command.positions[0]
            v, a = self._point(0)[1:]
            zero = np.zeros_like(p)
            return p.copy(), zero if v is None else v, zero if a is None else a
        if t < times[0]:
            b = self.before_time
            return interpolate(t - b, times[0] - b, self.before, self._point(0))
        if t >= times[-1]:
            p = self.command.positions[-1]
            v, a = self._point(len(times) - 1)[1:]
            zero = np.zeros_like(p)
            return p.copy(), zero if v is None else v, zero if a is None else a
        k = int(np.searchsorted(times, t, side='right')) - 1
        return interpolate(t - times[k], times[k + 1] - times[k], self._point(k),
                           self._point(k + 1))

    @property
    def still_from(self) -> float:
        """
        Return when the command comes to rest for good, relative to taken_at [s].

        At the first of the points that close the message at its last position and at rest:
        a stamped message ends with a hold (``STAMP_HORIZON`` after its stamp), in which the
        command already stands still.
        """
        last = self.command.positions[-1]
        k = len(self.times) - 1
        while k > 0 and np.array_equal(self.command.positions[k - 1], last) and not any(
                value is not None and np.any(value) for value in self._point(k - 1)[1:]):
            k -= 1
        return float(self.times[k])

    def peak_speed(self, start: float, end: float) -> np.ndarray:
        """
        Return per joint the largest speed at the message's points from start to end [s].

        Zeros where no point falls within.  At the points only: this planner's messages
        have one every controller period, so the speed between them is close to theirs.
        """
        first, last = np.searchsorted(self.times, (start, end), side='right')
        if last <= first:
            return np.zeros(self._speeds.shape[1])
        return self._speeds[first:last].max(axis=0)

    def at(self, t: float) -> np.ndarray:
        """Return the desired position t seconds after taken_at."""
        return self.sample(t)[0]

    def segment_at(self, t: float) -> int:
        """
        Return the segment running at time t, counting from the measured start.

        Segment 0 goes from the measured state to the first point; k from point k-1 to k.
        """
        k = int(np.searchsorted(self.times, t, side='right'))
        return int(np.clip(k, 0, len(self.times) - 1))


def taken_trajectory(command: TrajectoryCommand, now: float, q_measured: np.ndarray,
                     v_measured: np.ndarray | None = None,
                     last_command: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                     period: float = 1.0 / CONTROLLER_RATE) -> JtcTrajectory:
    """
    Return the trajectory JTC makes of a message it takes at the update at time now.

    From the measured state (``interpolate_from_desired_state`` false), or, given
    ``last_command`` (its last command: position, velocity, acceleration), from that, stamped
    one period before now (true).  The mock's controller, the planner's run and ``probdis
    replay`` all start a command here.
    """
    if last_command is None:
        return JtcTrajectory(command, q_measured, v_measured, now)
    q, v, a = last_command
    return JtcTrajectory(command, q, v, now, a, -period)


# where a stamp moved to or before another clock's zero lands: just after it (0 is no stamp)
EARLIEST_STAMP = 1e-9


def moved_onto_clock(command: TrajectoryCommand, shift: float) -> TrajectoryCommand | None:
    """
    Return a stamped command on another clock, its stamp moved by shift (unstamped: as is).

    The mock's arm and a replay count time from their own start, where a stamp of 0 means
    none (JTC starts such a message when it takes it): a message dated at or before that
    zero stays dated, a nanosecond after it, and its points move instead; those before the
    zero are dropped and the segment that runs across it starts there, at the spline's own
    state then (the same spline: JTC interpolates a segment from its two ends' fields).
    None where the message ends before the zero: JTC would refuse it as ending in the past.
    """
    if command.stamp <= 0:
        return command
    stamp = command.stamp + shift
    if stamp > 0:
        return replace(command, stamp=stamp)
    times = command.times + stamp - EARLIEST_STAMP
    k = int(np.searchsorted(times, 0.0, side='right'))
    if k == len(times):
        return None
    if k == 0:
        return replace(command, stamp=EARLIEST_STAMP, times=times)
    cut = JtcTrajectory(replace(command, stamp=0.0), command.positions[0]).sample(
        command.times[k - 1] - times[k - 1])
    rows = []
    for field, value in zip(('positions', 'velocities', 'accelerations'), cut):
        given = getattr(command, field)
        if given is None:
            rows.append(None)
            continue
        carried = field == 'positions' or not np.isnan(given[k - 1:k + 1]).any()
        rows.append(np.vstack([value if carried else np.full_like(value, np.nan), given[k:]]))
    return TrajectoryCommand(np.concatenate([[0.0], times[k:]]), *rows, stamp=EARLIEST_STAMP)


def ends_in_the_past(command: TrajectoryCommand, now: float) -> bool:
    """
    Tell whether JTC refuses a message at now: stamped, its last point is due before now.

    JTC's validation drops such a message ("ends in the past") and runs on with what it had:
    a stamped stop taken late would leave the running command to its end.
    """
    return command.stamp > 0 and command.stamp + float(command.times[-1]) < now


class TrajectoryController:
    """
    JTC's update loop: takes the newest message at its next update, commands one period ahead.

    Before any message, and after a message's last point, it holds (the first measured
    position, or the last point).
    """

    def __init__(self, period: float = 1.0 / CONTROLLER_RATE,
                 start: str = DEFAULT_JTC_START) -> None:
        if start not in JTC_STARTS:
            raise ValueError(f'start must be one of {", ".join(JTC_STARTS)}, got {start!r}')
        self.period = period
        self.start = start
        self.trajectory: JtcTrajectory | None = None
        self._pending: TrajectoryCommand | None = None
        self._hold: np.ndarray | None = None
        # the last command (position, velocity, acceleration), for a desired start
        self.last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def receive(self, command: TrajectoryCommand) -> None:
        """Take a new message; it replaces the running trajectory at the next update."""
        self._pending = command

    def update(self, now: float, q_measured: np.ndarray,
               v_measured: np.ndarray | None = None) -> np.ndarray:
        """Return the position command of the update at time now."""
        pending, self._pending = self._pending, None
        if pending is not None and not ends_in_the_past(pending, now):
            last = self.last if self.start == 'desired' else None
            self.trajectory = taken_trajectory(pending, now, q_measured, v_measured, last,
                                               self.period)
        if self.trajectory is None:
            if self._hold is None:
                self._hold = np.asarray(q_measured, dtype=float).copy()
                # JTC's activation holds the measured position: its last command from then on
                self.last = (self._hold.copy(), np.zeros_like(self._hold),
                             np.zeros_like(self._hold))
            return self._hold.copy()
        self.last = self.trajectory.sample(now + self.period - self.trajectory.taken_at)
        return self.last[0].copy()


class CommandLimiter:
    """
    ros2_control's joint limiter between JTC and the driver (``enforce_command_limits``).

    The lbr stack's controller manager enables it (its ``hardware_controllers.yaml``): each
    period the position command may move at most the URDF's velocity limit times the period
    from the previous *limited* command, and stays within the position limits.  A command
    that steps (a measured-start command after a block) reaches the driver as a ramp at the
    velocity limits; a smooth command within the limits passes unchanged.
    """

    def __init__(self, velocity_limits: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                 period: float = 1.0 / CONTROLLER_RATE) -> None:
        self.step = np.asarray(velocity_limits, dtype=float) * period
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.value: np.ndarray | None = None

    def reset(self, value: np.ndarray) -> None:
        """Start from value (ros2_control takes the measured position as the first command)."""
        self.value = np.asarray(value, dtype=float).copy()

    def __call__(self, command: np.ndarray) -> np.ndarray:
        """Return the command of one period as the limiter passes it on."""
        command = np.asarray(command, dtype=float)
        if self.value is None:
            self.reset(command)
        low = np.maximum(self.value - self.step, self.lower)
        high = np.minimum(self.value + self.step, self.upper)
        self.value = np.clip(command, low, high)
        return self.value.copy()


class FirstOrderFilter:
    """
    The lbr stack driver's filter: first order with time constant tau [s].

    From PR #220 on, the driver smooths every position command before it goes to FRI
    (:data:`DRIVER_FILTER_TAU`); older releases with :data:`OLD_DRIVER_FILTER_TAU`; tau = 0
    passes commands through.  A driver in ``open_loop`` reports this filter's output as the
    arm's position.  The same filter smooths the measured torques it reports
    (:data:`DRIVER_TORQUE_TAU`).
    """

    def __init__(self, tau: float = DRIVER_FILTER_TAU,
                 period: float = 1.0 / CONTROLLER_RATE) -> None:
        self.alpha = 1.0 if tau <= 0 else 1.0 - float(np.exp(-period / tau))
        self.value: np.ndarray | None = None

    def reset(self, value: np.ndarray | None) -> None:
        """Start from value (the position when the driver starts; None: the first given)."""
        self.value = None if value is None else np.asarray(value, dtype=float).copy()

    def __call__(self, command: np.ndarray) -> np.ndarray:
        """Return the filtered command of one driver cycle."""
        if self.value is None:
            self.reset(command)
        else:
            self.value = self.value + self.alpha * (np.asarray(command, dtype=float) - self.value)
        return self.value.copy()
