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

It publishes joint states of ``lbr_A1``..``lbr_A7`` at ``rate`` Hz and follows
JointTrajectory commands the way joint_trajectory_controller does: a new message replaces
the current trajectory, which starts from the current state and is interpolated linearly;
joint speeds are capped at the URDF velocity limits.  The end-effector stops compliantly at
its first contact with the hidden obstacles of a scenario file (the same contact code as the
offline simulator) and stays there until a command moves it away.  Optional joint-state
noise and latency exercise the planner's detector.
"""

from __future__ import annotations

from collections import deque
import sys

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.resources import scenario_path
from probdis_ros.ros.messages import timed_path_from_msg
from probdis_ros.ros.node_main import run_node
from probdis_ros.sim.worlds import load_world
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

JOINTS = [f'lbr_A{i}' for i in range(1, 8)]


def _describe(text: str, low: float | None = None, high: float | None = None
              ) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(description=text)
    if low is not None:
        descriptor.floating_point_range = [FloatingPointRange(from_value=low, to_value=high)]
    return descriptor


class MockIiwa(Node):
    """The simulated arm."""

    def __init__(self, **kwargs) -> None:
        super().__init__('mock_iiwa', **kwargs)
        p = self.declare_parameter
        p('scenario', 'demo_iiwa', _describe('scenario file, or name in config/scenarios/'))
        p('rate', 100.0, _describe('joint-state rate [Hz]', 1.0, 2000.0))
        p('noise', 0.0, _describe('std. dev. of joint-state noise [rad]', 0.0, 0.1))
        p('latency', 0.0, _describe('delay of published joint states [s]', 0.0, 1.0))
        p('seed', 0)
        p('joint_states_topic', '/lbr/joint_states')
        p('trajectory_topic', '/lbr/joint_trajectory_controller/joint_trajectory')
        self.arm = iiwa_arm()
        self.world = load_world(scenario_path(self.get_parameter('scenario').value))
        if self.world.setting == '2d':
            raise ValueError('the mock iiwa needs a 3d or 3d-orient scenario')
        self.sim = self.world.compliant_arm()
        self.q = self.world.start.copy()
        self.sim.execute(np.array([self.q, self.q]))   # load the compiled FK now, not mid-run
        self.path = None
        self.path_start = 0.0
        self.blocked = False
        self.rng = np.random.default_rng(self.get_parameter('seed').value)
        self.outbox: deque[tuple[float, JointState]] = deque()
        self.pub = self.create_publisher(JointState, self.get_parameter(
            'joint_states_topic').value, qos_profile_sensor_data)
        self.create_subscription(JointTrajectory, self.get_parameter('trajectory_topic').value,
                                 self._on_trajectory, 10)
        self.dt = 1.0 / self.get_parameter('rate').value
        self.last_step = self._now()
        self.create_timer(self.dt, self._step)
        self.get_logger().info(f'mock iiwa: scenario {self.world.name or "?"} with '
                               f'{len(self.world.obstacles)} hidden obstacles')

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        try:
            path = timed_path_from_msg(msg, JOINTS, self.q, self.arm.lower, self.arm.upper)
        except ValueError as err:
            self.get_logger().error(f'trajectory refused: {err}')
            return
        self.path, self.path_start = path, self._now()

    def _step(self) -> None:
        now = self._now()
        elapsed, self.last_step = max(0.0, now - self.last_step), now
        if self.path is not None:
            target = self.path.at(now - self.path_start)
            reach = self.arm.velocity_limits * elapsed     # a late tick may move further
            step = np.clip(target - self.q, -reach, reach)
            if np.any(step != 0):
                run = self.sim.execute(np.array([self.q, self.q + step]))
                self.q = run.config
                if run.blocked:
                    self.path = None
            if self.path is not None and now - self.path_start > self.path.duration and \
                    np.allclose(self.q, self.path.points[-1]):
                self.path = None
        self._publish(now)

    def _publish(self, now: float) -> None:
        msg = JointState()
        msg.name = list(JOINTS)
        noise = self.get_parameter('noise').value
        q = self.q + (self.rng.normal(scale=noise, size=7) if noise > 0 else 0.0)
        msg.position = [float(v) for v in q]
        latency = self.get_parameter('latency').value
        self.outbox.append((now + latency, msg))
        while self.outbox and self.outbox[0][0] <= now:
            out = self.outbox.popleft()[1]
            out.header.stamp = self.get_clock().now().to_msg()
            self.pub.publish(out)


def main(args: list[str] | None = None) -> int:
    """Run the mock iiwa node until SIGINT or SIGTERM."""
    return run_node('mock_iiwa', MockIiwa, args)


if __name__ == '__main__':
    sys.exit(main())
