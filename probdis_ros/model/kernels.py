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
Compiled inner loops (numba) of the ROS-free core.

Kept apart so that the Python modules stay readable and each kernel has one job.  Kernels
take plain arrays and write into preallocated outputs; ``cache=True`` keeps the compiled code
between runs.
"""

import numba
import numpy as np


@numba.njit(cache=True)
def chain_kernel(q: np.ndarray, offsets: np.ndarray, bases: np.ndarray, tip_offset: np.ndarray,
                 tip_rotation: np.ndarray, pos_out: np.ndarray, rot_out: np.ndarray) -> None:
    """
    Forward kinematics of a revolute chain for every row of q.

    Joint j moves its child frame by ``offsets[j]`` in the parent frame and rotates it by
    ``bases[j, 0] + cos(q_j) bases[j, 1] + sin(q_j) bases[j, 2]`` (each 3x3).  The rotation
    lives in nine scalars so that the loop stays in registers.
    """
    for k in range(q.shape[0]):
        px = py = pz = 0.0
        r00, r01, r02 = 1.0, 0.0, 0.0
        r10, r11, r12 = 0.0, 1.0, 0.0
        r20, r21, r22 = 0.0, 0.0, 1.0
        for j in range(offsets.shape[0]):
            ox, oy, oz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
            px += r00 * ox + r01 * oy + r02 * oz
            py += r10 * ox + r11 * oy + r12 * oz
            pz += r20 * ox + r21 * oy + r22 * oz
            c = np.cos(q[k, j])
            s = np.sin(q[k, j])
            b = bases[j]
            m00 = b[0, 0, 0] + c * b[1, 0, 0] + s * b[2, 0, 0]
            m01 = b[0, 0, 1] + c * b[1, 0, 1] + s * b[2, 0, 1]
            m02 = b[0, 0, 2] + c * b[1, 0, 2] + s * b[2, 0, 2]
            m10 = b[0, 1, 0] + c * b[1, 1, 0] + s * b[2, 1, 0]
            m11 = b[0, 1, 1] + c * b[1, 1, 1] + s * b[2, 1, 1]
            m12 = b[0, 1, 2] + c * b[1, 1, 2] + s * b[2, 1, 2]
            m20 = b[0, 2, 0] + c * b[1, 2, 0] + s * b[2, 2, 0]
            m21 = b[0, 2, 1] + c * b[1, 2, 1] + s * b[2, 2, 1]
            m22 = b[0, 2, 2] + c * b[1, 2, 2] + s * b[2, 2, 2]
            r00, r01, r02 = (r00 * m00 + r01 * m10 + r02 * m20, r00 * m01 + r01 * m11 + r02 * m21,
                             r00 * m02 + r01 * m12 + r02 * m22)
            r10, r11, r12 = (r10 * m00 + r11 * m10 + r12 * m20, r10 * m01 + r11 * m11 + r12 * m21,
                             r10 * m02 + r11 * m12 + r12 * m22)
            r20, r21, r22 = (r20 * m00 + r21 * m10 + r22 * m20, r20 * m01 + r21 * m11 + r22 * m21,
                             r20 * m02 + r21 * m12 + r22 * m22)
        ox, oy, oz = tip_offset[0], tip_offset[1], tip_offset[2]
        pos_out[k, 0] = px + r00 * ox + r01 * oy + r02 * oz
        pos_out[k, 1] = py + r10 * ox + r11 * oy + r12 * oz
        pos_out[k, 2] = pz + r20 * ox + r21 * oy + r22 * oz
        t = tip_rotation
        rot_out[k, 0, 0] = r00 * t[0, 0] + r01 * t[1, 0] + r02 * t[2, 0]
        rot_out[k, 0, 1] = r00 * t[0, 1] + r01 * t[1, 1] + r02 * t[2, 1]
        rot_out[k, 0, 2] = r00 * t[0, 2] + r01 * t[1, 2] + r02 * t[2, 2]
        rot_out[k, 1, 0] = r10 * t[0, 0] + r11 * t[1, 0] + r12 * t[2, 0]
        rot_out[k, 1, 1] = r10 * t[0, 1] + r11 * t[1, 1] + r12 * t[2, 1]
        rot_out[k, 1, 2] = r10 * t[0, 2] + r11 * t[1, 2] + r12 * t[2, 2]
        rot_out[k, 2, 0] = r20 * t[0, 0] + r21 * t[1, 0] + r22 * t[2, 0]
        rot_out[k, 2, 1] = r20 * t[0, 1] + r21 * t[1, 1] + r22 * t[2, 1]
        rot_out[k, 2, 2] = r20 * t[0, 2] + r21 * t[1, 2] + r22 * t[2, 2]


@numba.njit(cache=True)
def quaternion_kernel(rot: np.ndarray, quat_out: np.ndarray) -> None:
    """
    Write unit quaternions ``(w, x, y, z)``, ``w >= 0``, of rotation matrices ``(N, 3, 3)``.

    Each component's magnitude comes from the diagonal and its sign from the off-diagonal
    differences, which is accurate everywhere without branching on the largest component.
    """
    for k in range(rot.shape[0]):
        r = rot[k]
        w = 0.5 * np.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2]))
        x = 0.5 * np.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2]))
        y = 0.5 * np.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2]))
        z = 0.5 * np.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2]))
        x = np.copysign(x, r[2, 1] - r[1, 2])
        y = np.copysign(y, r[0, 2] - r[2, 0])
        z = np.copysign(z, r[1, 0] - r[0, 1])
        norm = np.sqrt(w * w + x * x + y * y + z * z)
        quat_out[k, 0] = w / norm
        quat_out[k, 1] = x / norm
        quat_out[k, 2] = y / norm
        quat_out[k, 3] = z / norm
