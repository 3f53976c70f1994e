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
Worlds of hidden obstacles: the paper's three settings, random from a seed or from YAML.

A world is a setting ('2d', '3d', '3d-orient'), a start and a goal configuration, and the
obstacles.  Random worlds put the start "entangled" among obstacles (one of them blocks the
straight joint-space move to the goal) and the goal outside them, and are kept only if a
planner that sees the obstacles (:mod:`probdis_ros.sim.oracle`) finds a way out; the number
of rejected draws is reported.

Scenario files (YAML; README "Scenario files")::

    setting: 2d                      # 2d | 3d | 3d-orient
    start: [q1, ..., q7]             # rad
    goal: [q1, ..., q7]
    orientation_tolerance: 0.5       # 3d-orient: D_ORIENT below which an obstacle blocks
    table: {height: 0.0, clearance: 0.05}   # 3d, 3d-orient, optional: the arm stands on it
    obstacles:
      - {type: disc, center: [x, y], radius: r}                          # 2d
      - {type: ball, center: [x, y, z], radius: r}                       # 3d
      - {type: disc, center: [x, y, z], radius: r, normal: [nx, ny, nz]} # 3d, flat
      - {..., orientation: [w, x, y, z]}   # 3d-orient: blocks only similar orientations
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from probdis_ros.model import arm_for_setting, SETTINGS
from probdis_ros.model.arms import Arm
from probdis_ros.model.table import Table
from probdis_ros.planning.seeds import stream, WORLD
from probdis_ros.sim.compliant_arm import CompliantArm, densify
from probdis_ros.sim.obstacles import Obstacle
from probdis_ros.sim.oracle import find_free_path
import yaml


class ScenarioError(ValueError):
    """A scenario file that cannot be used, with the reason."""


@dataclass
class World:
    """Start, goal and hidden obstacles of one disentangling problem."""

    setting: str
    start: np.ndarray
    goal: np.ndarray
    obstacles: list[Obstacle]
    orientation_tolerance: float = 0.5
    name: str = ''
    rejected_draws: int = 0
    #: the table the arm stands on (the planner keeps the arm above it); None: none
    table: Table | None = None
    arm: Arm = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Check the world against its arm."""
        if self.setting not in SETTINGS:
            raise ScenarioError(f'setting must be one of {", ".join(SETTINGS)}, '
                                f'got {self.setting!r}')
        self.arm = arm_for_setting(self.setting)
        if self.table is not None:
            if self.setting == '2d':
                raise ScenarioError('a table needs the iiwa (3d, 3d-orient), not the 2d arm')
            self.arm = self.arm.on_table(self.table)
        for name in ('start', 'goal'):
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if value.shape != (self.arm.n_joints,) or not np.all(np.isfinite(value)):
                raise ScenarioError(f'{name} must be {self.arm.n_joints} finite joint values')
            outside = self.arm.limit_problem(value)
            if outside:
                raise ScenarioError(f'{name} is outside the joint limits of the '
                                    f'{self.arm.name} arm: {outside}')
            problem = self.arm.table_problem(value)
            if problem:
                raise ScenarioError(f'{name} {problem}')
            setattr(self, name, value)
        dim = self.arm.task_space.dim
        for i, obstacle in enumerate(self.obstacles):
            if obstacle.dim != dim:
                raise ScenarioError(f'obstacle {i} is {obstacle.dim}-D in a {dim}-D setting')

    def compliant_arm(self, check_step: float | None = None) -> CompliantArm:
        """Return the simulated arm that executes paths in this world."""
        kwargs = {} if check_step is None else {'check_step': check_step}
        return CompliantArm(self.arm, self.obstacles, self.orientation_tolerance, **kwargs)

    def to_dict(self) -> dict:
        """Return the world as a scenario document."""
        doc = {'setting': self.setting, 'start': self.start.tolist(),
               'goal': self.goal.tolist(), 'orientation_tolerance': self.orientation_tolerance,
               'obstacles': [o.to_dict() for o in self.obstacles]}
        if self.table is not None:
            doc['table'] = {'height': self.table.height, 'clearance': self.table.clearance}
        if self.name:
            doc = {'name': self.name, **doc}
        return doc

    def save(self, path: str | Path) -> None:
        """Write the world as a scenario file."""
        Path(path).write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))


def load_world(path: str | Path) -> World:
    """Read a scenario file; any problem raises ScenarioError naming the file."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except OSError as err:
        raise ScenarioError(f'cannot read scenario {path}: {err.strerror}') from None
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise ScenarioError(f'{path}: not valid YAML: {err}') from None
    try:
        return world_from_dict(doc)
    except ScenarioError as err:
        raise ScenarioError(f'{path}: {err}') from None


def world_from_dict(doc: object) -> World:
    """Build a world from a scenario document."""
    if not isinstance(doc, dict):
        raise ScenarioError('a scenario is a mapping with setting, start, goal, obstacles')
    missing = [k for k in ('setting', 'start', 'goal', 'obstacles') if k not in doc]
    if missing:
        raise ScenarioError(f'missing {", ".join(missing)}')
    if not isinstance(doc['obstacles'], list):
        raise ScenarioError('obstacles must be a list')
    obstacles = []
    for i, entry in enumerate(doc['obstacles']):
        if not isinstance(entry, dict):
            raise ScenarioError(f'obstacle {i} must be a mapping')
        unknown = set(entry) - {'type', 'center', 'radius', 'normal', 'orientation'}
        if unknown:
            raise ScenarioError(f'obstacle {i}: unknown keys {", ".join(sorted(unknown))}')
        try:
            obstacles.append(Obstacle(entry.get('type'), entry.get('center'),
                                      float(entry.get('radius', 'nan')), entry.get('normal'),
                                      entry.get('orientation')))
        except (TypeError, ValueError) as err:
            raise ScenarioError(f'obstacle {i}: {err}') from None
    try:
        table = doc.get('table')
        if table is not None:
            if not isinstance(table, dict) or set(table) - {'height', 'clearance'}:
                raise ScenarioError('table must be a mapping of height and clearance [m]')
            table = Table(**{k: float(v) for k, v in table.items()})
        return World(str(doc['setting']), doc['start'], doc['goal'], obstacles,
                     float(doc.get('orientation_tolerance', 0.5)), str(doc.get('name', '')),
                     table=table)
    except (TypeError, ValueError) as err:
        raise ScenarioError(str(err)) from None


# -- random worlds ---------------------------------------------------------------------------

@dataclass(frozen=True)
class WorldSpec:
    """How a setting's random worlds are drawn (lengths in metres)."""

    cluster_radius: float     # obstacles are centred within this distance of the start point
    radius: tuple[float, float]
    min_move: float           # start and goal end-effector points are at least this far apart
    max_move: float


SPECS = {
    '2d': WorldSpec(cluster_radius=0.22, radius=(0.015, 0.04), min_move=0.25, max_move=0.45),
    '3d': WorldSpec(cluster_radius=0.25, radius=(0.03, 0.07), min_move=0.3, max_move=0.5),
    '3d-orient': WorldSpec(cluster_radius=0.25, radius=(0.03, 0.07), min_move=0.3,
                           max_move=0.5),
}


def _reachable_start(arm: Arm, rng: np.random.Generator, setting: str) -> np.ndarray:
    while True:
        q = arm.random_configurations(rng, 1)[0]
        x = arm.fk(q).positions[0]
        if setting == '2d' and 0.3 <= np.linalg.norm(x) <= 0.6:
            return q
        if setting != '2d' and 0.2 <= x[2] <= 0.6 and 0.35 <= np.hypot(x[0], x[1]) <= 0.7:
            return q


def _goal_for(arm: Arm, start: np.ndarray, rng: np.random.Generator, spec: WorldSpec,
              setting: str) -> np.ndarray:
    x_start = arm.fk(start).positions[0]
    while True:
        q = np.clip(start + rng.normal(scale=0.6, size=len(start)), arm.lower, arm.upper)
        x = arm.fk(q).positions[0]
        move = np.linalg.norm(x - x_start)
        if spec.min_move <= move <= spec.max_move and (setting == '2d' or x[2] > x_start[2]):
            return q


def _random_obstacle(rng: np.random.Generator, center: np.ndarray, spec: WorldSpec,
                     setting: str, orientation: np.ndarray | None = None,
                     normal: np.ndarray | None = None) -> Obstacle:
    radius = rng.uniform(*spec.radius)
    if setting == '2d':
        return Obstacle('disc', center, radius)
    quat = None
    if setting == '3d-orient':
        quat = orientation if orientation is not None else rng.normal(size=4)
    if rng.random() < 0.5:
        return Obstacle('ball', center, radius, orientation=quat)
    normal = normal if normal is not None else rng.normal(size=3)
    return Obstacle('disc', center, radius, normal=normal, orientation=quat)


def random_world(setting: str, n_obstacles: int, seed: int, max_draws: int = 200,
                 oracle_iterations: int = 1500) -> World:
    """
    Draw a solvable, entangled world of a setting from a seed (reproducibly).

    The world draws from the seed's WORLD stream (:mod:`probdis_ros.planning.seeds`), so a
    planner given the same seed draws independently of it.
    Raises RuntimeError if max_draws draws in a row are rejected.
    """
    if n_obstacles < 1:
        raise ValueError('a world needs at least one obstacle')
    arm = arm_for_setting(setting)
    spec = SPECS[setting]
    rng = stream(seed, WORLD)
    for draw in range(max_draws):
        start = _reachable_start(arm, rng, setting)
        goal = _goal_for(arm, start, rng, spec, setting)
        world = World(setting, start, goal, [], name=f'{setting}-{n_obstacles}-seed{seed}')
        pose = arm.fk(np.array([start, goal]))
        x_start, x_goal = pose.positions
        # the first obstacle sits on the straight move's end-effector trace: entangled
        dense, _ = densify(np.array([start, goal]), 0.01)
        trace = arm.fk(dense)
        dist = np.linalg.norm(trace.positions - x_start, axis=1)
        ahead = int(np.argmax(dist > spec.radius[1] + 0.02))
        motion = trace.positions[min(ahead + 1, len(dense) - 1)] - trace.positions[ahead]
        q_start = None if pose.orientations is None else pose.orientations[0]
        first = _random_obstacle(rng, trace.positions[ahead], spec, setting,
                                 orientation=q_start, normal=motion)
        obstacles = [first]
        while len(obstacles) < n_obstacles:
            offset = rng.normal(size=len(x_start))
            offset *= spec.cluster_radius * rng.random() ** (1 / len(x_start)) / \
                np.linalg.norm(offset)
            obstacle = _random_obstacle(rng, x_start + offset, spec, setting)
            if not obstacle.contains(np.array([x_start, x_goal])).any():
                obstacles.append(obstacle)
        world.obstacles = obstacles
        world.rejected_draws = draw
        sim = world.compliant_arm()
        if sim.collides(start) or sim.collides(goal) or sim.path_is_free(np.array([start, goal])):
            continue
        if find_free_path(sim, start, goal, rng, oracle_iterations) is not None:
            return world
    raise RuntimeError(f'no solvable {setting} world with {n_obstacles} obstacles in '
                       f'{max_draws} draws (seed {seed})')
