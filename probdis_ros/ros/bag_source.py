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
Reading any rosbag2 bag for replay and publishing, damaged MCAP files included.

Healthy bags (a bag folder, or a bare ``.mcap`` / ``.db3`` file; MCAP or sqlite3; metadata
v8 or v9; written by probdis, ``ros2 bag record`` or the ``mcap`` libraries) are read by
rosbags.  Types come from the bag's own definitions, one by one, over the Jazzy standard types:
a topic whose type is unknown or whose definition is broken only matters if it is read.

An MCAP file that rosbags refuses because it ends early or is corrupt (a recorder killed
without closing it, a copy cut short) is scanned record by record instead: the messages before
the damage are returned and :attr:`Bag.damage` says where the readable part ends.  No rclpy.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
import re
import struct

from rosbags.rosbag2 import Reader
from rosbags.rosbag2.storage_mcap import decompress
from rosbags.typesys import get_types_from_msg, get_typestore, Stores

MCAP_MAGIC = b'\x89MCAP0\r\n'


class BagError(Exception):
    """A path that is not a readable bag, or a message that cannot be decoded."""


@dataclass(frozen=True)
class BagMessage:
    """One stored message: topic, type, receive time [ns] and serialized (CDR) bytes."""

    topic: str
    msgtype: str
    stamp_ns: int
    raw: bytes


class Bag:
    """An open bag: its topics and types, its messages in time order, and a decoder."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'{self.path}: no such bag')
        self.damage: str | None = None      # where a damaged file stopped being readable
        self.notice: str | None = None      # a file read whole despite a broken index
        self._reader: Reader | None = None
        self._salvaged: list[BagMessage] = []
        self._typestore = get_typestore(Stores.ROS2_JAZZY)
        definitions: dict[str, tuple[str, str]] = {}
        try:
            reader = Reader(self.path)
            reader.open()
        except Exception as err:     # rosbags raises several types for a non-bag
            files = _mcap_files(self.path)
            if not files and self.path.is_dir() and \
                    not (self.path / 'metadata.yaml').exists():
                # rosbags' own message names the folder as the missing metadata file
                raise BagError(f'{self.path}: not a readable rosbag2 bag (a folder without '
                               f'metadata.yaml or an .mcap file)') from None
            if not files:
                raise BagError(f'{self.path}: not a readable rosbag2 bag ({err})') from None
            self._salvage(files, definitions, err)
        else:
            self._reader = reader
            self.topics = {c.topic: c.msgtype for c in reader.connections}
            self.start_ns = reader.start_time if reader.message_count else 0
            definitions = {c.msgtype: (c.msgdef.format.name, c.msgdef.data)
                           for c in reader.connections}
        self._register(definitions)

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """Yield the messages of ``topics`` (all when None) in receive-time order."""
        wanted = set(self.topics if topics is None else topics)
        if self._reader is None:
            yield from (m for m in self._salvaged if m.topic in wanted)
            return
        connections = [c for c in self._reader.connections if c.topic in wanted]
        if not connections:        # rosbags reads an empty selection as every message
            return
        for conn, stamp, raw in self._reader.messages(connections=connections):
            yield BagMessage(conn.topic, conn.msgtype, stamp, bytes(raw))

    def count(self, topics: Iterable[str] | None = None) -> int:
        """Return how many messages ``topics`` (all when None) have."""
        wanted = set(self.topics if topics is None else topics)
        if self._reader is None:
            return sum(1 for m in self._salvaged if m.topic in wanted)
        return sum(c.msgcount for c in self._reader.connections if c.topic in wanted)

    def deserialize(self, message: BagMessage) -> object:
        """Decode a message; BagError names the type when it is unknown or does not fit."""
        if message.msgtype not in self._typestore.fielddefs:
            raise BagError(f'message type {message.msgtype} of {message.topic} is unknown '
                           '(not a standard type and no definition in the bag)')
        try:
            return self._typestore.deserialize_cdr(message.raw, message.msgtype)
        except Exception as err:
            raise BagError(f'a {message.msgtype} message of {message.topic} does not decode '
                           f'({err})') from None

    def close(self) -> None:
        """Close the storage (idempotent)."""
        if self._reader is not None:
            reader, self._reader = self._reader, None
            reader.close()

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _register(self, definitions: dict[str, tuple[str, str]]) -> None:
        """Add the bag's own message definitions (ros2msg) over the standard types."""
        for msgtype, (fmt, text) in definitions.items():
            if msgtype in self._typestore.fielddefs or fmt != 'MSG' or not text:
                continue
            try:
                self._typestore.register(get_types_from_msg(text, msgtype))
            except Exception:      # a broken definition only matters if its topic is read
                continue

    def _salvage(self, files: list[Path], definitions: dict[str, tuple[str, str]],
                 refusal: Exception) -> None:
        """
        Read MCAP files record by record, each up to its first damaged record.

        A split bag (``--max-bag-size``) whose recorder died has no metadata.yaml, which is
        written at the end: every file of it is read, in the order of its number (read the
        first alone, the blocks in the later ones were missed without a word).
        """
        messages, damaged = [], []
        self.topics = {}
        for mcap in files:
            data = mcap.read_bytes()
            scan = _McapScan(data)
            scan.run()
            messages += scan.messages
            self.topics.update(scan.topics)
            definitions.update(scan.definitions)
            if not scan.complete:
                damaged.append(f'{mcap.name} is damaged at byte {scan.stop} of {len(data)} '
                               f'({scan.reason}); the {len(scan.messages)} messages before it '
                               'were read')
        self._salvaged = sorted(messages, key=lambda m: m.stamp_ns)
        self.start_ns = self._salvaged[0].stamp_ns if self._salvaged else 0
        names = ', '.join(f.name for f in files)
        if damaged:
            self.damage = '; '.join(damaged)
        else:
            self.notice = (f'{names}: read record by record, the index is unusable '
                           f'({refusal})')


def _mcap_files(path: Path) -> list[Path]:
    """Return the MCAP files of a bag folder (in their numbers' order) or file."""
    candidates = [path] if path.is_file() else sorted(
        path.glob('*.mcap'), key=lambda f: [int(p) if p.isdigit() else p
                                            for p in re.split(r'(\d+)', f.name)])
    found = []
    for candidate in candidates:
        with candidate.open('rb') as stream:
            if stream.read(8) == MCAP_MAGIC:
                found.append(candidate)
    return found


class _McapScan:
    """A forward-only MCAP record reader that stops cleanly at the first damaged record."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.stop = len(MCAP_MAGIC)
        self.complete = False
        self.reason = 'it ends without a footer'
        self.schemas: dict[int, tuple[str, str, str]] = {}
        self.channels: dict[int, tuple[str, str]] = {}
        self.topics: dict[str, str] = {}
        self.definitions: dict[str, tuple[str, str]] = {}
        self.messages: list[BagMessage] = []

    def run(self) -> None:
        """Read records until the end of the data section or the first damaged record."""
        try:
            self.complete = self._records(self.data, len(MCAP_MAGIC), top_level=True)
        except (struct.error, ValueError, KeyError, UnicodeDecodeError) as err:
            self.reason = str(err) or type(err).__name__

    def _records(self, data: bytes, pos: int, top_level: bool) -> bool:
        """Read the records in ``data`` from ``pos``; True when the file's end was reached."""
        while pos < len(data):
            if top_level and data[pos:] == MCAP_MAGIC:
                return True
            opcode = data[pos]
            (length,) = struct.unpack_from('<Q', data, pos + 1)
            body = data[pos + 9:pos + 9 + length]
            if len(body) < length:
                raise ValueError(f'record 0x{opcode:02x} cut short')
            self._record(opcode, body)
            pos += 9 + length
            if top_level:
                self.stop = pos
            if opcode == 0x0F:      # data end: what follows is the summary
                return True
        return not top_level

    def _record(self, opcode: int, body: bytes) -> None:
        if opcode == 0x03:
            (sid,) = struct.unpack_from('<H', body)
            name, pos = _string(body, 2)
            encoding, pos = _string(body, pos)
            text, _ = _string(body, pos)
            self.schemas[sid] = (name, encoding, text)
        elif opcode == 0x04:
            cid, sid = struct.unpack_from('<HH', body)
            topic, _ = _string(body, 4)
            name, encoding, text = self.schemas.get(sid, ('', '', ''))
            self.channels[cid] = (topic, name)
            self.topics[topic] = name
            self.definitions[name] = ('MSG' if encoding == 'ros2msg' else encoding, text)
        elif opcode == 0x05:
            cid, _, log_time = struct.unpack_from('<HIQ', body)
            topic, msgtype = self.channels[cid]
            self.messages.append(BagMessage(topic, msgtype, log_time, body[22:]))
        elif opcode == 0x06:
            _, _, size, crc = struct.unpack_from('<QQQI', body)
            compression, pos = _string(body, 28)
            (compressed_size,) = struct.unpack_from('<Q', body, pos)
            payload = body[pos + 8:pos + 8 + compressed_size]
            if len(payload) < compressed_size:
                raise ValueError('chunk cut short')
            records = payload if not compression else decompress(payload, compression, size,
                                                                 crc)
            self._records(records, 0, top_level=False)


def _string(body: bytes, pos: int) -> tuple[str, int]:
    """Read an MCAP string (u32 length + UTF-8) at ``pos``; return it and the next offset."""
    (length,) = struct.unpack_from('<I', body, pos)
    end = pos + 4 + length
    if end > len(body):
        raise ValueError('string cut short')
    return body[pos + 4:end].decode(), end
