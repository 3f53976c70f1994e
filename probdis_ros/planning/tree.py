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
The search tree of ProbRRT: nodes, parents, edge costs, costs-to-come, children.

A start tree holds costs-to-come (its edges run parent -> child, the way the arm moves); a
goal tree (``reverse``) holds costs-to-go (edges child -> parent).  Every node keeps the
list of its children, so that re-parenting a node updates the costs of its subtree alone,
as OMPL's RRT* does (``updateChildCosts``), instead of rebuilding the parent relation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Tree:
    """Nodes of one tree, preallocated to ``capacity``; costs kept equal to their edges' sums."""

    nodes: np.ndarray
    positions: np.ndarray
    reverse: bool
    parent: list[int] = field(default_factory=list)
    edge: list[float] = field(default_factory=list)
    children: list[list[int]] = field(default_factory=list)
    costs: np.ndarray = field(default_factory=lambda: np.zeros(0))
    size: int = 0
    rewires: int = 0

    @classmethod
    def rooted(cls, root: np.ndarray, root_position: np.ndarray, capacity: int,
               reverse: bool) -> Tree:
        """Return a tree holding only its root, with room for capacity nodes."""
        nodes = np.empty((capacity, len(root)))
        positions = np.empty((capacity, len(root_position)))
        tree = cls(nodes, positions, reverse, costs=np.empty(capacity))
        tree.append(root, root_position, -1, 0.0, 0.0)
        return tree

    @property
    def cost(self) -> np.ndarray:
        """Cost-to-come (start tree) or cost-to-go (goal tree) of every node."""
        return self.costs[:self.size]

    @property
    def full(self) -> bool:
        """Tell whether no node can be added."""
        return self.size == len(self.nodes)

    def append(self, node: np.ndarray, position: np.ndarray, parent: int, edge: float,
               cost: float) -> int:
        """Add a leaf under parent (-1: the root) and return its index."""
        if self.full:
            self._grow()
        index = self.size
        self.nodes[index] = node
        self.positions[index] = position
        self.parent.append(parent)
        self.edge.append(edge)
        self.children.append([])
        if parent >= 0:
            self.children[parent].append(index)
        self.costs[index] = cost
        self.size += 1
        return index

    def _grow(self) -> None:
        capacity = max(2 * len(self.nodes), 1)
        self.nodes = np.resize(self.nodes, (capacity, self.nodes.shape[1]))
        self.positions = np.resize(self.positions, (capacity, self.positions.shape[1]))
        self.costs = np.resize(self.costs, capacity)

    def is_ancestor(self, ancestor: int, node: int) -> bool:
        """Tell whether ancestor lies on the way from node up to the root (node included)."""
        while node >= 0:
            if node == ancestor:
                return True
            node = self.parent[node]
        return False

    def reparent(self, index: int, parent: int, edge: float) -> None:
        """Move a node under a new parent and update the costs of its subtree only."""
        if self.is_ancestor(index, parent):
            raise ValueError(f'node {parent} lies in the subtree of {index}: a cycle')
        self.children[self.parent[index]].remove(index)
        self.children[parent].append(index)
        self.parent[index] = parent
        self.edge[index] = edge
        self.rewires += 1
        stack = [index]
        while stack:
            node = stack.pop()
            self.costs[node] = self.costs[self.parent[node]] + self.edge[node]
            stack.extend(self.children[node])

    def chain(self, index: int) -> list[int]:
        """Node indices from index up to the root."""
        out = [index]
        while self.parent[out[-1]] >= 0:
            out.append(self.parent[out[-1]])
        return out

    def leaves(self) -> np.ndarray:
        """Return the indices of the nodes without children."""
        return np.array([i for i in range(self.size) if not self.children[i]], dtype=int)
