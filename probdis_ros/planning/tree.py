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
goal tree (``reverse``) holds costs-to-go (edges child -> parent).  Every node keeps its
children (a linked list: ``first_child``, ``next_sibling``), so that re-parenting a node
updates the costs of its subtree alone, as OMPL's RRT* does (``updateChildCosts``),
instead of rebuilding the parent relation.  Everything is a preallocated array, so that
the compiled planner loop (:mod:`probdis_ros.model.tree_kernels`) works on the same tree
as these methods.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from probdis_ros.model.tree_kernels import is_ancestor, reparent


@dataclass
class Tree:
    """Nodes of one tree, preallocated to ``capacity``; costs kept equal to their edges' sums."""

    nodes: np.ndarray
    positions: np.ndarray
    reverse: bool
    parent: np.ndarray
    edge: np.ndarray
    costs: np.ndarray
    first_child: np.ndarray
    next_sibling: np.ndarray
    counts: np.ndarray              # [size, rewires], shared with the compiled loop

    @classmethod
    def rooted(cls, root: np.ndarray, root_position: np.ndarray, capacity: int,
               reverse: bool) -> Tree:
        """Return a tree holding only its root, with room for capacity nodes."""
        capacity = max(int(capacity), 1)
        tree = cls(np.empty((capacity, len(root))), np.empty((capacity, len(root_position))),
                   reverse, np.empty(capacity, dtype=np.int64), np.empty(capacity),
                   np.empty(capacity), np.empty(capacity, dtype=np.int64),
                   np.empty(capacity, dtype=np.int64), np.zeros(2, dtype=np.int64))
        tree.append(root, root_position, -1, 0.0, 0.0)
        return tree

    @property
    def size(self) -> int:
        """Return the number of nodes."""
        return int(self.counts[0])

    @property
    def rewires(self) -> int:
        """Return how many re-parentings (RRT* rewiring) the tree has seen."""
        return int(self.counts[1])

    @property
    def cost(self) -> np.ndarray:
        """Cost-to-come (start tree) or cost-to-go (goal tree) of every node."""
        return self.costs[:self.size]

    @property
    def children(self) -> list[list[int]]:
        """Return the children of every node, each list in index order."""
        out = [[] for _ in range(self.size)]
        for node in range(1, self.size):
            out[self.parent[node]].append(node)
        return out

    def reserve(self, extra: int) -> None:
        """Make room for ``extra`` more nodes (the compiled loop cannot grow the arrays)."""
        need = self.size + extra
        if need <= len(self.nodes):
            return
        capacity = max(need, 2 * len(self.nodes))
        for name in ('nodes', 'positions', 'parent', 'edge', 'costs', 'first_child',
                     'next_sibling'):
            old = getattr(self, name)
            new = np.empty((capacity, *old.shape[1:]), dtype=old.dtype)
            new[:len(old)] = old
            setattr(self, name, new)

    def append(self, node: np.ndarray, position: np.ndarray, parent: int, edge: float,
               cost: float) -> int:
        """Add a leaf under parent (-1: the root) and return its index."""
        self.reserve(1)
        index = self.size
        self.nodes[index] = node
        self.positions[index] = position
        self.parent[index] = parent
        self.edge[index] = edge
        self.costs[index] = cost
        self.first_child[index] = -1
        self.next_sibling[index] = -1
        if parent >= 0:
            self.next_sibling[index] = self.first_child[parent]
            self.first_child[parent] = index
        self.counts[0] += 1
        return index

    def is_ancestor(self, ancestor: int, node: int) -> bool:
        """Tell whether ancestor lies on the way from node up to the root (node included)."""
        return bool(is_ancestor(self.parent, ancestor, node))

    def reparent(self, index: int, parent: int, edge: float) -> None:
        """Move a node under a new parent and update the costs of its subtree only."""
        if self.is_ancestor(index, parent):
            raise ValueError(f'node {parent} lies in the subtree of {index}: a cycle')
        reparent(self.parent, self.edge, self.costs, self.first_child, self.next_sibling,
                 self.counts, index, parent, edge)

    def chain(self, index: int) -> list[int]:
        """Node indices from index up to the root."""
        out = [index]
        while self.parent[out[-1]] >= 0:
            out.append(int(self.parent[out[-1]]))
        return out

    def leaves(self) -> np.ndarray:
        """Return the indices of the nodes without children."""
        return np.flatnonzero(self.first_child[:self.size] < 0)
