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

"""The RRT* tree: costs equal their edges' sums, no cycles, rewiring that acts."""

from itertools import pairwise

import numpy as np
from probdis_ros.model import arm_for_setting
from probdis_ros.model.edge_costs import ReferenceEdgeCoster
from probdis_ros.model.path_cost import path_cost
from probdis_ros.planning import FailureProbabilityObjective, ProbRRT, RRTSettings
from probdis_ros.planning.probes import ProbeRRT, ProbeSettings
from probdis_ros.planning.tree import Tree
import pytest
from test_planning import scattered_map


def check_tree(tree: Tree, reference: ReferenceEdgeCoster) -> None:
    """Assert the invariants, recomputing every edge with the reference coster."""
    size = tree.size
    assert tree.parent[0] == -1 and tree.cost[0] == 0.0
    for node in range(1, size):
        chain = tree.chain(node)
        assert len(chain) == len(set(chain)) <= size and chain[-1] == 0     # no cycle
        assert node in tree.children[tree.parent[node]]
        total = 0.0
        for child, parent in pairwise(chain):
            a, b = tree.nodes[parent], tree.nodes[child]
            if tree.reverse:            # goal tree: the arm moves child -> parent
                a, b = b, a
            total += reference.cost(a, b)
        assert tree.cost[node] == pytest.approx(total, rel=1e-9, abs=1e-12)
    assert sum(len(c) for c in tree.children[:size]) == size - 1


@pytest.mark.parametrize('setting', ['2d', '3d-orient'])
def test_costs_equal_their_edges_and_the_plan_its_path(setting):
    arm = arm_for_setting(setting)
    rng = np.random.default_rng(11)
    fmap = scattered_map(arm, rng, 12)
    start, goal = arm.random_configurations(rng, 2)
    planner = ProbRRT(arm, RRTSettings(iterations=40))
    objective = FailureProbabilityObjective()
    reference = objective.coster(arm, fmap, coster_type=ReferenceEdgeCoster)
    rewires = 0
    for seed in range(2):
        trees = planner.grow(start, goal, objective.coster(arm, fmap),
                             np.random.default_rng(seed))
        for tree in trees:
            check_tree(tree, reference)
            rewires += tree.rewires
        plan = planner.plan(start, goal, fmap, np.random.default_rng(seed))
        assert plan.cost == pytest.approx(path_cost(arm, fmap, plan.path), rel=1e-9)
    assert rewires > 0          # the neighbourhood holds neighbours: rewiring acts


def test_the_probes_costs_equal_their_edges_run_from_the_start():
    """Probe chains (ideas d, f) are costed as the arm runs them, root outward."""
    arm = arm_for_setting('3d-orient')
    rng = np.random.default_rng(13)
    fmap = scattered_map(arm, rng, 12)
    start = np.array([0.3, 0.6, -0.2, -1.4, 0.2, 0.9, 0.1])
    planner = ProbeRRT(arm, RRTSettings(iterations=10), probes=ProbeSettings(directions=6),
                       straight=True, turning=True)
    objective = FailureProbabilityObjective()
    tree, _ = planner.grow(start, -0.5 * start, objective.coster(arm, fmap),
                           np.random.default_rng(0))
    assert tree.size > 30
    check_tree(tree, objective.coster(arm, fmap, coster_type=ReferenceEdgeCoster))


def test_rewiring_finds_cheaper_paths_than_none():
    arm = arm_for_setting('3d-orient')
    rng = np.random.default_rng(12)
    fmap = scattered_map(arm, rng, 19)
    start, goal = arm.random_configurations(rng, 2)
    costs = {}
    for factor in (0.0, 1.0):
        planner = ProbRRT(arm, RRTSettings(rewire_factor=factor))
        plans = [planner.plan(start, goal, fmap, np.random.default_rng(s)) for s in range(6)]
        costs[factor] = np.median([p.cost for p in plans])
        assert (sum(p.rewires for p in plans) > 0) == (factor > 0)
    assert costs[1.0] < costs[0.0]


def test_reparent_moves_a_subtree_and_refuses_a_cycle():
    tree = Tree.rooted(np.zeros(2), np.zeros(2), 2, reverse=False)   # grows past capacity
    a = tree.append(np.ones(2), np.ones(2), 0, 1.0, 1.0)
    b = tree.append(np.ones(2), np.ones(2), a, 2.0, 3.0)
    c = tree.append(np.ones(2), np.ones(2), b, 0.5, 3.5)
    d = tree.append(np.ones(2), np.ones(2), 0, 0.25, 0.25)
    tree.reparent(b, d, 1.0)
    assert tree.children[a] == [] and tree.children[d] == [b]
    np.testing.assert_allclose(tree.cost, [0.0, 1.0, 1.25, 1.75, 0.25])
    assert tree.rewires == 1 and list(tree.leaves()) == [a, c]
    with pytest.raises(ValueError, match='cycle'):
        tree.reparent(d, c, 0.1)
