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

:class:`EdgeCoster` evaluates the same cost as :func:`probdis_ros.model.path_cost.edge_cost`
(probabilistic mode) or the Hard baseline's (length, or inf when any point probability
exceeds the threshold), through the numba kernels in :mod:`probdis_ros.model.kernels`.
:class:`ReferenceEdgeCoster` is the straightforward numpy evaluation of the same numbers; the
tests check that a planner gives the same paths with either.
"""

from __future__ import annotations

import numpy as np
from probdis_ros.model.arms import Arm, quaternion_to_rotation
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.model.kernels import cheapest_edge_kernel, edge_costs_kernel
from probdis_ros.model.path_cost import (
    DEFAULT_DELTA,
    DEFAULT_LENGTH_WEIGHT,
    edge_points,
    P_MAX,
    risk,
)


def _padded(values: np.ndarray, dim: int) -> np.ndarray:
    """Return ``(F, dim)`` values as a contiguous ``(F, 3)`` array (zeros beyond dim)."""
    out = np.zeros((len(values), 3))
    out[:, :dim] = np.asarray(values, dtype=float).reshape(-1, dim)
    return out


class EdgeCoster:
    """Cost of straight joint-space edges under a fixed failure map (compiled)."""

    def __init__(self, arm: Arm, fmap: FailureMap, delta: float = DEFAULT_DELTA,
                 length_weight: float = DEFAULT_LENGTH_WEIGHT,
                 hard_threshold: float | None = None) -> None:
        if fmap.task_space is not arm.task_space:
            raise ValueError(f'failure map is {fmap.task_space.value} but the arm works in '
                             f'{arm.task_space.value}')
        self.arm = arm
        self.fmap = fmap
        self.delta = float(delta)
        self.length_weight = float(length_weight)
        self.hard_threshold = hard_threshold
        dim = arm.task_space.dim
        self._failures = (          # points and directions padded to 3-D (z = 0 in 2-D)
            _padded(fmap.points, dim), _padded(fmap.directions, dim),
            np.ascontiguousarray(quaternion_to_rotation(fmap.orientations)).reshape(-1, 3, 3),
            float(fmap.c_fail), bool(arm.task_space.has_orientation))
        self._arm = arm.kernel_params()
        self._threshold = -1.0 if hard_threshold is None else float(hard_threshold)

    def costs(self, sources: np.ndarray, target: np.ndarray, toward: bool = True,
              base: np.ndarray | None = None) -> np.ndarray:
        """Return ``base[i] + cost(sources[i] -> target)``, or ``target -> sources[i]``."""
        sources = np.ascontiguousarray(sources, dtype=float).reshape(-1, self.arm.n_joints)
        target = np.ascontiguousarray(target, dtype=float)
        base = np.zeros(len(sources)) if base is None else np.asarray(base, dtype=float)
        out = np.empty(len(sources))
        edge_costs_kernel(sources, target, base, toward, self.delta, self.length_weight,
                          self._threshold, P_MAX, *self._arm, *self._failures, out)
        return out

    def cost(self, start: np.ndarray, end: np.ndarray) -> float:
        """Return the cost of one edge."""
        return float(self.costs(start, end)[0])

    def cheapest(self, sources: np.ndarray, target: np.ndarray, toward: bool = True,
                 base: np.ndarray | None = None) -> tuple[int, float]:
        """
        Return (i, total) of the least ``base[i] + cost`` over the edges, exactly.

        (-1, inf) when no edge is feasible.  Ties go to the lowest index, as with argmin.
        """
        sources = np.ascontiguousarray(sources, dtype=float).reshape(-1, self.arm.n_joints)
        target = np.ascontiguousarray(target, dtype=float)
        base = np.zeros(len(sources)) if base is None else np.asarray(base, dtype=float)
        index, total = cheapest_edge_kernel(sources, target, base, toward, self.delta,
                                            self.length_weight, self._threshold, P_MAX,
                                            *self._arm, *self._failures)
        return int(index), float(total)


class ReferenceEdgeCoster(EdgeCoster):
    """The same costs, evaluated point by point with numpy (slow; for tests and checks)."""

    def costs(self, sources: np.ndarray, target: np.ndarray, toward: bool = True,
              base: np.ndarray | None = None) -> np.ndarray:
        """Return every total, point by point."""
        sources = np.asarray(sources, dtype=float).reshape(-1, self.arm.n_joints)
        target = np.asarray(target, dtype=float)
        out = np.empty(len(sources))
        for i, source in enumerate(sources):
            a, b = (source, target) if toward else (target, source)
            points, step = edge_points(a, b, self.delta)
            length = step * len(points)
            if len(points) == 0:
                out[i] = 0.0
                continue
            p = self.fmap.probability(self.arm.fk(points)) if len(self.fmap) else \
                np.zeros(len(points))
            if self.hard_threshold is None:
                out[i] = risk(p, step, self.delta) + self.length_weight * length
            else:
                out[i] = length if p.max() <= self.hard_threshold else np.inf
        return out if base is None else out + np.asarray(base, dtype=float)

    def cheapest(self, sources: np.ndarray, target: np.ndarray, toward: bool = True,
                 base: np.ndarray | None = None) -> tuple[int, float]:
        """Return (i, total) of the least total, from every exact total."""
        totals = self.costs(sources, target, toward, base=base)
        index = int(np.argmin(totals))
        if not np.isfinite(totals[index]):
            return -1, np.inf
        return index, float(totals[index])
