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
The rclpy-free run under random interleavings of states, commands, stops, starts, faults.

A host like the planner node's (every joint state through the same ``StateCheck``, plans
answered late or failing, ``~/stop`` and ``~/start`` at any time) drives a :class:`Run`
against a kinematic arm run by JTC's rules (``jtc.TrajectoryController``), which blocks now
and then.  Faults are injected into the joint states: NaN, positions outside the limits,
twice-named joints, old stamps, old configurations, and streams that stop.  Every command
the run sends is sampled through ``JtcTrajectory`` from the arm's true state when JTC takes
it, every 2 ms (as ``test_profile.py`` does): no position leaves the joint limits, no
velocity exceeds them, and no velocity steps.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.detector import DetectorSettings
from probdis_ros.motion.jtc import JTC_STARTS, JtcTrajectory, taken_trajectory
from probdis_ros.motion.profiles import MAX_STOP_OVERLOAD
from probdis_ros.motion.state_check import BadJointStateError, StateCheck
from probdis_ros.planning.disentangle import Disentangler
from probdis_ros.run import (
    Learned,
    Phase,
    PlanFrom,
    Propose,
    RELEASE_SCALING,
    Run,
    RunSettings,
    Send,
    StatusChanged,
    Withdrawn,
)
import pytest

ARM = iiwa_arm()
NAMES = [f'lbr_A{i}' for i in range(1, 8)]
PERIOD = 0.01
SAMPLE = 0.002
#: The arm's joint-state noise [rad]: a velocity step of noise / period would stay tiny.
NOISE = 1e-6


@dataclass
class Path:
    """What the stub planner returns."""

    path: np.ndarray


class StubPlanner:
    """Random paths of 1-3 edges inside the limits (or none, or now and then one past a limit)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def plan(self, start, goal, fmap, rng):
        """Return a random path from start to goal, sometimes None."""
        if self.rng.random() < 0.05:
            return None
        middle = [start + self.rng.uniform(-0.4, 0.4, 7) for _ in range(self.rng.integers(0, 3))]
        path = np.clip(np.array([start, *middle, goal]), ARM.lower + 0.01, ARM.upper - 0.01)
        if self.rng.random() < 0.05:        # a planner bug: a via point past a limit
            path = np.vstack([path[:1], ARM.upper + 0.05, path[1:]])
        return Path(path)


class World:
    """
    The kinematic arm under JTC: it follows the command exactly unless it is blocked.

    A blocked arm decelerates to rest (at the acceleration limit: a real arm cannot stop
    dead either) and stays there until the next command.
    """

    def __init__(self, q: np.ndarray, deceleration: np.ndarray,
                 jtc_start: str = 'measured') -> None:
        self.q, self.v = q.copy(), np.zeros(7)
        self.deceleration = deceleration
        self.jtc_start = jtc_start
        self.trajectory: JtcTrajectory | None = None
        self.blocked = False

    def take(self, command, t: float) -> JtcTrajectory:
        """Take a command at t, from the arm's true state or JTC's last command."""
        last = None
        if self.jtc_start == 'desired' and self.trajectory is not None:
            last = self.trajectory.sample(t - self.trajectory.taken_at)
        self.trajectory = taken_trajectory(command, t, self.q, self.v, last, PERIOD)
        self.blocked = False
        return self.trajectory

    def pressed(self) -> float:
        """Return how far (L1) JTC's command is from the arm now."""
        if self.trajectory is None:
            return 0.0
        return float(np.abs(self.trajectory.sample(self.t - self.trajectory.taken_at)[0] -
                            self.q).sum())

    def step(self, t: float) -> None:
        """Move to time t (one period on)."""
        self.t = t
        if self.blocked:
            v = self.v - np.clip(self.v, -self.deceleration * PERIOD, self.deceleration * PERIOD)
            self.q = np.clip(self.q + 0.5 * (self.v + v) * PERIOD, ARM.lower, ARM.upper)
            self.v = v
        elif self.trajectory is not None:
            self.q, self.v, _ = self.trajectory.sample(t - self.trajectory.taken_at)


def check_command(jtc: JtcTrajectory, limits) -> None:
    """Sample a command as JTC runs it: inside the limits, within them, no velocity step."""
    times = np.arange(0.0, jtc.duration + 2 * SAMPLE, SAMPLE)
    samples = [jtc.sample(t) for t in times]
    q = np.array([s[0] for s in samples])
    v = np.array([s[1] for s in samples])
    assert np.all(q >= ARM.lower - 1e-6) and np.all(q <= ARM.upper + 1e-6), \
        'a commanded position leaves the joint limits'
    # JTC's first segment blends the arm's state into the command: the arm's acceleration is
    # not measured, so a command built from a state up to a period old may differ from the
    # arm by up to acceleration x period in velocity
    acceleration = limits.max_acceleration.max()
    blend = 1.2 * acceleration * PERIOD
    assert np.all(np.abs(v) <= limits.max_velocity * 1.02 + blend), 'too fast'
    assert np.all(np.abs(v) <= ARM.velocity_limits + blend), 'above the URDF velocity limits'
    step = np.abs(np.diff(v, axis=0)).max(initial=0.0)
    allowed = SAMPLE * acceleration * MAX_STOP_OVERLOAD * 1.2 + blend
    assert step <= allowed, f'velocity step of {step:.3f} rad/s in {SAMPLE} s'


def drive(seed: int, steps: int = 1500, jtc_start: str = 'measured',
          confirm: bool = False) -> dict:
    """
    Run one random interleaving; return counts of what happened.

    ``confirm``: every path waits (confirm_paths) for an operator who confirms or declines
    it at random moments.
    """
    rng = np.random.default_rng(seed)
    settings = RunSettings(velocity_scaling=float(rng.choice([0.2, 0.5, 0.7])),
                           state_timeout=0.1,
                           detection=DetectorSettings(motion_delay=0.0, echo_time=0.0),
                           jtc_start=jtc_start, confirm_paths=confirm)
    limits = settings.limits(ARM)
    if jtc_start == 'desired':       # a command pressed in past a blocked arm comes back faster
        limits = replace(limits, velocity_scaling=max(RELEASE_SCALING, limits.velocity_scaling))
    start = np.clip(rng.uniform(ARM.lower, ARM.upper) * 0.6, ARM.lower, ARM.upper)
    world = World(start, limits.max_acceleration, jtc_start)
    gate = StateCheck(NAMES, ARM.lower, ARM.upper, ARM.velocity_limits)
    counts = {'commands': 0, 'refused': 0, 'learned': 0, 'starts': 0, 'stops': 0,
              'ends_stopped': 0, 'paths_refused': 0, 'outcomes': set(), 'left_pressed': 0,
              'paths': 0, 'confirms': 0, 'declines': 0}
    confirming = [False]
    run: Run | None = None
    pending: list[tuple[float, Run, PlanFrom]] = []
    silent_until = -1.0
    measured_at, measured, velocity = -np.inf, None, None

    def act(run: Run, t: float) -> None:
        sent = False
        while run.actions:
            action = run.actions.pop(0)
            if isinstance(action, Send):
                sent = True
                counts['commands'] += 1
                check_command(world.take(action.command, t), limits)
                if action.path is not None:
                    counts['paths'] += 1
                    assert confirming[0] or not confirm, 'a path sent without a confirm'
                    # from where the arm is (measured) or JTC's command holds (desired)
                    assert jtc_start == 'desired' or np.abs(
                        action.path[0] - world.q).sum() <= settings.replan_tolerance + 0.02
            elif isinstance(action, StatusChanged) and not run.active and \
                    run.outcome != 'succeeded':
                # every end but the goal (a timeout, a refused state, a planner error, a
                # stop) commands the arm to rest in the same round
                assert sent, f'the run ended ({run.outcome}: {run.message}) without a stop'
                counts['ends_stopped'] += 1
                # a desired start's stop of a blocked arm brings the command back to it
                counts['left_pressed'] += world.blocked and \
                    world.pressed() > settings.detection.d_dist + 0.05
                counts['paths_refused'] += 'leaves the joint limits' in run.message
            elif isinstance(action, PlanFrom):
                pending.append((t + rng.uniform(0.0, 0.3), run, action))
            elif isinstance(action, Learned):
                counts['learned'] += 1

    clock = [0.0]
    for k in range(1, steps):
        t = clock[0] = k * PERIOD
        world.step(t)
        # an obstacle, or a stream that stops for a while (not both: a blocked arm that is
        # not heard from cannot be told from one that follows its command)
        if rng.random() < 0.004 and t >= silent_until:
            world.blocked = True
        if rng.random() < 0.003 and not world.blocked:
            silent_until = t + rng.uniform(0.05, 0.4)
        # the arm's joint state, or a fault in its place
        if t >= silent_until:
            q = world.q + rng.normal(0.0, NOISE, 7)
            names, positions, stamp = list(NAMES), list(q), t
            fault = rng.random()
            if fault < 0.002:
                positions[rng.integers(7)] = float(rng.choice([np.nan, np.inf, 1e6, 3.0]))
            elif fault < 0.004:
                names, positions = [*names, 'lbr_A1'], [*positions, positions[0] + 0.3]
            elif fault < 0.006:
                stamp = t - 0.5                         # a replayed, older state
            elif fault < 0.008:                         # an old configuration, 0.2-0.5 away
                old = q.copy()
                old[rng.integers(7)] += rng.choice([-1, 1]) * rng.uniform(0.2, 0.5)
                positions = list(np.clip(old, ARM.lower, ARM.upper))
            try:
                q, v = gate.check(t, names, positions, list(world.v), stamp)
            except BadJointStateError as err:
                counts['refused'] += 1
                if run is not None:
                    run.bad_joint_state(str(err))
                    act(run, t)
            else:
                measured, velocity, measured_at = q, v, t
                if run is not None:
                    run.on_joint_state(t, q, v)
                    act(run, t)
        # plans come back late, sometimes failing; a plan of an ended run is dropped
        for item in [p for p in pending if p[0] <= t]:
            pending.remove(item)
            _, owner, action = item
            if owner is not run:
                continue
            if rng.random() < 0.03:
                run.plan_failed(RuntimeError('injected planner fault'))
            else:
                run.on_plan(run.loop.next_path(action.config))
            act(run, t)
        if run is not None:
            run.tick(t)
            act(run, t)
        # the operator
        if confirm and run is not None and run.phase is Phase.AWAITING and \
                rng.random() < 0.05:
            if rng.random() < 0.3:
                counts['declines'] += 1
                assert run.decline(t) == ''
            else:
                counts['confirms'] += 1
                confirming[0] = True
                run.confirm(t)
                act(run, t)
                confirming[0] = False
            act(run, t)
        if rng.random() < 0.004 and run is not None:
            counts['stops'] += 1
            run.stop()
            act(run, t)
        if rng.random() < 0.01 and (run is None or not run.active) and \
                t - measured_at <= settings.state_timeout and \
                not gate.refused_within(t, 0.1):
            running, sent_at = None, None
            if run is not None:
                counts['outcomes'].add(run.outcome)
                # as the node does: the last command, while the arm may still run it (with
                # a desired start always: JTC starts the next one from it)
                last = run.trajectory
                if last is not None and (t <= last.taken_at + last.duration + 0.5 or
                                         jtc_start == 'desired'):
                    running, sent_at = last, run.sent_at
            goal = np.clip(measured + rng.uniform(-0.5, 0.5, 7), ARM.lower, ARM.upper)
            loop = Disentangler(ARM, StubPlanner(rng), goal, max_paths=8, seed=seed,
                                goal_tolerance=0.04)
            run = Run(ARM, loop, settings, clock=lambda: clock[0])
            counts['starts'] += 1
            run.start(measured_at, measured, velocity, running, sent_at)
            act(run, t)
    return counts


@pytest.mark.parametrize('jtc_start', JTC_STARTS)
@pytest.mark.parametrize('seed', range(8))
def test_no_command_leaves_the_limits_or_steps_in_velocity(seed, jtc_start):
    counts = drive(seed, jtc_start=jtc_start)
    assert counts['starts'] and counts['commands'] and counts['refused']
    if jtc_start == 'desired':
        assert not counts['left_pressed']


@pytest.mark.parametrize('jtc_start', JTC_STARTS)
@pytest.mark.parametrize('seed', range(4))
def test_with_confirm_paths_no_path_goes_unconfirmed_and_none_from_elsewhere(seed, jtc_start):
    counts = drive(seed, steps=3000, jtc_start=jtc_start, confirm=True)
    assert counts['confirms'] and counts['paths'] and counts['commands']


def test_a_confirm_after_the_arm_moved_sends_nothing_and_plans_again():
    class Straight:
        def plan(self, start, goal, fmap, rng):
            return Path(np.array([start, goal]))

    q0 = np.zeros(7)
    loop = Disentangler(ARM, Straight(), q0 + 0.5, max_paths=8, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(confirm_paths=True))

    def plans(t):
        for action in [a for a in run.actions if isinstance(a, PlanFrom)]:
            run.on_plan(loop.next_path(action.config))
        sent = [a for a in run.actions if isinstance(a, Send)]
        run.actions.clear()
        return sent

    run.start(0.0, q0)
    assert not plans(0.0) and run.phase is Phase.AWAITING and loop.paths_tried == 1
    moved = q0.copy()
    moved[1] += 0.08       # more than replan_tolerance, less than a motion of something else
    run.on_joint_state(0.01, moved, np.zeros(7))
    reason = run.confirm(0.02)
    assert 'moved 0.080 rad' in reason and 'not sent' in reason
    assert not plans(0.02) and run.phase is Phase.AWAITING and loop.paths_tried == 1
    np.testing.assert_allclose(run.proposed[0], moved)       # planned again from there
    assert run.proposals == 2 and run.message.startswith('proposal 2')
    assert run.confirm(0.03) == '' and run.phase is Phase.EXECUTING
    # a confirm from stale joint states stops the run instead
    run2 = Run(ARM, Disentangler(ARM, Straight(), q0 + 0.5, goal_tolerance=0.04),
               RunSettings(confirm_paths=True, state_timeout=0.1))
    run, loop = run2, run2.loop
    run.start(0.0, q0)
    plans(0.0)
    assert 'joint states stopped arriving' in run.confirm(0.5)
    assert run.phase is Phase.STOPPED
    # and a decline from stale joint states stops it too, planning nothing from there
    run = Run(ARM, Disentangler(ARM, Straight(), q0 + 0.5, goal_tolerance=0.04),
              RunSettings(confirm_paths=True, state_timeout=0.1))
    loop = run.loop
    run.start(0.0, q0)
    plans(0.0)
    assert 'joint states stopped arriving' in run.decline(0.5)
    assert run.phase is Phase.STOPPED and run.proposals == 1
    assert not any(isinstance(a, PlanFrom) for a in run.actions)


def test_a_path_declined_or_stopped_while_it_waits_is_withdrawn_from_view():
    """The node stops drawing a proposal on Withdrawn: declined, stopped, not when sent."""
    class Straight:
        def plan(self, start, goal, fmap, rng):
            return Path(np.array([start, goal]))

    q0 = np.zeros(7)
    run = Run(ARM, Disentangler(ARM, Straight(), q0 + 0.5, goal_tolerance=0.04),
              RunSettings(confirm_paths=True))

    def kinds(t):
        for action in [a for a in run.actions if isinstance(a, PlanFrom)]:
            run.on_plan(run.loop.next_path(action.config))
        out = [type(a) for a in run.actions]
        run.actions.clear()
        return out

    run.start(0.0, q0)
    assert Propose in kinds(0.0) and run.phase is Phase.AWAITING
    assert run.decline(0.01) == ''
    after_decline = kinds(0.01)
    assert after_decline.index(Withdrawn) < after_decline.index(Propose)   # then the next one
    assert run.confirm(0.02) == ''
    sent = kinds(0.02)
    assert Send in sent and Withdrawn not in sent
    run.stop()
    assert Withdrawn not in kinds(0.03)        # nothing awaited: nothing to withdraw
    run = Run(ARM, Disentangler(ARM, Straight(), q0 + 0.5, goal_tolerance=0.04),
              RunSettings(confirm_paths=True))
    run.start(0.0, q0)
    kinds(0.0)
    run.stop()
    assert Withdrawn in kinds(0.01) and run.proposed is None


def test_the_interleavings_reach_every_kind_of_event():
    totals: dict = {}
    for seed in range(8, 12):
        for key, value in drive(seed).items():
            totals[key] = totals.get(key, 0) + value if key != 'outcomes' else \
                totals.get(key, set()) | value
    assert totals['learned'] and totals['stops'] and totals['refused'] > 10
    assert totals['ends_stopped'] > 10 and totals['paths_refused']
    assert {'stopped', 'succeeded'} <= totals['outcomes']


def test_the_check_catches_a_velocity_step():
    """The property is not vacuous: a stop from a state one period old pulls the arm back."""
    settings = RunSettings(velocity_scaling=0.7)
    limits = settings.limits(ARM)
    q, v = np.zeros(7), np.full(7, 0.8)
    from probdis_ros.run import rest_command
    stale = rest_command(ARM, limits, q, v)          # built for where the arm was 10 ms ago
    with pytest.raises(AssertionError, match='velocity step'):
        check_command(JtcTrajectory(stale, q + v * PERIOD, v), limits)
    check_command(JtcTrajectory(stale, q, v), limits)
