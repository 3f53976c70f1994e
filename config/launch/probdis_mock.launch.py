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
Launch the physics mock iiwa, the planner and RViz (on a machine with ROS 2 installed).

    ros2 launch probdis_ros probdis_mock.launch.py                      # the demo scene
    ros2 launch probdis_ros probdis_mock.launch.py scene:=robot_maze rviz:=false
    ros2 service call /probdis_planner/start std_srvs/srv/Trigger

The planner's goal is the scene's goal.  robot_state_publisher turns ``/lbr/joint_states``
into TF from the package's URDF, so RViz draws the arm; the mock publishes the scene's
obstacles and the grasped object (``/mock_iiwa/scene``), the planner its failures, path and
map (``/probdis_planner/markers``).
"""

from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _share() -> Path:
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory('probdis_ros'))
    except (ImportError, LookupError, ValueError):
        return Path(__file__).resolve().parents[2]     # a source checkout


def _nodes(context, *args, **kwargs):
    from probdis_ros.physics import load_scene
    from probdis_ros.ros import default_map_file, DEFAULT_REAL_TIME_FACTOR
    share = _share()
    scene = LaunchConfiguration('scene').perform(context)
    world = load_scene(scene)
    goal = [float(v) for v in world.goal]
    urdf = (share / 'urdf' / 'iiwa14.urdf').read_text()
    sim = LaunchConfiguration('sim_time').perform(context).lower() == 'true'
    return [
        Node(package='probdis_ros', executable='mock_iiwa_node', name='mock_iiwa',
             parameters=[{'scene': scene, 'sim_time': sim,
                          'real_time_factor': DEFAULT_REAL_TIME_FACTOR if sim else 0.0}]),
        Node(package='probdis_ros', executable='planner_node', name='probdis_planner',
             parameters=[str(share / 'config' / 'planner.yaml'),
                         {'goal': goal, 'use_sim_time': sim,
                          'controller_node': '/mock_iiwa',
                          # a map of the mock's own: failures met in a scene must never
                          # steer the real arm, whose planner reads the default map
                          'map_file': str(Path(default_map_file()).with_name(
                              'mock_failure_map.json')),
                          # kept above the table, as the demo and the experiments keep it
                          'object_radius': float(world.object_reach)}]),
        Node(package='robot_state_publisher', executable='robot_state_publisher',
             parameters=[{'robot_description': urdf, 'use_sim_time': sim}],
             remappings=[('joint_states', '/lbr/joint_states')]),
        Node(package='rviz2', executable='rviz2', name='rviz2',
             arguments=['-d', str(share / 'config' / 'rviz' / 'probdis.rviz')],
             parameters=[{'use_sim_time': sim}],      # on the mock's clock, as TF is
             condition=IfCondition(LaunchConfiguration('rviz'))),
    ]


def generate_launch_description() -> LaunchDescription:
    """Return the mock, the planner, robot_state_publisher and RViz."""
    return LaunchDescription([
        DeclareLaunchArgument('scene', default_value='demo_hook',
                              description='physics scene: a file or a name in config/scenes'),
        DeclareLaunchArgument('rviz', default_value='true', description='start RViz'),
        DeclareLaunchArgument('sim_time', default_value='false',
                              description='run the mock on simulated time (/clock)'),
        OpaqueFunction(function=_nodes),
    ])
