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
from probdis_ros.experiments.hole_search import best_search, hole_bound, PRIORS
from probdis_ros.experiments.sweep import EpisodeKey, EPISODES_FILE, run_episode_record
from probdis_ros.sim.families import HOLE_MARGIN, HOLE_SPREAD, random_family_world, SETTING
import pytest

SEEDS = (0, 1, 2)


@pytest.fixture(scope='module')
def worlds():
    return {seed: random_family_world('plate_hole', seed) for seed in SEEDS}


def lines_out(world, count=60000, length=0.9):
    """Return the share of straight flange moves from the start that meet no obstacle."""
    d = np.random.default_rng(7).normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    x0 = world.arm.fk(world.start).positions[0]
    p0 = np.repeat(x0[None], count, axis=0)
    free = np.ones(count, dtype=bool)
    for obstacle in world.obstacles:
        free &= ~np.isfinite(obstacle.first_hit(p0, p0 + length * d))
    return float(free.mean()), count


def test_the_share_of_lines_out_is_what_the_simulator_lets_out(worlds):
    for seed, world in worlds.items():
        bound = hole_bound(world, seed)
        share, count = lines_out(world)
        sigma = math.sqrt(share * (1 - share) / count)
        assert share > 0.005
        assert abs(bound.direction_share - share) < 4 * sigma + 0.002, (seed, share)


def test_the_opening_is_the_rim_and_the_cusps_of_the_ring(worlds):
    for seed, world in worlds.items():
        bound = hole_bound(world, seed)
        disc = math.pi * bound.hole_radius ** 2
        assert 1.0 < bound.opening_m2 / disc < 1.1


def test_the_generator_puts_every_hole_where_the_generator_bound_says(worlds):
    for seed, world in worlds.items():
        p = world.params
        axes, center = np.array(p['axes']), np.array(p['center'])
        half, radius = np.array(p['half_size']), p['hole_radius']
        k = 'xyz'.index(p['plate_side'][1])
        offset = axes @ (np.array(p['hole_center']) - center)
        for m in (m for m in range(3) if m != k):
            room = max(half[m] - radius - HOLE_MARGIN, 0.0)
            assert abs(offset[m]) <= HOLE_SPREAD * room + 1e-4
        bound = hole_bound(world, seed)
        box, generator = bound.curve('box', 20), bound.curve('generator', 20)
        assert all(g >= b - 1e-12 for g, b in zip(generator, box))


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
    assert '| bound: knows the box, not where on a side |' in other.stdout
    assert 'epsilon' not in other.stdout and 'no method of' in other.stderr
    bad = run_probdis('experiment', 'bound', '--episodes', str(tmp_path / 'none'), check=False)
    assert bad.returncode == 2 and 'no episodes.jsonl there' in bad.stderr
