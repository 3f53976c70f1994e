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

"""The iiwa simulated with MuJoCo in KUKA's joint impedance, and physical scenes (no rclpy)."""

from __future__ import annotations

from probdis_ros.physics.arm import Contact, PhysicsIiwa
from probdis_ros.physics.scene import (
                                       GraspedObject,
                                       Hinge,
                                       load_scene,
                                       Primitive,
                                       Scene,
                                       scene_from_dict,
                                       SceneError,
                                       SceneObstacle,
                                       shipped_scenes,
)
from probdis_ros.physics.settings import PhysicsSettings

__all__ = [
    'Contact',
    'GraspedObject',
    'Hinge',
    'PhysicsIiwa',
    'PhysicsSettings',
    'Primitive',
    'Scene',
    'SceneError',
    'SceneObstacle',
    'load_scene',
    'scene_from_dict',
    'shipped_scenes',
]
