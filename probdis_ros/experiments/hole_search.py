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
How many ``plate_hole`` worlds could a search get out of within n paths: bounds, and one search.

In the kinematic simulator a blocked path ends where the flange first meets a surface: each
path tests one point of the trap, and gets out only if that point lies in the hole (the
flange is a point; the hole's rim has radius r).  Whatever a method learns from its
failures, it cannot do better than a searcher that knows the trap's geometry and tests the
likeliest points first; how well that searcher does depends on what it knows of where the
hole is.  Per world, three such bounds and one search that could be run:

``box``
    Knows the box exactly, and that the hole lies on one of its six sides (1/6 each, as the
    generator draws them) with its rim at least ``HOLE_MARGIN`` from the side's edges,
    anywhere there.  One path tests one point, which finds the holes whose opening holds
    it: at most ``a / A`` of a side whose possible centres cover A (all of it if A is
    smaller), a the opening's area (``pi r^2`` and the few per cent the ring's cusps add).
    The best n paths take the largest such shares first (a side's add up until it is
    covered).  An upper bound for boxes whose holes lie *anywhere* on a side, and a generous
    one (openings cannot tile a side without overlap, and a method must learn the box from
    its blocks).  Not a bound on this family's worlds: the generator puts the holes near a
    side's middle, and a search that tests the middles first (``centre_first``) beats it.
``generator``
    Knows also that this generator draws the centre within ``HOLE_SPREAD`` of the room
    around the side's centre: the upper bound on this family's worlds for any search that
    tests one point per path.
``direction``
    Knows nothing of the box and sends straight lines from the start, the hole's direction
    uniform on the sphere: each line finds it with the hole's share of the sphere of
    directions (its solid angle over 4 pi), so at most ``min(1, n share)``.  Not a bound on
    methods whose paths are not such lines; a yardstick for straight probes.
``centre_first``
    A possible search, not a bound, run on each world's own hole: knows the box and the
    hole's radius, not where the hole is; tests each side on a lattice that covers it,
    from the side's middle outward, round by round a point on each side.  What a method
    that knew the box and searched it with that generic habit could reach.
``learned_box``
    A possible search, not a bound, run in the simulator on each world: the centre-first
    search of a box it must first learn from its own blocks (it knows that the trap is a
    box and the hole's radius; it sees where each straight line from the start stopped).
    A block tells one number, how far its line went; a box takes nine (turn, six sides):
    :func:`learned_box_lines` spends ten to thirteen lines on it (three close together for
    a side's plane, the lines along that side's normal both ways, two across it for the
    turn, then the axes of the box that fits the stops best, both ways, where no line went
    yet), each of them a test of the hole as well, then searches the box it learnt.  One
    search that learns what ``centre_first`` is given, and not always right (its lines
    need not meet the sides as laid out).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
import itertools
import math
import warnings

import numpy as np
from probdis_ros.planning.seeds import PLANNER, stream
from probdis_ros.sim.families import (
    FamilyWorld,
    hole_room,
    HOLE_SPREAD,
    random_family_world,
)
from probdis_ros.sim.obstacles import Obstacle

FAMILY = 'plate_hole'
PRIORS = ('box', 'generator', 'direction', 'centre_first', 'learned_box')
#: what each searcher knows, as tables and figures name it
LABELS = {'box': 'bound if holes lay anywhere on a side (knows the box)',
          'generator': "bound: knows the generator's spread",
          'direction': 'straight lines from the start (bound for such lines)',
          'centre_first': "a search: knows the box, each side's middle first",
          'learned_box': 'a search: learns the box from its blocks, then middles first'}
#: directions of the Fibonacci lattice that measure a hole's solid angle (deterministic)
DIRECTIONS = 400_000


def fibonacci_sphere(count: int) -> np.ndarray:
    """Return ``count`` unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / count)
    azimuth = math.pi * (1.0 + math.sqrt(5.0)) * i
    return np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                     np.cos(polar)], axis=1)


def plate_discs(world: FamilyWorld, hole: np.ndarray, normal: np.ndarray) -> list[Obstacle]:
    """Return the flat discs of the plate (the hole's ring and the tiles) of a world."""
    return [o for o in world.obstacles if o.kind == 'disc' and o.normal is not None
            and abs(abs(float(o.normal @ normal)) - 1.0) < 1e-9
            and abs(float((o.center - hole) @ normal)) < 1e-9]


def open_in_plate(points: np.ndarray, discs: list[Obstacle]) -> np.ndarray:
    """Tell which points of the plate's plane no disc of the plate covers."""
    covered = np.zeros(len(points), dtype=bool)
    for disc in discs:
        covered |= np.linalg.norm(points - disc.center, axis=1) < disc.radius
    return ~covered


def open_area(hole: np.ndarray, radius: float, normal: np.ndarray, discs: list[Obstacle],
              cells: int = 600) -> float:
    """
    Return the area of the hole as the plate's discs leave it open [m^2].

    A little more than pi r^2: between the ring's discs, which touch the rim, the opening
    reaches a few per cent beyond it.  Counted on a grid of ``cells`` squared over the
    square of side 3 r about the centre (the opening lies within 1.1 r).
    """
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    side = 3.0 * radius
    g = (np.arange(cells) + 0.5) / cells * side - side / 2
    a, b = (m.ravel() for m in np.meshgrid(g, g))
    points = hole + a[:, None] * u + b[:, None] * v
    return float(open_in_plate(points, discs).mean()) * side ** 2


def direction_share(start: np.ndarray, hole: np.ndarray, radius: float, normal: np.ndarray,
                    discs: list[Obstacle], directions: int = DIRECTIONS) -> float:
    """
    Return the share of directions from ``start`` whose straight line leaves by the hole.

    A line leaves where it meets the plate's plane near the hole (within 1.5 r) and no disc
    of the plate covers that point; counted on a Fibonacci lattice of ``directions``.  The
    start lies inside a convex box whose side the plate is, so no other wall comes first.
    """
    height = float((hole - start) @ normal)
    if height < 0:
        normal, height = -normal, -height
    d = fibonacci_sphere(directions)
    toward = d @ normal
    ahead = toward > 1e-12
    crossing = start + (height / np.where(ahead, toward, 1.0))[:, None] * d
    near = ahead & (np.linalg.norm(crossing - hole, axis=1) < 1.5 * radius)
    return float(open_in_plate(crossing[near], discs).sum()) / directions


def side_shares(half: np.ndarray, radius: float, opening: float, spread: float) -> list[float]:
    """
    Return per side of the box the share of the hole's centres one tested point can find.

    Of a box of half-sizes ``half``, at most 1 per side.  A point finds the holes whose
    opening (area ``opening``) holds it.  The centres lie in a rectangle ``spread`` times
    the room on each axis wide (room: the half-size less the hole's radius and
    ``HOLE_MARGIN``): ``spread = 2`` anywhere the hole fits, ``2 * HOLE_SPREAD`` as the
    generator draws them.
    """
    shares = []
    for normal_axis in range(3):
        room = hole_room(half, radius, normal_axis)
        area = float(np.prod(spread * room))
        share = 1.0 if area <= opening else opening / area
        shares += [share, share]
    return shares


def best_search(shares: list[float], paths: int) -> list[float]:
    """
    Return the chance of having found the hole within 1..paths points, testing at best.

    Each side (1/6 of the chance) gains ``share`` per point until covered; taking the
    largest gain at each step is optimal for such gains (each side's do not grow).
    """
    tested = [0] * len(shares)
    found, curve = 0.0, []
    for _ in range(paths):
        gains = [min(s, max(0.0, 1.0 - k * s)) for s, k in zip(shares, tested)]
        best = int(np.argmax(gains))
        tested[best] += 1
        found += gains[best] / len(shares)
        curve.append(min(found, 1.0))
    return curve


#: the most points the centre-first search tests (beyond any episode's paths)
MOST_POINTS = 60


def centre_first_points(half: np.ndarray, radius: float, most: int = MOST_POINTS
                        ) -> list[tuple[int, float, float]]:
    """
    Return the centre-first search's points in order: (side, a, b) in the box's axes.

    On each side a hexagonal lattice of spacing ``r sqrt(3)`` (discs of radius r about its
    points cover the plane), nearest the side's middle first, as far as a hole's centre
    could lie; round by round a point on each side (the smallest side first), so that
    every side's middle is tried before any side's second point.
    """
    spacing = radius * math.sqrt(3.0)
    per_side, areas = [], []
    m = int(0.4 / spacing) + 2
    lattice = np.array([(spacing * (i + 0.5 * (j % 2)), spacing * math.sqrt(3.0) / 2 * j)
                        for i in range(-m, m + 1) for j in range(-2 * m, 2 * m + 1)])
    lattice = lattice[np.argsort(np.hypot(lattice[:, 0], lattice[:, 1]), kind='stable')]
    for side in range(6):
        room = hole_room(half, radius, side // 2)
        keep = np.all(np.abs(lattice) <= room + radius, axis=1)
        per_side.append(lattice[keep][:most])
        areas.append(float(room[0] * room[1]))
    # round by round, a point on each side, the smallest side first
    sides = sorted(range(6), key=lambda side: (areas[side], side))
    order = [(side, float(per_side[side][n][0]), float(per_side[side][n][1]))
             for n in range(most) for side in sides if n < len(per_side[side])]
    return order[:most]


def side_point(center: np.ndarray, axes: np.ndarray, half: np.ndarray, side: int, a: float,
               b: float) -> np.ndarray:
    """Return the point (a, b) of a box's side (0-5: +x, -x, ... of its axes, rows of axes)."""
    k = side // 2
    i, j = [m for m in range(3) if m != k]
    return center + (1 - 2 * (side % 2)) * half[k] * axes[k] + a * axes[i] + b * axes[j]


def centre_first_paths(world: FamilyWorld, discs: list[Obstacle]) -> int:
    """
    Return the paths the centre-first search takes to get out of a world (0: not within 60).

    A possible search, not a bound: it knows the box and the hole's radius, not where the
    hole is, and tests the middle of each side first.
    """
    p = world.params
    axes, center = np.array(p['axes']), np.array(p['center'])
    half, radius = np.array(p['half_size']), float(p['hole_radius'])
    plate = 2 * 'xyz'.index(p['plate_side'][1]) + (p['plate_side'][0] == '-')
    for n, (side, a, b) in enumerate(centre_first_points(half, radius), start=1):
        if side != plate:
            continue
        point = side_point(center, axes, half, side, a, b)
        if open_in_plate(point[None], discs)[0]:
            return n
    return 0


#: [rad] the learned-box search's first three lines lie this far apart (to meet one side)
TRIANGLE = math.radians(15)
#: [rad] its two lines across the first side's normal lie this far apart
ACROSS = math.radians(25)
#: [rad] it sends a line along each axis of the box it fits, unless one went this near
AXIS_TRIED = math.radians(10)


def first_stop(world: FamilyWorld, start: np.ndarray, direction: np.ndarray,
               length: float = 1.0) -> np.ndarray | None:
    """Return where a straight flange move from start first meets an obstacle (None: out)."""
    end = start + length * direction
    t = min(float(o.first_hit(start[None], end[None])[0]) for o in world.obstacles)
    return None if math.isinf(t) else start + t * length * direction


def _turned(axis: np.ndarray, v: np.ndarray, angle: float) -> np.ndarray:
    """Return v turned by angle about a unit axis (Rodrigues)."""
    return (v * math.cos(angle) + np.cross(axis, v) * math.sin(angle)
            + axis * float(axis @ v) * (1.0 - math.cos(angle)))


def _across(v: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Return a random unit vector perpendicular to unit v."""
    a = rng.normal(size=3)
    a -= float(a @ v) * v
    return a / np.linalg.norm(a)


@dataclass(frozen=True)
class LearnedBox:
    """The box the learned-box search believes in: rows of ``axes`` its axes."""

    axes: np.ndarray
    center: np.ndarray
    half: np.ndarray
    lines: int = 0          # the lines it took to learn it


#: [m] a stop this near a face of a box lies on it (the walls are exact planes)
ON_FACE = 0.002


def fit_box(stops: np.ndarray, start: np.ndarray) -> LearnedBox:
    """
    Return the box that puts the most stops on its faces, the start inside.

    Its first axis is the normal of a plane through three stops with no stop beyond it (a
    side of a convex box), its second the normal of a plane through the first axis and two
    stops (a side across it), its extent the stops' extremes along the axes; ties go to
    the smaller box.  Every such frame is tried.
    """
    rel = stops - start
    best, best_key = None, None
    for i, j, k in itertools.combinations(range(len(stops)), 3):
        n1 = np.cross(rel[j] - rel[i], rel[k] - rel[i])
        if np.linalg.norm(n1) < 1e-9:
            continue
        n1 /= np.linalg.norm(n1)
        n1 = n1 if float(n1 @ rel[i]) > 0 else -n1
        if np.any(rel @ n1 > float(n1 @ rel[i]) + ON_FACE):
            continue
        for a, b in itertools.combinations(range(len(stops)), 2):
            along = rel[b] - rel[a]
            along -= float(along @ n1) * n1
            if np.linalg.norm(along) < 1e-3:
                continue
            n2 = np.cross(n1, along / np.linalg.norm(along))
            axes = np.array([n1, n2, np.cross(n1, n2)])
            coords = rel @ axes.T
            low, high = coords.min(axis=0), coords.max(axis=0)
            on = ((np.abs(coords - low) < ON_FACE) | (np.abs(coords - high) < ON_FACE)).any(1)
            key = (int(on.sum()), -float(np.prod(high - low)))
            if best_key is None or key > best_key:
                best_key = key
                best = LearnedBox(axes, start + ((low + high) / 2) @ axes, (high - low) / 2)
    if best is None:
        raise ValueError('no box fits these stops (fewer than three, or all on a line)')
    return best


def learned_box_lines(world: FamilyWorld, radius: float, seed: int, most: int = MOST_POINTS
                      ) -> tuple[list[np.ndarray], LearnedBox | None]:
    """
    Run the learned-box search in the simulator: its lines' directions, and the box it learnt.

    It sees only where each straight line from the start stopped.  Three lines
    ``TRIANGLE`` apart meet, most likely, one side: their stops give its plane and normal
    n1; then lines along n1 and -n1, and two lines ``ACROSS`` apart across n1 (their
    stops' difference gives the turn about n1 if they meet one side); then a line along
    each axis of the box that fits the stops best (:func:`fit_box`) both ways, where none
    went yet; the box that fits all its stops then; then that box's centre-first lattice.
    It stops at the first line out or after ``most`` lines; draws from the seed's PLANNER
    stream.  The box is None if a line got out before it was learnt.
    """
    start = world.arm.fk(world.start).positions[0]
    rng = stream(seed, PLANNER)
    lines: list[np.ndarray] = []
    stops: list[np.ndarray] = []

    def out(direction: np.ndarray) -> bool:
        direction = direction / np.linalg.norm(direction)
        lines.append(direction)
        stop = first_stop(world, start, direction)
        if stop is not None:
            stops.append(stop)
        return stop is None or len(lines) >= most

    first = rng.normal(size=3)
    first /= np.linalg.norm(first)
    a = _across(first, rng)
    b = np.cross(first, a)
    triangle = [first] + [_turned(math.cos(t) * a + math.sin(t) * b, first, TRIANGLE)
                          for t in (0.0, 2 * math.pi / 3)]
    if any(out(u) for u in triangle):
        return lines, None
    n1 = np.cross(stops[1] - stops[0], stops[2] - stops[0])
    n1 /= np.linalg.norm(n1)
    n1 = n1 if float(n1 @ (stops[0] - start)) > 0 else -n1
    w = _across(n1, rng)
    if any(out(u) for u in (n1, -n1, w, _turned(n1, w, ACROSS))):
        return lines, None
    for axis in fit_box(np.array(stops), start).axes:
        for u in (axis, -axis):
            if max(float(u @ line) for line in lines) < math.cos(AXIS_TRIED) and out(u):
                return lines, None
    box = replace(fit_box(np.array(stops), start), lines=len(lines))
    for side, u, v in centre_first_points(box.half, radius, most):
        if out(side_point(box.center, box.axes, box.half, side, u, v) - start):
            break
    return lines, box


def learned_box_paths(world: FamilyWorld, radius: float, seed: int, most: int = MOST_POINTS
                      ) -> int:
    """Return the paths the learned-box search takes to get out of a world (0: not within most)."""
    lines, _ = learned_box_lines(world, radius, seed, most)
    start = world.arm.fk(world.start).positions[0]
    return len(lines) if first_stop(world, start, lines[-1]) is None else 0


@dataclass(frozen=True)
class HoleBound:
    """What bounds the search of one ``plate_hole`` world."""

    seed: int
    hole_radius: float
    opening_m2: float             # the hole's open area, a few per cent above pi r^2
    hole_distance: float          # [m] from the flange's start to the hole's centre
    direction_share: float        # of the sphere of directions from the start
    box_shares: tuple[float, ...]
    generator_shares: tuple[float, ...]
    centre_first_paths: int = 0   # the centre-first search's paths out (0: not within 60)
    learned_box_paths: int = 0    # the learned-box search's paths out (0: not within 60)

    def curve(self, prior: str, paths: int) -> list[float]:
        """Return the searcher's chance of being out within 1..paths paths."""
        if prior in ('centre_first', 'learned_box'):
            taken = getattr(self, f'{prior}_paths')
            return [float(0 < taken <= n) for n in range(1, paths + 1)]
        if prior == 'direction':
            return [min(1.0, n * self.direction_share) for n in range(1, paths + 1)]
        if prior == 'box':
            return best_search(list(self.box_shares), paths)
        if prior == 'generator':
            return best_search(list(self.generator_shares), paths)
        raise ValueError(f'unknown prior {prior!r}; choose from {", ".join(PRIORS)}')

    def to_dict(self) -> dict:
        """Return the bound as a JSON-ready record."""
        return {**asdict(self), 'box_shares': list(self.box_shares),
                'generator_shares': list(self.generator_shares)}


def hole_bound(world: FamilyWorld, seed: int, directions: int = DIRECTIONS) -> HoleBound:
    """Return the bounds of a ``plate_hole`` world from its parameters and start."""
    if world.family != FAMILY:
        raise ValueError(f'the bounds are of {FAMILY} worlds, not {world.family or "this"}')
    p = world.params
    axes = np.array(p['axes'])
    half, radius = np.array(p['half_size']), float(p['hole_radius'])
    hole = np.array(p['hole_center'])
    normal = axes['xyz'.index(p['plate_side'][1])]      # the plate's side: '+x' ... '-z'
    normal = normal / np.linalg.norm(normal)
    # the discs' own normal and centre, exact where the parameters are rounded
    ring = min((o for o in world.obstacles if o.kind == 'disc' and o.normal is not None
                and abs(float(o.normal @ normal)) > 0.999),
               key=lambda o: float(np.linalg.norm(o.center - hole)))
    normal = ring.normal / np.linalg.norm(ring.normal)
    hole = hole - float((hole - ring.center) @ normal) * normal
    discs = plate_discs(world, ring.center, normal)
    opening = open_area(hole, radius, normal, discs)
    start = world.arm.fk(world.start).positions[0]
    return HoleBound(seed, radius, opening, float(np.linalg.norm(hole - start)),
                     direction_share(start, hole, radius, normal, discs, directions),
                     tuple(side_shares(half, radius, opening, 2.0)),
                     tuple(side_shares(half, radius, opening, 2.0 * HOLE_SPREAD)),
                     centre_first_paths(world, discs),
                     learned_box_paths(world, radius, seed))


def world_bound(seed: int) -> HoleBound:
    """Return the bounds of the ``plate_hole`` world of ``seed``."""
    return hole_bound(random_family_world(FAMILY, seed), seed)


def mean_curves(bounds: list[HoleBound], paths: int) -> dict[str, list[float]]:
    """Return each searcher's share of the worlds out within 1..paths, averaged."""
    return {prior: np.mean([b.curve(prior, paths) for b in bounds], axis=0).tolist()
            for prior in PRIORS}


def mean_paths(bounds: list[HoleBound], prior: str, paths: int) -> float:
    """Return the searcher's mean paths over the worlds it gets out of, as a report counts."""
    found = total = 0.0
    for b in bounds:
        curve = np.concatenate([[0.0], b.curve(prior, paths)])
        steps = np.diff(curve)
        found += float(steps.sum())
        total += float(steps @ np.arange(1, paths + 1))
    return total / found if found else math.nan


def method_curves(records: list[dict], seeds: list[int], paths: int
                  ) -> dict[str, dict]:
    """
    Return each method's share of the worlds out within 1..paths, on exactly these seeds.

    ``records`` are sweep episodes; methods without an episode on every seed are left out
    with a warning, as are episodes allowed another number of paths; a method's episode on
    one world twice is refused (ValueError).  Per method: ``within`` (the curve) and
    ``mean_paths`` (of the worlds it got out of).
    """
    by_method: dict[str, dict[int, dict]] = {}
    for r in records:
        if r.get('family') == FAMILY and r.get('world_seed') in seeds:
            if r.get('max_paths', paths) != paths:
                warnings.warn(f'{r["method"]} on world {r["world_seed"]} was allowed '
                              f'{r["max_paths"]} paths, not {paths}: left out', stacklevel=2)
                continue
            episodes = by_method.setdefault(r['method'], {})
            if r['world_seed'] in episodes:
                raise ValueError(f'{r["method"]} on plate_hole world {r["world_seed"]} twice')
            episodes[r['world_seed']] = r
    curves = {}
    for method, episodes in sorted(by_method.items()):
        if len(episodes) < len(seeds):
            warnings.warn(f'{method}: episodes on {len(episodes)} of the {len(seeds)} worlds: '
                          'left out', stacklevel=2)
            continue
        taken = np.array([e['paths'] if e['success'] else paths + 1 for e in episodes.values()])
        out = taken[taken <= paths]
        curves[method] = {'within': [float(np.mean(taken <= n)) for n in range(1, paths + 1)],
                          'mean_paths': float(out.mean()) if out.size else math.nan}
    return curves


def plot_bounds(bounds_curves: dict[str, list[float]], methods: dict[str, dict],
                worlds: str, out) -> object:
    """Draw the searchers' bounds (dashed) and the methods' success within n paths."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from probdis_ros.plots import _save

    fig, ax = plt.subplots(figsize=(8.5, 3.6))
    for k, (prior, curve) in enumerate(bounds_curves.items()):
        n = np.arange(1, len(curve) + 1)
        search = prior in ('centre_first', 'learned_box')
        ax.step(n, curve, where='post', ls=':' if search else '--',
                color=('k', '0.45', '0.7', 'tab:purple', 'tab:olive')[k % 5],
                label=LABELS[prior])
    for k, (method, found) in enumerate(methods.items()):
        curve = found['within']
        n = np.arange(1, len(curve) + 1)
        ax.step(n, curve, where='post', color=plt.cm.tab10(k), lw=1.5, label=method)
    ax.axhline(0.9, color='tab:red', lw=0.8, alpha=0.5, label='0.90')
    ax.set_ylim(0, 1.02)
    ax.set_xticks(range(0, len(next(iter(bounds_curves.values()))) + 1, 2))
    ax.set_xlabel('paths')
    ax.set_ylabel('share of worlds out')
    ax.set_title(f'plate_hole, {worlds}: out within n paths', fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.02, 1.0))
    return _save(fig, out)
