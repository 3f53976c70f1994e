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

"""Shared helpers: run the real ``probdis`` command as a user would."""

import itertools
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: DDS domains for tests: a fresh one per use, from this run's ROS_DOMAIN_ID (else the pid),
#: within 1-101 (never 0, where a robot's stack usually runs; above 101 the ports fall among
#: Linux's ephemeral ones)
_DOMAIN_BASE = int(os.environ.get('ROS_DOMAIN_ID') or os.getpid() * 7)
_DOMAINS = itertools.count()


def next_domain() -> int:
    """
    Return a DDS domain no other test of this run is using (1-101, cycling).

    Tests on DDS run one at a time (``make test`` runs the others in parallel workers,
    whose domains would collide, and whose load would slow the nodes' timing): such a
    test must be marked ``ros``.
    """
    if int(os.environ.get('PYTEST_XDIST_WORKER_COUNT') or 1) > 1:
        raise RuntimeError('a test that uses DDS runs alone: mark it @pytest.mark.ros '
                           '(make test runs those one at a time, after the others)')
    return 1 + (_DOMAIN_BASE + next(_DOMAINS)) % 101


def probdis_command() -> list[str]:
    """Return the installed console script next to this Python, else ``python -m``."""
    script = Path(sys.executable).parent / 'probdis'
    if script.exists():
        return [str(script)]
    return [sys.executable, '-m', 'probdis_ros.cli']


def run_probdis(*args: str, timeout: float = 120, cwd: Path | None = None,
                check: bool = True) -> subprocess.CompletedProcess:
    """Run ``probdis ARGS`` and return the finished process (text output)."""
    result = subprocess.run(probdis_command() + list(args), capture_output=True, text=True,
                            timeout=timeout, cwd=cwd)
    if check and result.returncode != 0:
        raise AssertionError(f'probdis {" ".join(args)} exited {result.returncode}:\n'
                             f'{result.stdout}\n{result.stderr}')
    return result


def copy_source_tree(dest: Path) -> Path:
    """Copy the package sources (no virtualenv, build output or git data) to dest."""
    ignore = shutil.ignore_patterns('.venv', 'build', 'install', 'log', 'out', '.git',
                                    '__pycache__', '*.egg-info', '.pytest_cache', '.ruff_cache')
    shutil.copytree(ROOT, dest, ignore=ignore)
    return dest


@pytest.fixture
def probdis():
    """Run the probdis command; fails the test on a non-zero exit unless check=False."""
    return run_probdis
