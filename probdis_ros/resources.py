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
Where the package's data files (config/, urdf/) are, however it was installed.

* colcon build: ``share/probdis_ros`` found through the ament index (AMENT_PREFIX_PATH).
* editable install or a source checkout: the folders next to the package source.
* ``pip install .``: ``sys.prefix/share/probdis_ros``, where setup.py's data_files land.
"""

from __future__ import annotations

import os
from pathlib import Path
import sys

PACKAGE = 'probdis_ros'


def _ament_share() -> Path | None:
    try:
        from ament_index_python.packages import get_package_share_directory, PackageNotFoundError
    except ImportError:
        return None
    try:
        return Path(get_package_share_directory(PACKAGE))
    except (PackageNotFoundError, LookupError, ValueError, OSError):
        return None


def share_candidates() -> list[tuple[str, Path]]:
    """List where data files may be, most specific first, with how each was found."""
    found = []
    ament = _ament_share()
    if ament is not None:
        found.append(('ament index', ament))
    found.append(('source tree', Path(__file__).resolve().parent.parent))
    found.append(('python prefix', Path(sys.prefix) / 'share' / PACKAGE))
    return found


def share_dir() -> tuple[str, Path]:
    """Return the first place holding both config/ and urdf/, and how it was found."""
    candidates = share_candidates()
    for how, path in candidates:
        if (path / 'config').is_dir() and (path / 'urdf').is_dir():
            return how, path
    tried = os.pathsep.join(str(p) for _, p in candidates)
    raise FileNotFoundError(f'cannot find the {PACKAGE} config/ and urdf/ folders (looked in '
                            f'{tried}); reinstall the package or source its setup script')


def data_file(*parts: str) -> Path:
    """Return the path of a file shipped with the package (e.g. urdf/iiwa14.urdf)."""
    path = share_dir()[1].joinpath(*parts)
    if not path.exists():
        raise FileNotFoundError(f'{PACKAGE} data file missing: {path}')
    return path


def config_file(name: str | Path, folder: str) -> Path:
    """Return a user's file by its path, or the name of one shipped in config/<folder>/."""
    path = Path(name)
    if not path.exists() and path.suffix == '' and len(path.parts) == 1:
        shipped = share_dir()[1] / 'config' / folder / f'{name}.yaml'
        if shipped.exists():
            return shipped
    return path


def scenario_path(name: str) -> Path:
    """Return a scenario file: name as a path, or the name of one in config/scenarios/."""
    return config_file(name, 'scenarios')
