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
Forward kinematics of revolute chains, compiled (numba): batches and single poses.

Arm parameters as the kernels take them (``kind, joint_params, offsets, bases, tip_offset,
tip_rotation``, :meth:`probdis_ros.model.arms.Arm.kernel_params`):

* PLANAR: the planar chain; joint_params are the link lengths.
* CHAIN: any revolute chain; joint j moves its child frame by ``offsets[j]`` in the parent
  frame and rotates it by ``bases[j, 0] + cos(q_j) bases[j, 1] + sin(q_j) bases[j, 2]``.
* AXIS_CHAIN: a revolute chain whose joint frames are parallel at zero and whose axes are
  coordinate axes (the iiwa URDF): joint_params are signed axis codes (+-1 x, +-2 y, +-3 z),
  so that a joint only mixes two columns of the rotation (about 4x less arithmetic).
"""

import numba
import numpy as np
from probdis_ros.model.fast_math import sincos_into

PLANAR = 0
CHAIN = 1
AXIS_CHAIN = 2


@numba.njit(cache=True, nogil=True)
def chain_kernel(q: np.ndarray, kind: int, codes: np.ndarray, offsets: np.ndarray,
                 bases: np.ndarray, tip_offset: np.ndarray, tip_rotation: np.ndarray,
                 pos_out: np.ndarray, rot_out: np.ndarray) -> None:
    """
    Forward kinematics of a revolute chain (CHAIN or AXIS_CHAIN, below) for every row of q.

    Joint j moves its child frame by ``offsets[j]`` in the parent frame and rotates it by
    ``bases[j, 0] + cos(q_j) bases[j, 1] + sin(q_j) bases[j, 2]`` (each 3x3); an AXIS_CHAIN
    turns about the coordinate axis ``codes[j]`` instead, with a quarter of the arithmetic.
    """
    cs = np.empty(q.shape[1])
    sn = np.empty(q.shape[1])
    plain_tip = is_identity(tip_rotation)
    for k in range(q.shape[0]):
        for j in range(q.shape[1]):
            cs[j] = np.cos(q[k, j])
            sn[j] = np.sin(q[k, j])
        if kind == AXIS_CHAIN:
            axis_chain_pose(cs, sn, codes, offsets, tip_offset, tip_rotation, pos_out,
                            rot_out, k, plain_tip)
        else:
            chain_pose(cs, sn, offsets, bases, tip_offset, tip_rotation, pos_out, rot_out, k)


@numba.njit(cache=True, nogil=True)
def quaternion_kernel(rot: np.ndarray, quat_out: np.ndarray) -> None:
    """
    Write unit quaternions ``(w, x, y, z)``, ``w >= 0``, of rotation matrices ``(N, 3, 3)``.

    Shepperd's method: the largest of 4w^2, 4x^2, 4y^2, 4z^2 (from the trace and the
    diagonal) is taken by a square root, and the other three components from the
    off-diagonal sums and differences divided by it.  Signs then follow the matrix exactly;
    taking every magnitude from the diagonal instead loses the signs near half-turns, where
    the off-diagonal differences that would carry them are rounding noise.
    """
    for k in range(rot.shape[0]):
        r = rot[k]
        trace = r[0, 0] + r[1, 1] + r[2, 2]
        if trace >= r[0, 0] and trace >= r[1, 1] and trace >= r[2, 2]:
            s = 2.0 * np.sqrt(max(0.0, 1.0 + trace))          # 4w
            w = 0.25 * s
            x = (r[2, 1] - r[1, 2]) / s
            y = (r[0, 2] - r[2, 0]) / s
            z = (r[1, 0] - r[0, 1]) / s
        elif r[0, 0] >= r[1, 1] and r[0, 0] >= r[2, 2]:
            s = 2.0 * np.sqrt(max(0.0, 1.0 + 2.0 * r[0, 0] - trace))   # 4x
            w = (r[2, 1] - r[1, 2]) / s
            x = 0.25 * s
            y = (r[0, 1] + r[1, 0]) / s
            z = (r[0, 2] + r[2, 0]) / s
        elif r[1, 1] >= r[2, 2]:
            s = 2.0 * np.sqrt(max(0.0, 1.0 + 2.0 * r[1, 1] - trace))   # 4y
            w = (r[0, 2] - r[2, 0]) / s
            x = (r[0, 1] + r[1, 0]) / s
            y = 0.25 * s
            z = (r[1, 2] + r[2, 1]) / s
        else:
            s = 2.0 * np.sqrt(max(0.0, 1.0 + 2.0 * r[2, 2] - trace))   # 4z
            w = (r[1, 0] - r[0, 1]) / s
            x = (r[0, 2] + r[2, 0]) / s
            y = (r[1, 2] + r[2, 1]) / s
            z = 0.25 * s
        norm = np.sqrt(w * w + x * x + y * y + z * z)
        if w < 0.0:
            norm = -norm
        quat_out[k, 0] = w / norm
        quat_out[k, 1] = x / norm
        quat_out[k, 2] = y / norm
        quat_out[k, 3] = z / norm


@numba.njit(cache=True, inline='always')
def chain_pose(cs, sn, offsets, bases, tip_offset, tip_rotation, pos, rot, i):
    """Write pose i of a CHAIN arm from its joint cosines and sines."""
    px = py = pz = 0.0
    r00, r01, r02 = 1.0, 0.0, 0.0
    r10, r11, r12 = 0.0, 1.0, 0.0
    r20, r21, r22 = 0.0, 0.0, 1.0
    for j in range(offsets.shape[0]):
        ox, oy, oz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
        px += r00 * ox + r01 * oy + r02 * oz
        py += r10 * ox + r11 * oy + r12 * oz
        pz += r20 * ox + r21 * oy + r22 * oz
        c = cs[j]
        s = sn[j]
        m00 = bases[j, 0, 0, 0] + c * bases[j, 1, 0, 0] + s * bases[j, 2, 0, 0]
        m01 = bases[j, 0, 0, 1] + c * bases[j, 1, 0, 1] + s * bases[j, 2, 0, 1]
        m02 = bases[j, 0, 0, 2] + c * bases[j, 1, 0, 2] + s * bases[j, 2, 0, 2]
        m10 = bases[j, 0, 1, 0] + c * bases[j, 1, 1, 0] + s * bases[j, 2, 1, 0]
        m11 = bases[j, 0, 1, 1] + c * bases[j, 1, 1, 1] + s * bases[j, 2, 1, 1]
        m12 = bases[j, 0, 1, 2] + c * bases[j, 1, 1, 2] + s * bases[j, 2, 1, 2]
        m20 = bases[j, 0, 2, 0] + c * bases[j, 1, 2, 0] + s * bases[j, 2, 2, 0]
        m21 = bases[j, 0, 2, 1] + c * bases[j, 1, 2, 1] + s * bases[j, 2, 2, 1]
        m22 = bases[j, 0, 2, 2] + c * bases[j, 1, 2, 2] + s * bases[j, 2, 2, 2]
        r00, r01, r02 = (r00 * m00 + r01 * m10 + r02 * m20,
                         r00 * m01 + r01 * m11 + r02 * m21,
                         r00 * m02 + r01 * m12 + r02 * m22)
        r10, r11, r12 = (r10 * m00 + r11 * m10 + r12 * m20,
                         r10 * m01 + r11 * m11 + r12 * m21,
                         r10 * m02 + r11 * m12 + r12 * m22)
        r20, r21, r22 = (r20 * m00 + r21 * m10 + r22 * m20,
                         r20 * m01 + r21 * m11 + r22 * m21,
                         r20 * m02 + r21 * m12 + r22 * m22)
    tip_pose(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset,
             tip_rotation, pos, rot, i)


@numba.njit(cache=True, inline='always')
def axis_chain_frame(cs, sn, codes, offsets, n_used=-1):
    """
    Return the last joint frame of an AXIS_CHAIN, ``(px, py, pz, r00, r01, ..., r22)``.

    From its joint cosines and sines; the first ``n_used`` joints are turned (-1: all).
    The arithmetic of :func:`axis_chain_pose` (which moves this frame to the tip).
    """
    px = py = pz = 0.0
    r00, r01, r02 = 1.0, 0.0, 0.0
    r10, r11, r12 = 0.0, 1.0, 0.0
    r20, r21, r22 = 0.0, 0.0, 1.0
    n_turned = offsets.shape[0] if n_used < 0 else n_used
    for j in range(offsets.shape[0]):
        ox, oy, oz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
        if ox == 0.0 and oy == 0.0:
            px += r02 * oz
            py += r12 * oz
            pz += r22 * oz
        else:
            px += r00 * ox + r01 * oy + r02 * oz
            py += r10 * ox + r11 * oy + r12 * oz
            pz += r20 * ox + r21 * oy + r22 * oz
        if j >= n_turned:
            continue
        code = codes[j]
        c = cs[j]
        s = sn[j] if code > 0 else -sn[j]
        axis = abs(code)
        if axis == 3.0:      # R <- R Rz: columns 0, 1
            r00, r01 = r00 * c + r01 * s, r01 * c - r00 * s
            r10, r11 = r10 * c + r11 * s, r11 * c - r10 * s
            r20, r21 = r20 * c + r21 * s, r21 * c - r20 * s
        elif axis == 2.0:    # R <- R Ry: columns 0, 2
            r00, r02 = r00 * c - r02 * s, r02 * c + r00 * s
            r10, r12 = r10 * c - r12 * s, r12 * c + r10 * s
            r20, r22 = r20 * c - r22 * s, r22 * c + r20 * s
        else:                # R <- R Rx: columns 1, 2
            r01, r02 = r01 * c + r02 * s, r02 * c - r01 * s
            r11, r12 = r11 * c + r12 * s, r12 * c - r11 * s
            r21, r22 = r21 * c + r22 * s, r22 * c - r21 * s
    return px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22


@numba.njit(cache=True, inline='always')
def axis_chain_pose(cs, sn, codes, offsets, tip_offset, tip_rotation, pos, rot, i,
                    plain_tip=False, n_used=-1):
    """
    Write pose i of an AXIS_CHAIN arm from its joint cosines and sines.

    Offsets along z alone (the iiwa's) take a third of the arithmetic, and ``plain_tip``
    (an identity tip rotation, :func:`is_identity`) skips the tip rotation; the products they
    skip are exact zeros, so the pose is the same to the bit (but for the sign of a zero).
    ``rot`` None writes the position alone, and then only the first ``n_used`` joints are
    turned (-1: all; :func:`position_joints` tells how many turns the position depends on).
    """
    px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22 = axis_chain_frame(
        cs, sn, codes, offsets, n_used)
    if rot is None:
        ox, oy, oz = tip_offset[0], tip_offset[1], tip_offset[2]
        pos[i, 0] = px + r00 * ox + r01 * oy + r02 * oz
        pos[i, 1] = py + r10 * ox + r11 * oy + r12 * oz
        pos[i, 2] = pz + r20 * ox + r21 * oy + r22 * oz
        return
    (pos[i, 0], pos[i, 1], pos[i, 2], rot[i, 0, 0], rot[i, 0, 1], rot[i, 0, 2], rot[i, 1, 0],
     rot[i, 1, 1], rot[i, 1, 2], rot[i, 2, 0], rot[i, 2, 1], rot[i, 2, 2]) = tip_frame(
        px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset, tip_rotation,
        plain_tip)


@numba.njit(cache=True, nogil=True)
def is_identity(rotation):
    """Tell whether a 3x3 matrix is exactly the identity."""
    for r in range(3):
        for c in range(3):
            if rotation[r, c] != (1.0 if r == c else 0.0):
                return False
    return True


@numba.njit(cache=True, nogil=True)
def position_joints(codes, tip_offset):
    """
    Return how many leading joints of an AXIS_CHAIN move its tip position.

    All but the last when the tip offset lies on the last joint's axis (the iiwa's flange):
    that joint turns the two columns of the rotation the offset has no part in.
    """
    n = codes.shape[0]
    axis = int(abs(codes[n - 1])) - 1
    for c in range(3):
        if c != axis and tip_offset[c] != 0.0:
            return n
    return n - 1


@numba.njit(cache=True, nogil=True)
def positions_kernel(q, rows, kind, codes, offsets, bases, tip_offset, tip_rotation, pos_out):
    """
    Write the tip positions of the rows of q where ``rows`` is True (others are left alone).

    The same numbers as :func:`chain_kernel`'s positions (but for the sign of a zero), with
    less work: no rotation is written and an AXIS_CHAIN skips the joints the position does
    not depend on (:func:`position_joints`) and their sines and cosines.
    """
    n_joints = q.shape[1]
    cs = np.empty(n_joints)
    sn = np.empty(n_joints)
    pos = np.empty((1, 3))
    rot = np.empty((1, 3, 3))
    n_used = position_joints(codes, tip_offset) if kind == AXIS_CHAIN else n_joints
    for k in range(q.shape[0]):
        if not rows[k]:
            continue
        for j in range(n_used):
            cs[j] = np.cos(q[k, j])
            sn[j] = np.sin(q[k, j])
        if kind == AXIS_CHAIN:
            axis_chain_pose(cs, sn, codes, offsets, tip_offset, tip_rotation, pos_out, None, k,
                            False, n_used)
        else:
            chain_pose(cs, sn, offsets, bases, tip_offset, tip_rotation, pos, rot, 0)
            pos_out[k] = pos[0]


#: Rows posed together by :func:`sample_positions_kernel` (its scratch stays in L1/L2).
SAMPLE_BLOCK = 256


@numba.njit(cache=True, nogil=True, error_model='numpy')
def sample_positions_kernel(q, rows, codes, offsets, tip_offset, pos_out):
    """
    Write the tip positions of an AXIS_CHAIN's rows of q where ``rows`` is True, fast.

    Within a few 1e-16 m of :func:`positions_kernel` (the sines and cosines are
    :func:`probdis_ros.model.fast_math.sincos_into`'s), about ten times faster: blocks of
    rows are turned a joint at a time, one coordinate per row of scratch, in loops the
    compiler vectorises.  For the planner's random samples, whose positions only pick the
    one farthest from a tree (a tie within 1e-16 m is all they could change).
    """
    n_used = position_joints(codes, tip_offset)
    block = SAMPLE_BLOCK
    angles = np.empty(block)
    sines = np.empty((n_used, block))
    cosines = np.empty((n_used, block))
    rot = np.empty((9, block))         # row-major R, one coordinate per row
    pos = np.empty((3, block))
    for b0 in range(0, q.shape[0], block):
        count = min(block, q.shape[0] - b0)
        for j in range(n_used):
            for i in range(count):
                angles[i] = q[b0 + i, j]
            sincos_into(angles[:count], sines[j, :count], cosines[j, :count])
        for i in range(count):
            for e in range(9):
                rot[e, i] = 1.0 if e % 4 == 0 else 0.0
            pos[0, i] = pos[1, i] = pos[2, i] = 0.0
        for j in range(offsets.shape[0]):
            ox, oy, oz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
            for r in range(3):
                for i in range(count):
                    pos[r, i] += (rot[3 * r, i] * ox + rot[3 * r + 1, i] * oy
                                  + rot[3 * r + 2, i] * oz)
            if j >= n_used:
                continue
            # R <- R R_axis mixes two columns (a, b): a' = a c + b s, b' = b c - a s, with s
            # negated for a negative code and for y (whose column order is z, x)
            axis = abs(codes[j])
            a, b = (0, 1) if axis == 3.0 else (0, 2) if axis == 2.0 else (1, 2)
            sign = (1.0 if codes[j] > 0 else -1.0) * (-1.0 if axis == 2.0 else 1.0)
            for r in range(3):
                col_a = rot[3 * r + a]
                col_b = rot[3 * r + b]
                for i in range(count):
                    c = cosines[j, i]
                    s = sign * sines[j, i]
                    x = col_a[i]
                    y = col_b[i]
                    col_a[i] = x * c + y * s
                    col_b[i] = y * c - x * s
        ox, oy, oz = tip_offset[0], tip_offset[1], tip_offset[2]
        for i in range(count):
            if rows[b0 + i]:
                for r in range(3):
                    pos_out[b0 + i, r] = (pos[r, i] + rot[3 * r, i] * ox
                                          + rot[3 * r + 1, i] * oy + rot[3 * r + 2, i] * oz)


@numba.njit(cache=True, inline='always')
def tip_pose(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset,
             tip_rotation, pos, rot, i):
    """Write pose i: the last joint frame (p, R) moved to the tip by the fixed tip transform."""
    (pos[i, 0], pos[i, 1], pos[i, 2], rot[i, 0, 0], rot[i, 0, 1], rot[i, 0, 2], rot[i, 1, 0],
     rot[i, 1, 1], rot[i, 1, 2], rot[i, 2, 0], rot[i, 2, 1], rot[i, 2, 2]) = tip_frame(
        px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset, tip_rotation,
        False)


@numba.njit(cache=True, inline='always')
def tip_frame(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset,
              tip_rotation, plain_tip):
    """
    Return the tip's pose ``(x, y, z, R00, R01, ..., R22)`` from the last joint frame (p, R).

    ``plain_tip`` (an identity tip rotation, :func:`is_identity`) with the offset along z
    alone (the iiwa's flange) skips products that are exact zeros: the same pose to the bit
    (but for the sign of a zero).
    """
    ox, oy, oz = tip_offset[0], tip_offset[1], tip_offset[2]
    if plain_tip and ox == 0.0 and oy == 0.0:
        return (px + r02 * oz, py + r12 * oz, pz + r22 * oz,
                r00, r01, r02, r10, r11, r12, r20, r21, r22)
    t = tip_rotation
    return (px + r00 * ox + r01 * oy + r02 * oz,
            py + r10 * ox + r11 * oy + r12 * oz,
            pz + r20 * ox + r21 * oy + r22 * oz,
            r00 * t[0, 0] + r01 * t[1, 0] + r02 * t[2, 0],
            r00 * t[0, 1] + r01 * t[1, 1] + r02 * t[2, 1],
            r00 * t[0, 2] + r01 * t[1, 2] + r02 * t[2, 2],
            r10 * t[0, 0] + r11 * t[1, 0] + r12 * t[2, 0],
            r10 * t[0, 1] + r11 * t[1, 1] + r12 * t[2, 1],
            r10 * t[0, 2] + r11 * t[1, 2] + r12 * t[2, 2],
            r20 * t[0, 0] + r21 * t[1, 0] + r22 * t[2, 0],
            r20 * t[0, 1] + r21 * t[1, 1] + r22 * t[2, 1],
            r20 * t[0, 2] + r21 * t[1, 2] + r22 * t[2, 2])


@numba.njit(cache=True, inline='always')
def lowest_height(cs, sn, kind, joint_params, offsets, bases, tip_offset, shapes):
    """
    Return the lowest z of the arm's collision shapes and of its tip, from joint cos and sin.

    ``shapes`` (S, 9), one row per shape, in chain order: the joint whose frame carries it
    (1-based), its center (3) and unit axis (3, zeros for a sphere) in that frame, half its
    length and its radius.  A cylinder's lowest point lies ``h |u_z| + r sqrt(1 - u_z^2)``
    below its center (u its axis in the world); a sphere's r below.  Only the third row of
    each joint's rotation is needed for heights, a third of the pose's arithmetic.
    Chain arms only (CHAIN, AXIS_CHAIN).
    """
    pz = 0.0
    r20, r21, r22 = 0.0, 0.0, 1.0
    low = np.inf
    row = 0
    n_shapes = shapes.shape[0]
    for j in range(offsets.shape[0]):
        pz += r20 * offsets[j, 0] + r21 * offsets[j, 1] + r22 * offsets[j, 2]
        c = cs[j]
        if kind == AXIS_CHAIN:
            code = joint_params[j]
            s = sn[j] if code > 0 else -sn[j]
            axis = abs(code)
            if axis == 3.0:
                r20, r21 = r20 * c + r21 * s, r21 * c - r20 * s
            elif axis == 2.0:
                r20, r22 = r20 * c - r22 * s, r22 * c + r20 * s
            else:
                r21, r22 = r21 * c + r22 * s, r22 * c - r21 * s
        else:
            s = sn[j]
            t0 = t1 = t2 = 0.0
            for k in range(3):      # the third row times bases[j, 0] + c bases[j, 1] + s ...
                w = r20 if k == 0 else (r21 if k == 1 else r22)
                t0 += w * (bases[j, 0, k, 0] + c * bases[j, 1, k, 0] + s * bases[j, 2, k, 0])
                t1 += w * (bases[j, 0, k, 1] + c * bases[j, 1, k, 1] + s * bases[j, 2, k, 1])
                t2 += w * (bases[j, 0, k, 2] + c * bases[j, 1, k, 2] + s * bases[j, 2, k, 2])
            r20, r21, r22 = t0, t1, t2
        while row < n_shapes and shapes[row, 0] == j + 1:
            zc = pz + r20 * shapes[row, 1] + r21 * shapes[row, 2] + r22 * shapes[row, 3]
            uz = r20 * shapes[row, 4] + r21 * shapes[row, 5] + r22 * shapes[row, 6]
            low = min(low, zc - shapes[row, 7] * abs(uz)
                      - shapes[row, 8] * np.sqrt(max(0.0, 1.0 - uz * uz)))
            row += 1
    return min(low, pz + r20 * tip_offset[0] + r21 * tip_offset[1] + r22 * tip_offset[2])


@numba.njit(cache=True, nogil=True)
def lowest_heights_kernel(q, kind, joint_params, offsets, bases, tip_offset, shapes, out):
    """Write :func:`lowest_height` of each configuration of the batch q (N, n_joints)."""
    cs = np.empty(q.shape[1])
    sn = np.empty(q.shape[1])
    for i in range(q.shape[0]):
        for j in range(q.shape[1]):
            cs[j] = np.cos(q[i, j])
            sn[j] = np.sin(q[i, j])
        out[i] = lowest_height(cs, sn, kind, joint_params, offsets, bases, tip_offset, shapes)
