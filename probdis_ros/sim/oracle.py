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
An RRT-Connect that sees the obstacles: it decides whether a world is solvable at all.

Random worlds are kept only if this planner finds a collision-free joint path from start to
goal, so that a success rate measures the disentangling method and not the dice.
"""

from __future__ import annotations

import numpy as np
from probdis_ros.sim.compliant_arm import CompliantArm


def _extend(arm: CompliantArm, nodes: list[np.ndarray], parents: list[int], target: np.ndarray,
            step: float) -> tuple[str, int]:
    """Step the tree toward target; return ('reached' | 'advanced' | 'trapped', node)."""
    tree = np.asarray(nodes)
    near = int(np.argmin(((tree - target) ** 2).sum(axis=1)))
    delta = target - tree[near]
    dist = float(np.linalg.norm(delta))
    new = target if dist <= step else tree[near] + delta * (step / dist)
    if not arm.path_is_free(np.array([tree[near], new])):
        return 'trapped', near
    nodes.append(new)
    parents.append(near)
    return ('reached' if dist <= step else 'advanced'), len(nodes) - 1


def _chain(nodes: list[np.ndarray], parents: list[int], index: int) -> list[np.ndarray]:
    out = []
    while index >= 0:
        out.append(nodes[index])
        index = parents[index]
    return out


def find_free_path(arm: CompliantArm, start: np.ndarray, goal: np.ndarray,
                   rng: np.random.Generator, iterations: int = 1500,
                   step: float = 0.3) -> np.ndarray | None:
    """Return a collision-free joint path from start to goal, or None within the budget."""
    if arm.path_is_free(np.array([start, goal])):
        return np.array([start, goal])
    trees = ([start.copy()], [-1]), ([goal.copy()], [-1])
    for i in range(iterations):
        grow, other = (trees[0], trees[1]) if i % 2 == 0 else (trees[1], trees[0])
        target = arm.arm.random_configurations(rng, 1)[0]
        status, new = _extend(arm, grow[0], grow[1], target, step)
        if status == 'trapped':
            continue
        while True:
            status, last = _extend(arm, other[0], other[1], grow[0][new], step)
            if status != 'advanced':
                break
        if status == 'reached':
            a = _chain(grow[0], grow[1], new)[::-1]
            b = _chain(other[0], other[1], last)
            path = np.array(a + b[1:])
            return path if i % 2 == 0 else path[::-1]
    return None
