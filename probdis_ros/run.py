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
planned) -> ... -> succeeded | gave_up | stopped.  A command is checked against the joint
limits before it is sent; whatever ends a run that is not at the goal holds the arm.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.motion.detector import BlockDetector, DetectorSettings, Verdict
from probdis_ros.motion.jtc import JtcTrajectory, TrajectoryCommand
from probdis_ros.motion.timing import hold_command, nearest_segment, time_path
from probdis_ros.planning.disentangle import Disentangler, State


class Phase(str, Enum):
    """Where a run is; the value is what the status reports."""

    IDLE = 'idle'
    PLANNING = 'planning'
    EXECUTING = 'executing'
    RETREATING = 'retreating'
    SUCCEEDED = 'succeeded'
    GAVE_UP = 'gave_up'
    STOPPED = 'stopped'

    @property
    def active(self) -> bool:
        """Tell whether the arm is being driven by the run."""
        return self in (Phase.PLANNING, Phase.EXECUTING, Phase.RETREATING)


@dataclass
class RunSettings:
    """How a run drives the arm; every default in one place (the node declares these)."""

    velocity_scaling: float = 0.2
    d_dist: float = 0.04
    stall_time: float = 0.3
    state_timeout: float = 0.5

    def __post_init__(self) -> None:
        """Refuse values a run cannot use, naming them."""
        if not 0.0 < self.velocity_scaling <= 1.0:
            raise ValueError(f'velocity_scaling must be in (0, 1], got {self.velocity_scaling}')
        for name in ('d_dist', 'stall_time', 'state_timeout'):
            if not getattr(self, name) > 0:
                raise ValueError(f'{name} must be positive, got {getattr(self, name)}')

    @property
    def detector(self) -> DetectorSettings:
        """Return the detector's thresholds."""
        return DetectorSettings(d_dist=self.d_dist, stall_time=self.stall_time)


@dataclass(frozen=True)
class Send:
    """Send this command to the controller."""

    command: TrajectoryCommand
    path: np.ndarray | None = None     # the planned via points, for markers (paths only)


@dataclass(frozen=True)
class PlanFrom:
    """Plan the next path from this configuration (``loop.next_path``), then on_plan."""

    config: np.ndarray


@dataclass(frozen=True)
class Learned:
    """A block was detected and one failure added to the map."""

    event: dict


@dataclass(frozen=True)
class StatusChanged:
    """The status changed; publish it."""


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
        self.measured: np.ndarray | None = None
        self.measured_velocity: np.ndarray | None = None
        self.measured_at = -np.inf
        self.detector: BlockDetector | None = None
        self.plan_pending = False
        self.pending_path: np.ndarray | None = None
        self.block_time: float | None = None
        self.retreat_sent = 0.0
        self.retreat_done_at: float | None = None
        self.hold_on_next_state = False
        self.latencies: list[float] = []
        self.outcome = ''
        self.message = 'ready'
        self._now = -np.inf

    # -- events ------------------------------------------------------------------------

    def start(self, now: float, config: np.ndarray) -> None:
        """Start from config, the newest measured configuration."""
        self._now = now
        self.measured = np.asarray(config, dtype=float).copy()
        self.measured_at = now
        self.outcome, self.message = '', 'running'
        self._plan_from(self.measured)

    def on_joint_state(self, now: float, config: np.ndarray,
                       velocity: np.ndarray | None = None) -> None:
        """Take a measured configuration at time now."""
        self._now = now
        self.measured, self.measured_at = np.asarray(config, dtype=float), now
        self.measured_velocity = velocity
        if self.hold_on_next_state:
            self._hold()
            self.hold_on_next_state = False
        if self.detector is None or not self.phase.active:
            return
        verdict = self.detector.update(now, self.measured)
        if verdict is Verdict.MOVING:
            return
        self.detector = None
        if self.phase is Phase.EXECUTING:
            if verdict is Verdict.DONE:
                self._completed(self.measured)
            else:
                self._blocked(self.measured, now)
        elif self.phase is Phase.RETREATING:
            self.retreat_done_at = now
            self._send_pending()

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
        """A planner error must not leave the arm moving."""
        if self.plan_pending:
            self.plan_pending = False
            self.finish(State.STOPPED, f'planning failed: {error}')

    def tick(self, now: float) -> None:
        """Check the joint states are fresh (at least every state_timeout)."""
        self._now = now
        age = now - self.measured_at
        if self.phase.active and age > self.settings.state_timeout:
            self.finish(State.STOPPED, f'joint states stopped arriving: none for {age:.2f} s '
                                       f'(state_timeout)')

    def stop(self, reason: str = 'stopped on request') -> None:
        """End the run now and hold (or just hold when no run is active)."""
        if not self.phase.active:
            self._hold()
            return
        self.finish(State.STOPPED, reason)

    def bad_joint_state(self, reason: str) -> None:
        """A malformed joint state arrived: an active run stops."""
        if self.phase.active:
            self.finish(State.STOPPED, f'malformed joint state: {reason}')

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

    def _arm_ready(self) -> bool:
        return self.phase is Phase.PLANNING or (
            self.phase is Phase.RETREATING and self.retreat_done_at is not None)

    def _send_pending(self) -> None:
        if self.pending_path is None or not self._arm_ready():
            return
        path, self.pending_path = self.pending_path, None
        path[0] = self.measured
        if not self.arm.within_limits(path).all():
            self.finish(State.STOPPED, 'planned path leaves the joint limits; not sent')
            return
        timed = time_path(path, self.arm.velocity_limits, self.settings.velocity_scaling)
        now = self._time()
        if self.block_time is not None:
            waited = (self.retreat_sent - self.block_time) + max(
                0.0, now - (self.retreat_done_at or now))
            self.latencies.append(waited)
            self.block_time = None
        self._send(timed.command(), path)
        self.phase = Phase.EXECUTING
        self.retreat_done_at = None
        self._emit(StatusChanged())

    def _send(self, command: TrajectoryCommand, path: np.ndarray | None = None) -> None:
        """Send a command and watch it as JTC runs it, from the measured state now."""
        self._emit(Send(command, path))
        trajectory = JtcTrajectory(command, self.measured, self.measured_velocity)
        self.detector = BlockDetector(trajectory, self._time(), self.settings.detector)

    def _completed(self, config: np.ndarray) -> None:
        self.loop.report_completed(config)
        if self.loop.state.finished:
            self.finish(self.loop.state, 'goal reached' if self.loop.state is State.SUCCEEDED
                        else 'max_paths reached')
        else:
            self._plan_from(config)

    def _blocked(self, config: np.ndarray, now: float) -> None:
        path = self.loop.attempts[-1].path
        segment = nearest_segment(path, config)
        retreat = self.loop.report_blocked(config, segment)
        fmap = self.loop.fmap
        self._emit(Learned({'t': now, 'x': fmap.points[-1].tolist(),
                            'v': fmap.directions[-1].tolist(),
                            'q': fmap.orientations[-1].tolist(), 'segment': segment}))
        self.block_time = now
        timed = time_path(retreat, self.arm.velocity_limits, self.settings.velocity_scaling)
        self._send(timed.command())
        self.retreat_sent = self._time()
        self.phase = Phase.RETREATING
        self.retreat_done_at = None
        self.message = (f'blocked on segment {segment}: failure {len(fmap)} recorded, '
                        f'retreating and replanning')
        # plan the next path from the retreat target while the arm moves back
        self.loop.report_retreated(retreat[-1])
        if self.loop.state.finished:
            self.finish(self.loop.state, 'max_paths reached')
            return
        self.plan_pending = True
        self._emit(PlanFrom(retreat[-1].copy()))
        self._emit(StatusChanged())

    def finish(self, state: State, message: str) -> None:
        """End the run: a plan still pending is dropped, the arm holds unless at goal."""
        if state is State.STOPPED:
            self.loop.stop()
        self.outcome = state.value
        self.plan_pending = False
        self.pending_path = None
        self.detector = None
        self.message = message
        self.phase = Phase(state.value)
        if state is not State.SUCCEEDED:
            self._hold()
            self.hold_on_next_state = True
        self._emit(StatusChanged())

    def _hold(self) -> None:
        if self.measured is not None:
            self._emit(Send(hold_command(self.measured)))

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
        }
