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
    for k in range(q.shape[0]):
        for j in range(q.shape[1]):
            cs[j] = np.cos(q[k, j])
            sn[j] = np.sin(q[k, j])
        if kind == AXIS_CHAIN:
            _axis_chain_pose(cs, sn, codes, offsets, tip_offset, tip_rotation, pos_out,
                             rot_out, k)
        else:
            _chain_pose(cs, sn, offsets, bases, tip_offset, tip_rotation, pos_out, rot_out, k)


@numba.njit(cache=True)
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


# -- edge costs -------------------------------------------------------------------------------
#
# An edge is the straight joint-space segment from a to b, cut into n = ceil(L / delta) equal
# steps; the failure probability is evaluated at the end of each step.  Along the segment the
# joint angles (and, for the planar arm, their running sums) change linearly, so their cosines
# and sines are advanced by angle addition instead of being recomputed.  Points are handled in
# chunks: poses of a chunk, then their probabilities, then the running cost, so that an edge
# that can no longer win stops early.  (Numba function calls with array arguments cost more
# than the arithmetic of one point, so no function is called per point.)
#
# Arm parameters (kind, joint_params, offsets, bases, tip_offset, tip_rotation):
# * PLANAR: the planar chain; joint_params are the link lengths.
# * CHAIN: any revolute chain; offsets, bases, tip_offset, tip_rotation as in chain_kernel.
# * AXIS_CHAIN: a revolute chain whose joint frames are parallel at zero and whose axes are
#   coordinate axes (the iiwa URDF): joint_params are signed axis codes (+-1 x, +-2 y, +-3 z),
#   so that a joint only mixes two columns of the rotation (about 4x less arithmetic).
# Failure parameters: points (F, 3), unit directions (F, 3) (z = 0 in 2-D), rotations (F, 3, 3) of
# the failure orientations, c_fail, and use_orient.

PLANAR = 0
CHAIN = 1
#: [m] a pose this near a failure point is at it (where an edge may start: _start_probability)
AT_FAILURE = 1e-6
AXIS_CHAIN = 2
CHUNK = 16


@numba.njit(cache=True)
def _chunk_poses(cs, sn, cd, sd, b, k0, count, n, kind, joint_params, offsets, bases,
                 tip_offset, tip_rotation, pos, rot):
    """
    Advance the joint cosines/sines count steps; write the poses of points k0+1...

    The last point of the edge (k = n) is recomputed from b so that it lands exactly there.
    """
    n_joints = cs.shape[0]
    for i in range(count):
        k = k0 + i + 1
        for j in range(n_joints):
            c_new = cs[j] * cd[j] - sn[j] * sd[j]
            sn[j] = sn[j] * cd[j] + cs[j] * sd[j]
            cs[j] = c_new
        if k == n:
            angle = 0.0
            for j in range(n_joints):
                angle = angle + b[j] if kind == PLANAR else b[j]
                cs[j] = np.cos(angle)
                sn[j] = np.sin(angle)
        if kind == PLANAR:
            px = 0.0
            py = 0.0
            for j in range(n_joints):
                px += joint_params[j] * cs[j]
                py += joint_params[j] * sn[j]
            pos[i, 0] = px
            pos[i, 1] = py
            pos[i, 2] = 0.0
            continue
        if kind == AXIS_CHAIN:
            _axis_chain_pose(cs, sn, joint_params, offsets, tip_offset, tip_rotation, pos, rot,
                             i)
            continue
        _chain_pose(cs, sn, offsets, bases, tip_offset, tip_rotation, pos, rot, i)


@numba.njit(cache=True, inline='always')
def _chain_pose(cs, sn, offsets, bases, tip_offset, tip_rotation, pos, rot, i):
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
    _tip_pose(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset,
              tip_rotation, pos, rot, i)


@numba.njit(cache=True, inline='always')
def _axis_chain_pose(cs, sn, codes, offsets, tip_offset, tip_rotation, pos, rot, i):
    """Write pose i of an AXIS_CHAIN arm from its joint cosines and sines."""
    px = py = pz = 0.0
    r00, r01, r02 = 1.0, 0.0, 0.0
    r10, r11, r12 = 0.0, 1.0, 0.0
    r20, r21, r22 = 0.0, 0.0, 1.0
    for j in range(offsets.shape[0]):
        ox, oy, oz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
        px += r00 * ox + r01 * oy + r02 * oz
        py += r10 * ox + r11 * oy + r12 * oz
        pz += r20 * ox + r21 * oy + r22 * oz
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
    _tip_pose(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset,
              tip_rotation, pos, rot, i)


@numba.njit(cache=True, inline='always')
def _tip_pose(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset,
              tip_rotation, pos, rot, i):
    """Write pose i: the last joint frame (p, R) moved to the tip by the fixed tip transform."""
    ox, oy, oz = tip_offset[0], tip_offset[1], tip_offset[2]
    pos[i, 0] = px + r00 * ox + r01 * oy + r02 * oz
    pos[i, 1] = py + r10 * ox + r11 * oy + r12 * oz
    pos[i, 2] = pz + r20 * ox + r21 * oy + r22 * oz
    for c in range(3):
        t0, t1, t2 = tip_rotation[0, c], tip_rotation[1, c], tip_rotation[2, c]
        rot[i, 0, c] = r00 * t0 + r01 * t1 + r02 * t2
        rot[i, 1, c] = r10 * t0 + r11 * t1 + r12 * t2
        rot[i, 2, c] = r20 * t0 + r21 * t1 + r22 * t2


# asin(z) = z + z^3 g(z^2) on [0, 1/2]: g fitted to its Taylor series (Chebyshev nodes,
# degree 12); within 1 ulp of libm's asin there, so _arccos is within 2 ulp of libm's acos.
_G0, _G1, _G2, _G3 = (0.16666666666666652, 0.07499999999999062, 0.044642857145245546,
                      0.030381944220602152)
_G4, _G5, _G6, _G7 = (0.02237216971363298, 0.017352468476557165, 0.013970082058240421,
                      0.011490299128017144)
_G8, _G9, _G10, _G11, _G12 = (0.010249877585098172, 0.005773215955924502,
                              0.01653494841483269, -0.013488560155481588,
                              0.027819480814899197)


@numba.njit(cache=True, inline='always')
def _arccos(x):
    """
    Return arccos(x) for x in [-1, 1], inlined and without branches (so loops vectorise).

    |x| <= 1/2: pi/2 - asin(x); beyond: 2 asin(sqrt((1 - |x|) / 2)), reflected for x < 0.
    """
    a = abs(x)
    big = a > 0.5
    z = np.sqrt((1.0 - a) * 0.5) if big else a
    t = z * z
    g = (_G0 + t * (_G1 + t * (_G2 + t * (_G3 + t * (_G4 + t * (_G5 + t * (_G6 + t * (
        _G7 + t * (_G8 + t * (_G9 + t * (_G10 + t * (_G11 + t * _G12))))))))))))
    r = z + z * t * g
    small = 0.5 * np.pi - r if x >= 0.0 else 0.5 * np.pi + r
    large = 2.0 * r if x >= 0.0 else np.pi - 2.0 * r
    return large if big else small


#: From this many failures on, a chunk skips the failures that cannot raise its maximum.
SKIP_FROM = 4


@numba.njit(cache=True, error_model='numpy')
def _chunk_probabilities(pos, rot, count, f_points, f_dirs, f_rots, c_fail, use_orient, prune,
                         soa, p_out, near2=0.0, at_failure=-1.0):
    """
    Write max over failures of P_COORD * (1 - 0.5 D_ORIENT) for each pose of the chunk.

    Each evaluated (failure, point) pair is exact, in an inner loop over the chunk's points
    that the compiler vectorises: the poses are first copied to one contiguous row per
    coordinate (soa, (12, CHUNK)), the arccos is _arccos, and the numpy error model drops the
    division checks that would otherwise keep the loop scalar.  (Bounds per point cost more
    in scalar square roots and divisions than the vector arithmetic they save.)

    Exact pruning per chunk: an upper bound of each failure's probability over the chunk is
    compared with the least maximum found so far among the chunk's points; a failure whose
    bound does not exceed it cannot change any point's maximum and is skipped.  The bound
    takes the chunk's bounding sphere (a point is at least ``D - radius`` from the failure,
    its alpha at most the center's plus ``asin(radius / D)``) and the spread of its
    rotations about the middle pose (the angle to the failure's orientation is at least
    the middle pose's minus the spread), with margins above the kernel's rounding; the
    bounds of all failures are computed in one vectorised loop.  The failure of the highest
    bound goes first, so that the maximum rises early.  The result is the same number, bit
    for bit, as evaluating every failure: a maximum does not depend on the order, nor on
    values that do not win (``prune`` False evaluates them all, for the checks).
    """
    for i in range(count):
        p_out[i] = 0.0
        for k in range(3):
            soa[k, i] = pos[i, k]
        for k in range(9):
            soa[3 + k, i] = rot[i, k // 3, k % 3]
    n_fail = f_points.shape[0]
    if not prune or n_fail < SKIP_FROM or count < 2:
        for f in range(n_fail):
            _failure_into(f, count, soa, f_points, f_dirs, f_rots, c_fail, use_orient,
                          p_out, near2, at_failure)
        return
    # the chunk's bounding sphere (center: mean point) and, about its middle pose's
    # rotation, the largest rotation angle of its poses
    cx = cy = cz = 0.0
    for i in range(count):
        cx += soa[0, i]
        cy += soa[1, i]
        cz += soa[2, i]
    cx /= count
    cy /= count
    cz /= count
    r2 = 0.0
    mid = count // 2
    spread = 0.0
    for i in range(count):
        r2 = max(r2, (soa[0, i] - cx) ** 2 + (soa[1, i] - cy) ** 2 + (soa[2, i] - cz) ** 2)
        if use_orient:
            trace = 0.0
            for k in range(9):
                trace += soa[3 + k, mid] * soa[3 + k, i]
            spread = max(spread, _rotation_angle(trace))
    radius = np.sqrt(r2) * (1.0 + 1e-12) + 1e-12 + np.sqrt(near2)
    # every failure's bound, in one loop without branches that the compiler vectorises
    # (the failure arrays are column-major: EdgeCoster)
    bounds = np.empty(n_fail)
    for f in range(n_fail):
        dx = f_points[f, 0] - cx
        dy = f_points[f, 1] - cy
        dz = f_points[f, 2] - cz
        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
        apart = max(dist, 1e-300)
        gap = max(0.0, dist - radius)
        cos_c = (f_dirs[f, 0] * dx + f_dirs[f, 1] * dy + f_dirs[f, 2] * dz) / apart
        alpha = (_arccos(min(1.0, max(-1.0, cos_c))) + 0.5 * np.pi
                 - _arccos(min(1.0, radius / apart)) + ANGLE_MARGIN)
        ratio = min(1.0, alpha / np.pi)
        ratio = 1.0 if dist <= radius else ratio * ratio * ratio
        factor = 1.0
        if use_orient:
            trace = (f_rots[f, 0, 0] * soa[3, mid] + f_rots[f, 0, 1] * soa[4, mid]
                     + f_rots[f, 0, 2] * soa[5, mid] + f_rots[f, 1, 0] * soa[6, mid]
                     + f_rots[f, 1, 1] * soa[7, mid] + f_rots[f, 1, 2] * soa[8, mid]
                     + f_rots[f, 2, 0] * soa[9, mid] + f_rots[f, 2, 1] * soa[10, mid]
                     + f_rots[f, 2, 2] * soa[11, mid])
            factor = 1.0 - 0.5 * max(0.0, _rotation_angle(trace) - spread
                                     - ANGLE_MARGIN) / np.pi
        bounds[f] = (1.0 + 1e-9) * ratio * factor / (1.0 + c_fail * gap * gap)
    first = 0
    for f in range(n_fail):
        if bounds[f] > bounds[first]:
            first = f
    _failure_into(first, count, soa, f_points, f_dirs, f_rots, c_fail, use_orient, p_out,
                  near2, at_failure)
    least = _least(p_out, count)
    for f in range(n_fail):
        if f != first and bounds[f] > least:
            _failure_into(f, count, soa, f_points, f_dirs, f_rots, c_fail, use_orient,
                          p_out, near2, at_failure)
            least = _least(p_out, count)


#: [rad] added to angles in bounds: above the rounding of arccos near +-1 (~3e-8)
ANGLE_MARGIN = 1e-6


@numba.njit(cache=True, inline='always')
def _rotation_angle(trace):
    """Return the angle in [0, pi] of a rotation from its trace, as the kernel's D_ORIENT."""
    return 2.0 * _arccos(np.sqrt(min(1.0, max(0.0, (trace + 1.0) * 0.25))))


@numba.njit(cache=True, inline='always')
def _least(p_out, count):
    """Return the least value of the chunk's maxima."""
    least = p_out[0]
    for i in range(1, count):
        least = min(least, p_out[i])
    return least


@numba.njit(cache=True, error_model='numpy', inline='always')
def _failure_into(f, count, soa, f_points, f_dirs, f_rots, c_fail, use_orient, p_out, near2,
                  at_failure):
    """Raise each point's maximum in p_out to failure f's probability there."""
    px, py, pz = soa[0], soa[1], soa[2]
    r00, r01, r02, r10, r11, r12 = soa[3], soa[4], soa[5], soa[6], soa[7], soa[8]
    r20, r21, r22 = soa[9], soa[10], soa[11]
    fx, fy, fz = f_points[f, 0], f_points[f, 1], f_points[f, 2]
    ux, uy, uz = f_dirs[f, 0], f_dirs[f, 1], f_dirs[f, 2]
    g = f_rots[f]
    g00, g01, g02, g10, g11, g12 = g[0, 0], g[0, 1], g[0, 2], g[1, 0], g[1, 1], g[1, 2]
    g20, g21, g22 = g[2, 0], g[2, 1], g[2, 2]
    for i in range(count):
        dx = fx - px[i]
        dy = fy - py[i]
        dz = fz - pz[i]
        d2 = dx * dx + dy * dy + dz * dz
        # at the failure itself (d2 <= near2) cos alpha is at_failure: -1 (alpha = pi,
        # ratio 1) as in the paper, +1 (behind it) for where a Hard edge starts
        c = (ux * dx + uy * dy + uz * dz) / np.sqrt(d2) if d2 > near2 else at_failure
        ratio = _arccos(min(1.0, max(-1.0, c))) / np.pi
        p = ratio * ratio * ratio / (1.0 + c_fail * d2)
        # orientation: 1 - 0.5 D_ORIENT from trace(G^T R) (use_orient is constant in the
        # loop, which the compiler hoists)
        trace = (g00 * r00[i] + g01 * r01[i] + g02 * r02[i] + g10 * r10[i] + g11 * r11[i]
                 + g12 * r12[i] + g20 * r20[i] + g21 * r21[i] + g22 * r22[i])
        half_cos = np.sqrt(min(1.0, max(0.0, (trace + 1.0) * 0.25)))
        factor = 1.0 - _arccos(half_cos) / np.pi
        p_out[i] = max(p_out[i], p * factor if use_orient else p)


@numba.njit(cache=True, inline='always')
def _chunk_log_survival(p_buf, count, p_max):
    """Return (sum log(1 - min(p, p_max)), max p) over the chunk, with one logarithm."""
    survival = 1.0
    highest = 0.0
    for i in range(count):
        survival *= 1.0 - min(p_buf[i], p_max)
        highest = max(highest, p_buf[i])
    return np.log(survival), highest


@numba.njit(cache=True, inline='always')
def _descend(p_buf, count, cap, level):
    """
    Return the level after the chunk's points, or -1 if a point is forbidden.

    The rule of a cap (the Hard baseline's Y): a point above the cap is forbidden, except
    while the edge is leaving a region above the cap that it started in, its probability
    never rising on the way out (``level`` is the highest probability still allowed).
    """
    for i in range(count):
        if p_buf[i] > level:
            return -1.0
        level = max(cap, p_buf[i])
    return level


@numba.njit(cache=True)
def _start_probability(cs, sn, n, kind, joint_params, offsets, bases, tip_offset,
                       tip_rotation, f_points, f_dirs, f_rots, c_fail, use_orient, prune, pos, rot,
                       soa, p_buf):
    """
    Return the failure probability at the start of an edge (its cosines and sines).

    A start within AT_FAILURE of a failure point counts as behind it (probability 0 from
    that failure): an arm held where it was blocked is where it came from, and it may leave
    backwards but not go on.  (At the point itself the direction is undefined; the paper's
    alpha = pi would let a Hard edge run on through the obstacle, its probability falling.)
    """
    n_joints = cs.shape[0]
    _chunk_poses(cs.copy(), sn.copy(), np.ones(n_joints), np.zeros(n_joints), cs, -1, 1, n,
                 kind, joint_params, offsets, bases, tip_offset, tip_rotation, pos, rot)
    _chunk_probabilities(pos, rot, 1, f_points, f_dirs, f_rots, c_fail, use_orient, prune, soa,
                         p_buf, AT_FAILURE ** 2, 1.0)
    return p_buf[0]


@numba.njit(cache=True)
def edge_cost_kernel(a, b, limit, delta, length_weight, risk_weight, cap, p_max, kind,
                     joint_params, offsets, bases, tip_offset, tip_rotation,
                     f_points, f_dirs, f_rots, c_fail, use_orient, prune, pos, rot, soa, p_buf):
    """
    Return the cost of edge a -> b, or inf once it reaches limit (it only grows on the way).

    ``length_weight L - risk_weight sum (s/delta) log(1 - p)``, inf if a p > cap is not on the
    way out of a region above the cap that the edge started in (:func:`_descend`; the
    objective's terms, :class:`probdis_ros.model.path_cost.EdgeTerms`).  pos, rot, soa and
    p_buf are buffers for CHUNK points.
    """
    n_joints = a.shape[0]
    length = 0.0
    for j in range(n_joints):
        length += (b[j] - a[j]) ** 2
    length = np.sqrt(length)
    if length == 0.0:
        return 0.0
    n = max(1, int(np.ceil(length / delta - 1e-12)))
    cost = length_weight * length
    if cost >= limit:
        return np.inf
    if f_points.shape[0] == 0:
        return cost
    weight = risk_weight * (length / n) / delta
    cs = np.empty(n_joints)
    sn = np.empty(n_joints)
    cd = np.empty(n_joints)
    sd = np.empty(n_joints)
    run0 = 0.0
    run1 = 0.0
    for j in range(n_joints):
        run0 += a[j]
        run1 += b[j] - a[j]
        angle = run0 if kind == PLANAR else a[j]
        step = (run1 if kind == PLANAR else b[j] - a[j]) / n
        cs[j] = np.cos(angle)
        sn[j] = np.sin(angle)
        cd[j] = np.cos(step)
        sd[j] = np.sin(step)
    level = cap
    if cap < np.inf:
        level = max(cap, _start_probability(cs, sn, n, kind, joint_params, offsets, bases,
                                            tip_offset, tip_rotation, f_points, f_dirs,
                                            f_rots, c_fail, use_orient, prune, pos, rot, soa,
                                            p_buf))
    for k0 in range(0, n, CHUNK):
        count = min(CHUNK, n - k0)
        _chunk_poses(cs, sn, cd, sd, b, k0, count, n, kind, joint_params, offsets, bases,
                     tip_offset, tip_rotation, pos, rot)
        _chunk_probabilities(pos, rot, count, f_points, f_dirs, f_rots, c_fail, use_orient, prune,
                             soa, p_buf)
        log_survival, highest = _chunk_log_survival(p_buf, count, p_max)
        if highest > cap:
            level = _descend(p_buf, count, cap, level)
            if level < 0.0:
                return np.inf
        else:
            level = cap
        cost -= weight * log_survival
        if cost >= limit:
            return np.inf
    return cost


@numba.njit(cache=True, nogil=True)
def edge_costs_kernel(sources, target, base, limits, toward, delta, length_weight,
                      risk_weight, cap, p_max, kind, joint_params, offsets, bases, tip_offset,
                      tip_rotation, f_points, f_dirs, f_rots, c_fail, use_orient, prune, out):
    """
    Write ``base[i] + cost(sources[i] -> target)`` (``target -> sources[i]`` unless toward).

    An edge whose cost reaches ``limits[i]`` is abandoned there and written as inf: exact
    pruning for RRT* rewiring, which only needs edges cheaper than a neighbour's cost.
    """
    pos = np.empty((CHUNK, 3))
    rot = np.empty((CHUNK, 3, 3))
    soa = np.empty((12, CHUNK))
    p_buf = np.empty(CHUNK)
    for i in range(sources.shape[0]):
        a = sources[i] if toward else target
        b = target if toward else sources[i]
        out[i] = base[i] + edge_cost_kernel(a, b, limits[i], delta, length_weight,
                                            risk_weight, cap, p_max, kind, joint_params,
                                            offsets, bases, tip_offset, tip_rotation,
                                            f_points, f_dirs, f_rots, c_fail, use_orient,
                                            prune, pos,
                                            rot, soa, p_buf)


@numba.njit(cache=True)
def farthest_kernel(samples, nodes):
    """
    Return the index of the sample whose nearest node is farthest (squared distances).

    A sample is dropped as soon as a node nearer than the best so far is found: it can no
    longer win, so the answer is the same as from every distance.
    """
    best = -1.0
    best_index = 0
    for i in range(samples.shape[0]):
        nearest = np.inf
        for k in range(nodes.shape[0]):
            d2 = 0.0
            for c in range(samples.shape[1]):
                diff = samples[i, c] - nodes[k, c]
                d2 += diff * diff
            if d2 < nearest:
                nearest = d2
                if nearest <= best:
                    break
        if nearest > best:
            best = nearest
            best_index = i
    return best_index


@numba.njit(cache=True, nogil=True)
def cheapest_edge_kernel(sources, target, base, toward, delta, length_weight, risk_weight,
                         cap, p_max, kind, joint_params, offsets, bases, tip_offset,
                         tip_rotation, f_points, f_dirs, f_rots, c_fail, use_orient, prune):
    """
    Return (i, total) minimising ``base[i] + cost(edge i)``; (-1, inf) if none is finite.

    Best-first: each edge's cost so far (plus its length term, known up front) is a lower
    bound of its total, so the edge with the lowest bound is advanced by a chunk of points
    until one edge is complete with a total no other bound undercuts.  The result is exactly
    the argmin (ties to the lowest index) while most edges are never costed to the end.
    Edges run sources[i] -> target if toward, else target -> sources[i].
    """
    m, n_joints = sources.shape
    bound = np.empty(m)           # lower bound of the total (exact when done)
    level = np.full(m, cap)       # highest point probability still allowed (see _descend)
    done = np.zeros(m, dtype=np.bool_)
    steps = np.zeros(m, dtype=np.int64)
    k_done = np.zeros(m, dtype=np.int64)
    weight = np.zeros(m)
    cs = np.empty((m, n_joints))
    sn = np.empty((m, n_joints))
    cd = np.empty((m, n_joints))
    sd = np.empty((m, n_joints))
    ends = np.empty((m, n_joints))
    for i in range(m):
        a = sources[i] if toward else target
        b = target if toward else sources[i]
        length = 0.0
        for j in range(n_joints):
            length += (b[j] - a[j]) ** 2
        length = np.sqrt(length)
        bound[i] = base[i] + length_weight * length
        if length == 0.0 or f_points.shape[0] == 0:
            done[i] = True
            continue
        n = max(1, int(np.ceil(length / delta - 1e-12)))
        steps[i] = n
        weight[i] = risk_weight * (length / n) / delta
        run0 = 0.0
        run1 = 0.0
        for j in range(n_joints):
            run0 += a[j]
            run1 += b[j] - a[j]
            angle = run0 if kind == PLANAR else a[j]
            step = (run1 if kind == PLANAR else b[j] - a[j]) / n
            cs[i, j] = np.cos(angle)
            sn[i, j] = np.sin(angle)
            cd[i, j] = np.cos(step)
            sd[i, j] = np.sin(step)
            ends[i, j] = b[j]
    pos = np.empty((CHUNK, 3))
    rot = np.empty((CHUNK, 3, 3))
    soa = np.empty((12, CHUNK))
    p_buf = np.empty(CHUNK)
    if cap < np.inf:
        for i in range(m):
            if not done[i]:
                level[i] = max(cap, _start_probability(
                    cs[i], sn[i], steps[i], kind, joint_params, offsets, bases, tip_offset,
                    tip_rotation, f_points, f_dirs, f_rots, c_fail, use_orient, prune, pos, rot,
                    soa,
                    p_buf))
    while True:
        pick = -1
        for i in range(m):   # lowest bound first; on equal bounds a finished edge, then index
            if not np.isfinite(bound[i]):
                continue
            tie_done = bound[i] == bound[pick] and done[i] and not done[pick] if pick >= 0 \
                else False
            if pick < 0 or bound[i] < bound[pick] or tie_done:
                pick = i
        if pick < 0:
            return -1, np.inf
        if done[pick]:
            return pick, bound[pick]
        i = pick
        count = min(CHUNK, steps[i] - k_done[i])
        _chunk_poses(cs[i], sn[i], cd[i], sd[i], ends[i], k_done[i], count, steps[i], kind,
                     joint_params, offsets, bases, tip_offset, tip_rotation, pos, rot)
        _chunk_probabilities(pos, rot, count, f_points, f_dirs, f_rots, c_fail, use_orient, prune,
                             soa, p_buf)
        k_done[i] += count
        log_survival, highest = _chunk_log_survival(p_buf, count, p_max)
        if highest > cap:
            level[i] = _descend(p_buf, count, cap, level[i])
        else:
            level[i] = cap
        if level[i] < 0.0:
            bound[i] = np.inf
        else:
            bound[i] -= weight[i] * log_survival
        if k_done[i] == steps[i]:
            done[i] = True
