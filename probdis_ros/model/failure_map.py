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
The failure map: blocked movements and the failure probability they imply.

A failure ``f = (x_fail, v_fail, q_fail)`` records where the arm was blocked (task-space
point), the task-space direction it was moving in, and, where orientation is modelled, the
end-effector orientation (unit quaternion ``(w, x, y, z)``).  As in the paper and DESIGN.md::

    P(FAIL | c, F) = max_f  P_COORD(c, f) * (1 - 0.5 * D_ORIENT(c, f))
    P_COORD        = (alpha / pi)^3 / (1 + C_FAIL * |x - x_fail|^2)
    D_ORIENT       = (2 / pi) * arccos(|q . q_fail|)          (0 without orientation)

where alpha in [0, pi] is the angle between ``v_fail`` and ``x_fail - x`` (pi at
``x = x_fail``): high beyond the failure in the blocked direction, low behind it.

File format (JSON, written atomically; see README "Failure map files")::

    {"format": "probdis-failure-map", "version": 1, "task_space": "point2|point3|pose3",
     "c_fail": 100.0,
     "failures": [{"x": [...], "v": [...], "q": [w, x, y, z] or null}, ...]}
"""

from __future__ import annotations

import fcntl
import json
import math
import os
from pathlib import Path
import shutil
import tempfile
import time

import numpy as np
from probdis_ros.model.arms import TaskPoints, TaskSpace

FORMAT = 'probdis-failure-map'
VERSION = 1

#: Default C_FAIL in 1/m^2: the probability halves 0.1 m from a failure.
DEFAULT_C_FAIL = 100.0


class FailureMapError(ValueError):
    """A failure map file or failure that cannot be used, with the reason."""


def write_document(path: str | Path, doc: dict) -> None:
    """Write a map document atomically (temporary file, fsync, rename)."""
    write_atomically(path, json.dumps(doc, indent=1) + '\n')


def write_atomically(path: str | Path, text: str, private: bool = True) -> None:
    """
    Write a text file so that a crash leaves the old file or the new one, never half.

    A temporary file beside it, fsync, rename, fsync of the folder.  ``private``: readable
    by its owner alone (the map files); else with the permissions of any new file (the
    umask's).  A symbolic link is written through (renamed over, the link became a file of
    its own, and the file it named was no longer written).
    """
    path = Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    if private:
        fd, name = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.tmp', dir=path.parent)
        tmp, out = Path(name), os.fdopen(fd, 'w')
    else:
        tmp = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
        out = tmp.open('x')
    try:
        with out:
            out.write(text)
            out.flush()
            os.fsync(out.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    folder = os.open(path.parent, os.O_RDONLY)
    try:                # the rename itself to disk: a power cut could undo it before
        os.fsync(folder)
    finally:
        os.close(folder)


def set_aside(path: str | Path, why: str) -> Path:
    """
    Copy a map file that cannot be used here beside it, so that writing the map keeps it.

    The copy is ``<name>.<why>-<date>-<time>[-k]`` in the same folder; OSError if it fails.
    """
    copy = aside_path(path, why)
    shutil.copyfile(path, copy)
    return copy


class MapInUseError(RuntimeError):
    """Another process holds a map file's lock; ``holder`` is what it wrote there."""

    def __init__(self, path: Path, holder: dict) -> None:
        super().__init__(f'{path} is in use by {holder or "another process"}')
        self.path, self.holder = path, holder


def lock_map(path: str | Path, holder: dict) -> int:
    """
    Take a map file's lock (``<name>.lock`` beside it) for as long as the descriptor is open.

    Two planners writing one map each write their own whole, and the last write wins: the
    other's failures were lost without a word.  The lock file says who holds it
    (``holder``, JSON); MapInUseError, with what the holder wrote, if another process holds
    it.  OSError where no lock file can be made (the map is not writable there either).
    """
    target = Path(path).resolve()
    lock = target.with_name(target.name + '.lock')
    lock.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        try:
            other = json.loads(os.read(fd, 4096).decode('utf-8', errors='replace') or '{}')
        except ValueError:
            other = {}
        os.close(fd)
        raise MapInUseError(Path(path), other if isinstance(other, dict) else {}) from None
    except OSError:
        os.close(fd)
        raise
    os.ftruncate(fd, 0)
    os.pwrite(fd, json.dumps(holder).encode(), 0)
    return fd


def aside_path(path: str | Path, why: str) -> Path:
    """Return a new name beside a map file: ``<name>.<why>-<date>-<time>[-k]``."""
    path = Path(path)
    stem = f'{path.name}.{why}-{time.strftime("%Y%m%d-%H%M%S")}'
    copy, k = path.with_name(stem), 1
    while copy.exists():
        k += 1
        copy = path.with_name(f'{stem}-{k}')
    return copy


def unit(vector: np.ndarray, norm: float | None = None) -> np.ndarray:
    """
    Scale to unit length, keeping a vector already of unit length bit for bit.

    So that a map or world that is saved and reloaded is identical to the original.
    """
    norm = float(np.linalg.norm(vector)) if norm is None else norm
    return vector if abs(norm - 1.0) < 1e-12 else vector / norm


class FailureMap:
    """The set of failures and the batched probability ``P(FAIL | c, F)``."""

    def __init__(self, task_space: TaskSpace, c_fail: float = DEFAULT_C_FAIL) -> None:
        if not (math.isfinite(c_fail) and c_fail > 0):
            raise FailureMapError(f'c_fail must be a positive number, got {c_fail!r}')
        self.task_space = TaskSpace(task_space)
        self.c_fail = float(c_fail)
        dim = self.task_space.dim
        self._arrays = (np.empty((0, dim)), np.empty((0, dim)), np.empty((0, 4)))

    def __len__(self) -> int:
        return len(self.points)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Return (points, directions, orientations) as one set of the same failures.

        Read them so where another thread may add a failure meanwhile (the planner node
        learns a blocked retreat while a plan runs): the three attributes read one after
        another could be of different lengths, and the compiled kernels do not check.
        """
        return self._arrays

    @property
    def points(self) -> np.ndarray:
        """Return the failure points ``(F, dim)``."""
        return self._arrays[0]

    @points.setter
    def points(self, value: np.ndarray) -> None:
        self._arrays = (value, *self._arrays[1:])

    @property
    def directions(self) -> np.ndarray:
        """Return the unit directions of the blocked motions ``(F, dim)``."""
        return self._arrays[1]

    @directions.setter
    def directions(self, value: np.ndarray) -> None:
        self._arrays = (self._arrays[0], value, self._arrays[2])

    @property
    def orientations(self) -> np.ndarray:
        """Return the unit quaternions ``(F, 4)`` (w, x, y, z) held at the failures."""
        return self._arrays[2]

    @orientations.setter
    def orientations(self, value: np.ndarray) -> None:
        self._arrays = (*self._arrays[:2], value)

    def add(self, x: np.ndarray, v: np.ndarray, q: np.ndarray | None = None) -> None:
        """Record a blocked movement at x, moving along v, with orientation q."""
        x, v, q = self._failure(x, v, q)
        points, directions, orientations = self._arrays
        # one assignment: a reader in another thread sees the failure whole or not at all
        self._arrays = (np.vstack([points, x]), np.vstack([directions, v]),
                        np.vstack([orientations, q]))

    def copy(self) -> FailureMap:
        """Return a map of the same failures now (their arrays are replaced, never changed)."""
        copy = FailureMap(self.task_space, self.c_fail)
        copy._arrays = self._arrays
        return copy

    def _failure(self, x: np.ndarray, v: np.ndarray, q: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return a failure's point, unit direction and unit quaternion; refuse a bad one."""
        dim = self.task_space.dim
        x = np.asarray(x, dtype=float).reshape(-1)
        v = np.asarray(v, dtype=float).reshape(-1)
        if x.shape != (dim,) or v.shape != (dim,):
            raise FailureMapError(f'a failure in {self.task_space.value} needs x and v of '
                                  f'length {dim}, got {x.size} and {v.size}')
        speed = np.linalg.norm(v)
        if not (np.all(np.isfinite(x)) and np.isfinite(speed) and speed > 0):
            raise FailureMapError('a failure needs a finite point and a nonzero finite direction')
        if self.task_space.has_orientation:
            if q is None:
                raise FailureMapError('this map models orientation: a failure needs q')
            q = np.asarray(q, dtype=float).reshape(-1)
            norm = np.linalg.norm(q)
            if q.shape != (4,) or not (np.isfinite(norm) and norm > 0):
                raise FailureMapError('q must be a nonzero quaternion (w, x, y, z)')
            q = unit(q, norm)
        else:
            q = np.array([1.0, 0.0, 0.0, 0.0])
        return x, unit(v, speed), q

    def clear(self) -> None:
        """Forget every failure."""
        self.__init__(self.task_space, self.c_fail)

    def probability(self, poses: TaskPoints, c_fail: float | None = None,
                    behind_within: float = 0.0, reach: float = math.inf) -> np.ndarray:
        """
        ``P(FAIL | c, F)`` for each pose of the batch, in [0, 1] (0 for an empty map).

        ``c_fail`` replaces the map's C_FAIL (the Hard baseline draws its regions with its
        own); None uses the map's.  A pose within ``AT_FAILURE_POINT`` of a failure is at it
        (the paper's alpha = pi: nearer, the direction to it is rounding's); within
        ``behind_within`` [m] it counts as behind it (alpha = 0) instead (where a Hard edge
        starts: :mod:`probdis_ros.model.kernels`).  A finite ``reach``
        [m] (beyond the paper; the informed method's idea h) tapers each failure's
        probability by ``(1 - d^2 / reach^2)^2`` to 0 at that distance: a block tells of the
        surface it met, not of all the space beyond it.  Infinite: the paper's kernel.
        """
        from probdis_ros.model.edge_kernels import AT_FAILURE_HALF_COS, AT_FAILURE_POINT

        c_fail = self.c_fail if c_fail is None else float(c_fail)
        x = np.asarray(poses.positions, dtype=float)
        if len(self) == 0:
            return np.zeros(len(x))
        to_fail = self.points[None, :, :] - x[:, None, :]            # (N, F, d)
        dist2 = np.einsum('nfd,nfd->nf', to_fail, to_fail)
        dist = np.sqrt(dist2)
        cos_alpha = np.einsum('nfd,fd->nf', to_fail, self.directions)
        with np.errstate(invalid='ignore', divide='ignore'):
            near = behind_within if behind_within > 0 else AT_FAILURE_POINT
            cos_alpha = np.where(dist2 > near ** 2, cos_alpha / dist,
                                 1.0 if behind_within > 0 else -1.0)
        alpha = np.arccos(np.clip(cos_alpha, -1.0, 1.0))
        taper = np.maximum(0.0, 1.0 - dist2 / reach ** 2)
        prob = (alpha / np.pi) ** 3 * (taper * taper) / (1.0 + c_fail * dist2)
        if self.task_space.has_orientation:
            if poses.orientations is None:
                raise FailureMapError('this map models orientation: poses need quaternions')
            dots = np.abs(poses.orientations @ self.orientations.T)
            dots = np.where(dots > AT_FAILURE_HALF_COS, 1.0, dots)
            d_orient = (2.0 / np.pi) * np.arccos(np.clip(dots, 0.0, 1.0))
            prob = prob * (1.0 - 0.5 * d_orient)
        return prob.max(axis=1)

    # -- files -------------------------------------------------------------------------

    def to_dict(self) -> dict:
        """Return the map as the JSON document of the file format."""
        with_q = self.task_space.has_orientation
        return {
            'format': FORMAT, 'version': VERSION, 'task_space': self.task_space.value,
            'c_fail': self.c_fail,
            'failures': [
                {'x': x.tolist(), 'v': v.tolist(), 'q': q.tolist() if with_q else None}
                for x, v, q in zip(self.points, self.directions, self.orientations)],
        }

    def save(self, path: str | Path) -> None:
        """Write the map atomically: a crash leaves the old file or the new one, never half."""
        write_document(path, self.to_dict())

    @classmethod
    def from_dict(cls, doc: object, source: str = 'failure map') -> FailureMap:
        """Build a map from its JSON document, validating every field first."""
        if not isinstance(doc, dict) or doc.get('format') != FORMAT:
            raise FailureMapError(f'{source}: not a {FORMAT} document')
        if doc.get('version') != VERSION:
            raise FailureMapError(f'{source}: unsupported version {doc.get("version")!r}, '
                                  f'this probdis reads version {VERSION}')
        try:
            task_space = TaskSpace(doc.get('task_space'))
        except ValueError:
            raise FailureMapError(
                f'{source}: unknown task_space {doc.get("task_space")!r}') from None
        c_fail = doc.get('c_fail')
        if not isinstance(c_fail, (int, float)) or isinstance(c_fail, bool):
            raise FailureMapError(f'{source}: c_fail must be a number')
        failures = doc.get('failures')
        if not isinstance(failures, list):
            raise FailureMapError(f'{source}: failures must be a list')
        try:                # an integer of 400 digits overflows a float
            fmap = cls(task_space, float(c_fail))
        except (OverflowError, ValueError) as err:
            raise FailureMapError(f'{source}: {err}') from None
        rows = []
        for i, entry in enumerate(failures):
            if not isinstance(entry, dict):
                raise FailureMapError(f'{source}: failure {i} is not an object')
            try:
                rows.append(fmap._failure(entry.get('x'), entry.get('v'), entry.get('q')))
            except (FailureMapError, TypeError, ValueError, OverflowError) as err:
                raise FailureMapError(f'{source}: failure {i}: {err}') from None
        if rows:        # stacked once: a failure at a time was quadratic (1.6 s for 16,000)
            fmap._arrays = tuple(np.array(column) for column in zip(*rows))
        return fmap

    @classmethod
    def load(cls, path: str | Path) -> FailureMap:
        """Read a map file; a missing, partial or corrupt file raises FailureMapError."""
        path = Path(path)
        if path.exists() and not path.is_file():     # a folder, a pipe (reading would hang)
            raise FailureMapError(f'cannot read failure map {path}: not a regular file')
        try:
            text = path.read_text(encoding='utf-8')
        except OSError as err:
            raise FailureMapError(f'cannot read failure map {path}: {err.strerror}') from None
        except UnicodeDecodeError as err:
            raise FailureMapError(f'{path}: not a failure map (not UTF-8 text: {err.reason} '
                                  f'at byte {err.start})') from None
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as err:
            raise FailureMapError(f'{path}: not valid JSON (truncated or corrupt?): {err}') \
                from None
        except RecursionError:
            raise FailureMapError(f'{path}: not a failure map (JSON nested too deeply to '
                                  f'read)') from None
        return cls.from_dict(doc, source=str(path))
