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

"""The ``probdis`` command line, run as a real process."""

import json

import numpy as np
from probdis_ros.model import FailureMap, TaskSpace


def test_help_lists_the_subcommands(probdis):
    out = probdis('--help').stdout
    for command in ('info', 'fk', 'bench', 'map'):
        assert command in out


def test_fk_json_at_zero_is_straight_up(probdis):
    doc = json.loads(probdis('fk', '--json', *['0'] * 7).stdout)
    np.testing.assert_allclose(doc['position'], [0, 0, 1.306], atol=1e-9)
    np.testing.assert_allclose(doc['quaternion_wxyz'], [1, 0, 0, 0], atol=1e-9)
    assert doc['within_limits'] is True


def test_fk_planar_and_limit_warning(probdis):
    doc = json.loads(probdis('fk', '--setting', '2d', '--json', *['0'] * 7).stdout)
    np.testing.assert_allclose(doc['position'], [0.7, 0.0], atol=1e-12)
    result = probdis('fk', '0', '3', '0', '0', '0', '0', '0')
    assert 'outside the joint limits' in result.stderr


def test_fk_with_the_wrong_joint_count_is_a_clear_error(probdis):
    result = probdis('fk', '0.1', '0.2', '0.3', check=False)
    assert result.returncode == 2
    assert 'has 7 joints' in result.stderr and 'got 3 values' in result.stderr
    assert 'Traceback' not in result.stderr


def test_bench_fk_json_prints_the_figure(probdis):
    result = probdis('bench', 'fk', '--json', '--configs', '5000', '--repeats', '2')
    doc = json.loads(result.stdout)
    assert list(doc) == ['configs_per_s']
    assert isinstance(doc['configs_per_s'], float) and doc['configs_per_s'] > 0


def test_map_plot_writes_a_png(probdis, tmp_path):
    out = tmp_path / 'figs' / 'map.png'
    result = probdis('map', 'plot', '--out', str(out))
    assert out.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert '3 failures' in result.stdout


def test_map_plot_of_a_saved_map(probdis, tmp_path):
    fmap = FailureMap(TaskSpace.POINT2)
    fmap.add([0.1, 0.2], [0.0, 1.0])
    fmap.save(tmp_path / 'map.json')
    probdis('map', 'plot', '--map', str(tmp_path / 'map.json'), '--out', str(tmp_path / 'm.png'))
    assert (tmp_path / 'm.png').stat().st_size > 1000


def test_map_plot_refuses_bad_maps_clearly(probdis, tmp_path):
    fmap = FailureMap(TaskSpace.POINT3)
    fmap.add([0.1, 0.2, 0.3], [0.0, 1.0, 0.0])
    fmap.save(tmp_path / 'map3d.json')
    result = probdis('map', 'plot', '--map', str(tmp_path / 'map3d.json'), check=False)
    assert result.returncode == 2 and 'draws 2-D maps' in result.stderr
    (tmp_path / 'bad.json').write_text('{"format": "probdis-failure-map", "vers')
    result = probdis('map', 'plot', '--map', str(tmp_path / 'bad.json'), check=False)
    assert result.returncode == 2 and 'truncated or corrupt' in result.stderr
