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
The MuJoCo model of the iiwa in a scene, written as MJCF from the URDF's own numbers.

MuJoCo can load a URDF, but it fuses ``lbr_link_0`` into the world and the flange into
link 7 and drops what it does not know; so the model is generated here from
``urdf/iiwa14.urdf`` (joint origins, axes, limits, efforts, inertials, geometry), one body
per link in the URDF's frames, and the flange pose of the simulation equals the URDF's.

The impedance controller lives in the model, so that many physics steps run in C:

* each joint has a ``general`` actuator ``K ctrl - K q - D qdot`` (ctrl is the setpoint);
  the implicitfast integrator treats ``D`` implicitly, which keeps the light wrist stable;
* gravity compensation is MuJoCo's ``gravcomp`` on every moving body, routed through the
  joints' actuators (``actuatorgravcomp``) so that the total is clipped to the URDF effort
  (``actuatorfrcrange``) like the real drive's torque; on the grasped object it is the
  controller's assumed share of the real mass, which models a load-data error;
* the grasped object is welded to the flange, or (``grasp_stiffness`` > 0) held by three
  damped spring hinges at the flange, so that it turns in the grasp when pressed (its
  weight is compensated at those hinges too: it does not sag).

Collision filter: robot and object geoms (contype 1, conaffinity 0) collide only with scene
geoms (contype 0, conaffinity 1); no self-collision and no clutter-on-clutter contacts.  The
object's geoms also carry contype 2, and a scene with ``object_only`` gives its obstacles
conaffinity 2: they touch the object alone, the arm's links pass through them.  A gated
obstacle's conaffinity is set to 0 while it is open (:mod:`probdis_ros.physics.arm`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path
import xml.etree.ElementTree as ET

import numpy as np
from probdis_ros.physics.scene import Primitive, rpy_to_matrix, Scene
from probdis_ros.physics.settings import PhysicsSettings

FLANGE = 'lbr_link_ee'
OBJECT_BODY = 'grasped_object'
ROBOT_CONTYPE, SCENE_CONAFFINITY = 1, 1
OBJECT_CONTYPE = 2     # the grasped object's own bit, for scenes whose obstacles touch it alone
TABLE = 'table'        # the table top's geom (PhysicsSettings.table_height)


@dataclass(frozen=True)
class UrdfInertial:
    """A link's mass [kg], centre of mass and inertia tensor (3, 3) in the link frame."""

    mass: float
    com: np.ndarray
    rotation: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class UrdfLink:
    """One URDF link: inertial (None if massless) and collision primitives."""

    name: str
    inertial: UrdfInertial | None
    collisions: tuple[Primitive, ...]


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint: origin (child frame in the parent frame), axis and limits."""

    name: str
    kind: str
    parent: str
    child: str
    xyz: np.ndarray
    rotation: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float
    velocity: float
    effort: float


@dataclass(frozen=True)
class UrdfRobot:
    """A serial URDF: links by name and joints from the root outwards."""

    name: str
    links: dict[str, UrdfLink]
    joints: tuple[UrdfJoint, ...]

    @property
    def root(self) -> str:
        """Return the link that is no joint's child."""
        children = {j.child for j in self.joints}
        return next(name for name in self.links if name not in children)

    @property
    def movable(self) -> tuple[UrdfJoint, ...]:
        """Return the revolute joints in chain order."""
        return tuple(j for j in self.joints if j.kind != 'fixed')


def _vec(text: str | None, default: str) -> np.ndarray:
    return np.array([float(v) for v in (text or default).split()])


def _origin(element: ET.Element) -> tuple[np.ndarray, np.ndarray]:
    origin = element.find('origin')
    if origin is None:
        return np.zeros(3), np.eye(3)
    return _vec(origin.get('xyz'), '0 0 0'), rpy_to_matrix(_vec(origin.get('rpy'), '0 0 0'))


def _geometry(element: ET.Element) -> Primitive:
    xyz, rotation = _origin(element)
    geom = element.find('geometry')
    shape = None if geom is None else next(iter(geom), None)
    if shape is None or shape.tag not in ('box', 'cylinder', 'sphere'):
        raise ValueError(f'unsupported URDF geometry {shape.tag if shape is not None else None}')
    if shape.tag == 'box':
        size = tuple(_vec(shape.get('size'), ''))
    elif shape.tag == 'sphere':
        size = (float(shape.get('radius')),)
    else:
        size = (float(shape.get('radius')), float(shape.get('length')))
    return Primitive(shape.tag, size, xyz, rotation)


def _link(element: ET.Element) -> UrdfLink:
    inertial = None
    node = element.find('inertial')
    if node is not None:
        xyz, rotation = _origin(node)
        i = node.find('inertia').attrib
        tensor = np.array([[i['ixx'], i['ixy'], i['ixz']], [i['ixy'], i['iyy'], i['iyz']],
                           [i['ixz'], i['iyz'], i['izz']]], dtype=float)
        inertial = UrdfInertial(float(node.find('mass').get('value')), xyz, rotation, tensor)
    collisions = tuple(_geometry(c) for c in element.findall('collision'))
    return UrdfLink(element.get('name'), inertial, collisions)


def _joint(element: ET.Element) -> UrdfJoint:
    xyz, rotation = _origin(element)
    limit = element.find('limit')
    lim = {} if limit is None else limit.attrib
    axis = element.find('axis')
    return UrdfJoint(element.get('name'), element.get('type'),
                     element.find('parent').get('link'), element.find('child').get('link'),
                     xyz, rotation, _vec(None if axis is None else axis.get('xyz'), '1 0 0'),
                     float(lim.get('lower', 0)), float(lim.get('upper', 0)),
                     float(lim.get('velocity', 0)), float(lim.get('effort', 0)))


def read_urdf(path: str | Path) -> UrdfRobot:
    """Parse a serial-chain URDF of revolute and fixed joints with primitive geometry."""
    root = ET.parse(str(path)).getroot()
    links = {link.name: link for link in map(_link, root.findall('link'))}
    joints = {j.parent: j for j in map(_joint, root.findall('joint'))}
    for j in joints.values():
        if j.kind not in ('revolute', 'fixed'):
            raise ValueError(f'{path}: joint {j.name} is {j.kind}; only revolute and fixed')
    robot = UrdfRobot(root.get('name'), links, ())
    ordered, link = [], robot.root
    while link in joints:
        ordered.append(joints[link])
        link = joints[link].child
    if len(ordered) != len(joints):
        raise ValueError(f'{path}: not a serial chain')
    return UrdfRobot(robot.name, links, tuple(ordered))


@cache
def iiwa_urdf() -> UrdfRobot:
    """Return the package's iiwa URDF (the one the planner's kinematics reads)."""
    from probdis_ros.resources import data_file

    return read_urdf(data_file('urdf', 'iiwa14.urdf'))


# -- MJCF --------------------------------------------------------------------------------------


def _f(values: np.ndarray | tuple | float) -> str:
    """Format numbers for MJCF with full double precision (kinematics must not round)."""
    return ' '.join(repr(float(v)) for v in np.atleast_1d(np.asarray(values, dtype=float)))


def _quat(rotation: np.ndarray) -> str:
    """MJCF quaternion (w, x, y, z) of a rotation matrix."""
    from probdis_ros.model.arms import rotation_to_quaternion

    return _f(rotation_to_quaternion(np.asarray(rotation))[0])


def _geom_attrs(shape: Primitive) -> str:
    """Type, size and pose attributes of a primitive as an MJCF geom."""
    if shape.kind == 'box':
        size = np.asarray(shape.size) / 2.0
    elif shape.kind == 'sphere':
        size = np.asarray(shape.size)
    else:
        size = np.array([shape.size[0], shape.size[1] / 2.0])
    return (f'type="{shape.kind}" size="{_f(size)}" pos="{_f(shape.position)}" '
            f'quat="{_quat(shape.rotation)}"')


def _inertial(inertial: UrdfInertial) -> str:
    tensor = inertial.rotation @ inertial.inertia @ inertial.rotation.T
    full = [tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2], tensor[1, 2]]
    return (f'<inertial pos="{_f(inertial.com)}" mass="{_f(inertial.mass)}" '
            f'fullinertia="{_f(full)}"/>')


def _robot_geoms(link: UrdfLink, rgba: str) -> list[str]:
    return [f'<geom name="{link.name}/collision_{i}" {_geom_attrs(shape)} '
            f'contype="{ROBOT_CONTYPE}" conaffinity="0" rgba="{rgba}"/>'
            for i, shape in enumerate(link.collisions)]


#: The grasp's damping ratio, with stiffness ``PhysicsSettings.grasp_stiffness``.
GRASP_DAMPING_RATIO = 0.7


def _grasp_joints(scene: Scene, stiffness: float) -> list[str]:
    """
    Return three spring hinges at the flange about its axes: the object turns in the grasp.

    Damped at GRASP_DAMPING_RATIO for an inertia of mass x reach^2 / 3 (a rod held at its
    end, about the object's own); none for a rigid grasp (stiffness 0).
    """
    if stiffness <= 0:
        return []
    inertia = scene.grasped.mass * scene.object_reach ** 2 / 3
    damping = 2 * GRASP_DAMPING_RATIO * np.sqrt(stiffness * inertia)
    return [f'  <joint name="grasp_{axis}" type="hinge" axis="{_f(np.eye(3)[i])}" '
            f'stiffness="{_f(stiffness)}" damping="{_f(damping)}"/>'
            for i, axis in enumerate('xyz')]


def _object_body(scene: Scene, gravcomp: float, grasp_stiffness: float) -> list[str]:
    grasped = scene.grasped
    volume = sum(s.volume for s in grasped.shapes)
    lines = [f'<body name="{OBJECT_BODY}" gravcomp="{_f(gravcomp)}">',
             *_grasp_joints(scene, grasp_stiffness)]
    for i, shape in enumerate(grasped.shapes):
        name = shape.name or f'object/{i}'
        lines.append(f'  <geom name="{name}" {_geom_attrs(shape)} '
                     f'mass="{_f(grasped.mass * shape.volume / volume)}" '
                     f'contype="{ROBOT_CONTYPE | OBJECT_CONTYPE}" conaffinity="0" '
                     'rgba="0.2 0.4 0.9 1"/>')
    lines.append('</body>')
    return lines


def obstacle_name(scene: Scene, index: int) -> str:
    """Return the geom name of a scene obstacle: its own name or ``obstacles[i]``."""
    return scene.obstacles[index].shape.name or f'obstacles[{index}]'


def _scene_bodies(scene: Scene, settings: PhysicsSettings) -> list[str]:
    lines = []
    affinity = OBJECT_CONTYPE if scene.object_only else SCENE_CONAFFINITY
    for i, obstacle in enumerate(scene.obstacles):
        shape, name = obstacle.shape, obstacle_name(scene, i)
        geom = (f'{_geom_attrs(Primitive(shape.kind, shape.size, np.zeros(3)))} '
                f'contype="0" conaffinity="{affinity}" '
                f'friction="{_f(settings.friction)} 0.005 0.0001"')
        if obstacle.hinge is None:
            lines.append(f'<body name="{name}" pos="{_f(shape.position)}" '
                         f'quat="{_quat(shape.rotation)}">')
            lines.append(f'  <geom name="{name}" {geom} rgba="0.6 0.6 0.6 1"/>')
        else:
            hinge, to_local = obstacle.hinge, shape.rotation.T
            lines.append(f'<body name="{name}" pos="{_f(shape.position)}" '
                         f'quat="{_quat(shape.rotation)}" gravcomp="1">')
            lines.append(f'  <joint name="{name}/hinge" type="hinge" '
                         f'pos="{_f(to_local @ (hinge.point - shape.position))}" '
                         f'axis="{_f(to_local @ hinge.axis)}" stiffness="{_f(hinge.stiffness)}" '
                         f'damping="{_f(hinge.damping)}" armature="0.001"/>')
            lines.append(f'  <geom name="{name}" {geom} mass="{_f(obstacle.mass)}" '
                         f'rgba="0.4 0.7 0.4 1"/>')
        lines.append('</body>')
    return lines


def _table(scene: Scene | None, settings: PhysicsSettings) -> list[str]:
    """Return the table top under the base, touched by the links and the object (in a scene)."""
    if scene is None or settings.table_height is None:
        return []
    return [f'<geom name="{TABLE}" type="plane" size="0 0 1" '
            f'pos="0 0 {_f(settings.table_height)}" contype="0" '
            f'conaffinity="{SCENE_CONAFFINITY | OBJECT_CONTYPE}" '
            f'friction="{_f(settings.friction)} 0.005 0.0001" rgba="0.8 0.75 0.65 1"/>']


def object_gravcomp(scene: Scene | None, settings: PhysicsSettings) -> float:
    """Return the share of the object's weight the controller compensates (assumed / real)."""
    if scene is None or scene.grasped is None:
        return 0.0
    if settings.object_mass_error >= scene.grasped.mass + 1e-12:
        raise ValueError(f'object_mass_error {settings.object_mass_error:g} kg leaves the '
                         f'controller a negative load (the object has '
                         f'{scene.grasped.mass:g} kg)')
    return (scene.grasped.mass - settings.object_mass_error) / scene.grasped.mass


def build_mjcf(scene: Scene | None = None, settings: PhysicsSettings | None = None,
               robot: UrdfRobot | None = None) -> str:
    """Return the MJCF of the iiwa (from the URDF), its impedance actuators and the scene."""
    settings = settings or PhysicsSettings()
    robot = robot or iiwa_urdf()
    movable = robot.movable
    if len(movable) != len(settings.stiffness):
        raise ValueError(f'{robot.name}: {len(movable)} joints, '
                         f'{len(settings.stiffness)} stiffness values')
    body_lines: list[str] = []
    closing = 0
    root = robot.links[robot.root]
    body_lines.append(f'<body name="{root.name}">')
    if root.inertial is not None:
        body_lines.append(_inertial(root.inertial))
    body_lines += _robot_geoms(root, '0.5 0.5 0.5 1')
    closing += 1
    dof = 0
    for joint in robot.joints:
        link = robot.links[joint.child]
        body_lines.append(f'<body name="{link.name}" pos="{_f(joint.xyz)}" '
                          f'quat="{_quat(joint.rotation)}" gravcomp="1">')
        if link.inertial is not None:
            body_lines.append(_inertial(link.inertial))
        if joint.kind == 'revolute':
            body_lines.append(
                f'<joint name="{joint.name}" type="hinge" axis="{_f(joint.axis)}" '
                f'range="{_f((joint.lower, joint.upper))}" limited="true" '
                f'armature="{_f(settings.armature[dof])}" '
                f'frictionloss="{_f(settings.joint_friction)}" '
                f'actuatorfrcrange="{_f((-joint.effort, joint.effort))}" '
                f'actuatorfrclimited="true" actuatorgravcomp="true"/>')
            dof += 1
        body_lines += _robot_geoms(link, '1 0.42 0.04 1')
        closing += 1
    body_lines.append(f'<site name="{FLANGE}" size="0.005"/>')
    if scene is not None and scene.grasped is not None:
        body_lines += _object_body(scene, object_gravcomp(scene, settings),
                                   settings.grasp_stiffness)
    body_lines += ['</body>'] * closing
    actuators = [
        f'<general name="{j.name}" joint="{j.name}" gaintype="fixed" biastype="affine" '
        f'gainprm="{_f(k)}" biasprm="0 {_f(-k)} 0"/>'
        for j, k in zip(movable, settings.stiffness)]
    scene_lines = [] if scene is None else _scene_bodies(scene, settings)
    indent = '\n    '
    return f"""<mujoco model="{robot.name}_{scene.name if scene else 'alone'}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{_f(settings.timestep)}" integrator="implicitfast" jacobian="dense"
          noslip_iterations="{settings.noslip_iterations}" cone="elliptic"
          impratio="{_f(settings.impratio)}"/>
  <default>
    <geom solref="{_f(settings.contact_timeconst)} 1"
          friction="{_f(settings.friction)} 0.005 0.0001"/>
  </default>
  <worldbody>
    {indent.join(body_lines)}
    {indent.join(scene_lines + _table(scene, settings))}
  </worldbody>
  <actuator>
    {indent.join(actuators)}
  </actuator>
</mujoco>
"""


def build_model(scene: Scene | None = None, settings: PhysicsSettings | None = None):
    """Compile the MJCF of :func:`build_mjcf` into a ``mujoco.MjModel``."""
    import mujoco

    return mujoco.MjModel.from_xml_string(build_mjcf(scene, settings))
