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
One disentangling run on an arm, without ROS: phases, detection, retreats, stops.

The planner node and the offline physics simulation (``probdis sim --engine physics``)
both drive a :class:`Run`; neither holds any logic of its own about what a run does.  The
run is fed events (a joint state, a plan result, a tick of the clock, a stop request) and
answers with actions the host carries out (:attr:`Run.actions`): send a command to the
controller, plan from a configuration, a failure was learned, the status changed.  All
times are seconds on one clock, the host's (the DDS receive time or the node's simulated
clock for the node, the simulated time offline).

Phases: idle -> planning -> executing -> (blocked: retreating, while the next path is
planned) -> ... -> succeeded | gave_up | stopped.

What it commands (:mod:`probdis_ros.motion.profiles`): every path and retreat keeps the
planner's straight joint-space edges, jerk-limited within the velocity, acceleration and jerk
limits, sent as 10 ms points with positions, velocities and accelerations that JTC runs as the
planned profile; whatever ends a run that is not at the goal decelerates the arm to rest
from its current state (never a jump, never toward a stale position).

What it learns: a block is located where it began (the detector's onset: the arm touched
the obstacle there and swung on while its unblocked joints followed the command); the
retreat starts from where the arm is and goes back the way it came; a blocked retreat is a
block too, and the next path is planned from where the arm is when the plan it was to run
began elsewhere.  A driver that echoes the command instead of measuring stops the run.

What it does not learn from: motion it did not command.  A path the arm does not begin to
follow at all (nothing executes the commands) and an arm that moves while it should rest
between commands (``UNCOMMANDED``: something else drives it) stop the run with the reason,
nothing learned.

What it refuses: a configuration that is not finite or lies outside the joint limits by more
than ``LIMIT_TOLERANCE`` is never taken (the host's :mod:`probdis_ros.motion.state_check`
refuses it first; a run that gets one anyway stops as for any refused joint state), and a
start within ``goal_tolerance`` of the goal ends at once, succeeded, without a motion.  Its
hosts refuse a goal within the planner's ``joint_margin`` of a joint limit
(:func:`goal_problem`).  A run
that ends while a path is being planned cancels the planning (:class:`CancellablePlanner`:
before the next planner call; the host drops the result of the one under way).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import Enum
import itertools
import math
import threading

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.motion.cartesian_speed import CartesianSpeedLimit
from probdis_ros.motion.detector import (
    BlockDetector,
    DetectorSettings,
    ExternalTorqueObserver,
    slope_of,
    StateStream,
    Verdict,
)
from probdis_ros.motion.jtc import (
    CONTROLLER_RATE,
    DEFAULT_JTC_START,
    JTC_STARTS,
    JtcTrajectory,
    taken_trajectory,
    TrajectoryCommand,
)
from probdis_ros.motion.profiles import (
    DEFAULT_ACCELERATION,
    DEFAULT_JERK,
    DEFAULT_VELOCITY_SCALING,
    from_state,
    Motion,
    MotionLimits,
    stop,
    time_parameterize,
)
from probdis_ros.motion.state_check import JUMP_SPEED, LIMIT_TOLERANCE
from probdis_ros.planning.disentangle import Disentangler, State

#: What a run says when the joint states echo the command (README "Pointing it at the real arm").
ECHO_MESSAGE = ('joint states follow the command exactly as the driver sends it: the driver '
                'reports the commanded position, not the measured one, so no block could be '
                'seen. Use an lbr_fri_ros2_stack release from December 2024 on (PRs #220 and '
                '#239), which measures in JOINT_IMPEDANCE_CONTROL; do not set open_loop: false '
                'on an older one: its PID loop winds the command up against a blocked arm')


#: A stop from the measured state of an arm off its command carries it on at its measured
#: velocity for at most this long [s].
EXTRAPOLATE = 0.05
#: An arm whose L1 velocity differs from its command's by more than this [rad/s] does not
#: follow it (with its position within d_dist).
FOLLOWING_SPEED = 0.5
#: [s] on states without velocities, a blocked arm's velocity is its positions' slope over
#: this long (least squares: 2 states at 100 Hz, 16 at 1 kHz)
VELOCITY_WINDOW = 0.015
#: An arm at rest between commands that goes further than this x d_dist (L1) both from
#: where it came to rest and from where the last command holds it is moved by something else
#: (after a block, plus the gap it pressed with: it may settle by that much).
UNCOMMANDED = 1.5


class Phase(str, Enum):
    """Where a run is; the value is what the status reports."""

    IDLE = 'idle'
    PLANNING = 'planning'
    EXECUTING = 'executing'
    RETREATING = 'retreating'
    AWAITING = 'awaiting_confirmation'     # a planned path waits for the operator
    SUCCEEDED = 'succeeded'
    GAVE_UP = 'gave_up'
    STOPPED = 'stopped'

    @property
    def active(self) -> bool:
        """Tell whether the arm is being driven by the run."""
        return self in (Phase.PLANNING, Phase.EXECUTING, Phase.RETREATING, Phase.AWAITING)


#: The fastest velocity scaling a run takes: the arm in joint impedance overshoots its
#: commanded speed by up to 27 % as it catches up (on the physics mock, 48 random free edges
#: of 0.5-1.5 rad per joint: peaks of 0.74, 0.88 and 1.02 of the limit at 0.6, 0.7 and 0.8),
#: and the lbr stack's command guard stops the driver when a measured joint speed passes
#: the URDF's limit.  Impacts on rigid obstacles add spikes beyond that: near clutter the
#: default 0.2 keeps a wide margin.
MAX_VELOCITY_SCALING = 0.7
#: Faster than this velocity scaling (the default), impacts in clutter spike a joint past its
#: URDF velocity limit and the driver's command guard ends the session: on the physics mock's
#: family worlds of seeds 9000-9019, 1, 9 and 21 runs of 100 at 0.3, 0.4 and 0.5, none at
#: 0.2 with the measured start (RESULTS "How fast in clutter").  The planner node warns at
#: ``~/start`` above it.
CLUTTER_SCALING = DEFAULT_VELOCITY_SCALING
#: The slowest velocity scaling the node takes (slower, a path of a metre takes minutes).
MIN_VELOCITY_SCALING = 0.01
#: With a desired start, a retreat first brings JTC's command back from where it pressed in to
#: where the arm is, at this fraction of the velocity limits (the arm, held there, does not
#: move with it), then retreats at velocity_scaling: the spring is released within about
#: 0.2 s instead of over the slow retreat (during which a pressed arm slid off and snapped
#: past the driver's guard on the physics mock).  0: no release edge.
RELEASE_SCALING = MAX_VELOCITY_SCALING


@dataclass
class RunSettings:
    """How a run drives the arm; every default in one place (the node declares these)."""

    velocity_scaling: float = DEFAULT_VELOCITY_SCALING
    acceleration_scaling: float = 1.0
    acceleration_limit: float = DEFAULT_ACCELERATION   # rad/s^2, every joint (lbr MoveIt)
    jerk_limit: float = DEFAULT_JERK                   # rad/s^3, every joint
    state_timeout: float = 0.5                         # joint states older than this stop
    replan_tolerance: float = 0.05                     # L1 [rad] between plan start and arm
    # [m/s] no point of the arm (its collision shapes, the object's ball, the tip) faster on
    # a path or retreat (KUKA's T1: README "Pointing it at the real arm"); 0: joint limits only
    cartesian_speed_limit: float = 0.0
    detection: DetectorSettings = field(default_factory=DetectorSettings)
    # where JTC starts a new command: 'measured' (interpolate_from_desired_state false, the
    # default) or 'desired' (true: from its last command; every command is then planned
    # from that desired state, and one that starts pressed in waits for the gap to count)
    jtc_start: str = DEFAULT_JTC_START
    # each planned path waits at rest for confirm() (or decline()) before it is sent, so that
    # an operator in T1 sees where the arm will go first; retreats and stops are not held
    confirm_paths: bool = False

    def __post_init__(self) -> None:
        """Refuse values a run cannot use, naming them."""
        if not 0.0 < self.velocity_scaling <= MAX_VELOCITY_SCALING:
            raise ValueError(f'velocity_scaling must be in (0, {MAX_VELOCITY_SCALING}] (faster, '
                             f'the arm overshoots its velocity limits and the driver stops), '
                             f'got {self.velocity_scaling}')
        if not 0.0 < self.acceleration_scaling <= 1.0:
            raise ValueError(f'acceleration_scaling must be in (0, 1], got '
                             f'{self.acceleration_scaling}')
        for name in ('acceleration_limit', 'jerk_limit', 'state_timeout', 'replan_tolerance'):
            if not getattr(self, name) > 0:
                raise ValueError(f'{name} must be positive, got {getattr(self, name)}')
        if not 0 <= self.cartesian_speed_limit < math.inf:
            raise ValueError(f'cartesian_speed_limit must be finite and >= 0 (0: off), got '
                             f'{self.cartesian_speed_limit}')
        if self.jtc_start not in JTC_STARTS:
            raise ValueError(f'jtc_start must be one of {", ".join(JTC_STARTS)}, got '
                             f'{self.jtc_start!r}')

    def limits(self, arm: Arm) -> MotionLimits:
        """Return the motion limits: the arm's velocities, these accelerations and scalings."""
        cartesian = None
        if self.cartesian_speed_limit > 0:
            cartesian = CartesianSpeedLimit(arm, self.cartesian_speed_limit)
        return MotionLimits(velocity=arm.velocity_limits, acceleration=self.acceleration_limit,
                            jerk=self.jerk_limit, velocity_scaling=self.velocity_scaling,
                            acceleration_scaling=self.acceleration_scaling,
                            lower=arm.lower, upper=arm.upper, cartesian=cartesian)


#: What a run that nothing executes says of the lbr driver's guard, in releases that hold
#: the arm instead of ending the session: tripped by a joint's speed it holds it for good.
GUARD_HOLDS = ('a driver whose log says "Overriding invalid command to neutral command." holds '
               'the arm until it is restarted')

#: [s] a stamped message ends at least this long after its stamp (a hold at its last point)
STAMP_HORIZON = 1.0

#: [s] a stamped motion from a command that stands still first holds it this long.  JTC
#: takes a message late by its timing, its delivery and any stall of this host (a CI run
#: stalled 0.12 s), and runs it from its stamp: taken that late, a path started 0.12 s into
#: its ramp, JTC's command at 1.4 x a joint's velocity limit for a period (scaling 0.2);
#: taken within the hold, it does not move.  Its cost: each such path starts this much
#: later.  A stop is not held (it must act at once), so one taken late still steps: on
#: demo_hook, 1.0 x at 0.1 s late (JTC ran on with the old command meanwhile).
STAMP_LEAD = 0.1


def stamped(command: TrajectoryCommand, now: float, desired: bool) -> TrajectoryCommand:
    """
    Return the message of a command made at now: stamped where JTC starts from its command.

    With a desired start JTC starts a message from its own command when it takes it (its next
    update once built and delivered).  Made from that command at now and unstamped, a
    *moving* command fell back by however late JTC took it: a review measured A1 at 1.04
    rad/s going to 0.31 rad/s for a period, and with 8 or 20 ms of delivery to -0.73 or
    -1.77 (past its limit).  Stamped with now, JTC runs it on its own time line: a stop
    taken 0-30 ms late changes speed by at most its own deceleration over the delay (0.2
    rad/s in a period at scaling 0.7).  (A stamp ahead of now made a bump: JTC dates its own
    point before a message a period early; 30 ms ahead, 0.9 rad/s in a period.)  A command
    from rest is stamped too: unstamped, JTC ran it from its next update while the run
    modelled it from now, and a stop made later from that model put JTC's command as far
    ahead as the delivery was late (a fuzzer: 1.8 x the velocity limit for a period, taken
    13 ms late at scaling 0.7); stamped, one taken late starts a few milliseconds into its
    jerk-limited ramp (1e-4 rad, 0.02 rad/s at 20 ms).  JTC drops a stamped message whose
    last point is due before it arrives (:func:`ends_in_the_past`): a short stop taken late
    would leave the old command running, so a stamped message ends ``STAMP_HORIZON`` after
    its stamp at least, holding its last point.  With the measured start nothing is stamped:
    JTC starts a message from the arm when it takes it, and a late one would jump into its
    own middle.
    """
    if not desired or now <= 0:       # a stamp of 0 is none (a clock at its epoch)
        return command
    command = replace(command, stamp=now)
    if command.times[-1] >= STAMP_HORIZON:
        return command
    n = command.positions.shape[1]

    def held(rows: np.ndarray | None) -> np.ndarray | None:
        return None if rows is None else np.vstack([rows, np.zeros((1, n))])

    return replace(command, times=np.append(command.times, STAMP_HORIZON),
                   positions=np.vstack([command.positions, command.positions[-1:]]),
                   velocities=held(command.velocities),
                   accelerations=held(command.accelerations))


@dataclass(frozen=True)
class Send:
    """Send this command to the controller."""

    command: TrajectoryCommand
    path: np.ndarray | None = None     # the planned via points, for markers (paths only)
    at: float = 0.0                    # when it was sent: the detector watches it from then


@dataclass(frozen=True)
class PlanFrom:
    """Plan the next path from this configuration (``loop.next_path``), then on_plan."""

    config: np.ndarray


@dataclass(frozen=True)
class Propose:
    """A planned path waits for the operator: show it (confirm_paths)."""

    path: np.ndarray


@dataclass(frozen=True)
class Withdrawn:
    """The path shown awaiting confirmation was dropped (declined, replanned, run ended)."""


@dataclass(frozen=True)
class Learned:
    """A block was detected and one failure added to the map."""

    event: dict


@dataclass(frozen=True)
class StatusChanged:
    """The status changed; publish it."""


class PlanCancelledError(Exception):
    """The run that asked for this plan has ended."""


class CancellablePlanner:
    """A planner that refuses to start another plan once cancelled (wraps ``loop.planner``)."""

    def __init__(self, planner) -> None:
        self.planner = planner
        self.cancelled = threading.Event()

    def cancel(self) -> None:
        """Make the next plan call raise PlanCancelledError (the one running finishes)."""
        self.cancelled.set()

    def plan(self, start, goal, fmap, rng):
        """Plan as the wrapped planner does, unless cancelled."""
        if self.cancelled.is_set():
            raise PlanCancelledError('the run ended')
        return self.planner.plan(start, goal, fmap, rng)


def usable(arm: Arm, config: np.ndarray) -> str:
    """Return why a measured configuration cannot be taken ('' if it can)."""
    config = np.asarray(config, dtype=float)
    if config.shape != (arm.n_joints,) or not np.all(np.isfinite(config)):
        return f'not {arm.n_joints} finite positions: {config.tolist()}'
    if not arm.within_limits(config, LIMIT_TOLERANCE)[0]:
        return f'outside the joint limits: {np.round(config, 4).tolist()}'
    return ''


def scaling_warning(velocity_scaling: float) -> str:
    """Return what a run at this velocity scaling should be warned of ('' for none)."""
    if velocity_scaling <= CLUTTER_SCALING:
        return ''
    return (f'velocity_scaling {velocity_scaling:g}: in clutter, impacts this fast spike a '
            f"joint past its velocity limit and the driver's command guard ends the session "
            f'(on the physics mock 1, 9 and 21 of 100 family runs at 0.3, 0.4 and 0.5, none '
            f'at {CLUTTER_SCALING:g}); near clutter keep {CLUTTER_SCALING:g}')


def goal_problem(arm: Arm, goal: np.ndarray, joint_margin: float) -> str:
    """
    Return why a run may not drive the arm to goal ('' if it may).

    The goal must lie ``joint_margin`` (the planner's, kept by every other via point) inside
    the joint limits: an arm in joint impedance overshoots its command as it comes to rest
    (2 mrad on the physics mock), and an iiwa stops at an axis limit.
    """
    problem = arm.limit_problem(goal, room=joint_margin)
    if problem and arm.joint_outside(goal) is None:       # inside, but within the margin
        return (f'{problem} (joint_margin): an arm in joint impedance overshoots its command '
                f'as it comes to rest (about 2 mrad), and the robot stops at an axis limit; '
                f'move the goal at least joint_margin inside the limit')
    return problem


def rest_command(arm: Arm, limits: MotionLimits, q: np.ndarray,
                 v: np.ndarray | None = None) -> TrajectoryCommand:
    """Return the command that decelerates the arm to rest from (q, v), inside the limits."""
    q = np.clip(np.asarray(q, dtype=float), arm.lower, arm.upper)
    v = np.zeros_like(q) if v is None else np.asarray(v, dtype=float)
    return stop(q, possible(arm, v), np.zeros_like(q), limits).command


def tip_travel(arm: Arm, path: np.ndarray, step: float = 0.02) -> float:
    """Return how far the tip moves along a path's joint-space edges [m], every step rad."""
    points = [path[:1]]
    for a, b in itertools.pairwise(path):
        n = max(1, math.ceil(np.abs(b - a).max() / step))
        points.append(a + np.outer(np.arange(1, n + 1) / n, b - a))
    tips = arm.positions(np.vstack(points))
    return float(np.linalg.norm(np.diff(tips, axis=0), axis=1).sum())


def possible(arm: Arm, v: np.ndarray) -> np.ndarray:
    """
    Return v within what the arm can do (JUMP_SPEED x its velocity limits; finite).

    The joint states' check refuses faster ones; this keeps every stop built from a
    velocity inside the arm's range even if one got past it (a stop from 1e12 rad/s failed).
    """
    top = JUMP_SPEED * arm.velocity_limits
    return np.clip(np.nan_to_num(np.asarray(v, dtype=float)), -top, top)


@dataclass
class Run:
    """A disentangling run: feed it events, carry out its actions."""

    arm: Arm
    loop: Disentangler
    settings: RunSettings = field(default_factory=RunSettings)
    clock: Callable[[], float] | None = None    # for latencies; defaults to event times

    def __post_init__(self) -> None:
        """Start idle."""
        self.phase = Phase.IDLE
        self.actions: list = []
        self.limits = self.settings.limits(self.arm)
        self.period = 1.0 / CONTROLLER_RATE
        self.measured: np.ndarray | None = None
        self.measured_velocity: np.ndarray | None = None
        self.measured_at = -np.inf
        self.detector: BlockDetector | None = None
        # a verdict to answer at the newest state: (verdict, its detector, the state judged:
        # its time and configuration)
        self._judged: tuple[Verdict, BlockDetector, float, np.ndarray] | None = None
        self.trajectory: JtcTrajectory | None = None     # the last command, as JTC runs it
        # when it was sent (JTC took it then): the detector moves the trajectory's taken_at on
        # for an arm that begins late, which is no delay of JTC's own command
        self.sent_at = -np.inf
        self.following = False                           # the last state was on it
        self.motion: Motion | None = None                # the path or retreat being run
        self.plan_pending = False
        self.pending_path: np.ndarray | None = None
        self.proposed: np.ndarray | None = None          # the path awaiting confirmation
        self._confirmed = False                          # the pending path was confirmed
        self.proposals = 0                               # paths proposed, declined ones too
        self.block_time: float | None = None
        self.retreat_sent = 0.0
        self.retreat_done_at: float | None = None
        self.rest_at: np.ndarray | None = None           # where the arm came to rest
        self.rest_slack = 0.0      # how far it may still settle from there [rad L1]
        self.pressed = False                             # the last motion ended blocked
        self.blocked_still = False                       # ... without having moved the arm
        self._recent: deque[tuple[float, np.ndarray]] = deque()     # (time, measured)
        self.state_stream = StateStream()       # the joint states' period and noise
        self.latencies: list[float] = []
        # the latest any command of the run began against motion_delay [s]: JTC took it late,
        # or the arm lags more than motion_delay (the detector shifts such a command)
        self.late_take_max = 0.0
        # per joint, the largest external torque estimated (torque_observer) while the run
        # drove the arm [Nm] (None: the joint states carry no efforts)
        self.torque_peak: np.ndarray | None = None
        self.torque_observer = ExternalTorqueObserver(self.settings.detection)
        self.outcome = ''
        self.message = 'ready'
        self._now = -np.inf
        if self.loop is not None and not isinstance(self.loop.planner, CancellablePlanner):
            self.loop.planner = CancellablePlanner(self.loop.planner)

    # -- events ------------------------------------------------------------------------

    def start(self, now: float, config: np.ndarray, velocity: np.ndarray | None = None,
              running: JtcTrajectory | None = None, running_sent_at: float | None = None
              ) -> None:
        """
        Start from config (and velocity), the newest measured state (at the goal: done).

        ``running`` is the host's last command (sent at ``running_sent_at``) where the arm
        may still be running it (the end of the last run): where it comes to rest is no
        motion of anything else; with a desired start JTC's last command, which it holds.
        """
        self._now = now
        self.trajectory = running
        self.sent_at = -np.inf
        if running is not None:
            self.sent_at = running.taken_at if running_sent_at is None else running_sent_at
        self.outcome, self.message = '', 'running'
        problem = usable(self.arm, config)
        if problem:
            self.phase = Phase.PLANNING     # so that finish ends it like any refused state
            self.bad_joint_state(problem)
            return
        self.measured = np.clip(np.asarray(config, dtype=float), self.arm.lower, self.arm.upper)
        self.measured_at, self.measured_velocity = now, velocity
        self.rest_at, self.rest_slack = self.measured.copy(), 0.0
        if np.linalg.norm(self.measured - self.loop.goal) <= self.loop.goal_tolerance:
            self.finish(State.SUCCEEDED, 'already at the goal: nothing to do')
            return
        self._plan_from(self.measured)

    def on_joint_state(self, now: float, config: np.ndarray,
                       velocity: np.ndarray | None = None,
                       effort: np.ndarray | None = None, newest: bool = True) -> None:
        """
        Take a measured state at time now (a configuration that cannot be the arm's stops).

        ``effort``, the measured joint torques where the driver sends them, feeds the
        detector's external-torque ceiling and the run's peak external torque.  ``newest``
        False: newer states already wait (a host that could not run for a while takes them
        in a burst): a block is judged on this state, where it was seen, but answered from
        the newest, where the arm is by now (a retreat from an older state would first pull
        its command back by what the arm moved since, a step in velocity).
        """
        self._now = now
        problem = usable(self.arm, config)
        if problem:
            self.bad_joint_state(problem)
            return
        self.measured = np.clip(np.asarray(config, dtype=float), self.arm.lower, self.arm.upper)
        self.state_stream.add(now)
        # observed at every state with efforts (it follows the arm's motion), kept while active
        external = None if effort is None else \
            self.torque_observer.update(now, self.measured, velocity, effort)
        if external is not None and self.phase.active:
            self._note_torque(external)
        self.measured_at = now
        self.measured_velocity = velocity
        self._recent.append((now, self.measured))
        while now - self._recent[0][0] > VELOCITY_WINDOW + 1e-9:
            self._recent.popleft()
        if self.trajectory is not None:     # on its command: where and how fast it says
            t = now - self.trajectory.taken_at - self.settings.detection.motion_delay
            q, v, _ = self.trajectory.sample(t)
            self.following = bool(np.abs(q - self.measured).sum() <= self.settings.detection.d_dist
                                  and (velocity is None or
                                       np.abs(v - velocity).sum() <= FOLLOWING_SPEED))
            if velocity is None and self.following:
                # a state without velocities: the arm on its command moves as it says (a
                # stop or a path from it taken at rest would hold a moving arm dead)
                self.measured_velocity = v
            elif velocity is None and len(self._recent) > 1:
                # off its command (a lag other than motion_delay, springing back after a
                # block): as its positions move; taken at rest, a stop stepped a moving arm's
                # command by up to 2.2 rad/s in a period (a fuzzer, scaling 0.7)
                self.measured_velocity = self._positions_slope()
        if not self.phase.active:
            return
        if self._judged is not None:
            if newest:
                self._answer(*self._judged, velocity)
            return
        if self.detector is None:
            self._check_rest()
            return
        verdict = self.detector.update(now, self.measured, external,
                                       self.torque_observer.static)
        if verdict is Verdict.MOVING:
            return
        detector, self.detector = self.detector, None
        judged = (verdict, detector, now, self.measured.copy())
        if newest:
            self._answer(*judged, velocity)
        else:
            self._judged = judged

    def _answer(self, verdict: Verdict, detector: BlockDetector, now: float,
                seen: np.ndarray, velocity: np.ndarray | None) -> None:
        """Answer a verdict on the state (now, seen) from the newest (velocity: its own)."""
        self._judged = None
        self.late_take_max = max(self.late_take_max, detector.late)
        self.rest_at = self.measured.copy()
        # blocked twice running without the arm moving at all: a retreat that never moves is
        # blocked (the arm pressed from behind too), and the path after it begins pressed, so
        # neither can be told "not executed"; with a controller that stopped executing after
        # a block, every retreat and path was learned, a failure every 0.5 s until max_paths
        moved, allowance = detector.moved()
        # no noise judged yet (allowance inf): not known to be still
        still = verdict is Verdict.BLOCKED and moved <= allowance < math.inf
        still_again, self.blocked_still = still and self.blocked_still, still
        self.pressed = verdict is Verdict.BLOCKED
        if self.pressed and velocity is None:
            # blocked: held, or still moving (a torque ceiling tripped by a soft contact), which
            # the command's velocity does not tell (a block its torque showed within d_dist of
            # the command: the retreat ran on into it by the command's braking distance, 0.15
            # rad at scaling 0.7); the arm's recent positions do
            self.measured_velocity = self._positions_slope()
        # a compliant arm stopped while pressed into something springs back or slides by up
        # to the gap it pressed with (seen on the physics mock: 0.17 rad after a blocked
        # retreat): that settling is no motion of another driver
        self.rest_slack = detector.gap if self.pressed else 0.0
        if verdict is Verdict.ECHO:
            self.finish(State.STOPPED, ECHO_MESSAGE)
        elif still_again:
            self.finish(State.STOPPED, f'{detector.reason}: the arm has moved under neither this '
                                       f'command nor the one before, both blocked: nothing '
                                       f'executes the commands (is the controller active? '
                                       f'{GUARD_HOLDS}) or something holds the arm on every '
                                       f'side; stopped, this one not learned')
        elif verdict is Verdict.NOT_EXECUTED:
            self.finish(State.STOPPED, f'{detector.reason}: nothing executes the commands (is '
                                       f'the controller active? {GUARD_HOLDS}) or something '
                                       f'holds the arm; stopped, nothing learned')
        elif self.phase is Phase.EXECUTING:
            if verdict is Verdict.DONE:
                self._completed(self.measured)
            else:
                self._blocked(detector, now, seen)
        elif self.phase is Phase.RETREATING:
            if verdict is Verdict.BLOCKED:
                self._retreat_blocked(detector, now, seen)
                # JTC would run the retreat on to its end, its command ever farther from the
                # held arm, the push growing while the next plan is made: stop it here
                self._stop_arm()
            self.retreat_done_at = now
            self._send_pending()

    def _note_torque(self, external: np.ndarray) -> None:
        """Keep the largest external-torque estimate per joint (ExternalTorqueObserver)."""
        pushed = np.abs(external)
        self.torque_peak = pushed if self.torque_peak is None else \
            np.maximum(self.torque_peak, pushed)

    def _check_rest(self) -> None:
        """Stop when the arm, at rest between commands, moves away on its own."""
        if self.rest_at is None:
            return
        limit = UNCOMMANDED * self.settings.detection.d_dist + self.rest_slack
        away = float(np.abs(self.measured - self.rest_at).sum())
        command = self.trajectory
        if command is not None:         # or where the last command holds it
            held = command.command.positions[-1]
            away = min(away, float(np.abs(self.measured - held).sum()))
            t = self._now - command.taken_at
            detection = self.settings.detection
            if t <= command.duration + detection.motion_delay + detection.settle_time:
                # or, while it may still run, on the way it has taken the arm so far, at
                # any lag: a stop sent by the run before this one may still brake the arm
                # (0.44 rad L1 from 0.7 of the velocity limits in the node's test)
                way = command.points[:command.segment_at(t) + 2]
                away = min(away, float(np.abs(way - self.measured).sum(axis=1).min()))
        if away > limit:
            self.finish(State.STOPPED, f'the arm moved {away:.3f} rad (L1) while at rest between '
                                       f'commands: something other than this planner drives it; '
                                       f'stopped, nothing learned')

    def on_plan(self, path: np.ndarray | None) -> None:
        """Take the result of the last PlanFrom (None: no path within max_paths)."""
        if not self.plan_pending:
            return                    # the run ended while planning: drop it
        self.plan_pending = False
        if path is None:
            self.finish(self.loop.state, 'no path found within max_paths')
            return
        self.pending_path = np.asarray(path, dtype=float)
        self._send_pending()

    def plan_failed(self, error: BaseException) -> None:
        """Stop the run on a planner error: it must not leave the arm moving."""
        if self.plan_pending:
            self.plan_pending = False
            self.finish(State.STOPPED, f'planning failed: {error}')

    def tick(self, now: float) -> None:
        """Check the joint states are fresh (at least every state_timeout)."""
        self._now = now
        if self._judged is not None and self.phase.active:    # the newer states never came
            self._answer(*self._judged, None)
        age = now - self.measured_at
        if self.phase.active and age > self.settings.state_timeout:
            self.finish(State.STOPPED, f'joint states stopped arriving: none for {age:.2f} s '
                                       f'(state_timeout); has the driver stopped? (its log '
                                       f'says why: its command guard ends the FRI session on '
                                       f'a joint faster than its URDF limit, and so does a '
                                       f"safety stop of KUKA's controller, such as T1's "
                                       f'speed monitoring; once the driver is up again, the '
                                       f'next start goes on with the failures learned)')

    def stop(self, reason: str = 'stopped on request') -> None:
        """End the run now, decelerating the arm to rest (or hold it where it is)."""
        if not self.phase.active:
            self._stop_arm()
            return
        self.finish(State.STOPPED, reason)

    def confirm(self, now: float) -> str:
        """
        Send the path awaiting confirmation; return why not ('' when sent).

        Never from stale joint states (the run stops, as on its tick), nor once the arm has
        moved from the path's start (its first edge would be uncosted): that path is then
        dropped and another planned from where the arm is, which waits in turn.
        """
        self._now = now
        if self.phase is not Phase.AWAITING:
            return f'no path awaits confirmation (the run is {self.phase.value})'
        self.tick(now)
        if not self.active:
            return self.message
        origin = self._plan_origin(self._time())
        moved = float(np.abs(self.proposed[0] - origin).sum())
        if moved > self.settings.replan_tolerance:
            self._replan_proposal(origin, f'the arm moved {moved:.3f} rad (L1) from the start '
                                          f'of proposal {self.proposals}: not sent; planning '
                                          f'another from where it is')
            return self.message
        self.pending_path, self.proposed = self.proposed, None
        self.phase = Phase.PLANNING
        self.message = f'proposal {self.proposals} confirmed: path {self.loop.paths_tried}'
        self._confirmed = True
        try:
            self._send_pending()
        finally:
            self._confirmed = False
        return ''

    def decline(self, now: float) -> str:
        """
        Drop the path awaiting confirmation and plan another; return why not ('' when done).

        Never from stale joint states: the run stops instead, as on its tick.
        """
        self._now = now
        if self.phase is not Phase.AWAITING:
            return f'no path awaits confirmation (the run is {self.phase.value})'
        self.tick(now)
        if not self.active:
            return self.message
        self._replan_proposal(self._plan_origin(self._time()),
                              f'proposal {self.proposals} declined: planning another')
        return ''

    def _replan_proposal(self, origin: np.ndarray, message: str) -> None:
        """Drop the proposed path (not a path tried) and plan again from origin."""
        self._withdraw()
        self.loop.decline()
        self._plan_from(origin)
        self.message = message

    def bad_joint_state(self, reason: str) -> None:
        """Stop an active run: a joint state was refused (it is not used for anything)."""
        if self.phase.active:
            self.finish(State.STOPPED, f'joint state refused: {reason}')

    # -- what happens ------------------------------------------------------------------

    @property
    def active(self) -> bool:
        """Tell whether a run is in progress."""
        return self.phase.active

    def _emit(self, action) -> None:
        self.actions.append(action)

    def _time(self) -> float:
        return self.clock() if self.clock is not None else self._now

    def _plan_from(self, config: np.ndarray) -> None:
        self.phase = Phase.PLANNING
        self.plan_pending = True
        self._emit(PlanFrom(np.asarray(config, dtype=float).copy()))
        self._emit(StatusChanged())

    @property
    def _desired_start(self) -> bool:
        return self.settings.jtc_start == 'desired'

    def _origin(self, now: float) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """
        Return the state (q, v, a) JTC starts a command sent at now from.

        The measured state (no acceleration), or with ``jtc_start`` 'desired' the last command
        as the run models it (the measured state before any command).
        """
        last = self._last_command(now)
        if last is not None:
            return last
        return self.measured, self.measured_velocity, None

    def _positions_slope(self) -> np.ndarray:
        """Return the arm's velocity by its positions over VELOCITY_WINDOW (0: one state)."""
        times, positions = zip(*self._recent)
        return slope_of(np.array(times), np.array(positions))

    def _last_command(self, now: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """
        Return JTC's command (q, v, a) at now as the run models it, with a desired start.

        None with the measured start.  q is kept within the joint limits (a sample may pass
        them by rounding): every command built from it must stay within them.
        """
        if not self._desired_start or self.trajectory is None:
            return None
        q, v, a = self.trajectory.sample(now - self.sent_at)
        return np.clip(q, self.arm.lower, self.arm.upper), v, a

    def _command_holds(self, now: float) -> bool:
        """Tell whether JTC's command stands still at now: its last message has come to rest."""
        return self.trajectory is None or now - self.sent_at >= self.trajectory.still_from

    def _held(self) -> bool:
        """
        Tell whether the arm is held by what blocked it, short of JTC's command.

        After a block, until a command has come back to the arm (a free arm that lags its
        command is not held: bringing the command back to it would pull it back).
        """
        if self.detector is not None:
            return self.detector.pressed
        return self.pressed

    def _pressed_in(self, q0: np.ndarray) -> bool:
        """Tell whether a desired start q0 is pressed in past a held arm (beyond d_dist)."""
        return bool(self._desired_start and RELEASE_SCALING and self._held() and
                    np.abs(q0 - self.measured).sum() > self.settings.detection.d_dist)

    def _plan_origin(self, now: float) -> np.ndarray:
        """Return where the next path is planned from: where its command will start."""
        q0 = self._origin(now)[0]
        return self.measured if self._pressed_in(q0) else q0

    def _motion(self, path: np.ndarray, now: float) -> Motion:
        """
        Return the motion of path (its first point: where the command starts) as JTC runs it.

        A desired start pressed in past the arm first brings the command back to the arm at
        RELEASE_SCALING; the path then starts where the arm is (its first edge the release's
        too, so that a block is placed on the path's edges).
        """
        q0, v0, a0 = self._origin(now)
        if not self._pressed_in(q0):
            return from_state(q0, v0, path, self.limits, a=a0)
        release = self._release(q0, v0, a0)
        path = np.array(path, dtype=float)
        path[0] = self.measured
        rest = time_parameterize(path, self.limits)
        shift = release.duration
        return Motion(times=np.concatenate([release.times, shift + rest.times[1:]]),
                      positions=np.vstack([release.positions, rest.positions[1:]]),
                      velocities=np.vstack([release.velocities, rest.velocities[1:]]),
                      accelerations=np.vstack([release.accelerations, rest.accelerations[1:]]),
                      via_times=shift + rest.via_times,
                      overload=release.overload, period=release.period)

    def _message(self, motion: Motion) -> TrajectoryCommand:
        """
        Return a motion's message: from the state it was planned from, at time 0.

        JTC's first sample, one period on, is the motion's there whatever it starts from;
        the message (and so the bag) says where the motion began, so that a replay need not
        guess which joint state the live run had read when it sent it.
        """
        return motion.command_from_start

    def _release(self, q0: np.ndarray, v0: np.ndarray | None, a0: np.ndarray | None) -> Motion:
        """Return the command's way from q0 (pressed in, braked first) back to the arm."""
        fast = replace(self.limits, velocity_scaling=max(RELEASE_SCALING,
                                                         self.limits.velocity_scaling))
        return from_state(q0, v0, np.vstack([q0, self.measured]), fast, a=a0)

    def _arm_ready(self) -> bool:
        return self.phase is Phase.PLANNING or (
            self.phase is Phase.RETREATING and self.retreat_done_at is not None)

    def _send_pending(self) -> None:
        if self.pending_path is None or not self._arm_ready():
            return
        path, self.pending_path = self.pending_path, None
        planned_at = self._time()
        q0 = self._plan_origin(planned_at)
        if np.abs(path[0] - q0).sum() > self.settings.replan_tolerance:
            # the arm is not where this plan begins (its retreat was blocked): a first edge
            # from here would be uncosted, so plan again from where the arm is (or, desired
            # start, from where JTC's command is)
            self.loop.withdraw()
            self.plan_pending = True
            self.phase = Phase.PLANNING
            self._emit(PlanFrom(q0.copy()))
            return
        if not self.arm.within_limits(path).all():
            self.finish(State.STOPPED, 'planned path leaves the joint limits; not sent')
            return
        if self.settings.confirm_paths and not self._confirmed:
            self._note_latency()
            self._propose(path)
            return
        motion = self._motion(path, planned_at)
        self._note_latency()
        self._send(motion, path, planned_at if self._desired_start else None)
        self.phase = Phase.EXECUTING
        self.retreat_done_at = None
        self._emit(StatusChanged())

    def _note_latency(self) -> None:
        """After a block: note how long until the next path was ready (sent or proposed)."""
        if self.block_time is None:
            return
        now = self._time()
        waited = (self.retreat_sent - self.block_time) + max(
            0.0, now - (self.retreat_done_at or now))
        self.latencies.append(waited)
        self.block_time = None

    def _propose(self, path: np.ndarray) -> None:
        """Hold a planned path, the arm at rest, until confirm() or decline()."""
        self.proposed = path
        self.proposals += 1
        self.phase = Phase.AWAITING
        self.retreat_done_at = None
        self.message = (f'proposal {self.proposals} (path {self.loop.paths_tried}): '
                        f'{len(path) - 1} edges, the '
                        f'flange travels {tip_travel(self.arm, path):.2f} m; ~/confirm_path '
                        f'sends it, ~/decline_path plans another, ~/stop ends the run')
        self._emit(Propose(path.copy()))
        self._emit(StatusChanged())

    def _withdraw(self) -> None:
        """Drop the path awaiting confirmation, if any, so that it is no longer shown."""
        if self.proposed is not None:
            self.proposed = None
            self._emit(Withdrawn())

    def _send(self, motion: Motion, path: np.ndarray | None = None,
              planned_at: float | None = None) -> None:
        """
        Send a motion and watch it as JTC runs it.

        JTC starts it from the measured state now, or with a desired start from its command
        at ``planned_at``, where the motion was planned from (the clock moves on while it is
        timed: the command must start where the motion does).
        """
        now = self._time() if planned_at is None else planned_at
        last = self._last_command(now)
        if self._desired_start and self._command_holds(now) and motion.from_rest:
            motion = motion.held_first(STAMP_LEAD)
        command = stamped(self._message(motion), now, self._desired_start)
        self._emit(Send(command, path, now))
        self.motion = motion
        self.trajectory = taken_trajectory(command, now, self.measured, self.measured_velocity,
                                           last, self.period)
        self.sent_at = now
        pressed_start = None
        if last is not None and self._pressed_in(last[0]):
            pressed_start = (last[0], self.measured.copy())
        self.following = True
        # a path from a free arm must move it; one from an arm pressed against something
        # (its retreat blocked) may be blocked at once
        expect = path is not None and not self.pressed and pressed_start is None
        self.detector = BlockDetector(self.trajectory, now, self.settings.detection,
                                      expect_motion=expect, pressed_start=pressed_start,
                                      limits=(self.arm.lower, self.arm.upper),
                                      stream=self.state_stream)
        self.rest_at = None

    def _completed(self, config: np.ndarray) -> None:
        self.loop.report_completed(config)
        if self.loop.state.finished:
            self.finish(self.loop.state, 'goal reached' if self.loop.state is State.SUCCEEDED
                        else 'max_paths reached')
        else:
            self._plan_from(self._plan_origin(self._time()) if self._desired_start else config)

    def _onset(self, detector: BlockDetector, now: float, seen: np.ndarray
               ) -> tuple[np.ndarray, int, np.ndarray]:
        """
        Return where the block began, the motion's edge it began on, and the joint direction.

        The edge is the one the arm was on (``Motion.edge_reached``), which may lie before
        the command's: an arm that lags it had not reached the next via point, and a retreat
        through that point would run on into what blocked it.  The direction is the
        command's velocity then, if on that edge; else (a block at rest, a lagging arm) the
        edge's, or the first edge of the motion that has a length.  Without a traced onset,
        the block began at ``seen``, the state (of time now) it was judged on.
        """
        onset = detector.onset
        config, when = (onset.config, onset.time) if onset is not None else \
            (seen, now)
        elapsed = max(when - self.trajectory.taken_at - self.settings.detection.motion_delay,
                      0.0)
        segment = self.motion.edge_reached(config, elapsed)
        direction = onset.velocity if onset is not None and \
            segment == self.motion.segment_at(elapsed) else np.zeros_like(config)
        edges = np.diff(self.motion.via_positions, axis=0)
        order = [segment, *range(segment + 1, len(edges)), *range(segment - 1, -1, -1)]
        for k in order if not np.any(direction) else ():
            if np.any(edges[k]):
                direction = edges[k]
                break
        return config.copy(), segment, np.asarray(direction, dtype=float)

    def _blocked(self, detector: BlockDetector, now: float, seen: np.ndarray) -> None:
        config, segment, _ = self._onset(detector, now, seen)
        path = self.loop.attempts[-1].path
        segment = int(np.clip(segment, 0, len(path) - 2))
        # an edge of no length has no direction: the block is on the next one that moves
        lengths = np.abs(np.diff(path, axis=0)).sum(axis=1)
        moving = np.flatnonzero(lengths > 0)
        if len(moving) and lengths[segment] == 0:
            segment = int(moving[np.argmin(np.abs(moving - segment))])
        back = self.loop.report_blocked(config, segment)
        fmap = self.loop.fmap
        self._emit(Learned({'t': now, 'x': fmap.points[-1].tolist(),
                            'v': fmap.directions[-1].tolist(),
                            'q': fmap.orientations[-1].tolist(), 'segment': segment,
                            'config': config.tolist(), 'why': detector.reason}))
        self.block_time = now
        # from where the arm is (desired start: where JTC's command is), through where the
        # block began, back the way it came
        at = self._time()
        self._send(self._motion(np.vstack([self._plan_origin(at), back]), at), None,
                   at if self._desired_start else None)
        self.retreat_sent = self._time()
        self.phase = Phase.RETREATING
        self.retreat_done_at = None
        self.message = (f'blocked on segment {segment} ({detector.reason}): failure '
                        f'{len(fmap)} recorded, retreating and replanning')
        # plan the next path from the retreat target while the arm moves back
        self.loop.report_retreated(back[-1])
        if self.loop.state.finished:
            self.finish(self.loop.state, 'max_paths reached')
            return
        self.plan_pending = True
        self._emit(PlanFrom(back[-1].copy()))
        self._emit(StatusChanged())

    def _retreat_blocked(self, detector: BlockDetector, now: float, seen: np.ndarray) -> None:
        """Learn a blocked retreat like any block; the next plan starts where the arm is."""
        config, _, direction = self._onset(detector, now, seen)
        if not np.any(direction):
            self.message = f'retreat blocked ({detector.reason}) at rest: nothing to learn'
            return
        self.loop.learn(config, direction)
        fmap = self.loop.fmap
        self._emit(Learned({'t': now, 'x': fmap.points[-1].tolist(),
                            'v': fmap.directions[-1].tolist(),
                            'q': fmap.orientations[-1].tolist(), 'segment': -1,
                            'config': config.tolist(), 'why': f'retreat: {detector.reason}'}))
        self.message = (f'retreat blocked ({detector.reason}): failure {len(fmap)} recorded, '
                        f'replanning from where the arm is')

    def finish(self, state: State, message: str) -> None:
        """End the run: a plan still pending is dropped, the arm comes to rest unless at goal."""
        if state is State.STOPPED:
            self.loop.stop()
        if self.plan_pending and isinstance(self.loop.planner, CancellablePlanner):
            self.loop.planner.cancel()
        self.outcome = state.value
        self.plan_pending = False
        self.pending_path = None
        self._withdraw()
        if self._judged is not None:    # blocked, not yet answered: held pressed in
            self.pressed = self._judged[0] is Verdict.BLOCKED
        elif self.detector is not None:  # held now only if its command began pressed in
            self.pressed = self.detector.pressed
        self.detector, self._judged = None, None
        self.message = message
        self.phase = Phase(state.value)
        if state is not State.SUCCEEDED:
            self._stop_arm()
        self._emit(StatusChanged())

    def _stop_arm(self) -> None:
        """
        Decelerate to rest from the arm's state now, within the limits.

        With a desired start JTC starts the stop from its last command, so it brakes that, and
        a command pressed in past the arm (a block) is then brought back to the arm, or JTC
        would hold it pressed in.  Otherwise JTC starts it from the measured state, carried
        on to now (a stop built from a state even one period old would first pull a moving
        arm back): at its measured velocity over up to one and a half periods; beyond, by what
        the running command did since, while the arm followed it (that also carries its
        acceleration, which the joint states do not), else at its measured velocity for at
        most ``EXTRAPOLATE`` s (a blocked arm barely moves).  When the joint
        states have stopped arriving (older than state_timeout), from where the running
        command has taken the arm by now (the command motion_delay ago): never from a stale
        position.  With a desired start it may be stamped (:func:`stamped`).
        """
        now = self._time()
        age = max(now - self.measured_at, 0.0)
        fresh = age <= self.settings.state_timeout
        delay = self.settings.detection.motion_delay
        last = self._last_command(now)
        release = None
        if last is not None and fresh and self._pressed_in(last[0]):
            try:
                release = self._release(last[0], possible(self.arm, last[1]), last[2])
            except (RuntimeError, ValueError):      # brake it below at least
                release = None
        if release is not None:
            command = stamped(self._message(release), now, self._desired_start)
            self._emit(Send(command, None, now))
            self.trajectory = taken_trajectory(command, now, last[0], last[1], last,
                                               self.period)
            self.sent_at = now
            self.following = True
            return
        if last is not None:
            q, v, a = last        # JTC starts the stop from its last command: brake that
        elif self.trajectory is not None and not fresh:
            q, v, a = self.trajectory.sample(now - self.trajectory.taken_at - delay)
        elif self.measured is not None:
            v = self.measured_velocity
            if v is None or not np.all(np.isfinite(v)):
                v = 0 * self.measured
            a = 0 * self.measured
            if self.trajectory is not None and self.following and age > 1.5 * self.period:
                then = self.trajectory.sample(self.measured_at - self.trajectory.taken_at - delay)
                later = self.trajectory.sample(now - self.trajectory.taken_at - delay)
                q = self.measured + (later[0] - then[0])
                v = v + (later[1] - then[1])
            else:
                q = self.measured + v * min(age, EXTRAPOLATE)
        else:
            return
        q = np.clip(q, self.arm.lower, self.arm.upper)
        v = possible(self.arm, v) if v is not None else 0 * q
        try:
            command = self._message(stop(q, v, a, self.limits))
        except (RuntimeError, ValueError):      # never left without a command to stop
            command = self._message(stop(q, 0 * q, 0 * q, self.limits))   # hold there
        command = stamped(command, now, self._desired_start)
        self._emit(Send(command, None, now))
        # what the arm runs from now on: a later stop without fresh states starts from it
        self.trajectory = taken_trajectory(command, now, q, v, last, self.period)
        self.sent_at = now
        self.following = True

    def status(self) -> dict:
        """Return the run's part of the status document."""
        loop = self.loop
        return {
            'state': self.phase.value,
            'paths': loop.paths_tried if loop else 0,
            'failures': len(loop.fmap) if loop else 0,
            'last_plan_time_s': loop.plan_times[-1] if loop and loop.plan_times else 0.0,
            'last_replan_latency_s': self.latencies[-1] if self.latencies else None,
            'replan_latencies_s': self.latencies,
            'outcome': self.outcome,
            'message': self.message,
            # per joint, the largest external torque estimated from the efforts [Nm]
            'peak_external_torque_nm': None if self.torque_peak is None else
            [round(float(t), 1) for t in self.torque_peak],
            'late_take_max_s': round(self.late_take_max, 3),
            'proposal': self.proposals,
            # the via points [rad] of the path awaiting confirmation (confirm_paths)
            'proposed_path': None if self.proposed is None else self.proposed.tolist(),
        }
