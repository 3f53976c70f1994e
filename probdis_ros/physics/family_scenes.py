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
The entanglement families as physical scenes: a family world of a seed, solid in MuJoCo.

:func:`family_scene` turns a kinematic world of :mod:`probdis_ros.sim.families` into a
:class:`~probdis_ros.physics.scene.Scene` with the same obstacles, one primitive each, in
the same order (``disc_<i>`` / ``ball_<i>``, i the kinematic index):

* a flat disc (the tiles of walls and plates, the ring around a plate's hole, the strips
  of the hook's bar) becomes a cylinder of the disc's radius, ``THICKNESS`` thick along its
  normal, laid on the far side of the disc's plane from the start's flange point: the object
  meets it where the kinematic point met the disc.  Tiles of one wall overlap as their discs
  do, so walls have no gap and the hole keeps its round rim;
* a ball becomes a sphere of the same centre and radius;
* an orientation-gated obstacle keeps its gate (the start orientation and the world's
  tolerance): solid to the object held as at the start, open to one turned further.  No
  shape of the object does this; it is the kinematic worlds' rule carried into the
  simulation (:mod:`probdis_ros.physics.arm`).  Rigid walls that yield to a turn would be
  slotted walls and a shaped object: a new design of the families, not a conversion.

The kinematic worlds model the flange point alone; the arm's links reach through the walls
of a box to the flange inside.  So the scene is ``object_only``: the obstacles touch the
grasped object, a ball of ``OBJECT_RADIUS`` at the flange point, and the links pass through
them (with the links solid, all 25 starts of seeds 0-4 of the five families collide).

The object has a size and the kinematic point none: an obstacle that the start's flange
point clears by less than ``OBJECT_RADIUS + CLEARANCE`` (in ``clutter`` an item may graze
it; a disc's plane may pass within millimetres) is made to clear it: a ball shrinks, a disc
moves back along its normal, by the shortfall; the scene's description counts them.

The arm's goal keeps the planner node's ``joint_margin`` (``ROBOT_JOINT_MARGIN``) from
every joint limit, as the node requires of a goal (:func:`probdis_ros.run.goal_problem`: an
arm in joint impedance overshoots its goal as it comes to rest): a world's goal nearer to a
limit (13 of the 100 worlds of seeds 8000-8019; the kinematic worlds' goals are drawn
anywhere within the limits) is moved in to the margin, by at most 0.035 rad on a joint; the
scene's description says so (naming the joint moved most), and a move that is not free of
the obstacles and the table raises ValueError.

Scenes are named as the worlds, ``<family>-seed<S>``; :func:`load_scene` draws such a name
when no file of that name exists, so ``--scene closed_box-seed3`` works wherever a scene does.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np
from probdis_ros.physics.scene import Gate, GraspedObject, Primitive, Scene, SceneObstacle
from probdis_ros.planning.prob_rrt import ROBOT_JOINT_MARGIN

if TYPE_CHECKING:
    from probdis_ros.sim.families import FamilyWorld
    from probdis_ros.sim.obstacles import Obstacle

#: A flat disc becomes a cylinder this thick [m].
THICKNESS = 0.01
#: The grasped object: a ball of this radius at the flange point [m] (the kinematic point).
OBJECT_RADIUS = 0.005
#: Its mass [kg] (the shipped scenes' objects weigh as much).
OBJECT_MASS = 0.4
#: Space the object keeps from every obstacle at the start [m].
CLEARANCE = 0.002

_NAME = re.compile(r'^(?P<family>[a-z_]+)-seed(?P<seed>\d+)$')


def family_scene_name(family: str, seed: int) -> str:
    """Return the name of a family world's scene (the kinematic world's own name)."""
    return f'{family}-seed{seed}'


def parse_family_scene(name: object) -> tuple[str, int] | None:
    """Return (family, seed) of a name like ``closed_box-seed3``, or None."""
    from probdis_ros.sim.families import FAMILIES

    match = _NAME.match(str(name))
    if match is None or match['family'] not in FAMILIES:
        return None
    return match['family'], int(match['seed'])


def _frame(normal: np.ndarray) -> np.ndarray:
    """Return a rotation whose z axis is normal."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, normal)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(normal, x), normal])


def _disc_clearance(center: np.ndarray, normal: np.ndarray, radius: float,
                    point: np.ndarray) -> tuple[float, float]:
    """Return the distance of point from a flat disc, and its signed height over the plane."""
    rel = point - center
    height = float(rel @ normal)
    radial = float(np.linalg.norm(rel - height * normal))
    if radial <= radius:
        return abs(height), height
    return float(np.hypot(height, radial - radius)), height


def convert_obstacle(obstacle: Obstacle, index: int, flange: np.ndarray,
                     tolerance: float) -> tuple[SceneObstacle, bool]:
    """Return the scene obstacle of one kinematic obstacle, and whether it was made to clear."""
    need = OBJECT_RADIUS + CLEARANCE
    gate = None if obstacle.orientation is None else Gate(obstacle.orientation, tolerance)
    if obstacle.kind == 'ball':
        distance = float(np.linalg.norm(obstacle.center - flange))
        radius = min(obstacle.radius, distance - need)
        shape = Primitive('sphere', (radius,), obstacle.center.copy(), name=f'ball_{index}')
        return SceneObstacle(shape, gate=gate), radius < obstacle.radius
    clear, height = _disc_clearance(obstacle.center, obstacle.normal, obstacle.radius, flange)
    away = -1.0 if height >= 0 else 1.0          # the side of the plane without the flange
    shift = THICKNESS / 2 + max(0.0, need - clear)
    shape = Primitive('cylinder', (obstacle.radius, THICKNESS),
                      obstacle.center + away * shift * obstacle.normal,
                      _frame(obstacle.normal), name=f'disc_{index}')
    return SceneObstacle(shape, gate=gate), clear < need


def family_scene(world: FamilyWorld) -> Scene:
    """Return the physical scene of a family world, its obstacles in the world's order."""
    flange = world.arm.fk(world.start).positions[0]
    converted = [convert_obstacle(o, i, flange, world.orientation_tolerance)
                 for i, o in enumerate(world.obstacles)]
    moved = sum(m for _, m in converted)
    gated = sum(o.orientation is not None for o in world.obstacles)
    description = (f'entanglement family world {world.name}: {len(converted)} obstacles '
                   f'({gated} gated, tolerance {world.orientation_tolerance:.3f}); '
                   f'{moved} made to clear the object at the start')
    arm = world.arm
    goal = np.clip(world.goal, arm.lower + ROBOT_JOINT_MARGIN, arm.upper - ROBOT_JOINT_MARGIN)
    if not np.array_equal(goal, world.goal):
        # the world was certified solvable to its own goal: the move in must be free too
        if not (arm.above_table(goal)[0] and
                world.compliant_arm().path_is_free(np.array([world.goal, goal]))):
            raise ValueError(f'{world.name}: its goal moved in to the joint margin is not '
                             f'free (of the obstacles or the table)')
        j = int(np.argmax(np.abs(goal - world.goal)))
        description += (f'; goal moved {abs(goal[j] - world.goal[j]):.4f} rad in from '
                        f"{arm.joint_names[j]}'s limit, to the planner node's joint_margin")
    grasped = GraspedObject((Primitive('sphere', (OBJECT_RADIUS,), np.zeros(3),
                                       name='object'),), OBJECT_MASS)
    return Scene(world.name, world.start.copy(), goal,
                 tuple(o for o, _ in converted), grasped, description,
                 object_only=True)


def draw_family_scene(family: str, seed: int) -> Scene:
    """Draw the family world of a seed (as the sweeps do) and return its physical scene."""
    from probdis_ros.sim.families import random_family_world

    return family_scene(random_family_world(family, seed))
