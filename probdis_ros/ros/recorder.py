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
Recording runs as rosbag2 bags (MCAP, metadata version 9) with the rosbags library.

Messages are stored as the CDR bytes that arrived on the wire (raw subscriptions), which
every rosbag2 reader accepts.  The writer is closed (metadata written) by :meth:`close`;
the planner node closes it at the end of a run, on ~/stop and on SIGINT/SIGTERM.
"""

from __future__ import annotations

from pathlib import Path

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores


class BagRecorder:
    """One bag: add topics, write raw messages, close."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.typestore = get_typestore(Stores.ROS2_JAZZY)
        self.writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.connections = {}
        self.count = 0

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Declare a topic and its type (e.g. 'sensor_msgs/msg/JointState')."""
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(topic, msgtype,
                                                                 typestore=self.typestore)

    def write(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Store one serialized message of a declared topic."""
        if self.writer is not None:
            self.writer.write(self.connections[topic], stamp_ns, data)
            self.count += 1

    def close(self) -> None:
        """Write the metadata and close the bag (idempotent)."""
        if self.writer is not None:
            writer, self.writer = self.writer, None
            writer.close()
