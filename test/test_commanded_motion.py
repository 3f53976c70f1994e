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
Commanded motion only, failures from blocks only (no rclpy): the detector through noise.

What issue 14 asks of the rclpy-free parts: a stall is seen through 0.005 rad of joint-state
noise at 1 kHz; an arm that never begins to follow a path was not commanded by anything that
runs (nothing learned); an arm that moves while it should rest, a second publisher and
stale states stop a run without learning.
"""

from dataclasses import dataclass, replace
import re

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion import detector as detector_module
from probdis_ros.motion import state_check
from probdis_ros.motion.detector import (
    BlockDetector,
    DetectorSettings,
    LIMIT_HORIZON,
    motion_over,
    MotionWatch,
    RETREAT_START_WAIT,
    START_WAIT,
    StateStream,
    Verdict,
)
from probdis_ros.motion.jtc import (
    JtcTrajectory,
    taken_trajectory,
    TrajectoryCommand,
    TrajectoryController,
)
from probdis_ros.motion.profiles import from_state
from probdis_ros.motion.state_check import BadJointStateError, StateCheck
from probdis_ros.planning.disentangle import Disentangler, failure_from_block
from probdis_ros.planning.prob_rrt import ROBOT_JOINT_MARGIN
from probdis_ros.run import (
    Learned,
    MAX_VELOCITY_SCALING,
    PlanFrom,
    Run,
    RunSettings,
    Send,
    STAMP_HORIZON,
)
import pytest

ARM = iiwa_arm()
NAMES = [f'lbr_A{i}' for i in range(1, 8)]
Q0 = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
Q1 = Q0 + np.array([0.6, 0.3, 0.0, 0.4, 0.0, -0.3, 0.0])
NOISE = 0.005
RATE = 1000.0
SETTINGS = RunSettings()


def trajectory(q0=Q0, q1=Q1) -> JtcTrajectory:
    motion = from_state(q0, None, np.array([q0, q1]), SETTINGS.limits(ARM))
    return JtcTrajectory(motion.command, q0, None, 0.0)


def judge(detector, arm, until, seed=0):
    """Feed arm(t) plus noise at RATE until a verdict other than MOVING; return (t, verdict)."""
    return watch(detector, arm, until, np.random.default_rng(seed), NOISE)


def follows(jtc, settings, blocked_at=np.inf):
    """Return the arm: its command motion_delay late, stopped dead at blocked_at."""
    return lambda t: jtc.sample(min(t, blocked_at) - settings.motion_delay)[0]


STEP = 1.0 / RATE    # [s] the simulated arms' time step


def lagging(target, lag, q0=Q0):
    """Return an arm following target(t) with a first-order lag [s]: call it once a STEP."""
    q = q0.copy()

    def advance(t):
        q[:] += (target(t) - q) * STEP / lag
        return q
    return advance


def impedance(target, inertia, stiffness=200.0, damping_ratio=0.7, q0=Q0):
    """Return an arm held to target(t) by a joint spring and damper on a link's inertia."""
    q, v = q0.copy(), np.zeros(len(q0))
    damping = 2 * damping_ratio * np.sqrt(stiffness * inertia)

    def advance(t):
        v[:] += (stiffness * (target(t) - q) - damping * v) / inertia * STEP
        q[:] += v * STEP
        return q
    return advance


def watch(detector, arm, until, rng, noise, every=1):
    """
    Run arm(t) every STEP, its state plus noise every ``every`` STEPs, until a verdict.

    Return (t, verdict), (None, MOVING) where none other came by until.
    """
    for k, t in enumerate(np.arange(0.0, until, STEP)):
        q = arm(t)
        if k % every == 0:
            verdict = detector.update(t, q + rng.normal(0.0, noise, len(q)))
            if verdict is not Verdict.MOVING:
                return t, verdict
    return None, Verdict.MOVING


# ------------------------------------------------------------------ the stall through noise


@pytest.mark.parametrize('seed', range(3))
def test_a_stall_is_seen_through_noise_at_1khz(seed):
    # ceilings off: the stall test alone (summed noisy steps never fell below stall_motion)
    settings = DetectorSettings(gap_ceiling=0.0, joint_gap_ceiling=0.0)
    jtc = trajectory()
    contact = 0.6
    detected, verdict = judge(BlockDetector(jtc, 0.0, settings),
                              follows(jtc, settings, contact), jtc.duration, seed)
    assert verdict is Verdict.BLOCKED
    # the gap passes d_dist shortly after contact; then one stall window
    assert detected - contact < 0.2 + 1.5 * settings.stall_time, detected


@pytest.mark.parametrize('seed', range(3))
def test_free_motion_through_noise_is_never_a_stall(seed):
    settings = DetectorSettings()
    jtc = trajectory()
    _, verdict = judge(BlockDetector(jtc, 0.0, settings), follows(jtc, settings),
                       jtc.duration + 2.0, seed)
    assert verdict is Verdict.DONE


@pytest.mark.parametrize('seed', range(3))
def test_an_arm_lagging_a_little_more_than_motion_delay_did_not_take_its_command_late(seed):
    # 30 ms more lag than motion_delay, through 5 mrad of noise: within LATE_TAKE, so the
    # command's start stays where it was sent (moved on, the detector would compare the arm
    # with its command that much later, and every gap would read that much smaller)
    settings = DetectorSettings()
    jtc = trajectory()
    detector = BlockDetector(jtc, 0.0, settings)

    def arm(t):
        return jtc.sample(t - settings.motion_delay - 0.03)[0]
    _, verdict = judge(detector, arm, jtc.duration + 2.0, seed)
    assert verdict is Verdict.DONE and detector.late == 0.0, detector.late


@pytest.mark.parametrize('seed', range(4))
def test_a_command_from_a_noisy_state_taken_late_is_judged_from_when_it_began(seed):
    # the command starts at one state with 5 mrad of noise, the arm (lagging 0.06 s) follows
    # it 0.25 s late: when motion is first seen the means' noise is as large as the motion,
    # and a match of positions found no time of the command near the arm (no shift: a
    # stall was called a block)
    settings = DetectorSettings()
    rng = np.random.default_rng(seed)
    start = Q0 + rng.normal(0.0, NOISE, 7)
    limits = RunSettings(velocity_scaling=0.2).limits(ARM)
    command = from_state(start, None, np.array([start, Q1]), limits).command_from_start
    jtc = JtcTrajectory(command, start, None, 0.0)
    controller = JtcTrajectory(command, start, None, 0.0)   # the detector moves jtc's
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True)
    late = 0.25
    arm = lagging(lambda t: controller.sample(t - late)[0] if t >= late else Q0, 0.06)
    _, verdict = watch(detector, arm, jtc.duration + late + 2.0, rng, NOISE)
    # late by 0.25 + 0.06 - motion_delay against the detector's desired position
    assert verdict is Verdict.DONE and 0.05 < detector.late <= 0.21, \
        (detector.late, detector.reason)


@pytest.mark.parametrize('inertia', [3.0, 5.0])
def test_an_arm_lagging_more_than_motion_delay_is_not_blocked_as_its_path_ends(inertia):
    # joint impedance (200 Nm/rad, damping 0.7) on a link of this inertia [kg m^2]: a ramp
    # lags its command by 2 x 0.7 x sqrt(I / K), 0.17 and 0.22 s, with motion_delay 0.1.
    # The ceilings' speed allowance was the command's speed at one instant: as the path
    # ended it fell, while the lagging arm's gap had not (inertia 5: "gap 0.548 above the
    # ceiling 0.527" at 1.17 s of a 1.17 s path)
    settings = DetectorSettings()
    limits = RunSettings(velocity_scaling=0.7).limits(ARM)
    far = Q0 + np.array([1.0, 0.5, 0.4, 0.8, 0.5, -0.6, 1.0])
    motion = from_state(Q0, None, np.array([Q0, far]), limits)
    jtc = JtcTrajectory(motion.command_from_start, Q0, None, 0.0)
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True)
    arm = impedance(lambda t: jtc.sample(t)[0], inertia)
    _, verdict = watch(detector, arm, jtc.duration + 2.0, np.random.default_rng(0), 1e-4, 10)
    assert verdict is Verdict.DONE, detector.reason


def test_the_motion_measure_averages_the_noise_out():
    rng = np.random.default_rng(1)
    times = np.arange(0.0, 0.3, 0.001)
    still = Q0 + rng.normal(0.0, NOISE, (len(times), 7))
    motion, noise = motion_over(times, still)
    assert motion < noise and noise < 0.03      # summed steps: about 12 rad
    moving = still + np.outer(times, np.full(7, 0.05))
    motion, noise = motion_over(times, moving)
    assert abs(motion - 7 * 0.05 * times[-1]) < noise and motion > noise


# ------------------------------------------------------------------ a joint pushed to its limit

LIMITS = (ARM.lower, ARM.upper)
#: A4 runs to the planner's margin from its lower limit
NEAR_A4 = Q0 + np.array([0.5, 0.2, 0.0, ARM.lower[3] + ROBOT_JOINT_MARGIN - Q0[3], 0.0, 0.0, 0.0])


def pushed_a4(jtc, settings, after, speed=0.08):
    """Return the arm: its command motion_delay late, A4 pushed toward its lower limit."""
    def arm(t):
        q = jtc.sample(t - settings.motion_delay)[0].copy()
        q[3] -= speed * max(0.0, t - after)
        return q
    return arm


def test_a_joint_pushed_toward_its_limit_is_blocked_before_it_gets_there():
    # clutter-seed8014 on the physics mock: A4 run to its margin while A2 pressed on
    # something and A4 was bent on toward its limit at about 0.08 rad/s, its gap below
    # every ceiling, until it passed the limit (a KUKA stops there)
    settings = DetectorSettings()
    jtc = trajectory(Q0, NEAR_A4)
    after = 0.6 * jtc.duration
    arm = pushed_a4(jtc, settings, after)
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True, limits=LIMITS)
    t, verdict = watch(detector, arm, jtc.duration + 2.0, np.random.default_rng(0), 5e-4)
    room = arm(t)[3] - ARM.lower[3]
    assert verdict is Verdict.BLOCKED and 'A4 pushed toward its limit' in detector.reason, \
        detector.reason
    # as far ahead of limit_room as it goes in LIMIT_HORIZON at its 0.08 rad/s
    assert settings.limit_room < room < settings.limit_room + 0.08 * LIMIT_HORIZON + 0.003, room
    # without the arm's limits, the gap tests alone let it run into its limit
    blind = BlockDetector(jtc, 0.0, settings, expect_motion=True)
    t, verdict = watch(blind, arm, jtc.duration + 2.0, np.random.default_rng(0), 5e-4)
    assert t is None or arm(t)[3] < ARM.lower[3], (t, verdict, blind.reason)


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('inertia', [0.0, 1.5])
@pytest.mark.parametrize('noise', [5e-4, NOISE])
@pytest.mark.parametrize('way', ['to', 'back', 'along'])
def test_an_arm_that_runs_close_to_a_limit_is_not_pushed(seed, inertia, noise, way):
    # to a goal 12 mrad from A4's limit (within the margin: a start or goal may be), to it
    # and back, or from a start there with A4 kept there while A1 turns; on time or lagging
    # 0.12 s in joint impedance (ahead of its command as the command turns back), through
    # 0.5 or 5 mrad of noise (one state's noise is no push)
    settings = DetectorSettings()
    limits = RunSettings(velocity_scaling=0.7).limits(ARM)
    near = NEAR_A4 - np.array([0.0, 0.0, 0.0, ROBOT_JOINT_MARGIN - 0.012, 0.0, 0.0, 0.0])
    start = near if way == 'along' else Q0
    ways = {'to': [Q0, near], 'back': [Q0, near, Q0],
            'along': [near, near + np.array([-0.6, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])]}
    motion = from_state(start, None, np.array(ways[way]), limits)
    jtc = JtcTrajectory(motion.command_from_start, start, None, 0.0)
    arm = impedance(lambda t: jtc.sample(t)[0], inertia, q0=start) if inertia else \
        follows(jtc, settings)
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True, limits=LIMITS)
    _, verdict = watch(detector, arm, jtc.duration + 2.0, np.random.default_rng(seed), noise)
    assert verdict is Verdict.DONE, detector.reason


def test_an_arm_at_rest_by_a_limit_whose_command_leaves_late_is_not_pushed():
    # a start within the margin (0.005 rad from A4's limit), the command away from it taken
    # 0.3 s late: the arm stays behind its command, toward the limit, pushed by nothing
    settings = DetectorSettings()
    start = NEAR_A4 - np.array([0.0, 0.0, 0.0, ROBOT_JOINT_MARGIN - 0.005, 0.0, 0.0, 0.0])
    jtc = trajectory(start, Q0)
    controller = trajectory(start, Q0)      # the detector moves jtc's on a late take
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True, limits=LIMITS)
    late = 0.3

    def arm(t):
        return controller.sample(t - late - settings.motion_delay)[0]
    _, verdict = watch(detector, arm, jtc.duration + late + 2.0, np.random.default_rng(0),
                       5e-4)
    assert verdict is Verdict.DONE and detector.late > 0.2, (detector.reason, detector.late)


# ------------------------------------------------------------------ a command nothing runs


@pytest.mark.parametrize('expect, verdict', [(True, Verdict.NOT_EXECUTED),
                                             (False, Verdict.BLOCKED)])
def test_an_arm_that_never_moves_after_a_path_was_not_commanded_by_anything(expect, verdict):
    jtc = trajectory()
    detector = BlockDetector(jtc, 0.0, DetectorSettings(), expect_motion=expect)
    _, seen = judge(detector, lambda t: Q0, jtc.duration + 1.0)
    assert seen is verdict
    if expect:
        assert 'has not moved since the command began' in detector.reason


@pytest.mark.parametrize('scaling', [0.2, 0.7])
def test_an_arm_held_from_rest_presses_no_harder_than_a_blocked_one_while_waiting(scaling):
    # the wait for a late controller must not raise the force: held at Q0 from the start,
    # the run is stopped once a gap passes its ceiling (with the speed allowance that any
    # block has), well before START_WAIT (it waited for three times the ceilings: 0.48-0.56
    # rad at one joint, about 100 Nm on the real arm)
    settings = DetectorSettings()
    motion = from_state(Q0, None, np.array([Q0, Q1]),
                        RunSettings(velocity_scaling=scaling).limits(ARM))
    jtc = JtcTrajectory(motion.command, Q0, None, 0.0)
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True)
    when, seen = judge(detector, lambda t: Q0, jtc.duration + 1.0)
    assert seen is Verdict.NOT_EXECUTED and when < START_WAIT
    allowance = settings.speed_allowance * np.abs(jtc.sample(when)[1])
    assert detector.gap <= settings.gap_ceiling + allowance.sum() + 0.02
    assert detector.joint_gaps.max() <= settings.joint_gap_ceiling + allowance.max() + 0.02


@pytest.mark.parametrize('expect', [True, False])
def test_a_command_the_controller_takes_late_is_judged_from_when_it_began(expect):
    # a large message delivered 0.25 s late: the arm follows it from then, free (later than
    # its gap takes to pass a ceiling, 0.3 s at scaling 0.2, it is stopped as not executed:
    # an arm held from rest would be pressed harder than a blocked one).  A retreat
    # (expect_motion False) alike: on a loaded machine the kinematic mock took one 0.13 s
    # late, it was called blocked, and the retreat then moved the arm the run held at rest
    settings = DetectorSettings()
    jtc = trajectory()
    late = 0.25
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=expect)
    _, seen = judge(detector, lambda t: jtc.sample(t - late - settings.motion_delay)[0],
                    jtc.duration + late + 2.0)
    assert seen is Verdict.DONE
    # matched where the arm is, at the mean time of the states that say so (matched by the
    # distance moved, at the newest state's time, it read 0.266 s)
    assert abs(detector.late - late) < 0.01 and abs(jtc.taken_at - late) < 0.01


@pytest.mark.parametrize('speed', [0.4, 0.5, 0.6])
def test_an_arm_on_time_is_not_judged_late_where_its_command_first_swings_out_and_back(speed):
    # at rest a joint state's velocity is its positions' noise over a period (as the lbr
    # stack computes it): a path sent from there first brakes from that velocity and comes
    # back (speed: its L1 [rad/s], 0.55 from 1 mrad of noise at 100 Hz), a swing an arm in
    # joint impedance smooths away.  Matched with the first time the command had moved as
    # far as the arm, the arm leaving on time was read as late by the swing's time to its
    # far end (0.085 s here; 0.2 s on the kinematic mock with 1 mrad of noise, where the
    # gap as the arm moved on was called a block in 3 of 36 runs on a loaded machine)
    settings = DetectorSettings()
    limits = RunSettings(velocity_scaling=0.5).limits(ARM)
    back = -(Q1 - Q0) / np.abs(Q1 - Q0).sum() * speed
    jtc = JtcTrajectory(from_state(Q0, back, np.array([Q0, Q1]), limits).command, Q0, back, 0.0)
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True)
    arm = lagging(lambda t: jtc.sample(t)[0], 0.06)     # less than motion_delay behind
    _, verdict = watch(detector, arm, jtc.duration + 2.0, np.random.default_rng(0), 0.001, 10)
    assert verdict is Verdict.DONE and detector.late == 0.0, (detector.late, detector.reason)


def test_a_short_path_taken_late_is_done_where_the_arm_comes_to_rest_not_on_its_way():
    # 0.06 rad from the arm, taken 0.25 s late: its gap never passes d_dist, so without the
    # rest the path was done with the arm short of its end (the run planned from there, and
    # on the physics mock at a command latency of 0.25 s went back and forth 20 times)
    settings = DetectorSettings()
    end = Q0 + np.array([0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.01])
    jtc = trajectory(Q0, end)
    late = 0.25

    def arm(t):
        return jtc.sample(t - late - settings.motion_delay)[0]
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True)
    when, seen = judge(detector, arm, jtc.duration + late + 2.0)
    assert seen is Verdict.DONE
    assert np.abs(arm(when) - end).sum() < 0.005


def test_a_short_path_nothing_runs_is_not_executed_after_the_wait_for_a_late_controller():
    # its gap never passes d_dist, so no gap test would say so: it was done, and the run
    # planned again from where the arm stood, path after path
    settings = DetectorSettings()
    jtc = trajectory(Q0, Q0 + np.array([0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.01]))
    detector = BlockDetector(jtc, 0.0, settings, expect_motion=True)
    when, seen = judge(detector, lambda t: Q0, START_WAIT + 1.0)
    assert seen is Verdict.NOT_EXECUTED and START_WAIT <= when < START_WAIT + 0.05
    assert 'has not moved since the command began' in detector.reason


@pytest.mark.parametrize('scaling, length', [(0.2, 1.0), (0.7, 1.0), (0.2, 0.1)])
def test_a_retreat_held_from_its_start_is_blocked_at_its_ceiling_or_after_a_short_wait(
        scaling, length):
    # waited for as a late take, then blocked (not "not executed": an arm pressed from two
    # sides after a block is something to learn), pressing no harder than a blocked path,
    # and for RETREAT_START_WAIT at most where its gap stays under the ceilings (a short
    # retreat: it was pressed until START_WAIT, 2 s)
    settings = DetectorSettings()
    end = Q0 + length * (Q1 - Q0)
    motion = from_state(Q0, None, np.array([Q0, end]),
                        RunSettings(velocity_scaling=scaling).limits(ARM))
    jtc = JtcTrajectory(motion.command, Q0, None, 0.0)
    detector = BlockDetector(jtc, 0.0, settings)
    when, seen = judge(detector, lambda t: Q0, jtc.duration + 1.0)
    assert seen is Verdict.BLOCKED and when <= RETREAT_START_WAIT + 0.02
    assert 'the arm has not moved in' in detector.reason
    allowance = settings.speed_allowance * np.abs(jtc.sample(when)[1])
    assert detector.gap <= settings.gap_ceiling + allowance.sum() + 0.02


def test_an_arm_that_moved_and_then_stopped_is_blocked_even_when_motion_was_expected():
    settings = DetectorSettings()
    jtc = trajectory()
    _, verdict = judge(BlockDetector(jtc, 0.0, settings, expect_motion=True),
                       follows(jtc, settings, 0.6), jtc.duration + 1.0)
    assert verdict is Verdict.BLOCKED


def pressed_retreat():
    """Return a retreat from a command pressed in past the arm (held at M), and M."""
    held = Q1.copy()
    # pressed on along the motion from Q0 (L1 0.38, past the ceiling 0.3)
    pressed = held + np.array([0.2, 0.1, 0.0, 0.08, 0.0, 0.0, 0.0])
    motion = from_state(pressed, None, np.array([pressed, Q0]), SETTINGS.limits(ARM))
    jtc = JtcTrajectory(motion.command, pressed, np.zeros(7), 0.0, np.zeros(7), -0.01)
    return jtc, held


def held_until_back(jtc, settings, held, behind=False):
    """Return the arm: held where it pressed until its command comes back, then following."""
    sign = np.sign(jtc.before[0] - held)

    def arm(t):
        command = jtc.sample(t - settings.motion_delay)[0]
        q = np.where(sign > 0, np.minimum(command, held), np.maximum(command, held))
        return held if behind else np.where(sign == 0, command, q)
    return arm


@pytest.mark.parametrize('pressed, verdict', [(False, Verdict.BLOCKED), (True, Verdict.DONE)])
def test_a_command_that_starts_pressed_in_waits_for_it_to_come_back(pressed, verdict):
    # a desired start (interpolate_from_desired_state) right after a block: the retreat
    # starts at the pressed-in setpoint, the arm cannot follow it until it has come back
    settings = DetectorSettings()
    jtc, held = pressed_retreat()
    detector = BlockDetector(jtc, 0.0, settings,
                             pressed_start=(jtc.before[0], held) if pressed else None)
    _, seen = judge(detector, held_until_back(jtc, settings, held), jtc.duration + 2.0)
    assert seen is verdict
    assert not pressed or detector.released_at is not None


def test_a_pressed_in_retreat_that_is_blocked_behind_is_seen_once_it_has_come_back():
    settings = DetectorSettings()
    jtc, held = pressed_retreat()
    detector = BlockDetector(jtc, 0.0, settings, pressed_start=(jtc.before[0], held))
    when, seen = judge(detector, held_until_back(jtc, settings, held, behind=True),
                       jtc.duration + 2.0)
    assert seen is Verdict.BLOCKED and detector.released_at is not None
    assert when < jtc.duration


def test_a_pressed_in_retreat_blocked_after_its_release_presses_no_further_than_the_ceilings():
    # a command that starts pressed in is not waited for as one taken late: it starts the
    # press gap away from the arm, which read as a delay (0.28 s at scaling 0.7) that kept
    # the gap tests off while the arm pressed to 1.27 rad L1 (a review, 2026-12-05)
    settings = DetectorSettings()
    jtc, held = pressed_retreat()
    free = held_until_back(jtc, settings, held)
    back = next(t for t in np.arange(0.0, jtc.duration, 0.001)
                if np.abs(free(t) - held).sum() > 1e-6)
    detector = BlockDetector(jtc, 0.0, settings, pressed_start=(jtc.before[0], held))
    when, seen = judge(detector, lambda t: free(min(t, back + 0.3)), jtc.duration + 2.0)
    assert seen is Verdict.BLOCKED and detector.late == 0.0
    allowance = settings.speed_allowance * np.abs(jtc.sample(when)[1])
    assert detector.gap <= settings.gap_ceiling + allowance.sum() + 0.05
    assert detector.joint_gaps.max() <= settings.joint_gap_ceiling + allowance.max() + 0.05


# ------------------------------------------------------------------ the run learns nothing


@dataclass
class Path:
    path: np.ndarray


class Planner:
    def plan(self, start, goal, fmap, rng):
        return Path(np.array([start, goal]))


def run_from(q0=Q0, goal=Q1) -> Run:
    loop = Disentangler(ARM, Planner(), goal, max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(), clock=lambda: run._now)
    run.start(0.0, q0)
    return run


def running(planner=None, **settings) -> Run:
    """Return a run from Q0 to Q1 (RunSettings(**settings)) that has sent its first path."""
    loop = Disentangler(ARM, planner or Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(**settings), clock=lambda: run._now)
    run.start(0.0, Q0)
    run.on_plan(loop.next_path(Q0))
    return run


def learned(run) -> list:
    return [a for a in run.actions if isinstance(a, Learned)]


def test_a_path_that_begins_with_a_release_places_a_block_on_its_own_edges():
    # desired start after a blocked retreat: the command, pressed in past the arm, first
    # comes back to it; a block on the path must still be placed on the path's edges (the
    # release counted as an edge of its own once put the block one edge on, and the retreat
    # then ran forward to a via point not reached)
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(jtc_start='desired'), clock=lambda: 0.0)
    pressed = Q0 + np.array([0.2, 0.1, 0.0, 0.08, 0.0, 0.0, 0.0])
    held = from_state(pressed, None, np.array([pressed, pressed]), SETTINGS.limits(ARM))
    run.start(0.0, Q0, None, JtcTrajectory(held.command, pressed, np.zeros(7), 0.0), 0.0)
    run.pressed = True                        # its last motion ended blocked
    path = np.array([Q0, Q0 + 0.3, Q1])
    motion = run._motion(path, 0.0)
    assert motion.positions[0] == pytest.approx(pressed)       # from where JTC's command is
    assert len(motion.via_times) == len(path)
    assert [motion.segment_at(t) for t in (0.0, motion.via_times[1] + 0.01)] == [0, 1]


def test_a_release_continues_the_pressed_command_as_it_moves_and_accelerates():
    # desired start: JTC runs on from its last command, here still speeding up past the arm
    # (a retreat pressed in as it began); the release must start at that velocity and
    # acceleration, or JTC's acceleration steps
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(jtc_start='desired'), clock=lambda: 0.0)
    pressed = Q0 + np.array([0.2, 0.1, 0.0, 0.08, 0.0, 0.0, 0.0])
    onward = from_state(pressed, None, np.array([pressed, pressed + 0.3]),
                        SETTINGS.limits(ARM))
    last = JtcTrajectory(onward.command, pressed, np.zeros(7), -0.1)
    q0, v0, a0 = last.sample(0.1)
    assert np.abs(a0).min() > 0.1 and np.abs(v0).min() > 0.001    # moving, speeding up
    run.start(0.0, Q0, None, last)           # sent at -0.1 s
    run.pressed = True
    motion = run._motion(np.array([Q0, Q1]), 0.0)
    assert motion.positions[0] == pytest.approx(q0)
    assert motion.velocities[0] == pytest.approx(v0)
    assert motion.accelerations[0] == pytest.approx(a0)


def test_a_path_the_arm_never_follows_stops_the_run_and_learns_nothing():
    run = run_from()
    run.on_plan(run.loop.next_path(Q0))
    assert any(isinstance(a, Send) for a in run.actions)
    for t in np.arange(0.001, 3.0, 0.001):
        run.on_joint_state(t, Q0)
        if not run.active:
            break
    assert run.outcome == 'stopped' and 'nothing executes the commands' in run.message
    assert not learned(run) and len(run.loop.fmap) == 0


def test_a_controller_that_stops_executing_after_a_block_is_not_learned_again_and_again():
    # a real block, then nothing executes the commands (JTC switched off) while the joint
    # states go on: the retreat that never moves is blocked (as an arm pressed from behind
    # too) and learned, the path after it begins pressed; each was learned in turn, a
    # failure every 0.5 s until max_paths.  Two blocked commands in a row that never moved
    # the arm stop the run
    run = run_from()
    run.on_plan(run.loop.next_path(Q0))
    run.actions.clear()
    held, t = None, 0.0
    while run.active and t < 20.0:
        t += 0.01
        if held is None:
            jtc = run.trajectory
            q = jtc.sample(t - jtc.taken_at - 0.05)[0]
            if t >= 0.6:                    # blocked here; from now on nothing moves the arm
                held = q
        run.on_joint_state(t, q if held is None else held)
        for action in run.actions:
            if isinstance(action, PlanFrom):
                run.on_plan(run.loop.next_path(action.config))
        run.actions.clear()
        run.tick(t)
    assert run.outcome == 'stopped' and 'moved under neither' in run.message, run.message
    assert 'nothing executes the commands' in run.message
    assert len(run.loop.fmap) == 2 and t < 3.0      # the block and the retreat's
    assert run.loop.paths_tried == 2


def test_an_arm_moving_while_it_should_rest_stops_the_run_and_learns_nothing():
    run = run_from()                     # planning: the arm rests where it started
    velocity = np.array([0.3, 0, 0, 0, 0, 0, 0])
    for t in np.arange(0.01, 2.0, 0.01):
        run.on_joint_state(t, Q0 + velocity * t)
        if not run.active:
            break
    assert run.outcome == 'stopped' and 'while at rest between commands' in run.message
    assert t < 0.2 / 0.3 and not learned(run)


def test_an_arm_settling_after_a_blocked_retreat_is_no_foreign_motion():
    # pressed into something, then stopped, a compliant arm springs back or slides by up to
    # the gap it pressed with (0.17 rad seen on the physics mock): the run goes on
    run = run_from()
    run.on_plan(run.loop.next_path(Q0))
    jtc, settings = run.trajectory, run.settings.detection
    arm = follows(jtc, settings, blocked_at=0.6)
    t = 0.0
    while run.phase.value != 'retreating' and t < 5.0:
        t += 0.01
        run.on_joint_state(t, arm(t))
    held = arm(t)
    while run.detector is not None and t < 10.0:     # the retreat is blocked too
        t += 0.01
        run.on_joint_state(t, held)
    assert run.active and run.detector is None and run.rest_slack > 0.1
    step = np.array([0.2, 0, 0, 0, 0, 0, 0])
    for k in range(1, 21):                           # 0.2 rad (L1) of settling
        run.on_joint_state(t + 0.01 * k, held + step * k / 20)
    assert run.active, run.message
    for k in range(1, 41):                           # but 0.8 rad more is someone else's
        run.on_joint_state(t + 0.2 + 0.01 * k, held + step + 4 * step * k / 40)
    assert run.outcome == 'stopped' and 'while at rest between commands' in run.message


class TurningPlanner:
    """Plans Q0 -> V -> Q1, turning at V."""

    via = Q0 + np.array([0.4, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])

    def plan(self, start, goal, fmap, rng):
        return Path(np.array([start, self.via, goal]))


@pytest.mark.parametrize('start', ['measured', 'desired'])
def test_a_block_seen_late_is_placed_where_the_arm_was_and_retreats_back(start):
    # the arm stops dead halfway along the first edge; its states stop coming (an executor
    # stalled, as in CI, or an arm that lags its command) until the command is well along
    # the second: the block is the first edge's, and the retreat must not run on to the via
    # point never reached (timed alone, the block was placed on the second edge, V joined
    # the way back, and the retreat ran on into what had blocked the arm)
    run = running(TurningPlanner(), jtc_start=start)
    motion, delay = run.motion, run.settings.detection.motion_delay
    at_via = float(motion.via_times[1])
    arm = follows(run.trajectory, run.settings.detection, blocked_at=0.5 * at_via + delay)
    t, resumed = 0.0, at_via + delay + 0.4
    while run.phase.value == 'executing' and t < 10.0:
        t += 0.01
        if not 0.5 * at_via + delay + 0.05 < t < resumed:       # nothing read meanwhile
            run.on_joint_state(t, arm(t))
    assert t >= resumed and motion.segment_at(t - delay) == 1
    learned = [a.event for a in run.actions if isinstance(a, Learned)]
    assert len(learned) == 1 and learned[0]['segment'] == 0
    x, v, _ = failure_from_block(ARM, arm(t), TurningPlanner.via - Q0)
    assert np.allclose(learned[0]['x'], x, atol=0.01)
    assert np.dot(learned[0]['v'], v / np.linalg.norm(v)) > 0.99      # along the first edge
    retreat = [a.command for a in run.actions if isinstance(a, Send)][-1]
    assert np.abs(retreat.positions[-1] - Q0).max() < 1e-6      # back where it came from
    assert np.abs(retreat.positions - TurningPlanner.via).sum(axis=1).min() > 0.15


def test_a_block_seen_in_a_burst_of_states_is_answered_from_the_newest():
    # A2 and A4 meet something, the other joints move on; the host could not run for 0.6 s
    # and takes the waiting states at once: the block is judged (and learned) on the state
    # it was seen in, and the retreat starts where the arm is by the newest (from the state
    # judged, its command first jumped back by what the free joints moved since: 0.26 rad
    # after a 0.4 s stall, run at the URDF's speed by ros2_control's limiter)
    loop = Disentangler(ARM, Planner(), Q1 + np.r_[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5],
                        max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(), clock=lambda: clock[0])
    clock = [0.0]
    run.start(0.0, Q0)
    run.on_plan(loop.next_path(Q0))
    jtc, delay = run.trajectory, run.settings.detection.motion_delay

    def arm(t):
        q = jtc.sample(t - delay)[0]
        q[[1, 3]] = jtc.sample(min(t, 0.8) - delay)[0][[1, 3]]
        return q
    t = 0.0
    while t < 1.0:
        t = clock[0] = round(t + 0.01, 10)
        run.on_joint_state(t, arm(t))
    assert run.phase.value == 'executing'
    clock[0] = 1.8                                    # the host could not run until now
    burst = np.round(np.arange(1.71, 1.805, 0.01), 10)
    for k, t in enumerate(burst):
        run.on_joint_state(t, arm(t), newest=k == len(burst) - 1)
    learned = [a.event for a in run.actions if isinstance(a, Learned)]
    assert len(learned) == 1 and learned[0]['t'] < burst[-1]        # seen before the newest
    retreat = [a.command for a in run.actions if isinstance(a, Send)][-1]
    assert run.phase.value == 'retreating'
    moved = np.abs(arm(burst[-1]) - arm(learned[0]['t'])).sum()
    assert moved > 0.02                              # the free joints moved on meanwhile
    assert np.abs(retreat.positions[0] - arm(burst[-1])).max() < 1e-9


@pytest.mark.parametrize('extra', [0.0, 0.15])
def test_a_run_tells_how_late_its_commands_began_against_motion_delay(extra):
    # an arm lagging more than motion_delay (a load, a softer stiffness than calibrated)
    # looks like a command taken late: the detector shifts it, silently before; the status
    # (and the node's log at the run's end) now says by how much, so that the user measures
    # the lag again (probdis replay BAG --calibrate)
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(), clock=lambda: run._now)
    run.start(0.0, Q0)
    run.on_plan(loop.next_path(Q0))
    jtc, delay = run.trajectory, run.settings.detection.motion_delay
    for t in np.arange(0.01, jtc.duration + 2.0, 0.01):
        run.on_joint_state(t, jtc.sample(t - delay - extra)[0])
        if not run.active:
            break
    assert run.outcome == 'succeeded' and not learned(run), run.message
    assert run.status()['late_take_max_s'] == pytest.approx(extra, abs=0.02)


@pytest.mark.parametrize('start', ['measured', 'desired'])
def test_a_blocked_retreat_is_stopped_at_once_not_run_on_while_the_next_plan_is_made(start):
    # JTC runs a command to its end: a retreat blocked and left running would wind its
    # command ever farther from the held arm (200 Nm/rad on the real arm) until the next
    # plan comes, which may take seconds
    run = running(jtc_start=start)
    arm = follows(run.trajectory, run.settings.detection, blocked_at=0.6)
    t = 0.0
    while run.phase.value != 'retreating' and t < 5.0:
        t += 0.01
        run.on_joint_state(t, arm(t))
    held = arm(t)
    retreat = [a for a in run.actions if isinstance(a, Send)][-1].command
    assert np.abs(retreat.positions[-1] - held).max() > 0.1
    run.actions.clear()
    while run.detector is not None and t < 10.0:     # the retreat is blocked too
        t += 0.01
        run.on_joint_state(t, held)
    assert run.active and run.plan_pending           # the next plan is still being made
    sends = [a.command for a in run.actions if isinstance(a, Send)]
    assert sends, 'the blocked retreat was left running'
    assert np.abs(sends[-1].positions[-1] - held).max() < 0.02
    for k in range(1, 200):                          # and nothing pulls the arm after it
        run.on_joint_state(t + 0.01 * k, held)
    assert run.active and sum(isinstance(a, Send) for a in run.actions) == len(sends)
    assert np.abs(run.trajectory.sample(np.inf)[0] - held).max() < 0.02


@pytest.mark.parametrize('scaling', [0.2, 0.7])
def test_a_stop_from_states_without_velocities_brakes_the_moving_arm(scaling):
    # a driver that sends no velocities: the arm on its command moves as the command says;
    # a stop taken from rest held it dead in one period (30-104 rad/s^2, a review found)
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    settings = RunSettings(velocity_scaling=scaling)
    run = Run(ARM, loop, settings, clock=lambda: run._now)
    run.start(0.0, Q0)
    run.on_plan(loop.next_path(Q0))
    jtc = run.trajectory
    delay = settings.detection.motion_delay
    t = 0.0
    while t < 0.4 * jtc.duration:
        t += 0.01
        run.on_joint_state(t, jtc.sample(t - delay)[0])        # positions only
    moving = jtc.sample(t - delay)[1]
    assert np.abs(moving).max() > 0.1
    run.actions.clear()
    run.stop()
    stop = [a.command for a in run.actions if isinstance(a, Send)][-1]
    braking = JtcTrajectory(stop, jtc.sample(t - delay)[0], moving, t)
    first = braking.sample(0.01)[1]
    assert np.abs(first - moving).max() / 0.01 < 10.0       # rad/s^2: braking, not a wall
    assert braking.duration > 0.05


def torque_block(held: bool) -> tuple[np.ndarray, np.ndarray, TrajectoryCommand]:
    """
    Return (the arm's position and velocity, the retreat) after a block its torque showed.

    States without velocities, the torque ceiling on, at scaling 0.7: the arm held at half
    the path (stopped dead between two states), or following on (a soft contact, or a
    torque the gravity model does not know, for one state).
    """
    from probdis_ros.motion.detector import gravity_model

    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    settings = RunSettings(velocity_scaling=0.7, detection=replace(
        SETTINGS.detection, torque_ceiling=20.0))
    run = Run(ARM, loop, settings, clock=lambda: run._now)
    run.start(0.0, Q0)
    run.on_plan(loop.next_path(Q0))
    jtc, gravity = run.trajectory, gravity_model(0.0, (0.0, 0.0, 0.0))
    delay = settings.detection.motion_delay
    block = 0.5 * jtc.duration + 0.004
    t = 0.0
    while run.phase.value == 'executing' and t < jtc.duration:
        t += 0.01
        q = jtc.sample(min(t, block) - delay if held else t - delay)[0]
        push = np.array([0.0, 30.0, 0, 0, 0, 0, 0]) if t >= block else np.zeros(7)
        run.on_joint_state(t, q, None, gravity(q) + push)      # positions and efforts only
    assert run.phase.value == 'retreating' and t < block + 0.01       # seen at once
    q, v, _ = jtc.sample(min(t, block) - delay if held else t - delay)
    if held:
        v = 0 * v
    return q, v, [a.command for a in run.actions if isinstance(a, Send)][-1]


@pytest.mark.parametrize('lag', [0.06, 0.0])
def test_a_stop_from_states_without_velocities_of_an_arm_off_its_command_starts_at_its_speed(lag):
    # an arm lagging its command otherwise than motion_delay is not "following" it: on states
    # without velocities its stop was built from rest, and JTC (measured start) stepped the
    # command of a joint moving at 1.04 rad/s to 0 in a period (a fuzzer: up to 2.2 rad/s)
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(velocity_scaling=0.7), clock=lambda: run._now)
    run.start(0.0, Q0)
    run.on_plan(loop.next_path(Q0))
    jtc, t = run.trajectory, 0.0
    while t < 0.45 * jtc.duration:
        t += 0.01
        run.on_joint_state(t, jtc.sample(t - lag)[0])          # positions only
    q, v, _ = jtc.sample(t - lag)                               # the arm's true state
    assert not run.following and np.abs(v).max() > 1.0
    run.actions.clear()
    run.stop()
    stop = [a.command for a in run.actions if isinstance(a, Send)][-1]
    start = taken_trajectory(stop, t, q, v).sample(0.0)[1]      # JTC from the arm
    assert np.abs(start - v).max() < 0.05


def test_a_block_seen_by_its_torque_on_states_without_velocities_brakes_from_the_arms_motion():
    # a driver that sends no velocities: the arm on its command moves as the command says,
    # but a block its torque shows comes within d_dist of the command, where the arm still
    # counted as following it: the retreat began at the command's speed and ran 0.148 rad
    # on into what held the arm; taken as at rest, an arm still moving (a soft contact) got
    # a step of 1.04 rad/s (104 rad/s^2).  The recent positions' slope brakes from how the
    # arm moved, which lags a dead stop by up to a state's period: 0.126 rad here, the worst
    # of five places between two states (0.005-0.126)
    held, _, retreat = torque_block(held=True)
    forward = retreat.positions[0] - retreat.positions[-1]
    ahead = (retreat.positions - held) @ forward / np.linalg.norm(forward)
    assert ahead.max() < 0.135, f'the retreat ran {ahead.max():.4f} rad on into the block'
    q, moving, retreat = torque_block(held=False)
    assert np.abs(moving).max() > 1.0
    braking = JtcTrajectory(retreat, q, moving, 0.0)
    assert np.abs(braking.sample(0.01)[1] - moving).max() / 0.01 < 10.0     # rad/s^2


def test_a_stop_during_a_free_retreat_after_a_block_brakes_ahead_not_back_to_the_arm():
    # desired start: after a block the retreat first brings JTC's command back to the held
    # arm, then runs free; a ~/stop then took the arm as still held (the block's flag was
    # left standing when the stop dropped the retreat's detector) and brought the command
    # back to the arm, which lags it: the stop ended where the arm was, a reversal of a
    # moving arm (0.24 rad behind where braking ends), not a stop
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    settings = RunSettings(velocity_scaling=0.7, jtc_start='desired')
    run = Run(ARM, loop, settings, clock=lambda: run._now)
    run.start(0.0, Q0)
    run.on_plan(loop.next_path(Q0))
    jtc, delay = run.trajectory, settings.detection.motion_delay
    blocked_at = 0.5 * jtc.duration
    t = 0.0
    while run.phase.value == 'executing' and t < 10.0:
        t += 0.01
        q, v, _ = jtc.sample(min(t, blocked_at) - delay)
        run.on_joint_state(t, q, v if t < blocked_at else 0 * v)
    retreat = run.trajectory
    for _ in range(60):                  # free again: the arm follows the retreat
        t += 0.01
        q, v, _ = retreat.sample(t - retreat.taken_at - delay)
        run.on_joint_state(t, q, v)
    assert not run.detector.pressed and np.abs(v).max() > 0.5
    run.actions.clear()
    run.stop()
    stop = [a.command for a in run.actions if isinstance(a, Send)][-1]
    ahead = (stop.positions[-1] - q) @ v / np.linalg.norm(v)
    assert ahead > 0.1, f'the stop ends {ahead:.3f} rad along the motion of the arm'


STOP_AT = 1.403     # [s] into a path at scaling 0.7, between two of JTC's updates
EPOCH = 1.0         # [s] JTC's first update (a clock at 0 would make a stamp of 0: none)


def desired_stop_taken_late(latency: float, ticks: int, sent_at: float = EPOCH,
                            path_latency: float = 0.0) -> tuple[np.ndarray, list]:
    """
    Run a path with a desired start under the JTC model, stopped at STOP_AT, delivered late.

    The path is sent at sent_at and delivered path_latency later; JTC updates every 10 ms
    from EPOCH.  Returns JTC's position commands, one per period, and the stop's messages.
    """
    settings = RunSettings(velocity_scaling=0.7, jtc_start='desired')
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    clock = [sent_at]
    run = Run(ARM, loop, settings, clock=lambda: clock[0])
    jtc = TrajectoryController(0.01, 'desired')
    run.start(sent_at, Q0)
    run.on_plan(loop.next_path(Q0))
    deliveries = [(sent_at + path_latency, a.command) for a in run.actions
                  if isinstance(a, Send)]
    commands, stops = [], []
    for k in range(ticks):
        t = EPOCH + k * 0.01
        for when, command in [d for d in deliveries if d[0] <= t + 1e-12]:
            jtc.receive(command)
            deliveries.remove((when, command))
        commands.append(jtc.update(t, Q0 if k == 0 else commands[-1]))
        if t < STOP_AT <= t + 0.01:
            clock[0] = STOP_AT
            run.actions.clear()
            run.stop()
            stops = [a.command for a in run.actions if isinstance(a, Send)]
            deliveries += [(STOP_AT + latency, command) for command in stops]
    return np.array(commands), stops


@pytest.mark.parametrize('latency', [0.0, 0.005, 0.008, 0.012, 0.02, 0.03])
def test_with_a_desired_start_a_stop_taken_late_brakes_the_command_smoothly(latency):
    # JTC takes a message at its first update after it arrives and runs from its own last
    # command: a stop made from that command at the run's time, unstamped, set it back by
    # however late it was taken (a review: 1.04 rad/s to 0.31, or -0.73 and -1.77 rad/s with
    # 8 and 20 ms of delivery); stamped, it brakes from where the command is when taken,
    # its speed changing by no more than the stop's own deceleration over the delay
    commands, _ = desired_stop_taken_late(latency, 80)
    assert_braked_smoothly(commands)


def assert_braked_smoothly(commands: np.ndarray) -> None:
    speed = np.diff(commands[:, 0]) / 0.01                        # A1, the joint that moves most
    k = round((STOP_AT - EPOCH) / 0.01)
    assert speed[k - 1] > 0.9                                     # it was moving fast
    assert speed[k:].min() > -1e-3                                # never back
    assert np.abs(np.diff(speed[k - 2:])).max() / 0.01 < 25.0     # rad/s^2: braking
    assert np.abs(np.diff(commands, axis=0) / 0.01 / ARM.velocity_limits).max() <= 0.7 + 1e-6


@pytest.mark.parametrize('sent_at, path_latency', [(EPOCH, 0.005), (EPOCH + 0.004, 0.0),
                                                   (EPOCH + 0.004, 0.009)])
def test_with_a_desired_start_a_path_from_rest_taken_late_is_stopped_smoothly(
        sent_at, path_latency):
    # a path from rest went unstamped: JTC ran it from its next update, the run modelled it
    # from when it was sent, and a stop made from that model put JTC's command ahead by the
    # delay (a fuzzer: A1 from 1.04 to 2.69 rad/s for a period, 1.8 x its velocity limit,
    # the path taken 16 ms late); stamped, JTC runs it on the run's time line
    commands, _ = desired_stop_taken_late(0.0, 80, sent_at, path_latency)
    assert_braked_smoothly(commands)


@pytest.mark.parametrize('latency', [0.2, 0.5])
def test_with_a_desired_start_a_stop_taken_very_late_is_still_taken(latency):
    # JTC drops a stamped message whose last point is due before it arrives: a short stop
    # (0.16 s from 1 rad/s) delivered late would leave the path running to its end, so a
    # stamped message ends STAMP_HORIZON after its stamp at least
    commands, stops = desired_stop_taken_late(latency, 300)
    assert stops and stops[-1].stamp == STOP_AT and stops[-1].times[-1] >= STAMP_HORIZON
    assert np.abs(commands[-1] - Q1).max() > 0.05        # stopped short of the path's end
    assert np.abs(commands[-1] - commands[-2]).max() < 1e-9


@pytest.mark.parametrize('way, lag', [(0.3, 0.0), (0.6, 0.0), (0.6, 0.05)])
def test_an_arm_still_running_the_last_command_at_a_new_start_is_no_foreign_motion(way, lag):
    # the previous run's last command (its stop, say) still takes the arm on to its end:
    # halfway along 0.6 rad (L1) it is 0.3 from where it started and from the end, twice
    # what the rest check allows an arm at rest, and an arm in impedance lags its command
    end = Q0 + np.array([way, 0, 0, 0, 0, 0, 0])
    running = trajectory(Q0, end)
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(), clock=lambda: 0.0)
    run.start(0.0, Q0, running=running)
    for t in np.arange(0.01, running.duration + 0.5, 0.01):
        run.on_joint_state(t, running.sample(t - lag)[0])
    assert run.active and run.phase.value == 'planning', run.message


@pytest.mark.parametrize('back', [False, True])
def test_an_arm_leaving_the_way_of_its_last_command_at_a_new_start_is_stopped(back):
    # on that command's way at any lag, while it runs, is this planner's motion; off it,
    # or back along it once the command has run out and the arm settled, something else's
    end = Q0 + np.array([0.6, 0, 0, 0, 0, 0, 0])
    running = trajectory(Q0, end)
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    run = Run(ARM, loop, RunSettings(), clock=lambda: 0.0)
    run.start(0.0, Q0, running=running)
    after = running.duration + 1.0
    for t in np.arange(0.01, after + 2.0, 0.01):
        if back:      # on time, then pushed back along its way a second after its end
            q = running.sample(t if t <= after else 2 * after - t)[0]
        else:
            q = running.sample(t)[0] + np.array([0, 0, 0.5 * t, 0, 0, 0, 0])
        run.on_joint_state(t, q)
        if not run.active:
            break
    assert not run.active and 'something other than this planner' in run.message
    assert not back or t > after


# ------------------------------------------------------------------ what the gate refuses


def gate(late=None) -> StateCheck:
    return StateCheck(NAMES, ARM.lower, ARM.upper, ARM.velocity_limits, late=late)


def test_two_publishers_interleaving_are_refused_whatever_they_send():
    check = gate()
    near = Q0 + 0.01                      # within the jump allowance: no jump to see
    check.check(0.00, NAMES, Q0, stamp=10.00, sequence=500)
    check.check(0.01, NAMES, Q0, stamp=10.01, sequence=501)
    with pytest.raises(BadJointStateError, match='a second publisher'):
        check.check(0.015, NAMES, near, stamp=10.015, sequence=3)
    check.check(0.02, NAMES, Q0, stamp=10.02, sequence=502)
    # one started with the arm's at the same rate repeats its numbers
    with pytest.raises(BadJointStateError, match='a second publisher'):
        check.check(0.025, NAMES, near, stamp=10.025, sequence=502)
    check.check(0.03, NAMES, Q0, stamp=10.03, sequence=503)
    # a restarted driver, after a silence, is a new stream
    check.check(0.02 + 1.5, NAMES, Q0, stamp=11.6, sequence=1)


def test_on_simulated_time_a_state_off_the_clock_either_way_is_refused():
    check = gate(late=0.1)
    check.check(10.0, NAMES, Q0, stamp=10.0, clock=10.0)
    check.check(10.05, NAMES, Q0, stamp=10.01, clock=10.05)      # within late: taken
    with pytest.raises(BadJointStateError, match='from the simulated clock'):
        check.check(10.2, NAMES, Q0, stamp=10.02, clock=10.2)     # stale: 0.18 s behind
    with pytest.raises(BadJointStateError, match='from the simulated clock'):
        check.check(10.2, NAMES, Q0, stamp=10.5, clock=10.2)      # not on the clock's time


def test_a_backlog_delivered_late_is_stale():
    check = gate(late=0.5)
    for k in range(10):
        check.check(100.0 + 0.01 * k + 0.001, NAMES, Q0, stamp=100.0 + 0.01 * k)
    # the stream pauses, then its queued states arrive at once
    with pytest.raises(BadJointStateError, match=re.escape('stale (a backlog')):
        check.check(100.9, NAMES, Q0, stamp=100.1)


def test_states_are_dated_by_their_stamps_on_the_receivers_clock():
    check = gate(late=1.0)
    # the sender's clock is 1000 s off; the quickest delivery takes 0.5 ms
    for now, stamp in ((5.002, 1005.0), (5.0115, 1005.011), (5.0205, 1005.02)):
        check.check(now, NAMES, Q0, stamp=stamp)
    assert check.measured_at(5.0205, 1005.02) == pytest.approx(5.0205)
    # held up and delivered at once: dated when measured, not when they arrived
    check.check(5.4, NAMES, Q0, stamp=1005.03)
    assert check.measured_at(5.4, 1005.03) == pytest.approx(5.0305)
    # unstamped states are dated on arrival
    assert gate().measured_at(7.0, 0.0) == 7.0


@pytest.mark.parametrize('aging', [True, False])
def test_an_arm_clock_drifting_slow_for_20_min_dates_its_states_within_milliseconds(
        aging, monkeypatch):
    # the arm's clock runs 500 ppm slow (NTP slewing it at its fastest): 20 min at rest,
    # states at 10 Hz arriving 0.5-3 ms after they were stamped, then a motion at 1 kHz
    if not aging:
        monkeypatch.setattr(state_check, 'CLOCK_DRIFT', 0.0)   # the plain minimum of before
    rate, span = 1.0 - 5e-4, 1200.0
    rng = np.random.default_rng(5)
    check, errors = gate(late=0.5), []
    for t in np.arange(0.0, span, 0.1):
        try:
            check.check(t + rng.uniform(0.0005, 0.003), NAMES, Q0, stamp=1000.0 + rate * t)
        except BadJointStateError:
            continue
        # the receiver's clock less the arm's: what a command for the arm is stamped back by
        errors.append(check.clock_offset - (t - rate * t - 1000.0))
    if not aging:   # why: stamped commands (a stop) would reach the arm's controller up to
        # 0.5 s in its future, and then its states were refused as stale (a run stopped)
        assert min(errors) < -0.45 and 'stale' in check.refusal
        return
    assert check.refused == 0 and max(np.abs(errors)) < 0.003
    jtc = trajectory()
    arm = follows(jtc, DetectorSettings())
    detector = BlockDetector(jtc, span, DetectorSettings(), expect_motion=True)
    worst, now = 0.0, span
    for t in np.arange(span, span + jtc.duration + 1.0, 1.0 / RATE):
        stamp, now = 1000.0 + rate * t, max(now, t + rng.uniform(0.0005, 0.003))
        check.check(now, NAMES, arm(t - span), stamp=stamp)
        worst = max(worst, abs(check.measured_at(now, stamp) - t))
        verdict = detector.update(check.measured_at(now, stamp), arm(t - span))
        if verdict is not Verdict.MOVING:
            break
    assert worst < 0.003 and verdict is Verdict.DONE


def test_a_backlog_after_an_hour_of_drift_is_still_stale():
    check = gate(late=0.5)
    rate = 1.0 - 5e-4                     # NTP's largest slew
    for t in np.arange(0.0, 3600.0, 0.1):
        check.check(t + 0.001, NAMES, Q0, stamp=rate * t)
    # queued for 0.6 s, then delivered at once: at most CLOCK_DRIFT x 0.6 s of aging
    with pytest.raises(BadJointStateError, match=re.escape('stale (a backlog')):
        check.check(3600.6 + 0.001, NAMES, Q0, stamp=rate * 3600.0)


def sender_starved(start, until, end, catch_up=0.1, tick=0.02):
    """
    Return (stamp, arrival) of states until end from a sender starved from start to until [s].

    Like the mock on a busy machine taking a long command message: silent, then one state
    per tick, each up to catch_up further on, until it has caught up; otherwise one state
    per 1/RATE.  Each arrives 0.5 ms after it was sent.
    """
    sent = [(t, t) for t in np.arange(0.0, start, 1.0 / RATE)]
    t, now = start, until
    while t < now:
        t = min(t + catch_up, now)
        sent.append((t, now))
        now += tick if t < now else 0.0
    sent += [(tau, tau) for tau in np.arange(t + 1.0 / RATE, end, 1.0 / RATE)]
    return [(stamp, at + 0.0005) for stamp, at in sent]


def taken_late_after_sparse_states(late, seed):
    """
    Return the verdict on a path from rest at scaling 0.5, taken late, its states sparse.

    As a starved mock sends them: 100 Hz until the path is sent, then 0.1 s apart (one
    state per tick, each a catch-up of CATCH_UP) until the controller takes the path late,
    then 100 Hz again; 1 mrad of noise.
    """
    rng = np.random.default_rng(seed)
    limits = RunSettings(velocity_scaling=0.5).limits(ARM)
    start = Q0 + rng.normal(0.0, 0.001, 7)
    velocity = rng.normal(0.0, 0.001, 7) * 100.0 * np.sqrt(2.0)    # differenced at 100 Hz
    command = from_state(start, velocity, np.array([start, Q1]), limits).command
    jtc = JtcTrajectory(command, start, velocity, 0.0)
    controller = JtcTrajectory(command, start, velocity, 0.0)   # the detector moves jtc's
    stream = StateStream()
    for t in np.arange(-0.3, 0.0, 0.01):
        stream.add(t)
    detector = BlockDetector(jtc, 0.0, DetectorSettings(), expect_motion=True, stream=stream)
    arm = impedance(lambda t: controller.sample(t - late)[0] if t >= late else Q0, 1.0)
    sent = -1.0
    for t in np.arange(0.0, jtc.duration + late + 2.0, STEP):
        q = arm(t)
        if t < 0.06 or t - sent < (0.1 if t < late else 0.01) - 1e-9:
            continue
        sent = t
        stream.add(t)
        verdict = detector.update(t, q + rng.normal(0.0, 0.001, 7))
        if verdict is not Verdict.MOVING:
            return verdict
    return Verdict.MOVING


def test_states_held_up_while_a_path_is_taken_late_give_no_false_block():
    # the noise test's CI failure, retaken with a mock stopped for 0.05-0.6 s at a time:
    # 7 false blocks in the bags of 5 of 12 runs, none when they are replayed now
    # (the code before: every one of these seeds blocked at 0.4 s, on the path's second
    # state, its noise taken as zero)
    seeds = range(6)
    assert all(taken_late_after_sparse_states(0.2, seed) is Verdict.DONE for seed in seeds)
    # taken about as late as the detector waits for at this speed, or later: done, or not
    # executed; a block would be a failure learned where there is none
    for late in (0.25, 0.4):
        verdicts = [taken_late_after_sparse_states(late, seed) for seed in seeds]
        assert set(verdicts) <= {Verdict.NOT_EXECUTED, Verdict.DONE}, (late, verdicts)


@pytest.mark.parametrize('gap_rule', [True, False])
def test_a_moving_arm_is_not_stalled_on_states_held_up_on_their_way(gap_rule):
    # a fast path that turns, the arm 45 ms behind the detector's model (its gap past
    # d_dist), states 0.1 s apart for 0.6 s at a time (a mock catching up): judged across
    # the gaps, second differences hold the arm's acceleration over 0.1 s, and an arm that
    # moved 0.2-0.4 rad in 0.3 s was called stalled
    settings = DetectorSettings()
    limits = RunSettings(velocity_scaling=0.7).limits(ARM)
    via = Q0 + np.array([0.9, -0.3, 0.6, 0.1, -0.4, 0.2, 0.8])
    far = Q0 + np.array([1.0, 0.5, 0.4, 0.8, 0.5, -0.6, 1.0])
    motion = from_state(Q0, None, np.array([Q0, via, far, Q0]), limits)
    jtc = JtcTrajectory(motion.command_from_start, Q0, None, 0.0)
    verdicts = []
    with pytest.MonkeyPatch.context() as patch:
        if not gap_rule:
            patch.setattr(detector_module, 'STATE_GAP', np.inf)
        for begin in np.arange(0.25, 0.7, 0.05) * jtc.duration:
            detector = BlockDetector(jtc, 0.0, settings, expect_motion=True)
            rng = np.random.default_rng(0)
            arm = follows(jtc, replace(settings, motion_delay=settings.motion_delay + 0.045))
            verdicts.append(watch_sparse(detector, arm, jtc.duration + 2.0, rng,
                                         (begin, begin + 0.6)))
    if gap_rule:
        assert set(verdicts) == {Verdict.DONE}, verdicts
    else:
        assert Verdict.BLOCKED in verdicts, verdicts


def watch_sparse(detector, arm, until, rng, sparse):
    """Feed arm(t) with 1 mrad of noise at 100 Hz, 10 Hz within sparse; return the verdict."""
    sent = -1.0
    for t in np.arange(0.0, until, STEP):
        q = arm(t)
        if t - sent < (0.1 if sparse[0] <= t < sparse[1] else 0.01) - 1e-9:
            continue
        sent = t
        verdict = detector.update(t, q + rng.normal(0.0, 0.001, 7))
        if verdict is not Verdict.MOVING:
            return verdict
    return Verdict.MOVING


def test_the_state_period_is_the_streams_not_its_gaps():
    # a mock stopped most of the time sends 4 of 5 states 0.1 s apart (catching up): taken
    # for its period (a median did), those gaps hid no stall of the arm from the noise
    stream = StateStream()
    assert stream.period == np.inf
    t = 0.0
    for k in range(100):
        t += 0.01 if k % 5 == 0 else 0.1
        stream.add(t)
        stream.add(t)               # a repeated time is no spacing
    assert stream.period == pytest.approx(0.01) and stream.longest == pytest.approx(0.04)
    slow = StateStream()            # a 10 Hz driver: its spacing is its period
    for k in range(50):
        slow.add(0.1 * k)
    assert slow.period == pytest.approx(0.1)
    fast = StateStream()            # 1 kHz: a late tick of a few ms is no gap
    for k in range(50):
        fast.add(0.001 * k)
    assert fast.longest == pytest.approx(0.03)


def stall_in_a_stream_with_frequent_gaps(seed: int, stream) -> tuple[Verdict, float]:
    """
    Return the verdict on an arm stopped dead at 0.6 s, and its time.

    The stream was 100 Hz for a second; then 2 of 5 spacings are 10 ms, 3 of 5 are 0.1 s.
    """
    settings = DetectorSettings(gap_ceiling=0.0, joint_gap_ceiling=0.0)   # the stall alone
    for t in np.arange(-1.0, 0.0, 0.01):
        stream.add(t)
    jtc = trajectory()
    detector = BlockDetector(jtc, 0.0, settings, stream=stream)
    arm = follows(jtc, settings, 0.6)
    rng = np.random.default_rng(seed)
    sent, k, verdict = -1.0, 0, Verdict.MOVING
    for t in np.arange(0.0, jtc.duration, STEP):
        if t - sent < (0.01 if k % 5 < 2 else 0.1) - 1e-9:
            continue
        sent, k = t, k + 1
        stream.add(t)
        verdict = detector.update(t, arm(t) + rng.normal(0.0, 0.001, 7))
        if verdict is not Verdict.MOVING:
            return verdict, t
    return verdict, t


@pytest.mark.parametrize('seed', range(3))
def test_a_stall_is_seen_in_a_stream_with_frequent_gaps(seed):
    # the noise judged on the second differences between states 10 ms apart; a first
    # version cut the history at its last gap, never had the stall's 0.27 s of states left
    # and saw no stall at all (the ceilings off: nothing)
    verdict, seen = stall_in_a_stream_with_frequent_gaps(seed, StateStream())
    assert verdict is Verdict.BLOCKED, verdict
    assert 0.6 < seen < 0.6 + 0.2 + 1.5 * DetectorSettings().stall_time + 0.1, seen


def test_two_states_tell_no_motion_from_noise():
    # with fewer than three states there is no second difference to judge the noise by:
    # judged as none, two states 0.1 s apart (a mock catching up) differing by their noise
    # read as the start of a path that had not begun
    jtc = trajectory()
    detector = BlockDetector(jtc, 0.0, DetectorSettings(), expect_motion=True)
    rng = np.random.default_rng(0)
    for t in (0.0, 0.1):
        detector.update(t, Q0 + rng.normal(0.0, 0.002, 7))
    moved, allowance = detector.moved()
    assert moved > DetectorSettings().stall_motion and allowance == np.inf
    assert not detector.started


def test_a_burst_held_up_in_delivery_is_no_block_when_dated_by_stamps():
    settings = DetectorSettings()
    jtc = trajectory(Q0, Q0 + np.array([1.2, 0.5, 0.0, 0.8, 0.0, -0.6, 1.5]))
    arm = follows(jtc, settings)
    verdicts = {}
    for dated in ('stamp', 'arrival'):
        check, detector = gate(late=1.0), BlockDetector(jtc, 0.0, settings, expect_motion=True)
        for t, arrival in sender_starved(0.6, 1.1, jtc.duration + 1.0):
            check.check(arrival, NAMES, arm(t), stamp=100.0 + t)
            when = check.measured_at(arrival, 100.0 + t) if dated == 'stamp' else arrival
            verdicts[dated] = detector.update(when, arm(t))
            if verdicts[dated] is not Verdict.MOVING:
                break
    assert verdicts['stamp'] is Verdict.DONE
    # why arrival is not used: the held-up states read as an arm half a second behind
    assert verdicts['arrival'] is Verdict.BLOCKED


def test_on_simulated_time_a_state_stamped_off_the_clock_is_refused():
    check = gate(late=0.5)
    check.check(50.0, NAMES, Q0, stamp=50.0, clock=50.001)
    with pytest.raises(BadJointStateError, match='from the simulated clock'):
        check.check(1.7e9, NAMES, Q0, stamp=1.7e9, clock=50.02)


def test_the_motion_watch_tells_an_arm_at_rest_from_one_that_moves():
    rng = np.random.default_rng(2)
    still, moving = MotionWatch(0.3), MotionWatch(0.3)
    for t in np.arange(0.0, 0.5, 0.001):
        still.add(t, Q0 + rng.normal(0.0, NOISE, 7))
        moving.add(t, Q0 + rng.normal(0.0, NOISE, 7) + np.array([0.2, 0, 0, 0, 0, 0, 0]) * t)
    assert still.moving(0.5, 0.005) == 0.0
    assert moving.moving(0.5, 0.005) == pytest.approx(0.06, abs=0.02)


def test_an_arm_that_has_just_come_to_rest_does_not_move():
    watch = MotionWatch(0.3)
    for t in np.arange(0.0, 0.5, 0.001):
        watch.add(t, Q0 + np.array([0.5, 0, 0, 0, 0, 0, 0]) * min(t, 0.3))
    assert watch.moving(0.5, 0.005) == 0.0


@pytest.mark.parametrize('speed', [3.0, 1e12, np.inf])
def test_a_stop_from_an_impossible_measured_velocity_stays_within_the_arms_range(speed):
    # the joint states' check refuses such states; should one reach the run, its stop must
    # neither run the arm at that speed nor fail (a stop from 1e12 rad/s raised in ruckig)
    run = run_from()
    velocity = np.zeros(7)
    velocity[0] = speed
    run.on_joint_state(0.01, Q0, velocity)
    run.actions.clear()
    run.stop()
    sends = [a for a in run.actions if isinstance(a, Send)]
    assert sends, 'no stop was sent'
    command = sends[-1].command
    assert np.all(np.isfinite(command.positions)) and ARM.within_limits(command.positions).all()
    assert np.abs(command.velocities).max() <= 1.5 * ARM.velocity_limits.max()
    assert np.allclose(command.velocities[-1], 0.0)


def test_a_run_refuses_a_velocity_scaling_at_which_the_arm_overshoots_its_limits():
    # the arm in joint impedance overshoots its commanded speed by up to 27 %, and the
    # driver's command guard stops at the URDF's limit (test_simulated_robot.py)
    assert RunSettings(velocity_scaling=MAX_VELOCITY_SCALING).velocity_scaling == 0.7
    with pytest.raises(ValueError, match='velocity_scaling must be in'):
        RunSettings(velocity_scaling=0.8)


def stop_after_silence(age: float, blocked_at: float | None = None):
    """
    Return where the arm is and the stop a run sends ``age`` s after its last joint state.

    The arm follows the first path ``motion_delay`` behind (held from ``blocked_at`` on)
    and goes on so while no state reaches the run.
    """
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    clock = [0.0]
    settings = RunSettings(velocity_scaling=0.7)
    run = Run(ARM, loop, settings, clock=lambda: clock[0])
    run.start(0.0, Q0)
    run.on_plan(loop.next_path(Q0))
    jtc, delay = run.trajectory, settings.detection.motion_delay
    t = 0.0
    while t < 0.5 * jtc.duration and run.detector is not None:
        t += 0.01
        clock[0] = t
        q, v, _ = jtc.sample((t if blocked_at is None else min(t, blocked_at)) - delay)
        if blocked_at is not None and t > blocked_at:
            v = 0 * v
        run.on_joint_state(t, q, v)
    assert run.active
    arm = jtc.sample((t + age if blocked_at is None else blocked_at) - delay)[0]
    clock[0] = t + age
    run.actions.clear()
    run.stop()
    return arm, [a.command for a in run.actions if isinstance(a, Send)][-1]


@pytest.mark.parametrize('age, blocked_at, within', [
    (0.01, None, 1e-3),       # a free arm moves on as its command says: started 0.010 rad back
    (0.2, 0.3, 0.01),         # a held arm stays: started 0.21 rad into what holds it
])
def test_a_stop_made_after_the_last_joint_state_starts_where_the_arm_is_by_then(
        age, blocked_at, within):
    arm, stop_command = stop_after_silence(age, blocked_at)
    assert np.abs(stop_command.positions[0] - arm).max() < within


def test_a_stop_of_an_arm_just_short_of_a_limit_commands_nothing_past_it():
    # extrapolated from a state 3 mrad short of A1's upper limit at 1 rad/s, 15 ms on
    loop = Disentangler(ARM, Planner(), Q1, max_paths=5, seed=0, goal_tolerance=0.04)
    clock = [0.0]
    run = Run(ARM, loop, RunSettings(velocity_scaling=0.7), clock=lambda: clock[0])
    q, v = Q0.copy(), np.zeros(7)
    q[0], v[0] = ARM.upper[0] - 0.003, 1.0
    run.start(0.0, q, v)
    run.on_joint_state(0.0, q, v)
    clock[0] = 0.015
    run.actions.clear()
    run.stop()
    command = [a.command for a in run.actions if isinstance(a, Send)][-1]
    assert ARM.within_limits(command.positions).all()
