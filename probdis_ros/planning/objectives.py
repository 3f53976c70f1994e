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
Objectives: what a path costs, handed to the planner as an object (OMPL's lesson).

The planner (:class:`probdis_ros.planning.prob_rrt.ProbRRT`) never knows which method it
runs: it asks its objective for an edge coster and minimises the sum of edge costs.  Each
objective reduces to :class:`probdis_ros.model.path_cost.EdgeTerms`, the few numbers the
compiled kernels take, so one kernel serves all of them without a branch per method.

* :class:`FailureProbabilityObjective` (Probabilistic, the paper's method): minus the log
  success probability of the edge plus ``length_weight`` times its joint-space length.
* :class:`HardThresholdObjective` (the Hard Y baseline): the joint-space length, and an edge
  is infeasible if any of its points has a failure probability above Y.

How Y and C_FAIL interact for Hard (decisions the paper leaves open).  A point is forbidden
when its failure probability exceeds Y: straight ahead of a failure out to
``d = sqrt((1 / Y - 1) / C)``, less to the sides (the (alpha / pi)^3 factor).  With the map's
C_FAIL = 100 and Y = 0.01 that is a metre: after one failure the goal was forbidden in almost
every world, no edge reached it, and the arm never moved again (the old sweep: 1,736 of
2,400 Hard episodes ended with at most one failure after 20 empty plans).  The paper's Hard
worked and was sensitive to Y (its Fig. 5), so its regions must have been about the size of
an obstacle.  So:

1. Hard draws its regions with its own C_FAIL, ``HARD_C_FAIL`` = 30,000 1/m^2 (reach 5.7 cm
   at Y = 0.01, 4.0 cm at Y = 0.02), chosen on training worlds as the map's C_FAIL was;
   Y keeps the paper's meaning (0.02 forbids less than 0.01), the map is the loop's.
2. A region may be left but never entered: an edge that starts above Y may pass points above
   Y as long as their probability does not rise on the way out; an arm held where it was
   blocked (within 1 um of a failure point) counts as behind that failure, so it may back
   out but not go on (:func:`probdis_ros.model.edge_kernels._descend`).  Without this an arm
   whose retreat could not move it (blocked on its first motion) stood in a forbidden
   region and planned nothing for the rest of the episode.

Training worlds (seeds 1000-1009, not the tests'; ``probdis sim --method hard:Y:C``),
Hard 0.01, successes of 10 within 20 paths (mean paths of the successful; empty plans /
paths):

=========  ====================  ===================  ====================
C_HARD     2-D, 10 obstacles     3-D, 30 obstacles    3-D orient., 50
=========  ====================  ===================  ====================
100        0 (-; 190/200)        1 (2.0; 171/182)     -
1,000      4 (6.0; 105/144)      8 (4.4; 45/75)       -
3,000      9 (2.6; 19/43)        8 (4.2; 37/74)       9 (2.1; 19/39)
10,000     9 (6.4; 39/78)        9 (3.9; 13/55)       10 (2.1; 0/21)
30,000     9 (3.9; 17/55)        10 (4.1; 0/41)       10 (2.3; 0/23)
100,000    9 (6.7; 13/80)        10 (4.4; 0/44)       10 (3.0; 0/30)
=========  ====================  ===================  ====================

(Rows 100 and 1,000 before rule 2.)  Hard 0.02 ranked the values alike (3,000: 8/8/10,
10,000: 9/9/10, 30,000: 9/10/10 successes).  30,000 solved the most with the fewest empty
plans; beyond it the regions shrink below the obstacles and paths grow (100,000).  The
remaining empty plans are worlds where the learned regions close every way out: a hard
constraint's honest answer, counted as a path and reported (``empty_plans``).  Probabilistic
on the same worlds: 10/9/10 successes.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
import math

from probdis_ros.model.arms import Arm
from probdis_ros.model.edge_costs import EdgeCoster
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.model.path_cost import DEFAULT_DELTA, DEFAULT_LENGTH_WEIGHT, EdgeTerms

#: Y of the Hard baseline when none is given (the paper's Hard 0.01).
DEFAULT_THRESHOLD = 0.01
#: C_FAIL [1/m^2] of Hard's forbidden regions (not of the map), chosen on training worlds.
HARD_C_FAIL = 30_000.0


class Objective(ABC):
    """What a path costs: additive over edges, each edge's cost from its point probabilities."""

    @abstractmethod
    def terms(self) -> EdgeTerms:
        """Return the edge cost as the numbers the compiled kernels take."""

    def coster(self, arm: Arm, fmap: FailureMap, delta: float = DEFAULT_DELTA,
               coster_type: type[EdgeCoster] = EdgeCoster) -> EdgeCoster:
        """Return the edge coster of this objective under a map."""
        return coster_type(arm, fmap, delta, self.terms())


@dataclass(frozen=True)
class FailureProbabilityObjective(Objective):
    """
    Minus the log success probability, plus ``length_weight`` times the length (lambda).

    ``reach`` [m]: how far a failure's probability extends (infinite: the paper's kernel;
    finite: the informed method's idea h, :meth:`FailureMap.probability`).
    """

    length_weight: float = DEFAULT_LENGTH_WEIGHT
    reach: float = math.inf

    def __post_init__(self) -> None:
        """Refuse a negative length weight or a reach that is not positive."""
        if not self.length_weight >= 0:
            raise ValueError(f'length_weight must be >= 0, got {self.length_weight}')
        if not self.reach > 0:
            raise ValueError(f'reach must be > 0 (inf: none), got {self.reach}')

    def terms(self) -> EdgeTerms:
        """Return the risk term at weight 1, lambda on length, nothing infeasible."""
        return EdgeTerms(self.length_weight, 1.0, math.inf, None, self.reach)


@dataclass(frozen=True)
class HardThresholdObjective(Objective):
    """Length; an edge with a point probability above ``threshold`` (Y) is infeasible."""

    threshold: float = DEFAULT_THRESHOLD
    c_fail: float = HARD_C_FAIL

    def __post_init__(self) -> None:
        """Refuse a threshold outside [0, 1] or a C_FAIL that is not positive."""
        if not 0.0 <= self.threshold <= 1.0:
            raise ValueError(f'threshold must be in [0, 1], got {self.threshold}')
        if not (math.isfinite(self.c_fail) and self.c_fail > 0):
            raise ValueError(f'c_fail must be a positive number, got {self.c_fail}')

    def terms(self) -> EdgeTerms:
        """Return length at weight 1, no risk term, the cap Y, Hard's own C_FAIL."""
        return EdgeTerms(1.0, 0.0, self.threshold, self.c_fail)

    def reach(self) -> float:
        """Return how far [m] straight ahead of a failure points are forbidden."""
        return math.sqrt(max(0.0, 1.0 / self.threshold - 1.0) / self.c_fail) \
            if self.threshold > 0 else math.inf
