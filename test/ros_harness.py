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
Real rclpy nodes in-process for tests: one context (and DDS domain) per test.

Nodes and an executor run in a background thread; the test drives them with a probe node
that publishes joint states and records what the planner commands and reports.
"""

from __future__ import annotations

import json
import os
import threading
import time

from conftest import next_domain
import numpy as np
from probdis_ros.ros.client import REPLY_MATCH
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
JOINTS = [f'lbr_A{i}' for i in range(1, 8)]


def wait_for(predicate, timeout: float = 10.0, what: str = 'condition') -> None:
    """Poll predicate until true; fail the test after timeout seconds."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout} s waiting for {what}')
        time.sleep(0.01)


class RosTest:
    """A context of its own, nodes spinning in a thread, a probe to talk to the planner."""

    def __init__(self) -> None:
        self.domain = next_domain()
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.domain)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes = []
        self._clients = {}
        self.probe = rclpy.create_node('probe', context=self.context)
        self.trajectories: list[tuple[float, JointTrajectory]] = []
        self.statuses: list[dict] = []
        self.probe.create_subscription(
            JointTrajectory, '/lbr/joint_trajectory_controller/joint_trajectory',
            lambda m: self.trajectories.append((time.monotonic(), m)), 10)
        latched = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.probe.create_subscription(String, '/probdis_planner/status',
                                       lambda m: self.statuses.append(json.loads(m.data)),
                                       latched)
        self.js_pub = self.probe.create_publisher(JointState, '/lbr/joint_states',
                                                  qos_profile_sensor_data)
        self.add(self.probe)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def add(self, node):
        """Spin a node (made with context=self.context)."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def publish_state(self, q, names=None, positions=None) -> None:
        """Publish one joint state (names/positions override for malformed ones)."""
        msg = JointState()
        msg.name = list(names if names is not None else JOINTS)
        msg.position = [float(v) for v in (positions if positions is not None else q)]
        self.js_pub.publish(msg)

    def call(self, service: str, timeout: float = 10.0) -> Trigger.Response:
        """
        Call a planner Trigger service (or one named in full, ``/node/name``) from the probe.

        One client per service, kept: a client is ready once it has found the server, but
        the server must also find the client's reply reader, and a reply it sends before
        that is lost (rmw: "failed to send response (timeout)", seen in CI under load: the
        call then waited out its timeout).  So whenever the server had to be waited for (a
        new client, or a planner started again), the call waits REPLY_MATCH longer, as
        probdis_ros.ros.client does.
        """
        client = self._clients.get(service)
        if client is None:
            name = service if service.startswith('/') else f'/probdis_planner/{service}'
            client = self._clients[service] = self.probe.create_client(Trigger, name)
        if not client.service_is_ready():
            wait_for(client.service_is_ready, timeout, f'service {service}')
            time.sleep(REPLY_MATCH)
        future = client.call_async(Trigger.Request())
        wait_for(future.done, timeout, f'answer of {service}')
        return future.result()

    @property
    def status(self) -> dict:
        """Return the latest status of the planner ({} before the first)."""
        return self.statuses[-1] if self.statuses else {}

    def positions_commanded(self) -> list[np.ndarray]:
        """Return every position of every trajectory the planner sent."""
        return [np.array(p.positions) for _, msg in self.trajectories for p in msg.points]

    def close(self) -> None:
        """Stop spinning, destroy the nodes, shut the context down."""
        self.executor.shutdown(timeout_sec=2.0)
        # spin returns once it sees the shutdown: no callback may be running when the nodes
        # go (rclpy's shutdown does not wait for one, ros2/rclpy#968)
        self.thread.join(timeout=5.0)
        for node in self.nodes:
            node.destroy_node()
        self.context.try_shutdown()
