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
The Cartesian speed limit: every point of the arm, as the motion JTC runs moves it.

The checks move points of the arm's surface (its collision shapes' axis ends pushed out by
their radius in many directions, the object's ball, the flange) through the commanded
motion sampled every millisecond or two with JTC's interpolation, and difference their
positions in time: independent of the bound the limit computes.
"""

from __future__ import annotations

import numpy as np
from probdis_ros.model import iiwa_arm, PlanarArm
from probdis_ros.model.table import ROBOT_TABLE
from probdis_ros.motion.cartesian_speed import (
    CartesianSpeedLimit,
    edge_ratios,
    EDGE_SPACING,
    point_speeds,
    SAMPLING_MARGIN,
)
from probdis_ros.motion.profiles import MotionLimits, time_parameterize
from probdis_ros.run import RunSettings
import pytest

ARM = iiwa_arm().on_table(ROBOT_TABLE, 0.25)      # the object's ball reaches 0.25 m
MIDDLE = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])


def surface_points(rng: np.random.Generator, per_shape: int = 40
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Return (link index, local position) of points on the shapes' surfaces and the tip."""
    links, local = [ARM.n_joints - 1], [ARM.kernel_params()[4]]
    for joint, cx, cy, cz, ax, ay, az, half, radius in ARM.shapes:
        along = rng.uniform(-1.0, 1.0, per_shape)[:, None] * half * np.array([ax, ay, az])
        out = rng.normal(size=(per_shape, 3))
        out *= radius / np.linalg.norm(out, axis=1, keepdims=True)
        links += [int(joint) - 1] * per_shape
        local += list(np.array([cx, cy, cz]) + along + out)
    return np.array(links), np.array(local)


def fastest_point(configs: np.ndarray, dt: float, points) -> np.ndarray:
    """Return per step the fastest of the points, by differencing their positions in time."""
    links, local = points
    positions, rotations = ARM.joint_frames(configs)
    world = positions[:, links] + np.einsum('nkab,kb->nka', rotations[:, links], local)
    return np.linalg.norm(np.diff(world, axis=0), axis=2).max(axis=1) / dt


def random_path(rng: np.random.Generator) -> np.ndarray:
    a = np.clip(MIDDLE + rng.uniform(-1, 1, 7), ARM.lower + 0.1, ARM.upper - 0.1)
    b = np.clip(a + rng.uniform(-0.8, 0.8, 7), ARM.lower + 0.1, ARM.upper - 0.1)
    return np.array([a, b, MIDDLE])


def sampled(motion, dt: float = 1e-3) -> np.ndarray:
    """Return the motion's positions every dt, as JTC's interpolation runs it."""
    return np.array([motion.sample(t)[0] for t in np.arange(0.0, motion.duration, dt)])


def test_the_bound_holds_every_surface_point_and_is_reached_by_some():
    rng = np.random.default_rng(3)
    points = surface_points(rng)
    # the points' frames are the kinematics' own: the tip where tip_frames puts it
    q = np.clip(MIDDLE + rng.uniform(-1.5, 1.5, (5, 7)), ARM.lower, ARM.upper)
    positions, rotations = ARM.joint_frames(q)
    tips = positions[:, -1] + rotations[:, -1] @ points[1][0]
    np.testing.assert_allclose(tips, ARM.tip_frames(q)[0], atol=1e-12)
    for _ in range(20):
        q = np.clip(MIDDLE + rng.uniform(-1.5, 1.5, 7), ARM.lower, ARM.upper)
        qdot = rng.uniform(-1.0, 1.0, 7)
        dt = 1e-7
        moved = fastest_point(np.array([q - dt / 2 * qdot, q + dt / 2 * qdot]), dt, points)[0]
        bound = point_speeds(ARM, q[None], qdot[None])[0]
        assert moved <= bound * (1 + 1e-5)
        # and no looser than it must be: some point of a ball moves at least
        # sqrt(|v|^2 + (r |w|)^2) >= (|v| + r |w|) / sqrt(2)
        assert moved >= 0.7 * bound
    assert point_speeds(ARM, MIDDLE[None], np.zeros((1, 7)))[0] == 0.0


def test_sampling_the_edges_misses_no_faster_stretch():
    rng = np.random.default_rng(4)
    for _ in range(10):
        path = random_path(rng)
        dense = edge_ratios(ARM, path, spacing=EDGE_SPACING / 10) / (1 + SAMPLING_MARGIN)
        assert np.all(dense <= edge_ratios(ARM, path))
    # and short edges (under EDGE_SPACING): sampled at their start alone, one came out 3 %
    # slow
    for _ in range(100):
        start = 0.8 * rng.uniform(ARM.lower, ARM.upper)
        step = rng.normal(size=7)
        step *= rng.uniform(0.01, 0.05) / np.abs(step).max()
        path = np.array([start, start + step])
        dense = edge_ratios(ARM, path, spacing=0.0005) / (1 + SAMPLING_MARGIN)
        assert np.all(dense <= edge_ratios(ARM, path))


def test_a_capped_motion_moves_no_point_of_the_arm_faster_than_the_cap():
    rng = np.random.default_rng(5)
    points = surface_points(rng, per_shape=10)
    speed = 0.15
    capped = MotionLimits(cartesian=CartesianSpeedLimit(ARM, speed))
    fastest_free = []
    for _ in range(4):
        path = random_path(rng)
        free = sampled(time_parameterize(path), 2e-3)
        fastest_free.append(fastest_point(free, 2e-3, points).max())
        motion = time_parameterize(path, capped)
        assert fastest_point(sampled(motion, 2e-3), 2e-3, points).max() <= speed * 1.001
        # the commanded samples' own velocities too
        assert point_speeds(ARM, motion.positions, motion.velocities).max() <= speed
    assert max(fastest_free) > 1.5 * speed      # so the cap had something to do


def test_the_cap_leaves_edges_that_keep_it_alone_and_slows_the_others():
    rng = np.random.default_rng(6)
    path = random_path(rng)
    free = time_parameterize(path)
    # a cap above what the free motion reaches changes nothing, bit for bit
    loose = time_parameterize(path, MotionLimits(cartesian=CartesianSpeedLimit(
        ARM, 2.0 * point_speeds(ARM, free.positions, free.velocities).max() + 1.0)))
    np.testing.assert_array_equal(loose.positions, free.positions)
    tight = time_parameterize(path, MotionLimits(cartesian=CartesianSpeedLimit(
        ARM, 0.05)))
    assert tight.duration > free.duration


def test_bad_limits_are_refused():
    with pytest.raises(ValueError, match='must be positive'):
        CartesianSpeedLimit(ARM, 0.0)
    with pytest.raises(ValueError, match='serial chain'):
        CartesianSpeedLimit(PlanarArm(), 0.2)
    for bad in (-0.1, np.inf, np.nan):
        with pytest.raises(ValueError, match='cartesian_speed_limit'):
            RunSettings(cartesian_speed_limit=bad)
    assert RunSettings().limits(ARM).cartesian is None
    assert RunSettings(cartesian_speed_limit=0.2).limits(ARM).cartesian.speed == 0.2
