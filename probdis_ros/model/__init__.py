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

"""Arms, forward kinematics, the failure map and path cost (no rclpy)."""

from __future__ import annotations

from functools import cache

from probdis_ros.model.arms import Arm, PlanarArm, SerialChainArm, TaskPoints, TaskSpace
from probdis_ros.model.failure_map import FailureMap, FailureMapError
from probdis_ros.model.kernel_cache import check_kernel_cache

check_kernel_cache()        # before any kernel is loaded from the cache

#: The paper's three simulated settings and the arm and task space each uses.
SETTINGS = ('2d', '3d', '3d-orient')

IIWA_TIP_FRAME = 'lbr_link_ee'


@cache
def iiwa_arm(with_orientation: bool = True) -> SerialChainArm:
    """Load the LBR iiwa 14 R820 from the package's URDF, flange as the tip."""
    from probdis_ros.resources import data_file

    return SerialChainArm.from_urdf(data_file('urdf', 'iiwa14.urdf'), IIWA_TIP_FRAME,
                                    with_orientation)


def arm_for_setting(setting: str) -> Arm:
    """Return the arm of one of the paper's settings: '2d', '3d' or '3d-orient'."""
    if setting == '2d':
        return PlanarArm()
    if setting == '3d':
        return iiwa_arm(with_orientation=False)
    if setting == '3d-orient':
        return iiwa_arm(with_orientation=True)
    raise ValueError(f'unknown setting {setting!r}; choose one of {", ".join(SETTINGS)}')


__all__ = [
    'SETTINGS',
    'Arm',
    'FailureMap',
    'FailureMapError',
    'PlanarArm',
    'SerialChainArm',
    'TaskPoints',
    'TaskSpace',
    'arm_for_setting',
    'iiwa_arm',
]
