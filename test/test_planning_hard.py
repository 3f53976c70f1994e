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

"""The Hard baseline acts: it plans and moves after 1, 5 and 10 failures; it leaves regions."""

import numpy as np
from probdis_ros.model import arm_for_setting, FailureMap, TaskSpace
from probdis_ros.model.edge_costs import ReferenceEdgeCoster
from probdis_ros.planning import (
    Disentangler,
    EpsilonPlanner,
    HardThresholdObjective,
    Method,
    ProbRRT,
)
from probdis_ros.resources import scenario_path
from probdis_ros.sim.episode import drive, run_episode
from probdis_ros.sim.worlds import load_world, random_world
import pytest

PLANAR = arm_for_setting('2d')


def learned_map(world, failures: int):
    """Run Epsilon 0.5 in the world until it has learned this many failures (not escaped)."""
    for seed in range(50):
        loop = Disentangler(world.arm, EpsilonPlanner(world.arm, 0.5), world.goal,
                            FailureMap(world.arm.task_space), max_paths=500, seed=seed)
        current, _ = drive(loop, world.compliant_arm(), world.start,
                           until=lambda loop: len(loop.fmap) >= failures)
        if len(loop.fmap) == failures and loop.state.value == 'ready':
            return current, loop.fmap
    raise AssertionError(f'no run learned {failures} failures')


@pytest.mark.parametrize('failures', [1, 5, 10])
@pytest.mark.parametrize('world_name', ['demo_iiwa', '2d-10-seed3', '2d-30-seed4'])
def test_hard_plans_and_moves_after_failures(world_name, failures):
    if world_name == 'demo_iiwa':
        world = load_world(scenario_path('demo_iiwa'))
    else:
        _, n, seed = world_name.split('-')
        world = random_world('2d', int(n), int(seed[4:]))
    current, fmap = learned_map(world, failures)
    planner = Method.parse('hard:0.01').planner(world.arm)
    plans = [planner.plan(current, world.goal, fmap, np.random.default_rng(s))
             for s in range(3)]
    assert sum(p is not None for p in plans) >= 2          # plans, not empty plans
    plan = next(p for p in plans if p is not None)
    run = world.compliant_arm().execute(plan.path)
    assert np.linalg.norm(run.config - current) > 0.05    # and the arm moves


def test_a_hard_region_may_be_left_but_not_entered():
    fmap = FailureMap(TaskSpace.POINT2, 100.0)
    at = np.array([np.pi / 2, 0, 0, 0, 0, 0, 0])          # tip at (0, 0.7)
    fmap.add(PLANAR.fk(at).positions[0], [1.0, 0.0])      # blocked moving in +x
    behind = at + np.array([0.3, 0, 0, 0, 0, 0, 0])        # tip moves to -x: the way it came
    ahead = at - np.array([0.3, 0, 0, 0, 0, 0, 0])         # tip moves on in +x
    for coster_type in (None, ReferenceEdgeCoster):
        kwargs = {} if coster_type is None else {'coster_type': coster_type}
        hard = HardThresholdObjective(0.01, 1e4).coster(PLANAR, fmap, **kwargs)
        assert np.isfinite(hard.cost(at, behind))          # the start, p = 1, is left
        assert hard.cost(at, ahead) == np.inf               # deeper in: forbidden
        assert hard.cost(behind, at) == np.inf              # entering: forbidden
        costs = hard.costs(np.array([behind, ahead]), at, toward=False)
        assert np.isfinite(costs[0]) and costs[1] == np.inf
        index, _ = hard.cheapest(np.array([ahead, behind]), at, toward=False)
        assert index == 1
    plan = ProbRRT(PLANAR, objective=HardThresholdObjective(0.01, 1e4)).plan(
        at, behind + np.array([0.5, 0, 0, 0, 0, 0, 0]), fmap, np.random.default_rng(0))
    assert plan is not None


def test_hard_episodes_rarely_plan_nothing_in_2d():
    """The old Hard (its regions a metre long) planned nothing in 19 of 20 paths."""
    empty = paths = 0
    for seed in range(4):
        result = run_episode(random_world('2d', 10, seed), 'hard:0.01', seed=seed)
        empty += result.empty_plans
        paths += result.paths
        assert result.empty_plans == result.loop.empty_plans <= result.paths
    assert empty <= 0.2 * paths
