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
One disentangling against the physics arm, without ROS, as fast as the machine allows.

The same :class:`~probdis_ros.run.Run` as the planner node drives a
:class:`~probdis_ros.physics.simulated_robot.SimulatedRobot` on simulated time: every
controller period the run gets the reported joint state, and its commands go through JTC,
the driver's filter and MuJoCo.  Planning is done in place (simulated time stands still
while the planner thinks), so an episode measures the method and the arm, not this
machine's speed.  ``probdis sim --engine physics`` and the robot-style sweeps use it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import time

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.model.table import ROBOT_TABLE, Table
from probdis_ros.motion.cartesian_speed import point_speeds
from probdis_ros.physics.model import TABLE
from probdis_ros.physics.settings import PhysicsSettings
from probdis_ros.physics.simulated_robot import (
    build_robot,
    DRIVER_STOPPED,
    GUARD_HELD,
    RobotSettings,
)
from probdis_ros.planning import Disentangler, Method, RRTSettings, State
from probdis_ros.planning.disentangle import (
    DEFAULT_MAX_PATHS,
    DEFAULT_MIN_RETREAT,
    ROBOT_GOAL_TOLERANCE,
)
from probdis_ros.planning.prob_rrt import ROBOT_JOINT_MARGIN
from probdis_ros.run import goal_problem, Learned, Phase, PlanFrom, Propose, Run, RunSettings, Send

#: [s] of simulated time the arm rests, held, once the run stopped on the silent driver and
#: before the operator restarts it (``restarts``): a real restart takes longer, and the arm
#: has settled by then.
RESTART_AFTER = 2.0


@dataclass
class PhysicsEpisode:
    """What happened: the outcome, the arm's trace, the failures and the contacts."""

    success: bool
    outcome: str
    paths: int
    failures: list[dict]
    times: np.ndarray               # simulated time of every controller period [s]
    configs: np.ndarray             # the arm's true configuration then
    gaps: np.ndarray                # the detector's L1 gap then (0 where nothing runs)
    contact_force: np.ndarray       # summed normal force between arm/object and scene [N]
    table_force: np.ndarray         # the part of it on the mock's table top [N]
    external_torque_peak: np.ndarray  # per joint, the largest |external torque| [Nm]
    plan_times_s: list[float]
    sim_time_s: float
    wall_time_s: float
    scene: object = None
    # per joint, the largest |effort - g(q)| the planner's runs estimated (their status's
    # peak_external_torque_nm) [Nm]
    estimated_torque_peak: np.ndarray | None = None
    loop: Disentangler | None = None
    message: str = ''
    commands: list = field(default_factory=list)
    # the fastest one-period change of JTC's command and of the driver's, over the joint's
    # velocity limit (above 1: a step the arm's controller is sent)
    command_speed_peak: float = 0.0
    sent_speed_peak: float = 0.0
    # the fastest any point of the arm (collision shapes, the object's ball, the flange)
    # moved [m/s], of its true motion: what KUKA's Cartesian speed monitoring sees
    point_speed_peak: float = 0.0
    # when the driver was restarted after it stopped the arm (``restarts``) [s, simulated]
    restarted_at: list[float] = field(default_factory=list)
    # when each planned path was proposed to the operator (``confirm_paths``) [s, simulated]
    proposed_at: list[float] = field(default_factory=list)

    @property
    def restarts(self) -> int:
        """Return how often the driver was restarted after it stopped the arm."""
        return len(self.restarted_at)

    def summary(self) -> dict:
        """
        Return the JSON summary printed by ``probdis sim --engine physics --json``.

        ``lowest_m`` is as ``probdis sim`` reports it (the lowest height any collision shape
        of the arm, or its tip, reached), of the arm's true configurations; with
        ``peak_table_force_n`` it tells whether and how hard the arm or the object touched
        the mock's table top, which the planner keeps them clear of.
        ``peak_external_torque_nm``: per joint, the largest external torque the contacts
        exerted, what a real iiwa's collision detection (if its application sets one)
        compares with its thresholds.  ``driver_restarts``: how often the driver that stopped
        the arm was restarted and the planner started again (``restarts``).
        """
        return {'success': self.success, 'outcome': self.outcome, 'paths': self.paths,
                'failures': len(self.failures), 'message': self.message,
                'sim_time_s': round(self.sim_time_s, 3),
                'wall_time_s': round(self.wall_time_s, 3),
                'real_time_factor': round(self.sim_time_s / max(self.wall_time_s, 1e-9), 1),
                'peak_contact_force_n': round(float(self.contact_force.max(initial=0.0)), 1),
                'peak_table_force_n': round(float(self.table_force.max(initial=0.0)), 1),
                'lowest_m': round(float(iiwa_arm().lowest_heights(self.configs).min()), 4),
                'peak_external_torque_nm': [round(float(t), 1)
                                            for t in self.external_torque_peak],
                'command_speed_peak': round(self.command_speed_peak, 3),
                'sent_speed_peak': round(self.sent_speed_peak, 3),
                'point_speed_peak_mps': round(self.point_speed_peak, 3),
                'driver_restarts': self.restarts,
                'plan_times_s': self.plan_times_s}


def run_physics_episode(scene: str, method: str | Method = 'probabilistic', seed: int = 0,
                        max_paths: int = DEFAULT_MAX_PATHS, rrt: RRTSettings | None = None,
                        run_settings: RunSettings | None = None,
                        robot_settings: RobotSettings | None = None,
                        physics_settings: PhysicsSettings | None = None,
                        time_limit: float = 600.0,
                        goal_tolerance: float = ROBOT_GOAL_TOLERANCE,
                        min_retreat: float = DEFAULT_MIN_RETREAT,
                        table: Table | None = ROBOT_TABLE, restarts: int = 0,
                        confirm_after: float = 0.0, c_fail: float | None = None
                        ) -> PhysicsEpisode:
    """
    Disentangle a physics scene from its start to its goal; reproducible from seed.

    The planner keeps the arm and the grasped object (a ball about the flange point that
    holds it) above ``table``, as the planner node does with its parameters.  The driver and
    the physics arm run with ``robot_settings`` and ``physics_settings`` (their defaults:
    the ideal mock, JTC as ``run_settings`` models it).

    ``restarts``: when the driver stops the arm (its command guard, KUKA's speed
    monitoring), or its guard holds the arm as the run ends (``guard_holds``: the run stops
    on an arm that let go of its command), the operator lets the arm come to rest for
    :data:`RESTART_AFTER`, restarts the driver and starts the planner again, at most this
    many times: the map keeps what was learned (the node keeps it on disk), the new run
    plans from where the arm is, and all runs together plan at most ``max_paths`` paths.  A
    restart the robot application refuses (the arm presses on something:
    ``SimulatedRobot.restart``) ends the episode.

    ``confirm_after``: with ``run_settings.confirm_paths``, the operator confirms each
    planned path this long [s, simulated] after it is proposed (the arm waits at rest).
    ``c_fail``: the map's C_FAIL (None: the method's).

    A scene whose goal the planner node would refuse (within ``rrt.joint_margin`` of a joint
    limit, :func:`~probdis_ros.run.goal_problem`) raises ValueError.
    """
    if restarts < 0:
        raise ValueError(f'restarts must be >= 0, got {restarts}')
    if not 0.0 <= confirm_after < math.inf:
        raise ValueError(f'confirm_after must be finite and >= 0, got {confirm_after}')
    if confirm_after and not (run_settings and run_settings.confirm_paths):
        raise ValueError('confirm_after needs run_settings with confirm_paths')
    wall = time.perf_counter()
    method = Method.resolve(method) if isinstance(method, str) else method
    if robot_settings is None and run_settings is not None:
        # JTC as the run models it
        robot_settings = RobotSettings(jtc_start=run_settings.jtc_start)
    robot, _ = build_robot('physics', scene, robot_settings, physics_settings)
    scene_doc = robot.engine.scene
    arm = iiwa_arm().on_table(table, scene_doc.object_reach)
    fmap = method.failure_map(arm.task_space, c_fail)
    # the planner node's default margin, so that offline runs plan as the node does
    rrt = rrt or RRTSettings(joint_margin=ROBOT_JOINT_MARGIN)
    problem = goal_problem(arm, scene_doc.goal, rrt.joint_margin)
    if problem:                         # refused as the node refuses it
        raise ValueError(f'scene {scene_doc.name}: goal {problem}')
    planner = method.planner(arm, rrt)

    def start_run(paths: int) -> tuple[Disentangler, Run]:
        """Start a run, as ``~/start`` does: a new loop on the map, from where the arm is."""
        loop = method.disentangler(arm, planner, scene_doc.goal, fmap, max_paths=paths,
                                   seed=seed, goal_tolerance=goal_tolerance,
                                   min_retreat=min_retreat)
        run = Run(arm, loop, run_settings or RunSettings())
        state = robot.joint_state()
        run.start(state.time, state.position)
        return loop, run

    failures, commands, loops, messages, restarted_at = [], [], [], [], []
    proposed_at: list[float] = []         # when each path was proposed (confirm_paths)
    times, configs, velocities, gaps, forces, table_forces = [], [], [], [], [], []
    torque_peak = np.zeros(arm.n_joints)
    estimate_peak = np.zeros(arm.n_joints)     # the runs' own, from the efforts

    def act() -> None:
        while run.actions:
            action = run.actions.pop(0)
            if isinstance(action, Send):
                robot.command(action.command)
                seen = robot.joint_state()      # what JTC will start the command from
                commands.append((robot.time, action.command, seen.position, seen.velocity))
            elif isinstance(action, PlanFrom):
                run.on_plan(loop.next_path(action.config))
            elif isinstance(action, Learned):
                failures.append(action.event)
            elif isinstance(action, Propose):
                proposed_at.append(robot.time)
                if confirm_after == 0.0:
                    run.confirm(robot.time)

    def confirm_due() -> None:
        if run.phase is Phase.AWAITING and robot.time >= proposed_at[-1] + confirm_after:
            run.confirm(robot.time)
            act()

    def record(run: Run | None) -> None:
        times.append(robot.time)
        configs.append(robot.engine.q.copy())
        velocities.append(robot.engine.qdot)
        gaps.append(run.detector.gap if run is not None and run.detector is not None else 0.0)
        contacts = robot.engine.contacts()
        forces.append(sum(c.force for c in contacts))
        table_forces.append(sum(c.force for c in contacts if c.scene_geom == TABLE))
        if contacts:
            np.maximum(torque_peak, np.abs(robot.engine.tau_external), out=torque_peak)

    paths_used = 0
    while True:
        loop, run = start_run(max_paths - paths_used)
        loops.append(loop)
        act()
        while run.active and robot.time < time_limit:
            robot.step()
            if robot.stopped is None:       # a stopped driver reports nothing more
                state = robot.joint_state()
                run.on_joint_state(state.time, state.position, state.velocity, state.effort)
            run.tick(robot.time)
            act()
            confirm_due()
            record(run)
        if run.torque_peak is not None:
            np.maximum(estimate_peak, run.torque_peak, out=estimate_peak)
        if run.active:
            run.finish(State.STOPPED, f'time limit of {time_limit:.0f} s simulated reached')
        paths_used += loop.paths_tried
        if robot.stopped is None and robot.holding is None:
            messages.append(run.message)
            break
        messages.append(f'{run.message} ({DRIVER_STOPPED} {robot.stopped})' if robot.stopped
                        else f'{run.message} ({GUARD_HELD} {robot.holding})')
        # (a run that reached the goal as the driver stopped is done: nothing to restart)
        if run.phase is Phase.SUCCEEDED or len(loops) > restarts or paths_used >= max_paths:
            break
        rest_until = robot.time + RESTART_AFTER
        while robot.time < min(rest_until, time_limit):
            robot.step()
            record(None)
        if robot.time >= time_limit:
            messages.append(f'time limit of {time_limit:.0f} s simulated reached')
            break
        try:
            robot.restart()
        except RuntimeError as refused:
            messages.append(f'no restart: {refused}')
            break
        restarted_at.append(robot.time)

    return PhysicsEpisode(
        success=run.phase.value == 'succeeded', outcome=run.phase.value,
        paths=paths_used, failures=failures, times=np.array(times),
        configs=np.array(configs).reshape(-1, arm.n_joints), gaps=np.array(gaps),
        contact_force=np.array(forces), table_force=np.array(table_forces),
        external_torque_peak=torque_peak, estimated_torque_peak=estimate_peak,
        plan_times_s=[t for each in loops for t in each.plan_times],
        sim_time_s=robot.time, wall_time_s=time.perf_counter() - wall, scene=scene_doc,
        loop=loop, message='; then '.join(messages), commands=commands, restarted_at=restarted_at,
        proposed_at=proposed_at,
        command_speed_peak=robot.command_speed_peak, sent_speed_peak=robot.sent_speed_peak,
        point_speed_peak=float(point_speeds(arm, np.array(configs), np.array(velocities))
                               .max(initial=0.0)) if configs else 0.0)
