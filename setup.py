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

from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'probdis_ros'


def share(subdir: str, pattern: str) -> tuple[str, list[str]]:
    """Install the files matching pattern under share/probdis_ros/subdir."""
    files = sorted(glob(os.path.join(subdir, pattern)))
    return (os.path.join('share', package_name, subdir), files)


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        share('config', '*.yaml'),
        share('config/scenarios', '*.yaml'),
        share('config/scenes', '*.yaml'),
        share('config/launch', '*.launch.py'),
        share('config/rviz', '*.rviz'),
        share('urdf', '*.urdf'),
    ],
    install_requires=['setuptools'],
    python_requires='>=3.10',
    zip_safe=True,
    maintainer='probdis_ros maintainers',
    maintainer_email='maintainers@probdis.invalid',
    description='Probabilistic disentangling of a grasped object for the KUKA LBR iiwa (ROS 2).',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'probdis = probdis_ros.cli:main',
            'planner_node = probdis_ros.ros.planner_node:main',
            'mock_iiwa_node = probdis_ros.ros.mock_iiwa_node:main',
        ],
    },
)
