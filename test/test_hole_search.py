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

"""The plate_hole bounds: true to the worlds' geometry, optimal searches, and the command."""

import itertools
import json
import math

from conftest import run_probdis
import numpy as np
from probdis_ros.experiments.hole_search import (
    best_search,
    centre_first_points,
    fit_box,
    hole_bound,
    learned_box_lines,
    MOST_POINTS,
    PRIORS,
    side_shares,
)
from probdis_ros.experiments.sweep import EpisodeKey, EPISODES_FILE, run_episode_record
from probdis_ros.sim.families import HOLE_MARGIN, HOLE_SPREAD, random_family_world, SETTING
import pytest

SEEDS = (0, 1, 2)


@pytest.fixture(scope='module')
def worlds():
    return {seed: random_family_world('plate_hole', seed) for seed in SEEDS}


def lines_out(world, hole, radius, count=1_000_000, length=0.9):
    """Return the share of straight flange moves from the start that meet no obstacle."""
    d = np.random.default_rng(7).normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    x0 = world.arm.fk(world.start).positions[0]
    toward = (hole - x0) / np.linalg.norm(hole - x0)
    # only lines near the hole can leave (the families' tests show none other does)
    d = d[d @ toward > math.cos(math.atan2(1.5 * radius, np.linalg.norm(hole - x0)))]
    p0 = np.repeat(x0[None], len(d), axis=0)
    free = np.ones(len(d), dtype=bool)
    for obstacle in world.obstacles:
        free &= ~np.isfinite(obstacle.first_hit(p0, p0 + length * d))
    return float(free.sum()) / count, count


def test_the_share_of_lines_out_is_what_the_simulator_lets_out(worlds):
    for seed, world in worlds.items():
        bound = hole_bound(world, seed)
        share, count = lines_out(world, np.array(world.params['hole_center']),
                                 bound.hole_radius)
        sigma = math.sqrt(share * (1 - share) / count)
        assert share > 0.005
        # within 4 sigma: about 3 % of the share, less than the ring's cusps add (4-5 %)
        assert abs(bound.direction_share - share) < 4 * sigma, (seed, share)


def test_the_opening_is_the_rim_and_the_cusps_of_the_ring(worlds):
    for seed, world in worlds.items():
        bound = hole_bound(world, seed)
        disc = math.pi * bound.hole_radius ** 2
        assert 1.0 < bound.opening_m2 / disc < 1.1


def test_the_generator_puts_every_hole_where_the_generator_bound_says(worlds):
    for world in worlds.values():
        p = world.params
        axes, center = np.array(p['axes']), np.array(p['center'])
        half, radius = np.array(p['half_size']), p['hole_radius']
        k = 'xyz'.index(p['plate_side'][1])
        offset = axes @ (np.array(p['hole_center']) - center)
        for m in (m for m in range(3) if m != k):
            room = max(half[m] - radius - HOLE_MARGIN, 0.0)
            assert abs(offset[m]) <= HOLE_SPREAD * room + 1e-4


@pytest.mark.parametrize('spread', [2.0, 2.0 * HOLE_SPREAD])
def test_a_sides_share_is_the_chance_that_its_middle_finds_a_hole_drawn_so(spread):
    half, radius = np.array([0.18, 0.16, 0.15]), 0.03
    opening = math.pi * radius ** 2
    shares = side_shares(half, radius, opening, spread)
    rng = np.random.default_rng(5)
    for side in (0, 2, 4):
        i, j = [m for m in range(3) if m != side // 2]
        room = half[[i, j]] - radius - HOLE_MARGIN
        centres = rng.uniform(-spread / 2, spread / 2, size=(400_000, 2)) * room
        found = np.mean(np.linalg.norm(centres, axis=1) < radius)
        assert shares[side] < 1 and shares[side] == shares[side + 1]
        assert found == pytest.approx(shares[side], rel=0.05)


@pytest.mark.parametrize('radius', [0.03, 0.06])
def test_the_centre_first_lattice_covers_every_place_a_hole_could_be(radius):
    half = np.array([0.18, 0.12, 0.08])
    points = centre_first_points(half, radius, most=1000)
    assert points[0][1:] == (0.0, 0.0)
    rng = np.random.default_rng(9)
    for side in range(6):
        i, j = [m for m in range(3) if m != side // 2]
        room = np.maximum(half[[i, j]] - radius - HOLE_MARGIN, 0.0)
        lattice = np.array([(a, b) for s, a, b in points if s == side])
        centres = rng.uniform(-1, 1, size=(5000, 2)) * room
        nearest = np.linalg.norm(centres[:, None] - lattice[None], axis=2).min(axis=1)
        assert nearest.max() < radius


def leaves(world, side, a, b):
    """Tell whether the straight flange move from the start through a side's point leaves."""
    p = world.params
    axes, center, half = np.array(p['axes']), np.array(p['center']), np.array(p['half_size'])
    x0 = world.arm.fk(world.start).positions[0]
    k = side // 2
    i, j = [m for m in range(3) if m != k]
    point = center + (1 - 2 * (side % 2)) * half[k] * axes[k] + a * axes[i] + b * axes[j]
    end = x0 + 1.5 * (point - x0)
    return not any(np.isfinite(o.first_hit(x0[None], end[None]))[0] for o in world.obstacles)


def test_the_centre_first_search_gets_out_where_the_simulator_lets_it(worlds):
    for seed, world in worlds.items():
        bound = hole_bound(world, seed)
        n = bound.centre_first_paths
        assert 1 <= n <= MOST_POINTS
        points = centre_first_points(np.array(world.params['half_size']), bound.hole_radius)
        assert leaves(world, *points[n - 1])
        assert not any(leaves(world, *q) for q in points[:n - 1])


def box_stops(rng, count):
    """Return a random box (rows of axes, centre, half-sizes), a start in it, stops on it."""
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    axes, half = q.T, rng.uniform(0.08, 0.18, size=3)
    center = rng.normal(size=3)
    start = center + (rng.uniform(-0.5, 0.5, size=3) * half) @ axes
    lines = rng.normal(size=(count, 3))
    lines = np.vstack([lines / np.linalg.norm(lines, axis=1)[:, None], axes, -axes])
    local_start, local = (start - center) @ axes.T, lines @ axes.T
    reach = np.where(local > 0, half - local_start, -half - local_start) / local
    return axes, center, half, start, start + reach.min(axis=1)[:, None] * lines


def test_a_box_is_fitted_from_stops_on_its_sides():
    rng = np.random.default_rng(4)
    for _ in range(5):
        axes, center, half, start, stops = box_stops(rng, 24)
        box = fit_box(stops, start)
        match = np.abs(box.axes @ axes.T)           # the same axes, in any order and sense
        order = match.argmax(axis=1)
        assert sorted(order) == [0, 1, 2] and match.max(axis=1) == pytest.approx(1, abs=1e-9)
        assert box.center == pytest.approx(center, abs=1e-9)
        assert box.half == pytest.approx(half[order], abs=1e-9)
    with pytest.raises(ValueError, match='no box fits'):
        fit_box(np.zeros((2, 3)), np.ones(3))


def line_is_free(world, x0, direction, length=1.0):
    """Tell whether the straight flange move of length from x0 along direction meets nothing."""
    end = (x0 + length * direction)[None]
    return not any(np.isfinite(o.first_hit(x0[None], end))[0] for o in world.obstacles)


def test_the_learned_box_search_sees_only_its_stops_and_gets_out_where_the_simulator_lets_it(
        worlds):
    for seed, world in worlds.items():
        bound = hole_bound(world, seed)
        lines, box = learned_box_lines(world, bound.hole_radius, seed)
        assert bound.learned_box_paths in (0, len(lines)) and len(lines) <= MOST_POINTS
        x0 = world.arm.fk(world.start).positions[0]
        assert [line_is_free(world, x0, u) for u in lines[:-1]] == [False] * (len(lines) - 1)
        assert line_is_free(world, x0, lines[-1]) == (bound.learned_box_paths > 0)
        again, _ = learned_box_lines(world, bound.hole_radius, seed)
        assert np.array_equal(np.array(again), np.array(lines))      # the seed's stream
        if box is not None:                                  # the box it learnt holds the start
            local = (x0 - box.center) @ box.axes.T
            assert np.all(np.abs(local) < box.half)


def test_the_learned_box_search_can_learn_a_box_from_its_stops_alone():
    # seed 3: its lines meet the sides as they were laid out to, and the box comes out right
    # (within the world's parameters' rounding); it does not always (seeds 0 and 4: a side
    # 1.4-4.5 cm off; RESULTS.md counts how often)
    world = random_family_world('plate_hole', 3)
    p = world.params
    _, box = learned_box_lines(world, p['hole_radius'], 3)
    match = np.abs(box.axes @ np.array(p['axes']).T)
    order = match.argmax(axis=1)
    assert sorted(order) == [0, 1, 2] and match.max(axis=1).min() > math.cos(math.radians(1))
    assert np.linalg.norm(box.center - np.array(p['center'])) < 0.002
    assert np.abs(box.half - np.array(p['half_size'])[order]).max() < 0.002


def brute_force(shares, paths):
    """Return the best chance over every way of spreading ``paths`` points over the sides."""
    best = 0.0
    for sides in itertools.combinations_with_replacement(range(len(shares)), paths):
        counts = np.bincount(sides, minlength=len(shares))
        best = max(best, sum(min(1.0, k * s) for k, s in zip(counts, shares)) / len(shares))
    return best


def test_the_best_search_is_the_best_spread_of_its_points():
    assert best_search([1.0] * 6, 8) == pytest.approx([1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6, 1, 1, 1])
    assert best_search([0.5] * 6, 12)[-1] == pytest.approx(1.0)
    assert best_search([0.5] * 6, 12)[5] == pytest.approx(0.5)
    rng = np.random.default_rng(3)
    for _ in range(20):
        shares = list(rng.uniform(0.05, 1.0, size=6))
        curve = best_search(shares, 5)
        for n in range(1, 6):
            assert curve[n - 1] == pytest.approx(brute_force(shares, n))


def test_the_command_bounds_the_worlds_and_sets_the_methods_beside(tmp_path):
    sweep = tmp_path / 'sweep'
    sweep.mkdir()
    records = [run_episode_record(EpisodeKey(SETTING, 0, w, 'epsilon:0.2', 1000, 'plate_hole'),
                                  20) for w in range(2)]
    (sweep / EPISODES_FILE).write_text(''.join(json.dumps(r) + '\n' for r in records))
    out = tmp_path / 'bound'
    run = run_probdis('experiment', 'bound', '--worlds', '2', '--seed', '1000', '--episodes',
                      str(sweep), '--out', str(out), '--json')
    doc = json.loads(run.stdout)
    assert doc['seeds'] == [1000, 1001] and set(doc['bounds']) == set(PRIORS)
    curve = doc['methods']['epsilon:0.2']['within']
    for n in (1, 5, 20):
        assert curve[n - 1] == np.mean([r['success'] and r['paths'] <= n for r in records])
    per_world = [json.loads(line) for line in (out / 'hole_bound.jsonl').read_text().splitlines()]
    assert [w['seed'] for w in per_world] == [1000, 1001]
    assert (out / 'hole_bound.png').stat().st_size > 0
    for prior in PRIORS:
        within = doc['bounds'][prior]['within']
        assert all(a <= b + 1e-12 for a, b in itertools.pairwise(within)) and within[-1] <= 1
    other = run_probdis('experiment', 'bound', '--worlds', '2', '--seed', '1001',
                        '--episodes', str(sweep))
    assert '| bound if holes lay anywhere on a side (knows the box) |' in other.stdout
    assert 'epsilon' not in other.stdout and 'no method of' in other.stderr
    assert 'episodes on 1 of the 2 worlds: left out' in other.stderr
    twice = tmp_path / 'twice'
    twice.mkdir()
    (twice / EPISODES_FILE).write_text(json.dumps(records[0]) + '\n')
    both = run_probdis('experiment', 'bound', '--worlds', '2', '--seed', '1000', '--episodes',
                       str(sweep), '--episodes', str(twice), check=False)
    assert both.returncode == 2 and 'on plate_hole world 1000 twice' in both.stderr
    bad = run_probdis('experiment', 'bound', '--episodes', str(tmp_path / 'none'), check=False)
    assert bad.returncode == 2 and 'no episodes.jsonl there' in bad.stderr
