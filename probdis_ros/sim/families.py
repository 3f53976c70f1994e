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
Entanglement families: robot-style traps around the grasped object, drawn from a seed.

The paper's random worlds scatter obstacles at random; a robot's grasped object is caught
in things with a shape: a box, a hole, a hook, a heap.  Each family below builds one kind of
trap around the flange point of the iiwa (the ``3d-orient`` setting: the flange point plus
its orientation; the arm's links are not modelled) from the simulator's primitives (balls,
flat discs, orientation-gated obstacles that block only an object held as it was at the
start) at a random start anywhere in the arm's workspace (flange 0.35-0.7 m from the base
axis, 0.15-0.75 m high, any azimuth) and a random goal configuration 0.05-0.45 m beyond the
trap.  Every size is drawn per world from its seed and kept in ``World.params``.

``open_box``
    A box (half-sizes 0.08-0.18 m each, turned at random in space) around the flange, the
    flange anywhere in its inner half, with one open side (one of six, at random): the way
    out must be found, no turn helps.  Like ``robot_maze``, but anywhere.
``closed_box``
    The same box with all six sides, orientation-gated at the start orientation with a
    tolerance of 0.25-0.45 (a turn of 45-81 degrees): passable only with the object turned.
``plate_hole``
    The box of ``open_box`` whose open side is a plate with one circular hole (radius
    0.03-0.06 m, off the plate's centre by up to half the room left) that the flange must
    find and pass straight through.  Like ``robot_bunny``, but the plate has no other gap.
``hook_bar``
    A hook under a bar (as ``demo_hook``, seen from the hook's tip): a horizontal strip
    0.02-0.05 m above the flange (0.3-0.6 m long along a bar of random direction, 0.04-0.10
    m across: the hook's reach under it) and a wall 0.1-0.25 m deep down from the strip's
    edge on the stem's side, all orientation-gated at the start orientation (tolerance
    0.3-0.5: a turn of the hook frees it).  Out: a side step away from the stem, along the
    bar, down and under the wall, or a turn.
``clutter``
    20-45 items (balls of radius 0.03-0.10 m, a quarter of them flat discs of random
    normal) within 0.15-0.25 m of the flange, one of them on the straight move to the goal;
    a share of 0-60 % of them soft: they give way to an object turned by more than the
    tolerance (0.25-0.5) from its start orientation, like ``robot_waste``.

Walls and plates are tiled with flat discs that overlap, so a wall has no gap; a plate's
hole is a ring of discs whose inner edge is the hole's rim.  A world is kept only if the
flange starts and ends free, the straight joint-space move from start to goal is blocked,
and a planner that sees the obstacles (:mod:`probdis_ros.sim.oracle`) finds a way out; for
a box or a plate it may start from the exit the trap was built with (the flange led out
through the opening or the hole by damped least squares), since a random tree rarely
threads a hole; either way the whole path is checked free by the compliant arm.
``World.rejected_draws`` counts the draws thrown away.  The world draws only from its
seed's WORLD stream (:mod:`probdis_ros.planning.seeds`), so an episode given the same seed
plans with an independent stream.  Evaluation worlds are seeds 0-99 of each family;
anything tuned on this benchmark is tuned on seeds 1000 and above.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
import math

import numpy as np
from probdis_ros.model import arm_for_setting
from probdis_ros.model.arms import Arm, quaternion_to_rotation
from probdis_ros.model.table import ROBOT_TABLE
from probdis_ros.planning.seeds import stream, WORLD
from probdis_ros.sim.compliant_arm import densify
from probdis_ros.sim.obstacles import Obstacle
from probdis_ros.sim.oracle import find_free_path
from probdis_ros.sim.worlds import World

SETTING = '3d-orient'
FAMILIES = ('open_box', 'closed_box', 'plate_hole', 'hook_bar', 'clutter')
#: Longest side of a wall's tile (one flat disc) [m]; fewer obstacles, faster contact tests.
WALL_TILE = 0.2
#: Tile of a plate around its hole: small, so the ring of the hole stays small.
PLATE_TILE = 0.06
#: [m] a plate's hole keeps its rim at least this far from the plate's edges ...
HOLE_MARGIN = 0.02
#: ... and its centre within this share of the room that leaves, around the plate's centre.
HOLE_SPREAD = 0.5
#: Relative overlap of neighbouring discs, so that no seam lets the point through.
OVERLAP = 1.02
_AXES = ('x', 'y', 'z')


@dataclass
class FamilyWorld(World):
    """A world of an entanglement family, with the parameters it was drawn with."""

    family: str = ''
    params: dict = field(default_factory=dict)
    way_out: list = field(default_factory=list, repr=False)   # flange points of an exit

    def to_dict(self) -> dict:
        """Return the scenario document, with the family and its parameters for the reader."""
        return {**super().to_dict(), 'family': self.family, 'params': self.params}


# -- geometry --------------------------------------------------------------------------------

def _rectangle(center: np.ndarray, u: np.ndarray, v: np.ndarray, a: float, b: float,
               gate: np.ndarray | None, tile: float = WALL_TILE,
               keep: Callable[[np.ndarray, float], bool] | None = None) -> list[Obstacle]:
    """
    Return flat discs that cover the rectangle ``center +- a u +- b v`` without a gap.

    The rectangle is cut into tiles of at most ``tile`` a side, and no longer than the
    rectangle is wide, so that no disc sticks out far beyond a thin strip; each tile gets the
    disc through its corners (a little larger).  ``keep(center, radius)`` may leave tiles out.
    """
    tile = min(tile, 2 * min(a, b))
    nu, nv = max(1, math.ceil(2 * a / tile - 1e-9)), max(1, math.ceil(2 * b / tile - 1e-9))
    su, sv = 2 * a / nu, 2 * b / nv
    radius = OVERLAP * math.hypot(su, sv) / 2
    normal = np.cross(u, v)
    discs = []
    for i in range(nu):
        for j in range(nv):
            c = center + (-a + (i + 0.5) * su) * u + (-b + (j + 0.5) * sv) * v
            if keep is None or keep(c, radius):
                discs.append(Obstacle('disc', c, radius, normal=normal, orientation=gate))
    return discs


def ring_radius(hole: float, reach: float, count: int = 12) -> float:
    """
    Return the disc radius R of a ring of ``count`` discs around a hole of radius ``hole``.

    The discs touch the rim (centres at hole + R); R is the smallest (in 5 mm steps) whose
    union covers the annulus out to ``reach``, so the plate's tiles can stay clear of it.
    """
    s, c = math.sin(math.pi / count), math.cos(math.pi / count)
    radius = hole
    while True:
        d = hole + radius
        half = d * s
        if half < radius:
            h = math.sqrt(radius ** 2 - half ** 2)
            if d * c + h >= reach:
                return radius
        radius += 0.005


def _plate_with_hole(center: np.ndarray, u: np.ndarray, v: np.ndarray, a: float, b: float,
                     hole_at: np.ndarray, hole: float, count: int = 12) -> list[Obstacle]:
    """Return discs that cover the rectangle except a circular hole (at ``hole_at``)."""
    tile_radius = OVERLAP * math.hypot(PLATE_TILE, PLATE_TILE) / 2
    radius = ring_radius(hole, hole + 2 * tile_radius + 0.005, count)
    normal = np.cross(u, v)
    ring = [Obstacle('disc', hole_at + (hole + radius) * (math.cos(t) * u + math.sin(t) * v),
                     radius, normal=normal)
            for t in 2 * math.pi * np.arange(count) / count]
    # a tile stays if its disc keeps clear of the hole; those left out lie inside the ring
    tiles = _rectangle(center, u, v, a, b, None, PLATE_TILE,
                       keep=lambda c, r: float(np.linalg.norm(c - hole_at)) - r >= hole)
    return ring + tiles


def hole_room(half: np.ndarray, hole: float, normal_axis: int) -> np.ndarray:
    """
    Return the room a hole of radius ``hole`` leaves on a box's side, along its two axes.

    The side is the one across ``normal_axis`` of a box of half-sizes ``half``: its
    half-extents less the hole's radius and ``HOLE_MARGIN`` (at least 0).
    """
    i, j = [m for m in range(3) if m != normal_axis]
    return np.maximum(np.asarray(half, dtype=float)[[i, j]] - hole - HOLE_MARGIN, 0.0)


def _box(center: np.ndarray, rot: np.ndarray, half: np.ndarray, gate: np.ndarray | None,
         skip: int | None = None) -> list[Obstacle]:
    """Return the walls of a box (axes the columns of rot), all but face ``skip`` (0-5)."""
    discs = []
    for face in range(6):
        if face == skip:
            continue
        k, sign = divmod(face, 2)
        i, j = [m for m in range(3) if m != k]
        normal_center = center + (1 - 2 * sign) * half[k] * rot[:, k]
        discs += _rectangle(normal_center, rot[:, i], rot[:, j], half[i], half[j], gate)
    return discs


def face_name(face: int) -> str:
    """Name a box face 0-5 as +x, -x, +y, -y, +z, -z of the box's own axes."""
    k, sign = divmod(face, 2)
    return f'{"+-"[sign]}{_AXES[k]}'


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    quat = rng.normal(size=4)
    return quaternion_to_rotation(quat / np.linalg.norm(quat))[0]


# -- families --------------------------------------------------------------------------------

@dataclass
class Trap:
    """What a family builds around the flange: obstacles, the room they take, parameters."""

    obstacles: list[Obstacle]
    center: np.ndarray
    reach: float                    # no obstacle is farther than this from center [m]
    tolerance: float = 0.5
    params: dict = field(default_factory=dict)
    way_out: list[np.ndarray] = field(default_factory=list)   # flange points of an exit


def _box_room(rng: np.random.Generator, x_start: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Draw a box around the flange: centre, rotation, half-sizes (flange in its inner half)."""
    half = rng.uniform(0.08, 0.18, size=3)
    rot = _random_rotation(rng)
    offset = rng.uniform(-0.5, 0.5, size=3) * (half - 0.03)
    return x_start - rot @ offset, rot, half


def _box_params(center: np.ndarray, rot: np.ndarray, half: np.ndarray) -> dict:
    return {'center': center.round(4).tolist(), 'half_size': half.round(4).tolist(),
            'axes': rot.T.round(4).tolist()}


def open_box(rng: np.random.Generator, x_start: np.ndarray, q_start: np.ndarray) -> Trap:
    """Build a box with one open side, in a random direction; no turn helps."""
    center, rot, half = _box_room(rng, x_start)
    face = int(rng.integers(6))
    k, sign = divmod(face, 2)
    out = (1 - 2 * sign) * rot[:, k]
    return Trap(_box(center, rot, half, None, skip=face), center,
                float(np.linalg.norm(half)) + 0.05,
                params={**_box_params(center, rot, half), 'open_side': face_name(face),
                        'open_direction': out.round(4).tolist()},
                way_out=[center + (half[k] - 0.03) * out, center + (half[k] + 0.1) * out])


def closed_box(rng: np.random.Generator, x_start: np.ndarray, q_start: np.ndarray) -> Trap:
    """Build a closed box whose walls block only the object held as at the start."""
    center, rot, half = _box_room(rng, x_start)
    tolerance = float(rng.uniform(0.25, 0.45))
    return Trap(_box(center, rot, half, q_start), center, float(np.linalg.norm(half)) + 0.05,
                tolerance, {**_box_params(center, rot, half), 'orientation_tolerance':
                            round(tolerance, 4), 'turn_deg': round(180 * tolerance, 1)})


def plate_hole(rng: np.random.Generator, x_start: np.ndarray, q_start: np.ndarray) -> Trap:
    """Build a box whose sixth side is a plate with one hole the flange must pass."""
    center, rot, half = _box_room(rng, x_start)
    face = int(rng.integers(6))
    hole = float(rng.uniform(0.03, 0.06))
    k, sign = divmod(face, 2)
    i, j = [m for m in range(3) if m != k]
    room = hole_room(half, hole, k)
    shift = rng.uniform(-HOLE_SPREAD, HOLE_SPREAD, size=2) * room
    plate_center = center + (1 - 2 * sign) * half[k] * rot[:, k]
    hole_at = plate_center + shift[0] * rot[:, i] + shift[1] * rot[:, j]
    plate = _plate_with_hole(plate_center, rot[:, i], rot[:, j], half[i], half[j], hole_at,
                             hole)
    reach = max(float(np.linalg.norm(o.center - center)) + o.radius for o in plate)
    out = (1 - 2 * sign) * rot[:, k]
    return Trap(_box(center, rot, half, None, skip=face) + plate, center,
                max(reach, float(np.linalg.norm(half))) + 0.05,
                params={**_box_params(center, rot, half), 'plate_side': face_name(face),
                        'hole_radius': round(hole, 4), 'hole_center': hole_at.round(4).tolist()},
                way_out=[hole_at - 0.03 * out, hole_at + 0.1 * out])


def hook_bar(rng: np.random.Generator, x_start: np.ndarray, q_start: np.ndarray) -> Trap:
    """Build a hook caught under a bar: a strip above, a wall on the stem's side, gated."""
    heading = rng.uniform(0, 2 * math.pi)
    along = np.array([math.cos(heading), math.sin(heading), 0.0])
    across = np.array([-math.sin(heading), math.cos(heading), 0.0])   # toward the free side
    up = np.array([0.0, 0.0, 1.0])
    length = float(rng.uniform(0.3, 0.6))
    width = float(rng.uniform(0.04, 0.10))       # the hook's reach under the bar
    gap = float(rng.uniform(0.02, 0.05))         # flange to bar
    stem = float(rng.uniform(0.01, 0.03))        # flange to the wall on the stem's side
    depth = float(rng.uniform(0.10, 0.25))       # the stem's length below the bar
    slide = float(rng.uniform(-0.3, 0.3)) * length
    tolerance = float(rng.uniform(0.3, 0.5))
    mid = x_start - slide * along
    strip_center = mid + gap * up + (width / 2 - stem) * across
    wall_center = mid + (gap - depth / 2) * up - stem * across
    obstacles = _rectangle(strip_center, along, across, length / 2, width / 2, q_start) + \
        _rectangle(wall_center, along, up, length / 2, depth / 2, q_start)
    reach = max(float(np.linalg.norm(o.center - mid)) + o.radius for o in obstacles)
    return Trap(obstacles, mid, reach + 0.05, tolerance, {
        'bar_direction': along.round(4).tolist(), 'free_side': across.round(4).tolist(),
        'bar_length': round(length, 4), 'hook_width': round(width, 4),
        'gap_above': round(gap, 4), 'stem_gap': round(stem, 4), 'stem_depth': round(depth, 4),
        'orientation_tolerance': round(tolerance, 4), 'turn_deg': round(180 * tolerance, 1)})


def clutter(rng: np.random.Generator, x_start: np.ndarray, q_start: np.ndarray) -> Trap:
    """Draw the heap's parameters; its items are placed once the goal is known."""
    r_low = float(rng.uniform(0.03, 0.05))
    params = {'items': int(rng.integers(20, 46)), 'cluster_radius':
              round(float(rng.uniform(0.15, 0.25)), 4),
              'item_radius': [round(r_low, 4), round(float(r_low + rng.uniform(0.02, 0.05)), 4)],
              'soft_share': round(float(rng.uniform(0.0, 0.6)), 4),
              'orientation_tolerance': round(float(rng.uniform(0.25, 0.5)), 4)}
    return Trap([], x_start.copy(), params['cluster_radius'] + params['item_radius'][1] + 0.05,
                params['orientation_tolerance'], params)


def _clutter_items(rng: np.random.Generator, arm: Arm, trap: Trap, start: np.ndarray,
                   goal: np.ndarray, q_start: np.ndarray) -> list[Obstacle]:
    """Place the heap: one item on the straight move to the goal, the rest around the flange."""
    p = trap.params
    x_start, x_goal = arm.fk(np.array([start, goal])).positions

    def item(center: np.ndarray, normal: np.ndarray | None = None) -> Obstacle:
        radius = rng.uniform(*p['item_radius'])
        gate = q_start if rng.random() < p['soft_share'] else None
        if rng.random() < 0.25:
            return Obstacle('disc', center, radius,
                            normal=normal if normal is not None else rng.normal(size=3),
                            orientation=gate)
        return Obstacle('ball', center, radius, orientation=gate)

    dense, _ = densify(np.array([start, goal]), 0.01)
    trace = arm.fk(dense).positions
    ahead = int(np.argmax(np.linalg.norm(trace - x_start, axis=1) > p['item_radius'][1] + 0.02))
    ahead = min(ahead, len(trace) - 2)
    items = [item(trace[ahead], trace[ahead + 1] - trace[ahead])]
    while len(items) < p['items']:
        offset = rng.normal(size=3)
        offset *= p['cluster_radius'] * rng.random() ** (1 / 3) / np.linalg.norm(offset)
        candidate = item(x_start + offset)
        if not candidate.contains(np.array([x_start, x_goal])).any():
            items.append(candidate)
    return items


BUILDERS: dict[str, Callable[[np.random.Generator, np.ndarray, np.ndarray], Trap]] = {
    'open_box': open_box, 'closed_box': closed_box, 'plate_hole': plate_hole,
    'hook_bar': hook_bar, 'clutter': clutter}


# -- starts, goals, worlds -------------------------------------------------------------------

def in_workspace(points: np.ndarray) -> np.ndarray:
    """Tell which flange points lie in the benchmark's part of the iiwa's workspace."""
    radial = np.hypot(points[:, 0], points[:, 1])
    return (radial >= 0.35) & (radial <= 0.7) & (points[:, 2] >= 0.15) & (points[:, 2] <= 0.75)


def _draw_configuration(arm: Arm, rng: np.random.Generator,
                        accept: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Draw uniform configurations in batches until one's flange point is accepted."""
    while True:
        configs = arm.random_configurations(rng, 256)
        ok = np.flatnonzero(accept(arm.fk(configs).positions))
        if len(ok):
            return configs[ok[0]]


def follow(arm: Arm, start: np.ndarray, points: list[np.ndarray], step: float = 0.005,
           damping: float = 1e-3) -> np.ndarray | None:
    """
    Return a joint path whose flange follows straight lines through ``points``, or None.

    Damped least squares on a finite-difference Jacobian, ``step`` metres at a time; None
    where the arm cannot follow within its joint limits (the flange then strays).
    """
    q = start.copy()
    path = [q.copy()]
    eye = 1e-6 * np.eye(len(q))
    x = arm.fk(q).positions[0]
    for target in points:
        n = max(1, math.ceil(float(np.linalg.norm(target - x)) / step))
        for k in range(1, n + 1):
            goal = x + (target - x) * k / n
            for _ in range(3):
                here = arm.fk(np.vstack([q, q + eye])).positions
                jac = (here[1:] - here[0]).T / 1e-6
                error = goal - here[0]
                dq = jac.T @ np.linalg.solve(jac @ jac.T + damping * np.eye(3), error)
                q = np.clip(q + dq, arm.lower, arm.upper)
            path.append(q.copy())
        x = target
        if np.linalg.norm(arm.fk(q).positions[0] - target) > 0.005:
            return None
    return np.array(path)


def certify(world: FamilyWorld, rng: np.random.Generator, iterations: int = 3000) -> bool:
    """
    Tell whether a way out was found: the trap's exit, then the oracle's; or the oracle's.

    A narrow exit (a hole) is rarely threaded by a random tree; following the exit the trap
    was built with, then planning the free rest, certifies such worlds in a fraction of the
    time.  Either way the whole path is checked free by the compliant arm.
    """
    sim = world.compliant_arm()
    if world.way_out:
        way = follow(world.arm, world.start, world.way_out)
        if way is not None and sim.path_is_free(way):
            rest = find_free_path(sim, way[-1], world.goal, rng, iterations)
            if rest is not None and sim.path_is_free(np.vstack([way, rest[1:]])):
                return True
    return find_free_path(sim, world.start, world.goal, rng, iterations) is not None


def random_family_world(family: str, seed: int, max_draws: int = 100,
                        oracle_iterations: int = 3000) -> FamilyWorld:
    """
    Draw a solvable, entangled world of an entanglement family from a seed (reproducibly).

    Raises ValueError for an unknown family, RuntimeError if max_draws draws in a row are
    rejected.
    """
    if family not in BUILDERS:
        raise ValueError(f'unknown family {family!r}; choose from {", ".join(FAMILIES)}')
    arm = arm_for_setting(SETTING).on_table(ROBOT_TABLE)
    rng = stream(seed, WORLD)
    for draw in range(max_draws):
        start = _draw_configuration(arm, rng, in_workspace)
        pose = arm.fk(start)
        x_start, q_start = pose.positions[0], pose.orientations[0]
        trap = BUILDERS[family](rng, x_start, q_start)

        def beyond(points: np.ndarray, trap: Trap = trap) -> np.ndarray:
            dist = np.linalg.norm(points - trap.center, axis=1)
            return in_workspace(points) & (dist >= trap.reach + 0.05) & \
                (dist <= trap.reach + 0.45)

        goal = _draw_configuration(arm, rng, beyond)
        if family == 'clutter':
            trap.obstacles = _clutter_items(rng, arm, trap, start, goal, q_start)
        if not arm.above_table(np.array([start, goal])).all():
            continue        # an arm that would start or end in its table
        world = FamilyWorld(SETTING, start, goal, trap.obstacles, trap.tolerance,
                            name=f'{family}-seed{seed}', rejected_draws=draw, table=ROBOT_TABLE,
                            family=family,
                            params={**trap.params, 'obstacles': len(trap.obstacles)},
                            way_out=trap.way_out)
        sim = world.compliant_arm()
        if sim.collides(start) or sim.collides(goal) or sim.path_is_free(np.array([start, goal])):
            continue
        if certify(world, rng, oracle_iterations):
            return world
    raise RuntimeError(f'no solvable {family} world in {max_draws} draws (seed {seed})')
