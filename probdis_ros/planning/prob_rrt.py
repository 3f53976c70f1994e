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

Joint margin (beyond the paper): samples, new nodes and the smoothing's moves keep
``joint_margin`` (0 by default, the paper's planner; ``ROBOT_JOINT_MARGIN`` = 0.035 rad, about
2 degrees, on the robot) from every joint limit, so that no
via point asks the arm to go right to a limit.  A start or goal inside the true limits but
within the margin is accepted: its tree grows from it into the shrunk box (a new node is
clipped into it), so the start and goal are the only via points that may lie outside it.
(A run on the arm refuses such a goal, :func:`probdis_ros.run.goal_problem`: the arm
overshoots a goal as it comes to rest.)
``joint_margin = 0`` is the paper's planner, and gives the plans of before the margin bit
for bit.
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

Anytime (beyond the paper): with a ``plan_time`` budget the trees grow alternately in
slices of 1, 2, 4, ... up to ``anytime_slice`` iterations (each slice with its own draws)
while ``1 - refine_share`` of the budget lasts, Connect takes the best path, and
:meth:`ProbRRT.refine` improves that path on the same cost until the budget ends
(shortcuts, then via points moved and edges split, each kept only if the cost falls).
``plan_time = 0`` (the default) is the paper's single round of K, exactly.  Measured
beside OMPL's BIT* by ``probdis bench quality``.

Speed: the iterations run compiled (:mod:`probdis_ros.model.tree_kernels`) on the arrays
of :class:`Tree`; this module's Python loop is the reference they equal bit for bit, and it
serves the planar arm and the reference coster (``compiled=False`` forces it).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise
import time

import numpy as np
from probdis_ros.model.arms import Arm
from probdis_ros.model.edge_costs import EdgeCoster
from probdis_ros.model.failure_map import FailureMap
from probdis_ros.model.kinematics import PLANAR
from probdis_ros.model.path_cost import DEFAULT_DELTA
from probdis_ros.model.tree_kernels import (
    connect_kernel,
    farthest_kernel,
    grow_kernel,
    nearest_order,
    neighbour_count,
    step_toward,
)
from probdis_ros.planning.objectives import FailureProbabilityObjective, Objective
from probdis_ros.planning.tree import Tree

#: [rad] kept from every joint limit on the robot (planner node, robot experiment; about 2
#: degrees): a plan never asks the arm to go right to a limit, where a controller's own
#: margin (the real iiwa stops short of the URDF limits) would refuse it.  RRTSettings keeps
#: 0, the paper's planner, so that the simulated sweeps reproduce it path for path.
ROBOT_JOINT_MARGIN = 0.035
#: The most samples a round may draw (K x |C_RAND|): it draws them all at once, about 80 B
#: each (0.8 GB here); more would exhaust a robot PC's memory in the middle of a run.
MAX_ROUND_SAMPLES = 10_000_000


@dataclass
class RRTSettings:
    """ProbRRT parameters; defaults are the paper's where it gives them."""

    iterations: int = 100           # K, per tree
    delta: float = DEFAULT_DELTA    # discretisation of edges [rad]
    n_random: int = 100             # |C_RAND|
    p_goal: float = 0.1             # P_GOAL
    step: float = 1.0               # longest new edge [rad] (NewConfiguration)
    rewire_factor: float = 1.0      # RRT* neighbours: k = ceil(factor e (1 + 1/d) log n); 0: none
    rewire_radius: float = 0.0      # and only those this near [rad]; 0: no limit
    plan_time: float = 0.0          # anytime budget [s] (grow, then refine the path); 0: the paper
    anytime_slice: int = 10         # anytime: iterations per tree between looks at the clock
    refine_share: float = 0.5       # anytime: share of the budget kept for refining the path
    closest_candidates: int = 10    # k nearest in joint space are costed; 0: every node (paper)
    connect_candidates: int = 10    # likewise for Connect
    joint_margin: float = 0.0       # [rad] kept from every joint limit; 0: none (the paper)
    # [rad] a narrower range the trees keep to, per joint (a cell's room: A1 within +-1.5
    # keeps the arm in front of its base); None: the joint limits
    joint_lower: tuple[float, ...] | None = None
    joint_upper: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        """Refuse settings the planner cannot work with."""
        checks = [(self.iterations >= 1, 'iterations must be >= 1'),
                  (self.delta > 0, 'delta must be > 0'),
                  (self.n_random >= 1, 'n_random must be >= 1'),
                  (self.iterations * self.n_random <= MAX_ROUND_SAMPLES,
                   f'iterations x n_random must be at most {MAX_ROUND_SAMPLES:,} (a round '
                   f'draws {self.iterations:,} x {self.n_random:,} samples at once, about 80 '
                   'B each)'),
                  (0.0 <= self.p_goal <= 1.0, 'p_goal must be in [0, 1]'),
                  (self.step > 0, 'step must be > 0'),
                  (self.rewire_factor >= 0, 'rewire_factor must be >= 0'),
                  (self.rewire_radius >= 0, 'rewire_radius must be >= 0'),
                  (self.plan_time >= 0, 'plan_time must be >= 0'),
                  (self.anytime_slice >= 1, 'anytime_slice must be >= 1'),
                  (0.0 <= self.refine_share < 1.0, 'refine_share must be in [0, 1)'),
                  (self.closest_candidates >= 0, 'closest_candidates must be >= 0'),
                  (self.connect_candidates >= 0, 'connect_candidates must be >= 0'),
                  (self.joint_margin >= 0, 'joint_margin must be >= 0')]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)


def planning_box(arm: Arm, settings: RRTSettings) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the (low, high) that a planner's samples and steps keep to.

    The joint limits less ``joint_margin``, narrowed to ``joint_lower`` / ``joint_upper``
    where given; ValueError where that leaves no room.
    """
    margin = settings.joint_margin
    if np.any(arm.upper - arm.lower <= 2 * margin):
        raise ValueError(f'joint_margin {margin} leaves no room between the joint limits')
    low, high = arm.lower + margin, arm.upper - margin
    for name, bound in (('joint_lower', settings.joint_lower),
                        ('joint_upper', settings.joint_upper)):
        if bound is not None and np.shape(bound) != (arm.n_joints,):
            raise ValueError(f'{name} must give {arm.n_joints} values, got {bound}')
    if settings.joint_lower is not None:
        low = np.maximum(low, np.asarray(settings.joint_lower, dtype=float))
    if settings.joint_upper is not None:
        high = np.minimum(high, np.asarray(settings.joint_upper, dtype=float))
    if np.any(high <= low):
        joint = int(np.argmax(low - high))
        raise ValueError(f'A{joint + 1}: joint_lower and joint_upper leave no room within the '
                         f'joint limits (less joint_margin)')
    return low, high


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
                 coster_type: type[EdgeCoster] = EdgeCoster,
                 compiled: bool = True) -> None:
        self.arm = arm
        self.settings = settings or RRTSettings()
        self.objective = objective or FailureProbabilityObjective()
        self.coster_type = coster_type
        # the compiled loop where it can run (a chain arm, the compiled coster); the Python
        # loop is its reference, bit for bit
        self.compiled = compiled and arm.kernel_params()[0] != PLANAR
        s = self.settings
        # the box that samples, steps, probes and smoothing keep to (a start or goal may lie
        # between it and the limits: the trees grow from it into the box)
        self.low, self.high = planning_box(arm, s)
        # steps are clipped into the box where it is narrower than the joint limits
        self.clips = s.joint_margin > 0 or s.joint_lower is not None or \
            s.joint_upper is not None
        self._warm_up()

    def _warm_up(self) -> None:
        """Load (or compile) the kernels now, so that no plan's time includes it."""
        fmap = FailureMap(self.arm.task_space)
        middle = (self.arm.lower + self.arm.upper) / 2
        pose = self.arm.fk(middle)
        q = None if pose.orientations is None else pose.orientations[0]
        for sign in (1.0, -1.0):    # two failures: the arrays' layout of every real map
            fmap.add(pose.positions[0], sign * np.ones(self.arm.task_space.dim), q)
        coster = self.objective.coster(self.arm, fmap, self.settings.delta, self.coster_type)
        upper = np.array(self.arm.upper, dtype=float)     # the layout of the planner's rows
        for target in (upper, self.arm.upper):
            coster.costs(middle[None], target, limits=np.inf)
            coster.cheapest(middle[None], target)
        farthest_kernel(pose.positions, pose.positions)
        if self._compiles(coster):
            rng = np.random.default_rng(0)
            trees = self._roots(self.arm.lower, self.arm.upper, 2)
            self._grow_round(trees[0], trees[1].nodes[0], coster, rng, 2)
            self._connect(trees[0], trees[1], coster)

    def _compiles(self, coster: EdgeCoster) -> bool:
        return self.compiled and coster.compiled

    def plan(self, start: np.ndarray, goal: np.ndarray, fmap: FailureMap,
             rng: np.random.Generator) -> Plan | None:
        """Return the least-cost path from start to goal found, or None if none is feasible."""
        t0 = time.perf_counter()
        here = self._checked(start, 'start')
        there = self._checked(goal, 'goal')
        problem = self.arm.table_problem(there)
        if problem:
            raise ValueError(f'goal configuration {problem}: {there}')
        if np.array_equal(here, there):
            return Plan(here[None], 0.0)        # there already: no detour
        coster = self.objective.coster(self.arm, fmap, self.settings.delta, self.coster_type)
        trees = self.grow(start, goal, coster, rng, t0)
        plan = self._connect(trees[0], trees[1], coster)
        if plan is not None and self.settings.plan_time > 0:
            plan = self.refine(plan, coster, rng, t0 + self.settings.plan_time)
        if plan is not None:
            plan.plan_time_s = time.perf_counter() - t0
            plan.tree_sizes = (trees[0].size, trees[1].size)
            plan.rewires = trees[0].rewires + trees[1].rewires
        return plan

    def _roots(self, start: np.ndarray, goal: np.ndarray, capacity: int,
               coster: EdgeCoster | None = None, rng: np.random.Generator | None = None
               ) -> tuple[Tree, Tree]:
        """Return the start and the goal tree, each its root alone (coster, rng: subclasses')."""
        ends = self.arm.positions(np.array([start, goal]))
        return (Tree.rooted(start, ends[0], capacity, reverse=False),
                Tree.rooted(goal, ends[1], capacity, reverse=True))

    def grow(self, start: np.ndarray, goal: np.ndarray, coster: EdgeCoster,
             rng: np.random.Generator, t0: float | None = None) -> tuple[Tree, Tree]:
        """
        Grow the start and the goal tree (public for inspection).

        Without a ``plan_time`` budget, one round of K iterations per tree: the paper's
        planner exactly.  With one, the trees grow alternately in slices of 1, 2, 4, ... up
        to ``anytime_slice`` iterations, each with its own draws, until the share of the
        budget (counted from t0) not kept for refining the path has no room for another.
        """
        s = self.settings
        start = self._checked(start, 'start')
        goal = self._checked(goal, 'goal')
        t0 = time.perf_counter() if t0 is None else t0
        trees = self._roots(start, goal, s.iterations + 1, coster, rng)
        if s.plan_time <= 0:
            for tree, other in (trees, trees[::-1]):
                self._grow_round(tree, other.nodes[0], coster, rng, s.iterations)
            return trees
        grow_until = t0 + s.plan_time * (1.0 - s.refine_share)
        iterations = 1          # doubling up to anytime_slice: small budgets are kept too
        while True:
            slice_start = time.perf_counter()
            for tree, other in (trees, trees[::-1]):
                self._grow_round(tree, other.nodes[0], coster, rng, iterations)
            now = time.perf_counter()
            following = min(2 * iterations, s.anytime_slice)
            if now + (now - slice_start) * following / iterations > grow_until:
                return trees
            iterations = following

    def _draws(self, rng: np.random.Generator, iterations: int):
        """
        Return a round's draws: goal-bias coins, |C_RAND| samples per iteration, positions.

        All are made up front, in this order, by both loops; the farthest sample depends on
        the tree as it has grown, so it is chosen when its iteration comes.
        """
        s = self.settings
        to_goal = rng.random(iterations) < s.p_goal
        samples = self.arm.random_within(rng, iterations * s.n_random, self.low, self.high)
        # only the samples of iterations that do not aim at the other root are looked at
        return to_goal, samples, self.arm.sample_positions(samples,
                                                           np.repeat(~to_goal, s.n_random))

    def _grow_round(self, tree: Tree, other_root: np.ndarray, coster: EdgeCoster,
                    rng: np.random.Generator, iterations: int) -> None:
        """Run iterations of one tree: compiled where it can, else the Python loop."""
        s = self.settings
        to_goal, samples, positions = self._draws(rng, iterations)
        if self._compiles(coster):
            tree.reserve(iterations)
            grow_kernel(tree.nodes, tree.positions, tree.parent, tree.edge, tree.costs,
                        tree.first_child, tree.next_sibling, tree.counts, to_goal, samples,
                        positions, 0, iterations, other_root, s.n_random, s.step, self.low,
                        self.high, self.clips, s.rewire_factor, s.rewire_radius,
                        s.closest_candidates, tree.reverse, *coster.kernel_args())
            return
        for k in range(iterations):
            if to_goal[k]:
                target = other_root
            else:
                rows = slice(k * s.n_random, (k + 1) * s.n_random)
                target = samples[rows][farthest_kernel(positions[rows],
                                                       tree.positions[:tree.size])]
            self._extend(tree, target, coster)

    def _checked(self, config: np.ndarray, name: str) -> np.ndarray:
        config = self.arm.as_batch(config)[0]
        problem = self.arm.limit_problem(config)
        if problem:
            raise ValueError(f'{name} configuration is outside the joint limits: {problem}')
        return config

    def _nearest(self, tree: Tree, config: np.ndarray, k: int) -> np.ndarray:
        """Tree node indices sorted by joint-space distance to config (the k nearest if k)."""
        return nearest_order(tree.nodes, tree.size, config, k)

    def _extend(self, tree: Tree, target: np.ndarray, coster: EdgeCoster) -> None:
        s = self.settings
        candidates = self._nearest(tree, target, s.closest_candidates)
        best, _ = coster.cheapest(tree.nodes[candidates], target, toward=not tree.reverse)
        if best < 0:
            return
        closest = candidates[best]
        new = np.empty(self.arm.n_joints)
        if step_toward(tree.nodes[closest], target, s.step, new, self.low, self.high,
                       self.clips):
            self._insert(tree, new, closest, coster)

    def _neighbours(self, tree: Tree, config: np.ndarray, closest: int) -> np.ndarray:
        """Return RRT*'s neighbourhood of config: its k nearest nodes, and closest."""
        factor = self.settings.rewire_factor
        if factor == 0:
            return np.array([closest])
        near = self._nearest(tree, config, neighbour_count(factor, self.arm.n_joints,
                                                           tree.size))
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
        if self._compiles(coster):
            size = goal_tree.size
            first, leaf, best_total = connect_kernel(
                start_tree.nodes[:start_tree.size], start_tree.cost, goal_tree.nodes[:size],
                goal_tree.cost, goal_tree.first_child[:size], s.connect_candidates,
                *coster.kernel_args())
            best_pair = None if first < 0 else (int(first), int(leaf))
        else:
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
        return Plan(path[np.concatenate(([True], ~repeated))], float(best_total))

    def refine(self, plan: Plan, coster: EdgeCoster, rng: np.random.Generator,
               deadline: float) -> Plan:
        """
        Improve a path on the same cost until the deadline (the anytime mode's second half).

        Shortcuts first: from each via point, the farthest later one whose straight edge
        costs less than the path between them.  Then, until the deadline, local moves, each
        kept only if it lowers the cost: a via point moved by a Gaussian step (its size
        grows after a success and shrinks after a miss), and now and then the costliest edge
        split at its middle.  Edges are costed only as far as they can still win
        (``limits``).  The trees only find the way around the failures; the moves then pull
        the path into the cheapest nearby shape, which a tree of K nodes cannot represent.
        """
        path = [np.array(q) for q in plan.path]
        edges = [coster.cost(a, b) for a, b in pairwise(path)]

        def edge(a: np.ndarray, b: np.ndarray, limit: float) -> float:
            return float(coster.costs(a[None], b, limits=limit)[0])

        i = 0
        while i < len(path) - 2:
            for j in range(len(path) - 1, i + 1, -1):
                along = sum(edges[i:j])
                direct = edge(path[i], path[j], along)
                if direct < along:
                    path[i + 1:j] = []
                    edges[i:j] = [direct]
                    break
            i += 1
        lower, upper = self.low, self.high

        def inside(q: np.ndarray) -> np.ndarray:
            return np.clip(q, lower, upper)

        sigma = 0.1
        tries = 0
        while time.perf_counter() < deadline:
            tries += 1
            if tries % 50 == 0:                 # split the costliest edge at its middle
                k = int(np.argmax(edges))
                middle = inside((path[k] + path[k + 1]) / 2)
                first = edge(path[k], middle, edges[k])
                second = edge(middle, path[k + 1], edges[k] - first)
                if first + second <= edges[k]:
                    path.insert(k + 1, middle)
                    edges[k:k + 1] = [first, second]
                continue
            if len(path) < 3:
                path.insert(1, inside((path[0] + path[1]) / 2))
                edges = [coster.cost(a, b) for a, b in pairwise(path)]
                continue
            k = int(rng.integers(1, len(path) - 1))
            moved = inside(path[k] + rng.normal(0.0, sigma, len(path[k])))
            before = edges[k - 1] + edges[k]
            first = edge(path[k - 1], moved, before)
            second = edge(moved, path[k + 1], before - first) if first < before else np.inf
            if first + second < before:
                path[k] = moved
                edges[k - 1], edges[k] = first, second
                sigma = min(0.5, sigma * 1.5)
            else:
                sigma = max(1e-3, sigma * 0.95)
        total = float(sum(edges))
        return Plan(np.array(path), total) if total < plan.cost else plan
