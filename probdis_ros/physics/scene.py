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
Physical scenes: solid obstacles, the grasped object and the arm's start and goal.

A scene is what the physics-simulated iiwa (:mod:`probdis_ros.physics.arm`) moves in.  Unlike
the kinematic scenarios (config/scenarios/), whose obstacles block a point, a scene has
shapes with volume that the arm and the object collide with, and clutter that yields.

Scene files (YAML; README "Scene files"), all lengths in metres, angles in radians, poses in
the base frame ``lbr_link_0`` (the world) unless said otherwise::

    name: demo_hook                  # optional; default: the file's stem
    description: text                # optional
    start: [q1, ..., q7]             # rad, inside the joint limits
    goal: [q1, ..., q7]
    object:                          # the grasped object, welded to the flange lbr_link_ee
      mass: 0.5                      # kg, > 0, spread over the shapes by volume
      shapes:                        # primitives posed in the flange frame
        - {type: capsule, radius: 0.012, length: 0.2, position: [0, 0, 0.1]}
    obstacles:                       # primitives posed in the base frame
        - {type: box, size: [0.4, 0.03, 0.03], position: [0.6, 0, 0.5], rpy: [0, 0, 0.3]}
        - {type: cylinder, radius: 0.02, length: 0.3, position: [...], quaternion: [w, x, y, z]}
        - {type: sphere, radius: 0.05, position: [...],
           hinge: {point: [x, y, z], axis: [ax, ay, az], stiffness: 5.0, damping: 0.2},
           mass: 0.3}
        - {type: box, size: [0.2, 0.2, 0.01], position: [...],
           gate: {orientation: [w, x, y, z], tolerance: 0.4}}
    object_only: false               # optional; true: obstacles touch the object alone

Primitives: ``box`` (``size``: full edge lengths x, y, z), ``capsule`` and ``cylinder``
(``radius``, ``length`` along the local z axis; a capsule's length is between the centres of
its end caps), ``sphere`` (``radius``).  Orientation: ``rpy`` (URDF convention, fixed axes x,
y, z) or ``quaternion`` (w, x, y, z), not both; neither means unrotated.  An obstacle is rigid
unless it has a ``hinge``: then it turns about the axis through ``point`` (base frame) on a
torsional spring of ``stiffness`` Nm/rad (rest: its pose in the file) with ``damping``
Nms/rad, so clutter gives way to a push; its own weight is carried by the hinge (it does not
sag) and ``mass`` (kg, default 0.3) sets its inertia.  With a ``gate`` an obstacle is solid
only to an object held like ``orientation`` (the flange quaternion, w x y z): while
``D_ORIENT = (2 / pi) arccos(|q_flange . orientation|)`` is below ``tolerance``; to an object
turned further it is open (the kinematic worlds' orientation-gated obstacles, carried over
as a rule of the simulation, not as a shape: :mod:`probdis_ros.physics.family_scenes`).
``object_only: true`` lets the arm's links pass through every obstacle, so that only the
grasped object touches the scene (the kinematic worlds model the flange alone).  An
optional ``name`` on a primitive names it in contacts.  Any problem raises
:class:`SceneError` naming the file and the entry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

#: Primitive types and the size keys each needs.
PRIMITIVES = {'box': ('size',), 'capsule': ('radius', 'length'),
              'cylinder': ('radius', 'length'), 'sphere': ('radius',)}
DEFAULT_HINGED_MASS = 0.3
_POSE_KEYS = {'type', 'name', 'position', 'rpy', 'quaternion', 'size', 'radius', 'length'}
_TOP_KEYS = {'name', 'description', 'start', 'goal', 'object', 'obstacles', 'object_only'}


class SceneError(ValueError):
    """A scene file that cannot be used; the message names the file and the entry."""


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """Rotation of URDF roll-pitch-yaw (fixed axes x, y, z): ``Rz(y) Ry(p) Rx(r)``."""
    r, p, y = np.asarray(rpy, dtype=float)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def quaternion_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation of a unit quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(quat, dtype=float)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@dataclass(frozen=True)
class Primitive:
    """
    One solid shape and its pose in its parent frame.

    ``size`` is as in the file: box ``(x, y, z)`` full edges, capsule and cylinder
    ``(radius, length)``, sphere ``(radius,)``.
    """

    kind: str
    size: tuple[float, ...]
    position: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    name: str = ''

    @property
    def extent(self) -> float:
        """Return the radius [m] of a ball about the shape's center that holds it."""
        if self.kind == 'box':
            return float(np.linalg.norm(self.size)) / 2
        if self.kind == 'sphere':
            return self.size[0]
        radius, length = self.size
        if self.kind == 'capsule':
            return length / 2 + radius
        return float(np.hypot(length / 2, radius))

    @property
    def volume(self) -> float:
        """Return the shape's volume in m^3 (spreads an object's mass over its shapes)."""
        if self.kind == 'box':
            return float(np.prod(self.size))
        if self.kind == 'sphere':
            return 4.0 / 3.0 * np.pi * self.size[0] ** 3
        radius, length = self.size
        cylinder = np.pi * radius ** 2 * length
        return cylinder + (4.0 / 3.0 * np.pi * radius ** 3 if self.kind == 'capsule' else 0.0)


@dataclass(frozen=True)
class Hinge:
    """A torsional spring that lets an obstacle turn about an axis through a point."""

    point: np.ndarray
    axis: np.ndarray
    stiffness: float
    damping: float


@dataclass(frozen=True)
class Gate:
    """An obstacle solid only to an object held within ``tolerance`` (D_ORIENT) of this."""

    orientation: np.ndarray      # unit quaternion (w, x, y, z) of the flange
    tolerance: float

    def solid(self, quat: np.ndarray) -> bool:
        """Tell whether the obstacle blocks an object held at flange quaternion quat."""
        dot = min(1.0, abs(float(np.dot(quat, self.orientation))))
        return (2.0 / np.pi) * float(np.arccos(dot)) < self.tolerance


@dataclass(frozen=True)
class SceneObstacle:
    """A primitive in the base frame, rigid (hinge None) or on a spring hinge; maybe gated."""

    shape: Primitive
    hinge: Hinge | None = None
    mass: float = DEFAULT_HINGED_MASS
    gate: Gate | None = None


@dataclass(frozen=True)
class GraspedObject:
    """The object in the gripper: primitives in the flange frame and its real mass."""

    shapes: tuple[Primitive, ...]
    mass: float

    @property
    def reach(self) -> float:
        """Return the radius [m] of a ball about the flange point that holds every shape."""
        return max((float(np.linalg.norm(s.position)) + s.extent for s in self.shapes),
                   default=0.0)


@dataclass(frozen=True)
class Scene:
    """Obstacles, grasped object, start and goal configuration of one physical problem."""

    name: str
    start: np.ndarray
    goal: np.ndarray
    obstacles: tuple[SceneObstacle, ...] = ()
    grasped: GraspedObject | None = None
    description: str = ''
    source: str = ''
    object_only: bool = False

    @property
    def object_reach(self) -> float:
        """Return the reach [m] of the grasped object about the flange point (0: none)."""
        return self.grasped.reach if self.grasped is not None else 0.0


# -- parsing ---------------------------------------------------------------------------------


def _numbers(value: object, n: int, what: str, positive: bool = False) -> np.ndarray:
    """Return value as n finite floats (positive if asked) or raise SceneError saying what."""
    kind = 'positive numbers' if positive else 'numbers'
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        arr = None
    if (value is None or isinstance(value, (str, bytes, bool)) or arr is None
            or arr.shape != (n,) or not np.all(np.isfinite(arr))
            or (positive and not np.all(arr > 0))):
        raise SceneError(f'{what} of {n} {kind}' if n > 1 else f'{what} a {kind[:-1]}')
    return arr


def _scalar(entry: dict, key: str, what: str, default: float | None = None,
            minimum: float = 0.0, strict: bool = True) -> float:
    if key not in entry and default is not None:
        return float(default)
    value = _numbers(entry.get(key), 1, f'{what} needs {key} as', positive=False)[0]
    if value < minimum or (strict and value == minimum):
        bound = 'positive' if strict and minimum == 0 else f'at least {minimum:g}'
        raise SceneError(f'{what} needs {key} {bound}, got {value:g}')
    return float(value)


def _rotation(entry: dict, kind: str) -> np.ndarray:
    if 'rpy' in entry and 'quaternion' in entry:
        raise SceneError(f'{kind}: give rpy or quaternion, not both')
    if 'rpy' in entry:
        return rpy_to_matrix(_numbers(entry['rpy'], 3, f'{kind} needs rpy'))
    if 'quaternion' in entry:
        quat = _numbers(entry['quaternion'], 4, f'{kind} needs quaternion (w, x, y, z)')
        norm = float(np.linalg.norm(quat))
        if norm < 1e-9:
            raise SceneError(f'{kind}: quaternion must not be zero')
        return quaternion_to_matrix(quat / norm)
    return np.eye(3)


def _primitive(entry: object, extra_keys: set[str] = frozenset()) -> Primitive:
    """Parse one primitive entry (errors without the entry's place, the caller adds it)."""
    if not isinstance(entry, dict):
        raise SceneError('must be a mapping with type, position and size')
    kind = entry.get('type')
    if kind not in PRIMITIVES:
        raise SceneError(f'type must be one of {", ".join(PRIMITIVES)}, got {kind!r}')
    unknown = set(entry) - _POSE_KEYS - extra_keys
    if unknown:
        raise SceneError(f'{kind}: unknown keys {", ".join(sorted(map(str, unknown)))}')
    for key in set(_POSE_KEYS) - {'type', 'name', 'position', 'rpy', 'quaternion'}:
        if key in entry and key not in PRIMITIVES[kind]:
            raise SceneError(f'{kind} takes no {key} (it needs {", ".join(PRIMITIVES[kind])})')
    if kind == 'box':
        size = tuple(_numbers(entry.get('size'), 3, 'box needs size', positive=True))
    elif kind == 'sphere':
        size = (_scalar(entry, 'radius', kind),)
    else:
        size = (_scalar(entry, 'radius', kind), _scalar(entry, 'length', kind))
    position = _numbers(entry.get('position'), 3, f'{kind} needs position')
    return Primitive(kind, tuple(float(s) for s in size), position, _rotation(entry, kind),
                     str(entry.get('name', '')))


def _check_mapping(entry: object, what: str, keys: set[str], message: str) -> None:
    """Refuse an entry that is not a mapping (with message) or has keys other than keys."""
    if not isinstance(entry, dict):
        raise SceneError(message)
    unknown = set(entry) - keys
    if unknown:
        raise SceneError(f'{what}: unknown keys {", ".join(sorted(map(str, unknown)))}')


def _hinge(entry: object) -> Hinge:
    _check_mapping(entry, 'hinge', {'point', 'axis', 'stiffness', 'damping'},
                   'hinge must be a mapping with point, axis, stiffness, damping')
    point = _numbers(entry.get('point'), 3, 'hinge needs point')
    axis = _numbers(entry.get('axis'), 3, 'hinge needs axis')
    if np.linalg.norm(axis) < 1e-9:
        raise SceneError('hinge: axis must not be zero')
    return Hinge(point, axis / np.linalg.norm(axis), _scalar(entry, 'stiffness', 'hinge'),
                 _scalar(entry, 'damping', 'hinge', minimum=0.0, strict=False))


def _gate(entry: object) -> Gate:
    _check_mapping(entry, 'gate', {'orientation', 'tolerance'},
                   'gate must be a mapping with orientation and tolerance')
    quat = _numbers(entry.get('orientation'), 4, 'gate needs orientation (w, x, y, z)')
    if np.linalg.norm(quat) < 1e-9:
        raise SceneError('gate: orientation must not be zero')
    tolerance = _scalar(entry, 'tolerance', 'gate')
    if tolerance > 1:
        raise SceneError(f'gate needs tolerance at most 1 (D_ORIENT), got {tolerance:g}')
    return Gate(quat / np.linalg.norm(quat), tolerance)


def _obstacle(entry: object) -> SceneObstacle:
    shape = _primitive(entry, {'hinge', 'mass', 'gate'})
    assert isinstance(entry, dict)
    gate = _gate(entry['gate']) if 'gate' in entry else None
    if 'hinge' not in entry:
        if 'mass' in entry:
            raise SceneError(f'{shape.kind}: mass is only for an obstacle with a hinge')
        return SceneObstacle(shape, gate=gate)
    return SceneObstacle(shape, _hinge(entry['hinge']),
                         _scalar(entry, 'mass', shape.kind, default=DEFAULT_HINGED_MASS), gate)


def _grasped(entry: object) -> GraspedObject:
    _check_mapping(entry, 'object', {'mass', 'shapes'},
                   'object must be a mapping with mass and shapes')
    mass = _scalar(entry, 'mass', 'object')
    shapes = entry.get('shapes')
    if not isinstance(shapes, list) or not shapes:
        raise SceneError('object needs shapes, a non-empty list of primitives')
    parsed = []
    for i, shape in enumerate(shapes):
        try:
            parsed.append(_primitive(shape))
        except SceneError as err:
            raise SceneError(f'object.shapes[{i}]: {err}') from None
    return GraspedObject(tuple(parsed), mass)


def _configuration(doc: dict, key: str) -> np.ndarray:
    from probdis_ros.model import iiwa_arm

    arm = iiwa_arm()
    if key not in doc:
        raise SceneError(f'missing {key} (7 joint values in rad)')
    q = _numbers(doc[key], arm.n_joints, f'{key}: needs a list')
    if not arm.within_limits(q)[0]:
        outside = [arm.joint_names[j] for j in range(arm.n_joints)
                   if not arm.lower[j] <= q[j] <= arm.upper[j]]
        raise SceneError(f'{key}: outside the joint limits at {", ".join(outside)}')
    return q


def scene_from_dict(doc: object, name: str = '', source: str = '') -> Scene:
    """Build a scene from a scene document; problems raise SceneError naming the entry."""
    if not isinstance(doc, dict):
        raise SceneError('a scene is a mapping with start, goal, object and obstacles')
    unknown = set(doc) - _TOP_KEYS
    if unknown:
        raise SceneError(f'unknown keys {", ".join(sorted(map(str, unknown)))}')
    start, goal = _configuration(doc, 'start'), _configuration(doc, 'goal')
    grasped = None
    if doc.get('object') is not None:
        grasped = _grasped(doc['object'])
    entries = doc.get('obstacles', [])
    if not isinstance(entries, list):
        raise SceneError('obstacles must be a list')
    obstacles = []
    for i, entry in enumerate(entries):
        try:
            obstacles.append(_obstacle(entry))
        except SceneError as err:
            raise SceneError(f'obstacles[{i}]: {err}') from None
    object_only = doc.get('object_only', False)
    if not isinstance(object_only, bool):
        raise SceneError(f'object_only must be true or false, got {object_only!r}')
    return Scene(str(doc.get('name', name)), start, goal, tuple(obstacles), grasped,
                 str(doc.get('description', '')), source, object_only)


def scene_path(name: str | Path) -> Path:
    """Return a scene file: a path, or the name of one shipped in config/scenes/."""
    from probdis_ros.resources import config_file

    return config_file(name, 'scenes')


def shipped_scenes() -> list[str]:
    """Return the names of the scenes in config/scenes/."""
    from probdis_ros.resources import share_dir

    return sorted(p.stem for p in (share_dir()[1] / 'config' / 'scenes').glob('*.yaml'))


def load_scene(name: str | Path) -> Scene:
    """
    Read a scene file (a path or a shipped name); any problem raises SceneError.

    A name like ``closed_box-seed3`` that is no file is the entanglement family world of
    that seed, drawn and made physical (:mod:`probdis_ros.physics.family_scenes`).
    """
    path = scene_path(name)
    if not path.exists():
        from probdis_ros.physics.family_scenes import draw_family_scene, parse_family_scene

        family = parse_family_scene(name)
        if family is not None:
            return draw_family_scene(*family)
    try:
        doc = yaml.safe_load(path.read_text())
    except OSError as err:
        raise SceneError(f'cannot read scene {path}: {err.strerror}') from None
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise SceneError(f'{path}: not valid YAML: {err}') from None
    try:
        return scene_from_dict(doc, path.stem, str(path))
    except SceneError as err:
        raise SceneError(f'{path}: {err}') from None
