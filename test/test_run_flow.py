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
The run's flow without ROS: its settings, stamps, plans, proposals, latencies and status.

A straight-line planner and JTC's rules (``jtc.TrajectoryController``) stand in for the
planner and the controller; each test drives a :class:`Run` by hand through the events that
matter to it.
"""

from dataclasses import dataclass

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.jtc import TrajectoryController
from probdis_ros.planning.disentangle import Disentangler
from probdis_ros.run import PlanFrom, Run, RunSettings, Send

ARM = iiwa_arm()
Q0 = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
Q1 = Q0 + np.array([0.6, 0.3, 0.0, 0.4, 0.0, -0.3, 0.0])
PERIOD = 0.01


@dataclass
class Path:
    """What the planner returns."""

    path: np.ndarray


class Straight:
    """A planner of one straight edge to the goal."""

    def plan(self, start, goal, fmap, rng):
        """Return the edge from start to goal."""
        return Path(np.array([start, goal]))


def new_run(goal=Q1, clock=None, **settings) -> Run:
    """Return a run to goal (RunSettings(**settings)) on the straight planner."""
    loop = Disentangler(ARM, Straight(), goal, max_paths=5, seed=0, goal_tolerance=0.04)
    return Run(ARM, loop, RunSettings(**settings), clock=clock)


def answer_plans(run: Run) -> None:
    """Plan every PlanFrom the run asked for, at once."""
    for action in [a for a in run.actions if isinstance(a, PlanFrom)]:
        run.on_plan(run.loop.next_path(action.config))


def sends(run: Run) -> list:
    """Return the commands the run sent, and forget its actions."""
    out = [a.command for a in run.actions if isinstance(a, Send)]
    run.actions.clear()
    return out


# ---------------------------------------------------------------- stamps and holds


def restart_after_a_stop(gap: float, late: float) -> np.ndarray:
    """
    Stop a run (desired start) 0.5 s into its path, start another gap s later.

    JTC takes the new run's path late s after it was sent; return JTC's speed per period
    as a fraction of each joint's velocity limit (the largest joint's).
    """
    clock = [1.0]
    jtc = TrajectoryController(PERIOD, 'desired')
    first = new_run(clock=lambda: clock[0], jtc_start='desired')
    first.start(1.0, Q0)
    answer_plans(first)
    inbox = [(1.0, command) for command in sends(first)]
    commands = []
    for k in range(round(0.5 / PERIOD + gap / PERIOD) + 60):
        t = clock[0] = round(1.0 + k * PERIOD, 9)
        for item in [d for d in inbox if d[0] <= t + 1e-12]:
            jtc.receive(item[1])
            inbox.remove(item)
        commands.append(jtc.update(t, Q0 if not commands else commands[-1]))
        if k == round(0.5 / PERIOD):
            first.stop()
            inbox += [(t, command) for command in sends(first)]
        if k == round(0.5 / PERIOD + gap / PERIOD):
            second = new_run(clock=lambda: clock[0], jtc_start='desired')
            second.start(t, commands[-1], np.zeros(7), first.trajectory, first.sent_at)
            answer_plans(second)
            inbox += [(t + late, command) for command in sends(second)]
    speed = np.abs(np.diff(np.array(commands), axis=0)) / PERIOD / ARM.velocity_limits
    return speed.max(axis=1)


def test_a_path_after_a_stop_that_has_come_to_rest_is_held_however_soon_it_is_sent():
    # a stamped stop holds its last point up to STAMP_HORIZON (1 s) after its stamp; JTC's
    # command stands still there all the same, so a path sent meanwhile must first hold it
    # (STAMP_LEAD) like one sent later: taken 0.12 s late (a stall of this host), an unheld
    # path started 0.12 s into its ramp, JTC's command at 1.5 x a joint's velocity limit
    for gap in (0.5, 1.5):
        assert restart_after_a_stop(gap, 0.12).max() <= 0.2 + 1e-6    # velocity_scaling
