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
Copyright and license notice in every source file.

On a ROS machine ament_copyright does the check.  Its wheel is not on PyPI, so without it
the same rule is checked here directly: each Python file opens with a ``Copyright <year>
<holder>`` line followed by the Apache License 2.0 notice that ament_copyright recognises.
"""

from pathlib import Path
import re

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTICE_LINES = [
    'Licensed under the Apache License, Version 2.0 (the "License");',
    'you may not use this file except in compliance with the License.',
    'http://www.apache.org/licenses/LICENSE-2.0',
    'distributed under the License is distributed on an "AS IS" BASIS,',
]


def source_files() -> list[Path]:
    files = [ROOT / 'setup.py']
    for folder in ('probdis_ros', 'test'):
        files += sorted((ROOT / folder).rglob('*.py'))
    return files


@pytest.mark.copyright
@pytest.mark.linter
def test_copyright():
    try:
        from ament_copyright.main import main
    except ImportError:
        main = None
    if main is not None:
        assert main(argv=[str(ROOT / 'probdis_ros'), str(ROOT / 'test')]) == 0
    missing = []
    for path in source_files():
        head = path.read_text().splitlines()[:15]
        has_copyright = bool(head) and re.match(r'# Copyright \d{4} \S', head[0])
        has_notice = all(any(line in text for text in head) for line in NOTICE_LINES)
        if not (has_copyright and has_notice):
            missing.append(str(path.relative_to(ROOT)))
    assert not missing, 'files without the copyright and Apache-2.0 notice: ' + ', '.join(missing)
