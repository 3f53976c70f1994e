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
The least failure probability a map gives any pose of the arm, for exact pruning.

With the paper's kernel a failure's probability never reaches 0 in front of it, so a map
of failures facing several ways gives every pose some probability, and every point of
every edge adds at least ``-log(1 - p)`` of it to the edge's cost.  The best-first edge
search (:func:`probdis_ros.model.edge_kernels.cheapest_edge_kernel`) adds that least cost
for an edge's remaining points to its lower bound, so that losing edges stop sooner: the
same results, bit for bit, from fewer points.

:func:`least_probability` finds a lower bound of the probability over a ball that holds the
arm's tip (:func:`tip_ball`) by branch and bound over cubes; :func:`least_point_cost` turns
it into the kernels' least cost per point, and remembers it: a map that holds every failure
of another gives every pose at least that map's probability (a maximum over more
failures), so the bound of a map reaches the maps grown from it (a run adds one failure a
plan), and is searched again only once the map has grown by a quarter.
"""

from __future__ import annotations

from dataclasses import dataclass
import heapq
import math
import threading

import numba
import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.model.edge_kernels import (
    _coord_probability,
    ALONG_AT_FAILURE,
    ALONG_NEAR2,
    ANGLE_MARGIN,
)
from probdis_ros.model.kinematics import AXIS_CHAIN

#: Cells per side of the first grid of :func:`least_probability`'s search
GRID = 4
#: Halvings of a cell at most in :func:`least_probability`'s search
DEPTH = 7
#: The search ends once every cube's bound is this close to the least probability seen
CLOSE = 0.9
#: A least probability below this is not used (it would spare no search a point)
LEAST_USEFUL = 1e-5
#: A remembered bound serves maps grown from its map by less than this factor
REUSE_GROWTH = 1.25


def tip_ball(arm: Arm) -> tuple[np.ndarray, float] | None:
    """
    Return (center, radius) of a ball that holds the arm's tip in every configuration.

    An AXIS_CHAIN's first offset is fixed, and so is the second if it lies along the first
    joint's axis; the rest can at most add up (with margins above the rounding).  None for
    other arms.
    """
    kind, codes, offsets, _, tip_offset, _ = arm.kernel_params()
    if kind != AXIS_CHAIN or len(offsets) < 2:
        return None
    center = np.array(offsets[0], dtype=float)
    rest = np.asarray(offsets[1:], dtype=float)
    axis = np.zeros(3)
    axis[int(abs(codes[0])) - 1] = 1.0
    if np.all(np.cross(axis, rest[0]) == 0.0):
        center = center + rest[0]
        rest = rest[1:]
    radius = float(np.linalg.norm(rest, axis=1).sum() + np.linalg.norm(tip_offset))
    return center, radius * (1.0 + 1e-9) + 1e-9


@numba.njit(cache=True, nogil=True)
def _cube_bound(f_points, f_dirs, c_fail, half, x, y, z, r, hint, inside, enough):
    """
    Return (bound, best failure, probability at the center) of a cube.

    The bound holds at every point within r of (x, y, z) (:func:`least_probability`); the
    probability at the center (P_COORD times half) only if inside, else 0.  The hint
    failure is bounded first, and the others only until the bound reaches enough (and the
    center's probability too, if inside): above it, its exact value does not matter.
    """
    bound = 0.0
    at_center = 0.0
    best = hint
    for slot in range(f_points.shape[1]):
        f = hint if slot == 0 else slot - 1 if slot <= hint else slot
        if f_points[3, f] == 0.0:
            continue
        dx = f_points[0, f] - x
        dy = f_points[1, f] - y
        dz = f_points[2, f] - z
        if inside:
            at_center = max(at_center, half * _coord_probability(
                dx, dy, dz, f_dirs[0, f], f_dirs[1, f], f_dirs[2, f], c_fail, ALONG_NEAR2,
                ALONG_AT_FAILURE))
        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
        if dist <= r:
            continue
        c = (f_dirs[0, f] * dx + f_dirs[1, f] * dy + f_dirs[2, f] * dz) / dist
        alpha = np.arccos(min(1.0, max(-1.0, c)))
        far = (dist + r) * (1.0 + 1e-12)
        taper = max(0.0, 1.0 - far * far * c_fail[1])
        low = max(0.0, alpha - np.arcsin(min(1.0, r / dist)) - ANGLE_MARGIN) / np.pi
        value = half * low * low * low * (taper * taper) / (1.0 + c_fail[0] * far * far)
        if value > bound:
            bound = value
            best = f
        if bound >= enough and (not inside or at_center >= enough):
            break
    return bound, best, at_center


@numba.njit(cache=True, nogil=True)
def least_probability(f_points, f_dirs, c_fail, use_orient, center, radius):
    """
    Return a lower bound of the failure probability at every pose with its tip in a ball.

    The probability of a pose is at least max over failures of P_COORD / 2 (the
    orientation factor is at least 1/2; 1 without orientation).  Branch and bound over
    cubes covering the ball (center, radius): in a cube of half diagonal r about x0, a
    failure at distance D from x0 is at most D + r away and its alpha at least the center's
    less asin(r / D), which bounds its P_COORD from below (a taper too); the bound of a
    cube is the best failure's.  The cube of the least bound is halved (at most DEPTH
    times) until that bound is CLOSE times the least probability found at a cube's center
    (which the result cannot exceed); the result is the least bound of the cubes left.
    Margins above the rounding (the kernels' arccos included) make it a bound of the
    numbers the kernels compute.  0 for an empty map, or where failures taper to 0 (a
    reach shorter than the arm's).  The failure arrays and c_fail as the kernels take them
    (:mod:`probdis_ros.model.edge_kernels`).
    """
    if f_points.shape[1] == 0:
        return 0.0
    half = 0.5 * (1.0 - 1e-6) if use_orient else 1.0 - 1e-6
    seen = np.inf         # the least probability (as bounded from below) at a center
    least = np.inf
    # a heap of cubes: bound, center, half side, depth, the failure that bounded it best
    heap = [(0.0, 0.0, 0.0, 0.0, 0.0, 0, 0)]
    heap.pop()
    # the first grid, GRID cubes a side about the center, then halved cubes
    side = radius / GRID
    r = side * np.sqrt(3.0) * (1.0 + 1e-12)
    for i in range(GRID ** 3):
        cx = center[0] + (2 * (i % GRID) + 1 - GRID) * side
        cy = center[1] + (2 * (i // GRID % GRID) + 1 - GRID) * side
        cz = center[2] + (2 * (i // GRID ** 2) + 1 - GRID) * side
        seen = _push_cube(heap, f_points, f_dirs, c_fail, half, center, radius, cx, cy, cz,
                          side, r, 0, 0, seen)
    while len(heap) > 0:
        bound, x, y, z, h, depth, hint = heapq.heappop(heap)
        if bound >= CLOSE * seen or depth == DEPTH:
            least = min(least, bound)
            if bound >= CLOSE * seen:
                break
            continue
        h2 = 0.5 * h
        r = h2 * np.sqrt(3.0) * (1.0 + 1e-12)
        for i in range(8):
            seen = _push_cube(heap, f_points, f_dirs, c_fail, half, center, radius,
                              x + (h2 if i & 1 else -h2), y + (h2 if i & 2 else -h2),
                              z + (h2 if i & 4 else -h2), h2, r, depth + 1, hint, seen)
    return least * (1.0 - 1e-6) if np.isfinite(least) else 0.0


@numba.njit(cache=True, nogil=True)
def _push_cube(heap, f_points, f_dirs, c_fail, half, center, radius, cx, cy, cz, h, r, depth,
               hint, seen):
    """Bound a cube of half side h about (cx, cy, cz) that meets the ball; return seen."""
    to_center = np.sqrt((cx - center[0]) ** 2 + (cy - center[1]) ** 2
                        + (cz - center[2]) ** 2)
    if to_center > radius + r:
        return seen
    inside = to_center <= radius
    bound, best, at_center = _cube_bound(f_points, f_dirs, c_fail, half, cx, cy, cz, r, hint,
                                         inside, seen)
    heapq.heappush(heap, (bound, cx, cy, cz, h, depth, best))
    return min(seen, at_center) if inside else seen


@dataclass(frozen=True)
class _Known:
    """A least probability found, with what it depends on (:func:`least_point_cost`)."""

    setting: tuple
    points: np.ndarray
    directions: np.ndarray
    probability: float


#: The bounds found last (newest last), shared by the threads that make plans
_KNOWN: list[_Known] = []
_KNOWN_LOCK = threading.Lock()
#: How many bounds are remembered
KNOWN_MAPS = 8


def least_point_cost(arm: Arm, points: np.ndarray, directions: np.ndarray, failures: tuple,
                     reach: float, p_max: float) -> float:
    """
    Return the least cost any point of any edge adds per unit of weight (0: none known).

    ``-log(1 - p)`` at the least probability p of the map (:func:`least_probability`,
    capped at p_max as the kernels cap each point, with a margin below), where the arm's
    tip ball is known, the failures reach beyond it (reach, the objective's) and p is at
    least LEAST_USEFUL.  points and directions are the map's failures (N, dim), failures
    the kernels' arrays of them (points, directions, rotations, c_fail, use_orient).  A
    bound found for a map whose failures are the first of these serves while it holds at
    least 1 / REUSE_GROWTH of them (it is valid for every map that holds its failures).
    """
    points, directions = np.asarray(points, dtype=float), np.asarray(directions, dtype=float)
    ball = tip_ball(arm)
    if ball is None or len(points) == 0 or reach < ball[1]:
        return 0.0
    center, radius = ball
    f_points, f_dirs, _, c_fail, use_orient = failures[:5]
    setting = (float(c_fail[0]), float(c_fail[1]), bool(use_orient), *center.tolist(), radius)
    probability = None
    with _KNOWN_LOCK:
        for known in reversed(_KNOWN):
            held = len(known.points)
            if (known.setting == setting and held <= len(points)
                    and held * REUSE_GROWTH >= len(points)
                    and np.array_equal(known.points, points[:held])
                    and np.array_equal(known.directions, directions[:held])):
                probability = known.probability
                break
    if probability is None:
        probability = least_probability(f_points, f_dirs, c_fail, use_orient, center, radius)
        with _KNOWN_LOCK:
            _KNOWN.append(_Known(setting, points.copy(), directions.copy(), probability))
            del _KNOWN[:-KNOWN_MAPS]
    if probability < LEAST_USEFUL:
        return 0.0
    return -math.log1p(-min(probability, p_max)) * (1.0 - 1e-6)
