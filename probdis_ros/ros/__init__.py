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

"""ROS 2 adapters: the planner node, the mock iiwa node and their command-line clients."""

import os

#: The mock iiwa's node name: it plays joint_trajectory_controller, so the planner reads the
#: controller's parameters there (``controller_node``).
MOCK_NODE = 'mock_iiwa'

# The lbr stack's names for a robot named ``lbr`` (its launch files' default), the defaults
# of the planner, the mock and ``probdis replay`` (no rclpy here: the CLI reads them too).
#: The arm's joints, in URDF order.
JOINT_NAMES = tuple(f'lbr_A{i}' for i in range(1, 8))

#: The driver's joint states (sensor_msgs/JointState).
JOINT_STATES_TOPIC = '/lbr/joint_states'
#: joint_trajectory_controller's command topic (trajectory_msgs/JointTrajectory).
TRAJECTORY_TOPIC = '/lbr/joint_trajectory_controller/joint_trajectory'


#: The detector's settings the planner node has as parameters (the others keep their
#: defaults there; the offline runs take them all).
DETECTOR_FIELDS = ('d_dist', 'stall_time', 'stall_motion', 'settle_time', 'motion_delay',
                   'gap_ceiling', 'joint_gap_ceiling', 'limit_room', 'onset_gap',
                   'echo_time', 'driver_tau', 'torque_ceiling', 'load_mass', 'load_com')

#: The mock's pace on simulated time, at most this times the wall clock: at 5, on a 2-core
#: machine under load, the planner fell behind the simulation (retreats went unwatched and
#: stale gaps read as blocks; README "The robot experiment").
DEFAULT_REAL_TIME_FACTOR = 1.0


def checked_joint_names(names) -> list[str]:
    """Return names as a list, or raise ValueError unless they name 7 different joints."""
    names = list(names)
    if len(names) != len(JOINT_NAMES) or len(set(names)) != len(names):
        raise ValueError(f'joint_names must name 7 different joints, got {names}')
    return names


def default_map_file() -> str:
    """Return ``$ROS_HOME/probdis/failure_map.json`` (ROS_HOME defaults to ~/.ros)."""
    home = os.environ.get('ROS_HOME') or os.path.join(os.path.expanduser('~'), '.ros')
    return os.path.join(home, 'probdis', 'failure_map.json')
