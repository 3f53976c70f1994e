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
    ``bases[j, 0] + cos(q_j) bases[j, 1] + sin(q_j) bases[j, 2]`` (each 3x3).
    """
    cs = np.empty(q.shape[1])
    sn = np.empty(q.shape[1])
    for k in range(q.shape[0]):
        for j in range(q.shape[1]):
            cs[j] = np.cos(q[k, j])
            sn[j] = np.sin(q[k, j])
        _chain_pose(cs, sn, offsets, bases, tip_offset, tip_rotation, pos_out, rot_out, k)


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
# Failure parameters: points (F, d), unit directions (F, d), rotation matrices (F, 3, 3) of
# the failure orientations, c_fail, and use_orient.

PLANAR = 0
CHAIN = 1
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


@numba.njit(cache=True, inline='always')
def _arccos_upper(x):
    """
    Return a tight upper bound of arccos(x) on [-1, 1] that needs only a square root.

    arccos(x) = 2 arcsin(y) with y = sqrt((1 - x) / 2), and arcsin(y) <= y + (pi/2 - 1) y^3
    on [0, 1] (its Taylor terms beyond y are all positive and y^(2k+1) <= y^3), with
    equality at both ends.
    """
    y = np.sqrt(max(0.0, (1.0 - x) * 0.5))
    return 2.0 * (y + (0.5 * np.pi - 1.0) * y * y * y)


@numba.njit(cache=True)
def _chunk_probabilities(pos, rot, count, dim, f_points, f_dirs, f_rots, c_fail, use_orient,
                         winner, den, p_out):
    """
    Write max over failures of P_COORD * (1 - 0.5 D_ORIENT) for each pose of the chunk.

    ``1 + c d^2`` of every (point, failure) pair comes first, in a loop the compiler
    vectorises (den is a scratch buffer).  Then, per point, the previous point's winning
    failure goes first, and a failure is skipped as soon as an upper bound of its probability
    cannot beat the best so far: ``1 / (1 + c d^2)``, a cheap bound of alpha, the value without
    the orientation factor (at most 1).  The bounds are rigorous (inflated by 1e-9 against
    rounding), so the maximum is exact.  Returns the winner of the last point.
    """
    n_fail = f_points.shape[0]
    for f in range(n_fail):
        fx = f_points[f, 0]
        fy = f_points[f, 1]
        fz = f_points[f, 2] if dim == 3 else 0.0
        for i in range(count):
            dx = fx - pos[i, 0]
            dy = fy - pos[i, 1]
            dz = fz - pos[i, 2]
            den[f, i] = 1.0 + c_fail * (dx * dx + dy * dy + dz * dz)
    for i in range(count):
        px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
        best = 0.0
        for m in range(-1, n_fail):
            f = winner if m < 0 else m
            if f < 0 or (m >= 0 and f == winner):
                continue
            denominator = den[f, i]
            if best * denominator >= 1.0:     # 1 / (1 + c d^2) <= best, without dividing
                continue
            bound = 1.0 / denominator
            dx = f_points[f, 0] - px
            dy = f_points[f, 1] - py
            dz = f_points[f, 2] - pz if dim == 3 else 0.0
            d2 = dx * dx + dy * dy + dz * dz
            if d2 > 0.0:
                dot = f_dirs[f, 0] * dx + f_dirs[f, 1] * dy
                if dim == 3:
                    dot += f_dirs[f, 2] * dz
                cos_alpha = min(1.0, max(-1.0, dot / np.sqrt(d2)))
                upper = _arccos_upper(cos_alpha) / np.pi * (1.0 + 1e-9)
                if upper * upper * upper * bound <= best:
                    continue
                ratio = np.arccos(cos_alpha) / np.pi
            else:
                ratio = 1.0
            p = ratio * ratio * ratio * bound
            if p <= best:
                continue
            if use_orient:
                trace = 0.0
                for r in range(3):
                    for c in range(3):
                        trace += f_rots[f, r, c] * rot[i, r, c]
                half_cos = np.sqrt(min(1.0, max(0.0, (trace + 1.0) * 0.25)))
                # arccos(h) >= 2 sqrt((1 - h) / 2) bounds the factor before the arccos
                lower = 2.0 * np.sqrt(max(0.0, (1.0 - half_cos) * 0.5)) * (1.0 - 1e-9)
                if p * (1.0 - lower / np.pi) <= best:
                    continue
                p *= 1.0 - 0.5 * (2.0 / np.pi) * np.arccos(half_cos)
            if p > best:
                best = p
                winner = f
        p_out[i] = best
    return winner


@numba.njit(cache=True)
def edge_cost_kernel(a, b, delta, length_weight, hard_threshold, p_max, kind,
                     joint_params, offsets, bases, tip_offset, tip_rotation,
                     f_points, f_dirs, f_rots, c_fail, use_orient, pos, rot, den, p_buf):
    """
    Return the cost of edge a -> b.

    Probabilistic mode (hard_threshold < 0): ``-sum (s/delta) log(1 - p) + length_weight L``.
    Hard mode: ``L`` if every p <= hard_threshold, else inf.  pos, rot, den and p_buf are
    scratch buffers for CHUNK points.
    """
    n_joints = a.shape[0]
    length = 0.0
    for j in range(n_joints):
        length += (b[j] - a[j]) ** 2
    length = np.sqrt(length)
    if length == 0.0:
        return 0.0
    n = max(1, int(np.ceil(length / delta - 1e-12)))
    hard = hard_threshold >= 0.0
    cost = length if hard else length_weight * length
    if f_points.shape[0] == 0:
        return cost
    weight = (length / n) / delta
    dim = f_points.shape[1]
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
    winner = -1
    for k0 in range(0, n, CHUNK):
        count = min(CHUNK, n - k0)
        _chunk_poses(cs, sn, cd, sd, b, k0, count, n, kind, joint_params, offsets, bases,
                     tip_offset, tip_rotation, pos, rot)
        winner = _chunk_probabilities(pos, rot, count, dim, f_points, f_dirs, f_rots, c_fail,
                                      use_orient, winner, den, p_buf)
        for i in range(count):
            p = p_buf[i]
            if hard:
                if p > hard_threshold:
                    return np.inf
            else:
                cost -= weight * np.log1p(-min(p, p_max))
    return cost


@numba.njit(cache=True, nogil=True)
def edge_costs_kernel(sources, target, base, toward, delta, length_weight, hard_threshold,
                      p_max, kind, joint_params, offsets, bases, tip_offset, tip_rotation,
                      f_points, f_dirs, f_rots, c_fail, use_orient, out):
    """Write ``base[i] + cost(sources[i] -> target)`` (``target -> sources[i]`` unless toward)."""
    pos = np.empty((CHUNK, 3))
    rot = np.empty((CHUNK, 3, 3))
    den = np.empty((f_points.shape[0], CHUNK))
    p_buf = np.empty(CHUNK)
    for i in range(sources.shape[0]):
        a = sources[i] if toward else target
        b = target if toward else sources[i]
        out[i] = base[i] + edge_cost_kernel(a, b, delta, length_weight, hard_threshold, p_max,
                                            kind, joint_params, offsets, bases, tip_offset,
                                            tip_rotation, f_points, f_dirs, f_rots, c_fail,
                                            use_orient, pos, rot, den, p_buf)


@numba.njit(cache=True)
def farthest_kernel(samples, nodes):
    """Return the index of the sample whose nearest node is farthest (squared distances)."""
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
        if nearest > best:
            best = nearest
            best_index = i
    return best_index


@numba.njit(cache=True, nogil=True)
def cheapest_edge_kernel(sources, target, base, toward, delta, length_weight, hard_threshold,
                         p_max, kind, joint_params, offsets, bases, tip_offset, tip_rotation,
                         f_points, f_dirs, f_rots, c_fail, use_orient):
    """
    Return (i, total) minimising ``base[i] + cost(edge i)``; (-1, inf) if none is finite.

    Best-first: each edge's cost so far (plus its length term, known up front) is a lower
    bound of its total, so the edge with the lowest bound is advanced by a chunk of points
    until one edge is complete with a total no other bound undercuts.  The result is exactly
    the argmin (ties to the lowest index) while most edges are never costed to the end.
    Edges run sources[i] -> target if toward, else target -> sources[i].
    """
    m, n_joints = sources.shape
    hard = hard_threshold >= 0.0
    bound = np.empty(m)           # lower bound of the total (exact when done)
    done = np.zeros(m, dtype=np.bool_)
    steps = np.zeros(m, dtype=np.int64)
    k_done = np.zeros(m, dtype=np.int64)
    weight = np.zeros(m)
    winner = np.full(m, -1, dtype=np.int64)
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
        bound[i] = base[i] + (length if hard else length_weight * length)
        if length == 0.0 or f_points.shape[0] == 0:
            done[i] = True
            continue
        n = max(1, int(np.ceil(length / delta - 1e-12)))
        steps[i] = n
        weight[i] = (length / n) / delta
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
    den = np.empty((f_points.shape[0], CHUNK))
    p_buf = np.empty(CHUNK)
    dim = f_points.shape[1] if f_points.shape[0] > 0 else 3
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
        winner[i] = _chunk_probabilities(pos, rot, count, dim, f_points, f_dirs, f_rots,
                                         c_fail, use_orient, winner[i], den, p_buf)
        k_done[i] += count
        for r in range(count):
            p = p_buf[r]
            if hard:
                if p > hard_threshold:
                    bound[i] = np.inf
                    break
            else:
                bound[i] -= weight[i] * np.log1p(-min(p, p_max))
        if k_done[i] == steps[i]:
            done[i] = True
