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
planner_node: probabilistic disentangling over ROS 2 topics and services.

A thin adapter: joint states in, JointTrajectory commands out, the disentangling loop
(:class:`probdis_ros.planning.Disentangler`) and the blocked-motion detector
(:mod:`probdis_ros.motion.detector`) in between.  All node state lives in the executor thread;
planning runs in a worker thread so that joint states keep being read and checked while a
plan is computed, and its result is picked up by a timer.

Safety: every commanded position is inside the joint limits and timed within
``velocity_scaling`` x the URDF velocity limits; every joint state passes
:class:`~probdis_ros.motion.state_check.StateCheck` first, and one it refuses (malformed,
outside the limits, time running back, a jump) is logged, stops a run (decelerating from the
last accepted state) and refuses ``~/start`` for ``REFUSAL_HOLD`` seconds; stale joint states
stop the run; ``~/stop`` decelerates to rest.  A start is refused without a subscriber on the
trajectory topic (other than this node's recorder), or while the arm moves with no command
of this node running, and a run stops when the controller goes; a second node of this name
refuses to start.  With use_sim_time everything runs on the node's clock (/clock), and a
start is refused, a run stopped, while /clock does not advance (``CLOCK_STALL`` of wall
time: the tick runs on the wall clock); on wall time the node's time is the wall clock less
its steps (:mod:`probdis_ros.motion.host_clock`), and a step stops a run.  The failure map
is written atomically after every new failure and reloaded at start-up; a file that cannot
be read is copied aside, one that cannot be written is an error in the status and
diagnostics (the run goes on, the map in memory).
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import asdict, replace
import json
import math
import os
from pathlib import Path
import socket
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from probdis_ros.model import FailureMap, FailureMapError, iiwa_arm
from probdis_ros.model.arms import DRIVER_LIMIT_INSET
from probdis_ros.model.failure_map import (
    aside_path,
    DEFAULT_C_FAIL,
    lock_map,
    MapInUseError,
    set_aside,
    write_document,
)
from probdis_ros.model.path_cost import DEFAULT_LENGTH_WEIGHT
from probdis_ros.model.table import ROBOT_TABLE, Table
from probdis_ros.motion.detector import DetectorSettings, MotionWatch
from probdis_ros.motion.host_clock import HostClock
from probdis_ros.motion.state_check import BadJointStateError, StateCheck, values_by_name
from probdis_ros.planning import Disentangler, Method, RRTSettings, State
from probdis_ros.planning.disentangle import (
    DEFAULT_MAX_PATHS,
    DEFAULT_MIN_RETREAT,
    ROBOT_GOAL_TOLERANCE,
)
from probdis_ros.planning.epsilon import DEFAULT_EPSILON
from probdis_ros.planning.methods import DEFAULT_METHOD
from probdis_ros.planning.objectives import DEFAULT_THRESHOLD
from probdis_ros.planning.prob_rrt import planning_box, ROBOT_JOINT_MARGIN
from probdis_ros.planning.warm_up import warm_up
from probdis_ros.ros import (
    checked_joint_names,
    default_map_file,
    DETECTOR_FIELDS,
    JOINT_NAMES,
    JOINT_STATES_TOPIC,
    TRAJECTORY_TOPIC,
)
from probdis_ros.ros.controller_check import ControllerSetting
from probdis_ros.ros.markers import markers_msg
from probdis_ros.ros.messages import stamp_seconds, trajectory_msg
from probdis_ros.ros.node_main import refuse_unknown_parameters, run_node
from probdis_ros.ros.recorder import BagRecorder, message_types, RECORDING_SUFFIX
from probdis_ros.run import (
    goal_problem,
    Learned,
    MAX_VELOCITY_SCALING,
    MIN_VELOCITY_SCALING,
    PlanCancelledError,
    PlanFrom,
    Propose,
    rest_command,
    Run,
    RunSettings,
    scaling_warning,
    Send,
    StatusChanged,
    Withdrawn,
)
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

NODE_NAME = 'probdis_planner'
#: The defaults of the run and of its detector: the parameters below take theirs from here.
RUN, DETECT = RunSettings(), RunSettings().detection
RRT = RRTSettings()
#: JTC's path tolerance a joint needs at least: above its lag in free motion, this plus
#: this many seconds of its scaled velocity limit [rad, s] (JTC's error on a long free edge:
#: 0.070 rad at velocity scaling 0.2, 0.25 at 0.7; RESULTS "Velocity scaling: the driver's
#: guard and JTC's lag")
PATH_TOLERANCE_FLOOR, PATH_TOLERANCE_LAG = 0.15, 0.15
RUN_FIELDS = ('velocity_scaling', 'acceleration_scaling', 'acceleration_limit', 'jerk_limit',
              'state_timeout', 'replan_tolerance', 'cartesian_speed_limit', 'confirm_paths')
#: After a refused joint state, ~/start is refused for this long [s].
REFUSAL_HOLD = 1.0
#: How often the graph is checked: the trajectory topic's subscribers, namesakes [s].
GRAPH_CHECK = 0.5
#: A new planner refuses ~/start this long while a namesake shows in the graph: time to hear
#: the namesake's ``~/instance`` announcement (the younger of two leaves) [s].
DISCOVERY_WAIT = 3.0
#: With use_sim_time, a /clock that has not advanced for this long on the wall clock has
#: stopped: ~/start is refused and a run stops [s].
CLOCK_STALL = 2.0
#: [s] how long a node going down waits for the controller to confirm its stop (reliable DDS
#: confirms on the writer's heartbeat, every 3 s by default)
HALT_WAIT = 3.5
#: [s] a clock offset to the arm's beyond this is said (once) when a command is stamped
CLOCK_OFFSET_SAID = 0.05
#: [s] the node's timer period: it feeds the run the clock's ticks and watches the executor
TICK = 0.01
#: [s] an executor kept from running longer than this during a run is said: blocks are
#: detected that much later, and the arm presses on meanwhile (5 joint states at 100 Hz)
STALL_SAID = 0.05


def _float(text: str, low: float, high: float) -> ParameterDescriptor:
    return ParameterDescriptor(description=text, floating_point_range=[
        FloatingPointRange(from_value=low, to_value=high)])


def _int(text: str, low: int, high: int) -> ParameterDescriptor:
    return ParameterDescriptor(description=text, integer_range=[
        IntegerRange(from_value=low, to_value=high)])


#: The goal parameter's value until it is set (a double array, so that ros2 param set takes
#: one): a goal must be given, since a default would send the arm there (upright, all zeros)
UNSET_GOAL = [math.nan] * 7


#: joint_lower / joint_upper until set: every joint's limit
UNSET_RANGE = [math.nan] * 7


def _unset(goal) -> bool:
    """Tell whether a goal parameter's value is UNSET_GOAL (7 NaN)."""
    goal = np.asarray(goal, dtype=float)
    return goal.shape == (7,) and bool(np.all(np.isnan(goal)))


PARAMETERS = {
    'joint_states_topic': (JOINT_STATES_TOPIC, ParameterDescriptor(
        description='sensor_msgs/JointState in (sensor-data QoS)')),
    'trajectory_topic': (TRAJECTORY_TOPIC, ParameterDescriptor(
        description='trajectory_msgs/JointTrajectory out')),
    'joint_names': (list(JOINT_NAMES), ParameterDescriptor(
        description='the 7 arm joints, in URDF order (matched by name in joint states)')),
    'goal': (UNSET_GOAL, ParameterDescriptor(
        description='goal configuration [rad], 7 values within the joint limits (no default: '
                    '~/start refuses until it is set); read at ~/start: a run goes on to '
                    'the goal it started with')),
    'velocity_scaling': (RUN.velocity_scaling, _float(
        'fraction of the URDF velocity limits (faster than 0.7, the arm in joint impedance '
        "overshoots them and the driver's command guard stops it)", MIN_VELOCITY_SCALING,
        MAX_VELOCITY_SCALING)),
    'acceleration_scaling': (RUN.acceleration_scaling, _float(
        'fraction of the acceleration and jerk limits', 0.01, 1.0)),
    'acceleration_limit': (RUN.acceleration_limit, _float(
        'joint acceleration limit [rad/s^2] (the lbr stack MoveIt configuration)', 0.1, 100.0)),
    'jerk_limit': (RUN.jerk_limit, _float('joint jerk limit [rad/s^3]', 1.0, 10000.0)),
    'cartesian_speed_limit': (RUN.cartesian_speed_limit, _float(
        'fastest [m/s] any point of the arm (its URDF collision shapes, the ball of '
        "object_radius, the flange) moves on a path or retreat; in KUKA's T1 (250 mm/s) "
        'set 0.15 with gap_ceiling 0.15 and joint_gap_ceiling 0.08 (config/planner_t1.yaml); '
        '0: the joint limits only', 0.0, 10.0)),
    'confirm_paths': (RUN.confirm_paths, ParameterDescriptor(
        description='each planned path waits, the arm at rest, for ~/confirm_path (or '
                    '~/decline_path: plan another) before it is sent, and the status and '
                    "markers show it first (a first session in T1); retreats and stops don't "
                    'wait; read at ~/start')),
    'd_dist': (DETECT.d_dist, _float('L1 gap [rad] above which a stalled motion is blocked',
                                     0.001, 1.0)),
    'stall_time': (DETECT.stall_time, _float('time without progress that counts as stalled '
                                             '[s]', 0.02, 10.0)),
    'stall_motion': (DETECT.stall_motion, _float('L1 motion [rad] over stall_time below which '
                                                 'the arm has stalled', 1e-4, 1.0)),
    'settle_time': (DETECT.settle_time, _float('after the end, the gap must close within this '
                                               '[s]', 0.01, 10.0)),
    'motion_delay': (DETECT.motion_delay, _float('how far the arm lags its command [s]: the '
                                                 'detector compares with the command this '
                                                 'much earlier', 0.0, 1.0)),
    'gap_ceiling': (DETECT.gap_ceiling, _float('L1 gap [rad] that is a block at once (force '
                                               '~ stiffness x gap); 0: off', 0.0, 10.0)),
    'joint_gap_ceiling': (DETECT.joint_gap_ceiling, _float("one joint's gap [rad] that is a "
                                                           'block at once; 0: off', 0.0, 10.0)),
    'limit_room': (DETECT.limit_room, _float(
        'a joint pushed (off its command, toward its limit) to within this [rad] of its limit '
        'is a block at once; 0: off', 0.0, 0.5)),
    'onset_gap': (DETECT.onset_gap, _float('a block began where the gap last rose above this '
                                           '[rad]', 0.001, 1.0)),
    'echo_time': (DETECT.echo_time, _float('seconds of motion that follows the command as '
                                           'the driver sends it and reveals a driver echoing '
                                           'it; 0: off', 0.0, 10.0)),
    'driver_tau': (DETECT.driver_tau, _float("the time constant [s] of the driver's command "
                                             "filter (the lbr stack's joint_position_tau), "
                                             'for the echo test', 0.0, 1.0)),
    'torque_ceiling': (DETECT.torque_ceiling, _float(
        'external torque [Nm] at a joint (measured effort minus the gravity of arm and load) '
        'that is a block at once; needs efforts in the joint states; 0: off', 0.0, 500.0)),
    'load_mass': (DETECT.load_mass, _float('mass of the grasped load [kg], for the external '
                                           'torque estimate', 0.0, 30.0)),
    'load_com': (list(DETECT.load_com), ParameterDescriptor(
        description="the load's centre of mass [m] in the flange frame, 3 values")),
    'replan_tolerance': (RUN.replan_tolerance, _float('L1 distance [rad] between the arm and '
                                                      "a plan's start above which it plans "
                                                      'again from the arm', 0.001, 1.0)),
    'goal_tolerance': (ROBOT_GOAL_TOLERANCE, _float(
        'joint-space distance to the goal that counts as reached', 0.0, 1.0)),
    'state_timeout': (RUN.state_timeout, _float('joint states older than this stop the run '
                                                '[s]', 0.01, 10.0)),
    'max_paths': (DEFAULT_MAX_PATHS, _int('N_ITER: paths before giving up', 1, 1000)),
    'min_retreat': (DEFAULT_MIN_RETREAT, _float(
        'a retreat goes back along the way the arm came until this far from the block [rad]; '
        '0: to the last via point only', 0.0, 10.0)),
    'method': (DEFAULT_METHOD, ParameterDescriptor(
        description='informed (the method of the paper with 8x its iterations, probes '
                    'around the start, turning and, once a turned object was blocked, '
                    'straight, and failures that reach 0.5 m; informed:IDEAS with letters '
                    'of adfghij, e.g. informed:afh) | probabilistic (that of '
                    'the paper) | hard | epsilon (hard:Y, epsilon:X set their parameter)')),
    'threshold': (DEFAULT_THRESHOLD, _float('Y of the hard method', 0.0, 1.0)),
    'epsilon': (DEFAULT_EPSILON, _float('X of the epsilon method', 0.0, 1.0)),
    'c_fail': (DEFAULT_C_FAIL, _float('C_FAIL [1/m^2]', 1e-3, 1e6)),
    'delta': (RRT.delta, _float('Delta: edge discretisation [rad]', 1e-3, 1.0)),
    'length_weight': (DEFAULT_LENGTH_WEIGHT, _float('lambda: weight of joint-space length',
                                                    0.0, 10.0)),
    'iterations': (RRT.iterations, _int('K: iterations per tree', 1, 100000)),
    'n_random': (RRT.n_random, _int('|C_RAND|: samples per RandomConfiguration', 1, 100000)),
    'p_goal': (RRT.p_goal, _float('P_GOAL', 0.0, 1.0)),
    'step': (RRT.step, _float('longest new tree edge [rad]', 0.01, 10.0)),
    'joint_margin': (ROBOT_JOINT_MARGIN, _float(
        'distance [rad] that samples and via points keep from every joint limit', 0.0, 0.5)),
    'joint_lower': (UNSET_RANGE, ParameterDescriptor(
        description='the room of the cell: lowest position [rad] per joint that the planned '
                    'paths go to (7 values; NaN: the joint limit), e.g. A1 -1.5 with '
                    'joint_upper A1 1.5 keeps the arm in front of its base; the goal must lie '
                    'within')),
    'joint_upper': (UNSET_RANGE, ParameterDescriptor(
        description='highest position [rad] per joint that the planned paths go to (7 '
                    'values; NaN: the joint limit)')),
    # 0 until a budget is shown to disentangle better (README "Planning and simulation")
    'plan_time': (RRT.plan_time, _float(
        'anytime budget [s]: the trees keep growing in rounds of K while it lasts; 0: one '
        'round of K (the paper)', 0.0, 60.0)),
    'seed': (0, _int('random seed of the planner', 0, 2**31 - 1)),
    'map_file': (default_map_file(), ParameterDescriptor(
        description='failure map file, written after every failure and read at start-up; '
                    'empty: keep the map in memory only')),
    'bag_dir': (os.path.join(os.path.dirname(default_map_file()), 'bags'), ParameterDescriptor(
        description='each run is recorded to a rosbag2 bag (MCAP) in this folder; '
                    'empty: no recording')),
    'interpolate_from_desired_state': (RUN.jtc_start == 'desired', ParameterDescriptor(
        description="joint_trajectory_controller's parameter of that name, which this must "
                    'equal (checked through controller_node): true, JTC starts each new '
                    'command from its last one and the command never steps; false (the '
                    "controller's default), from the measured state, stepping back by the "
                    'lag')),
    'controller_node': ('/lbr/joint_trajectory_controller', ParameterDescriptor(
        description="the controller's node, whose interpolate_from_desired_state ~/start "
                    'checks; empty: not checked')),
    'orientation': (True, ParameterDescriptor(
        description='model the flange orientation in the failure map (3-D with orientation)')),
    'table': (True, ParameterDescriptor(
        description='the arm stands on a table: no plan takes any part of it (its URDF '
                    'collision shapes) or its tip below table_height + table_clearance; '
                    'false: no table is known (an arm on a wall or a ceiling)')),
    'table_height': (ROBOT_TABLE.height, _float(
        'height [m] of the table top in the base frame (lbr_link_0 stands on it at 0)',
        -5.0, 5.0)),
    'table_clearance': (ROBOT_TABLE.clearance, _float(
        'distance [m] every part of the arm keeps from the table top', 0.0, 1.0)),
    'object_radius': (0.0, _float(
        'radius [m] of a ball about the flange point (the tip) that holds the grasped '
        'object: the table check keeps it above the table too; 0: the point alone',
        0.0, 2.0)),
}


def full_path(path: str) -> str:
    """Return a file parameter's path with '~' expanded and absolute ('' stays '': none)."""
    return os.path.abspath(os.path.expanduser(path)) if path else ''


class PlannerNode(Node):
    """Disentangles on request, over the arm's topics."""

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.started = time.monotonic()
        self.namesake_heard = False
        for name, (default, descriptor) in PARAMETERS.items():
            self.declare_parameter(name, default, descriptor)
        refuse_unknown_parameters(self)
        self.add_on_set_parameters_callback(self._check_parameters)
        # '~' is no shell's here: map_file '~/...' was a folder named '~' in the working
        # directory, and the map learned on the arm was not the one the next start read
        self.set_parameters([Parameter(name, value=full_path(self.get_parameter(name).value))
                             for name in ('map_file', 'bag_dir')])
        self._run_settings()      # start-up values that do not go together: exit 2, named
        self.use_sim_time = bool(self.get_parameter('use_sim_time').value)
        self.arm = iiwa_arm(with_orientation=bool(self.get_parameter('orientation').value))
        # the object's ball is the arm's whether a table is known or not: the Cartesian speed
        # limit keeps its points too
        table = Table(self.get_parameter('table_height').value,
                      self.get_parameter('table_clearance').value) \
            if self.get_parameter('table').value else None
        self.arm = self.arm.on_table(table, self.get_parameter('object_radius').value)
        self.joint_names = checked_joint_names(self.get_parameter('joint_names').value)
        goal = self.get_parameter('goal').value
        problem = self._goal_problem(goal)
        if problem and not _unset(goal):
            raise ValueError(f'goal parameter: {problem}')     # exit 2, as any start-up value
        if problem:
            self.get_logger().warning(f'goal parameter {problem}; ~/start refuses until it is')
        # compile (or load) every kernel a run calls now, not at ~/start or at the first block,
        # where it would hold the executor for seconds while the retreat must be watched
        # (short plans do: the anytime budget only repeats the same kernels)
        self.get_logger().info('loading the planning kernels (the first start after an install '
                               'compiles them: 20-50 s on two cores)')
        compiling = time.perf_counter()
        warm_planner = self._make_planner(longest_plan=0.05)
        self._refuse_namesake()           # in this process: the graph is complete at once
        warm_up(self.arm, warm_planner, float(self.get_parameter('c_fail').value))
        message_types()                   # and the bag's, which the first ~/start opens
        self._refuse_namesake()           # another process's: discovery has had more time
        self.errors: dict[str, str] = {}      # recording: set and read in the executor thread
        self.map_error = ''                    # set by the I/O thread
        self.refusing = ''                     # joint states are being refused: the first why
        self.map_writable = True
        self.map_lock = self._lock_map()
        self.fmap = self._load_map()
        self.get_logger().info(
            f'planner kernels ready in {time.perf_counter() - compiling:.1f} s')
        self.state_check = StateCheck(self.joint_names, self.arm.lower, self.arm.upper,
                                      self.arm.velocity_limits,
                                      late=self.get_parameter('state_timeout').value)
        # the arm's motion while no run drives it (something else would be moving it)
        self.motion_watch = MotionWatch(self.get_parameter('stall_time').value)
        self.own_motion_until = -np.inf     # when this node's last command has run out
        # with use_sim_time: the last /clock and the wall time it last advanced (best effort,
        # as rclpy's own: it matches every /clock publisher, and holds the newest alone)
        self.sim_clock, self.sim_clock_advanced = 0, -np.inf
        # on wall time: the wall clock less its steps (an NTP step must not read as a late arm)
        self.host_clock = HostClock()
        self.host_steps_answered = 0    # its steps said in the log (and a run stopped)
        self.host_steps_dated = 0       # its steps before the last batch of joint states
        self.clock_sub = self.create_subscription(
            ClockMsg, '/clock', self._on_clock,
            QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)) \
            if self.use_sim_time else None
        self.measured: np.ndarray | None = None
        self.measured_velocity: np.ndarray | None = None
        self.measured_at = -np.inf
        self.run: Run | None = None
        self.run_stream = 0             # the joint-state stream the last run began on
        self.stall_max = 0.0          # [s] the longest the executor stalled in the run
        self.ticked_at = time.monotonic()
        self._ended_run: Run | None = None
        self.plan_future: Future | None = None
        self.io = ThreadPoolExecutor(max_workers=1, thread_name_prefix='probdis_io')
        self._graph_checked = -np.inf
        self.foreign_at, self.foreign = -np.inf, ''
        self._published_errors: list[str] = []
        self.traj_pub = self.create_publisher(
            JointTrajectory, self.get_parameter('trajectory_topic').value, 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.status_pub = self.create_publisher(String, '~/status', latched)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.marker_pub = self.create_publisher(MarkerArray, '~/markers', latched)
        # joint states arrive raw: the same bytes feed the detector and the bag, so a replay
        # sees exactly what the live planner saw (sensor-data QoS; a short queue keeps the
        # newest states first at 1 kHz instead of a growing backlog)
        states_qos = QoSProfile(depth=10, reliability=qos_profile_sensor_data.reliability,
                                durability=qos_profile_sensor_data.durability)
        self.states_sub = self.create_subscription(
            JointState, self.get_parameter('joint_states_topic').value, self._on_joint_state,
            states_qos, raw=True)
        self.failure_pub = self.create_publisher(String, '~/failures', 10)
        self.recorder: BagRecorder | None = None
        self._sent: deque[float] = deque()     # when each own command was sent, to record it
        self.recorder_close_at: float | None = None
        self.bag_path = ''
        self._record_topics = [
            (self.get_parameter('joint_states_topic').value, JointState, None),
            (self.get_parameter('trajectory_topic').value, JointTrajectory, 100),
            # a queue, not the latched depth of 1: two statuses in a row must both be kept
            (f'{self.get_fully_qualified_name()}/status', String,
             QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)),
            (f'{self.get_fully_qualified_name()}/failures', String, 100)]
        for topic, msg_type, qos in self._record_topics[1:]:
            self.create_subscription(msg_type, topic,
                                     lambda data, info, t=topic: self._record(t, data, info),
                                     qos, raw=True)
        # every planner announces itself on a latched topic its namesakes share: the younger
        # of two learns of the other there even when discovery was too slow for the check
        self.instance = {'pid': os.getpid(), 'host': socket.gethostname(),
                         'started_at': time.time()}
        self.create_subscription(String, '~/instance', self._on_instance, latched)
        self.create_publisher(String, '~/instance', latched).publish(
            String(data=json.dumps(self.instance)))
        self.controller_setting = ControllerSetting(
            self, self.get_parameter('controller_node').value, self.joint_names)
        self.controller_due = False       # a run started before the controller answered
        self.create_service(Trigger, '~/start', self._on_start)
        self.create_service(Trigger, '~/stop', self._on_stop)
        self.create_service(Trigger, '~/reset_map', self._on_reset_map)
        self.create_service(Trigger, '~/confirm_path', self._on_confirm_path)
        self.create_service(Trigger, '~/decline_path', self._on_decline_path)
        # on the wall clock: with use_sim_time the run's timeouts read the node's (simulated)
        # clock in the tick, and a /clock that stops must still be noticed
        self.create_timer(TICK, self._tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.create_timer(1.0, self._publish_diagnostics)
        self._publish_status()
        self._publish_markers(None)     # latched: RViz draws the map as it is, any time
        map_file = self.get_parameter('map_file').value
        self.get_logger().info(f'{NODE_NAME} ready: {len(self.fmap)} failures in the map'
                               + (f' ({map_file})' if map_file else ' (in memory only)'))

    def _refuse_namesake(self) -> None:
        """Raise ValueError (exit 2) if the graph shows a namesake, before the map is read."""
        namesake = self._namesake()
        if namesake:
            Node.destroy_node(self)
            raise ValueError(namesake + '; not starting a second one')

    def _namesake(self) -> str:
        """Return what is wrong when the graph shows another node of this name ('' if not)."""
        me = (self.get_name(), self.get_namespace())
        if self.get_node_names_and_namespaces().count(me) > 1:
            return (f'another node named {self.get_fully_qualified_name()} is running '
                    f'(it would share the services, the map and the bag folder)')
        return ''

    def _namesake_refusal(self) -> str:
        """
        Return why ~/start is refused for a namesake ('' if it is not).

        One that announced itself, or any in the graph while this node is new (its
        announcement may still come).  A namesake killed with SIGKILL stays in the graph for
        a while without announcing itself: it does not block a restarted planner for long.
        """
        namesake = self._namesake()
        if namesake and (self.namesake_heard or
                         time.monotonic() - self.started < DISCOVERY_WAIT):
            return namesake
        return ''

    def _on_instance(self, msg: String) -> None:
        """Leave (an error out of spin: exit 2) if an older namesake runs; else warn of it."""
        try:
            other = json.loads(msg.data)
            if not isinstance(other, dict):
                raise ValueError('not an object')
        except ValueError as err:       # someone else's message: not a reason to go
            self.get_logger().warning(f"ignored a message on ~/instance that is not a planner's "
                                      f'announcement ({err})', throttle_duration_sec=10.0)
            return
        if other == self.instance:
            return
        message = (f'another node named {self.get_fully_qualified_name()} is running '
                   f'(pid {other.get("pid")} on {other.get("host")})')
        if (other.get('started_at', 0.0), other.get('pid', 0)) < \
                (self.instance['started_at'], self.instance['pid']):
            if self.active:
                self._guarded(self.run.stop, message)
            raise ValueError(message + '; not starting a second one')
        self.namesake_heard = True
        self.get_logger().error(f'{message}: ~/start is refused while it runs')

    def _command_subscribers(self) -> int:
        """Return how many subscribers other than this node's recorder the commands have."""
        me = (self.get_name(), self.get_namespace())
        return sum((info.node_name, info.node_namespace) != me
                   for info in self.get_subscriptions_info_by_topic(self.traj_pub.topic_name))

    # -- parameters --------------------------------------------------------------------

    def _joint_range(self, changes: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
        """
        Return the planned paths' room per joint, (lower, upper), from the parameters.

        NaN stands for the joint's limit.  ValueError for a range that is not 7 values,
        outside the joint limits, or empty, also once ``joint_margin`` is kept from the
        limits (the planner's box, :func:`planning_box`, checked here, where it is set).
        """
        bounds = []
        for name, limit in (('joint_lower', self.arm.lower), ('joint_upper', self.arm.upper)):
            value = (changes or {}).get(name, self.get_parameter(name).value)
            value = np.asarray(value, dtype=float)
            if value.shape != (7,):
                raise ValueError(f'{name} needs 7 values, has {value.size}')
            bounds.append(np.where(np.isnan(value), limit, value))
        lower, upper = bounds
        for bound, name in ((lower, 'joint_lower'), (upper, 'joint_upper')):
            j = self.arm.joint_outside(bound)
            if j is not None:
                raise ValueError(f'{name}: {self.arm.joint_names[j]} at {bound[j]:.4g} rad is '
                                 f'outside its limits [{self.arm.lower[j]:.4f}, '
                                 f'{self.arm.upper[j]:.4f}]')
        if np.any(upper <= lower):
            j = int(np.argmax(lower - upper))
            raise ValueError(f'joint_lower {lower[j]:.4g} is not below joint_upper '
                             f'{upper[j]:.4g} for {self.arm.joint_names[j]}')
        margin = (changes or {}).get('joint_margin', self.get_parameter('joint_margin').value)
        planning_box(self.arm, RRTSettings(joint_margin=margin, joint_lower=tuple(lower),
                                           joint_upper=tuple(upper)))
        return lower, upper

    def _goal_problem(self, goal, changes: dict | None = None) -> str:
        """Return why goal is refused ('' if not), with the range parameters ``changes``."""
        goal = np.asarray(goal, dtype=float)
        if _unset(goal):
            return 'is not set: give the 7 joint positions [rad], -p goal:=[a1, ..., a7]'
        if goal.shape != (7,):
            return f'needs 7 values, has {goal.size}'
        outside = self.arm.limit_problem(goal)
        if outside:
            return outside
        lower, upper = self._joint_range(changes)
        outside = (goal < lower - 1e-9) | (goal > upper + 1e-9)
        if outside.any():
            j = int(np.argmax(outside))
            return (f'{self.arm.joint_names[j]} at {goal[j]:.4g} rad is outside '
                    f'[{lower[j]:.4g}, {upper[j]:.4g}] (joint_lower, joint_upper)')
        j = self.arm.joint_outside(goal, tol=-DRIVER_LIMIT_INSET)
        if j is not None:
            return (f'{self.arm.joint_names[j]} at {goal[j]:.6f} rad is outside the joint '
                    f'limits as KUKA has them (whole degrees, which the driver keeps): keep it '
                    f'{DRIVER_LIMIT_INSET:g} rad inside the URDF limits')
        margin = (changes or {}).get('joint_margin', self.get_parameter('joint_margin').value)
        return goal_problem(self.arm, goal, margin) or self.arm.table_problem(goal)

    def _run_settings(self, changes: dict | None = None) -> RunSettings:
        """
        Return the run's settings from the parameters (with ``changes`` on top).

        Raises ValueError for values that do not go together (gap_ceiling not above
        d_dist, a load_com without three coordinates): refused when set, not at ~/start.
        """
        values = {name: self.get_parameter(name).value for name in RUN_FIELDS + DETECTOR_FIELDS}
        values.update(changes or {})
        detection = DetectorSettings(**{name: values[name] for name in DETECTOR_FIELDS})
        desired = self.get_parameter('interpolate_from_desired_state').value
        return RunSettings(**{name: values[name] for name in RUN_FIELDS}, detection=detection,
                           jtc_start='desired' if desired else 'measured')

    def _check_parameters(self, params) -> SetParametersResult:
        changes = {p.name: p.value for p in params if p.name in RUN_FIELDS + DETECTOR_FIELDS}
        if changes:
            try:
                self._run_settings(changes)
            except (ValueError, TypeError) as err:
                return SetParametersResult(successful=False, reason=str(err))
        ranges = {p.name: p.value for p in params
                  if p.name in ('joint_lower', 'joint_upper', 'joint_margin')}
        if ranges and hasattr(self, 'arm'):
            try:
                self._joint_range(ranges)
            except ValueError as err:
                return SetParametersResult(successful=False, reason=str(err))
        method = {p.name: p.value for p in params if p.name in ('method', 'threshold', 'epsilon')}
        if method:       # the method as it would run: hard with threshold 0 plans nothing
            current = {name: self.get_parameter(name).value
                       for name in ('method', 'threshold', 'epsilon')}
            current.update(method)
            try:
                Method.for_node(str(current.pop('method')), **current)
            except ValueError as err:
                return SetParametersResult(successful=False, reason=f'method: {err}')
        sizes = {p.name: p.value for p in params if p.name in ('iterations', 'n_random', 'method')}
        if sizes and hasattr(self, 'arm'):     # (informed runs 8 K: with the method)
            try:
                self._make_planner(changes=sizes)
            except ValueError as err:
                return SetParametersResult(successful=False, reason=f'planner: {err}')
        for param in params:
            if param.name == 'goal':      # (with the range set in the same call)
                problem = self._goal_problem(param.value, ranges)
                if problem:
                    return SetParametersResult(successful=False, reason=f'goal {problem}')
            # use_sim_time too: switched during a run, the node's clock would read /clock's
            # (0 without a simulation) while the run's times are the wall clock's; and
            # map_file, read at start-up only: set later, the node's map overwrote that file
            if param.name in ('joint_names', 'joint_states_topic', 'trajectory_topic',
                              'orientation', 'table', 'table_height', 'table_clearance',
                              'object_radius', 'controller_node', 'use_sim_time',
                              'map_file') and hasattr(self, 'arm'):
                return SetParametersResult(successful=False,
                                           reason=f'{param.name} is fixed at start-up')
        return SetParametersResult(successful=True)

    # -- the failure map ---------------------------------------------------------------

    def _lock_map(self) -> int | None:
        """
        Hold map_file's lock for the node's life; raise ValueError (exit 2) if another holds it.

        Two planners in other namespaces or ROS domains share the default map_file: each
        wrote its own map over the other's.  Where no lock file can be made, the map is not
        writable there either: said at its first write.
        """
        path = self.get_parameter('map_file').value
        if not path:
            return None
        me = {'node': self.get_fully_qualified_name(), 'pid': os.getpid(),
              'host': socket.gethostname()}
        try:
            return lock_map(path, me)
        except OSError:
            return None
        except MapInUseError as err:
            other = err.holder
            Node.destroy_node(self)
            who = (f'another node named {other.get("node")} is running'
                   if other.get('node') == me['node'] else f'{other.get("node", "a planner")} '
                   f'uses it') + f' (pid {other.get("pid")} on {other.get("host")})'
            raise ValueError(f'map_file {path} is in use: {who}; give each arm its own '
                             f'map_file; not starting a second one') from None

    def _load_map(self) -> FailureMap:
        """
        Read map_file; one that cannot be used here is named in one line and kept aside.

        A file that is not a map, or a map of another task space, is copied beside itself
        (``set_aside``) before the first failure overwrites it; a path that is not a regular
        file, or a file that cannot be copied, is not written at all (an error in the status).
        """
        c_fail = float(self.get_parameter('c_fail').value)
        empty = FailureMap(self.arm.task_space, c_fail)
        path = self.get_parameter('map_file').value
        if not path or not os.path.lexists(path):
            return empty
        try:
            fmap = FailureMap.load(path)
        except FailureMapError as err:
            if not Path(path).is_file():
                return self._map_unusable(f'{err}; the map is kept in memory only')
            why, problem = 'unreadable', str(err)
        else:
            if fmap.task_space is self.arm.task_space:
                return fmap
            why = fmap.task_space.value
            problem = (f'{path} is a {fmap.task_space.value} map, this arm needs '
                       f'{self.arm.task_space.value}')
        try:
            copy = set_aside(path, why)
        except OSError as err:
            return self._map_unusable(f'{problem}; it cannot be copied aside ({err.strerror}), '
                                      f'so it is not overwritten: the map is kept in memory only')
        self.get_logger().error(f'{problem}; kept it as {copy}; starting with an empty map')
        return empty

    def _map_unusable(self, message: str) -> FailureMap:
        self.get_logger().error(message)
        self.map_error, self.map_writable = message, False
        return FailureMap(self.arm.task_space, float(self.get_parameter('c_fail').value))

    def _save_map(self) -> Future | None:
        """Write the map in the I/O thread (a snapshot, in order); the future says if it did."""
        path = self.get_parameter('map_file').value
        if not path:
            return None
        if not self.map_writable:
            done: Future = Future()
            done.set_result(False)
            return done
        return self.io.submit(self._write_map, path, self.fmap.to_dict())

    def _keep_finished_map(self, bag_path: str, doc: dict) -> None:
        """
        Keep a finished run's map beside its bag, then empty the map file (I/O thread).

        Without a bag (``bag_dir`` empty, or it could not be opened), or should that copy
        fail, beside the map file (``<name>.finished-<date>-<time>``): emptied regardless,
        the map of a run that gave up, the one most wanted, was kept nowhere.
        """
        path = self.get_parameter('map_file').value
        places = [str(Path(bag_path) / 'failure_map.json')] if bag_path else []
        if path and self.map_writable:
            places.append(str(aside_path(path, 'finished')))
        kept = next((place for place in places if self._write_map(place, doc, False)), None)
        if kept is None:
            if places:
                self.get_logger().error("the finished run's map could not be kept beside its "
                                        'bag or the map file; the map file keeps it until '
                                        'the next run writes it')
            return
        count = len(doc['failures'])
        self.get_logger().info(f"the finished run's {count} failure{'' if count == 1 else 's'} "
                               f'kept in {kept}; the map starts empty')
        if path and self.map_writable:
            self._write_map(path, FailureMap(self.arm.task_space, doc['c_fail']).to_dict())

    def _write_map(self, path: str, doc: dict, persist: bool = True) -> bool:
        """Write a map document; a failure is logged and, for map_file, kept in map_error."""
        try:
            write_document(path, doc)
        except OSError as err:
            message = f'cannot write the failure map {path}: {err}'
            self.get_logger().error(message)
            if persist:
                self.map_error = message + ' (the map is kept in memory)'
            return False
        if persist:
            self.map_error = ''
        return True

    def _publish_markers(self, path: np.ndarray | None) -> None:
        """Build and publish the RViz markers in the I/O thread (they take milliseconds)."""
        fmap = self.fmap.copy()         # in O(1): this runs before a block's retreat is sent
        # coloured as the running planner prices the map (Epsilon has no objective)
        objective = getattr(self.run.loop.planner, 'objective', None) if self.run else None
        reach = objective.terms().reach if objective is not None else math.inf
        self.io.submit(lambda: self.marker_pub.publish(
            markers_msg(self.arm, fmap, path, self.get_clock(), reach=reach)))

    # -- services ----------------------------------------------------------------------

    def _now(self) -> float:
        """
        Return the node's time [s]; on simulated time the newest /clock DDS has received.

        A busy executor falls behind on /clock as on the joint states; a command timed by an
        old /clock began, for the detector, before the arm's time it was sent at (a fast path
        then read as not executed), and before a state already taken (measured at its stamp)
        in the recording (a replay fed it to the command): so never before that state either.
        """
        if not self.use_sim_time:
            return self.host_clock.now()
        now = self.get_clock().now().nanoseconds * 1e-9
        self._take_waiting_clock()
        now = max(now, self.sim_clock * 1e-9)
        if 0.0 < self.measured_at - now <= self.get_parameter('state_timeout').value:
            return self.measured_at
        return now

    def _take_waiting_clock(self) -> None:
        """
        Take a /clock that DDS holds and the executor has not yet handed to its callback.

        An executor kept from running (a plan holding the GIL, a loaded machine) resumes
        with the /clock it took last, while the simulation has run on: a command timed by
        that clock began, for the detector, up to that long before the arm took it (a fast
        path read as not executed).  DDS keeps receiving meanwhile; its newest is the time.
        """
        for msg, _ in _waiting(self.clock_sub):
            self._on_clock(msg)

    def _receive_time(self, info: dict) -> float:
        """
        Return when a message arrived [s], on the time base of the detector and the bag.

        On wall-clock time the DDS receive time (independent of how busy the executor is),
        less the steps of this host's clock (:mod:`probdis_ros.motion.host_clock`); with
        use_sim_time the node's clock, which the simulation's /clock drives.
        """
        received = info.get('received_timestamp')
        if received and not self.use_sim_time:
            return self.host_clock.receipt(received * 1e-9)
        return self._now()

    def _on_clock(self, msg: ClockMsg) -> None:
        nanoseconds = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        if nanoseconds > self.sim_clock:
            self.sim_clock, self.sim_clock_advanced = nanoseconds, time.monotonic()

    def _clock_problem(self) -> str:
        """Return why the simulated clock cannot drive a run ('' if it can, or on wall time)."""
        if not self.use_sim_time:
            return ''
        if self.get_clock().now().nanoseconds == 0 or not self.sim_clock:
            return 'use_sim_time is set but no /clock has arrived; is the simulation on?'
        stalled = time.monotonic() - self.sim_clock_advanced
        if stalled > CLOCK_STALL:
            return (f'use_sim_time is set but /clock has not advanced for {stalled:.1f} s; is '
                    f'the simulation paused or gone?')
        return ''

    def _sent_command(self, at: float, command) -> None:
        """Note a command sent at ``at``: the arm may move until it has run out, and settled."""
        self._sent.append(at)
        self.own_motion_until = at + float(command.times[-1]) + \
            self.get_parameter('motion_delay').value + self.get_parameter('settle_time').value

    def _on_start(self, request, response):
        response.success, response.message = self._start()
        self.get_logger().info(f'start: {response.message}')
        return response

    def _start(self) -> tuple[bool, str]:
        if self.active:
            return False, 'a run is already active; call ~/stop first'
        self._host_clock_stepped()
        clock = self._clock_problem()
        if clock:
            return False, clock
        namesake = self._namesake_refusal()
        if namesake:
            return False, namesake
        now = self._now()
        self.state_check.late = self.get_parameter('state_timeout').value
        refused = self.state_check.refused_within(now, REFUSAL_HOLD)
        if refused:
            return False, (f'joint states were refused {now - self.state_check.refused_at:.1f} s '
                           f'ago ({refused}); not starting')
        age = now - self.measured_at
        if self.measured is None or age > self.get_parameter('state_timeout').value:
            return False, (f'no fresh joint state has arrived on '
                           f'{self.get_parameter("joint_states_topic").value}; is the arm '
                           f'(driver) running?')
        if not self._command_subscribers():
            return False, (f'nothing subscribes to {self.traj_pub.topic_name}: no controller '
                           f'would execute the commands; is joint_trajectory_controller active?')
        publishers = self._other_publishers()
        if publishers:
            return False, (f'{", ".join(publishers)} also publishes on '
                           f'{self.traj_pub.topic_name}: its commands would be taken for ours')
        if now - self.foreign_at <= REFUSAL_HOLD:
            return False, f'{self.foreign} {now - self.foreign_at:.1f} s ago; not starting'
        moving = self.motion_watch.moving(now, self.get_parameter('stall_motion').value)
        own = now <= self.own_motion_until      # the arm may still run this node's command
        if moving and not own:
            window = self.motion_watch.window
            return False, (f'the arm is moving ({moving:.3f} rad in the last {window:.1f} s) '
                           f'though this planner commands nothing: something else drives it; '
                           f'not starting')
        goal = self.get_parameter('goal').value
        problem = self._goal_problem(goal)
        if problem:
            return False, f'goal parameter {problem}'
        desired = bool(self.get_parameter('interpolate_from_desired_state').value)
        refusal = self.controller_setting.refusal(desired)
        if refusal:
            return False, refusal
        unchecked = ''
        # a start moments after the node came up: the controller is checked once it answers
        self.controller_due = self.controller_setting.value is None and \
            self.controller_setting.first_answer_due()
        if self.controller_setting.value is None and not self.controller_due:
            unchecked = self._controller_unknown(desired)
            self.get_logger().warning(unchecked)
        checked_later = (f'; {self.controller_setting.controller_node} has not answered yet '
                         '(this planner came up moments ago): the run stops if it starts '
                         'commands elsewhere than modelled' if self.controller_due else '')
        scaled = self.arm.velocity_limits * self.get_parameter('velocity_scaling').value
        tight = self.controller_setting.below_lag(dict(zip(
            self.joint_names, PATH_TOLERANCE_FLOOR + PATH_TOLERANCE_LAG * scaled)))
        if tight and not desired:
            lag = (f"joint_trajectory_controller's path tolerance leaves no room for the arm's "
                   f'lag in free motion at this velocity_scaling ({tight} rad): where JTC '
                   f'holds mid-path, the path reads as blocked (README, "Pointing it at the '
                   f'real arm")')
            self.get_logger().warning(lag)
            unchecked = '; '.join(filter(None, (unchecked, lag)))
        fast = scaling_warning(self.get_parameter('velocity_scaling').value)
        if fast:
            self.get_logger().warning(fast)
            unchecked = '; '.join(filter(None, (unchecked, fast)))
        planner = self._make_planner()
        self.fmap.c_fail = float(self.get_parameter('c_fail').value)
        loop = Disentangler(self.arm, planner, np.asarray(goal, dtype=float), self.fmap,
                            max_paths=self.get_parameter('max_paths').value,
                            seed=self.get_parameter('seed').value,
                            goal_tolerance=self.get_parameter('goal_tolerance').value,
                            min_retreat=self.get_parameter('min_retreat').value)
        settings = self._run_settings()
        # the last command, where the arm may still run it; with a desired start always: JTC
        # holds it and starts the next command from it.  Unless the joint states went silent
        # since that run began (a new stream): the driver was restarted (after a safety stop,
        # say), and a controller that comes up again holds the measured position
        same_driver = self._same_driver()
        keep = self.run is not None and same_driver and (own or settings.jtc_start == 'desired')
        running = self.run.trajectory if keep else None
        running_sent_at = self.run.sent_at if keep else None
        self.run_stream = self.state_check.streams
        self.run = Run(self.arm, loop, settings, clock=self._now)
        self.stall_max = 0.0
        self.plan_future = None
        self._open_bag()
        start = self.measured.copy()
        self._guarded(self.run.start, self.measured_at, start, self.measured_velocity, running,
                      running_sent_at)
        if self.run.outcome == 'succeeded':
            return True, f'already at the goal ({np.round(start, 3).tolist()}): nothing to do'
        started = f'disentangling from {np.round(start, 3).tolist()}{checked_later}'
        return True, f'{started}; warning: {unchecked}' if unchecked else started

    # -- recording -----------------------------------------------------------------------

    def _open_bag(self) -> None:
        self._close_bag()
        folder = full_path(self.get_parameter('bag_dir').value)     # it may be set between runs
        if not folder:
            return
        name = time.strftime('run_%Y%m%d_%H%M%S')
        path, suffix = Path(folder) / name, 1
        self.bag_path = ''
        self.errors.pop('recording', None)
        for _ in range(10):       # another recorder may take the same name meanwhile
            while os.path.lexists(path):
                suffix += 1
                path = Path(folder) / f'{name}_{suffix}'
            try:
                recorder = BagRecorder(path)
                break
            except Exception as err:    # OSError, rosbags' WriterError: never the node
                if os.path.lexists(path):
                    continue            # taken meanwhile: the next name
                self._recording_failed(f'cannot record to {path}: {err}')
                return
        else:
            self._recording_failed(f'cannot record to {path}: the name is taken')
            return
        for topic, msg_type, _ in self._record_topics:
            module = msg_type.__module__.split('.')[0]
            recorder.add_topic(topic, f'{module}/msg/{msg_type.__name__}')
        marker = f'{self.get_fully_qualified_name()}{RECORDING_SUFFIX}'
        recorder.add_topic(marker, 'std_msgs/msg/String')
        recorder.write(marker, round(self._now() * 1e9), serialize_message(String(
            data=json.dumps({'status': self._record_topics[2][0]}))))
        self.recorder, self.bag_path = recorder, str(path)
        self._check_recorder()

    def _recording_failed(self, message: str) -> None:
        """Stop recording; the run goes on (supervising the arm matters more), the user told."""
        self.errors['recording'] = f'{message}; the run goes on unrecorded'
        self.get_logger().error(self.errors['recording'])
        self._publish_status()

    def _check_recorder(self) -> None:
        recorder = self.recorder
        if recorder is not None and recorder.error:
            self.recorder = None
            self.recorder_close_at = None
            self._recording_failed(recorder.error)

    def _write_bag(self, topic: str, stamp_ns: int, data: bytes) -> None:
        if self.recorder is not None:
            self.recorder.write(topic, stamp_ns, data)
            self._check_recorder()

    def _record(self, topic: str, data: bytes, info: dict) -> None:
        """
        Store a message stamped on the detector's time base.

        That is its receive time, except for this node's own commands: they are stamped with
        the time the detector began to watch them, so that a replay judges them alike.
        """
        stamp = self._receive_time(info)
        if topic == self._record_topics[1][0]:
            if self._sent:
                stamp = self._sent.popleft()
            else:
                self._foreign_command(stamp)
        self._write_bag(topic, round(stamp * 1e9), data)

    def _foreign_command(self, now: float) -> None:
        """Another node commanded the arm: stop the run (its motion is no block to learn)."""
        publishers = self._other_publishers()
        self.foreign_at = now
        self.foreign = (f'a command on {self.traj_pub.topic_name} that this node did not send'
                        + (f' (from {", ".join(publishers)})' if publishers else ''))
        self.get_logger().error(self.foreign, throttle_duration_sec=1.0)
        if self.active:
            self._guarded(self.run.stop, f'{self.foreign}; stopped, nothing learned from it')

    def _other_publishers(self) -> list[str]:
        """Return the nodes other than this one that publish on the trajectory topic."""
        me = (self.get_name(), self.get_namespace())
        return sorted({f'{info.node_namespace.rstrip("/")}/{info.node_name}'
                       for info in self.get_publishers_info_by_topic(self.traj_pub.topic_name)
                       if (info.node_name, info.node_namespace) != me})

    def _close_bag(self) -> None:
        if self.recorder is not None:
            recorder, self.recorder = self.recorder, None
            recorder.close()
            if recorder.error:
                self.errors['recording'] = recorder.error
                message = recorder.error
            else:
                message = f'recorded {recorder.count} messages to {recorder.path}'
            if self.context.ok():
                self.get_logger().info(message)
            else:                 # shutting down after SIGINT/SIGTERM: rosout is gone
                print(f'[{NODE_NAME}] {message}', file=sys.stderr)
        self.recorder_close_at = None

    def _make_planner(self, longest_plan: float | None = None, changes: dict | None = None):
        """
        Return the planner the parameters ask for (its budget capped at longest_plan [s]).

        changes: parameters about to be set, in place of theirs (a check before they are);
        ValueError if the planner cannot be built from them.
        """
        def value(name: str):
            return (changes or {}).get(name, self.get_parameter(name).value)

        plan_time = value('plan_time')
        if longest_plan is not None:
            plan_time = min(plan_time, longest_plan)
        settings = RRTSettings(
            iterations=value('iterations'), delta=value('delta'), n_random=value('n_random'),
            p_goal=value('p_goal'), step=value('step'), plan_time=plan_time,
            joint_margin=value('joint_margin'),
            **dict(zip(('joint_lower', 'joint_upper'),
                       (tuple(bound.tolist()) for bound in self._joint_range(changes)))))
        method = Method.for_node(value('method'), value('threshold'), value('epsilon'))
        return method.planner(self.arm, settings, value('length_weight'))

    def _same_driver(self) -> bool:
        """Tell whether the joint states are still the stream the last run began on."""
        return self.state_check.streams == self.run_stream

    def _on_stop(self, request, response):
        """
        Stop the run and its planning; the arm decelerates to rest, whatever it was doing.

        Without a run (or after one), only from a fresh joint state: the arm may have been
        moved since, and a stop built from an old one would pull it back there.
        """
        was_active = self.active
        self._host_clock_stepped()          # a step seen now stops the run itself
        if was_active:
            if self.active:
                self._guarded(self.run.stop, 'stopped on request')
            response.success, response.message = True, 'stopped; decelerating to rest'
            return response
        fresh = self._now() - self.measured_at <= self.get_parameter('state_timeout').value
        # the ended run knows what JTC runs, unless the driver was restarted since (a new
        # joint-state stream): a controller that comes up again holds the measured position,
        # and a stop from the run's last command would jump the arm back there
        if fresh and self.run is not None and self._same_driver():
            self._guarded(self.run.stop, 'stopped on request')
        elif fresh:
            settings = self._run_settings()
            command = rest_command(self.arm, settings.limits(self.arm), self.measured,
                                   self.measured_velocity)
            self.traj_pub.publish(self._trajectory_msg(command))
            self._sent_command(self._now(), command)
        response.success, response.message = True, (
            'no run active; decelerating to rest' if fresh else
            'no run active and no fresh joint state: nothing commanded')
        return response

    def _on_confirm_path(self, request, response):
        """Send the path that awaits confirmation (confirm_paths)."""
        return self._answer_proposal(response, 'confirm')

    def _on_decline_path(self, request, response):
        """Drop the path that awaits confirmation and plan another (confirm_paths)."""
        return self._answer_proposal(response, 'decline')

    def _answer_proposal(self, response, answer: str):
        run = self.run
        if run is None:
            response.success, response.message = False, 'no path awaits confirmation'
            return response
        self._host_clock_stepped()
        answers: list[str] = []
        self._guarded(lambda now: answers.append(getattr(run, answer)(now)), self._now())
        response.success = answers == ['']          # '' : done; else why not
        response.message = answers[0] if answers and answers[0] else run.message
        return response

    def _on_reset_map(self, request, response):
        if self.active:
            response.success, response.message = False, 'a run is active; call ~/stop first'
            return response
        count, kept = len(self.fmap), self.fmap.copy()
        self.fmap.clear()
        written = self._save_map()
        # "cleared" means cleared on disk too; if not, nothing changes, in memory either
        problem = ''
        try:
            if written is not None and not written.result(timeout=10.0):
                problem = self.map_error or 'the map file cannot be written'
        except FutureTimeout:                # a hung disk: not cleared, and the node lives
            problem = 'the map file was not written within 10 s'
        if problem:
            self.fmap = kept
            response.success, response.message = False, (
                f'not cleared: {problem}; the map keeps its {count} failures')
        else:
            response.success, response.message = True, f'cleared {count} failures'
            self._publish_markers(None)
        self._publish_status()
        return response

    # -- the run: events into Run, its actions out ------------------------------------

    def _trajectory_msg(self, command) -> JointTrajectory:
        """
        Return a command's message; a stamped one (a desired start's) on the arm's clock.

        JTC runs a stamped message from its stamp on the controller manager's clock, the
        clock that stamps the arm's joint states, while the run stamps with this node's
        time: on two machines whose clocks disagree by more than a stamped message's
        horizon (1 s), a stop would be dropped as past, or waited for as future.  The state
        check knows the offset (the quickest delivery of the joint states), so the stamp is
        moved by it: the same instant on the arm's clock, early by the shortest delivery.
        """
        if command.stamp > 0 and self.state_check.refused_within(self._now(), REFUSAL_HOLD):
            # the states just refused may be a clock that stepped: with the old offset a
            # stamped stop could land in JTC's past and be dropped, the path running on
            self.get_logger().warning('joint states refused: this command goes unstamped, '
                                      'taken when it arrives')
            command = replace(command, stamp=0.0)
        if command.stamp > 0:
            offset = self.state_check.clock_offset
            if self.state_check.last_stamp <= 0:
                self.get_logger().warning(
                    "the arm's joint states carry no stamps: stamped commands are stamped on "
                    "this node's clock, which JTC's must agree with (synchronise the two "
                    'clocks)', once=True)
            elif abs(offset) > CLOCK_OFFSET_SAID:
                stepped = ''
                if self.host_clock.count:    # the same clock, off by what this node left out
                    stepped = (f" (this host's clock stepped {self.host_clock.steps:+.3f} s "
                               f"since this node started; this node's time goes on without it)")
                self.get_logger().warning(
                    f"the arm's clock reads {-offset:+.3f} s from this node's (by its joint "
                    f"states' stamps){stepped}: stamped commands are moved onto the arm's clock "
                    f'(synchronise the two clocks)', once=True)
            command = replace(command, stamp=command.stamp - offset)
        return trajectory_msg(command, self.joint_names, self.arm.lower, self.arm.upper)

    @property
    def active(self) -> bool:
        """Tell whether a disentangling run is in progress."""
        return self.run is not None and self.run.active

    def _act(self) -> None:
        """Carry out what the run asks for, in order."""
        run = self.run
        while run is not None and run.actions:
            action = run.actions.pop(0)
            if isinstance(action, Send):
                self.traj_pub.publish(self._trajectory_msg(action.command))
                self._sent_command(action.at, action.command)
                if action.path is not None:
                    self._publish_markers(action.path)
            elif isinstance(action, PlanFrom):
                self.plan_future = _in_thread(run.loop.next_path, action.config)
            elif isinstance(action, Propose):
                self._publish_markers(action.path)
                self.get_logger().info(run.message)
            elif isinstance(action, Withdrawn):
                self._publish_markers(None)     # no longer drawn as if it were to run
            elif isinstance(action, Learned):
                self.failure_pub.publish(String(data=json.dumps(action.event)))
                self._save_map()
                self._publish_markers(None)
                self.get_logger().info(run.message)
            elif isinstance(action, StatusChanged):
                if not run.active:
                    self.plan_future = None     # cancelled by the run; its result is dropped
                    self._ended()
                self._publish_status()
            if self.recorder is not None:
                self.recorder.flush()           # commands, failures, status: on disk now
                self._check_recorder()

    def _ended(self) -> None:
        """
        Log a run's end, close its bag a little later (the last status and the stop).

        A finished run (succeeded, gave up) leaves its map beside its bag and the next run
        starts from an empty one, as the paper's loop does; an interrupted one (~/stop, a
        fault, a crash) keeps the map, and the next ~/start resumes with it.
        """
        if self._ended_run is self.run:
            return
        self._ended_run = self.run
        peak = self.run.torque_peak
        pressed = '' if peak is None else (
            f' (peak external torque {peak.max():.1f} Nm at A{int(peak.argmax()) + 1}, '
            f'efforts less gravity and dynamics)')
        self.get_logger().info(f'run ended: {self.run.outcome}: {self.run.message}{pressed}')
        late, delay = self.run.late_take_max, self.get_parameter('motion_delay').value
        if late > 0.0:      # the detector shifts commands begun more than LATE_TAKE late
            self.get_logger().warning(
                f'commands of this run began up to {late:.2f} s later than motion_delay '
                f'({delay:g} s) expects: JTC took them late, or the arm lags its commands more '
                f'than motion_delay (measure it on a free move: probdis replay BAG '
                f'--calibrate); a lag beyond motion_delay + speed_allowance reads as a block '
                f'as a path ends')
        if self.recorder is not None:
            self.recorder_close_at = self._now() + 0.5
        if self.run.outcome in ('succeeded', 'gave_up'):
            finished = self.fmap.to_dict()
            self.fmap = FailureMap(self.arm.task_space, self.fmap.c_fail)
            self.io.submit(self._keep_finished_map, self.bag_path, finished)
            self._publish_markers(None)

    def _controller_unknown(self, desired: bool) -> str:
        return (f"could not read joint_trajectory_controller's interpolate_from_desired_state "
                f'({self.controller_setting.problem}): make sure it is '
                f'{str(desired).lower()}, as this planner models it')

    def _check_controller_late(self) -> None:
        """Check a run started before the controller's first answer, once it is in."""
        setting = self.controller_setting
        if not self.controller_due or (setting.first_answer_due() and setting.value is None):
            return
        self.controller_due = False
        desired = self.run is not None and self.run.settings.jtc_start == 'desired'
        refusal = setting.refusal(desired).removesuffix('; not starting')
        if refusal and self.active:
            self._guarded(self.run.stop, f'{refusal}: the run started before it answered; '
                          'stopped')
        elif setting.value is None:
            self.get_logger().warning(self._controller_unknown(desired))

    def _host_clock_stepped(self) -> None:
        """
        Answer a step of this host's wall clock seen since the last one answered.

        The node's time goes on without the step (:mod:`probdis_ros.motion.host_clock`), which
        is right for a driver on another computer.  One on this computer stamps its states by
        the stepped clock, and its controller may jump along its command by the step, which
        nothing here models: the joint states begin a new stream (their offset learnt anew),
        noted as a refusal (commands go unstamped for REFUSAL_HOLD, a start waits as long),
        and a run stops, decelerating from where the arm is, learning nothing of the step.
        """
        if self.use_sim_time:
            return
        now = self.host_clock.now()
        if self.host_clock.count == self.host_steps_answered:
            return
        self.host_steps_answered = self.host_clock.count
        step = f"this host's clock stepped {self.host_clock.last_step:+.3f} s"
        self.get_logger().warning(f"{step} (an NTP step?): this node's time goes on without "
                                  f'it; synchronise the clocks before a run')
        self.state_check.restart(now, f'{step}: a new stream')
        if self.active:
            self._guarded(self.run.stop, f'{step}; stopped (nothing learned of it)')

    def _tick(self) -> None:
        self._note_stall()
        self._host_clock_stepped()
        now = self._now()
        if self.recorder_close_at is not None and now >= self.recorder_close_at:
            self._close_bag()
        recorder = self.recorder
        if recorder is not None and time.monotonic() - recorder.flushed_at >= \
                recorder.flush_interval:
            recorder.flush()
            self._check_recorder()
        if self.refusing and not self.state_check.refused_within(now, REFUSAL_HOLD):
            self.refusing = ''        # a second without a refused joint state ends the spell
        if self._errors() != self._published_errors:      # e.g. from the I/O thread
            self._publish_status()
        if time.monotonic() - self._graph_checked >= GRAPH_CHECK:
            self._check_graph()
        self.controller_setting.poll()
        self._check_controller_late()
        if self.run is None:
            return
        clock = self._clock_problem() if self.active else ''
        if clock:
            self._guarded(self.run.stop, f'{clock}; stopped')
        self._guarded(self.run.tick, now)
        if self.plan_future is not None and self.plan_future.done():
            future, self.plan_future = self.plan_future, None
            try:
                path = future.result()
            except PlanCancelledError:
                return
            except Exception as err:   # a planner bug must not leave the arm moving
                self.get_logger().error(f'planning failed: {err!r}')
                self._guarded(self.run.plan_failed, err)
            else:
                self._guarded(self.run.on_plan, path)

    def _note_stall(self) -> None:
        """
        Keep the longest the executor was kept from running during the run, and say it.

        The timer runs every TICK on the wall clock unless something holds the executor (a
        loaded machine, a long callback): the joint states wait meanwhile, and every block
        is detected that much later while the arm presses on.
        """
        ticked_at, self.ticked_at = self.ticked_at, time.monotonic()
        stall = self.ticked_at - ticked_at - TICK
        if not self.active:
            return
        self.stall_max = max(self.stall_max, stall)
        if stall > STALL_SAID:
            self.get_logger().warning(
                f'this node could not run for {stall:.3f} s: joint states waited, and a block '
                f'is detected that much later while the arm presses on (is this machine '
                f'overloaded?)', throttle_duration_sec=5.0)

    def _check_graph(self) -> None:
        """Stop a run whose commands nobody executes; warn of a namesake once."""
        self._graph_checked = time.monotonic()
        if not self._namesake():
            self.namesake_heard = False       # it has gone
        if self.active and not self._command_subscribers():
            self._guarded(self.run.stop, f'nothing subscribes to {self.traj_pub.topic_name} '
                                         f'any more: the controller is gone; stopped')
        publishers = self._other_publishers() if self.active else []
        if publishers:
            self._guarded(self.run.stop, f'{", ".join(publishers)} also publishes on '
                                         f'{self.traj_pub.topic_name}; stopped')

    def _on_joint_state(self, data: bytes, info: dict) -> None:
        """
        Take a joint state and those already waiting behind it, oldest first.

        An executor kept from running resumes with a queue of states: each is judged at its
        own time, and a block seen in one is answered from the newest (``Run.on_joint_state``),
        where the arm is by now.  The first batch after a step of this host's clock may hold
        states received on either side of it: they are dated as taken, at a time read before
        the queue is emptied, so that no later state is dated before them.
        """
        self._host_clock_stepped()
        across = self.host_clock.count != self.host_steps_dated
        self.host_steps_dated = self.host_clock.count
        taken = self._now() if across else None
        batch = [(data, info), *_waiting(self.states_sub)]
        for k, (data, info) in enumerate(batch):
            self._take_joint_state(data, info, newest=k == len(batch) - 1, taken=taken)

    def _take_joint_state(self, data: bytes, info: dict, newest: bool,
                          taken: float | None = None) -> None:
        """Take one joint state; received at ``taken`` if given, else by its receipt."""
        try:
            msg = deserialize_message(data, JointState)
        except Exception as err:   # undecodable bytes must not stop the node
            self._record(self._record_topics[0][0], data, info)
            now = self._receive_time(info) if taken is None else taken
            self.state_check.refuse(now, f'undecodable: {err}')
            self._refused(f'undecodable: {err}')
            return
        stamp = stamp_seconds(msg)
        # on simulated time the stamp is the sample's time; the node's clock may already
        # have moved on when a busy executor gets to the message
        received = stamp if self.use_sim_time and stamp > 0 else \
            self._receive_time(info) if taken is None else taken
        try:
            q, v = self.state_check.check(
                received, msg.name, msg.position, msg.velocity, stamp,
                sequence=info.get('publication_sequence_number') or 0,
                clock=self._now() if self.use_sim_time and self.sim_clock else None)
        except BadJointStateError as err:
            self._write_bag(self._record_topics[0][0], round(received * 1e9), data)
            self._refused(str(err))
            return
        # dated by its stamp on wall time too: arrival jitters when threads starve
        now = self.state_check.measured_at(received, stamp)
        self._write_bag(self._record_topics[0][0], round(now * 1e9), data)
        self.measured, self.measured_velocity, self.measured_at = q, v, now
        self.motion_watch.add(now, q)
        if self.run is not None:
            effort = values_by_name(msg.name, msg.effort, self.joint_names)
            self._guarded(self.run.on_joint_state, now, q, v, effort, newest)

    def _refused(self, reason: str) -> None:
        """Log a refused joint state; a run stops, decelerating from the last accepted one."""
        self.get_logger().error(f'joint state refused: {reason}', throttle_duration_sec=1.0)
        if not self.refusing:         # the first reason of a spell (the values in it vary)
            self.refusing = f'joint states refused: {reason}'
        if self.run is not None:
            self._guarded(self.run.bad_joint_state, reason)

    def _guarded(self, event, *args) -> None:
        """Feed the run an event; a bug in it stops the run safely instead of the node."""
        try:
            event(*args)
        except Exception as err:        # the arm must never be left moving unsupervised
            self.get_logger().error(f'run failed: {err!r}; stopping the arm')
            # nothing half made is sent; but a failure learned before the error is kept (it
            # is in the map already: written only at the next failure, or never)
            self.run.actions[:] = [a for a in self.run.actions if isinstance(a, Learned)]
            self.run.finish(State.STOPPED, f'internal error: {err}')
        self._act()

    # -- reporting ---------------------------------------------------------------------

    def status(self) -> dict:
        """Return the status document published on ~/status."""
        if self.run is not None:
            status = {**self.run.status(), 'detection': asdict(self.run.settings.detection),
                      'jtc_start': self.run.settings.jtc_start,
                      'cartesian_speed_limit': self.run.settings.cartesian_speed_limit}
        else:
            status = {'state': 'idle', 'paths': 0, 'last_plan_time_s': 0.0,
                      'last_replan_latency_s': None, 'replan_latencies_s': [],
                      'outcome': '', 'message': 'ready'}
        failures = status.get('failures', 0) if self.run is not None else len(self.fmap)
        return {**status, 'failures': failures, 'executor_stall_max_s': self.stall_max,
                'bag': self.bag_path, 'errors': self._errors()}

    def _errors(self) -> list[str]:
        """Return the faults in effect: recording, map persistence, refused joint states."""
        return [e for e in (self.errors.get('recording', ''), self.map_error, self.refusing)
                if e]

    def _publish_status(self) -> None:
        self._published_errors = self._errors()
        self.status_pub.publish(String(data=json.dumps(self.status())))
        self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        status = self.status()
        level = DiagnosticStatus.OK
        if status['state'] in ('stopped', 'gave_up'):
            level = DiagnosticStatus.WARN
        message = status['message']
        if status['errors']:
            level = DiagnosticStatus.ERROR
            message = '; '.join([message, *status['errors']])
        diag = DiagnosticStatus(level=level, name=f'{NODE_NAME}: disentangling',
                                hardware_id='lbr_iiwa14', message=message)
        diag.values = [KeyValue(key=k, value=str(v)) for k, v in status.items()
                       if k not in ('replan_latencies_s', 'detection', 'proposed_path')]
        msg = DiagnosticArray(status=[diag])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def halt(self, reason: str) -> None:
        """
        Stop a run before the node goes (SIGINT, SIGTERM, an error): decelerate to rest.

        Waits (up to HALT_WAIT) until the controller has the stop: a process that exits at
        once may take an unsent message with it, and JTC would run the rest of the path.
        """
        if not self.active:
            return
        self._host_clock_stepped()          # a step seen now stops it, its stop unstamped
        if self.active:
            self.get_logger().warning(f'{reason}: stopping the run')
            self._guarded(self.run.stop, reason)
        if not self.traj_pub.wait_for_all_acked(Duration(seconds=HALT_WAIT)):
            self.get_logger().error(f'the stop was not acknowledged within {HALT_WAIT} s')

    def destroy_node(self) -> None:
        """Close the bag, cancel planning (its thread is a daemon), finish the map writes."""
        self._close_bag()
        if self.run is not None and self.run.active:
            self.run.loop.planner.cancel()
        self.io.shutdown(wait=True)     # the last map write finishes
        if getattr(self, 'map_lock', None) is not None:
            os.close(self.map_lock)
            self.map_lock = None
        super().destroy_node()


def _waiting(subscription) -> list[tuple]:
    """Take the (message, info) pairs DDS holds that the executor has not handed over yet."""
    waiting = []
    try:
        with subscription.handle:
            while (taken := subscription.handle.take_message(subscription.msg_type,
                                                             subscription.raw)):
                waiting.append(taken)
    except InvalidHandle:       # the node is being destroyed
        pass
    return waiting


def _in_thread(function, *args) -> Future:
    """
    Run function(*args) in a daemon thread of its own; return its future.

    A plan abandoned by ~/stop runs on in its thread without delaying the next run's
    planning, and does not keep the process alive after SIGINT.
    """
    future: Future = Future()

    def work() -> None:
        if not future.set_running_or_notify_cancel():
            return
        try:
            future.set_result(function(*args))
        except BaseException as err:    # handed to the executor thread
            future.set_exception(err)
    threading.Thread(target=work, name='probdis_plan', daemon=True).start()
    return future


def main(args: list[str] | None = None) -> int:
    """Run the planner node until SIGINT or SIGTERM (the bag is closed either way)."""
    return run_node(NODE_NAME, PlannerNode, args)


if __name__ == '__main__':
    sys.exit(main())
