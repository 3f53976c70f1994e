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

"""The entanglement families: seeded, solvable, entangled, and trapped the way they say."""

import json
import subprocess

from conftest import probdis_command
import numpy as np
from probdis_ros.experiments.sweep import EPISODES_FILE, read_episodes
from probdis_ros.sim.compliant_arm import densify
from probdis_ros.sim.families import (
    certify,
    FAMILIES,
    follow,
    random_family_world,
    ring_radius,
)
from probdis_ros.sim.worlds import world_from_dict
import pytest

SEEDS = (0, 1, 2)


@pytest.fixture(scope='module')
def worlds():
    return {(f, s): random_family_world(f, s) for f in FAMILIES for s in SEEDS}


def escapes(world, directions, length=0.9, quat=None):
    """Return which straight flange moves from the start point meet no obstacle."""
    x0 = world.arm.fk(world.start).positions[0]
    p0 = np.repeat(x0[None], len(directions), axis=0)
    p1 = p0 + length * directions
    free = np.ones(len(directions), dtype=bool)
    for obstacle in world.obstacles:
        hit = np.isfinite(obstacle.first_hit(p0, p1))
        if quat is not None:
            hit &= bool(obstacle.blocks_orientation(quat[None], world.orientation_tolerance)[0]
                        if obstacle.orientation is not None else True)
        free &= ~hit
    return free


def directions(n=20000, seed=0):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1)[:, None]


def box_exit(world, dirs):
    """Return the box-frame face (0-5) and base-frame point where rays leave the box."""
    p = world.params
    axes, center, half = np.array(p['axes']), np.array(p['center']), np.array(p['half_size'])
    x0 = world.arm.fk(world.start).positions[0]
    local0, local = axes @ (x0 - center), dirs @ axes.T
    with np.errstate(divide='ignore'):
        t = np.min(np.where(local != 0, (np.sign(local) * half - local0) / local, np.inf),
                   axis=1)
    where = local0 + t[:, None] * local
    k = np.argmax(np.abs(where) / half, axis=1)
    sign = where[np.arange(len(k)), k] < 0
    return 2 * k + sign, x0 + t[:, None] * dirs


def test_every_family_is_reproducible_from_its_seed_and_its_parameters_vary(worlds):
    for family in FAMILIES:
        again = random_family_world(family, SEEDS[0])
        first = worlds[(family, SEEDS[0])]
        assert json.dumps(again.to_dict()) == json.dumps(first.to_dict())
        # world_from_dict reads the saved world back (family and params are extra keys)
        back = world_from_dict(first.to_dict())
        assert np.array_equal(back.start, first.start) and \
            len(back.obstacles) == len(first.obstacles)
        params = [json.dumps(worlds[(family, s)].params, sort_keys=True) for s in SEEDS]
        assert len(set(params)) == len(SEEDS), family
        starts = [tuple(worlds[(family, s)].start) for s in SEEDS]
        assert len(set(starts)) == len(SEEDS)
        assert first.family == family and first.setting == '3d-orient'


def test_every_world_starts_free_is_entangled_and_has_a_way_out(worlds):
    for (family, seed), world in worlds.items():
        sim = world.compliant_arm()
        assert not sim.collides(world.start) and not sim.collides(world.goal)
        assert not sim.path_is_free(np.array([world.start, world.goal])), (family, seed)
        # the certificate again, with another stream: a way out the compliant arm follows
        assert certify(world, np.random.default_rng(7)), (family, seed)


def _pose(world):
    pose = world.arm.fk(world.start)
    return pose.positions[0], pose.orientations[0]


def _unit(v):
    return v / np.linalg.norm(v)


def _turned(world, q):
    """Return orientation q turned about x by a little more than the world's tolerance."""
    angle = np.pi * world.orientation_tolerance * 1.05
    w1, v1 = np.cos(angle / 2), np.array([np.sin(angle / 2), 0.0, 0.0])
    w0, v0 = q[0], q[1:]
    return np.r_[w0 * w1 - v0 @ v1, w0 * v1 + w1 * v0 + np.cross(v0, v1)]


def test_an_open_box_lets_the_flange_out_only_through_its_open_side(worlds):
    for seed in SEEDS:
        world = worlds[('open_box', seed)]
        dirs = directions()
        free = escapes(world, dirs)
        assert 0 < free.sum() < len(dirs)
        faces, _ = box_exit(world, dirs[free])
        names = {f'{"+-"[f % 2]}{"xyz"[f // 2]}' for f in faces}
        assert names == {world.params['open_side']}


def test_a_closed_box_holds_the_object_as_held_and_lets_it_out_turned(worlds):
    for seed in SEEDS:
        world = worlds[('closed_box', seed)]
        _, q_start = _pose(world)
        dirs = directions(5000)
        assert not escapes(world, dirs, quat=q_start).any()
        # turned by a little more than the tolerance (about the x axis): every way is open
        assert escapes(world, dirs, quat=_turned(world, q_start)).all()
        assert 0.25 <= world.orientation_tolerance <= 0.45


def test_a_plate_with_a_hole_lets_the_flange_out_only_through_the_hole(worlds):
    for seed in SEEDS:
        world = worlds[('plate_hole', seed)]
        dirs = directions(40000)
        free = escapes(world, dirs)
        assert free.sum() > 0
        faces, points = box_exit(world, dirs[free])
        hole, radius = np.array(world.params['hole_center']), world.params['hole_radius']
        assert {f'{"+-"[f % 2]}{"xyz"[f // 2]}' for f in faces} == \
            {world.params['plate_side']}
        # the ring's cusps reach a few per cent beyond the rim, never farther
        assert np.linalg.norm(points - hole, axis=1).max() < 1.1 * radius
        assert 0.03 <= radius <= 0.06


def test_the_ring_of_a_hole_covers_the_annulus_it_promises():
    radius = ring_radius(0.04, 0.13)
    d = 0.04 + radius
    angles = np.linspace(0, 2 * np.pi, 720)
    centres = d * np.column_stack([np.cos(2 * np.pi * np.arange(12) / 12),
                                   np.sin(2 * np.pi * np.arange(12) / 12)])
    for r in np.linspace(0.045, 0.13, 30):
        points = r * np.column_stack([np.cos(angles), np.sin(angles)])
        gaps = np.linalg.norm(points[:, None] - centres[None], axis=2).min(axis=1)
        assert (gaps <= radius + 1e-9).all(), r
    points = 0.0399 * np.column_stack([np.cos(angles), np.sin(angles)])
    assert (np.linalg.norm(points[:, None] - centres[None], axis=2) > radius).all()


def test_a_hook_under_a_bar_blocks_up_and_the_stem_side_but_not_the_free_side(worlds):
    for seed in SEEDS:
        world = worlds[('hook_bar', seed)]
        p = world.params
        free_side, up = np.array(p['free_side']), np.array([0.0, 0.0, 1.0])
        moves = np.array([up, -free_side, _unit(0.1 * free_side + up)])
        assert not escapes(world, moves, length=0.3).any()
        x0 = world.arm.fk(world.start).positions[0]
        aside = x0 + (p['hook_width'] + 0.01) * free_side
        for obstacle in world.obstacles:      # a side step, then up: free
            assert not np.isfinite(obstacle.first_hit(np.array([x0, aside]),
                                                      np.array([aside, aside + 0.3 * up]))).any()


def test_clutter_puts_an_item_on_the_straight_move_and_soft_ones_give_way_turned(worlds):
    soft = expected = 0.0
    for seed in SEEDS:
        world = worlds[('clutter', seed)]
        p = world.params
        assert 20 <= len(world.obstacles) == p['items'] <= 45
        x0, q_start = _pose(world)
        assert all(np.linalg.norm(o.center - x0) <= p['cluster_radius'] + 0.1
                   for o in world.obstacles)
        # the straight move to the goal, the object as held, meets an item
        trace = world.arm.fk(densify(np.array([world.start, world.goal]), 0.01)[0]).positions
        assert any(np.isfinite(o.first_hit(trace[:-1], trace[1:])).any()
                   for o in world.obstacles)
        gated = [o for o in world.obstacles if o.orientation is not None]
        for obstacle in gated:        # soft: blocks the object as held, not turned past
            assert obstacle.blocks_orientation(q_start[None], world.orientation_tolerance)[0]
            assert not obstacle.blocks_orientation(_turned(world, q_start)[None],
                                                   world.orientation_tolerance)[0]
        soft += len(gated)
        expected += p['soft_share'] * len(world.obstacles)
    assert soft > 0 and abs(soft - expected) <= 4 * np.sqrt(expected) + 1


def test_following_a_line_keeps_the_flange_on_it():
    world = random_family_world('open_box', 0)
    x0 = world.arm.fk(world.start).positions[0]
    target = x0 + np.array([0.0, 0.0, 0.05])
    path = follow(world.arm, world.start, [target])
    xs = world.arm.fk(path).positions
    assert np.linalg.norm(xs[-1] - target) < 0.005
    assert np.abs(xs[:, :2] - x0[:2]).max() < 0.005


def test_an_unknown_family_is_named():
    with pytest.raises(ValueError, match="unknown family 'cage'"):
        random_family_world('cage', 0)


def test_a_small_family_sweep_runs_through_the_cli_and_the_report_draws_it(tmp_path):
    out = tmp_path / 'families'
    command = [*probdis_command(), 'experiment', 'sweep', '--family', 'open_box,hook_bar',
               '--worlds', '2', '--methods', 'probabilistic,epsilon:0.2', '--seed', '1000',
               '--workers', '2', '--out', str(out)]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    records = read_episodes(out / EPISODES_FILE)
    assert sorted(r['id'] for r in records) == sorted(
        f'{f}/{w}/{m}' for f in ('open_box', 'hook_bar') for w in (0, 1)
        for m in ('probabilistic', 'epsilon:0.2'))
    assert {(r['family'], r['world'], r['world_seed']) for r in records} == {
        (f, w, 1000 + w) for f in ('open_box', 'hook_bar') for w in (0, 1)}
    again = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and '8 already done, 0 run' in again.stdout
    report = subprocess.run([*probdis_command(), 'experiment', 'report', str(out)],
                            capture_output=True, text=True, timeout=120)
    assert report.returncode == 0, report.stderr
    rows = [line for line in report.stdout.splitlines() if line.startswith('| open_box')
            or line.startswith('| hook_bar')]
    assert len(rows) == 4
    assert (out / 'families.png').stat().st_size > 0
    assert not (out / 'success.png').exists()
    summary = json.loads((out / 'summary.json').read_text())
    assert {(c['family'], c['method'], c['episodes']) for c in summary['cells']} == {
        (f, m, 2) for f in ('open_box', 'hook_bar') for m in ('probabilistic', 'epsilon:0.2')}
    bad = subprocess.run([*probdis_command(), 'experiment', 'sweep', '--family', 'cage',
                          '--out', str(tmp_path / 'x')], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "unknown family 'cage'" in bad.stderr
    both = subprocess.run([*probdis_command(), 'experiment', 'sweep', '--family', 'clutter',
                           '--setting', '2d', '--out', str(tmp_path / 'y')],
                          capture_output=True, text=True, timeout=60)
    assert both.returncode == 2 and 'no --setting' in both.stderr
