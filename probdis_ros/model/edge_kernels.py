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
Compiled edge costs (numba): the failure probability along straight joint-space edges.

An edge is the straight joint-space segment from a to b, cut into n = ceil(L / delta) equal
steps; the failure probability is evaluated at the end of each step.  Along the segment the
joint angles (and, for the planar arm, their running sums) change linearly, so their cosines
and sines are advanced by angle addition instead of being recomputed.  Points are handled in
chunks: poses of a chunk, then their probabilities, then the running cost, so that an edge
that can no longer win stops early.  (Numba function calls with array arguments cost more
than the arithmetic of one point, so no function is called per point.)

Arm parameters as in :mod:`probdis_ros.model.kinematics`.  Failure parameters, one row per
coordinate (so that a map of any size has one numba type, C-contiguous, and a loop over the
failures reads each coordinate contiguously): points (4, F) (the fourth row 1 for a
failure, 0 for padding), unit directions (3, F) (z = 0 in 2-D), rotations (3, 3, F) of the
failure orientations (F: the map's failures, padded to a multiple of VECTOR from 2 VECTOR
on with copies of the last, which no kernel evaluates: :func:`padded_count`), c_fail as the
triple (C_FAIL, 1 / reach^2, least point cost) (0: no reach, the paper's kernel; the least
cost any point of any edge adds per unit of weight, from
:mod:`probdis_ros.model.least_probability`, 0: none known), and use_orient.  The arm's
table (:mod:`probdis_ros.model.table`): its collision shapes (S, 9) and the floor no point
may go below (-inf: no table, and nothing is checked).
"""

import numba
import numpy as np
from probdis_ros.model.fast_math import arccos, rotation_angle
from probdis_ros.model.kinematics import (
    AXIS_CHAIN,
    axis_chain_frame,
    chain_pose,
    is_identity,
    lowest_height,
    PLANAR,
    tip_frame,
)

#: [m] a pose this near a failure point is at it (where an edge may start: _start_probability)
AT_FAILURE = 1e-6
#: [m] along an edge (not at its start), a point this near a failure point is on it, where
#: cos alpha is -1 (alpha = pi, ratio 1), as in the paper at the failure itself
#: (_rows_probabilities); nearer than this the direction to the failure is rounding's, and an
#: edge that ends on a failure's configuration got any ratio from 0 to 1
AT_FAILURE_POINT = 1e-9
ALONG_NEAR2 = AT_FAILURE_POINT ** 2
#: cos(angle / 2) of a turn from a failure's orientation above which the turn is none: its
#: arccos has an error of about 1e-8 rad from the rounding of the rotations alone (a
#: pose on a failure's could weigh it by any factor within 1e-8 of 1, and -log(1 - p)
#: turned that into an edge cost up to 1.5 apart); this is a turn of about 3e-7 rad
AT_FAILURE_HALF_COS = 1.0 - 1e-14
ALONG_AT_FAILURE = -1.0
CHUNK = 16


@numba.njit(cache=True, nogil=True)
def _chunk_poses(cs, sn, cd, sd, b, k0, count, n, kind, joint_params, offsets, bases,
                 tip_offset, tip_rotation, shapes, floor, pos, rot, soa):
    """
    Advance the joint cosines/sines count steps; write the poses of points k0+1... to soa.

    The last point of the edge (k = n) is recomputed from b so that it lands exactly there.
    The poses go to rows 0-11 of the :func:`workspace` soa, one row per coordinate: an
    AXIS_CHAIN's straight there (as :func:`axis_chain_pose` computes them), the others
    through pos and rot.  Return the lowest height of the arm at these points
    (:func:`lowest_height`), or inf without a table (floor -inf).
    """
    n_joints = cs.shape[0]
    plain_tip = is_identity(tip_rotation)
    low = np.inf
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
        if floor > -np.inf:
            low = min(low, lowest_height(cs, sn, kind, joint_params, offsets, bases,
                                         tip_offset, shapes))
        if kind == AXIS_CHAIN:
            # axis_chain_pose's pose, written to the rows
            px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22 = axis_chain_frame(
                cs, sn, joint_params, offsets)
            (soa[0, i], soa[1, i], soa[2, i], soa[3, i], soa[4, i], soa[5, i], soa[6, i],
             soa[7, i], soa[8, i], soa[9, i], soa[10, i], soa[11, i]) = tip_frame(
                px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, tip_offset,
                tip_rotation, plain_tip)
            continue
        chain_pose(cs, sn, offsets, bases, tip_offset, tip_rotation, pos, rot, i)
    if kind != AXIS_CHAIN:
        _to_rows(pos, rot, count, soa)
    return low


@numba.njit(cache=True, inline='always')
def _to_rows(pos, rot, count, soa):
    """Copy poses pos (count, 3) and rot (count, 3, 3) to rows 0-11 of the workspace soa."""
    for i in range(count):
        for k in range(3):
            soa[k, i] = pos[i, k]
        for k in range(9):
            soa[3 + k, i] = rot[i, k // 3, k % 3]


#: From this many failures on, a chunk skips the failures that cannot raise its maximum.
SKIP_FROM = 4


@numba.njit(cache=True, nogil=True)
def _chunk_probabilities(pos, rot, count, f_points, f_dirs, f_rots, c_fail, use_orient, prune,
                         soa, p_out, near2, at_failure):
    """Write :func:`_rows_probabilities` of the poses pos (count, 3) and rot (count, 3, 3)."""
    _to_rows(pos, rot, count, soa)
    _rows_probabilities(count, f_points, f_dirs, f_rots, c_fail, use_orient, prune, soa, p_out,
                        near2, at_failure)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _rows_probabilities(count, f_points, f_dirs, f_rots, c_fail, use_orient, prune, soa, p_out,
                        near2, at_failure):
    """
    Write max over failures of P_COORD * (1 - 0.5 D_ORIENT) for each pose of the chunk.

    The poses are in rows 0-11 of soa, one contiguous row per coordinate
    (:func:`_chunk_poses`).  Each evaluated (failure, point) pair is exact, in an inner loop
    over the chunk's points that the compiler vectorises: the arccos is fast_math's, and the
    numpy error model drops the division checks that would otherwise keep the loop scalar.
    (Bounds per point cost more in scalar square roots and divisions than the vector
    arithmetic they save.)  The rows are indexed in place (``soa[k, i]``), never taken as
    views, and no function with array arguments is inlined in the loops: numba counts a
    view's or an inlined argument's references with atomic increments and decrements, and
    the loops with them cost a chunk about as much as the arithmetic of a failure (1.26
    against 0.82 us a chunk at 19 failures).

    Exact pruning per chunk: an upper bound of each failure's probability over the chunk is
    compared with the least maximum found so far among the chunk's points; a failure whose
    bound does not exceed it cannot change any point's maximum and is skipped.  The bound
    takes the chunk's bounding sphere (a point is at least ``D - radius`` from the failure,
    its alpha at most the center's plus ``asin(radius / D)``) and the spread of its
    rotations about the middle pose (the angle to the failure's orientation is at least
    the middle pose's minus the spread), with margins above the kernel's rounding; the
    bounds of all failures are computed in one vectorised loop (with cheap upper bounds of
    asin and of the rotation angle, ``ASIN_CUBE``).  The failure of the highest bound goes
    first, so that the maximum rises early, then the others in order, each only if its
    bound is still above the least maximum (one loop: one copy of the evaluation to
    compile; sorting the others by bound made no plan faster), and the orientation
    factor of its bound spares most of them the factor (the evaluation loop).  The result
    is the same number, bit for bit, as evaluating every failure: a maximum does not depend
    on the order, nor on values that do not win (``prune`` False evaluates them all, for the
    checks).  ``soa`` is the :func:`workspace` of the map.
    """
    for i in range(count):
        p_out[i] = 0.0
    n_fail = f_points.shape[1]
    pruned = prune and n_fail >= SKIP_FROM and count >= 2
    first = 0
    if pruned:
        # the chunk's bounding sphere and every failure's bound, in one loop without
        # branches that the compiler vectorises (the failure arrays hold one row per
        # coordinate: EdgeCoster); rows 12 and 14 of the workspace hold the bounds and
        # their orientation factors
        cx, cy, cz, radius, mid, spread = _sphere(soa, count, use_orient, near2)
        m00, m01, m02 = soa[3, mid], soa[4, mid], soa[5, mid]
        m10, m11, m12 = soa[6, mid], soa[7, mid], soa[8, mid]
        m20, m21, m22 = soa[9, mid], soa[10, mid], soa[11, mid]
        for f in range(n_fail):
            dx = f_points[0, f] - cx
            dy = f_points[1, f] - cy
            dz = f_points[2, f] - cz
            dist = np.sqrt(dx * dx + dy * dy + dz * dz)
            inverse = 1.0 / max(dist, 1e-300)
            gap = max(0.0, dist - radius)
            # alpha <= the center's + asin(x), x = radius / dist, and asin(x) <= x +
            # (pi/2 - 1) x^3 on [0, 1] ((asin(x) - x) / x^3 rises to pi/2 - 1 at 1)
            cos_c = (f_dirs[0, f] * dx + f_dirs[1, f] * dy + f_dirs[2, f] * dz) * inverse
            x = min(1.0, radius * inverse)
            alpha = (arccos(min(1.0, max(-1.0, cos_c))) + x + ASIN_CUBE * x * x * x
                     + ANGLE_MARGIN)
            ratio = min(1.0, alpha * INV_PI)
            ratio = 1.0 if dist <= radius else ratio * ratio * ratio
            factor = 1.0
            if use_orient:
                trace = (f_rots[0, 0, f] * m00 + f_rots[0, 1, f] * m01
                         + f_rots[0, 2, f] * m02 + f_rots[1, 0, f] * m10
                         + f_rots[1, 1, f] * m11 + f_rots[1, 2, f] * m12
                         + f_rots[2, 0, f] * m20 + f_rots[2, 1, f] * m21
                         + f_rots[2, 2, f] * m22)
                # the angle from trace = 1 + 2 cos(angle): one arccos, within ~5e-8 rad
                # of the kernel's half-angle form (below ANGLE_MARGIN)
                angle = arccos(min(1.0, max(-1.0, (trace - 1.0) * 0.5)))
                factor = 1.0 - 0.5 * max(0.0, angle - spread - ANGLE_MARGIN) * INV_PI
            soa[14, f] = factor
            taper = max(0.0, 1.0 - gap * gap * c_fail[1])
            soa[12, f] = ((1.0 + 1e-9) * ratio * factor * (taper * taper)
                          / (1.0 + c_fail[0] * gap * gap))
        for f in range(n_fail):
            if soa[12, f] > soa[12, first]:
                first = f
    # the failure of the highest bound first, then the others in order, each only while its
    # bound exceeds the least maximum so far (no point starts above 0); a padding column
    # is skipped (a copy of the last failure: never first, its bound not above that one's)
    least = 0.0 if pruned else -1.0
    for slot in range(n_fail):
        f = first if slot == 0 else slot - 1 if slot <= first else slot
        most = soa[14, f] if pruned else 1.0
        if (pruned and soa[12, f] <= least) or f_points[3, f] == 0.0:
            continue
        # failure f's probability at each point raises that point's maximum in p_out (written
        # out here, not an inlined function: its array arguments would cost atomic reference
        # counts per failure).  With orientation, in two passes: P_COORD first (kept in row
        # 13); only if P_COORD times ``most``, an upper bound of the orientation factor over
        # the chunk (the chunk bound's: 1 unpruned), exceeds some point's maximum is the
        # factor computed, for the whole chunk.  Most failures that pass the chunk's bound
        # lose already there (on the 400-failure map 5 of 43 per chunk go on, against 20 with
        # a bound of 1), and the factor is three of the eight square roots and divisions per
        # point.  The numbers are those of one pass: the same operations on the same values
        # (a product of non-negative numbers rounds monotonically, so coord * factor <=
        # coord * most wherever factor <= most).  At the failure itself (d2 <= near2) cos
        # alpha is at_failure: -1 (alpha = pi, ratio 1) as in the paper, +1 (behind it) for
        # where a Hard edge starts.
        fx, fy, fz = f_points[0, f], f_points[1, f], f_points[2, f]
        ux, uy, uz = f_dirs[0, f], f_dirs[1, f], f_dirs[2, f]
        higher = 0
        if not use_orient:
            for i in range(count):
                p = _coord_probability(fx - soa[0, i], fy - soa[1, i], fz - soa[2, i], ux, uy,
                                       uz, c_fail, near2, at_failure)
                p_out[i] = max(p_out[i], p)
        else:
            for i in range(count):
                p = _coord_probability(fx - soa[0, i], fy - soa[1, i], fz - soa[2, i], ux, uy,
                                       uz, c_fail, near2, at_failure)
                soa[13, i] = p
                higher += 1 if p * most > p_out[i] else 0
        if higher > 0:
            # orientation: 1 - 0.5 D_ORIENT from trace(G^T R)
            g00, g01, g02 = f_rots[0, 0, f], f_rots[0, 1, f], f_rots[0, 2, f]
            g10, g11, g12 = f_rots[1, 0, f], f_rots[1, 1, f], f_rots[1, 2, f]
            g20, g21, g22 = f_rots[2, 0, f], f_rots[2, 1, f], f_rots[2, 2, f]
            for i in range(count):
                trace = (g00 * soa[3, i] + g01 * soa[4, i] + g02 * soa[5, i]
                         + g10 * soa[6, i] + g11 * soa[7, i] + g12 * soa[8, i]
                         + g20 * soa[9, i] + g21 * soa[10, i] + g22 * soa[11, i])
                half_cos = np.sqrt(min(1.0, max(0.0, (trace + 1.0) * 0.25)))
                half_cos = 1.0 if half_cos > AT_FAILURE_HALF_COS else half_cos
                factor = 1.0 - arccos(half_cos) / np.pi
                p_out[i] = max(p_out[i], soa[13, i] * factor)
        if pruned:
            least = _least(p_out, count)


@numba.njit(cache=True, inline='always')
def _sphere(soa, count, use_orient, near2):
    """
    Return (cx, cy, cz, radius, mid, spread) of a chunk's poses in the workspace.

    Their bounding sphere about the mean point (the radius widened by margins above the
    rounding and by sqrt(near2)) and, about the middle pose's rotation, the largest
    rotation angle among them (0 without orientation).
    """
    cx = cy = cz = 0.0
    for i in range(count):
        cx += soa[0, i]
        cy += soa[1, i]
        cz += soa[2, i]
    cx /= count
    cy /= count
    cz /= count
    r2 = 0.0
    for i in range(count):
        r2 = max(r2, (soa[0, i] - cx) ** 2 + (soa[1, i] - cy) ** 2 + (soa[2, i] - cz) ** 2)
    mid = count // 2
    spread = 0.0
    if use_orient:
        # the angle falls as the trace rises: the largest angle is the least trace's (to
        # rounding, far below ANGLE_MARGIN), one arccos instead of one per pose
        least_trace = np.inf
        for i in range(count):
            trace = 0.0
            for k in range(9):
                trace += soa[3 + k, mid] * soa[3 + k, i]
            least_trace = min(least_trace, trace)
        spread = rotation_angle(least_trace)
    radius = np.sqrt(r2) * (1.0 + 1e-12) + 1e-12 + np.sqrt(near2)
    return cx, cy, cz, radius, mid, spread


#: [rad] added to angles in bounds: above the rounding of arccos near +-1 (~3e-8)
ANGLE_MARGIN = 1e-6
#: pi/2 - 1, rounded up: asin(x) <= x + ASIN_CUBE x^3 on [0, 1]
ASIN_CUBE = 0.5707963267948967
#: 1 / pi, rounded up (bounds multiply by it)
INV_PI = (1.0 + 1e-15) / np.pi


#: Failures bounded at once by the vectorised loop of :func:`_rows_probabilities` (AVX-512)
VECTOR = 8


@numba.njit(cache=True)
def padded_count(n_fail):
    """
    Return the columns of a map of n_fail failures in the kernels' arrays.

    From 2 VECTOR failures on, a multiple of VECTOR: the compiled bound loop of
    :func:`_rows_probabilities` runs VECTOR failures at a time from 2 VECTOR on, and the
    rest one at a time, each costing about as much as VECTOR together.  The padding
    columns are copies of the last failure (finite: NaN columns made plans 10 % slower),
    flagged 0 in the fourth row of the points, and never evaluated.
    """
    if n_fail < 2 * VECTOR:
        return n_fail
    return n_fail + (-n_fail) % VECTOR


@numba.njit(cache=True, nogil=True)
def workspace(n_fail):
    """
    Return the scratch rows of :func:`_rows_probabilities` for a map of n_fail failures.

    Rows 0-11: a chunk's poses, one row per coordinate; row 12: the failures' bounds;
    row 13: one failure's P_COORD at the chunk's points; row 14: the orientation factor
    of each failure's bound.
    """
    return np.empty((15, max(CHUNK, padded_count(n_fail))))


@numba.njit(cache=True, inline='always')
def _least(p_out, count):
    """Return the least value of the chunk's maxima (pairwise: a short chain of minima)."""
    if count != CHUNK:
        least = p_out[0]
        for i in range(1, count):
            least = min(least, p_out[i])
        return least
    a0 = min(min(p_out[0], p_out[1]), min(p_out[2], p_out[3]))
    a1 = min(min(p_out[4], p_out[5]), min(p_out[6], p_out[7]))
    a2 = min(min(p_out[8], p_out[9]), min(p_out[10], p_out[11]))
    a3 = min(min(p_out[12], p_out[13]), min(p_out[14], p_out[15]))
    return min(min(a0, a1), min(a2, a3))


@numba.njit(cache=True, error_model='numpy', inline='always')
def _coord_probability(dx, dy, dz, ux, uy, uz, c_fail, near2, at_failure):
    """
    Return P_COORD of one failure at offset (dx, dy, dz) from it to the point.

    c_fail starts (C_FAIL, 1 / reach^2): the taper of FailureMap.probability, which is exactly
    1.0 with no reach (0), so that the paper's kernel gives the same numbers bit for bit.
    """
    d2 = dx * dx + dy * dy + dz * dz
    c = (ux * dx + uy * dy + uz * dz) / np.sqrt(d2) if d2 > near2 else at_failure
    ratio = arccos(min(1.0, max(-1.0, c))) / np.pi
    taper = max(0.0, 1.0 - d2 * c_fail[1])
    return ratio * ratio * ratio * (taper * taper) / (1.0 + c_fail[0] * d2)


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


@numba.njit(cache=True, inline='always')
def _edge_rotations(a, b, n, kind, cs, sn, cd, sd):
    """
    Write the edge a -> b's first joint angles and per-step increments as cos and sin.

    On a planar chain the angles are cumulative (absolute link directions).
    """
    run0 = 0.0
    run1 = 0.0
    for j in range(a.shape[0]):
        run0 += a[j]
        run1 += b[j] - a[j]
        angle = run0 if kind == PLANAR else a[j]
        step = (run1 if kind == PLANAR else b[j] - a[j]) / n
        cs[j] = np.cos(angle)
        sn[j] = np.sin(angle)
        cd[j] = np.cos(step)
        sd[j] = np.sin(step)


@numba.njit(cache=True, nogil=True)
def _start_probability(cs, sn, n, kind, joint_params, offsets, bases, tip_offset,
                       tip_rotation, shapes, f_points, f_dirs, f_rots, c_fail, use_orient, prune,
                       pos, rot, soa, p_buf):
    """
    Return the failure probability at the start of an edge (its cosines and sines).

    A start within AT_FAILURE of a failure point counts as behind it (probability 0 from
    that failure): an arm held where it was blocked is where it came from, and it may leave
    backwards but not go on.  (At the point itself the direction is undefined; the paper's
    alpha = pi would let a Hard edge run on through the obstacle, its probability falling.)
    """
    n_joints = cs.shape[0]
    one = np.int64(1)     # not a literal 1: a literal argument would compile a kernel again
    _chunk_poses(cs.copy(), sn.copy(), np.ones(n_joints), np.zeros(n_joints), cs, -one, one, n,
                 kind, joint_params, offsets, bases, tip_offset, tip_rotation, shapes, -np.inf,
                 pos, rot, soa)
    _rows_probabilities(one, f_points, f_dirs, f_rots, c_fail, use_orient, prune, soa, p_buf,
                        AT_FAILURE ** 2, 1.0)
    return p_buf[0]


@numba.njit(cache=True, inline='always')
def _ground(cs, sn, kind, joint_params, offsets, bases, tip_offset, shapes, floor):
    """
    Return how low an edge starting at (cs, sn) may take the arm: the floor (-inf: no table).

    An edge that starts lower (an arm left near the table) may not go lower than its start:
    it can leave, upwards, but never sink further.
    """
    if floor == -np.inf:
        return floor
    return min(floor, lowest_height(cs, sn, kind, joint_params, offsets, bases, tip_offset,
                                    shapes))


@numba.njit(cache=True, nogil=True)
def edge_cost_kernel(a, b, limit, delta, length_weight, risk_weight, cap, p_max, kind,
                     joint_params, offsets, bases, tip_offset, tip_rotation, shapes, floor,
                     f_points, f_dirs, f_rots, c_fail, use_orient, prune, pos, rot, soa, p_buf):
    """
    Return the cost of edge a -> b, or inf once it reaches limit (it only grows on the way).

    Also inf as soon as the cost so far and the remaining points at their least cost
    (c_fail[2], :func:`cheapest_edge_kernel`) reach limit: the cost would reach it too.

    ``length_weight L - risk_weight sum (s/delta) log(1 - p)``, inf if a p > cap is not on the
    way out of a region above the cap that the edge started in (:func:`_descend`; the
    objective's terms, :class:`probdis_ros.model.path_cost.EdgeTerms`), and inf if a point
    takes the arm below the floor (:func:`_ground`).  pos, rot, soa and p_buf are buffers
    for CHUNK points.
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
    if f_points.shape[1] == 0 and floor == -np.inf:
        return cost
    weight = risk_weight * (length / n) / delta
    # the least each point adds (:func:`cheapest_edge_kernel`)
    tail = weight * c_fail[2] if prune and limit < np.inf else 0.0
    if tail > 0.0 and cost + _ahead(tail, n, cost) >= limit:
        return np.inf
    cs = np.empty(n_joints)
    sn = np.empty(n_joints)
    cd = np.empty(n_joints)
    sd = np.empty(n_joints)
    _edge_rotations(a, b, n, kind, cs, sn, cd, sd)
    ground = _ground(cs, sn, kind, joint_params, offsets, bases, tip_offset, shapes, floor)
    level = cap
    if cap < np.inf:
        level = max(cap, _start_probability(cs, sn, n, kind, joint_params, offsets, bases,
                                            tip_offset, tip_rotation, shapes, f_points, f_dirs,
                                            f_rots, c_fail, use_orient, prune, pos, rot, soa,
                                            p_buf))
    for k0 in range(0, n, CHUNK):
        count = min(CHUNK, n - k0)
        if k0 > 0 and tail > 0.0 and cost + _ahead(tail, n - k0, cost) >= limit:
            return np.inf
        if _chunk_poses(cs, sn, cd, sd, b, k0, count, n, kind, joint_params, offsets, bases,
                        tip_offset, tip_rotation, shapes, floor, pos, rot, soa) < ground:
            return np.inf
        _rows_probabilities(count, f_points, f_dirs, f_rots, c_fail, use_orient, prune, soa,
                            p_buf, ALONG_NEAR2, ALONG_AT_FAILURE)
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
                      tip_rotation, shapes, floor, f_points, f_dirs, f_rots, c_fail, use_orient,
                      prune, out):
    """
    Write ``base[i] + cost(sources[i] -> target)`` (``target -> sources[i]`` unless toward).

    An edge whose cost reaches ``limits[i]`` is abandoned there and written as inf: exact
    pruning for RRT* rewiring, which only needs edges cheaper than a neighbour's cost.
    """
    pos = np.empty((CHUNK, 3))
    rot = np.empty((CHUNK, 3, 3))
    soa = workspace(f_points.shape[1])
    p_buf = np.empty(CHUNK)
    for i in range(sources.shape[0]):
        a = sources[i] if toward else target
        b = target if toward else sources[i]
        out[i] = base[i] + edge_cost_kernel(a, b, limits[i], delta, length_weight,
                                            risk_weight, cap, p_max, kind, joint_params,
                                            offsets, bases, tip_offset, tip_rotation,
                                            shapes, floor, f_points, f_dirs, f_rots, c_fail,
                                            use_orient,
                                            prune, pos,
                                            rot, soa, p_buf)


@numba.njit(cache=True, inline='always')
def _ahead(tail, remaining, so_far):
    """
    Return a lower bound of what an edge's remaining points add to its cost so far.

    tail is the least a point adds (its weight times the least point cost, c_fail[2]),
    less margins above the rounding of the chunks' sums (:func:`edge_cost_kernel`).
    """
    if tail == 0.0 or remaining == 0:
        return 0.0
    return max(0.0, tail * remaining - 1e-12 * abs(so_far))


@numba.njit(cache=True, nogil=True)
def cheapest_edge_kernel(sources, target, base, toward, delta, length_weight, risk_weight,
                         cap, p_max, kind, joint_params, offsets, bases, tip_offset,
                         tip_rotation, shapes, floor, f_points, f_dirs, f_rots, c_fail,
                         use_orient, prune):
    """
    Return (i, total) minimising ``base[i] + cost(edge i)``; (-1, inf) if none is finite.

    Best-first: each edge's cost so far (plus its length term, known up front) is a lower
    bound of its total, so the edge with the lowest bound is advanced by a chunk of points
    until one edge is complete with a total no other bound undercuts.  The result is exactly
    the least total while most edges are never costed to the end; on equal totals an edge
    already complete wins over one that is not, then the lowest index (numpy's argmin takes
    the lowest index alone: the Python loop and the planner's recorded episodes follow this
    kernel).
    Edges run sources[i] -> target if toward, else target -> sources[i].

    With a least point cost (c_fail[2], the least cost any point adds per unit of weight:
    :mod:`probdis_ros.model.least_probability`; 0: none), each bound also counts the
    edge's remaining points at that cost (:func:`_ahead`): a tighter lower bound, so that
    losing edges stop sooner (a fifth to a third fewer points in RRT*'s choice of parent).
    The search then advances edges in another order, which changes nothing unless two
    totals tie; so if, at the end, another edge's bound does not exceed the winner's total,
    the search runs again without it, as before, and its answer is returned.
    """
    m, n_joints = sources.shape
    bound = np.empty(m)           # lower bound of the total (exact when done)
    level = np.empty(m)           # highest point probability still allowed (see _descend)
    ground = np.empty(m)          # lowest height still allowed (see _ground)
    done = np.empty(m, dtype=np.bool_)
    steps = np.zeros(m, dtype=np.int64)
    k_done = np.empty(m, dtype=np.int64)
    weight = np.zeros(m)
    tail = np.zeros(m)            # the least cost each remaining point adds
    cs = np.empty((m, n_joints))
    sn = np.empty((m, n_joints))
    cd = np.empty((m, n_joints))
    sd = np.empty((m, n_joints))
    ends = np.empty((m, n_joints))
    pos = np.empty((CHUNK, 3))
    rot = np.empty((CHUNK, 3, 3))
    soa = workspace(f_points.shape[1])
    p_buf = np.empty(CHUNK)
    term = c_fail[2] if prune else 0.0
    for attempt in range(2):
        use_tail = attempt == 0 and term > 0.0
        for i in range(m):
            a = sources[i] if toward else target
            b = target if toward else sources[i]
            length = 0.0
            for j in range(n_joints):
                length += (b[j] - a[j]) ** 2
            length = np.sqrt(length)
            bound[i] = base[i] + length_weight * length
            level[i] = cap
            ground[i] = floor
            k_done[i] = 0
            done[i] = False
            if length == 0.0 or (f_points.shape[1] == 0 and floor == -np.inf):
                done[i] = True
                continue
            n = max(1, int(np.ceil(length / delta - 1e-12)))
            steps[i] = n
            weight[i] = risk_weight * (length / n) / delta
            tail[i] = weight[i] * term if use_tail else 0.0
            if cap < np.inf:    # the start's probability needs them now; else when first picked
                _edge_rotations(a, b, n, kind, cs[i], sn[i], cd[i], sd[i])
            for j in range(n_joints):
                ends[i, j] = b[j]
        if cap < np.inf:
            for i in range(m):
                if not done[i]:
                    level[i] = max(cap, _start_probability(
                        cs[i], sn[i], steps[i], kind, joint_params, offsets, bases, tip_offset,
                        tip_rotation, shapes, f_points, f_dirs, f_rots, c_fail, use_orient,
                        prune, pos, rot, soa, p_buf))
        while True:
            pick = -1
            lowest = np.inf
            for i in range(m):  # lowest bound first; on equal bounds a finished edge, then index
                if not np.isfinite(bound[i]):
                    continue
                value = bound[i] + _ahead(tail[i], steps[i] - k_done[i], bound[i])
                tie_done = value == lowest and done[i] and not done[pick] if pick >= 0 \
                    else False
                if pick < 0 or value < lowest or tie_done:
                    pick = i
                    lowest = value
            if pick < 0:
                return -1, np.inf
            if done[pick]:
                if use_tail:
                    for i in range(m):      # a tie the order of the search might decide
                        if i != pick and np.isfinite(bound[i]) and bound[i] + _ahead(
                                tail[i], steps[i] - k_done[i], bound[i]) <= bound[pick]:
                            pick = -1
                            break
                    if pick < 0:
                        break
                return pick, bound[pick]
            i = pick
            if k_done[i] == 0:
                if cap == np.inf:
                    # an edge's cosines and sines once it is advanced at all (many never are)
                    _edge_rotations(sources[i] if toward else target, ends[i], steps[i], kind,
                                    cs[i], sn[i], cd[i], sd[i])
                ground[i] = _ground(cs[i], sn[i], kind, joint_params, offsets, bases,
                                    tip_offset, shapes, floor)
            count = min(CHUNK, steps[i] - k_done[i])
            if _chunk_poses(cs[i], sn[i], cd[i], sd[i], ends[i], k_done[i], count, steps[i],
                            kind, joint_params, offsets, bases, tip_offset, tip_rotation,
                            shapes, floor, pos, rot, soa) < ground[i]:
                bound[i] = np.inf
                continue
            _rows_probabilities(count, f_points, f_dirs, f_rots, c_fail, use_orient, prune,
                                soa, p_buf, ALONG_NEAR2, ALONG_AT_FAILURE)
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
    return -1, np.inf       # not reached: the search without tails ends in a return
