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
Cost and success probability of joint-space edges and paths under a failure map.

The paper writes path failure as a product of point probabilities, which would make longer
paths look safer.  What it means, and what DESIGN.md fixes, is the product integral of the
failure density along the path, by the rectangle rule: an edge of joint-space length L is cut
into ``n = ceil(L / delta)`` equal steps of length ``s = L / n``; with ``p_k`` the failure
probability at the end of step k,

    success(edge) = prod_k (1 - p_k) ** (s / delta)
    cost(edge)    = -sum_k (s / delta) * log(1 - p_k) + length_weight * L

so ``success(path) = exp(-(cost - length_weight * length))``, and costs add along a path,
which is what RRT* rewiring needs.  The small length term breaks ties and keeps paths short
where the map is empty.  ``p`` is capped at ``P_MAX`` so a step through a failure point costs
a large finite amount instead of infinity.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise
import math

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.model.failure_map import FailureMap

#: Discretisation step Delta in joint space (rad), the paper's value.
DEFAULT_DELTA = 0.04
#: Weight lambda of joint-space length in the cost.
DEFAULT_LENGTH_WEIGHT = 0.01
#: Largest point failure probability used in a logarithm.
P_MAX = 1.0 - 1e-9


@dataclass(frozen=True)
class EdgeTerms:
    """
    The numbers that make an edge cost, as the compiled kernels take them.

    ``cost = length_weight * L - risk_weight * sum (s / delta) log(1 - p)``, or infinite
    when a point probability exceeds ``cap`` -- unless the edge started above the cap and is
    on its way out, its probability not rising (a hard constraint may be left, never
    entered); the probabilities are computed with ``c_fail`` (None: the map's own C_FAIL)
    and ``reach`` (:meth:`FailureMap.probability`; infinite: the paper's kernel).
    Objectives (:mod:`probdis_ros.planning.objectives`) are what the planner is handed;
    these are what they reduce to, so that one generic kernel serves every objective without
    a branch per method.
    """

    length_weight: float = DEFAULT_LENGTH_WEIGHT
    risk_weight: float = 1.0
    cap: float = math.inf
    c_fail: float | None = None
    reach: float = math.inf

    def __post_init__(self) -> None:
        """Refuse terms that would make a cost negative or meaningless."""
        if not (self.length_weight >= 0 and self.risk_weight >= 0 and self.cap >= 0):
            raise ValueError('length_weight, risk_weight and cap must be >= 0')
        if not self.reach > 0:
            raise ValueError(f'reach must be > 0 (inf: none), got {self.reach!r}')
        if self.c_fail is not None and not (math.isfinite(self.c_fail) and self.c_fail > 0):
            raise ValueError(f'c_fail must be a positive number, got {self.c_fail!r}')

    def allows(self, probabilities: np.ndarray, start: float = 0.0) -> bool:
        """Tell whether an edge from probability start through these points keeps the cap."""
        level = max(self.cap, start)
        for p in np.asarray(probabilities, dtype=float):
            if p > level:
                return False
            level = max(self.cap, p)
        return True

    def reference_cost(self, probabilities: np.ndarray, step: float, delta: float,
                       length: float, start: float = 0.0) -> float:
        """Return the cost of an edge from its point probabilities (numpy, for checks)."""
        p = np.asarray(probabilities, dtype=float)
        if not self.allows(p, start):
            return math.inf
        cost = self.length_weight * length
        if self.risk_weight:
            cost += self.risk_weight * risk(p, step, delta)
        return cost


def edge_points(start: np.ndarray, end: np.ndarray,
                delta: float = DEFAULT_DELTA) -> tuple[np.ndarray, float]:
    """Return the ends of the ``ceil(L / delta)`` equal steps of an edge, and the step length."""
    start = np.asarray(start, dtype=float)
    end = np.asarray(end, dtype=float)
    length = float(np.linalg.norm(end - start))
    n = max(1, math.ceil(length / delta - 1e-12)) if length > 0 else 0
    if n == 0:
        return np.empty((0, len(start))), 0.0
    fractions = np.arange(1, n + 1)[:, None] / n
    return start + fractions * (end - start), length / n


def risk(probabilities: np.ndarray, step: float, delta: float = DEFAULT_DELTA) -> float:
    """Return ``-sum (step / delta) log(1 - p)``, minus the log success probability."""
    p = np.minimum(np.asarray(probabilities, dtype=float), P_MAX)
    return float(-(step / delta) * np.log1p(-p).sum())


def edge_cost(arm: Arm, fmap: FailureMap, start: np.ndarray, end: np.ndarray,
              delta: float = DEFAULT_DELTA,
              length_weight: float = DEFAULT_LENGTH_WEIGHT) -> float:
    """Return the additive cost of the straight joint-space edge from start to end."""
    points, step = edge_points(start, end, delta)
    length = step * len(points)
    if len(points) == 0:
        return 0.0
    return risk(fmap.probability(arm.fk(points)), step, delta) + length_weight * length


def path_cost(arm: Arm, fmap: FailureMap, path: np.ndarray, delta: float = DEFAULT_DELTA,
              length_weight: float = DEFAULT_LENGTH_WEIGHT) -> float:
    """Return the sum of the edge costs along the via points of path ``(M, n_joints)``."""
    path = arm.as_batch(path)
    return sum(edge_cost(arm, fmap, a, b, delta, length_weight) for a, b in pairwise(path))


def path_length(path: np.ndarray) -> float:
    """Return the joint-space (Euclidean) length of a polyline of configurations."""
    path = np.atleast_2d(np.asarray(path, dtype=float))
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def path_success_probability(arm: Arm, fmap: FailureMap, path: np.ndarray,
                             delta: float = DEFAULT_DELTA) -> float:
    """Return the probability that the whole path executes without being blocked."""
    return math.exp(-path_cost(arm, fmap, path, delta, length_weight=0.0))
