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
Jerk-limited motions the arm can follow, sent so that JTC runs exactly what was planned.

The planner costs straight joint-space edges, so a path is run edge by edge: the arm rests at
every via point and moves along each edge with a 1-D time-optimal jerk-limited profile from
ruckig (pinned; its open-source build has no intermediate waypoints, hence edge by edge),
then rests until the next controller period, so every via point is a command point at rest
and no JTC segment spans two edges: the commanded motion stays on the edges.  The command
carries positions, velocities and accelerations every period, so JTC's quintic segments
reproduce the profile (see ``jtc.py``).

Stops decelerate from the commanded state with ruckig's velocity interface: never a jump.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cache
import math
from typing import TYPE_CHECKING

import numpy as np
from probdis_ros.motion.jtc import CONTROLLER_RATE, interpolate, TrajectoryCommand
import ruckig

if TYPE_CHECKING:
    from probdis_ros.motion.cartesian_speed import CartesianSpeedLimit

#: The lbr stack's MoveIt ``joint_limits.yaml`` (iiwa14_moveit_config): 10 rad/s² per joint.
DEFAULT_ACCELERATION = 10.0
#: Jerk [rad/s³]: neither the URDF nor the lbr stack gives one.  MoveIt's Ruckig smoothing
#: falls back to 100 rad/s³ without one (MoveIt 1; MoveIt 2 later lowered it to 20).  With
#: 10 rad/s² it ramps the acceleration over 0.1 s, ten controller periods, which JTC's
#: segments between 10 ms points follow to 0.3 rad/s² (the margin kept, see JTC_*).
DEFAULT_JERK = 100.0
#: Fraction of the velocity limits, as the planner's ``velocity_scaling`` (planner.yaml).
DEFAULT_VELOCITY_SCALING = 0.2
#: Fraction of the acceleration and jerk limits (the yaml's limits are already MoveIt's).
DEFAULT_ACCELERATION_SCALING = 1.0
#: Edges shorter than this in every joint are skipped [rad] (below positions' rounding).
MIN_EDGE = 1e-12
#: A stop that cannot halt a joint inside its position limits may use up to this multiple of
#: the unscaled acceleration and jerk limits before it is clipped at the limit.
MAX_STOP_OVERLOAD = 2.0
#: Bisection steps for the least overload that keeps a stop inside the limits (~1e-4).
OVERLOAD_STEPS = 14
#: Floating-point slack [s, rad]: durations a hair over a period, ends a hair past a limit.
ROUNDING = 1e-9
#: Largest departure of v or a from a line for a stop to run along it [rad/s, rad/s²].
COLLINEAR = 1e-9
#: JTC's update period [s].
PERIOD = 1.0 / CONTROLLER_RATE
#: Where a profile's jerk jumps by dJ between two points h apart, JTC's quintic between them
#: (positions, velocities, accelerations) errs by up to dJ h / 16 in acceleration, 0.0048 dJ h²
#: in velocity and dJ h³ / 768 in position; its first segment, a cubic from the measured
#: state, by up to 4/27 dJ h, 0.0162 dJ h² and dJ h³ / 192.  ruckig's jumps are at most
#: 2 x jerk.  Profiles keep the larger margins below the limits, so what JTC runs keeps them.
JTC_ACCELERATION_ERROR = 4.0 / 27.0
JTC_VELOCITY_ERROR = 0.0162


@cache
def _arm_defaults() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the URDF's velocity and position limits (loaded once)."""
    from probdis_ros.model import iiwa_arm

    arm = iiwa_arm()
    return arm.velocity_limits.copy(), arm.lower.copy(), arm.upper.copy()


def _default(index: int) -> np.ndarray:
    return _arm_defaults()[index].copy()


@dataclass(frozen=True)
class MotionLimits:
    """
    Per-joint limits of every commanded motion, and the scalings applied to them.

    Scalars broadcast to every joint.  Jerk is scaled with ``acceleration_scaling`` so that
    the acceleration ramp time (acceleration / jerk) does not depend on the scaling.  The
    position limits (``lower``, ``upper``; the URDF's by default, pass them minus a margin)
    bound stops.  ``cartesian`` (None: none) caps the speed of every point of the arm on each
    edge of a path (:mod:`probdis_ros.motion.cartesian_speed`); a stop only slows down.
    """

    velocity: np.ndarray = field(default_factory=lambda: _default(0))
    acceleration: np.ndarray | float = DEFAULT_ACCELERATION
    jerk: np.ndarray | float = DEFAULT_JERK
    velocity_scaling: float = DEFAULT_VELOCITY_SCALING
    acceleration_scaling: float = DEFAULT_ACCELERATION_SCALING
    lower: np.ndarray = field(default_factory=lambda: _default(1))
    upper: np.ndarray = field(default_factory=lambda: _default(2))
    cartesian: CartesianSpeedLimit | None = None

    def __post_init__(self) -> None:
        """Broadcast to arrays and refuse what no motion could respect, naming the field."""
        velocity = np.asarray(self.velocity, dtype=float).reshape(-1)
        n = len(velocity)
        for name in ('velocity', 'acceleration', 'jerk', 'lower', 'upper'):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.ndim == 0:
                value = np.full(n, float(value))
            if value.shape != (n,):
                raise ValueError(f'{name} must have one value per joint ({n}), '
                                 f'got shape {value.shape}')
            if not np.all(np.isfinite(value)):
                raise ValueError(f'{name} must be finite, got {value}')
            if name in ('velocity', 'acceleration', 'jerk') and np.any(value <= 0):
                raise ValueError(f'{name} limits must be positive, got {value}')
            object.__setattr__(self, name, value)
        if np.any(self.lower >= self.upper):
            raise ValueError(f'lower must be below upper, got {self.lower} and {self.upper}')
        for name in ('velocity_scaling', 'acceleration_scaling'):
            value = getattr(self, name)
            if not 0.0 < value <= 1.0:
                raise ValueError(f'{name} must be in (0, 1], got {value}')

    @property
    def max_velocity(self) -> np.ndarray:
        """Return the velocity limits times velocity_scaling [rad/s]."""
        return self.velocity * self.velocity_scaling

    @property
    def max_acceleration(self) -> np.ndarray:
        """Return the acceleration limits times acceleration_scaling [rad/s²]."""
        return self.acceleration * self.acceleration_scaling

    @property
    def max_jerk(self) -> np.ndarray:
        """Return the jerk limits times acceleration_scaling [rad/s³]."""
        return self.jerk * self.acceleration_scaling


@dataclass(frozen=True)
class Motion:
    """
    A planned motion sampled every period from its start (where the arm is) to rest.

    ``times[0] = 0`` is the start, which is not sent; ``command`` is the rest.  ``via_times``
    gives when each via point of the path is reached (for a stop: the start and the end).
    ``overload`` is the factor on the scaled acceleration and jerk limits the motion needed
    (1 except for a stop that had to brake harder to stay inside the position limits).
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    via_times: np.ndarray
    overload: float = 1.0
    period: float = PERIOD

    @property
    def duration(self) -> float:
        """Return when the motion is at rest at its end [s]."""
        return float(self.times[-1])

    @property
    def from_rest(self) -> bool:
        """Tell whether the motion starts at rest (no velocity, no acceleration)."""
        return not (self.velocities[0].any() or self.accelerations[0].any())

    def held_first(self, hold: float) -> Motion:
        """
        Return this motion (from rest) begun after holding its start for ``hold`` [s].

        Rounded up to whole periods.  A stamped message that JTC takes up to ``hold`` late
        then starts inside the hold, where its command stands still; taken late into the
        move itself, the command would step ahead to catch up with the stamp's time line.
        """
        if not self.from_rest:
            raise ValueError('only a motion from rest can hold its start')
        steps = int(np.ceil(hold / self.period - 1e-9))
        if steps <= 0:
            return self
        shift = steps * self.period
        at_rest = np.zeros((1, self.positions.shape[1]))
        return replace(self, times=np.concatenate([[0.0], shift + self.times]),
                       positions=np.vstack([self.positions[:1], self.positions]),
                       velocities=np.vstack([at_rest, self.velocities]),
                       accelerations=np.vstack([at_rest, self.accelerations]),
                       via_times=shift + self.via_times)

    @property
    def command(self) -> TrajectoryCommand:
        """Return the message: every sample after the start, with all three fields."""
        if len(self.times) == 1:   # already there: hold it, at rest, one period ahead
            return TrajectoryCommand(np.array([self.period]), self.positions,
                                     np.zeros_like(self.positions),
                                     np.zeros_like(self.positions))
        return TrajectoryCommand(self.times[1:], self.positions[1:], self.velocities[1:],
                                 self.accelerations[1:])

    @property
    def command_from_start(self) -> TrajectoryCommand:
        """
        Return the message with the start as its first point, at time 0.

        JTC samples one period ahead, so its first sample is the motion's one period on
        whatever it starts from: from the measured state (the default) as from its last
        command (``interpolate_from_desired_state``, which it stamps one period early, so
        that a message whose first point came one period on would run at half speed for
        two periods).  And the message says where the motion began.
        """
        return TrajectoryCommand(self.times, self.positions, self.velocities,
                                 self.accelerations)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Return the planned (position, velocity, acceleration) at t.

        Between samples it is the quintic matching both, as JTC runs it: exact at every
        sample, within the JTC_* bounds of ruckig's profile between them.
        """
        times = self.times
        if t <= times[0]:
            return self.positions[0].copy(), self.velocities[0].copy(), \
                self.accelerations[0].copy()
        if t >= times[-1]:
            return self.positions[-1].copy(), self.velocities[-1].copy(), \
                self.accelerations[-1].copy()
        k = int(np.searchsorted(times, t, side='right')) - 1
        return interpolate(t - times[k], times[k + 1] - times[k],
                           (self.positions[k], self.velocities[k], self.accelerations[k]),
                           (self.positions[k + 1], self.velocities[k + 1],
                            self.accelerations[k + 1]))

    @property
    def via_positions(self) -> np.ndarray:
        """Return the path's via points, where the motion is at via_times."""
        return self.positions[np.searchsorted(self.times, self.via_times)]

    def segment_at(self, t: float) -> int:
        """Return the path edge being run at t (k: from via point k to k + 1)."""
        k = int(np.searchsorted(self.via_times, t, side='right')) - 1
        return int(np.clip(k, 0, max(len(self.via_times) - 2, 0)))

    def edge_reached(self, config: np.ndarray, t: float) -> int:
        """
        Return the path edge an arm at config is on, its command at t (k: via k to k + 1).

        The time alone says which edge the command runs, and an arm lags its command: in
        joint impedance by 0.1-0.3 s, and by as long as a block is detected late (a stalled
        executor), enough to be an edge behind on short edges or near a via point
        (:func:`edge_reached`).
        """
        return edge_reached(self.via_positions, config, self.segment_at(t))


def edge_reached(points: np.ndarray, config: np.ndarray, latest: int) -> int:
    """
    Return which edge of a polyline (k: points k to k + 1) a lagging arm at config is on.

    Of the edges up to ``latest`` (its command's then: the arm never runs ahead of it), the
    one whose line lies nearest config in joint space; of edges as near (a point between
    them), the later.
    """
    points = np.asarray(points, dtype=float)
    if len(points) < 2:
        return latest
    latest = int(np.clip(latest, 0, len(points) - 2))
    config = np.asarray(config, dtype=float)
    starts, edges = points[:latest + 1], np.diff(points[:latest + 2], axis=0)
    lengths = np.einsum('ij,ij->i', edges, edges)
    along = np.einsum('ij,ij->i', config - starts, edges)
    share = np.clip(np.divide(along, lengths, out=np.zeros_like(along), where=lengths > 0),
                    0.0, 1.0)
    distance = np.linalg.norm(starts + share[:, None] * edges - config, axis=1)
    return int(np.flatnonzero(distance <= distance.min() + 1e-9)[-1])


def _check_period(period: float) -> None:
    if not (np.isfinite(period) and period > 0):
        raise ValueError(f'period must be positive, got {period}')


def profile_limits(limits: MotionLimits, period: float = PERIOD
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return the per-joint (velocity, acceleration, jerk) limits given to ruckig.

    The scaled limits less JTC's interpolation error at the largest jerk jump (2 x jerk),
    so that the motion as JTC runs it keeps the scaled limits; never less than half of them.
    """
    jump = 2.0 * limits.max_jerk
    v = limits.max_velocity - JTC_VELOCITY_ERROR * jump * period ** 2
    a = limits.max_acceleration - JTC_ACCELERATION_ERROR * jump * period
    return (np.maximum(v, 0.5 * limits.max_velocity),
            np.maximum(a, 0.5 * limits.max_acceleration), limits.max_jerk)


def _sample_1d(trajectory: ruckig.Trajectory, times: np.ndarray) -> np.ndarray:
    """
    Return (len(times), 3) rows of (s, ds, dds) of a 1-DOF ruckig trajectory.

    Evaluated from its profile's phases at once (the planner's hot path: ``at_time`` per
    sample costs 2 ms on a long path); a profile with a brake phase (never from rest) is
    sampled with ``at_time``.  After the end it is at rest at its end.
    """
    times = np.minimum(times, trajectory.duration)
    profile = trajectory.profiles[0][0]
    if profile.brake.duration > 0:
        return np.array([[x[0] for x in trajectory.at_time(float(t))] for t in times])
    starts = np.concatenate([[0.0], np.cumsum(profile.t)])
    phases = (profile.j, profile.a, profile.v, profile.p)
    j, a, v, p = (np.asarray(x, dtype=float) for x in phases)
    k = np.clip(np.searchsorted(starts, times, side='right') - 1, 0, len(j) - 1)
    dt = times - starts[k]
    return np.column_stack([p[k] + dt * (v[k] + dt * (a[k] / 2 + dt * j[k] / 6)),
                            v[k] + dt * (a[k] + dt * j[k] / 2),
                            a[k] + dt * j[k]])


def time_parameterize(path: np.ndarray, limits: MotionLimits | None = None,
                      period: float = PERIOD) -> Motion:
    """
    Time via points ``(M, n)`` from rest at the first (where the arm is) to rest at the last.

    Each edge is a 1-D jerk-limited time-optimal profile of the edge parameter, with scalar
    limits (the smallest over joints of limit_j / |direction_j|; the velocity also no more
    than ``limits.cartesian`` allows on the edge), then rest until the next period; the arm
    rests at every via point.  Zero-length edges are skipped (their via points share one
    time).  A path of one point, or of zero-length edges only, gives a
    motion of no duration whose command is a one-point hold at that point.
    """
    limits = MotionLimits() if limits is None else limits
    _check_period(period)
    path = np.asarray(path, dtype=float)
    n = len(limits.velocity)
    if path.ndim != 2 or path.shape[1] != n or len(path) == 0:
        raise ValueError(f'path must be (M >= 1, {n}), got shape {path.shape}')
    if not np.all(np.isfinite(path)):
        raise ValueError('path must be finite')

    otg = ruckig.Ruckig(1, period)
    inp = ruckig.InputParameter(1)
    inp.current_position = [0.0]
    inp.current_velocity = inp.current_acceleration = [0.0]
    inp.target_velocity = inp.target_acceleration = [0.0]
    trajectory = ruckig.Trajectory(1)
    v_max, a_max, j_max = profile_limits(limits, period)

    # every edge at once: length (largest joint move), direction, scalar limits
    deltas = np.diff(path, axis=0)
    lengths = np.abs(deltas).max(axis=1)
    u = np.abs(deltas) / np.maximum(lengths, MIN_EDGE)[:, None]   # max |u_j| = 1
    with np.errstate(divide='ignore'):
        scalar = [np.min(np.where(u > 0, x / u, np.inf), axis=1) for x in (v_max, a_max, j_max)]
    if limits.cartesian is not None:
        scalar[0] = np.minimum(scalar[0], limits.cartesian.edge_speeds(path))

    blocks = [(path[0][None], np.zeros((1, n)), np.zeros((1, n)))]
    via_steps = [0]
    steps = 0
    for k, (length, d) in enumerate(zip(lengths, deltas)):
        if length < MIN_EDGE:
            via_steps.append(steps)
            continue
        inp.target_position = [float(length)]
        inp.max_velocity = [float(scalar[0][k])]
        inp.max_acceleration = [float(scalar[1][k])]
        inp.max_jerk = [float(scalar[2][k])]
        result = otg.calculate(inp, trajectory)
        if result != ruckig.Result.Working:
            raise RuntimeError(f'ruckig could not time an edge of length {length}: {result}')
        count = max(math.ceil(trajectory.duration / period - ROUNDING), 1)
        s = _sample_1d(trajectory, period * np.arange(1, count + 1))
        s[-1] = length, 0.0, 0.0   # exactly at rest on the via point
        direction = d / length
        positions = path[k] + s[:, :1] * direction
        positions[-1] = path[k + 1]
        blocks.append((positions, s[:, 1:2] * direction, s[:, 2:3] * direction))
        steps += count
        via_steps.append(steps)

    positions, velocities, accelerations = (np.vstack(part) for part in zip(*blocks))
    return Motion(period * np.arange(steps + 1), positions, velocities, accelerations,
                  period * np.asarray(via_steps, dtype=float), period=period)


def _line(v: np.ndarray, a: np.ndarray) -> np.ndarray | None:
    """Return a direction (largest component 1) along which v and a both lie, or None."""
    for lead in (v, a):
        size = float(np.abs(lead).max())
        if size == 0.0:
            continue
        u = lead / size
        along = [float(x @ u) / float(u @ u) for x in (v, a)]
        if all(np.abs(x - k * u).max() <= COLLINEAR for x, k in zip((v, a), along)):
            return u
    return None


def stop(q: np.ndarray, v: np.ndarray, a: np.ndarray, limits: MotionLimits | None = None,
         period: float = PERIOD) -> Motion:
    """
    Bring the commanded state (q, v, a) to rest (v = a = 0) as fast as the limits allow.

    Time-optimal and jerk-limited from what JTC commands now, so the command continues it
    without a jump.  A state moving along a line (v and a parallel, as on every edge of a
    path) stops on that line with the edge's scalar limits: a 1-D profile like the path's,
    so it comes to rest about where the path would at the latest (time-synchronised joints
    would not: non-leading joints brake later).  Other states stop joint by joint,
    time-synchronised.  If a joint would pass its position limit, the stop brakes harder, by
    the least factor on the acceleration and jerk limits (``overload``, found by bisection)
    that keeps it inside (or, for a joint already outside, no further out), up to
    MAX_STOP_OVERLOAD x the unscaled limits; if even that overshoots, the positions are
    clipped at the limit, the joint holds there (at rest) from its first sample past it, and
    ``overload`` is inf (only an arm already within the joint margin of a limit, moving
    toward it, gets there).  At rest the motion is empty and its
    command a one-point hold at q.

    Velocities: a stop cannot undo the speed its state's acceleration still adds (a² / 2 jerk);
    from a state of a path as JTC runs it, whose acceleration differs from the profile's by
    up to jerk x period / 8, that can exceed the velocity limit by up to
    min(acceleration, sqrt(velocity x jerk)) x period / 8 (0.5 % at the defaults).
    """
    limits = MotionLimits() if limits is None else limits
    _check_period(period)
    n = len(limits.velocity)
    q, v, a = (np.asarray(x, dtype=float).reshape(-1) for x in (q, v, a))
    if not (q.shape == v.shape == a.shape == (n,)):
        raise ValueError(f'q, v and a must have {n} values each')
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v)) and np.all(np.isfinite(a))):
        raise ValueError('q, v and a must be finite')
    if not (np.any(v) or np.any(a)):
        return Motion(np.zeros(1), q[None], np.zeros((1, n)), np.zeros((1, n)), np.zeros(1),
                      period=period)

    v_max, a_max, j_max = profile_limits(limits, period)
    u = _line(v, a)
    if u is None:       # joint by joint
        dofs, current = n, (q, v, a)
    else:               # along the line: s from 0, q = q0 + s u
        dofs, moving = 1, u != 0
        ratio = np.abs(u[moving])
        v_max, a_max, j_max = (np.array([np.min(x[moving] / ratio)])
                               for x in (v_max, a_max, j_max))
        current = ([0.0], [float(v @ u) / float(u @ u)], [float(a @ u) / float(u @ u)])
    otg = ruckig.Ruckig(dofs, period)
    inp = ruckig.InputParameter(dofs)
    inp.control_interface = ruckig.ControlInterface.Velocity
    inp.synchronization = ruckig.Synchronization.Time
    inp.current_position, inp.current_velocity, inp.current_acceleration = current
    inp.target_velocity = inp.target_acceleration = np.zeros(dofs)
    inp.max_velocity = np.maximum(v_max, np.abs(current[1]))   # not used by a stop
    trajectory = ruckig.Trajectory(dofs)
    # a state a hair outside (JTC's quintic past a via point on a limit) may go no further
    lower, upper = np.minimum(limits.lower, q), np.maximum(limits.upper, q)

    def inside(overload: float) -> bool:
        """Time the stop at overload x the limits; return whether it keeps the limits."""
        inp.max_acceleration = a_max * overload
        inp.max_jerk = j_max * overload
        result = otg.calculate(inp, trajectory)
        if result != ruckig.Result.Working:
            raise RuntimeError(f'ruckig could not stop from {q}, {v}, {a}: {result}')
        low = np.array([e.min for e in trajectory.position_extrema])
        high = np.array([e.max for e in trajectory.position_extrema])
        if u is not None:
            low, high = np.minimum(q + low * u, q + high * u), np.maximum(q + low * u,
                                                                          q + high * u)
        return bool(np.all(low >= lower - ROUNDING) and np.all(high <= upper + ROUNDING))

    overload = 1.0
    if not inside(overload):
        top = MAX_STOP_OVERLOAD / limits.acceleration_scaling
        if inside(top):   # the least overload that keeps the limits, from above
            low, overload = 1.0, top
            for _ in range(OVERLOAD_STEPS):
                middle = 0.5 * (low + overload)
                low, overload = (low, middle) if inside(middle) else (middle, overload)
            inside(overload)
        else:
            overload = np.inf

    count = max(math.ceil(trajectory.duration / period - ROUNDING), 1)
    times = period * np.arange(count + 1)
    if u is None:
        samples = np.empty((3, count + 1, n))
        for i, t in enumerate(np.minimum(times, trajectory.duration)):
            samples[:, i] = trajectory.at_time(float(t))
        positions, velocities, accelerations = samples
    else:
        s = _sample_1d(trajectory, times)
        positions, velocities, accelerations = q + s[:, :1] * u, s[:, 1:2] * u, s[:, 2:3] * u
    positions[0], velocities[0], accelerations[0] = q, v, a
    velocities[-1] = accelerations[-1] = 0.0
    if overload == np.inf:
        # a joint that cannot stop before its limit holds there from the first sample past
        # it: clipped positions with the profile's speeds left on would run JTC's quintic
        # past the limit between samples
        past = np.maximum.accumulate((positions < lower) | (positions > upper), axis=0)
        past[0] = False
        velocities[past] = 0.0
        accelerations[past] = 0.0
    positions = np.clip(positions, lower, upper)   # by ROUNDING unless overload is inf
    return Motion(times, positions, velocities, accelerations,
                  np.array([0.0, times[-1]]), overload, period)


def from_state(q: np.ndarray, v: np.ndarray | None, path: np.ndarray,
               limits: MotionLimits | None = None, period: float = PERIOD,
               still: float = 1e-3, a: np.ndarray | None = None) -> Motion:
    """
    Return a path's motion from the arm's state (q, v): first brought to rest, then the path.

    JTC starts every new command from the measured state; a path timed from rest, sent while
    the arm still moves (a block declared by a gap ceiling mid-motion), would make JTC brake
    within one controller period.  Below ``still`` rad/s (L1) on every joint the arm counts
    as at rest and the path starts at q; otherwise a stop (within the limits) comes first and
    the path starts where it ends.  ``via_times`` are the path's, shifted by the stop.

    ``a``: the state's acceleration, for a start from JTC's desired state (which carries
    one; the measured state does not, and a stop from it starts at zero acceleration).
    """
    q = np.asarray(q, dtype=float)
    path = np.array(path, dtype=float)
    a = np.zeros_like(q) if a is None else np.asarray(a, dtype=float)
    if (v is None or np.abs(v).sum() < still) and np.abs(a).sum() < still:
        path[0] = q
        return time_parameterize(path, limits, period)
    v = np.zeros_like(q) if v is None else np.asarray(v, dtype=float)
    brake = stop(q, v, a, limits, period)
    path[0] = brake.positions[-1]
    rest = time_parameterize(path, limits, period)
    shift = brake.duration
    return Motion(times=np.concatenate([brake.times, shift + rest.times[1:]]),
                  positions=np.vstack([brake.positions, rest.positions[1:]]),
                  velocities=np.vstack([brake.velocities, rest.velocities[1:]]),
                  accelerations=np.vstack([brake.accelerations, rest.accelerations[1:]]),
                  via_times=shift + rest.via_times, overload=brake.overload, period=period)
