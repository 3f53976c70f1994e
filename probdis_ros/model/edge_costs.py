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
Edge costs for the planner: many edges per call, compiled; the cheapest edge best-first.

:class:`EdgeCoster` evaluates an edge cost given by :class:`EdgeTerms` (what an objective of
:mod:`probdis_ros.planning.objectives` reduces to: the failure-probability cost of
:func:`probdis_ros.model.path_cost.edge_cost`, or the Hard baseline's length-or-infinite)
through the numba kernels in :mod:`probdis_ros.model.edge_kernels`.  :class:`ReferenceEdgeCoster`
is the straightforward numpy evaluation of the same numbers; the tests check that a planner
gives the same paths with either.
"""

from __future__ import annotations

import numpy as np
from probdis_ros.model.arms import Arm, quaternion_to_rotation
from probdis_ros.model.edge_kernels import (
    AT_FAILURE,
    cheapest_edge_kernel,
    edge_costs_kernel,
    padded_count,
)
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.model.least_probability import least_point_cost
from probdis_ros.model.path_cost import DEFAULT_DELTA, edge_points, EdgeTerms, P_MAX


def _padded(values: np.ndarray, dim: int) -> np.ndarray:
    """Return ``(F, dim)`` values as a contiguous ``(F, 3)`` array (zeros beyond dim)."""
    out = np.zeros((len(values), 3))
    out[:, :dim] = np.asarray(values, dtype=float).reshape(-1, dim)
    return out


def _columns(values: np.ndarray) -> np.ndarray:
    """
    Return ``(F, ...)`` values as contiguous columns ``(..., padded_count(F))``.

    The padding columns repeat the last failure (edge_kernels.padded_count).
    """
    columns = np.moveaxis(values, 0, -1)
    index = np.minimum(np.arange(padded_count(len(values))), len(values) - 1)
    return np.ascontiguousarray(columns[..., index])


def _batch(arm: Arm, sources: np.ndarray, target: np.ndarray, base, limits):
    sources = np.ascontiguousarray(sources, dtype=float).reshape(-1, arm.n_joints)
    target = np.ascontiguousarray(target, dtype=float)
    if target.shape != (arm.n_joints,):     # the kernels do not check: they would read past it
        raise ValueError(f'target must have {arm.n_joints} joint values, has {target.size}')
    base = np.zeros(len(sources)) if base is None else \
        np.broadcast_to(np.asarray(base, dtype=float), len(sources))
    # fresh writable arrays: a read-only one is another type to numba, compiled again
    limits = np.full(len(sources), np.inf) if limits is None else \
        np.array(np.broadcast_to(np.asarray(limits, dtype=float), len(sources)))
    return sources, target, np.array(base), limits


def edge_above_table(arm: Arm, start: np.ndarray, end: np.ndarray,
                     delta: float = DEFAULT_DELTA) -> bool:
    """
    Tell whether the table lets the arm move along the edge (True without a table).

    At the edge's points (every delta, as it is costed) no part of the arm may be below the
    table's floor, nor lower than at the start (an arm near the table may leave upwards):
    the rule of the compiled kernels (``_ground``), point by point with numpy.
    """
    if arm.table is None:
        return True
    points, _ = edge_points(start, end, delta)
    if not len(points):
        return True
    heights = arm.lowest_heights(np.vstack([start, points]))
    return bool(heights[1:].min() >= min(arm.table.floor, heights[0]))


class EdgeCoster:
    """Cost of straight joint-space edges under a fixed failure map (compiled)."""

    def __init__(self, arm: Arm, fmap: FailureMap, delta: float = DEFAULT_DELTA,
                 terms: EdgeTerms | None = None, prune: bool = True) -> None:
        """
        Prepare the map for the kernels.

        ``prune`` lets a chunk of points skip the failures whose bound cannot raise its
        maximum probability (exact: the same costs bit for bit; False for the checks).
        """
        if fmap.task_space is not arm.task_space:
            raise ValueError(f'failure map is {fmap.task_space.value} but the arm works in '
                             f'{arm.task_space.value}')
        self.arm = arm
        self.fmap = fmap
        self.delta = float(delta)
        self.terms = terms or EdgeTerms()
        self.c_fail = float(fmap.c_fail if self.terms.c_fail is None else self.terms.c_fail)
        dim = arm.task_space.dim
        # points and directions padded to 3-D (z = 0 in 2-D); one row per coordinate
        # (C-contiguous whatever the map's size: one numba type, so the kernels compile
        # once, and the kernels' bounds of all failures vectorise), padded to whole vectors
        # with copies of the last failure that the fourth row of the points flags 0
        # (edge_kernels.padded_count)
        points, directions, orientations = fmap.arrays()    # the same failures, whole
        rotations = quaternion_to_rotation(orientations).reshape(-1, 3, 3)
        flags = (np.arange(padded_count(len(points))) < len(points)).astype(float)
        failures = (np.ascontiguousarray(np.vstack([_columns(_padded(points, dim)), flags])),
                    _columns(_padded(directions, dim)), _columns(rotations),
                    (self.c_fail, 1.0 / self.terms.reach ** 2),
                    bool(arm.task_space.has_orientation))
        # the least cost a point adds, c_fail[2] of the kernels (exact pruning too:
        # edge_kernels.cheapest_edge_kernel; none where the cost has no risk term)
        least = least_point_cost(arm, points, directions, failures, self.terms.reach, P_MAX) \
            if prune and self.terms.risk_weight > 0 else 0.0
        self._failures = (*failures[:3], (*failures[3], least), failures[4], bool(prune))
        self._arm = arm.kernel_params()
        self._table = arm.table_params()
        self._terms = (float(self.terms.length_weight), float(self.terms.risk_weight),
                       float(self.terms.cap), P_MAX)

    @property
    def failure_arrays(self) -> tuple:
        """Return the map as the kernels take it (points, directions, rotations, constants)."""
        return self._failures

    @property
    def compiled(self) -> bool:
        """Tell whether the costs come from the compiled kernels (not overridden)."""
        return type(self).costs is EdgeCoster.costs and type(self).cheapest is EdgeCoster.cheapest

    def kernel_args(self) -> tuple:
        """Return delta, the terms, the arm, its table and the failures, for the kernels."""
        return (self.delta, *self._terms, *self._arm, *self._table, *self._failures)

    def costs(self, sources: np.ndarray, target: np.ndarray, toward: bool = True,
              base: np.ndarray | float | None = None,
              limits: np.ndarray | float | None = None) -> np.ndarray:
        """
        Return ``base[i] + cost(sources[i] -> target)``, or ``target -> sources[i]``.

        With ``limits``, an edge whose own cost reaches ``limits[i]`` is given as inf (and
        stops being costed there).
        """
        sources, target, base, limits = _batch(self.arm, sources, target, base, limits)
        out = np.empty(len(sources))
        edge_costs_kernel(sources, target, base, limits, toward, self.delta, *self._terms,
                          *self._arm, *self._table, *self._failures, out)
        return out

    def cost(self, start: np.ndarray, end: np.ndarray) -> float:
        """Return the cost of one edge."""
        return float(self.costs(start, end)[0])

    def cheapest(self, sources: np.ndarray, target: np.ndarray, toward: bool = True,
                 base: np.ndarray | None = None) -> tuple[int, float]:
        """
        Return (i, total) of the least ``base[i] + cost`` over the edges, exactly.

        (-1, inf) when no edge is feasible.  On equal totals a completed edge wins, then the
        lowest index (:func:`cheapest_edge_kernel`).
        """
        sources, target, base, _ = _batch(self.arm, sources, target, base, None)
        index, total = cheapest_edge_kernel(sources, target, base, toward, self.delta,
                                            *self._terms, *self._arm, *self._table,
                                            *self._failures)
        return int(index), float(total)


class ReferenceEdgeCoster(EdgeCoster):
    """The same costs, evaluated point by point with numpy (slow; for tests and checks)."""

    def costs(self, sources: np.ndarray, target: np.ndarray, toward: bool = True,
              base: np.ndarray | float | None = None,
              limits: np.ndarray | float | None = None) -> np.ndarray:
        """Return every total, point by point."""
        sources, target, base, limits = _batch(self.arm, sources, target, base, limits)
        out = np.empty(len(sources))
        for i, source in enumerate(sources):
            a, b = (source, target) if toward else (target, source)
            points, step = edge_points(a, b, self.delta)
            if len(points) == 0:
                out[i] = 0.0
                continue
            p = self.fmap.probability(self.arm.fk(points), self.c_fail,
                                      reach=self.terms.reach) if len(self.fmap) \
                else np.zeros(len(points))
            start = self.fmap.probability(self.arm.fk(a), self.c_fail, AT_FAILURE,
                                          self.terms.reach)[0] \
                if len(self.fmap) and self.terms.cap < np.inf else 0.0
            cost = self.terms.reference_cost(p, step, self.delta, step * len(points), start)
            if not edge_above_table(self.arm, a, b, self.delta):
                cost = np.inf
            out[i] = cost if cost < limits[i] else np.inf
        return out + base

    def cheapest(self, sources: np.ndarray, target: np.ndarray, toward: bool = True,
                 base: np.ndarray | None = None) -> tuple[int, float]:
        """Return (i, total) of the least total, from every exact total."""
        totals = self.costs(sources, target, toward, base=base)
        index = int(np.argmin(totals))
        if not np.isfinite(totals[index]):
            return -1, np.inf
        return index, float(totals[index])
