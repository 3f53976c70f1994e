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
The disentangling loop (the paper's ProbDis, Algorithm 1) as a small state machine.

The simulator and the ROS planner node drive the same object::

    loop = Disentangler(arm, planner, goal)
    path = loop.next_path(current)          # plan from where the arm is
    ...execute...
    loop.report_completed(current)          # the whole path ran: at the goal -> success
    retreat = loop.report_blocked(config, segment)   # blocked on edge `segment` at config:
    ...execute retreat...                    #   one failure is added, and the retreat goes
    loop.report_retreated(current)          #   back to the last via point reached

It stops on success, after ``max_paths`` paths (N_ITER), or when asked to (:meth:`stop`).
A plan that finds no feasible path (possible for Hard) still counts as one of the paths, as
an *empty plan* (:attr:`Disentangler.empty_plans`): reports show how many of a method's
paths were empty, so that a baseline that cannot act is seen as such.  The planner draws
from the PLANNER stream of ``seed`` (:mod:`probdis_ros.planning.seeds`), independent of a
world drawn from the same seed.

Decision beyond the paper: the retreat goes back to the last via point reached, as in the
paper, but retraces the way the arm came (the via points it reached, path after path, which
it has moved between without contact) until it is at least ``min_retreat`` from where it
was blocked.  A path blocked on its first edge, right where it started, would otherwise
retreat nowhere: the arm stays in contact, every next path may be blocked at the same
place, and the run ends after N_ITER failures at one point (seen in 3-D sweep episodes).
``min_retreat = 0`` is the paper's rule.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
import time
from typing import Protocol

import numpy as np
from probdis_ros.model.arms import Arm, quaternion_to_rotation
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.planning.seeds import PLANNER, stream

#: Joint-space distance [rad] used to find the task-space direction of a blocked motion.
DIRECTION_PROBE = 1e-3
#: [m] how far ahead of the flange a block met while turning in place is taken to act: a
#: grasped object reaches beyond the flange point, which a pure turn does not move.
LEVER = 0.1
#: How far [rad, joint space] a retreat goes back at least, along the way the arm came.
DEFAULT_MIN_RETREAT = 0.1
#: N_ITER: paths before giving up (the paper's 20).
DEFAULT_MAX_PATHS = 20
#: [rad] joint-space distance to the goal that a run on the arm counts as reached (the
#: paper's simulated worlds stop at 1e-3: the arm ends within its lag and noise).
ROBOT_GOAL_TOLERANCE = 0.04


def failure_from_block(arm: Arm, config: np.ndarray, joint_direction: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """
    Return the failure (x, v, q) of a motion blocked at config while moving along joint_direction.

    x and q are the end-effector pose there; v is its task-space direction of motion, from a
    small step back along the joint direction.
    """
    norm = float(np.linalg.norm(joint_direction))
    if norm == 0.0:
        raise ValueError('a blocked motion needs a nonzero joint direction')
    before = config - DIRECTION_PROBE * joint_direction / norm
    ends = np.array([before, config, config + joint_direction])
    pose = arm.fk(ends)
    v = pose.positions[1] - pose.positions[0]
    if np.linalg.norm(v) < 1e-12:   # singular configuration: use the whole edge's motion
        v = pose.positions[2] - pose.positions[1]
    q = None if pose.orientations is None else pose.orientations[1]
    if np.linalg.norm(v) < 1e-12 and q is not None:
        v = _turn_direction(pose.orientations, pose.positions)
    return pose.positions[1], v, q


def _turn_direction(orientations: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """
    Return the direction of a block met while turning in place (the flange point still).

    The grasped object reaches beyond the flange: the motion of a point LEVER ahead of it
    along the tool's z axis (or, turning about that axis, its x or y axis), first over the
    small step back, then over the whole edge.  Zero if the orientation does not change.
    """
    frames = quaternion_to_rotation(orientations)
    for axis in (2, 0, 1):
        lever = positions + LEVER * frames[:, :, axis]
        for a, b in ((0, 1), (1, 2)):
            v = lever[b] - lever[a]
            if np.linalg.norm(v) >= 1e-12:
                return v
    return np.zeros(3)


class State(str, Enum):
    """Where the loop is."""

    READY = 'ready'              # waiting for next_path
    EXECUTING = 'executing'      # a planned path is being executed
    RETREATING = 'retreating'    # moving back to the last via point reached
    SUCCEEDED = 'succeeded'
    GAVE_UP = 'gave_up'
    STOPPED = 'stopped'

    @property
    def finished(self) -> bool:
        """Tell whether the run is over."""
        return self in (State.SUCCEEDED, State.GAVE_UP, State.STOPPED)


class Planner(Protocol):
    """Anything that plans a joint path from start to goal under a failure map."""

    def plan(self, start: np.ndarray, goal: np.ndarray, fmap: FailureMap,
             rng: np.random.Generator):
        """Return an object with ``path`` (via points) or None if no path was found."""


@dataclass
class Attempt:
    """One planned path and what became of it, for reports and plots."""

    path: np.ndarray
    plan_time_s: float
    blocked_at: np.ndarray | None = None
    segment: int = -1
    empty: bool = False     # the planner found no feasible path; the arm did not move


@dataclass
class Disentangler:
    """Plans, receives execution reports, learns failures, replans."""

    arm: Arm
    planner: Planner
    goal: np.ndarray
    fmap: FailureMap | None = None
    max_paths: int = DEFAULT_MAX_PATHS
    seed: int = 0
    goal_tolerance: float = 1e-3
    min_retreat: float = DEFAULT_MIN_RETREAT
    state: State = State.READY
    attempts: list[Attempt] = field(default_factory=list)

    def __post_init__(self) -> None:
        """Validate the goal and create an empty map and the random generator."""
        self.goal = self.arm.as_batch(self.goal)[0].copy()
        problem = self.arm.limit_problem(self.goal)
        if problem:
            raise ValueError(f'goal is outside the joint limits: {problem}')
        if self.max_paths < 1:
            raise ValueError('max_paths must be at least 1')
        if self.min_retreat < 0:
            raise ValueError('min_retreat must be >= 0')
        if self.fmap is None:
            self.fmap = FailureMap(self.arm.task_space)
        self.rng = stream(self.seed, PLANNER)
        # the way the arm came: configurations it moved between without contact, in order
        self._route: list[np.ndarray] = []

    @property
    def paths_tried(self) -> int:
        """Return the number of paths planned so far."""
        return len(self.attempts)

    @property
    def empty_plans(self) -> int:
        """Return how many of the paths were empty plans (no feasible path found)."""
        return sum(a.empty for a in self.attempts)

    @property
    def plan_times(self) -> list[float]:
        """Return the planning time of every path [s]."""
        return [a.plan_time_s for a in self.attempts]

    def _expect(self, *states: State) -> None:
        if self.state not in states:
            raise RuntimeError(f'disentangler is {self.state.value}, expected '
                               f'{" or ".join(s.value for s in states)}')

    def next_path(self, current: np.ndarray) -> np.ndarray | None:
        """Plan from current; return the via points to execute, or None when finished."""
        if self.state.finished:
            return None
        self._expect(State.READY)
        current = self.arm.as_batch(current)[0]
        if not self._route or not np.array_equal(self._route[-1], current):
            self._route.append(current.copy())
        while self.paths_tried < self.max_paths:
            t0 = time.perf_counter()
            plan = self.planner.plan(current, self.goal, self.fmap, self.rng)
            elapsed = time.perf_counter() - t0
            path = None if plan is None else np.asarray(plan.path, dtype=float)
            self.attempts.append(Attempt(path if path is not None else current[None].copy(),
                                         elapsed, empty=path is None))
            if path is not None:
                self.state = State.EXECUTING
                return path
        self.state = State.GAVE_UP
        return None

    def report_completed(self, current: np.ndarray) -> None:
        """Report that the whole path ran; success if the arm is at the goal."""
        self._expect(State.EXECUTING)
        current = self.arm.as_batch(current)[0]
        self._route += [q.copy() for q in self.attempts[-1].path[1:-1]] + [current.copy()]
        if np.linalg.norm(current - self.goal) <= self.goal_tolerance:
            self.state = State.SUCCEEDED
        elif self.paths_tried >= self.max_paths:
            self.state = State.GAVE_UP
        else:
            self.state = State.READY

    def report_blocked(self, config: np.ndarray, segment: int) -> np.ndarray:
        """
        Report a block at config while executing edge ``segment`` of the current path.

        Adds exactly one failure (where, moving which way, with which orientation) and
        returns the retreat path: back to the last via point reached and on along the way the
        arm came until ``min_retreat`` from config (or back at the start of the run).
        """
        self._expect(State.EXECUTING)
        attempt = self.attempts[-1]
        if not 0 <= segment < len(attempt.path) - 1:
            raise ValueError(f'segment {segment} is not an edge of the current path')
        config = self.arm.as_batch(config)[0]
        attempt.blocked_at, attempt.segment = config.copy(), segment
        self.fmap.add(*self.failure_at(config, attempt.path[segment + 1] - attempt.path[segment]))
        self._route += [q.copy() for q in attempt.path[1:segment + 1]]
        back = len(self._route) - 1
        while back > 0 and np.linalg.norm(self._route[back] - config) < self.min_retreat:
            back -= 1
        retreat = [config, *self._route[back:][::-1]]
        del self._route[back + 1:]      # the arm retraces these; the route ends at the target
        self.state = State.RETREATING
        return np.array(retreat)

    def failure_at(self, config: np.ndarray, joint_direction: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Return the failure (x, v, q) of a block at config, moving along joint_direction."""
        return failure_from_block(self.arm, config, joint_direction)

    def report_retreated(self, current: np.ndarray) -> None:
        """Report that the retreat ended (or stopped); the next plan starts from current."""
        self._expect(State.RETREATING)
        self.state = State.GAVE_UP if self.paths_tried >= self.max_paths else State.READY

    def withdraw(self) -> None:
        """
        Take back the path just planned, which was not executed: plan again from elsewhere.

        The arm is not where that plan starts (its retreat was blocked), so the path would
        begin with an edge the planner never costed; it does not count as a path tried.  Nor
        is that start (the retreat's target) a via point reached: it leaves the route, so
        that the next retreat goes back to the one before it, not along the line just
        blocked (the start of the run stays).
        """
        self._expect(State.EXECUTING)
        start = self.attempts.pop().path[0]
        if len(self._route) > 1 and np.array_equal(self._route[-1], start):
            self._route.pop()
        self.state = State.READY

    def decline(self) -> None:
        """
        Take back the path just planned, which the operator declined: plan again from its start.

        The arm is at that start; the path does not count as a path tried.
        """
        self._expect(State.EXECUTING)
        self.attempts.pop()
        self.state = State.READY

    def learn(self, config: np.ndarray, joint_direction: np.ndarray) -> None:
        """Add the failure of a motion blocked outside a planned path (a blocked retreat)."""
        self.fmap.add(*self.failure_at(self.arm.as_batch(config)[0], joint_direction))

    def stop(self) -> None:
        """End the run now (no further paths)."""
        if not self.state.finished:
            self.state = State.STOPPED
