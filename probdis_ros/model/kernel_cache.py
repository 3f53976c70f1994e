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
The compiled kernels' cache on disk, dropped whenever any kernel's source changes.

numba ties a cached kernel to the time stamp of its own file only: a kernel that calls or
inlines one from another file keeps its old machine code when only that other file
changes (the tree loop of ``tree_kernels.py`` went on costing edges the old way after a
change to ``edge_kernels.py``, until its own file changed too).  So the package stamps the
cache with a digest of every kernel file and deletes those files' cached kernels when the
digest differs: a change anywhere recompiles them all (20-50 s once).  A fresh install or
clone starts with no cache and is not affected.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

#: The files of the model package that hold compiled kernels (they call one another).
KERNEL_FILES = ('fast_math.py', 'kinematics.py', 'edge_kernels.py', 'tree_kernels.py',
                'least_probability.py')
#: The stamp written beside the cached kernels.
STAMP = 'probdis_kernels.sha256'


def kernel_digest(source_dir: Path = Path(__file__).parent) -> str:
    """Return the SHA-256 of the kernel files' contents, in order."""
    digest = hashlib.sha256()
    for name in KERNEL_FILES:
        digest.update(name.encode())
        digest.update((source_dir / name).read_bytes())
    return digest.hexdigest()


def drop_stale_kernels(cache_dir: Path, digest: str) -> bool:
    """
    Delete the kernel files' cached kernels in cache_dir unless stamped with digest.

    Return whether any were dropped.  A cache that cannot be written is left alone (numba
    then compiles in memory, or caches elsewhere).
    """
    stamp = cache_dir / STAMP
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    stems = {Path(name).stem for name in KERNEL_FILES}
    dropped = False
    try:
        if cache_dir.is_dir():
            for path in cache_dir.glob('*.nb[ci]'):
                if path.name.split('.', 1)[0] in stems:
                    path.unlink(missing_ok=True)
                    dropped = True
        cache_dir.mkdir(parents=True, exist_ok=True)
        fresh = stamp.with_name(f'{STAMP}.{os.getpid()}')    # whole or not at all
        fresh.write_text(digest)
        os.replace(fresh, stamp)
    except OSError:
        return False
    return dropped


def check_kernel_cache() -> None:
    """Drop the package's cached kernels if a kernel file changed since they were cached."""
    from probdis_ros.model.kinematics import chain_kernel

    cache = getattr(chain_kernel, '_cache', None)          # numba's cache of this dispatcher
    path = getattr(cache, '_cache_path', None)
    if path:
        drop_stale_kernels(Path(path), kernel_digest())
