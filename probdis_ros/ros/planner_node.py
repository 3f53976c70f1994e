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
``velocity_scaling`` x the URDF velocity limits; malformed or stale joint states stop the
run with a hold at the last good position; ``~/stop`` holds at once.  The failure map is
written atomically after every new failure and reloaded at start-up.
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict
import json
import os
from pathlib import Path
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from probdis_ros.model import FailureMap, FailureMapError, iiwa_arm
from probdis_ros.model.failure_map import write_document
from probdis_ros.motion.detector import DetectorSettings
from probdis_ros.motion.timing import hold_command
from probdis_ros.planning import Disentangler, Method, METHODS, RRTSettings, State
from probdis_ros.ros.markers import markers_msg
from probdis_ros.ros.messages import (
    BadJointStateError,
    joint_positions,
    joint_velocities,
    trajectory_msg,
)
from probdis_ros.ros.node_main import run_node
from probdis_ros.ros.recorder import BagRecorder
from probdis_ros.run import Learned, PlanFrom, Run, RunSettings, Send, StatusChanged
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

NODE_NAME = 'probdis_planner'
#: The defaults of the run and of its detector: the parameters below take theirs from here.
RUN, DETECT = RunSettings(), RunSettings().detection
RUN_FIELDS = ('velocity_scaling', 'acceleration_scaling', 'acceleration_limit', 'jerk_limit',
              'state_timeout', 'replan_tolerance')
DETECTOR_FIELDS = ('d_dist', 'stall_time', 'stall_motion', 'settle_time', 'motion_delay',
                   'gap_ceiling', 'joint_gap_ceiling', 'onset_gap', 'echo_time')


def _float(text: str, low: float, high: float) -> ParameterDescriptor:
    return ParameterDescriptor(description=text, floating_point_range=[
        FloatingPointRange(from_value=low, to_value=high)])


def _int(text: str, low: int, high: int) -> ParameterDescriptor:
    return ParameterDescriptor(description=text, integer_range=[
        IntegerRange(from_value=low, to_value=high)])


def default_map_file() -> str:
    """Return ``$ROS_HOME/probdis/failure_map.json`` (ROS_HOME defaults to ~/.ros)."""
    home = os.environ.get('ROS_HOME') or os.path.join(os.path.expanduser('~'), '.ros')
    return os.path.join(home, 'probdis', 'failure_map.json')


PARAMETERS = {
    'joint_states_topic': ('/lbr/joint_states', ParameterDescriptor(
        description='sensor_msgs/JointState in (sensor-data QoS)')),
    'trajectory_topic': ('/lbr/joint_trajectory_controller/joint_trajectory',
                         ParameterDescriptor(description='trajectory_msgs/JointTrajectory out')),
    'joint_names': ([f'lbr_A{i}' for i in range(1, 8)], ParameterDescriptor(
        description='the 7 arm joints, in URDF order (matched by name in joint states)')),
    'goal': ([0.0] * 7, ParameterDescriptor(
        description='goal configuration [rad], 7 values within the joint limits')),
    'velocity_scaling': (RUN.velocity_scaling, _float(
        'fraction of the URDF velocity limits', 0.01, 1.0)),
    'acceleration_scaling': (RUN.acceleration_scaling, _float(
        'fraction of the acceleration and jerk limits', 0.01, 1.0)),
    'acceleration_limit': (RUN.acceleration_limit, _float(
        'joint acceleration limit [rad/s^2] (the lbr stack MoveIt configuration)', 0.1, 100.0)),
    'jerk_limit': (RUN.jerk_limit, _float('joint jerk limit [rad/s^3]', 1.0, 10000.0)),
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
    'onset_gap': (DETECT.onset_gap, _float('a block began where the gap last rose above this '
                                           '[rad]', 0.001, 1.0)),
    'echo_time': (DETECT.echo_time, _float('seconds of lag-free motion that reveal a driver '
                                           'echoing the command; 0: off', 0.0, 10.0)),
    'replan_tolerance': (RUN.replan_tolerance, _float('L1 distance [rad] between the arm and '
                                                      "a plan's start above which it plans "
                                                      'again from the arm', 0.001, 1.0)),
    'goal_tolerance': (0.04, _float('joint-space distance to the goal that counts as reached',
                                    0.0, 1.0)),
    'state_timeout': (RUN.state_timeout, _float('joint states older than this stop the run '
                                                '[s]', 0.01, 10.0)),
    'max_paths': (20, _int('N_ITER: paths before giving up', 1, 1000)),
    'min_retreat': (0.1, _float('a retreat goes back along the way the arm came until this '
                                'far from the block [rad]; 0: to the last via point only',
                                0.0, 10.0)),
    'method': ('probabilistic', ParameterDescriptor(
        description='probabilistic | hard | epsilon')),
    'threshold': (0.01, _float('Y of the hard method', 0.0, 1.0)),
    'epsilon': (0.2, _float('X of the epsilon method', 0.0, 1.0)),
    'c_fail': (100.0, _float('C_FAIL [1/m^2]', 1e-3, 1e6)),
    'delta': (0.04, _float('Delta: edge discretisation [rad]', 1e-3, 1.0)),
    'length_weight': (0.01, _float('lambda: weight of joint-space length', 0.0, 10.0)),
    'iterations': (100, _int('K: iterations per tree', 1, 100000)),
    'n_random': (100, _int('|C_RAND|: samples per RandomConfiguration', 1, 100000)),
    'p_goal': (0.1, _float('P_GOAL', 0.0, 1.0)),
    'step': (1.0, _float('longest new tree edge [rad]', 0.01, 10.0)),
    # 0 until a budget is shown to disentangle better (README "Planning and simulation")
    'plan_time': (0.0, _float('anytime budget [s]: the trees keep growing in rounds of K '
                              'while it lasts; 0: one round of K (the paper)', 0.0, 60.0)),
    'seed': (0, _int('random seed of the planner', 0, 2**31 - 1)),
    'map_file': (default_map_file(), ParameterDescriptor(
        description='failure map file, written after every failure and read at start-up; '
                    'empty: keep the map in memory only')),
    'bag_dir': (os.path.join(os.path.dirname(default_map_file()), 'bags'), ParameterDescriptor(
        description='each run is recorded to a rosbag2 bag (MCAP) in this folder; '
                    'empty: no recording')),
    'orientation': (True, ParameterDescriptor(
        description='model the flange orientation in the failure map (3-D with orientation)')),
}


class PlannerNode(Node):
    """Disentangles on request, over the arm's topics."""

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        for name, (default, descriptor) in PARAMETERS.items():
            self.declare_parameter(name, default, descriptor)
        self.add_on_set_parameters_callback(self._check_parameters)
        self.use_sim_time = bool(self.get_parameter('use_sim_time').value)
        self.arm = iiwa_arm(with_orientation=bool(self.get_parameter('orientation').value))
        self.joint_names = list(self.get_parameter('joint_names').value)
        problem = self._goal_problem(self.get_parameter('goal').value)
        if len(self.joint_names) != 7:
            raise ValueError('joint_names must name 7 joints')
        if problem:
            self.get_logger().warning(f'goal parameter: {problem}; ~/start will refuse')
        self.fmap = self._load_map()
        self.planner = self._make_planner()   # loads the compiled kernels now, not at ~/start
        self.measured: np.ndarray | None = None
        self.measured_at = -np.inf
        self.run: Run | None = None
        self._ended_run: Run | None = None
        self.plan_future: Future | None = None
        self.worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='probdis_plan')
        self.io = ThreadPoolExecutor(max_workers=1, thread_name_prefix='probdis_io')
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
        self.create_subscription(JointState, self.get_parameter('joint_states_topic').value,
                                 self._on_joint_state, states_qos, raw=True)
        self.failure_pub = self.create_publisher(String, '~/failures', 10)
        self.recorder: BagRecorder | None = None
        self._sent: deque[float] = deque()     # when each own command was sent, to record it
        self.recorder_close_at: float | None = None
        self.bag_path = ''
        self._record_topics = [
            (self.get_parameter('joint_states_topic').value, JointState, None),
            (self.get_parameter('trajectory_topic').value, JointTrajectory, 100),
            (f'{self.get_fully_qualified_name()}/status', String, latched),
            (f'{self.get_fully_qualified_name()}/failures', String, 100)]
        for topic, msg_type, qos in self._record_topics[1:]:
            self.create_subscription(msg_type, topic,
                                     lambda data, info, t=topic: self._record(t, data, info),
                                     qos, raw=True)
        self.create_service(Trigger, '~/start', self._on_start)
        self.create_service(Trigger, '~/stop', self._on_stop)
        self.create_service(Trigger, '~/reset_map', self._on_reset_map)
        self.create_timer(0.01, self._tick)
        self.create_timer(1.0, self._publish_diagnostics)
        self._publish_status()
        self.get_logger().info(f'{NODE_NAME} ready: {len(self.fmap)} failures in the map')

    # -- parameters --------------------------------------------------------------------

    def _goal_problem(self, goal) -> str:
        goal = np.asarray(goal, dtype=float)
        if goal.shape != (7,):
            return f'needs 7 values, has {goal.size}'
        if not np.all(np.isfinite(goal)) or not self.arm.within_limits(goal)[0]:
            return 'outside the joint limits'
        return ''

    def _check_parameters(self, params) -> SetParametersResult:
        for param in params:
            if param.name == 'goal':
                problem = self._goal_problem(param.value)
                if problem:
                    return SetParametersResult(successful=False, reason=f'goal {problem}')
            if param.name == 'method' and param.value not in METHODS:
                return SetParametersResult(successful=False,
                                           reason=f'method must be one of {", ".join(METHODS)}')
            if param.name in ('joint_names', 'joint_states_topic', 'trajectory_topic',
                              'orientation') and hasattr(self, 'arm'):
                return SetParametersResult(successful=False,
                                           reason=f'{param.name} is fixed at start-up')
        return SetParametersResult(successful=True)

    # -- the failure map ---------------------------------------------------------------

    def _load_map(self) -> FailureMap:
        c_fail = float(self.get_parameter('c_fail').value)
        path = self.get_parameter('map_file').value
        if path and Path(path).exists():
            try:
                fmap = FailureMap.load(path)
                if fmap.task_space is self.arm.task_space:
                    return fmap
                self.get_logger().error(f'{path} is a {fmap.task_space.value} map; '
                                        f'starting with an empty one')
            except FailureMapError as err:
                self.get_logger().error(f'{err}; starting with an empty map')
        return FailureMap(self.arm.task_space, c_fail)

    def _save_map(self) -> Future | None:
        """Write the map in the I/O thread (a snapshot, in order), off the executor thread."""
        path = self.get_parameter('map_file').value
        if path:
            return self.io.submit(self._write_map, path, self.fmap.to_dict())
        return None

    def _write_map(self, path: str, doc: dict) -> None:
        try:
            write_document(path, doc)
        except OSError as err:
            self.get_logger().error(f'cannot write the failure map {path}: {err}')

    def _publish_markers(self, path: np.ndarray | None) -> None:
        """Build and publish the RViz markers in the I/O thread (they take milliseconds)."""
        fmap = FailureMap.from_dict(self.fmap.to_dict())
        self.io.submit(lambda: self.marker_pub.publish(
            markers_msg(self.arm, fmap, path, self.get_clock())))

    # -- services ----------------------------------------------------------------------

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _receive_time(self, info: dict) -> float:
        """
        Return when a message arrived [s], on the time base of the detector and the bag.

        On wall-clock time the DDS receive time (independent of how busy the executor is);
        with use_sim_time the node's clock, which the simulation's /clock drives.
        """
        received = info.get('received_timestamp')
        if received and not self.use_sim_time:
            return received * 1e-9
        return self._now()

    def _on_start(self, request, response):
        response.success, response.message = self._start()
        self.get_logger().info(f'start: {response.message}')
        return response

    def _start(self) -> tuple[bool, str]:
        if self.active:
            return False, 'a run is already active; call ~/stop first'
        if self.use_sim_time and self.get_clock().now().nanoseconds == 0:
            return False, 'use_sim_time is set but no /clock has arrived; is the simulation on?'
        age = self._now() - self.measured_at
        if self.measured is None or age > self.get_parameter('state_timeout').value:
            return False, 'no fresh joint state has arrived; is the arm (driver) running?'
        goal = self.get_parameter('goal').value
        problem = self._goal_problem(goal)
        if problem:
            return False, f'goal parameter {problem}'
        planner = self._make_planner()
        self.fmap.c_fail = float(self.get_parameter('c_fail').value)
        loop = Disentangler(self.arm, planner, np.asarray(goal, dtype=float), self.fmap,
                            max_paths=self.get_parameter('max_paths').value,
                            seed=self.get_parameter('seed').value,
                            goal_tolerance=self.get_parameter('goal_tolerance').value,
                            min_retreat=self.get_parameter('min_retreat').value)
        value = self.get_parameter
        detection = DetectorSettings(**{name: value(name).value for name in DETECTOR_FIELDS})
        settings = RunSettings(**{name: value(name).value for name in RUN_FIELDS},
                               detection=detection)
        self.run = Run(self.arm, loop, settings, clock=self._now)
        self._open_bag()
        self._guarded(self.run.start, self.measured_at, self.measured)
        return True, f'disentangling from {np.round(self.measured, 3).tolist()}'

    # -- recording -----------------------------------------------------------------------

    def _open_bag(self) -> None:
        self._close_bag()
        folder = self.get_parameter('bag_dir').value
        if not folder:
            return
        name = time.strftime('run_%Y%m%d_%H%M%S')
        path = Path(folder) / name
        suffix = 1
        while path.exists():
            suffix += 1
            path = Path(folder) / f'{name}_{suffix}'
        try:
            self.recorder = BagRecorder(path)
        except OSError as err:
            self.get_logger().error(f'cannot record to {path}: {err}')
            return
        for topic, msg_type, _ in self._record_topics:
            module = msg_type.__module__.split('.')[0]
            self.recorder.add_topic(topic, f'{module}/msg/{msg_type.__name__}')
        self.bag_path = str(path)

    def _record(self, topic: str, data: bytes, info: dict) -> None:
        """
        Store a message stamped on the detector's time base.

        That is its receive time, except for this node's own commands: they are stamped with
        the time the detector began to watch them, so that a replay judges them alike.
        """
        if self.recorder is None:
            return
        stamp = self._receive_time(info)
        if topic == self._record_topics[1][0] and self._sent:
            stamp = self._sent.popleft()
        self.recorder.write(topic, round(stamp * 1e9), data)

    def _close_bag(self) -> None:
        if self.recorder is not None:
            recorder, self.recorder = self.recorder, None
            recorder.close()
            message = f'recorded {recorder.count} messages to {recorder.path}'
            if self.context.ok():
                self.get_logger().info(message)
            else:                 # shutting down after SIGINT/SIGTERM: rosout is gone
                print(f'[{NODE_NAME}] {message}', file=sys.stderr)
        self.recorder_close_at = None

    def _make_planner(self):
        settings = RRTSettings(
            iterations=self.get_parameter('iterations').value,
            delta=self.get_parameter('delta').value,
            n_random=self.get_parameter('n_random').value,
            p_goal=self.get_parameter('p_goal').value, step=self.get_parameter('step').value,
            plan_time=self.get_parameter('plan_time').value)
        method = Method.from_parameters(self.get_parameter('method').value,
                                        self.get_parameter('threshold').value,
                                        self.get_parameter('epsilon').value)
        return method.planner(self.arm, settings, self.get_parameter('length_weight').value)

    def _on_stop(self, request, response):
        if not self.active:
            if self.measured is not None:
                self.traj_pub.publish(trajectory_msg(hold_command(self.measured),
                                                     self.joint_names))
            response.success, response.message = True, 'no run active; holding'
            return response
        self._guarded(self.run.stop, 'stopped on request')
        response.success, response.message = True, 'stopped; holding the measured position'
        return response

    def _on_reset_map(self, request, response):
        if self.active:
            response.success, response.message = False, 'a run is active; call ~/stop first'
            return response
        count = len(self.fmap)
        self.fmap.clear()
        written = self._save_map()
        if written is not None:
            written.result(timeout=10.0)   # "cleared" means cleared on disk too
        self._publish_status()
        response.success, response.message = True, f'cleared {count} failures'
        return response

    # -- the run: events into Run, its actions out ------------------------------------

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
                self.traj_pub.publish(trajectory_msg(action.command, self.joint_names))
                self._sent.append(action.at)
                if action.path is not None:
                    self._publish_markers(action.path)
            elif isinstance(action, PlanFrom):
                self.plan_future = self.worker.submit(run.loop.next_path, action.config)
            elif isinstance(action, Learned):
                self.failure_pub.publish(String(data=json.dumps(action.event)))
                self._save_map()
                self._publish_markers(None)
                self.get_logger().info(run.message)
            elif isinstance(action, StatusChanged):
                if not run.active:
                    self._ended()
                self._publish_status()

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
        self.get_logger().info(f'run ended: {self.run.outcome}: {self.run.message}')
        if self.recorder is not None:
            self.recorder_close_at = self._now() + 0.5
        if self.run.outcome in ('succeeded', 'gave_up'):
            if self.bag_path:
                self.io.submit(self._write_map, str(Path(self.bag_path) / 'failure_map.json'),
                               self.fmap.to_dict())
            self.fmap = FailureMap(self.arm.task_space, self.fmap.c_fail)
            self._save_map()

    def _tick(self) -> None:
        now = self._now()
        if self.recorder_close_at is not None and now >= self.recorder_close_at:
            self._close_bag()
        if self.run is None:
            return
        self._guarded(self.run.tick, now)
        if self.plan_future is not None and self.plan_future.done():
            future, self.plan_future = self.plan_future, None
            try:
                path = future.result()
            except Exception as err:   # a planner bug must not leave the arm moving
                self.get_logger().error(f'planning failed: {err!r}')
                self._guarded(self.run.plan_failed, err)
            else:
                self._guarded(self.run.on_plan, path)

    def _on_joint_state(self, data: bytes, info: dict) -> None:
        try:
            msg = deserialize_message(data, JointState)
        except Exception as err:   # undecodable bytes must not stop the node
            self._record(self._record_topics[0][0], data, info)
            self.get_logger().error(f'joint state undecodable: {err}', throttle_duration_sec=1.0)
            return
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        # on simulated time the stamp is the sample's time; the node's clock may already
        # have moved on when a busy executor gets to the message
        now = stamp if self.use_sim_time and stamp > 0 else self._receive_time(info)
        if self.recorder is not None:
            self.recorder.write(self._record_topics[0][0], round(now * 1e9), data)
        try:
            q = joint_positions(msg, self.joint_names)
        except BadJointStateError as err:
            self.get_logger().error(f'joint state refused: {err}',
                                    throttle_duration_sec=1.0)
            if self.run is not None:
                self._guarded(self.run.bad_joint_state, str(err))
            return
        self.measured, self.measured_at = q, now
        if self.run is not None:
            self._guarded(self.run.on_joint_state, now, q,
                          joint_velocities(msg, self.joint_names))

    def _guarded(self, event, *args) -> None:
        """Feed the run an event; a bug in it stops the run safely instead of the node."""
        try:
            event(*args)
        except Exception as err:        # the arm must never be left moving unsupervised
            self.get_logger().error(f'run failed: {err!r}; stopping the arm')
            self.run.actions.clear()
            self.run.finish(State.STOPPED, f'internal error: {err}')
        self._act()

    # -- reporting ---------------------------------------------------------------------

    def status(self) -> dict:
        """Return the status document published on ~/status."""
        if self.run is not None:
            status = {**self.run.status(), 'detection': asdict(self.run.settings.detection)}
        else:
            status = {'state': 'idle', 'paths': 0, 'last_plan_time_s': 0.0,
                      'last_replan_latency_s': None, 'replan_latencies_s': [],
                      'outcome': '', 'message': 'ready'}
        failures = status.get('failures', 0) if self.run is not None else len(self.fmap)
        return {**status, 'failures': failures, 'bag': self.bag_path}

    def _publish_status(self) -> None:
        self.status_pub.publish(String(data=json.dumps(self.status())))
        self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        status = self.status()
        level = DiagnosticStatus.OK
        if status['state'] in ('stopped', 'gave_up'):
            level = DiagnosticStatus.WARN
        diag = DiagnosticStatus(level=level, name=f'{NODE_NAME}: disentangling',
                                hardware_id='lbr_iiwa14', message=status['message'])
        diag.values = [KeyValue(key=k, value=str(v)) for k, v in status.items()
                       if k not in ('replan_latencies_s', 'detection')]
        msg = DiagnosticArray(status=[diag])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def destroy_node(self) -> None:
        """Close the bag and stop the worker thread with the node."""
        self._close_bag()
        self.worker.shutdown(wait=False, cancel_futures=True)
        self.io.shutdown(wait=True)     # the last map write finishes
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the planner node until SIGINT or SIGTERM (the bag is closed either way)."""
    return run_node(NODE_NAME, PlannerNode, args)


if __name__ == '__main__':
    sys.exit(main())
