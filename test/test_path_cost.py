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

"""Path cost: additive, length alone on an empty map, ~zero success through a failure."""

import math

import numpy as np
from probdis_ros.model import arm_for_setting, FailureMap, TaskSpace
from probdis_ros.model.path_cost import (
    edge_cost,
    edge_points,
    EdgeTerms,
    path_cost,
    path_length,
    path_success_probability,
)
import pytest

DELTA = 0.04
LAMBDA = 0.01


@pytest.fixture(scope='module')
def iiwa():
    return arm_for_setting('3d-orient')


@pytest.fixture(scope='module')
def busy_map(iiwa):
    """19 failures near configurations on the test edges."""
    rng = np.random.default_rng(0)
    fmap = FailureMap(TaskSpace.POSE3, 100.0)
    poses = iiwa.fk(rng.uniform(-1, 1, (19, 7)))
    for x, q in zip(poses.positions, poses.orientations):
        fmap.add(x, rng.normal(size=3), q)
    return fmap


def test_edge_points_are_equal_steps_no_longer_than_delta():
    a, b = np.zeros(7), np.full(7, 0.1)
    points, step = edge_points(a, b, DELTA)
    assert step <= DELTA and len(points) == int(np.ceil(np.linalg.norm(b - a) / DELTA))
    np.testing.assert_allclose(points[-1], b)
    np.testing.assert_allclose(np.diff(np.vstack([a, points]), axis=0).__abs__().sum(axis=1),
                               np.full(len(points), np.abs(b - a).sum() / len(points)))
    assert len(edge_points(a, a, DELTA)[0]) == 0


def test_empty_map_cost_is_lambda_times_length(iiwa):
    empty = FailureMap(TaskSpace.POSE3)
    path = np.random.default_rng(1).uniform(-1, 1, (5, 7))
    assert path_cost(iiwa, empty, path, DELTA, LAMBDA) == pytest.approx(LAMBDA * path_length(path))
    assert path_success_probability(iiwa, empty, path, DELTA) == 1.0


def test_cost_is_additive_over_split_edges(iiwa, busy_map):
    rng = np.random.default_rng(2)
    for _ in range(10):
        a, b = rng.uniform(-1, 1, (2, 7))
        # steps land on the same points when the halves keep the step count even
        n = int(np.ceil(np.linalg.norm(b - a) / DELTA))
        b = a + (b - a) * (2 * (n // 2) * DELTA * 0.999) / np.linalg.norm(b - a)
        mid = (a + b) / 2
        whole = edge_cost(iiwa, busy_map, a, b, DELTA, LAMBDA)
        split = edge_cost(iiwa, busy_map, a, mid, DELTA, LAMBDA) + \
            edge_cost(iiwa, busy_map, mid, b, DELTA, LAMBDA)
        assert whole > LAMBDA * np.linalg.norm(b - a)
        assert split == pytest.approx(whole, rel=1e-12)
        assert path_cost(iiwa, busy_map, np.array([a, mid, b]), DELTA, LAMBDA) == \
            pytest.approx(whole, rel=1e-12)


def test_extra_via_points_on_an_edge_change_the_cost_only_by_discretisation(iiwa, busy_map):
    rng = np.random.default_rng(3)
    a, b = rng.uniform(-1, 1, (2, 7))
    whole = edge_cost(iiwa, busy_map, a, b, DELTA, LAMBDA)
    path = a + np.array([0.0, 0.13, 0.37, 0.8, 1.0])[:, None] * (b - a)
    assert path_cost(iiwa, busy_map, path, DELTA, LAMBDA) == pytest.approx(whole, rel=0.05)


def test_path_through_a_failure_point_has_near_zero_success(iiwa):
    rng = np.random.default_rng(5)
    a, b = rng.uniform(-1, 1, (2, 7))
    through = a + 0.5 * (b - a)
    pose = iiwa.fk(through)
    fmap = FailureMap(TaskSpace.POSE3, 100.0)
    fmap.add(pose.positions[0], rng.normal(size=3), pose.orientations[0])
    path = np.array([a, through, b])
    assert path_success_probability(iiwa, fmap, path, DELTA) < 1e-6
    away = path + np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    away[:, 0] += 2.0
    assert path_success_probability(iiwa, fmap, away, DELTA) > \
        path_success_probability(iiwa, fmap, path, DELTA)


def test_a_capped_edge_may_leave_a_region_above_the_cap_but_never_go_deeper():
    # Hard: an edge that starts above the cap (the arm where it was blocked) may go on
    # while the probability falls, through points still above the cap; any rise is refused
    terms = EdgeTerms(cap=0.1)
    assert terms.allows([0.8, 0.6, 0.3, 0.05], start=0.9)
    assert not terms.allows([0.8, 0.85], start=0.9)
    assert not terms.allows([0.05, 0.2])                  # entering from below the cap
    assert terms.allows([0.1, 0.1])                       # at the cap is within it


def test_the_compiled_arccos_is_within_one_ulp_of_libm():
    """The edge kernels' inlined arccos must not change any probability beyond rounding."""
    import numba
    from probdis_ros.model.fast_math import arccos

    many = numba.njit(lambda x: np.array([arccos(v) for v in x]))
    x = np.concatenate([np.linspace(-1.0, 1.0, 400_001), [-1.0, -0.5, -0.0, 0.0, 0.5, 1.0],
                        np.random.default_rng(0).uniform(-1.0, 1.0, 200_000)])
    exact = np.array([math.acos(v) for v in x])     # libm's (numpy's own differs by version)
    ulps = np.abs(many(x) - exact) / np.spacing(np.maximum(exact, np.finfo(float).tiny))
    assert ulps.max() <= 1.0
    assert many(np.array([1.0]))[0] == 0.0 and many(np.array([-1.0]))[0] == np.pi
