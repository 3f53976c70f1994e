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
mock_iiwa_node: a simulated LBR iiwa for tests and demos, with hidden obstacles.

It stands where the lbr stack's driver and joint_trajectory_controller stand: commands on
the JTC topic go through JTC's own interpolation rules (:mod:`probdis_ros.motion.jtc`), the
driver's command filter and an arm (:mod:`probdis_ros.physics.simulated_robot`), and joint
states (positions, velocities, and the physics arm's measured torques as efforts) come out
at the controller rate.  ``engine``
chooses the arm:

* ``physics`` (default): MuJoCo in joint impedance with a scene of rigid and yielding
  clutter (``scene``: a file, or a name in config/scenes/);
* ``kinematic``: the idealised arm of the first mock (``scenario``: config/scenarios/),
  which copies the command and stops dead at the first contact of the flange point.

With ``sim_time`` the mock runs on simulated time: it publishes ``/clock`` and runs
``real_time_factor`` times faster than the wall clock (0: as fast as it can), so a planner
started with ``use_sim_time:=true`` can be tested many times faster than real time.
Optional faults: joint-state noise, latency, commands delivered late (``command_latency``),
the "echo" of a driver in open loop, and of
the physics arm a load-model error, the motors' reflected inertia (``armature``) and a
grasp that gives (``grasp_stiffness``); and the robot application's joint impedance
(``stiffness``, ``damping_ratio``), which a user sets on the real arm.  When the driver's
command guard or KUKA's speed monitoring (``speed_monitor``) stops it, no joint state
follows until ``~/restart_driver`` (std_srvs/Trigger) brings it up again where the arm
holds, as the operator restarts the robot application and the driver (refused, as the
robot application refuses it, while the arm presses on something with more than 2 Nm).
"""

from __future__ import annotations

import sys
import time

from builtin_interfaces.msg import Time
import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.jtc import DEFAULT_JTC_START, DRIVER_TORQUE_TAU, moved_onto_clock
from probdis_ros.physics.settings import PhysicsSettings
from probdis_ros.physics.simulated_robot import (
    build_robot,
    ENGINES,
    FAULTS,
    JointStateSample,
    RobotSettings,
    with_faults,
)
from probdis_ros.ros import (
    checked_joint_names,
    DEFAULT_REAL_TIME_FACTOR,
    JOINT_NAMES,
    JOINT_STATES_TOPIC,
    MOCK_NODE,
    TRAJECTORY_TOPIC,
)
from probdis_ros.ros.markers import scene_markers
from probdis_ros.ros.messages import command_from_msg
from probdis_ros.ros.node_main import refuse_unknown_parameters, run_node
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

#: The most simulated time [s] a late tick on wall time catches up at once.
CATCH_UP = 0.1


def _describe(text: str, low: float | None = None, high: float | None = None
              ) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(description=text, read_only=True)
    if low is not None:
        descriptor.floating_point_range = [FloatingPointRange(from_value=low, to_value=high)]
    return descriptor


class MockIiwa(Node):
    """The simulated arm: a thin adapter around :class:`SimulatedRobot`."""

    def __init__(self, **kwargs) -> None:
        super().__init__(MOCK_NODE, **kwargs)
        p = self.declare_parameter
        p('engine', 'physics', _describe('physics (MuJoCo, joint impedance) | kinematic'))
        p('scene', 'demo_hook', _describe('physics scene file, or name in config/scenes/'))
        p('scenario', 'demo_iiwa', _describe('kinematic scenario file, or name in '
                                             'config/scenarios/'))
        p('rate', 100.0, _describe('controller and joint-state rate [Hz]', 10.0, 2000.0))
        p('noise', 0.0, _describe('std. dev. of joint-state noise [rad]', 0.0, 0.1))
        p('effort_noise', 0.0, _describe('std. dev. of the torques in the joint states [Nm] '
                                         '(the physics arm)', 0.0, 50.0))
        p('latency', 0.0, _describe('delay of published joint states [s]', 0.0, 1.0))
        p('command_latency', 0.0, _describe('delay of each trajectory message before JTC '
                                            'takes it [s]', 0.0, 1.0))
        p('publish_velocities', True, _describe(
            'publish the measured velocities (false: joint states without them, as a '
            'joint_state_broadcaster whose interfaces leave them out)'))
        p('measured_torque_tau', DRIVER_TORQUE_TAU, _describe(
            "the driver's first-order filter of the measured joint torques before they are "
            "published [s] (the lbr stack's parameter of that name; 0: none)", 0.0, 10.0))
        p('echo', False, _describe('report the commanded position (a driver in open loop)'))
        p('guard_holds', False, _describe(
            "the driver's command guard sends the measured position in place of a command it "
            'refuses and the driver runs on, as lbr releases that log "Overriding invalid '
            'command to neutral command." do (false: it stops the driver, as releases that '
            'throw "Invalid command." do)'))
        p('speed_monitor', 0.0, _describe(
            "KUKA's Cartesian speed monitoring [m/s]: a point of the arm (URDF collision "
            'shapes, flange) faster stops it, as a safety stop ends the FRI session (T1 means '
            'to keep 0.25); 0: off', 0.0, 10.0))
        p('collision_torque', 0.0, _describe(
            "KUKA's collision detection [Nm]: an external torque above this at any joint stops "
            'it, as a safety stop ends the FRI session; 0: off', 0.0, 1000.0))
        p('enforce_command_limits', True, _describe(
            "the controller manager's joint limiter between JTC and the driver (the lbr "
            "stack's default): each period's command within the velocity limits of the last"))
        p('interpolate_from_desired_state', DEFAULT_JTC_START == 'desired', _describe(
            "joint_trajectory_controller's: start each new command from the last one (true) "
            'or from the measured state (false, its default)'))
        p('object_mass_error', 0.0, _describe('real minus assumed object mass [kg]',
                                              -5.0, 5.0))
        p('armature', PhysicsSettings().armature[0], _describe(
            "the motors' reflected inertia, every joint [kg m^2] (not published by KUKA)",
            0.0, 10.0))
        p('joint_friction', PhysicsSettings().joint_friction, _describe(
            'dry friction in every joint that the impedance law leaves [Nm] (the physics '
            'arm)', 0.0, 100.0))
        p('grasp_stiffness', PhysicsSettings().grasp_stiffness, _describe(
            'the grasp turns the object by torque / this [Nm/rad]; 0: the object is welded '
            'to the flange', 0.0, 1e5))
        p('stiffness', PhysicsSettings().stiffness[0], _describe(
            "the robot application's joint impedance stiffness, every joint [Nm/rad] (the lbr "
            "stack's: 200)", 1.0, 5000.0))
        p('damping_ratio', PhysicsSettings().damping_ratio, _describe(
            "the robot application's joint impedance damping ratio (Sunrise takes 0.1 to 1.0; "
            'its default 0.7)', 0.1, 1.0))
        p('sim_time', False, _describe('run on simulated time and publish /clock'))
        p('real_time_factor', DEFAULT_REAL_TIME_FACTOR, _describe(
            'with sim_time: speed over the wall clock (at most); 0: as fast as possible', 0.0,
            1000.0))
        clock = _describe("the arm's clock less the wall clock [s]: the clock its controller "
                          'and joint states run on, as on a second machine whose clock is not '
                          'synchronised; set while running, the clock steps', -1e6, 1e6)
        clock.read_only = False
        p('clock_offset', 0.0, clock)
        p('seed', 0, ParameterDescriptor(description='noise stream', read_only=True))
        p('joint_states_topic', JOINT_STATES_TOPIC, _describe('sensor_msgs/JointState out'))
        p('trajectory_topic', TRAJECTORY_TOPIC, _describe('trajectory_msgs/JointTrajectory in'))
        p('joint_names', list(JOINT_NAMES), _describe(
            'the 7 arm joints, in URDF order, as its joint states name them and its commands '
            'must (the lbr stack names them after robot_name)'))
        refuse_unknown_parameters(self)
        value = lambda name: self.get_parameter(name).value   # noqa: E731
        if value('engine') not in ENGINES:
            raise ValueError(f'engine must be one of {", ".join(ENGINES)}, '
                             f'got {value("engine")!r}')
        self.arm = iiwa_arm()
        self.joint_names = checked_joint_names(value('joint_names'))
        settings, physics = with_faults(
            {name: value(name) for name in FAULTS},
            RobotSettings(period=1.0 / value('rate'), echo=value('echo'), seed=value('seed'),
                          guard_holds=value('guard_holds'),
                          limiter=value('enforce_command_limits'),
                          torque_tau=value('measured_torque_tau'),
                          jtc_start='desired' if value('interpolate_from_desired_state')
                          else 'measured'))
        world = value('scene') if value('engine') == 'physics' else value('scenario')
        self.robot, self.description = build_robot(value('engine'), world, settings, physics)
        self.sim_time = bool(value('sim_time'))
        self.publish_velocities = bool(value('publish_velocities'))
        self.factor = float(value('real_time_factor'))
        # simulated time starts at the wall clock (its arm's: clock_offset), so stamps and
        # bags read as real dates
        self.epoch = time.time() + value('clock_offset')
        self.add_on_set_parameters_callback(self._on_parameters)
        self.wall_start = time.monotonic()
        self.ticking = False            # wall_start and epoch move to the first tick
        self.driver_down = False        # the command guard stopped the driver
        self.guard_trips = 0            # its trips said (guard_holds)
        self.pub = self.create_publisher(JointState, value('joint_states_topic'),
                                         qos_profile_sensor_data)
        self.clock_pub = self.create_publisher(Clock, '/clock', 10) if self.sim_time else None
        self.create_subscription(JointTrajectory, value('trajectory_topic'),
                                 self._on_trajectory, 10)
        self.create_service(Trigger, '~/restart_driver', self._on_restart_driver)
        scene = getattr(self.robot.engine, 'scene', None)
        if scene is not None:         # for RViz: what the planner cannot see
            latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self.scene_pub = self.create_publisher(MarkerArray, '~/scene', latched)
            self.scene_pub.publish(scene_markers(scene, self._stamp(self.robot.time)))
        self.period = settings.period
        # on simulated time one controller period per callback, so that a command arriving
        # in between is taken at the next update, as JTC takes it; the timer sets the speed
        fastest = 0.0005
        tick = self.period if not self.sim_time else (
            max(self.period / self.factor, fastest) if self.factor else fastest)
        self.create_timer(tick, self._tick)
        self.get_logger().info(f'mock iiwa ({value("engine")}): {self.description}' +
                               (' on simulated time' if self.sim_time else ''))

    def _on_parameters(self, params: list) -> SetParametersResult:
        """Step the arm's clock by a new clock_offset (an NTP step on the arm's computer)."""
        for param in params:
            if param.name == 'clock_offset':
                self.epoch += param.value - self.get_parameter('clock_offset').value
        return SetParametersResult(successful=True)

    def _on_restart_driver(self, _request: Trigger.Request, response: Trigger.Response
                           ) -> Trigger.Response:
        """Bring a stopped driver up again where the arm holds (the operator's restart)."""
        try:
            self.robot.restart()
        except RuntimeError as refused:
            response.success, response.message = False, str(refused)
            return response
        self.driver_down = False
        self.guard_trips = 0
        response.success = True
        response.message = f'driver restarted at {np.round(self.q, 3).tolist()}'
        self.get_logger().info(response.message)
        return response

    @property
    def q(self) -> np.ndarray:
        """Return where the simulated arm is (the truth, not the reported state)."""
        return self.robot.engine.q

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        try:
            command = command_from_msg(msg, self.joint_names)
        except ValueError as err:
            self.get_logger().error(f'trajectory refused: {err}')
            return
        # the node's clock counts from its epoch, the arm's from 0
        moved = moved_onto_clock(command, -self.epoch)
        if moved is None:
            self.get_logger().error('trajectory refused: stamped, it ends in the past')
            return
        # a starved mock first runs the periods it owes: JTC takes a message at its first
        # update after it arrives, on the wall clock; queued at the arm's lagging time, it
        # was taken up to CATCH_UP early, the arm ran ahead of the planner's model by that
        # much and, matching the raw command, read as an echoing driver (a CI failure)
        if not self.sim_time:
            self._catch_up()
        self.robot.command(moved)

    def _steps_due(self) -> int:
        """
        Return how many controller periods to run now (on wall time a late tick catches up).

        A real arm moves in real time however late the host's threads run, so a starved
        mock runs every period it owes (up to ``CATCH_UP`` seconds' worth per tick) instead
        of slowing its arm down: capped at ten, a 1 kHz mock ticking every 20 ms on a busy
        2-core machine ran at half speed and its states arrived ever later after their
        stamps.  Beyond ``CATCH_UP`` behind, it says so: this machine cannot run it in real time.
        """
        if self.sim_time:
            return 1
        if not self.ticking:
            # the arm's time starts at the first tick, not at the node's construction (what
            # ran between, a garbage collection of the start-up's heap among it, put the
            # first tick 0.1 s behind and said so at every demo)
            late = time.monotonic() - self.wall_start
            self.wall_start += late
            self.epoch += late
            self.ticking = True
        due = time.monotonic() - self.wall_start - self.robot.time
        most = round(CATCH_UP / self.period)
        if due > CATCH_UP + self.period:
            self.get_logger().warning(
                f'the simulated arm is {due:.2f} s behind the wall clock: this machine cannot '
                f'run it at {1.0 / self.period:.0f} Hz in real time (lower rate:=)',
                throttle_duration_sec=5.0)
        return int(np.clip(np.floor(due / self.period + 1e-9), 0, most))

    def _catch_up(self) -> int:
        """Run the controller periods due now (:meth:`_steps_due`); return how many."""
        steps = self._steps_due()
        for _ in range(steps):
            self.robot.step()
        return steps

    def _tick(self) -> None:
        steps = self._catch_up()
        if self.clock_pub is not None and steps:    # time goes on with the driver down too
            self.clock_pub.publish(Clock(clock=self._stamp(self.robot.time)))
        if self.robot.stopped is not None:
            if not self.driver_down:
                self.driver_down = True
                self.get_logger().error(f'the command guard stopped the driver: '
                                        f'{self.robot.stopped}; no more joint states')
            return
        if self.robot.guard_trips > self.guard_trips:
            self.guard_trips = self.robot.guard_trips
            self.get_logger().warning(f'the command guard overrode an invalid command with the '
                                      f'measured position: {self.robot.guard_trip}',
                                      throttle_duration_sec=1.0)
        if steps:
            self._publish(self.robot.joint_state())

    def _stamp(self, seconds: float) -> Time:
        nanoseconds = round((self.epoch + seconds) * 1e9)
        return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)

    def _publish(self, state: JointStateSample) -> None:
        msg = JointState()
        msg.header.stamp = self._stamp(state.time)
        msg.name = list(self.joint_names)
        msg.position = state.position.tolist()
        msg.velocity = state.velocity.tolist() if self.publish_velocities else []
        msg.effort = [] if state.effort is None else state.effort.tolist()
        self.pub.publish(msg)


def main(args: list[str] | None = None) -> int:
    """Run the mock iiwa node until SIGINT or SIGTERM."""
    return run_node('mock_iiwa', MockIiwa, args)


if __name__ == '__main__':
    sys.exit(main())
