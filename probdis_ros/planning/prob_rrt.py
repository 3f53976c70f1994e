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
ProbRRT: the paper's probabilistic bidirectional RRT (Algorithms 1-5), for any objective.

Two trees grow for K iterations each, one from the start and one from the goal.  Each
iteration (Algorithm 2):

* RandomConfiguration: with probability P_GOAL the other tree's root, else of |C_RAND|
  uniform samples within the joint limits the one farthest in task space (end-effector
  position) from the tree.
* ClosestConfiguration: the tree node whose edge to the sample costs least, found exactly
  and best-first (:meth:`EdgeCoster.cheapest`: an edge is costed only as far as it can still
  win).  Decision left open by the paper: only the ``closest_candidates`` (default 10)
  nodes nearest in joint space are candidates, ``0`` makes every node one, as in the paper.
  DESIGN measured the same success with 10 and a plan ~2-3x faster; so did we
  (README "Planner speed").
* NewConfiguration: a step of at most ``step`` (joint-space length) from that node toward the
  sample; both ends are inside the box of joint limits, so the step is too.
* RewireNeighbours (RRT*): the new node takes the cheapest parent among its neighbours, and
  neighbours whose cost improves through it are re-parented (their subtrees' costs follow,
  :meth:`Tree.reparent`).  The paper does not say which neighbours; we take OMPL's RRT*
  default, the ``k = ceil(k_RRT log n)`` nearest in joint space with
  ``k_RRT = rewire_factor * e * (1 + 1/d)`` (d joints, n nodes; about 15 of 100 nodes for
  d = 7), which always holds neighbours, unlike a fixed radius below the step (0.8 rad
  against 1 rad held ~0.05 neighbours and re-parented 0 of 573 nodes).  ``rewire_factor = 0``
  turns rewiring off (the closest node is the parent).  Only edges cheaper than a
  neighbour's cost matter, so they are costed only that far (exact pruning).

Costs are additive edge costs given by the planner's objective
(:mod:`probdis_ros.planning.objectives`), always of the edge in the direction the arm will
execute it: parent -> child in the start tree, child -> parent in the goal tree (whose costs
are therefore costs-to-go).  Connect (Algorithm 1) joins each leaf of the goal tree to the
start-tree node (of its ``connect_candidates`` nearest; 0: all) that gives the cheapest whole
path, and the least-cost start-to-goal path is returned.  The planner never knows which
method it runs: Probabilistic and Hard differ only in the objective they hand it.

Anytime (beyond the paper): with a ``plan_time`` budget the trees grow in further rounds of K
iterations each while the budget has room for another round as long as the last, and Connect
then takes the best path of the larger trees; ``plan_time = 0`` (the default) is the paper's
single round of K, exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.model.edge_costs import EdgeCoster
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.model.kernels import farthest_kernel
from probdis_ros.planning.objectives import FailureProbabilityObjective, Objective
from probdis_ros.planning.tree import Tree


@dataclass
class RRTSettings:
    """ProbRRT parameters; defaults are the paper's where it gives them."""

    iterations: int = 100           # K, per tree
    delta: float = 0.04             # discretisation of edges [rad]
    n_random: int = 100             # |C_RAND|
    p_goal: float = 0.1             # P_GOAL
    step: float = 1.0               # longest new edge [rad] (NewConfiguration)
    rewire_factor: float = 1.0      # RRT* neighbours: k = ceil(factor e (1 + 1/d) log n); 0: none
    rewire_radius: float = 0.0      # and only those this near [rad]; 0: no limit
    plan_time: float = 0.0          # anytime budget [s]: more rounds of K while it lasts; 0: one
    closest_candidates: int = 10    # k nearest in joint space are costed; 0: every node (paper)
    connect_candidates: int = 10    # likewise for Connect

    def __post_init__(self) -> None:
        """Refuse settings the planner cannot work with."""
        checks = [(self.iterations >= 1, 'iterations must be >= 1'),
                  (self.delta > 0, 'delta must be > 0'),
                  (self.n_random >= 1, 'n_random must be >= 1'),
                  (0.0 <= self.p_goal <= 1.0, 'p_goal must be in [0, 1]'),
                  (self.step > 0, 'step must be > 0'),
                  (self.rewire_factor >= 0, 'rewire_factor must be >= 0'),
                  (self.rewire_radius >= 0, 'rewire_radius must be >= 0'),
                  (self.plan_time >= 0, 'plan_time must be >= 0'),
                  (self.closest_candidates >= 0, 'closest_candidates must be >= 0'),
                  (self.connect_candidates >= 0, 'connect_candidates must be >= 0')]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)


@dataclass
class Plan:
    """A planned path: via points ``(M, n_joints)`` from start to goal and its cost."""

    path: np.ndarray
    cost: float
    plan_time_s: float = 0.0
    tree_sizes: tuple[int, int] = (0, 0)
    rewires: int = 0                # RRT* re-parentings in both trees


class ProbRRT:
    """Plans least-cost joint-space paths under a failure map, for an objective."""

    def __init__(self, arm: Arm, settings: RRTSettings | None = None,
                 objective: Objective | None = None,
                 coster_type: type[EdgeCoster] = EdgeCoster) -> None:
        self.arm = arm
        self.settings = settings or RRTSettings()
        self.objective = objective or FailureProbabilityObjective()
        self.coster_type = coster_type
        self._warm_up()

    def _warm_up(self) -> None:
        """Load (or compile) the kernels now, so that no plan's time includes it."""
        fmap = FailureMap(self.arm.task_space)
        middle = (self.arm.lower + self.arm.upper) / 2
        pose = self.arm.fk(middle)
        q = None if pose.orientations is None else pose.orientations[0]
        fmap.add(pose.positions[0], np.ones(self.arm.task_space.dim), q)
        coster = self.objective.coster(self.arm, fmap, self.settings.delta, self.coster_type)
        coster.costs(middle[None], self.arm.upper, limits=np.inf)
        coster.cheapest(middle[None], self.arm.upper)
        farthest_kernel(pose.positions, pose.positions)

    def plan(self, start: np.ndarray, goal: np.ndarray, fmap: FailureMap,
             rng: np.random.Generator) -> Plan | None:
        """Return the least-cost path from start to goal found, or None if none is feasible."""
        t0 = time.perf_counter()
        coster = self.objective.coster(self.arm, fmap, self.settings.delta, self.coster_type)
        trees = self.grow(start, goal, coster, rng, t0)
        plan = self._connect(trees[0], trees[1], coster)
        if plan is not None:
            plan.plan_time_s = time.perf_counter() - t0
            plan.tree_sizes = (trees[0].size, trees[1].size)
            plan.rewires = trees[0].rewires + trees[1].rewires
        return plan

    def grow(self, start: np.ndarray, goal: np.ndarray, coster: EdgeCoster,
             rng: np.random.Generator, t0: float | None = None) -> tuple[Tree, Tree]:
        """
        Grow the start and the goal tree, K iterations each (public for inspection).

        With a ``plan_time`` budget, rounds of K iterations per tree go on while the budget
        (counted from t0) has room for another round as long as the last one; without, one
        round: the paper's planner exactly.
        """
        s = self.settings
        start = self._checked(start, 'start')
        goal = self._checked(goal, 'goal')
        t0 = time.perf_counter() if t0 is None else t0
        capacity = s.iterations + 1
        ends = self.arm.positions(np.array([start, goal]))
        trees = (Tree.rooted(start, ends[0], capacity, reverse=False),
                 Tree.rooted(goal, ends[1], capacity, reverse=True))
        while True:
            round_start = time.perf_counter()
            for tree, other in (trees, trees[::-1]):
                for target in self._random_configurations(tree, other.nodes[0], rng):
                    self._extend(tree, target, coster)
            now = time.perf_counter()
            if now - t0 + (now - round_start) > s.plan_time:
                return trees

    def _checked(self, config: np.ndarray, name: str) -> np.ndarray:
        config = self.arm.as_batch(config)[0]
        if not (np.all(np.isfinite(config)) and self.arm.within_limits(config)[0]):
            raise ValueError(f'{name} configuration is outside the joint limits: {config}')
        return config

    def _random_configurations(self, tree: Tree, other_root: np.ndarray,
                               rng: np.random.Generator):
        """
        Yield RandomConfiguration's target of each of the tree's K iterations.

        All draws are made up front (goal-bias draws, then |C_RAND| samples per iteration)
        and their positions computed in one FK batch; the farthest sample depends on the tree
        as it has grown, so it is chosen when its iteration comes.
        """
        s = self.settings
        to_goal = rng.random(s.iterations) < s.p_goal
        samples = self.arm.random_configurations(rng, s.iterations * s.n_random)
        positions = self.arm.positions(samples)
        for k in range(s.iterations):
            if to_goal[k]:
                yield other_root
                continue
            rows = slice(k * s.n_random, (k + 1) * s.n_random)
            yield samples[rows][farthest_kernel(positions[rows],
                                                tree.positions[:tree.size])]

    def _nearest(self, tree: Tree, config: np.ndarray, k: int) -> np.ndarray:
        """Tree node indices sorted by joint-space distance to config (the k nearest if k)."""
        d2 = ((tree.nodes[:tree.size] - config) ** 2).sum(axis=1)
        order = np.argsort(d2, kind='stable')
        return order[:k] if k else order

    def _extend(self, tree: Tree, target: np.ndarray, coster: EdgeCoster) -> None:
        s = self.settings
        candidates = self._nearest(tree, target, s.closest_candidates)
        best, _ = coster.cheapest(tree.nodes[candidates], target, toward=not tree.reverse)
        if best < 0:
            return
        closest = candidates[best]
        direction = target - tree.nodes[closest]
        distance = float(np.linalg.norm(direction))
        if distance == 0.0:
            return
        new = tree.nodes[closest] + direction * min(1.0, s.step / distance)
        self._insert(tree, new, closest, coster)

    def _neighbours(self, tree: Tree, config: np.ndarray, closest: int) -> np.ndarray:
        """Return RRT*'s neighbourhood of config: its k nearest nodes, and closest."""
        factor = self.settings.rewire_factor
        if factor == 0:
            return np.array([closest])
        d = self.arm.n_joints
        k = math.ceil(factor * math.e * (1 + 1 / d) * math.log(tree.size + 1))
        near = self._nearest(tree, config, k)
        radius = self.settings.rewire_radius
        if radius > 0:
            d2 = ((tree.nodes[near] - config) ** 2).sum(axis=1)
            near = near[d2 <= radius * radius]
        return near if (near == closest).any() else np.append(near, closest)

    def _insert(self, tree: Tree, new: np.ndarray, closest: int, coster: EdgeCoster) -> None:
        """Add new under its cheapest neighbour (RRT*), then rewire the neighbours."""
        near = self._neighbours(tree, new, closest)
        costs_to = tree.cost[near]
        best, total = coster.cheapest(tree.nodes[near], new, toward=not tree.reverse,
                                      base=costs_to)
        if best < 0:
            return
        parent = int(near[best])
        edge = total - costs_to[best]
        position = self.arm.positions(new)[0]
        index = tree.append(new, position, parent, edge, tree.costs[parent] + edge)
        others = np.delete(near, best)
        if len(others) == 0:
            return
        # only an edge cheaper than what the neighbour costs now can improve it
        out = coster.costs(tree.nodes[others], new, toward=tree.reverse,
                           limits=tree.cost[others] - tree.cost[index])
        for node, edge_out in zip(others.tolist(), out.tolist()):
            if tree.cost[index] + edge_out < tree.cost[node] and \
                    not tree.is_ancestor(node, index):
                tree.reparent(node, index, edge_out)

    def _connect(self, start_tree: Tree, goal_tree: Tree, coster: EdgeCoster) -> Plan | None:
        """Join each goal-tree leaf to its best start-tree node; keep the cheapest path."""
        s = self.settings
        best_total, best_pair = np.inf, None
        start_costs = start_tree.cost
        for leaf in goal_tree.leaves():
            leaf_config = goal_tree.nodes[leaf]
            candidates = self._nearest(start_tree, leaf_config, s.connect_candidates)
            i, total = coster.cheapest(start_tree.nodes[candidates], leaf_config,
                                       base=start_costs[candidates] + goal_tree.cost[leaf])
            if total < best_total:
                best_total, best_pair = total, (int(candidates[i]), int(leaf))
        if best_pair is None:
            return None
        head = start_tree.chain(best_pair[0])[::-1]
        tail = goal_tree.chain(best_pair[1])
        path = np.vstack([start_tree.nodes[head], goal_tree.nodes[tail]])
        # a start-tree node that reached the goal tree's root exactly joins it twice
        repeated = np.all(path[1:] == path[:-1], axis=1)
        return Plan(path[np.concatenate(([True], ~repeated))], best_total)
