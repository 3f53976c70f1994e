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
A planner that sees the scene: it decides whether a physical scene is solvable at all.

RRT-Connect in joint space; a configuration is free if the arm and the grasped object do
not penetrate the scene with its clutter at rest (:meth:`PhysicsIiwa.in_collision`), and a
straight joint-space segment is free if its configurations are at most ``resolution`` rad
apart on every joint.  A scene is kept only if this finds a way out, so that a run that
fails measures the disentangling method and not an impossible scene.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import itertools
import time

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.physics.arm import PhysicsIiwa
from probdis_ros.physics.scene import Scene
from probdis_ros.planning.prob_rrt import ROBOT_JOINT_MARGIN
from probdis_ros.run import goal_problem

DEFAULT_RESOLUTION = 0.02   # rad, per joint, between checked configurations
#: RRT-Connect iterations per attempt of :func:`check_scene`: a 5 mm ball threading the
#: families' clutter needed more than the 3,000 that plan the shipped scenes (clutter-seed16)
CHECK_ITERATIONS = 10_000
#: [rad] per joint between the configurations :func:`check_scene` checks: the tip then moves
#: at most about 1.6 cm between two (0.004 rad times the sum of the joints' reach to it),
#: less than the 2 cm in which the families' 5 mm ball meets a 1 cm plate; at
#: DEFAULT_RESOLUTION a way out could pass through a plate between two checks
CHECK_RESOLUTION = 0.004


def segment_configurations(a: np.ndarray, b: np.ndarray,
                           resolution: float = DEFAULT_RESOLUTION) -> np.ndarray:
    """Return configurations from a to b (both included) at most resolution apart per joint."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n = max(1, int(np.ceil(np.abs(b - a).max() / resolution)))
    return a + (b - a) * np.linspace(0.0, 1.0, n + 1)[:, None]


def first_collision(arm: PhysicsIiwa, path: np.ndarray,
                    resolution: float = DEFAULT_RESOLUTION,
                    clearance: float = 0.0) -> np.ndarray | None:
    """Return the first configuration along a joint path that collides, or None if free."""
    path = np.atleast_2d(np.asarray(path, dtype=float))
    if arm.in_collision(path[0], clearance):
        return path[0]
    for a, b in itertools.pairwise(path):
        for q in segment_configurations(a, b, resolution)[1:]:
            if arm.in_collision(q, clearance):
                return q
    return None


def path_is_free(arm: PhysicsIiwa, path: np.ndarray, resolution: float = DEFAULT_RESOLUTION,
                 clearance: float = 0.0) -> bool:
    """Tell whether a joint path (its straight segments) is collision-free."""
    return first_collision(arm, path, resolution, clearance) is None


class _Tree:
    def __init__(self, root: np.ndarray) -> None:
        self.nodes = [root.copy()]
        self.parents = [-1]

    def nearest(self, q: np.ndarray) -> int:
        return int(np.argmin(((np.asarray(self.nodes) - q) ** 2).sum(axis=1)))

    def add(self, q: np.ndarray, parent: int) -> int:
        self.nodes.append(q)
        self.parents.append(parent)
        return len(self.nodes) - 1

    def chain(self, index: int) -> list[np.ndarray]:
        out = []
        while index >= 0:
            out.append(self.nodes[index])
            index = self.parents[index]
        return out


def find_free_path(arm: PhysicsIiwa, start: np.ndarray, goal: np.ndarray,
                   rng: np.random.Generator, iterations: int = 3000, step: float = 0.3,
                   resolution: float = DEFAULT_RESOLUTION, clearance: float = 0.0,
                   limit_margin: float = 0.05, local_share: float = 0.7,
                   local_spread: float = 0.2, attempts: int = 3) -> np.ndarray | None:
    """
    Return a collision-free joint path from start to goal, or None within the budget.

    Samples stay ``limit_margin`` rad inside the joint limits.  A share ``local_share`` of
    them is drawn around a random node of the growing tree (normal, ``local_spread`` rad per
    joint): uniform samples alone rarely thread the narrow passages of an entanglement (a
    slot, a hole) in 7 dimensions.  Up to ``attempts`` fresh pairs of trees of
    ``iterations`` each (a tree stuck in a pocket is cheaper to drop than to grow).  Seeded by
    ``rng``, so the same call gives the same path.
    """
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    if arm.in_collision(start, clearance) or arm.in_collision(goal, clearance):
        return None
    if path_is_free(arm, np.array([start, goal]), resolution, clearance):
        return np.array([start, goal])
    lower, upper = arm.lower + limit_margin, arm.upper - limit_margin

    def extend(tree: _Tree, target: np.ndarray) -> tuple[str, int]:
        near = tree.nearest(target)
        delta = target - tree.nodes[near]
        dist = float(np.linalg.norm(delta))
        new = target if dist <= step else tree.nodes[near] + delta * (step / dist)
        if not path_is_free(arm, np.array([tree.nodes[near], new]), resolution, clearance):
            return 'trapped', near
        return ('reached' if dist <= step else 'advanced'), tree.add(new, near)

    for _ in range(attempts):
        path = _connect(start, goal, rng, iterations, lower, upper, local_share,
                        local_spread, extend)
        if path is not None:
            return shortcut(arm, path, rng, resolution, clearance)
    return None


def _connect(start: np.ndarray, goal: np.ndarray, rng: np.random.Generator, iterations: int,
             lower: np.ndarray, upper: np.ndarray, local_share: float, local_spread: float,
             extend: Callable[[_Tree, np.ndarray], tuple[str, int]]) -> np.ndarray | None:
    """One RRT-Connect run: two trees from start and goal until they meet."""
    trees = (_Tree(start), _Tree(goal))
    for i in range(iterations):
        grow, other = (trees[0], trees[1]) if i % 2 == 0 else (trees[1], trees[0])
        if rng.random() < local_share:
            base = grow.nodes[int(rng.integers(len(grow.nodes)))]
            target = np.clip(base + rng.normal(0.0, local_spread, base.shape), lower, upper)
        else:
            target = rng.uniform(lower, upper)
        status, new = extend(grow, target)
        if status == 'trapped':
            continue
        while True:
            status, last = extend(other, grow.nodes[new])
            if status != 'advanced':
                break
        if status == 'reached':
            path = np.array(grow.chain(new)[::-1] + other.chain(last)[1:])
            return path if i % 2 == 0 else path[::-1]
    return None


def shortcut(arm: PhysicsIiwa, path: np.ndarray, rng: np.random.Generator,
             resolution: float = DEFAULT_RESOLUTION, clearance: float = 0.0,
             tries: int = 50) -> np.ndarray:
    """Shorten a free path by replacing stretches with free straight segments."""
    path = list(np.asarray(path, dtype=float))
    for _ in range(tries):
        if len(path) <= 2:
            break
        i, j = sorted(rng.choice(len(path), size=2, replace=False))
        if j - i > 1 and path_is_free(arm, np.array([path[i], path[j]]), resolution,
                                      clearance):
            path = path[:i + 1] + path[j:]
    return np.array(path)


@dataclass(frozen=True)
class SceneCheck:
    """
    Whether a scene measures a disentangling method: entangled at the start, and solvable.

    ``blocked_after_m`` is how far the tip moves on the straight joint-space move to the
    goal before the arm or object first touches the scene (None: that move is free);
    ``way_out`` the free path found (None: none within the budget, which says the scene
    may be unsolvable, not that it is).
    """

    name: str
    start_free: bool
    goal_free: bool
    blocked_after_m: float | None
    way_out: np.ndarray | None
    seconds: float
    goal_room: str = ''         # why the planner node would refuse the goal ('' : it takes it)

    @property
    def problems(self) -> list[str]:
        """Return what makes the scene unfit, one phrase each (empty: fit)."""
        found = [f'the goal {self.goal_room}'] if self.goal_room else []
        if not self.start_free:
            found.append('the start collides')
        if not self.goal_free:
            found.append('the goal collides')
        if self.start_free and self.goal_free and self.blocked_after_m is None:
            found.append('the straight move to the goal is free: nothing to disentangle')
        if self.start_free and self.goal_free and self.way_out is None:
            found.append('no way out found (the scene may be unsolvable, or need a larger '
                         '--iterations)')
        return found

    @property
    def ok(self) -> bool:
        """Tell whether the scene is entangled and a way out was found."""
        return not self.problems


def check_scene(scene: Scene, rng: np.random.Generator, iterations: int = CHECK_ITERATIONS,
                clearance: float = 0.0, resolution: float = CHECK_RESOLUTION) -> SceneCheck:
    """
    Check a scene as the tests check the shipped ones (``probdis scene check``).

    Start and goal free, the straight move blocked, and a way out found by the planner that
    sees the scene (with ``clearance`` [m] to spare along it); and a goal the planner node
    takes (``joint_margin`` from every joint limit).
    """
    t0 = time.perf_counter()
    arm = PhysicsIiwa(scene)
    start_free = not arm.in_collision(scene.start)
    goal_free = not arm.in_collision(scene.goal)
    hit = first_collision(arm, np.array([scene.start, scene.goal]), resolution)
    blocked = None
    if hit is not None:
        tips = iiwa_arm().positions(np.array([scene.start, hit]))
        blocked = float(np.linalg.norm(tips[1] - tips[0]))
    way = None
    if start_free and goal_free:
        way = find_free_path(arm, scene.start, scene.goal, rng, iterations,
                             resolution=resolution, clearance=clearance)
    room = goal_problem(iiwa_arm(), scene.goal, ROBOT_JOINT_MARGIN)
    return SceneCheck(scene.name, start_free, goal_free, blocked, way,
                      time.perf_counter() - t0, room)
