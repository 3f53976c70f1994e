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
``probdis replay BAG --publish``: put a recording back on its topics with its timing.

Every message goes out as the bytes that were recorded (nothing is decoded, so any type the
ROS installation knows can be played) at its recorded time offset divided by ``rate``, so the
planner, RViz or a second recorder can be driven from a recording.  Publishers are reliable
and transient-local with a history of 100: that offer matches every subscriber, whatever
reliability and durability it asks for (the status topic is latched, joint states are not).
Topics whose type is not installed here are skipped with a note, like ``ros2 bag play`` does.

Commands to the arm (``trajectory_msgs/msg/JointTrajectory``) are left out unless asked for
(``commands``): every probdis bag holds them, and on the robot's computer
joint_trajectory_controller would execute them, moving the arm from wherever it is with no
one watching.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import importlib
import sys
import time

from probdis_ros.ros.bag_source import Bag
import rclpy
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: [s] waited once every topic has a subscriber: the publisher learns of a subscriber before
#: the subscriber has matched the publisher, and messages sent in between arrive later, repaired
#: in a burst out of their timing (seen: the first 0.3 s of a replay squeezed together)
MATCH_SETTLE = 0.5
#: The type of the commands to the arm, published only on request.
COMMAND_TYPE = 'trajectory_msgs/msg/JointTrajectory'


@dataclass
class PlayResult:
    """What was published: message count, skipped topics and why, wall time [s]."""

    published: int = 0
    skipped: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    damage: str | None = None
    interrupted: bool = False


def message_class(msgtype: str) -> type:
    """Return the installed Python class of e.g. 'sensor_msgs/msg/JointState'."""
    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def play(path: str, rate: float = 1.0, wait: float = 2.0, progress: bool = True,
         commands: bool = False) -> PlayResult:
    """
    Publish every message of the bag at ``path`` with its recorded timing scaled by ``rate``.

    Commands to the arm only with ``commands`` (never where a controller runs).

    Waits up to ``wait`` seconds for every topic to have a subscriber before the first
    message, then ``MATCH_SETTLE`` (so that a listener started just before gets the
    beginning, on time).
    """
    if not rate > 0:
        raise ValueError(f'--rate must be positive, not {rate}')
    result = PlayResult()
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('probdis_bag_player', context=context)
    try:
        with Bag(path) as bag:
            publishers = {}
            for topic, msgtype in sorted(bag.topics.items()):
                if msgtype == COMMAND_TYPE and not commands:
                    result.skipped[topic] = ('commands to the arm: left out, a controller '
                                             'would execute them')
                    continue
                try:
                    publishers[topic] = node.create_publisher(message_class(msgtype), topic, QOS)
                except (ImportError, AttributeError, ValueError) as err:
                    result.skipped[topic] = f'{msgtype} is not installed here ({err})'
            for topic, reason in result.skipped.items():
                print(f'probdis replay: skipping {topic}: {reason}', file=sys.stderr)
            deadline = time.monotonic() + wait
            while time.monotonic() < deadline and \
                    any(p.get_subscription_count() == 0 for p in publishers.values()):
                time.sleep(0.01)
            if publishers and all(p.get_subscription_count() for p in publishers.values()):
                time.sleep(MATCH_SETTLE)
            total = bag.count(publishers)
            start = time.monotonic()
            try:
                _publish_all(bag, publishers, rate, start, total, result, progress)
            except KeyboardInterrupt:
                result.interrupted = True
            result.damage = bag.damage
            for publisher in publishers.values():
                publisher.wait_for_all_acked(Duration(seconds=5.0))
            result.seconds = time.monotonic() - start
            if progress and result.published:
                print(f'\rpublished {result.published}/{total} messages', file=sys.stderr)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return result


def _publish_all(bag: Bag, publishers: dict, rate: float, start: float, total: int,
                 result: PlayResult, progress: bool) -> None:
    """Publish in recorded order, each message when its scaled time offset has come."""
    shown = start
    for message in bag.messages(publishers):
        due = start + (message.stamp_ns - bag.start_ns) * 1e-9 / rate
        pause = due - time.monotonic()
        if pause > 0:
            time.sleep(pause)
        publishers[message.topic].publish(message.raw)
        result.published += 1
        if progress and time.monotonic() - shown > 1.0:
            shown = time.monotonic()
            print(f'\rpublished {result.published}/{total} messages', end='',
                  file=sys.stderr, flush=True)
