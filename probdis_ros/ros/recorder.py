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

What is written reaches the file within ``FLUSH_INTERVAL`` (and at every :meth:`flush`, which
the node calls on every command, failure and status change): the MCAP chunk in memory is
closed and handed to the operating system, so a recorder killed with SIGKILL leaves a bag
that ends at most that long before the kill (``probdis replay`` reads it up to there).

A write that fails (a full disk, a removed folder) never raises: the recording stops, the
file is closed as far as it can be, and :attr:`error` says why.

The file is written by a thread of the recorder's own: the node hands each message over and
returns at once, so a disk that hangs (a network home directory) never holds the executor
that supervises the arm; :meth:`close` waits for the writes at most ``CLOSE_WAIT``.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
import queue
import threading
import time

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
from rosbags.typesys.store import Typestore

#: Longest time a written message stays in memory before it reaches the file [s].
FLUSH_INTERVAL = 0.5
#: A planner's bag says so on its topic ``<node>/recording`` (written into the bag, never
#: published): its one message names the status topic of that planner.  A replay dates the
#: joint states of such a bag as the planner recorded them; another recorder's (``ros2 bag
#: record -a``, which records the planner's status too) holds receive times.
RECORDING_SUFFIX = '/recording'
#: Longest wait of :meth:`BagRecorder.close` for the writes handed over [s].
CLOSE_WAIT = 5.0


@cache
def message_types() -> Typestore:
    """
    Return ROS 2 Jazzy's message types, loaded once.

    The first call imports rosbags' type stores: 0.09 s here with the files in the page
    cache, 0.5 s after a reboot.  The planner node calls it at start-up: at the first
    ~/start, opening the bag must not hold the executor while the run starts (joint states
    queued behind it for 0.5 s tripped the state timeout at once, on a fresh clone).
    """
    return get_typestore(Stores.ROS2_JAZZY)


class BagRecorder:
    """One bag: add topics, write raw messages, flush, close; failures end up in error."""

    def __init__(self, path: str | Path, flush_interval: float = FLUSH_INTERVAL) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.typestore = message_types()
        self.writer: Writer | None = Writer(self.path, version=9,
                                            storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.connections = {}           # the writer thread's: topic -> connection
        self.topics: set[str] = set()   # the declared ones, known to the caller at once
        self.count = 0                  # messages written
        self.error = ''
        self.flush_interval = flush_interval
        self.flushed_at = time.monotonic()
        self.closed = False
        self._work: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._write_all, name='probdis_bag', daemon=True)
        self._thread.start()

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Declare a topic and its type (e.g. 'sensor_msgs/msg/JointState')."""
        if topic not in self.topics and not self.closed:
            self.topics.add(topic)
            self._work.put((self._add_connection, (topic, msgtype)))

    def write(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Store one serialized message of a declared topic (handed to the writer thread)."""
        if topic in self.topics and not self.closed and not self.error:
            self._work.put((self._write, (topic, stamp_ns, data)))
            if time.monotonic() - self.flushed_at >= self.flush_interval:
                self.flush()

    def flush(self) -> None:
        """Hand everything written so far to the operating system (closes the MCAP chunk)."""
        self.flushed_at = time.monotonic()
        if not self.closed:
            self._work.put((self._flush, ()))

    def close(self, wait: float = CLOSE_WAIT) -> None:
        """Write the metadata and close the bag (idempotent; a failure lands in error)."""
        if not self.closed:
            self.closed = True
            self._work.put((None, ()))
        self._thread.join(wait)
        if self._thread.is_alive() and not self.error:
            self.error = (f'recording to {self.path} did not finish within {wait:.0f} s '
                          f'(does the disk hang?)')

    def _write_all(self) -> None:
        """Carry out what was handed over, in order, until close (the writer thread)."""
        while True:
            action, args = self._work.get()
            if action is None:
                break
            if self.writer is not None:
                action(*args)
        if self.writer is not None:
            writer = self.writer
            if self._guard(writer.close):
                self.writer = None

    def _add_connection(self, topic: str, msgtype: str) -> None:
        self._guard(lambda: self.connections.__setitem__(topic, self.writer.add_connection(
            topic, msgtype, typestore=self.typestore)))

    def _write(self, topic: str, stamp_ns: int, data: bytes) -> None:
        if topic in self.connections and \
                self._guard(lambda: self.writer.write(self.connections[topic], stamp_ns, data)):
            self.count += 1

    def _flush(self) -> None:
        storage = getattr(self.writer, 'storage', None)
        chunk = getattr(storage, 'chunk', None)
        if storage is None or chunk is None:
            return

        def flush() -> None:
            if chunk.msgs:
                storage.close_chunk()
            storage.bio.flush()
        self._guard(flush)

    def _guard(self, action) -> bool:
        """Run a write; on failure stop recording, keep the reason, and return False."""
        try:
            action()
            return True
        except Exception as err:       # OSError (ENOSPC), rosbags' WriterError, ...
            if not self.error:
                self.error = f'recording to {self.path} failed: {err}'
            writer, self.writer = self.writer, None
            if writer is not None:
                try:
                    writer.abort()
                except Exception:      # the file may refuse even its close
                    pass
            return False
