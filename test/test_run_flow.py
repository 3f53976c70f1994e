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
from probdis_ros.model import iiwa_arm, PlanarArm
from probdis_ros.motion.jtc import JtcTrajectory, TrajectoryController
from probdis_ros.motion.profiles import from_state
from probdis_ros.planning.disentangle import Disentangler
from probdis_ros.run import (
    PlanCancelledError,
    PlanFrom,
    rest_command,
    Run,
    RunSettings,
    scaling_warning,
    Send,
    STAMP_LEAD,
)
import pytest

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


def new_run(goal=Q1, clock=None, max_paths=5, **settings) -> Run:
    """Return a run to goal (RunSettings(**settings)) on the straight planner."""
    loop = Disentangler(ARM, Straight(), goal, max_paths=max_paths, seed=0,
                        goal_tolerance=0.04)
    return Run(ARM, loop, RunSettings(**settings), clock=clock)


def answer_plans(run: Run) -> None:
    """Plan every PlanFrom the run asked for, at once."""
    for action in [a for a in run.actions if isinstance(a, PlanFrom)]:
        run.on_plan(run.loop.next_path(action.config))


def started_run(**settings) -> tuple[Run, list]:
    """Return a run started at Q0 at time 0, its first path planned, and its clock to set."""
    clock = [0.0]
    run = new_run(clock=lambda: clock[0], **settings)
    run.start(0.0, Q0)
    answer_plans(run)
    return run, clock


def sends(run: Run) -> list:
    """Return the commands the run sent, and forget its actions."""
    out = [a.command for a in run.actions if isinstance(a, Send)]
    run.actions.clear()
    return out


# ---------------------------------------------------------------- settings


@pytest.mark.parametrize('name', ['acceleration_limit', 'jerk_limit', 'state_timeout',
                                  'replan_tolerance'])
@pytest.mark.parametrize('bad', [0.0, -0.1, np.nan])
def test_a_run_refuses_a_limit_timeout_or_tolerance_that_is_not_positive(name, bad):
    # a state_timeout of 0 stops every run at its first tick, a replan_tolerance of 0 replans
    # every path whose start the arm has crept off by a microradian: refused by name
    with pytest.raises(ValueError, match=f'{name} must be positive'):
        RunSettings(**{name: bad})


def test_a_run_refuses_an_unknown_jtc_start_naming_the_known_ones():
    # a misspelt jtc_start ('desire') would plan from the measured state while JTC starts
    # from its command: every path then begins with a step
    with pytest.raises(ValueError, match='jtc_start must be one of measured, desired, got'):
        RunSettings(jtc_start='desire')


def test_the_motion_limits_carry_every_setting_and_the_arms_own_limits():
    # every motion is timed with these: a setting dropped here would drive the arm at the
    # default instead of what the operator set
    arm = PlanarArm(velocity_limit=1.5)
    limits = RunSettings(velocity_scaling=0.5, acceleration_scaling=0.25,
                         acceleration_limit=3.0, jerk_limit=40.0).limits(arm)
    assert (limits.velocity_scaling, limits.acceleration_scaling) == (0.5, 0.25)
    np.testing.assert_array_equal(limits.velocity, arm.velocity_limits)
    assert np.all(limits.acceleration == 3.0) and np.all(limits.jerk == 40.0)
    np.testing.assert_array_equal(limits.lower, arm.lower)
    np.testing.assert_array_equal(limits.upper, arm.upper)


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


def test_with_a_measured_start_a_path_moves_at_once_and_with_a_desired_start_after_a_hold():
    # JTC runs a stamped message from its stamp: a path from a command that stands still
    # first holds it STAMP_LEAD, so that one taken late starts within the hold; with the
    # measured start nothing is stamped (JTC starts it when it takes it) and the path has
    # no hold to pay for
    for start, hold in (('measured', 0.0), ('desired', STAMP_LEAD)):
        run = new_run(clock=lambda: 1.0, jtc_start=start)
        run.start(1.0, Q0)
        answer_plans(run)
        path = sends(run)[0]
        moving = np.flatnonzero(np.abs(path.positions - Q0).max(axis=1) > 0)[0]
        assert path.times[moving] == pytest.approx(hold + PERIOD)
        assert path.stamp == (1.0 if start == 'desired' else 0.0)


def test_a_new_run_takes_up_jtc_command_on_the_time_line_it_was_sent_on():
    # with a desired start a new run begins where JTC's last command is: on the time line
    # of when it was sent, not of when the arm began to follow it (the detector moves that
    # on for an arm that begins late, 0.15 s here); from that, the first path began 0.15 s
    # of motion behind the command, a step JTC would take at once
    limits = RunSettings().limits(ARM)
    way = from_state(Q0, None, np.array([Q0, Q1]), limits)
    running = JtcTrajectory(way.command, Q0, None, 0.15)          # sent at 0.0
    commanded, speed, _ = running.sample(0.5)
    assert np.abs(speed).max() > 0.05 and np.abs(commanded - running.sample(0.35)[0]).sum() > 0.01
    clock = [0.5]
    run = new_run(goal=Q0, clock=lambda: clock[0], jtc_start='desired')
    run.start(0.5, running.sample(0.35)[0], running.sample(0.35)[1], running, 0.0)
    plans_from(run)
    sent = sends(run)
    assert len(sent) == 1
    np.testing.assert_allclose(sent[0].positions[0], commanded, atol=1e-9)
    np.testing.assert_allclose(sent[0].velocities[0], speed, atol=1e-9)


def test_a_start_within_goal_tolerance_succeeds_at_once_and_one_just_outside_plans():
    # goal_tolerance is the planner's own: a start just outside it must still be driven there
    for off, phase in ((0.03, 'succeeded'), (0.05, 'planning')):
        run = new_run(clock=lambda: 0.0)
        run.start(0.0, Q1 + np.r_[off, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        assert run.phase.value == phase
        assert sum(isinstance(a, PlanFrom) for a in run.actions) == (phase == 'planning')


def test_a_measured_start_on_an_arm_still_moving_begins_its_path_at_the_arms_speed():
    # the arm may still run the last command when a run starts: JTC starts the path from the
    # measured state, velocity included; from rest it would stop the moving arm dead
    moving = np.r_[0.2, -0.1, 0.0, 0.15, 0.0, 0.0, 0.0]
    run = new_run(clock=lambda: 0.0)
    run.start(0.0, Q0, moving)
    answer_plans(run)
    sent = sends(run)
    assert len(sent) == 1
    np.testing.assert_allclose(sent[0].velocities[0], moving, atol=1e-9)


# ---------------------------------------------------------------- blocks, plans, latencies


def drive(run: Run, clock: list, until: float, blocked=(), plan_after: float = 0.0,
          lead: float = 0.0, t: float = 0.0, done=lambda run: False,
          origins: list | None = None) -> float:
    """
    Drive the run on an arm that follows each command motion_delay late, every 10 ms.

    The arm is held where it is during each (start, end) interval of ``blocked``; the run's
    clock reads ``lead`` s past each state's time (the host's processing); each plan comes
    back ``plan_after`` s after it was asked for (its start appended to ``origins``).  From
    t until the run ends, ``until`` or done(run); return the time driven to.
    """
    delay = run.settings.detection.motion_delay
    held, asked = None, []
    while run.active and t < until and not done(run):
        t = round(t + PERIOD, 9)
        clock[0] = t + lead
        jtc = run.trajectory
        q = jtc.sample(t - jtc.taken_at - delay)[0] if jtc is not None else run.measured
        if any(start <= t < end for start, end in blocked):
            held = q if held is None else held
        else:
            held = None
        run.on_joint_state(t, q if held is None else held, None)
        asked += [(t + plan_after, a) for a in run.actions if isinstance(a, PlanFrom)]
        if origins is not None:
            origins += [a.config for a in run.actions if isinstance(a, PlanFrom)]
        run.actions[:] = [a for a in run.actions if not isinstance(a, PlanFrom)]
        for item in [a for a in asked if a[0] <= t]:
            asked.remove(item)
            run.on_plan(run.loop.next_path(item[1].config))
        run.tick(t)
    return t


def blocked_and_retreated(lead: float = 0.0, **settings) -> tuple[Run, list, float]:
    """Return a run whose first path was blocked at 0.6 s, its retreat done, plan awaited."""
    run, clock = started_run(**settings)
    if run.phase.value == 'awaiting_confirmation':
        run.confirm(0.0)
    t = drive(run, clock, 10.0, blocked=[(0.6, 1.2)], plan_after=np.inf, lead=lead,
              done=lambda run: run.retreat_done_at is not None)
    assert run.phase.value == 'retreating' and run.plan_pending
    return run, clock, t


def test_the_replan_latency_counts_the_retreat_and_the_wait_for_the_plan_after_it():
    # after a block the status reports how long until the next path was ready: from the
    # block seen to its retreat sent (the host's clock, here 0.02 s on), plus however long
    # the plan came after the retreat was done (0.3 s, 0.32 s on the host's clock)
    run, clock, t = blocked_and_retreated(lead=0.02)
    assert run.retreat_sent - run.block_time == pytest.approx(0.02)
    t = run.retreat_done_at + 0.3
    clock[0] = t + 0.02
    run.on_plan(run.loop.next_path(run.measured))
    assert run.phase.value == 'executing'
    assert run.latencies == [pytest.approx(0.34)]
    assert run.status()['last_replan_latency_s'] == pytest.approx(0.34)
    # a plan that came before the retreat was done waits for nothing more than the host
    # (0.02 s at the block, 0.02 s at the retreat's end)
    drive(run, clock, 20.0, t=t, blocked=[(t + 0.6, t + 1.2)], plan_after=0.0, lead=0.02,
          done=lambda run: len(run.latencies) > 1)
    assert run.latencies[1] == pytest.approx(0.04)
    assert run.status()['last_replan_latency_s'] == pytest.approx(0.04)
    assert run.status()['replan_latencies_s'] == run.latencies


def test_a_block_counts_one_latency_until_its_path_is_proposed_not_another_at_the_confirm():
    # with confirm_paths the latency ends when the next path is shown to the operator; the
    # time the operator takes is not the planner's, and confirming it is no second replan
    run, clock, _ = blocked_and_retreated(confirm_paths=True)
    run.on_plan(run.loop.next_path(run.measured))
    assert run.phase.value == 'awaiting_confirmation' and len(run.latencies) == 1
    latency = run.latencies[0]
    clock[0] += 0.2
    assert run.confirm(clock[0]) == '' and run.phase.value == 'executing'
    assert run.latencies == [latency]


def test_with_a_desired_start_the_plan_after_a_path_short_of_the_goal_begins_at_the_command():
    # the arm ends a path 0.08 rad (L1) short of its command (a sag within d_dist: done),
    # outside goal_tolerance: the next path is planned from where JTC's command holds, where
    # the next command will start, not from the arm (which would be withdrawn and planned
    # again: a plan lost)
    clock = [1.0]
    run = new_run(clock=lambda: clock[0], jtc_start='desired')
    run.start(1.0, Q0)
    answer_plans(run)
    assert len(sends(run)) == 1
    sag = np.r_[0.0, 0.04, 0.0, 0.04, 0.0, 0.0, 0.0]
    jtc, delay = run.trajectory, run.settings.detection.motion_delay
    t, asked = 1.0, []
    while run.phase.value == 'executing' and t < 10.0:
        t = clock[0] = round(t + PERIOD, 9)
        q = jtc.sample(t - jtc.taken_at - delay)[0]
        run.on_joint_state(t, q - sag * min(1.0, (t - 1.0) / jtc.duration), None)
        asked += [a.config for a in run.actions if isinstance(a, PlanFrom)]
        run.actions.clear()
    assert run.phase.value == 'planning' and len(asked) == 1
    np.testing.assert_allclose(asked[0], Q1, atol=1e-9)


def test_a_plan_from_where_a_blocked_retreat_did_not_go_is_planned_again_from_the_arm():
    # the retreat was blocked too: the arm is not where the plan made meanwhile begins (the
    # retreat's target), whose first edge would be uncosted; it is planned again from where
    # the arm is, and that path is sent
    run, clock = started_run()
    run.actions.clear()
    origins = []
    t = drive(run, clock, 10.0, blocked=[(0.6, 20.0)], plan_after=0.5, origins=origins,
              done=lambda run: len(origins) > 1)
    assert run.phase.value == 'planning' and run.plan_pending     # the status says so
    clock[0] = t + 0.5
    run.on_plan(run.loop.next_path(origins[-1]))
    assert run.phase.value == 'executing'
    held = run.measured
    assert np.abs(held - Q0).sum() > 0.2 and run.loop.paths_tried == 2
    assert len(origins) == 2 and np.abs(origins[0] - Q0).max() < 1e-9
    np.testing.assert_allclose(origins[1], held, atol=1e-6)
    np.testing.assert_allclose(run.loop.attempts[-1].path[0], held, atol=1e-6)


def test_a_path_from_an_arm_pressed_after_a_blocked_retreat_may_be_blocked_at_once():
    # the retreat moved, then was blocked too; the next path starts from the arm pressed
    # against that: blocked at once, it has not moved the arm, which is a block to learn,
    # not a controller that executes nothing
    run, clock = started_run()
    run.actions.clear()
    t = drive(run, clock, 10.0, blocked=[(0.6, 20.0)],
              done=lambda run: run.phase.value == 'retreating')
    drive(run, clock, 20.0, t=t, blocked=[(t + 0.3, 40.0)],
          done=lambda run: len(run.loop.fmap) >= 3)
    assert run.active and len(run.loop.fmap) == 3, run.message
    assert run.phase.value == 'retreating'


def test_a_block_on_the_last_path_allowed_gives_up_at_once_and_plans_nothing_more():
    # max_paths reached with the block: the run ends there (the arm brought to rest), no
    # plan is asked for that could only come back empty
    run, clock = started_run(max_paths=1)
    run.actions.clear()
    origins = []
    drive(run, clock, 5.0, blocked=[(0.6, 20.0)], origins=origins)
    assert (run.outcome, run.message) == ('gave_up', 'max_paths reached')
    assert not origins and len(run.loop.fmap) == 1


def test_a_block_judged_on_a_state_with_newer_ones_waiting_is_answered_at_the_tick():
    # a block judged in a burst is answered from the newest state; when the newer states
    # never come (the stream stopped), the next tick answers it from the last one
    run, clock = started_run()
    jtc, delay = run.trajectory, run.settings.detection.motion_delay
    t = 0.0
    while run.detector is not None and t < 5.0:
        t = clock[0] = round(t + PERIOD, 9)
        run.on_joint_state(t, jtc.sample(min(t, 0.6) - delay)[0], None, newest=t < 0.6)
    assert run.phase.value == 'executing' and run._judged is not None
    run.tick(t + PERIOD)
    assert run.phase.value == 'retreating' and len(run.loop.fmap) == 1
    assert sum(isinstance(a, Send) for a in run.actions) == 2       # the path, its retreat


def test_a_stop_before_a_judged_block_is_answered_brings_the_pressed_command_back_to_the_arm():
    # desired start: JTC's command has run on past the held arm; stopped before the block is
    # answered, the stop must still treat the arm as held and bring the command back to it,
    # or JTC would hold it pressed in (200 Nm/rad on the real arm)
    run, clock = started_run(jtc_start='desired')
    run.actions.clear()
    jtc, delay = run.trajectory, run.settings.detection.motion_delay
    t = 0.0
    while run.detector is not None and t < 5.0:
        t = clock[0] = round(t + PERIOD, 9)
        run.on_joint_state(t, jtc.sample(min(t, 0.6) - delay)[0], None, newest=False)
    held = jtc.sample(0.6 - delay)[0]
    assert run._judged is not None and np.abs(jtc.sample(t)[0] - held).sum() > 0.1
    run.stop()
    stop = sends(run)[-1]
    assert run.outcome == 'stopped'
    np.testing.assert_allclose(stop.positions[-1], held, atol=0.02)


def test_a_stop_after_silence_does_not_carry_on_an_arm_that_had_stopped_near_its_command():
    # the arm stopped dead 20 ms ago, still within d_dist of its command (not yet judged),
    # and says so in its velocities; then no state for 50 ms: the stop starts where the arm
    # is, not where the command took it meanwhile (as though it still followed), which would
    # pull it on into what stopped it
    run, clock = started_run(velocity_scaling=0.7)
    jtc, delay = run.trajectory, run.settings.detection.motion_delay
    t = 0.0
    while t < 0.62:
        t = clock[0] = round(t + PERIOD, 9)
        q, v, _ = jtc.sample(min(t, 0.6) - delay)
        run.on_joint_state(t, q, v if t <= 0.6 else 0 * v)
    held = jtc.sample(0.6 - delay)[0]
    assert np.abs(jtc.sample(t - delay)[0] - held).sum() < run.settings.detection.d_dist
    assert np.abs(jtc.sample(t - delay)[1]).sum() > 1.0 and run.phase.value == 'executing'
    clock[0] = t + 0.05
    run.actions.clear()
    run.stop()
    np.testing.assert_allclose(sends(run)[-1].positions[0], held, atol=1e-9)


def test_a_stop_of_an_arm_on_its_command_without_velocities_starts_at_the_commands_speed():
    # a driver that sends no velocities, its positions noisy (1 mrad at 1 kHz): an arm on
    # its command moves as the command says; the slope of its positions is the noise
    # differentiated (about 0.1 rad/s a joint over the window), a stop from it a step
    rng = np.random.default_rng(0)
    run, clock = started_run(velocity_scaling=0.7)
    jtc, delay = run.trajectory, run.settings.detection.motion_delay
    t = 0.0
    while t < 0.5:
        t = clock[0] = round(t + 0.001, 9)
        run.on_joint_state(t, jtc.sample(t - delay)[0] + rng.normal(0.0, 0.001, 7), None)
    assert run.phase.value == 'executing' and run.following
    run.actions.clear()
    run.stop()
    np.testing.assert_allclose(sends(run)[-1].velocities[0], jtc.sample(t - delay)[1],
                               atol=1e-9)


def test_the_latest_take_is_kept_over_the_run_not_only_the_last_commands():
    # the status tells how late any command began (an arm lagging more than motion_delay:
    # measure it again), not only the last: here the path 0.15 s late, its retreat on time
    run, clock = started_run()
    run.actions.clear()
    delay = run.settings.detection.motion_delay
    t = 0.0
    while run.phase.value == 'executing' and t < 5.0:
        t = clock[0] = round(t + PERIOD, 9)
        jtc = run.trajectory
        run.on_joint_state(t, jtc.sample(min(t, 0.9) - jtc.taken_at - delay - 0.15)[0])
    assert run.phase.value == 'retreating'
    drive(run, clock, 10.0, t=t, plan_after=np.inf,
          done=lambda run: run.retreat_done_at is not None)
    assert run.retreat_done_at is not None
    assert run.status()['late_take_max_s'] == pytest.approx(0.15, abs=0.02)


def test_a_run_that_reaches_its_goal_says_so_and_sends_nothing_after_its_path():
    # at the goal the path's own end holds the arm there; a stop would only nudge it
    run, clock = started_run()
    run.actions.clear()
    drive(run, clock, 10.0)
    assert (run.outcome, run.message) == ('succeeded', 'goal reached')
    assert not any(isinstance(a, Send) for a in run.actions)


# ---------------------------------------------------------------- proposals


def plans_from(run: Run) -> list:
    """Answer each plan asked for, and each asked for then; return where each began."""
    origins = []
    while any(isinstance(a, PlanFrom) for a in run.actions):
        asked = [a for a in run.actions if isinstance(a, PlanFrom)]
        run.actions[:] = [a for a in run.actions if not isinstance(a, PlanFrom)]
        for action in asked:
            origins.append(action.config)
            run.on_plan(run.loop.next_path(action.config))
    return origins


def test_with_a_desired_start_proposals_begin_and_are_confirmed_where_jtc_command_is():
    # with a desired start JTC starts the next command from its own, which a free arm at
    # rest may sit short of (here 0.08 rad L1, within d_dist): a path is planned from the
    # command, declined or confirmed against it; measured against the arm, a confirm was
    # refused as though the arm had moved, and a decline planned from where no command starts
    command_at = Q0 + np.r_[0.0, 0.04, 0.0, 0.04, 0.0, 0.0, 0.0]
    limits = RunSettings().limits(ARM)
    holding = JtcTrajectory(rest_command(ARM, limits, command_at), command_at, None, -2.0)
    run = new_run(clock=lambda: 0.0, confirm_paths=True, jtc_start='desired')
    run.start(0.0, Q0, np.zeros(7), holding, -2.0)
    assert np.abs(plans_from(run)[-1] - command_at).max() < 1e-9
    assert run.phase.value == 'awaiting_confirmation'
    np.testing.assert_allclose(run.proposed[0], command_at)
    assert run.decline(0.0) == ''
    origins = plans_from(run)
    assert len(origins) == 1 and np.abs(origins[0] - command_at).max() < 1e-9
    run.actions.clear()
    assert run.confirm(0.0) == ''
    sent = sends(run)
    assert len(sent) == 1 and np.abs(sent[0].positions[0] - command_at).max() < 1e-9


# ---------------------------------------------------------------- ends


def test_a_run_stopped_while_planning_cancels_the_next_plan_and_drops_the_one_under_way():
    # the planner runs on the host's worker: after a stop no further plan may start, and
    # the result of the one under way must not send the arm anywhere
    run = new_run(clock=lambda: 0.0)
    run.start(0.0, Q0)
    asked = [a for a in run.actions if isinstance(a, PlanFrom)]
    run.stop()
    assert run.phase.value == 'stopped' and run.loop.state.value == 'stopped'
    with pytest.raises(PlanCancelledError):
        run.loop.planner.plan(Q0, Q1, run.loop.fmap, None)
    run.actions.clear()
    run.on_plan(np.array([Q0, Q1]))
    run.plan_failed(RuntimeError('the planner failed after the stop'))
    assert not run.actions and run.message == 'stopped on request'
    assert asked and not run.plan_pending


def test_a_stop_after_the_run_has_ended_still_holds_the_arm():
    # ~/stop is the operator's way to hold the arm whatever the run's state: after the run
    # has ended (here at its goal) it still sends a command to rest
    run = new_run(clock=lambda: 0.0)
    run.start(0.0, Q1)
    assert run.outcome == 'succeeded' and not run.active
    run.actions.clear()
    run.stop()
    held = sends(run)
    assert len(held) == 1 and np.abs(held[0].positions - Q1).max() < 1e-9
    assert run.outcome == 'succeeded'


# ---------------------------------------------------------------- status


def test_the_peak_external_torque_is_only_what_the_arm_met_while_the_run_drove_it():
    # the status reports how hard the run pushed: a push on the arm before the run began or
    # after it ended (someone moving it by hand) is not the run's
    run = new_run(clock=lambda: 0.0)
    pushed = np.r_[0.0, 40.0, 0.0, 20.0, 0.0, 0.0, 0.0]
    for k in range(50):
        run.on_joint_state(0.01 * k, Q1, np.zeros(7), pushed)
    run.start(0.5, Q1)                                  # at the goal: ends at once
    for k in range(50):
        run.on_joint_state(0.5 + 0.01 * k, Q1, np.zeros(7), pushed)
    assert not run.active and run.status()['peak_external_torque_nm'] is None


def test_the_status_counts_paths_failures_and_proposals_and_shows_the_newest():
    # the node publishes this document as it is: the operator reads the run from it
    run = new_run(clock=lambda: 0.0)
    status = run.status()
    assert (status['state'], status['paths'], status['failures'], status['proposal']) == \
        ('idle', 0, 0, 0)
    assert status['last_replan_latency_s'] is None and status['proposed_path'] is None
    run, _, _ = blocked_and_retreated()
    status = run.status()
    assert (status['state'], status['paths'], status['failures']) == ('retreating', 1, 1)
    run.on_plan(run.loop.next_path(run.measured))
    status = run.status()
    assert (status['state'], status['paths'], status['failures']) == ('executing', 2, 1)
    times = run.loop.plan_times
    assert times[0] != times[1] and status['last_plan_time_s'] == times[1]
    # with confirm_paths, the path waiting and how many were proposed
    run = new_run(clock=lambda: 0.0, confirm_paths=True)
    run.start(0.0, Q0)
    answer_plans(run)
    run.actions.clear()
    assert run.status()['proposal'] == 1
    np.testing.assert_allclose(run.status()['proposed_path'], [Q0, Q1])
    assert run.decline(0.0) == ''
    answer_plans(run)
    assert run.status()['proposal'] == 2 and run.status()['paths'] == 1


def test_a_run_faster_than_the_default_is_warned_of_the_drivers_guard_in_clutter():
    # on fresh family worlds the guard ended 0, 1, 9 and 21 of 100 runs at 0.2 ... 0.5
    assert scaling_warning(RunSettings().velocity_scaling) == '' == scaling_warning(0.1)
    warning = scaling_warning(0.3)
    assert warning.startswith('velocity_scaling 0.3: in clutter, impacts this fast spike')
    assert warning.endswith('near clutter keep 0.2')
