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
The arm as the planner meets it: JTC, the driver's filter, an arm, and what the driver reports.

:class:`SimulatedRobot` runs the real stack's command path at the controller rate (100 Hz):
joint_trajectory_controller (:mod:`probdis_ros.motion.jtc`) samples the newest command one
period ahead, ros2_control's joint limiter keeps it within the velocity limits of the last
(``enforce_command_limits``, which the lbr stack's controller manager sets; ``limiter``), the
lbr stack driver smooths it with its first-order filter, and an *engine* moves the arm toward
it for one period:

* :class:`~probdis_ros.physics.arm.PhysicsIiwa`: MuJoCo in joint impedance (the default of
  the mock): lags, swings around a contact, presses with a force set by its stiffness;
* :class:`KinematicEngine`: the idealised arm of the first mock and the offline simulator:
  follows the command with a servo lag within the velocity limits and stops dead at the
  first contact of the flange point with a scenario's hidden obstacles.

The driver's command guard (the lbr stack's default, ``guard``): a command outside the URDF's
position limits, or a measured joint speed (the difference of two measured positions over
the period) above the URDF's velocity limit, stops the driver (:attr:`SimulatedRobot.stopped`
says why): from then on the arm holds where it is and no joint state is reported, as a
real driver that threw "invalid command" leaves it.  KUKA's own Cartesian speed monitoring
(``speed_monitor`` [m/s], 0 by default: off; a safety configuration may set one, T1 means to
keep 250 mm/s) stops it the same way when a point of the arm (its URDF collision shapes and
the flange) moves faster: a safety stop ends the FRI session.  Some releases of the lbr
stack's position command interface do not throw but log "Overriding invalid command to
neutral command." (``guard_holds``): the guard checks each filtered command before it is
sent, with the measured motion since the last period that passed, and sends the measured
position instead of one that fails; the driver keeps running and reporting.

What the driver measures is what JTC reads and what it reports: the arm's position (with the
encoders' Gaussian ``noise``, if any) and, as the lbr stack's ``compute_hw_velocity_`` makes
it, a velocity that is the difference of the last two measured positions over the period
(so the noise reaches it divided by the period; the engine's own velocity is never seen).
The reported joint states (:meth:`SimulatedRobot.joint_state`) can also come late
(``latency``); their torques come through the driver's first-order filter
(``torque_tau``, the lbr stack's ``measured_torque_tau``), so they lag the arm's by about
0.1 s; and a driver with ``open_loop`` in effect "echoes": its position is the one
it commands (JTC's command after the driver's filter, as the lbr stack's
``set_state_open_loop`` copies it), differenced the same way, with the measured torques
as they are.
Commands can reach JTC late (``command_latency``), as on a loaded machine or network.
No rclpy: the mock node and ``probdis sim --engine physics`` both drive this class.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, replace
import math
from pathlib import Path
from typing import Protocol, TYPE_CHECKING

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.motion.cartesian_speed import point_speeds
from probdis_ros.motion.jtc import (
    CommandLimiter,
    CONTROLLER_RATE,
    DEFAULT_JTC_START,
    DRIVER_FILTER_TAU,
    DRIVER_TORQUE_TAU,
    FirstOrderFilter,
    JTC_STARTS,
    TrajectoryCommand,
    TrajectoryController,
)
from probdis_ros.sim.compliant_arm import CompliantArm

if TYPE_CHECKING:
    from probdis_ros.physics.scene import Scene
    from probdis_ros.physics.settings import PhysicsSettings


class Engine(Protocol):
    """What moves the arm: the physics or the kinematic stand-in."""

    time: float
    q: np.ndarray
    qdot: np.ndarray

    def reset(self, q: np.ndarray) -> None:
        """Place the arm at rest at q."""

    def advance(self, setpoint: np.ndarray, duration: float) -> None:
        """Move toward setpoint for duration seconds of simulated time."""


#: What an episode's message says of each stop of the driver (its guard, KUKA's speed
#: monitoring), before the reason.
DRIVER_STOPPED = 'the driver stopped:'
#: ... or its guard holds the arm (``guard_holds``), as the episodes' messages say it
GUARD_HELD = "the driver's guard holds the arm:"
#: [Nm] the robot application refuses to switch to joint impedance while the external torque
#: on a joint is above this (current lbr stack releases; README "Pointing it at the real
#: arm"), so a driver stopped while the arm presses on something cannot be restarted there.
RESTART_TORQUE = 2.0
#: The kinematic arm follows its setpoint with this first-order lag [s], as a servo does: an
#: arm that copied the driver's command at once could not be told from a driver that echoes
#: it (the planner's echo test), and no real arm does.
SERVO_TAU = 0.05


class KinematicEngine:
    """
    The idealised arm: follows the setpoint (a servo lag, the velocity limits), stops at contact.

    On contact with a hidden obstacle the flange stops just before it and stays until a
    setpoint leads away (the compliant arm of the offline simulator).
    """

    def __init__(self, arm: Arm, compliant: CompliantArm) -> None:
        self.arm = arm
        self.compliant = compliant
        self.time = 0.0
        self.q = np.zeros(arm.n_joints)
        self.qdot = np.zeros(arm.n_joints)
        self.tau_measured: np.ndarray | None = None     # no torques modelled

    def reset(self, q: np.ndarray) -> None:
        """Place the arm at q (and load the compiled FK now, not mid-run)."""
        self.q = np.asarray(q, dtype=float).copy()
        self.qdot[:] = 0.0
        self.compliant.execute(np.array([self.q, self.q]))

    def advance(self, setpoint: np.ndarray, duration: float) -> None:
        """Step toward setpoint with the servo lag, at most the velocity limits allow."""
        reach = self.arm.velocity_limits * duration
        share = 1.0 - math.exp(-duration / SERVO_TAU)
        step = np.clip(share * (np.asarray(setpoint, dtype=float) - self.q), -reach, reach)
        before = self.q
        if np.any(step != 0):
            self.q = self.compliant.execute(np.array([self.q, self.q + step])).config
        self.qdot = (self.q - before) / duration if duration > 0 else 0.0 * self.q
        self.time += duration


#: The faults of the command path and the driver (RobotSettings' non-negative fields).
DRIVER_FAULTS = ('noise', 'effort_noise', 'latency', 'command_latency', 'speed_monitor',
                 'collision_torque')
#: The second word of the seed of the joint torques' noise stream (RobotSettings.seed first).
EFFORT_STREAM = 1


@dataclass
class RobotSettings:
    """The command path and what the driver reports; every default in one place."""

    period: float = 1.0 / CONTROLLER_RATE   # JTC and driver cycle [s]
    filter_tau: float = DRIVER_FILTER_TAU   # the driver's command filter [s]; 0: none
    torque_tau: float = DRIVER_TORQUE_TAU   # its filter of the measured torques [s]; 0: none
    noise: float = 0.0                      # std. dev. of reported positions [rad]
    effort_noise: float = 0.0               # std. dev. of reported joint torques [Nm]
    latency: float = 0.0                    # reported joint states are this old [s]
    command_latency: float = 0.0            # a command reaches JTC this long after it is sent [s]
    echo: bool = False                      # report the command sent, not the arm (open_loop)
    guard: bool = True                      # the driver's command guard stops it on a fault
    guard_holds: bool = False               # ... or commands the measured position instead
    speed_monitor: float = 0.0              # KUKA's Cartesian speed monitoring [m/s]; 0: off
    collision_torque: float = 0.0           # KUKA's collision detection [Nm, a joint]; 0: off
    limiter: bool = True                    # ros2_control's joint limiter (CommandLimiter)
    seed: int = 0                           # noise stream
    jtc_start: str = DEFAULT_JTC_START      # JTC's interpolate_from_desired_state: 'desired'

    def __post_init__(self) -> None:
        """Refuse settings that cannot run."""
        if not self.period > 0:
            raise ValueError(f'period must be positive, got {self.period}')
        for name in ('filter_tau', 'torque_tau', *DRIVER_FAULTS):
            if not getattr(self, name) >= 0:
                raise ValueError(f'{name} must be non-negative, got {getattr(self, name)}')
        if self.jtc_start not in JTC_STARTS:
            raise ValueError(f'jtc_start must be one of {", ".join(JTC_STARTS)}, got '
                             f'{self.jtc_start!r}')


@dataclass(frozen=True)
class JointStateSample:
    """One joint state as the driver reports it."""

    time: float
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray | None      # the measured joint torques; None: the engine has none


class SimulatedRobot:
    """JTC -> joint limiter -> driver filter -> engine, one controller period per :meth:`step`."""

    def __init__(self, engine: Engine, start: np.ndarray,
                 settings: RobotSettings | None = None) -> None:
        self.engine = engine
        self.settings = settings or RobotSettings()
        self.filter = FirstOrderFilter(self.settings.filter_tau, self.settings.period)
        self.torque_filter = FirstOrderFilter(self.settings.torque_tau, self.settings.period)
        self.rng = np.random.default_rng(self.settings.seed)
        # the torques' noise from a stream of its own: the positions' stays as it was
        self.effort_rng = np.random.default_rng((self.settings.seed, EFFORT_STREAM))
        from probdis_ros.model import iiwa_arm
        self._limits = iiwa_arm()
        self.limiter = CommandLimiter(self._limits.velocity_limits, self._limits.lower,
                                      self._limits.upper, self.settings.period) \
            if self.settings.limiter else None
        engine.reset(start)
        # the fastest change of a joint's command in one period, over its velocity limit:
        # JTC's output and the driver's (after the limiter and its filter); above 1 the
        # command stepped
        self.command_speed_peak = 0.0
        self.sent_speed_peak = 0.0
        self._activate()

    def _activate(self) -> None:
        """Start the driver and JTC where the arm is: JTC holds it until a command comes."""
        q = self.engine.q
        self.controller = TrajectoryController(self.settings.period, self.settings.jtc_start)
        self.filter.reset(q)
        self.torque_filter.reset(None)       # starts at the first torque it is given
        if self.limiter is not None:
            self.limiter.reset(q)
        self.commanded = q.copy()             # JTC's last position command
        self._sent_before = q.copy()          # the driver's command one period earlier
        self.stopped: str | None = None       # why the driver's command guard stopped it
        # guard_holds: the measured position its velocity check last passed, and its trips
        self._guard_passed = q.copy()
        self.guard_trips = 0
        self.guard_trip: str | None = None    # why it tripped last
        self.holding: str | None = None       # ... if it tripped in the last period too
        self._stop_torque = np.zeros(len(q))  # the contacts' torques then [Nm]
        self._reported: deque[JointStateSample] = deque()
        # (when JTC gets it, the command) of messages still on their way (command_latency)
        self._in_flight: deque[tuple[float, TrajectoryCommand]] = deque()
        self._measured: JointStateSample | None = None   # none before: velocity 0
        self._measure()

    def restart(self) -> None:
        """
        Restart a stopped driver, as the operator does after a safety stop.

        Also one whose holding guard has tripped (``guard_holds``), which a joint's speed
        leaves holding the arm for good while the driver runs.

        The robot application and the driver come up again where the arm holds: JTC holds
        the measured position, no command of before survives, joint states flow again.
        RuntimeError if the driver runs, or if the robot application would refuse to
        switch to joint impedance: an external torque above :data:`RESTART_TORQUE` on a
        joint (the physics arm's contacts), as current lbr stack releases refuse it.  A
        real arm's safety stop puts it on its brakes, which keep a contact it pressed at
        the stop pressing; the mock holds the stopped arm with its impedance, which lets
        the contact relax: so the torque at the stop counts, or now's if larger.
        """
        if self.stopped is None and not self.guard_trips:
            raise RuntimeError('the driver is running: nothing to restart')
        external = np.maximum(self._stop_torque, self._external_torque())
        if external.max() > RESTART_TORQUE:
            joint = int(external.argmax())
            raise RuntimeError(
                f'the robot application refuses joint impedance: an external torque of '
                f'{external[joint]:.1f} Nm on A{joint + 1}, above {RESTART_TORQUE:g} Nm (the '
                f'arm pressed on something when it stopped, and its brakes hold it so: move '
                f'it free first)')
        self._activate()

    def _external_torque(self) -> np.ndarray:
        """Return |the torque contacts exert on each joint| [Nm] (0 on the kinematic arm)."""
        return np.abs(getattr(self.engine, 'tau_external', np.zeros(len(self.engine.q))))

    @property
    def time(self) -> float:
        """Return the simulated time [s]."""
        return self.engine.time

    def command(self, command: TrajectoryCommand) -> None:
        """Send JTC a trajectory message; it takes it at its first update after it arrives."""
        self._in_flight.append((self.engine.time + self.settings.command_latency, command))

    def step(self) -> None:
        """Run one controller period: JTC update, joint limiter, driver filter, the arm moves."""
        if self.stopped is not None:        # the driver is down: the arm holds, unreported
            self.engine.advance(self._held, self.settings.period)
            return
        while self._in_flight and self._in_flight[0][0] <= self.engine.time + 1e-12:
            self.controller.receive(self._in_flight.popleft()[1])   # the newest replaces
        state = self._measured      # JTC starts a new trajectory from the measured state
        # (or, jtc_start 'desired', from its last command)
        previous = self.commanded
        self.commanded = self.controller.update(self.engine.time, state.position,
                                                state.velocity)
        if not np.all(np.isfinite(self.commanded)):
            # a spline that overflowed (a finite but absurd velocity in the message): the
            # driver takes no target that is not a number, it holds its last
            self.commanded = previous
        self._sent_before = self.filter.value.copy()
        before = self.engine.q.copy()
        limited = self.commanded if self.limiter is None else self.limiter(self.commanded)
        sent = self.filter(limited)
        if self.settings.guard and self.settings.guard_holds:
            sent = self._guard_hold(sent)
        self.command_speed_peak = max(self.command_speed_peak,
                                      self._speed_over_limit(self.commanded - previous))
        self.sent_speed_peak = max(self.sent_speed_peak,
                                   self._speed_over_limit(sent - self._sent_before))
        self.engine.advance(sent, self.settings.period)
        if self.settings.guard or self.settings.speed_monitor or \
                self.settings.collision_torque:
            self.stopped = self._guard(sent, before)
            if self.stopped is not None:
                self._held = self.engine.q.copy()
                self._stop_torque = self._external_torque()
                return
        self._measure()

    def _guard_hold(self, sent: np.ndarray) -> np.ndarray:
        """
        Return the command the driver sends this period, its guard holding where it trips.

        The lbr stack's releases that log "Overriding invalid command to neutral command."
        check the filtered command against the position limits and the measured motion
        since the last period that passed (velocity limits) before they send it, and send
        the measured position instead of a command that fails; the filter goes on from
        there.  The driver keeps running, and its joint states keep coming.
        """
        # in open loop the driver measures the command it sent the period before
        measured = self._sent_before.copy() if self.settings.echo else self.engine.q.copy()
        reason = self._command_guard(sent, measured - self._guard_passed)
        self.holding = reason
        if reason is None:
            self._guard_passed = measured
            return sent
        self.guard_trips += 1
        self.guard_trip = reason
        self.filter.reset(measured)
        return measured

    def _speed_over_limit(self, change: np.ndarray) -> float:
        speed = np.abs(change) / self.settings.period
        return float(np.max(speed / self._limits.velocity_limits))

    def _guard(self, sent: np.ndarray, before: np.ndarray) -> str | None:
        """Return why the command guard or KUKA's speed monitoring stops it now, or None."""
        limit = self.settings.speed_monitor
        if limit:
            fastest = float(point_speeds(self._limits, self.engine.q[None],
                                         self.engine.qdot[None])[0])
            if fastest > limit:
                return (f"KUKA's Cartesian speed monitoring: a point of the arm at "
                        f'{fastest:.3f} m/s, above {limit:g} m/s (a safety stop)')
        limit = self.settings.collision_torque
        if limit:
            torque = self._external_torque()
            if torque.max() > limit:
                joint = int(np.argmax(torque))
                return (f"KUKA's collision detection: an external torque of "
                        f'{torque[joint]:.1f} Nm at A{joint + 1}, above {limit:g} Nm (a safety '
                        f'stop)')
        if not self.settings.guard or self.settings.guard_holds:
            return None
        return self._command_guard(sent, self.engine.q - before)

    def _command_guard(self, sent: np.ndarray, moved: np.ndarray) -> str | None:
        """
        Return why the lbr command guard refuses a command, or None.

        sent outside the position limits, or the measured motion over one period, moved,
        faster than the velocity limits.
        """
        limits = self._limits
        outside = (sent < limits.lower) | (sent > limits.upper)
        if outside.any():
            joint = int(np.argmax(outside))
            return f'position command of A{joint + 1} outside its limits ({sent[joint]:.4f} rad)'
        speed = np.abs(moved) / self.settings.period
        over = speed / limits.velocity_limits
        if over.max() > 1.0 + 1e-9:
            joint = int(np.argmax(over))
            return (f'A{joint + 1} measured at {speed[joint]:.2f} rad/s, above its velocity '
                    f'limit {limits.velocity_limits[joint]:.2f} rad/s')
        return None

    def _measure(self) -> None:
        """
        Measure the arm now, as the driver's state interfaces hold it, and report it.

        The position is the arm's (the echo: the driver's filtered command) with the
        encoders' noise; the velocity its difference from the measurement one period
        before (0 at the first, the arm at rest); the torques the engine's through the
        driver's filter (``torque_tau``; it starts at the first torque), with the published
        torques' noise (the kinematic engine models none: its states carry none, as zeros
        would read as the whole of gravity pressing on the arm).
        """
        e, settings = self.engine, self.settings
        position = self.filter.value.copy() if settings.echo else e.q.copy()
        if settings.noise > 0:
            position = position + self.rng.normal(scale=settings.noise, size=position.shape)
        before = self._measured
        velocity = np.zeros_like(position) if before is None else \
            (position - before.position) / settings.period
        torques = getattr(e, 'tau_measured', None)
        effort = None if torques is None else self.torque_filter(torques)
        if settings.effort_noise > 0 and effort is not None:
            effort = effort + self.effort_rng.normal(scale=settings.effort_noise,
                                                     size=effort.shape)
        self._measured = JointStateSample(e.time, position, velocity, effort)
        self._reported.append(self._measured)
        horizon = e.time - settings.latency
        while len(self._reported) > 1 and self._reported[1].time <= horizon + 1e-12:
            self._reported.popleft()

    def joint_state(self) -> JointStateSample:
        """Return the newest joint state the driver has reported (``latency`` old)."""
        return self._reported[0]


#: The arms a SimulatedRobot can drive.
ENGINES = ('physics', 'kinematic')


#: The faults of the physics arm alone.
PHYSICS_FAULTS = ('object_mass_error', 'armature', 'grasp_stiffness', 'stiffness',
                  'damping_ratio', 'joint_friction')
#: What a real setup adds to the ideal mock, by the mock node's parameter names: the
#: driver's joint-state ``noise`` [rad], ``effort_noise`` [Nm] and ``latency`` [s], the
#: delivery of its commands, ``command_latency`` [s] (a loaded machine or network, a large
#: message), KUKA's ``speed_monitor`` [m/s] and ``collision_torque`` [Nm: its collision
#: detection on the external torque of any joint] (RobotSettings), the load model's
#: ``object_mass_error`` [kg], the motors' reflected inertia ``armature`` [kg m^2, every
#: joint], a grasp that gives, ``grasp_stiffness`` [Nm/rad], the joints' dry friction the
#: impedance law leaves, ``joint_friction`` [Nm]; and the robot application's
#: joint impedance, ``stiffness`` [Nm/rad, every joint] and ``damping_ratio``, which a user
#: sets on the real arm (PhysicsSettings; the physics arm only).
FAULTS = DRIVER_FAULTS + PHYSICS_FAULTS


def with_faults(faults: Mapping[str, float], settings: RobotSettings | None = None
                ) -> tuple[RobotSettings, PhysicsSettings]:
    """
    Return the driver's and the physics arm's settings with ``faults`` (names of FAULTS) in.

    Raises ValueError naming an unknown fault or a value the settings refuse.
    """
    from probdis_ros.physics.settings import PhysicsSettings

    unknown = sorted(set(faults) - set(FAULTS))
    if unknown:
        raise ValueError(f'no fault {unknown[0]!r} (one of {", ".join(FAULTS)})')
    robot = replace(settings or RobotSettings(),
                    **{k: float(v) for k, v in faults.items() if k in DRIVER_FAULTS})
    per_joint = ('armature', 'stiffness')       # one value for every joint
    physics = replace(PhysicsSettings(), **{k: float(v) for k, v in faults.items()
                                            if k in PHYSICS_FAULTS and k not in per_joint})
    for name in per_joint:
        if name in faults:
            physics = replace(physics, **{name: (float(faults[name]),) * 7})
    return robot, physics


def build_robot(engine: str, world: str | Path | Scene, settings: RobotSettings | None = None,
                physics: PhysicsSettings | None = None) -> tuple[SimulatedRobot, str]:
    """
    Return a robot at the start of a world, and a line describing it.

    world is a physics scene (a Scene, a file or a name in config/scenes/) for ``physics``
    (moved by the physics arm with ``physics``'s settings), a kinematic scenario (file or
    name in config/scenarios/) for ``kinematic``.
    """
    settings = settings or RobotSettings()
    if engine == 'kinematic':
        from probdis_ros.model import iiwa_arm
        from probdis_ros.resources import scenario_path
        from probdis_ros.sim.worlds import load_world
        scenario = load_world(scenario_path(world))
        if scenario.setting == '2d':
            raise ValueError(f'{world}: the iiwa needs a 3d or 3d-orient scenario')
        kinematic = KinematicEngine(iiwa_arm(), scenario.compliant_arm())
        robot = SimulatedRobot(kinematic, scenario.start, settings)
        return robot, (f'scenario {scenario.name or world} with {len(scenario.obstacles)} '
                       f'hidden obstacles')
    if engine == 'physics':
        from probdis_ros.physics import load_scene, PhysicsIiwa, PhysicsSettings
        scene = load_scene(world) if isinstance(world, (str, Path)) else world
        robot = SimulatedRobot(PhysicsIiwa(scene, physics or PhysicsSettings()), scene.start,
                               settings)
        return robot, f'scene {scene.name} with {len(scene.obstacles)} hidden obstacles'
    raise ValueError(f'engine must be one of {", ".join(ENGINES)}, got {engine!r}')
