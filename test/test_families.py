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

import copy
from dataclasses import replace
import json
import subprocess

from conftest import probdis_command
import numpy as np
from probdis_ros.experiments.sweep import EPISODES_FILE, read_episodes
from probdis_ros.planning.seeds import stream, WORLD
from probdis_ros.sim.compliant_arm import densify
from probdis_ros.sim.families import (
    _draw_configuration,
    BUILDERS,
    certify,
    FAMILIES,
    follow,
    HOLE_MARGIN,
    HOLE_SPREAD,
    in_workspace,
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


def face_names(faces):
    return {f'{"+-"[f % 2]}{"xyz"[f // 2]}' for f in faces}


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


def test_a_plate_is_covered_everywhere_but_at_its_hole(worlds):
    # a point of the plate outside the hole lies in one of its discs (to the 4 decimals of
    # the params): no gap between the ring and the tiles around it
    for seed in SEEDS:
        world = worlds[('plate_hole', seed)]
        p = world.params
        axes, center, half = (np.array(p[k]) for k in ('axes', 'center', 'half_size'))
        k, sign = 'xyz'.index(p['plate_side'][1]), p['plate_side'][0] == '-'
        i, j = [m for m in range(3) if m != k]
        plate = center + (-1 if sign else 1) * half[k] * axes[k]
        discs = [o for o in world.obstacles
                 if abs(axes[k] @ (o.center - plate)) < 1e-3 and abs(o.normal @ axes[k]) > 0.99]
        u, v = np.meshgrid(np.linspace(-1, 1, 121) * half[i], np.linspace(-1, 1, 121) * half[j])
        points = plate + u.reshape(-1, 1) * axes[i] + v.reshape(-1, 1) * axes[j]
        hole = np.array(p['hole_center'])
        points = points[np.linalg.norm(points - hole, axis=1) > 1.1 * p['hole_radius']]
        covered = np.zeros(len(points), dtype=bool)
        for disc in discs:
            covered |= np.linalg.norm(points - disc.center, axis=1) <= disc.radius + 1e-4
        assert covered.all(), (seed, points[~covered][:3])


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
    soft = expected = variance = 0.0
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
        variance += p['soft_share'] * (1 - p['soft_share']) * len(world.obstacles)
    # each item soft with the world's share: the count within 3 binomial deviations
    assert soft > 0 and abs(soft - expected) <= 3 * np.sqrt(variance) + 1


def _between(value, low, high):
    return low - 1e-4 <= value <= high + 1e-4     # params are kept to 4 decimals


def test_every_world_draws_its_start_goal_and_sizes_within_the_documented_ranges(worlds):
    # the benchmark's worlds are what the docs say they are: its results speak of them
    discs = items = 0
    for (family, seed), world in worlds.items():
        x0, xg = world.arm.fk(np.array([world.start, world.goal])).positions
        assert in_workspace(np.array([x0, xg])).all(), (family, seed)
        assert world.arm.above_table(np.array([world.start, world.goal])).all()
        for x in (x0, xg):
            assert 0.35 <= np.hypot(x[0], x[1]) <= 0.7 and 0.15 <= x[2] <= 0.75
        p = world.params
        if family in ('open_box', 'closed_box', 'plate_hole'):
            half, axes, center = (np.array(p[k]) for k in ('half_size', 'axes', 'center'))
            assert all(_between(h, 0.08, 0.18) for h in half), (family, seed)
            # the flange anywhere in the box's inner half
            assert (np.abs(axes @ (x0 - center)) <= 0.5 * (half - 0.03) + 1e-3).all()
            # the goal 0.05-0.45 m beyond the trap (a box reaches |half| + 0.05 from its
            # centre; a plate's ring may reach a little farther)
            reach, dist = np.linalg.norm(half) + 0.05, np.linalg.norm(xg - center)
            assert dist >= reach + 0.05 - 1e-3, (family, seed)
            if family != 'plate_hole':
                assert dist <= reach + 0.45 + 1e-3, (family, seed)
        if family == 'plate_hole':
            assert _between(p['hole_radius'], 0.03, 0.06)
            # the hole's centre within HOLE_SPREAD of the room its rim leaves on the plate
            k = 'xyz'.index(p['plate_side'][1])
            local = axes @ (np.array(p['hole_center']) - center)
            for i in (m for m in range(3) if m != k):
                room = max(half[i] - p['hole_radius'] - HOLE_MARGIN, 0.0)
                assert abs(local[i]) <= HOLE_SPREAD * room + 1e-3, (seed, i)
            # the exit it was built with passes straight through the hole, from inside out
            way, hole = np.array(world.way_out), np.array(p['hole_center'])
            assert len(way) == 2 and abs(axes[k] @ (way[0] - center)) < half[k] < \
                abs(axes[k] @ (way[1] - center))
            along = (way[1] - way[0]) / np.linalg.norm(way[1] - way[0])
            assert np.linalg.norm(np.cross(hole - way[0], along)) < 1e-3
        if family == 'closed_box':
            assert _between(p['orientation_tolerance'], 0.25, 0.45)
        if family == 'hook_bar':
            for name, low, high in (('bar_length', 0.3, 0.6), ('hook_width', 0.04, 0.10),
                                    ('gap_above', 0.02, 0.05), ('stem_gap', 0.01, 0.03),
                                    ('stem_depth', 0.10, 0.25),
                                    ('orientation_tolerance', 0.3, 0.5)):
                assert _between(p[name], low, high), (seed, name, p[name])
            assert all(o.orientation is not None for o in world.obstacles)
        if family == 'clutter':
            low, high = p['item_radius']
            assert 0.03 <= low < high <= 0.10 and _between(p['cluster_radius'], 0.15, 0.25)
            assert _between(p['soft_share'], 0.0, 0.6)
            assert _between(p['orientation_tolerance'], 0.25, 0.5)
            radii = [o.radius for o in world.obstacles]
            assert low - 1e-4 <= min(radii) < max(radii) <= high + 1e-4
            reach = p['cluster_radius'] + high + 0.05
            assert reach + 0.05 - 1e-3 <= np.linalg.norm(xg - x0) <= reach + 0.45 + 1e-3
            discs += sum(o.kind == 'disc' for o in world.obstacles)
            items += len(world.obstacles)
    # a quarter of the heap's items are flat discs
    assert abs(discs - items / 4) <= 4 * np.sqrt(items * 3 / 16) + 1


def test_every_trap_draws_its_sizes_within_the_documented_ranges():
    # many draws of each builder (no oracle: fast), so that a range drawn too wide shows
    ranges = {'hook_bar': {'bar_length': (0.3, 0.6), 'hook_width': (0.04, 0.10),
                           'gap_above': (0.02, 0.05), 'stem_gap': (0.01, 0.03),
                           'stem_depth': (0.10, 0.25), 'orientation_tolerance': (0.3, 0.5)},
              'closed_box': {'orientation_tolerance': (0.25, 0.45)},
              'plate_hole': {'hole_radius': (0.03, 0.06)},
              'clutter': {'items': (20, 45), 'cluster_radius': (0.15, 0.25),
                          'soft_share': (0.0, 0.6), 'orientation_tolerance': (0.25, 0.5)}}
    x_start, q_start = np.array([0.5, 0.0, 0.4]), np.array([1.0, 0.0, 0.0, 0.0])
    for family in FAMILIES:
        rng = np.random.default_rng(1)
        drawn = [BUILDERS[family](rng, x_start, q_start).params for _ in range(60)]
        for name, (low, high) in ranges.get(family, {}).items():
            values = [p[name] for p in drawn]
            assert _between(min(values), low, high) and _between(max(values), low, high), \
                (family, name, min(values), max(values))
            assert max(values) - min(values) > 0.5 * (high - low)    # and they vary
        if 'half_size' in drawn[0]:
            halves = np.array([p['half_size'] for p in drawn])
            assert _between(halves.min(), 0.08, 0.18) and _between(halves.max(), 0.08, 0.18)
        if family == 'clutter':
            radii = np.array([p['item_radius'] for p in drawn])
            assert (radii[:, 0] < radii[:, 1]).all()
            assert _between(radii.min(), 0.03, 0.10) and _between(radii.max(), 0.03, 0.10)


def test_a_world_is_drawn_from_its_seeds_world_stream_and_counts_its_rejected_draws(worlds):
    # the first draw of the WORLD stream is the start, unless that draw was rejected
    first = {}
    for (family, seed), world in worlds.items():
        if seed not in first:
            first[seed] = _draw_configuration(world.arm, stream(seed, WORLD), in_workspace)
        assert (world.rejected_draws == 0) == np.array_equal(world.start, first[seed]), \
            (family, seed, world.rejected_draws)
    assert any(w.rejected_draws == 0 for w in worlds.values())


def test_an_open_box_says_which_way_its_open_side_lies_and_leads_out_through_it(worlds):
    for seed in SEEDS:
        world = worlds[('open_box', seed)]
        out = np.array(world.params['open_direction'])
        faces, _ = box_exit(world, out[None] / np.linalg.norm(out))
        assert face_names(faces) == {world.params['open_side']}
        # the exit the box was built with ends outside, beyond its open side
        axes, center = np.array(world.params['axes']), np.array(world.params['center'])
        half = np.array(world.params['half_size'])
        k = 'xyz'.index(world.params['open_side'][1])
        assert abs(axes[k] @ (world.way_out[-1] - center)) > half[k]
        assert (world.way_out[-1] - center) @ out > 0


def test_an_unsolvable_world_is_not_certified_even_with_an_exit_given(worlds):
    # the closed box, every wall solid whatever the turn, and an exit through one wall
    world = copy.copy(worlds[('closed_box', 0)])
    world.obstacles = [replace(o, orientation=None) for o in world.obstacles]
    world.way_out = list(worlds[('open_box', 0)].way_out)   # the same box (seed 0's draws)
    assert not certify(world, np.random.default_rng(0), iterations=200)


def test_following_a_line_keeps_the_flange_on_it():
    world = random_family_world('open_box', 0)
    x0 = world.arm.fk(world.start).positions[0]
    target = x0 + np.array([0.0, 0.0, 0.05])
    path = follow(world.arm, world.start, [target])
    xs = world.arm.fk(path).positions
    assert np.linalg.norm(xs[-1] - target) < 0.005
    assert np.abs(xs[:, :2] - x0[:2]).max() < 0.005
    # a line that leaves the arm's reach: no path, not one that strays from the line
    assert follow(world.arm, world.start, [np.array([1.1, 0.0, 0.36])]) is None
    # from joints at their limits: a way along the line within the limits, or none
    arm, followed = world.arm, 0
    for j in range(6):
        for limit, inward in ((arm.lower[j], 0.002), (arm.upper[j], -0.002)):
            q0 = np.array([0.0, 0.8, 0.0, -1.2, 0.0, 0.9, 0.0])
            q0[j] = limit + inward
            x0 = arm.fk(q0).positions[0]
            for d in np.vstack([np.eye(3), -np.eye(3)]):
                path = follow(arm, q0, [x0 + 0.1 * d])
                if path is not None:
                    followed += 1
                    assert ((path >= arm.lower) & (path <= arm.upper)).all(), (j, limit, d)
    assert followed > 0


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
