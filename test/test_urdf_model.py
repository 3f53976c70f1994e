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

"""The iiwa URDF's dynamics and geometry: added without moving the kinematics by a digit."""

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
from probdis_ros.model import iiwa_arm
from probdis_ros.physics.model import read_urdf
from probdis_ros.resources import data_file
import yourdfpy

URDF = data_file('urdf', 'iiwa14.urdf')
#: Published link masses of the iiwa 14 (Drake's description), links 1-7.
MASSES = [5.76, 6.35, 3.5, 3.5, 3.5, 1.8, 1.2]


def kinematic_only_copy(tmp_path):
    """Write the URDF without inertials, visuals, collisions, materials: the chain alone."""
    root = ET.parse(URDF).getroot()
    for element in list(root):
        if element.tag == 'material':
            root.remove(element)
    for link in root.findall('link'):
        for child in list(link):
            link.remove(child)
    path = tmp_path / 'kinematic.urdf'
    ET.ElementTree(root).write(path)
    return path


def test_flange_poses_equal_the_kinematic_only_chain_to_1e_12(tmp_path):
    bare = kinematic_only_copy(tmp_path)
    full_model = pin.buildModelFromUrdf(str(URDF))
    bare_model = pin.buildModelFromUrdf(str(bare))
    full_data, bare_data = full_model.createData(), bare_model.createData()
    frame = full_model.getFrameId('lbr_link_ee')
    assert frame == bare_model.getFrameId('lbr_link_ee')
    full_urdf = yourdfpy.URDF.load(str(URDF), load_meshes=False,
                                   build_collision_scene_graph=False)
    bare_urdf = yourdfpy.URDF.load(str(bare), load_meshes=False,
                                   build_collision_scene_graph=False)
    arm = iiwa_arm()
    configs = arm.random_configurations(np.random.default_rng(7), 100)
    positions, rotations = arm.tip_frames(configs)
    for q, x, rot in zip(configs, positions, rotations):
        pin.framesForwardKinematics(full_model, full_data, q)
        pin.framesForwardKinematics(bare_model, bare_data, q)
        full, ref = full_data.oMf[frame], bare_data.oMf[frame]
        np.testing.assert_allclose(full.translation, ref.translation, atol=1e-12, rtol=0)
        np.testing.assert_allclose(full.rotation, ref.rotation, atol=1e-12, rtol=0)
        np.testing.assert_allclose(full.translation, x, atol=1e-12, rtol=0)
        np.testing.assert_allclose(full.rotation, rot, atol=1e-12, rtol=0)
        full_urdf.update_cfg(q)
        bare_urdf.update_cfg(q)
        np.testing.assert_allclose(full_urdf.get_transform('lbr_link_ee'),
                                   bare_urdf.get_transform('lbr_link_ee'), atol=1e-12, rtol=0)


def test_joints_are_unchanged_from_the_kinematic_description():
    """Origins, axes and limits of the datasheet (the text of every joint element)."""
    robot = read_urdf(URDF)
    offsets = [0.1575, 0.2025, 0.2045, 0.2155, 0.1845, 0.2155, 0.081, 0.045]
    axes = [(0, 0, 1), (0, 1, 0), (0, 0, 1), (0, -1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1)]
    for joint, offset in zip(robot.joints, offsets):
        np.testing.assert_array_equal(joint.xyz, [0, 0, offset])
        np.testing.assert_array_equal(joint.rotation, np.eye(3))
    for joint, axis in zip(robot.movable, axes):
        np.testing.assert_array_equal(joint.axis, axis)
    assert [j.effort for j in robot.movable] == [320, 320, 176, 176, 110, 40, 40]


def test_links_have_the_published_masses_and_physical_inertias():
    robot = read_urdf(URDF)
    masses = [robot.links[f'lbr_link_{i}'].inertial.mass for i in range(1, 8)]
    assert masses == MASSES
    model = pin.buildModelFromUrdf(str(URDF))
    assert sum(model.inertias[i].mass for i in range(1, 8)) == sum(MASSES)
    for i in range(8):
        inertial = robot.links[f'lbr_link_{i}'].inertial
        principal = np.linalg.eigvalsh(inertial.inertia)
        assert np.all(principal > 0)
        a, b, c = principal
        assert a + b >= c and b + c >= a and a + c >= b       # a rigid body's inertia
        assert np.linalg.norm(inertial.com) < 0.2             # inside the link's reach


def shape_of(element):
    shape = element.find('geometry')[0]
    return element.find('origin').attrib, shape.tag, shape.attrib


def test_every_moving_link_has_collision_geometry_drawn_the_same():
    robot = read_urdf(URDF)
    root = ET.parse(URDF).getroot()
    for link in root.findall('link'):
        name = link.get('name')
        if name == 'lbr_link_ee':
            assert len(link) == 0               # the flange frame: a grasped object is not here
            continue
        visuals = [shape_of(v) for v in link.findall('visual')]
        collisions = [shape_of(c) for c in link.findall('collision')]
        assert collisions and visuals == collisions
        assert all(v.find('material') is not None for v in link.findall('visual'))
        assert robot.links[name].collisions


def test_collision_geometry_covers_the_arm_from_base_to_flange():
    """Every point of the straight arm's axis lies inside some link's geometry."""
    robot = read_urdf(URDF)
    heights = np.cumsum([0.0] + [j.xyz[2] for j in robot.joints])
    covered = np.zeros(1261, dtype=bool)
    for height, joint in zip(heights, [None, *robot.joints]):
        link = robot.links[joint.child if joint else robot.root]
        for shape in link.collisions:
            half = shape.size[0] if shape.kind == 'sphere' else shape.size[1] / 2
            lo, hi = height + shape.position[2] - half, height + shape.position[2] + half
            covered[max(0, int(np.ceil(lo * 1000))):int(np.floor(hi * 1000)) + 1] = True
    assert covered.all()
