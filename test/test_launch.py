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


"""The launch file and the RViz configuration shipped for ROS machines."""

import importlib.util
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
LAUNCH = ROOT / 'config' / 'launch' / 'probdis_mock.launch.py'


def test_the_rviz_configuration_shows_the_arm_the_scene_and_the_planner():
    config = yaml.safe_load((ROOT / 'config' / 'rviz' / 'probdis.rviz').read_text())
    manager = config['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == 'lbr_link_0'
    topics = {d['Class']: d.get('Topic', d.get('Description Topic', {})).get('Value')
              for d in manager['Displays'] if 'Topic' in d or 'Description Topic' in d}
    assert topics['rviz_default_plugins/RobotModel'] == '/robot_description'
    shown = {d.get('Topic', {}).get('Value') for d in manager['Displays']}
    assert {'/mock_iiwa/scene', '/probdis_planner/markers'} <= shown


def test_the_launch_description_loads_where_launch_is_installed():
    pytest.importorskip('launch')
    pytest.importorskip('launch_ros')
    spec = importlib.util.spec_from_file_location('probdis_mock_launch', LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    names = {getattr(e, 'name', None) for e in description.entities}
    assert {'scene', 'rviz', 'sim_time'} <= names
