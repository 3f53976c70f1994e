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
Figures of the physics mock that the detector is tuned on (``probdis bench physics``).

* real-time factor: simulated over wall-clock seconds, for the arm alone (MuJoCo holding a
  setpoint) and for the whole command path (JTC, the driver's filter, the arm);
* free-motion tracking: the L1 gap between what JTC commands (as the planner's detector
  computes it) and where the arm is, during a motion and after it settles, at a velocity
  scaling;
* a block: the demo scene's straight path into its obstacle, from the first contact to the
  detector's verdict: the delay, the gap and the contact force then, and how far the flange
  moved between contact and detection (what makes "the segment nearest at detection" late).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
import time

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.detector import BlockDetector, DetectorSettings, Verdict
from probdis_ros.motion.jtc import JtcTrajectory
from probdis_ros.motion.profiles import time_parameterize
from probdis_ros.physics.scene import load_scene
from probdis_ros.physics.simulated_robot import build_robot, RobotSettings
from probdis_ros.run import RunSettings


def real_time_factor(scene: str = 'demo_hook', seconds: float = 5.0) -> dict:
    """Return simulated / wall seconds for the arm alone and for the whole command path."""
    robot, _ = build_robot('physics', scene)
    engine = robot.engine
    hold = engine.q.copy()
    steps = round(seconds / robot.settings.period)
    t0 = time.perf_counter()
    for _ in range(steps):
        engine.advance(hold, robot.settings.period)
    arm_alone = seconds / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for _ in range(steps):
        robot.step()
    return {'arm_alone': arm_alone, 'command_path': seconds / (time.perf_counter() - t0),
            'timestep_s': engine.settings.timestep}


def _detection(**overrides) -> DetectorSettings:
    """Return the detector settings of a run (the planner's defaults), with overrides."""
    return replace(DetectorSettings(), **overrides)


def _motion(path: np.ndarray, velocity_scaling: float):
    """Return a path timed as the run times it (at any scaling, the run's range or beyond)."""
    limits = replace(RunSettings().limits(iiwa_arm()), velocity_scaling=velocity_scaling)
    return time_parameterize(path, limits)


def _drive(robot, command, settings: DetectorSettings, limit: float,
           on_step: Callable[[BlockDetector], None] | None = None
           ) -> tuple[BlockDetector, Verdict]:
    """Send command and step until the detector's verdict (or limit seconds)."""
    state = robot.joint_state()
    robot.command(command)
    detector = BlockDetector(JtcTrajectory(command, state.position, state.velocity),
                             robot.time, settings)
    end = robot.time + limit
    verdict = Verdict.MOVING
    while verdict is Verdict.MOVING and robot.time < end:
        robot.step()
        reported = robot.joint_state()
        verdict = detector.update(reported.time, reported.position)
        if on_step is not None:
            on_step(detector)
    return detector, verdict


@dataclass
class Tracking:
    """Free-motion tracking at one velocity scaling."""

    velocity_scaling: float
    peak_gap: float          # largest L1 gap during the motion [rad]
    final_gap: float         # L1 gap when the detector said done [rad]
    verdict: str
    settle_s: float          # from the planned end to the verdict [s]


def free_tracking(velocity_scaling: float, scene: str = 'demo_hook',
                  robot_settings: RobotSettings | None = None) -> Tracking:
    """Drive the scene's start -> goal with its obstacles removed; return the gaps."""
    free = replace(load_scene(scene), obstacles=())
    robot, _ = build_robot('physics', free, robot_settings)
    start = robot.joint_state().position
    goal = robot.engine.scene.goal
    motion = _motion(np.array([start, goal]), velocity_scaling)
    t_start = robot.time
    gaps = []
    detector, verdict = _drive(robot, motion.command, _detection(), motion.duration + 5.0,
                               lambda d: gaps.append(d.gap))
    peak = max(gaps, default=0.0)
    return Tracking(velocity_scaling, peak, detector.gap, verdict.value,
                    robot.time - t_start - motion.duration)


#: A long free edge, every joint moving 0.5-1.5 rad: the arm cruises at its scaled limits.
LONG_EDGE = (np.array([0.0, 0.6, 0.0, -1.2, 0.0, 0.6, 0.0]),
             np.array([1.5, 1.1, 1.5, -0.7, 1.5, 1.1, 1.5]))


@dataclass
class LongEdge:
    """LONG_EDGE in free space at one velocity scaling."""

    jtc_error: float        # one joint's largest |JTC's desired - measured| [rad]
    speed_over_limit: float  # the largest measured joint speed / its URDF limit


def long_edge(velocity_scaling: float) -> LongEdge:
    """
    Run LONG_EDGE in free space (the driver's guard off): the lag and the speed it reaches.

    The lag is what JTC's path tolerance (``constraints.<joint>.trajectory``) is checked
    against, largest at cruise speed; the speed is what the lbr stack's command guard
    checks (a measured speed above the URDF's limit stops the driver): the arm in joint
    impedance overshoots its commanded speed as it catches up.
    """
    start, goal = LONG_EDGE
    robot, _ = build_robot('physics', replace(load_scene('demo_hook'), obstacles=(),
                                              start=start, goal=goal), RobotSettings(guard=False))
    motion = _motion(np.array([start, goal]), velocity_scaling)
    robot.command(motion.command)
    error, speed = 0.0, 0.0
    limits = iiwa_arm().velocity_limits
    while robot.time < motion.duration + 0.5:
        before = robot.engine.q.copy()
        robot.step()
        running = robot.controller.trajectory
        desired = running.at(robot.time - running.taken_at)
        error = max(error, float(np.abs(desired - robot.engine.q).max()))
        moved = np.abs(robot.engine.q - before) / robot.settings.period
        speed = max(speed, float((moved / limits).max()))
    return LongEdge(error, speed)


@dataclass
class BlockFigures:
    """The demo scene's straight path into its obstacle."""

    verdict: str
    contact_s: float | None          # first contact after the command [s]
    detected_s: float | None         # the detector's verdict after the command [s]
    planned_s: float                 # the command's duration [s]
    gap_at_detection: float          # L1 [rad]
    peak_force_n: float              # largest summed normal force before detection [N]
    force_at_detection_n: float
    flange_moved_m: float            # from the first contact to detection [m]
    reason: str = ''                 # what declared the block
    onset_error_m: float | None = None   # flange at the detector's onset vs at contact [m]


def straight_block(scene: str = 'demo_hook', velocity_scaling: float = 0.2,
                   robot_settings: RobotSettings | None = None) -> BlockFigures:
    """Command the scene's straight start -> goal path and measure the block."""
    robot, _ = build_robot('physics', scene, robot_settings)
    start = robot.joint_state().position
    motion = _motion(np.array([start, robot.engine.scene.goal]), velocity_scaling)
    t0 = robot.time
    seen = {'contact_t': None, 'contact_x': None, 'peak': 0.0, 'force': 0.0}

    def watch(_: BlockDetector) -> None:
        force = sum(c.force for c in robot.engine.contacts())
        seen['force'], seen['peak'] = force, max(seen['peak'], force)
        if force > 0 and seen['contact_t'] is None:
            seen['contact_t'] = robot.time - t0
            seen['contact_x'] = robot.engine.flange_pose()[0]

    detector, verdict = _drive(robot, motion.command, _detection(), motion.duration + 5.0,
                               watch)
    contact_t, contact_x = seen['contact_t'], seen['contact_x']
    peak, force = seen['peak'], seen['force']
    detected = robot.time - t0 if verdict is Verdict.BLOCKED else None
    moved = 0.0 if contact_x is None else float(
        np.linalg.norm(robot.engine.flange_pose()[0] - contact_x))
    onset_error = None
    if detector.onset is not None and contact_x is not None:
        onset_x = iiwa_arm().fk(detector.onset.config[None]).positions[0]
        onset_error = float(np.linalg.norm(onset_x - contact_x))
    return BlockFigures(verdict.value, contact_t, detected, motion.duration, detector.gap,
                        peak, force, moved, detector.reason, onset_error)
