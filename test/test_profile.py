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
Jerk-limited motions as JTC runs them: limits, continuity, straight edges, stops.

Every check samples the commands through ``jtc.interpolate`` (JTC's rules, written once),
the property test batched over many commands at once (checked against ``JtcTrajectory`` on
a few), every 2 ms.  Tolerances are floating-point only: the profiles keep JTC's interpolation
error below the limits (``profiles.JTC_*``), except positions, which JTC may carry past a via
point by at most 2 x jerk x period³ / 192 (1e-6 rad at the defaults).
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from linear_path import time_path
import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.jtc import interpolate, JtcTrajectory
from probdis_ros.motion.profiles import (
    from_state,
    MAX_STOP_OVERLOAD,
    Motion,
    MotionLimits,
    PERIOD,
    profile_limits,
    stop,
    time_parameterize,
)
import pytest
import ruckig

ARM = iiwa_arm()
N = 7
H = PERIOD
#: JTC samples per command period (every 2 ms), both ends included (continuity at points).
LOCAL = np.linspace(0.0, H, 6)
REL = 1e-9     # floating-point slack on limits, relative
POSITION_TOL = 2e-6   # > JTC's position error (1e-6 rad at the default jerk, see above)


def ceil_period(t: float) -> float:
    """Return t rounded up to a whole number of periods (ruckig's discrete duration)."""
    return math.ceil(t / H - 1e-9) * H


# ---------------------------------------------------------------- the limits and their checks


def test_defaults_come_from_the_urdf_and_the_lbr_stack():
    limits = MotionLimits()
    assert limits.velocity == pytest.approx(ARM.velocity_limits)
    assert limits.acceleration == pytest.approx(np.full(N, 10.0))
    assert limits.jerk == pytest.approx(np.full(N, 100.0))
    assert limits.lower == pytest.approx(ARM.lower) and limits.upper == pytest.approx(ARM.upper)
    scaled = MotionLimits(velocity_scaling=0.5, acceleration_scaling=0.1)
    assert scaled.max_velocity == pytest.approx(0.5 * ARM.velocity_limits)
    assert scaled.max_acceleration == pytest.approx(np.full(N, 1.0))
    assert scaled.max_jerk == pytest.approx(np.full(N, 10.0))   # jerk scales with acceleration


@pytest.mark.parametrize('kwargs, name', [
    ({'velocity_scaling': 0.0}, 'velocity_scaling'),
    ({'velocity_scaling': 1.5}, 'velocity_scaling'),
    ({'acceleration_scaling': -0.1}, 'acceleration_scaling'),
    ({'acceleration': -1.0}, 'acceleration'),
    ({'jerk': np.ones(3)}, 'jerk'),
    ({'velocity': np.full(N, np.nan)}, 'velocity'),
    ({'lower': np.zeros(N), 'upper': np.zeros(N)}, 'lower'),
])
def test_invalid_limits_are_refused_naming_the_field(kwargs, name):
    with pytest.raises(ValueError, match=name):
        MotionLimits(**kwargs)


def test_invalid_paths_and_states_are_refused():
    with pytest.raises(ValueError, match='path'):
        time_parameterize(np.zeros((3, 6)))
    with pytest.raises(ValueError, match='path'):
        time_parameterize(np.full((2, N), np.nan))
    with pytest.raises(ValueError, match='period'):
        time_parameterize(np.zeros((2, N)), period=0.0)
    with pytest.raises(ValueError, match='finite'):
        stop(np.zeros(N), np.full(N, np.inf), np.zeros(N))


# ---------------------------------------------------------------- hand-checked small cases


def one_joint_edge(length: float, joint: int = 0, scaling: float = 1.0) -> Motion:
    start = np.array([0.0, 0.5, 0.0, -1.0, 0.0, 0.5, 0.0])
    goal = start.copy()
    goal[joint] += length
    return time_parameterize(np.array([start, goal]), MotionLimits(velocity_scaling=scaling))


def test_a_long_edge_cruises_for_the_analytic_time():
    # reaches both the velocity and the acceleration limit: T = L/v + v/a + a/j
    v, a, j = (x[0] for x in profile_limits(MotionLimits(velocity_scaling=1.0)))
    assert v >= a * a / j and 1.0 > v * (v / a + a / j)
    motion = one_joint_edge(1.0)
    assert motion.duration == pytest.approx(ceil_period(1.0 / v + v / a + a / j))
    peak = np.abs(motion.velocities[:, 0]).max()   # a little lower: stretched to the period
    assert 0.98 * v < peak <= v * (1 + REL)
    assert np.abs(motion.accelerations[:, 0]).max() <= a * (1 + REL)


def test_a_short_edge_is_jerk_limited_for_the_analytic_time():
    # neither limit reached: four jerk phases of (L / 2j)^(1/3) each
    _, _, j = (x[0] for x in profile_limits(MotionLimits()))
    motion = one_joint_edge(1e-3)
    assert motion.duration == pytest.approx(ceil_period(4 * (1e-3 / (2 * j)) ** (1 / 3)))


def test_the_duration_is_ruckigs_rounded_up_to_the_period():
    limits = MotionLimits(velocity_scaling=0.3, acceleration_scaling=0.5)
    v, a, j = (x[3] for x in profile_limits(limits))
    otg, inp, out = ruckig.Ruckig(1), ruckig.InputParameter(1), ruckig.Trajectory(1)
    inp.current_position, inp.target_position = [0.0], [0.4]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
    assert otg.calculate(inp, out) == ruckig.Result.Working
    start = np.zeros(N)
    goal = start.copy()
    goal[3] = -0.4
    motion = time_parameterize(np.array([start, goal]), limits)
    assert motion.duration == pytest.approx(ceil_period(out.duration))


def test_the_command_starts_one_period_ahead_and_ends_at_rest_on_the_goal():
    motion = one_joint_edge(0.3, joint=4)
    command = motion.command
    assert command.times[0] == pytest.approx(H)
    assert np.diff(command.times) == pytest.approx(np.full(len(command.times) - 1, H))
    assert np.array_equal(command.positions[-1], motion.positions[-1])
    assert not command.velocities[-1].any() and not command.accelerations[-1].any()
    assert not np.isnan(command.velocities).any() and not np.isnan(command.accelerations).any()


def test_a_path_of_one_point_is_a_hold_and_zero_length_edges_are_skipped():
    q = np.array([0.1, 0.2, 0.3, -0.4, 0.5, 0.6, 0.7])
    hold = time_parameterize(q[None])
    assert hold.duration == 0.0
    command = hold.command
    assert command.times == pytest.approx([H]) and np.array_equal(command.positions, q[None])
    assert not command.velocities.any() and not command.accelerations.any()
    goal = q + 0.2
    plain = time_parameterize(np.array([q, goal]))
    repeated = time_parameterize(np.array([q, q, goal, goal]))
    assert repeated.duration == plain.duration
    assert repeated.via_times == pytest.approx([0.0, 0.0, plain.duration, plain.duration])
    assert time_parameterize(np.array([q, q])).duration == 0.0


def test_the_profile_sample_is_the_commanded_points():
    path = np.array([[0.0] * N, [0.2, -0.1, 0.3, -0.2, 0.1, 0.4, -0.3], [0.1] * N])
    motion = time_parameterize(path)
    for k in (0, 7, 33, len(motion.times) - 1):
        q, v, _ = motion.sample(motion.times[k])
        assert np.array_equal(q, motion.positions[k]) and np.array_equal(v, motion.velocities[k])
    assert motion.segment_at(0.0) == 0 and motion.segment_at(motion.duration) == 1
    assert motion.segment_at(motion.via_times[1] + H) == 1


def test_the_edge_reached_is_the_one_the_arm_is_on_never_ahead_of_its_command():
    a, b, c = np.zeros(N), np.r_[0.4, [0.0] * (N - 1)], np.r_[0.4, 0.4, [0.0] * (N - 2)]
    motion = time_parameterize(np.array([a, b, b, c]))        # a repeated via point too
    late = motion.via_times[-1] - 0.1                          # the command on the last edge
    assert motion.segment_at(late) == 2
    assert motion.edge_reached(0.5 * (a + b), late) == 0       # the arm lags, short of b
    assert motion.edge_reached(b + np.r_[0.0, 0.01, [0.0] * (N - 2)], late) == 2   # past b
    assert motion.edge_reached(b, late) == 2                   # at b: the later edge
    assert motion.edge_reached(0.5 * (b + c), 0.1) == 0        # never ahead of the command
    assert motion.edge_reached(c + 1.0, late) == 2             # off the path: the nearest
    assert motion.edge_reached(a - 1.0, late) == 0


# ---------------------------------------------------------------- stops


def test_a_path_from_an_arm_that_still_creeps_brakes_it_first():
    # 2 mrad/s (L1) is motion: a path from it taken as from rest steps JTC's velocity;
    # below 1 mrad/s the arm is at rest and the path starts at once
    q = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
    path = np.array([q, q + 0.3])
    for speed, brakes in ((2e-3, True), (5e-4, False)):
        v = np.zeros(N)
        v[1] = speed
        motion = from_state(q, v, path)
        np.testing.assert_array_equal(motion.velocities[0], v if brakes else np.zeros(N))
        np.testing.assert_array_equal(motion.positions[0], q)


def test_a_motion_from_rest_held_first_waits_whole_periods_at_its_start_then_runs_as_before():
    q = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
    motion = time_parameterize(np.array([q, q + 0.3, q - 0.1]))
    held = motion.held_first(0.095)                 # rounded up: 10 periods
    assert held.times[:2] == pytest.approx([0.0, 10 * H])
    np.testing.assert_allclose(held.times[1:], motion.times + 10 * H)
    np.testing.assert_allclose(held.via_times, motion.via_times + 10 * H)
    for name in ('positions', 'velocities', 'accelerations'):
        np.testing.assert_array_equal(getattr(held, name)[1:], getattr(motion, name))
    np.testing.assert_array_equal(held.positions[0], q)
    for t in (0.0, 0.04, 10 * H):                   # still throughout the hold
        position, velocity, _ = held.sample(t)
        np.testing.assert_array_equal(position, q)
        assert not velocity.any()
    np.testing.assert_allclose(held.sample(10 * H + 0.2)[0], motion.sample(0.2)[0])
    assert motion.held_first(0.0) is motion
    creeping = from_state(q, np.full(N, 0.01), np.array([q, q + 0.3]))
    with pytest.raises(ValueError, match='from rest'):
        creeping.held_first(0.1)


def test_a_stop_at_rest_is_a_one_point_hold():
    q = np.array([0.1, 0.2, 0.3, -0.4, 0.5, 0.6, 0.7])
    command = stop(q, np.zeros(N), np.zeros(N)).command
    assert command.times == pytest.approx([H]) and np.array_equal(command.positions, q[None])
    assert not command.velocities.any() and not command.accelerations.any()


def test_a_stop_from_full_speed_decelerates_for_the_analytic_time():
    limits = MotionLimits(velocity_scaling=1.0)
    _, a, j = (x[1] for x in profile_limits(limits))
    v = np.zeros(N)
    v[1] = limits.max_velocity[1]
    q = np.array([0.0, -1.0, 0.0, -1.0, 0.0, 0.5, 0.0])
    motion = stop(q, v, np.zeros(N), limits)
    assert v[1] >= a * a / j   # reaches the deceleration limit: T = v/a + a/j
    assert motion.duration == pytest.approx(ceil_period(v[1] / a + a / j))
    assert motion.overload == 1.0
    speeds = motion.velocities[:, 1]
    assert np.all(np.diff(speeds) <= 1e-12) and speeds[-1] == 0.0
    assert np.all(motion.positions[:, [0, 2, 3, 4, 5, 6]] == q[[0, 2, 3, 4, 5, 6]])
    # no jump: the first point continues the state
    first = motion.command.positions[0]
    assert np.abs(first - (q + v * H)).max() <= j * H ** 3 / 6 + 1e-12


@pytest.mark.parametrize('sign', [1.0, -1.0])
def test_a_stop_heading_into_a_limit_brakes_harder_and_stays_inside(sign):
    # toward the upper limit and toward the lower one: a stop that checked one side only ran
    # JTC's quintic 1.9 mrad past the other
    limits = MotionLimits(velocity_scaling=1.0, acceleration_scaling=0.2)
    limit = limits.upper[0] if sign > 0 else limits.lower[0]
    v = np.zeros(N)
    v[0] = sign * limits.max_velocity[0]
    q = np.zeros(N)
    q[0] = limit - sign * 0.2    # at 2 rad/s² it needs 0.6 rad, at 10 rad/s² 0.18
    motion = stop(q, v, np.zeros(N), limits)
    assert 1.0 < motion.overload <= MAX_STOP_OVERLOAD / limits.acceleration_scaling
    assert limits.lower[0] <= motion.positions[:, 0].min()
    assert motion.positions[:, 0].max() <= limits.upper[0]
    trajectory = JtcTrajectory(motion.command, q, v)
    reached = [trajectory.sample(t)[0][0] for t in np.arange(0.0, trajectory.duration + 0.02,
                                                             1e-3)]
    assert limits.lower[0] <= min(reached) and max(reached) <= limits.upper[0]
    q[0] = limit - sign * 1e-4    # no braking can do this: clipped at the limit
    clipped = stop(q, v, np.zeros(N), limits)
    assert clipped.overload == np.inf
    assert limits.lower[0] <= clipped.positions[:, 0].min()
    assert clipped.positions[:, 0].max() <= limits.upper[0]


@pytest.mark.parametrize('sign', [1.0, -1.0])
@pytest.mark.parametrize('gap', [0.002, 0.005])
def test_a_stop_that_cannot_brake_before_a_limit_holds_there_as_jtc_runs_it(gap, sign):
    # positions clipped at the limit with the profile's speeds left on: JTC's quintic ran
    # 4e-4 rad past the limit between the points, at 160 rad/s^2
    limits = MotionLimits(velocity_scaling=0.2)
    limit = limits.upper[0] if sign > 0 else limits.lower[0]
    v = np.zeros(N)
    v[0] = sign * limits.max_velocity[0]
    q = np.array([0.0, 0.5, 0.0, -1.0, 0.0, 0.5, 0.0])
    q[0] = limit - sign * gap
    motion = stop(q, v, np.zeros(N), limits)
    assert motion.overload == np.inf
    trajectory = JtcTrajectory(motion.command, q, v)
    past = max(sign * (trajectory.sample(t)[0][0] - limit)
               for t in np.arange(0.0, trajectory.duration + 0.02, 1e-4))
    assert past <= 1e-12


# ---------------------------------------------------------------- the property test


@dataclass
class Case:
    """One commanded motion, from the state JTC measures when it takes it."""

    motion: Motion
    start_v: np.ndarray
    limits: MotionLimits
    path: np.ndarray | None   # the via points whose edges it must keep (None: a stop)


def random_limits(rng: np.random.Generator) -> MotionLimits:
    return MotionLimits(velocity_scaling=float(rng.uniform(0.1, 1.0)),
                        acceleration_scaling=float(rng.uniform(0.1, 1.0)))


def random_path(rng: np.random.Generator) -> np.ndarray:
    """Return 2-6 via points in the limits: edges 0.001-0.6 rad, some repeated, some on a limit."""
    points = [rng.uniform(ARM.lower, ARM.upper)]
    for _ in range(int(rng.integers(1, 6))):
        roll = rng.random()
        if roll < 0.05:
            points.append(points[-1].copy())    # zero-length edge
            continue
        step = rng.normal(size=N)
        step *= 10.0 ** rng.uniform(-3, -0.2) / np.abs(step).max()
        nxt = points[-1] + step
        if roll < 0.15:   # onto a limit
            nxt[rng.integers(N)] = rng.choice([ARM.lower, ARM.upper])[rng.integers(N)]
        points.append(np.clip(nxt, ARM.lower, ARM.upper))
    return np.array(points)


def jtc_state(motion: Motion, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return what JTC commands t into a motion started from rest at its first point."""
    return JtcTrajectory(motion.command, motion.positions[0], np.zeros(N)).sample(t)


def make_cases(rng: np.random.Generator, count: int) -> list[Case]:
    """Return count cases: 60 % paths, 20 % retreats, 20 % stops, in a fixed order."""
    cases: list[Case] = []
    while len(cases) < count:
        kind = len(cases) % 5
        limits = random_limits(rng)
        path = random_path(rng)
        motion = time_parameterize(path, limits)
        if kind < 3 or motion.duration == 0.0:
            cases.append(Case(motion, np.zeros(N), limits, path))
            continue
        t = float(rng.uniform(0.0, motion.duration))
        q, v, a = jtc_state(motion, t)
        if kind == 3:   # blocked at t: back from there along the way it came
            back = np.vstack([q, path[motion.segment_at(t)::-1]])
            cases.append(Case(time_parameterize(back, limits), np.zeros(N), limits, back))
        else:           # stopped at t, from what JTC commands then
            cases.append(Case(stop(q, v, a, limits), v, limits, None))
    return cases


def jtc_samples(cases: list[Case]) -> dict[str, np.ndarray]:
    """
    Return JTC's samples of every case every 2 ms: ``q, v, a`` of shape (segments, 6, n).

    Segment 0 of a case goes from the measured start (position and velocity: cubic), the
    others between command points (quintic).  ``case`` and ``edge`` give each segment's
    case and path edge.
    """
    p0, v0, a0, p1, v1, a1, first, case_of, edge_of = ([] for _ in range(9))
    for i, case in enumerate(cases):
        m, c = case.motion, case.motion.command
        k = len(c.times)
        p0.append(np.vstack([m.positions[0], c.positions[:-1]]))
        v0.append(np.vstack([case.start_v, c.velocities[:-1]]))
        a0.append(np.vstack([np.zeros(N), c.accelerations[:-1]]))
        p1.append(c.positions)
        v1.append(c.velocities)
        a1.append(c.accelerations)
        first.append(np.arange(k) == 0)
        case_of.append(np.full(k, i))
        steps = np.round(m.via_times / H).astype(int)
        edge_of.append(np.clip(np.searchsorted(steps, np.arange(1, k + 1), side='left') - 1,
                               0, max(len(steps) - 2, 0)))
    p0, v0, a0, p1, v1, a1 = (np.vstack(x) for x in (p0, v0, a0, p1, v1, a1))
    first = np.concatenate(first)
    q, v, a = (np.empty((len(p0), len(LOCAL), N)) for _ in range(3))
    rows = np.flatnonzero(first)   # one per case: the cubic from the measured state
    start = (p0[rows], v0[rows], None)
    end = (p1[rows], v1[rows], a1[rows])
    for j, t in enumerate(LOCAL):
        q[:, j], v[:, j], a[:, j] = interpolate(t, H, (p0, v0, a0), (p1, v1, a1))
        q[rows, j], v[rows, j], a[rows, j] = interpolate(t, H, start, end)
    return {'q': q, 'v': v, 'a': a, 'case': np.concatenate(case_of),
            'edge': np.concatenate(edge_of)}


def stop_speed_bound(limits: MotionLimits) -> np.ndarray:
    """
    Return the speed a stop from a JTC state may reach: see ``stop``.

    JTC's state differs from the profile's by up to 2 jerk x period / 16 in acceleration,
    which the stop's first ramp carries into a_p x that / jerk more speed.
    """
    v, a, j = limits.max_velocity, limits.max_acceleration, limits.max_jerk
    return v + np.minimum(a, np.sqrt(v * j)) * H / 8


def check_cases(cases: list[Case]) -> None:
    """Assert every property of every case, naming the first case that breaks one."""
    s = jtc_samples(cases)
    q, v, a, case_of = s['q'], s['v'], s['a'], s['case']
    v_max = np.array([stop_speed_bound(c.limits) if c.path is None else c.limits.max_velocity
                      for c in cases])[case_of][:, None]
    # a stop near a position limit may brake harder: by its own (reported) overload
    a_max = np.array([c.limits.max_acceleration * c.motion.overload
                      for c in cases])[case_of][:, None]

    def first_bad(bad: np.ndarray, what: str) -> None:
        rows = np.flatnonzero(bad.reshape(len(bad), -1).any(axis=1))
        assert len(rows) == 0, f'{what}: case {case_of[rows[0]]} of this batch'

    first_bad(np.abs(v) > v_max * (1 + REL) + 1e-12, 'velocity above its limit')
    first_bad(np.abs(a) > a_max * (1 + REL) + 1e-12, 'acceleration above its limit')
    first_bad((q < ARM.lower - POSITION_TOL) | (q > ARM.upper + POSITION_TOL), 'position limits')
    # velocity continuous: 2 ms apart inside a segment, equal at the points between them
    dv = np.abs(np.diff(v, axis=1))
    first_bad(dv > a_max * (LOCAL[1] - LOCAL[0]) * (1 + REL) + 1e-12, 'velocity step')
    same = case_of[1:] == case_of[:-1]
    first_bad(np.abs(v[1:, 0] - v[:-1, -1])[same] > 1e-9, 'velocity jump at a point')
    first_bad(np.abs(q[1:, 0] - q[:-1, -1])[same] > 1e-12, 'position jump at a point')

    # every sample on the straight edge it belongs to; every motion ends at rest
    paths = [c.path for c in cases]
    is_path = np.array([p is not None for p in paths])[case_of]
    starts = np.vstack([p[:-1] if p is not None and len(p) > 1 else np.zeros((1, N))
                        for p in paths])
    offsets = np.cumsum([0] + [max(len(p) - 1, 1) if p is not None else 1 for p in paths])
    row = offsets[case_of] + s['edge']
    ends = np.vstack([p[1:] if p is not None and len(p) > 1 else np.zeros((1, N))
                      for p in paths])
    d = (ends - starts)[row][:, None]
    rel = q - starts[row][:, None]
    frac = np.clip((rel * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
    off = np.abs(rel - frac[..., None] * d).max(-1)
    first_bad((off > POSITION_TOL)[is_path], 'off the straight edge')
    for i, case in enumerate(cases):
        m = case.motion
        assert not m.command.velocities[-1].any() and not m.command.accelerations[-1].any()
        if case.path is not None:
            assert np.array_equal(m.command.positions[-1], case.path[-1]), f'case {i} end'
            at = np.round(m.via_times / H).astype(int)
            assert np.abs(m.positions[at] - case.path).max() <= 1e-12, f'case {i} via points'
            assert not m.velocities[at].any(), f'case {i} not at rest at a via point'


def test_the_batched_samples_are_jtcs():
    rng = np.random.default_rng(7)
    cases = make_cases(rng, 10)
    s = jtc_samples(cases)
    for i in (0, 3, 4, 9):
        rows = np.flatnonzero(s['case'] == i)
        trajectory = JtcTrajectory(cases[i].motion.command, cases[i].motion.positions[0],
                                   cases[i].start_v)
        for r in rows[:: max(len(rows) // 7, 1)]:
            t = (r - rows[0]) * H + LOCAL[4]
            q, v, a = trajectory.sample(t)
            assert q == pytest.approx(s['q'][r, 4], abs=1e-12)
            assert v == pytest.approx(s['v'][r, 4], abs=1e-12)
            assert a == pytest.approx(s['a'][r, 4], abs=1e-9)


def test_ten_thousand_paths_retreats_and_stops_keep_the_limits_as_jtc_runs_them():
    rng = np.random.default_rng(2026)
    total = 0
    for _ in range(40):
        cases = make_cases(rng, 250)
        check_cases(cases)
        total += len(cases)
    assert total == 10_000


def test_the_property_check_can_fail():
    path = np.array([[0.0, 0.7, 0.0, -1.3, 0.0, 0.9, 0.0],
                     [0.1, 0.5, 0.1, -1.2, 0.0, 0.8, 0.1],
                     [0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0]])
    fast, slow = MotionLimits(velocity_scaling=1.0), MotionLimits(velocity_scaling=0.2)
    check_cases([Case(time_parameterize(path, fast), np.zeros(N), fast, path)])
    with pytest.raises(AssertionError, match='velocity above'):
        check_cases([Case(time_parameterize(path, fast), np.zeros(N), slow, path)])
    with pytest.raises(AssertionError, match='acceleration above'):
        check_cases([Case(time_parameterize(path, fast), np.zeros(N),
                          MotionLimits(velocity_scaling=1.0, acceleration_scaling=0.5), path)])
    with pytest.raises(AssertionError, match='off the straight edge'):
        check_cases([Case(time_parameterize(path[[0, 2]], fast), np.zeros(N), fast, path)])


def test_todays_linear_timing_steps_the_velocity_where_the_profile_does_not():
    path = np.array([[0.0, 0.7, 0.0, -1.3, 0.0, 0.9, 0.0],
                     [0.1, 0.5, 0.1, -1.2, 0.0, 0.8, 0.1],
                     [0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0]])
    limits = MotionLimits()
    timed = time_path(path, ARM.velocity_limits, limits.velocity_scaling)
    motion = time_parameterize(path, limits)
    steps = []
    runs = ((timed.command(), timed.duration), (motion.command, motion.duration))
    for command, duration in runs:
        trajectory = JtcTrajectory(command, path[0], np.zeros(N))
        v = np.array([trajectory.sample(t)[1] for t in np.arange(0.0, duration + H, 1e-3)])
        steps.append(np.abs(np.diff(v, axis=0)).max() / 1e-3)
    assert steps[0] > 10 * limits.max_acceleration.max()      # a step of 0.3 rad/s in 1 ms
    assert steps[1] <= limits.max_acceleration.max()
