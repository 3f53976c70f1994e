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
ProbRRT: the paper's probabilistic bidirectional RRT (Algorithms 1-5), and the Hard baseline.

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
* RewireNeighbours (RRT*): the new node takes the cheapest parent among the nodes within
  ``rewire_radius``, and neighbours whose cost improves through it are re-parented.

Costs are additive edge costs (:mod:`probdis_ros.model.path_cost`), always of the edge in the
direction the arm will execute it: parent -> child in the start tree, child -> parent in the
goal tree (whose costs are therefore costs-to-go).  Connect (Algorithm 1) joins each leaf of
the goal tree to the start-tree node (of its ``connect_candidates`` nearest; 0: all) that
gives the cheapest whole path, and the least-cost start-to-goal path is returned.

The Hard baseline is the same planner with ``hard_threshold = Y``: an edge with any point
probability above Y is infeasible and the cost of a feasible edge is its length.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import time

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.model.edge_costs import EdgeCoster
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.model.kernels import farthest_kernel


@dataclass
class RRTSettings:
    """ProbRRT parameters; defaults are the paper's where it gives them."""

    iterations: int = 100           # K, per tree
    delta: float = 0.04             # discretisation of edges [rad]
    n_random: int = 100             # |C_RAND|
    p_goal: float = 0.1             # P_GOAL
    step: float = 1.0               # longest new edge [rad] (NewConfiguration)
    rewire_radius: float = 0.8      # RRT* neighbourhood [rad]
    length_weight: float = 0.01     # lambda
    closest_candidates: int = 10    # k nearest in joint space are costed; 0: every node (paper)
    connect_candidates: int = 10    # likewise for Connect
    hard_threshold: float | None = None   # Y of the Hard baseline; None: probabilistic

    def __post_init__(self) -> None:
        """Refuse settings the planner cannot work with."""
        checks = [(self.iterations >= 1, 'iterations must be >= 1'),
                  (self.delta > 0, 'delta must be > 0'),
                  (self.n_random >= 1, 'n_random must be >= 1'),
                  (0.0 <= self.p_goal <= 1.0, 'p_goal must be in [0, 1]'),
                  (self.step > 0, 'step must be > 0'),
                  (self.rewire_radius >= 0, 'rewire_radius must be >= 0'),
                  (self.length_weight >= 0, 'length_weight must be >= 0'),
                  (self.closest_candidates >= 0, 'closest_candidates must be >= 0'),
                  (self.connect_candidates >= 0, 'connect_candidates must be >= 0'),
                  (self.hard_threshold is None or 0 <= self.hard_threshold <= 1,
                   'hard_threshold must be in [0, 1]')]
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


@dataclass
class _Tree:
    """Nodes, parents and costs of one tree; reverse for the goal tree (costs-to-go)."""

    nodes: np.ndarray
    positions: np.ndarray
    reverse: bool
    parent: list[int] = field(default_factory=list)
    edge: list[float] = field(default_factory=list)
    costs: np.ndarray = field(default_factory=lambda: np.zeros(0))
    size: int = 0

    @classmethod
    def rooted(cls, root: np.ndarray, root_position: np.ndarray, capacity: int,
               reverse: bool) -> _Tree:
        nodes = np.empty((capacity, len(root)))
        positions = np.empty((capacity, len(root_position)))
        tree = cls(nodes, positions, reverse, costs=np.empty(capacity))
        tree.append(root, root_position, -1, 0.0, 0.0)
        return tree

    @property
    def cost(self) -> np.ndarray:
        """Cost-to-come (start tree) or cost-to-go (goal tree) of every node."""
        return self.costs[:self.size]

    def append(self, node: np.ndarray, position: np.ndarray, parent: int, edge: float,
               cost: float) -> int:
        self.nodes[self.size] = node
        self.positions[self.size] = position
        self.parent.append(parent)
        self.edge.append(edge)
        self.costs[self.size] = cost
        self.size += 1
        return self.size - 1

    def reparent(self, index: int, parent: int, edge: float) -> None:
        """Move a node under a new parent and update the costs of its whole subtree."""
        self.parent[index] = parent
        self.edge[index] = edge
        children: dict[int, list[int]] = {}
        for child, par in enumerate(self.parent):
            children.setdefault(par, []).append(child)
        stack = [index]
        while stack:
            node = stack.pop()
            self.costs[node] = self.costs[self.parent[node]] + self.edge[node]
            stack.extend(children.get(node, []))

    def chain(self, index: int) -> list[int]:
        """Node indices from index up to the root."""
        out = [index]
        while self.parent[out[-1]] >= 0:
            out.append(self.parent[out[-1]])
        return out

    def leaves(self) -> np.ndarray:
        has_child = np.zeros(self.size, dtype=bool)
        for par in self.parent[1:]:
            has_child[par] = True
        return np.flatnonzero(~has_child)


class ProbRRT:
    """Plans least-cost joint-space paths under a failure map."""

    def __init__(self, arm: Arm, settings: RRTSettings | None = None,
                 coster_type: type[EdgeCoster] = EdgeCoster) -> None:
        self.arm = arm
        self.settings = settings or RRTSettings()
        self.coster_type = coster_type
        self._warm_up()

    def _warm_up(self) -> None:
        """Load (or compile) the kernels now, so that no plan's time includes it."""
        fmap = FailureMap(self.arm.task_space)
        middle = (self.arm.lower + self.arm.upper) / 2
        pose = self.arm.fk(middle)
        q = None if pose.orientations is None else pose.orientations[0]
        fmap.add(pose.positions[0], np.ones(self.arm.task_space.dim), q)
        coster = self.coster_type(self.arm, fmap, self.settings.delta)
        coster.costs(middle[None], self.arm.upper)
        coster.cheapest(middle[None], self.arm.upper)
        farthest_kernel(pose.positions, pose.positions)

    def plan(self, start: np.ndarray, goal: np.ndarray, fmap: FailureMap,
             rng: np.random.Generator) -> Plan | None:
        """Return the least-cost path from start to goal found, or None if none is feasible."""
        t0 = time.perf_counter()
        s = self.settings
        start = self._checked(start, 'start')
        goal = self._checked(goal, 'goal')
        coster = self.coster_type(self.arm, fmap, s.delta, s.length_weight, s.hard_threshold)
        capacity = s.iterations + 1
        ends = self.arm.positions(np.array([start, goal]))
        trees = (_Tree.rooted(start, ends[0], capacity, reverse=False),
                 _Tree.rooted(goal, ends[1], capacity, reverse=True))
        for tree, other in (trees, trees[::-1]):
            targets = self._random_configurations(tree, other.nodes[0], rng)
            for target in targets:
                self._extend(tree, target, coster)
        plan = self._connect(trees[0], trees[1], coster)
        if plan is not None:
            plan.plan_time_s = time.perf_counter() - t0
            plan.tree_sizes = (trees[0].size, trees[1].size)
        return plan

    def _checked(self, config: np.ndarray, name: str) -> np.ndarray:
        config = self.arm.as_batch(config)[0]
        if not (np.all(np.isfinite(config)) and self.arm.within_limits(config)[0]):
            raise ValueError(f'{name} configuration is outside the joint limits: {config}')
        return config

    def _random_configurations(self, tree: _Tree, other_root: np.ndarray,
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

    def _nearest(self, tree: _Tree, config: np.ndarray, k: int) -> np.ndarray:
        """Tree node indices sorted by joint-space distance to config (the k nearest if k)."""
        d2 = ((tree.nodes[:tree.size] - config) ** 2).sum(axis=1)
        order = np.argsort(d2, kind='stable')
        return order[:k] if k else order

    def _extend(self, tree: _Tree, target: np.ndarray, coster: EdgeCoster) -> None:
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

    def _insert(self, tree: _Tree, new: np.ndarray, closest: int, coster: EdgeCoster) -> None:
        """Add new under its cheapest neighbour (RRT*), then rewire the neighbours."""
        s = self.settings
        d2 = ((tree.nodes[:tree.size] - new) ** 2).sum(axis=1)
        near = np.flatnonzero(d2 <= s.rewire_radius ** 2)
        if not (near == closest).any():
            near = np.sort(np.append(near, closest))
        costs_to = tree.cost[near]
        best, total = coster.cheapest(tree.nodes[near], new, toward=not tree.reverse,
                                      base=costs_to)
        if best < 0:
            return
        position = self.arm.positions(new)[0]
        index = tree.append(new, position, int(near[best]), total - costs_to[best], total)
        others = np.concatenate((near[:best], near[best + 1:]))
        if len(others) == 0:
            return
        out = coster.costs(tree.nodes[others], new, toward=tree.reverse)
        through = tree.cost[index] + out
        for node, edge, total in zip(others, out, through):
            if total < tree.cost[node] and node not in tree.chain(index):
                tree.reparent(int(node), index, float(edge))

    def _connect(self, start_tree: _Tree, goal_tree: _Tree, coster: EdgeCoster) -> Plan | None:
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
