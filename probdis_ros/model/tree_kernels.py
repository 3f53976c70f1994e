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
Compiled ProbRRT iterations (numba): the same steps as :class:`ProbRRT`'s Python loop.

A plan at the paper's parameters makes ~400 extend steps and ~70 Connect queries; in Python
each cost ~150 us of interpreter and array overhead (about 30 ms a plan on an empty map),
more than the edge costs themselves.  Here the whole loop runs compiled, on the arrays of
:class:`probdis_ros.planning.tree.Tree`, calling the same edge kernels and the same
helpers (:func:`nearest_order`, :func:`step_toward`) as the Python loop, in the same order
and with the same floating-point operations, so that both give the same plan bit for bit
(``test/test_bench_speed.py``).  The Python loop stays as the readable reference and
serves arms without a compiled chain (the planar arm) and the reference coster.

numba's cache (``cache=True``) is keyed by each module's own source: after an edit of
:mod:`probdis_ros.model.edge_kernels` (or :mod:`~probdis_ros.model.kinematics`), the loops
here may still run the cached code of the old edge kernels until this module changes or
the ``__pycache__/*.nbi``/``*.nbc`` files are removed.  Remove them when measuring.
"""

import math

import numba
import numpy as np
from probdis_ros.model.edge_kernels import (
    cheapest_edge_kernel,
    CHUNK,
    edge_cost_kernel,
    workspace,
)
from probdis_ros.model.kinematics import chain_kernel


@numba.njit(cache=True, nogil=True, error_model='numpy')
def farthest_kernel(samples, nodes):
    """
    Return the index of the sample whose nearest node is farthest (squared distances).

    Every (node, sample) distance, a node at a time over all samples (one row per
    coordinate), in a loop the compiler vectorises: twice as fast on trees of a hundred
    nodes as dropping a sample at the first node nearer than the best so far, four times
    on the informed method's trees of 800, with the same answer (the first of equal
    distances).
    """
    m = samples.shape[0]
    rows = np.empty((4, m))
    sx, sy, sz, nearest = rows[0], rows[1], rows[2], rows[3]
    for i in range(m):
        sx[i] = samples[i, 0]
        sy[i] = samples[i, 1]
        sz[i] = samples[i, 2] if samples.shape[1] > 2 else 0.0
        nearest[i] = np.inf
    for k in range(nodes.shape[0]):
        nx = nodes[k, 0]
        ny = nodes[k, 1]
        nz = nodes[k, 2] if nodes.shape[1] > 2 else 0.0
        for i in range(m):
            dx = sx[i] - nx
            dy = sy[i] - ny
            dz = sz[i] - nz
            nearest[i] = min(nearest[i], dx * dx + dy * dy + dz * dz)
    best = -1.0
    best_index = 0
    for i in range(m):
        if nearest[i] > best:
            best = nearest[i]
            best_index = i
    return best_index


@numba.njit(cache=True, nogil=True)
def is_ancestor(parent, ancestor, node):
    """Tell whether ancestor lies on the way from node up to the root (node included)."""
    while node >= 0:
        if node == ancestor:
            return True
        node = parent[node]
    return False


@numba.njit(cache=True, nogil=True)
def reparent(parent, edge, costs, first_child, next_sibling, counts, index, new_parent,
             new_edge):
    """Move node index under new_parent (no cycle: checked by the caller); update its subtree."""
    old = parent[index]
    if first_child[old] == index:
        first_child[old] = next_sibling[index]
    else:
        sibling = first_child[old]
        while next_sibling[sibling] != index:
            sibling = next_sibling[sibling]
        next_sibling[sibling] = next_sibling[index]
    next_sibling[index] = first_child[new_parent]
    first_child[new_parent] = index
    parent[index] = new_parent
    edge[index] = new_edge
    counts[1] += 1
    stack = [index]
    while len(stack) > 0:
        node = stack.pop()
        costs[node] = costs[parent[node]] + edge[node]
        child = first_child[node]
        while child >= 0:
            stack.append(child)
            child = next_sibling[child]


@numba.njit(cache=True, nogil=True)
def nearest_order(nodes, size, config, k):
    """
    Node indices by joint-space distance to config (stable; the k nearest if 0 < k).

    The k nearest are kept by insertion (ties to the lower index), the same indices in the
    same order as a stable sort's first k at a fraction of its cost.
    """
    d2 = np.empty(size)
    for i in range(size):
        total = 0.0
        for j in range(nodes.shape[1]):
            diff = nodes[i, j] - config[j]
            total += diff * diff
        d2[i] = total
    if not 0 < k < size:
        return np.argsort(d2, kind='mergesort')
    order = np.empty(k, dtype=np.int64)
    kept = np.empty(k)
    count = 0
    for i in range(size):
        value = d2[i]
        if count == k and value >= kept[k - 1]:
            continue
        slot = min(count, k - 1)
        while slot > 0 and kept[slot - 1] > value:
            kept[slot] = kept[slot - 1]
            order[slot] = order[slot - 1]
            slot -= 1
        kept[slot] = value
        order[slot] = i
        count = min(count + 1, k)
    return order


@numba.njit(cache=True, nogil=True)
def step_toward(node, target, step, out, low, high, clip):
    """
    Write node + (target - node) * min(1, step / distance) to out; False if distance is 0.

    With ``clip``, the result is then clipped into [low, high] (the joint limits shrunk by
    the planner's margin): a root within the margin of a limit steps into the shrunk box.
    """
    total = 0.0
    for j in range(node.shape[0]):
        diff = target[j] - node[j]
        total += diff * diff
    distance = np.sqrt(total)
    if distance == 0.0:
        return False
    scale = min(1.0, step / distance)
    for j in range(node.shape[0]):
        out[j] = node[j] + (target[j] - node[j]) * scale
        if clip:
            out[j] = min(max(out[j], low[j]), high[j])
    return True


@numba.njit(cache=True, nogil=True)
def neighbour_count(factor, n_joints, size):
    """Return RRT*'s k = ceil(factor e (1 + 1/d) log(n + 1)) (OMPL's k-nearest RRT*)."""
    return math.ceil(factor * math.e * (1 + 1 / n_joints) * math.log(size + 1))


@numba.njit(cache=True, nogil=True)
def grow_kernel(nodes, positions, parent, edge, costs, first_child, next_sibling, counts,
                to_goal, samples, sample_positions, k_from, k_to, other_root, n_random, step,
                low, high, clip,
                rewire_factor, rewire_radius, closest_k, reverse, delta, length_weight,
                risk_weight, cap, p_max, kind, joint_params, offsets, bases, tip_offset,
                tip_rotation, shapes, floor, f_points, f_dirs, f_rots, c_fail, use_orient,
                prune):
    """
    Run iterations k_from..k_to-1 of a round of one tree (Algorithm 2), in place.

    The round's draws are made by the caller, as the Python loop makes them: ``to_goal``
    (K,), ``samples`` (K * n_random, d) and their tip positions.  The arrays must have room
    for k_to - k_from more nodes.
    """
    n_joints = nodes.shape[1]
    new = np.empty(n_joints)
    pos = np.empty((1, 3))
    rot = np.empty((1, 3, 3))
    buf_pos = np.empty((CHUNK, 3))
    buf_rot = np.empty((CHUNK, 3, 3))
    soa = workspace(f_points.shape[1])
    p_buf = np.empty(CHUNK)
    for k in range(k_from, k_to):
        size = counts[0]
        if to_goal[k]:
            target = other_root
        else:
            rows = slice(k * n_random, (k + 1) * n_random)
            target = samples[rows][farthest_kernel(sample_positions[rows], positions[:size])]
        # ClosestConfiguration
        candidates = nearest_order(nodes, size, target, closest_k)
        best, _ = cheapest_edge_kernel(
            nodes[candidates], target, np.zeros(len(candidates)), not reverse, delta,
            length_weight, risk_weight, cap, p_max, kind, joint_params, offsets, bases,
            tip_offset, tip_rotation, shapes, floor, f_points, f_dirs, f_rots, c_fail,
            use_orient, prune)
        if best < 0:
            continue
        closest = candidates[best]
        # NewConfiguration
        if not step_toward(nodes[closest], target, step, new, low, high, clip):
            continue
        # RewireNeighbours: the cheapest parent among the neighbours
        if rewire_factor == 0:
            near = np.array([closest])
        else:
            near = nearest_order(nodes, size, new,
                                 neighbour_count(rewire_factor, n_joints, size))
            if rewire_radius > 0:
                keep = np.empty(len(near), dtype=np.bool_)
                for i in range(len(near)):
                    d2 = 0.0
                    for j in range(n_joints):
                        d2 += (nodes[near[i], j] - new[j]) ** 2
                    keep[i] = d2 <= rewire_radius * rewire_radius
                near = near[keep]
            if not (near == closest).any():
                near = np.append(near, closest)
        costs_to = costs[near]
        best, total = cheapest_edge_kernel(
            nodes[near], new, costs_to, not reverse, delta, length_weight, risk_weight, cap,
            p_max, kind, joint_params, offsets, bases, tip_offset, tip_rotation, shapes, floor,
            f_points, f_dirs, f_rots, c_fail, use_orient, prune)
        if best < 0:
            continue
        chosen = near[best]
        edge_in = total - costs_to[best]
        chain_kernel(new.reshape(1, n_joints), kind, joint_params, offsets, bases, tip_offset,
                     tip_rotation, pos, rot)
        index = size
        nodes[index] = new
        positions[index] = pos[0]
        parent[index] = chosen
        edge[index] = edge_in
        costs[index] = costs[chosen] + edge_in
        first_child[index] = -1
        next_sibling[index] = first_child[chosen]
        first_child[chosen] = index
        counts[0] = size + 1
        # and the neighbours that the new node makes cheaper: every edge is costed first
        # (only as far as the neighbour's cost then), then they are re-parented in turn
        out = np.empty(len(near))
        for i in range(len(near)):
            if i == best:
                continue
            node = near[i]
            a = nodes[node] if reverse else new
            b = new if reverse else nodes[node]
            out[i] = 0.0 + edge_cost_kernel(
                a, b, costs[node] - costs[index], delta, length_weight, risk_weight, cap,
                p_max, kind, joint_params, offsets, bases, tip_offset, tip_rotation, shapes,
                floor, f_points, f_dirs, f_rots, c_fail, use_orient, prune, buf_pos, buf_rot,
                soa, p_buf)
        for i in range(len(near)):
            node = near[i]
            if i != best and costs[index] + out[i] < costs[node] and \
                    not is_ancestor(parent, node, index):
                reparent(parent, edge, costs, first_child, next_sibling, counts, node, index,
                         out[i])


@numba.njit(cache=True, nogil=True)
def connect_kernel(start_nodes, start_costs, goal_nodes, goal_costs, goal_first_child,
                   connect_k, delta, length_weight, risk_weight, cap, p_max, kind,
                   joint_params, offsets, bases, tip_offset, tip_rotation, shapes, floor,
                   f_points, f_dirs, f_rots, c_fail, use_orient, prune):
    """
    Return (start node, goal leaf, total) of Connect (Algorithm 1); (-1, -1, inf) if none.

    Each goal-tree leaf is joined to its cheapest start-tree node (of its connect_k nearest).
    A leaf whose every candidate costs at least the best total so far before its edge's
    risk (the costs of both ends and the length term, as the edge kernel starts from) is
    skipped: its total could not be lower, so the result is the same (most leaves of a
    plan, 86 % on the 19-failure map with R = 0.5 m, 65 % with the paper's kernel).
    """
    toward = np.bool_(True)   # not a literal True: that would compile the kernel again
    best_total = np.inf
    best_start = -1
    best_leaf = -1
    for leaf in range(goal_nodes.shape[0]):
        if goal_first_child[leaf] >= 0:
            continue
        candidates = nearest_order(start_nodes, start_nodes.shape[0], goal_nodes[leaf],
                                   connect_k)
        base = start_costs[candidates] + goal_costs[leaf]
        lowest = np.inf
        for i in range(len(candidates)):
            length = 0.0
            for j in range(goal_nodes.shape[1]):
                length += (goal_nodes[leaf, j] - start_nodes[candidates[i], j]) ** 2
            lowest = min(lowest, base[i] + length_weight * np.sqrt(length))
        if lowest >= best_total:
            continue
        i, total = cheapest_edge_kernel(
            start_nodes[candidates], goal_nodes[leaf], base,
            toward, delta, length_weight, risk_weight, cap, p_max, kind, joint_params, offsets,
            bases, tip_offset, tip_rotation, shapes, floor, f_points, f_dirs, f_rots, c_fail,
            use_orient, prune)
        if total < best_total:
            best_total = total
            best_start = candidates[i]
            best_leaf = leaf
    return best_start, best_leaf, best_total
