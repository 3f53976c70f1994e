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

"""Physical scenes: the file format, bad files refused, and every shipped scene solvable."""

import itertools
import json

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.physics import load_scene, PhysicsIiwa, scene_from_dict, SceneError
from probdis_ros.physics.oracle import (
    check_scene,
    find_free_path,
    first_collision,
    path_is_free,
    segment_configurations,
)
from probdis_ros.physics.scene import scene_path, shipped_scenes
import pytest
import yaml

ARM = iiwa_arm()
D_DIST = 0.04
SCENES = ['demo_hook', 'robot_bunny', 'robot_maze', 'robot_waste']
LIMIT_MARGIN = np.radians(3)
GOOD = {
    'name': 'mine',
    'start': [0.0, 0.45, 0.0, -1.5, 0.0, 1.15, 0.0],
    'goal': [0.2, 0.5, 0.0, -0.7, 0.0, 1.9, 0.3],
    'object': {'mass': 0.4, 'shapes': [
        {'type': 'capsule', 'radius': 0.012, 'length': 0.2, 'position': [0, 0, 0.1]},
        {'type': 'box', 'size': [0.05, 0.02, 0.02], 'position': [0, 0, 0.2],
         'quaternion': [1, 0, 0, 0]}]},
    'obstacles': [
        {'type': 'cylinder', 'radius': 0.02, 'length': 0.5, 'position': [0.6, 0, 0.3],
         'rpy': [1.5708, 0, 0], 'name': 'bar'},
        {'type': 'sphere', 'radius': 0.05, 'position': [0.3, 0.4, 0.3],
         'hinge': {'point': [0.3, 0.4, 0.5], 'axis': [1, 0, 0], 'stiffness': 5.0,
                   'damping': 0.1}, 'mass': 0.2}]}


def tracked(arm, path, speed=0.3, hold=1.0, record=None):
    """Move the impedance setpoint along a joint path at `speed` rad/s, then hold."""
    for a, b in itertools.pairwise(path):
        n = max(1, int(np.ceil(np.abs(b - a).max() / speed / 0.01)))
        for k in range(1, n + 1):
            arm.advance(a + (b - a) * k / n, 0.01)
            if record is not None:
                record(arm)
    arm.advance(path[-1], hold)
    return float(np.abs(path[-1] - arm.q).sum())


def test_the_shipped_scenes_are_listed():
    assert shipped_scenes() == SCENES


@pytest.mark.parametrize('name', SCENES)
def test_scene_is_entangled_near_the_start_and_a_free_path_exists(name):
    scene = load_scene(name)
    for q in (scene.start, scene.goal):
        assert np.all(q > ARM.lower + LIMIT_MARGIN) and np.all(q < ARM.upper - LIMIT_MARGIN)
    # a way out exists, with 1 cm to spare (so that the lagging real arm can follow it too)
    check = check_scene(scene, np.random.default_rng(0), clearance=0.01)
    assert check.ok, check.problems
    assert check.start_free and check.goal_free
    # the straight joint-space move is blocked, within 1-30 cm of the start
    assert 0.01 < check.blocked_after_m < 0.3
    path = check.way_out
    np.testing.assert_array_equal(path[0], scene.start)
    np.testing.assert_array_equal(path[-1], scene.goal)
    arm = PhysicsIiwa(scene)
    assert path_is_free(arm, path, clearance=0.01)
    assert all(np.abs(np.diff(segment_configurations(a, b), axis=0)).max() <= 0.02 + 1e-12
               for a, b in itertools.pairwise(path))


def test_scene_check_tells_a_fit_scene_from_unfit_ones(probdis, tmp_path):
    """A user's files: a copy of Maze passes; without obstacles, or starting inside one, not."""
    doc = yaml.safe_load(scene_path('robot_maze').read_text())
    files = {}
    for name, obstacles in (
            ('maze', doc['obstacles']),
            ('empty', []),
            ('inside', doc['obstacles'] + [{
                'type': 'sphere', 'radius': 0.1,
                'position': ARM.positions(np.array(doc['start']))[0].tolist()}])):
        files[name] = tmp_path / f'{name}.yaml'
        files[name].write_text(yaml.safe_dump({**doc, 'name': name, 'obstacles': obstacles}))
    # a goal 1 mrad inside A1's limit, which the planner node refuses
    near = [float(ARM.lower[0]) + 0.001, *doc['goal'][1:]]
    files['near'] = tmp_path / 'near.yaml'
    files['near'].write_text(yaml.safe_dump({**doc, 'name': 'near', 'goal': near,
                                             'obstacles': []}))
    result = probdis('scene', 'check', *map(str, files.values()), check=False)
    assert result.returncode == 1, result.stderr
    lines = dict(line.split(': ', 1) for line in result.stdout.splitlines()[:4])
    assert lines[str(files['near'])].startswith('NOT FIT: the goal lbr_A1 at -2.96606 rad '
                                                'lies 0.00100 rad from its limit'), lines
    assert lines[str(files['maze'])].startswith('ok: the straight move is blocked')
    assert lines[str(files['empty'])] == \
        'NOT FIT: the straight move to the goal is free: nothing to disentangle'
    assert lines[str(files['inside'])].startswith('NOT FIT: the start collides')
    assert result.stdout.splitlines()[-1] == '1 of 4 scenes entangled and solvable'
    # --json: the way out itself, from the start to the goal
    doc = json.loads(probdis('scene', 'check', str(files['maze']), '--json').stdout)
    assert doc['ok'] and doc['problems'] == []
    np.testing.assert_array_equal(doc['way_out'][0], load_scene(str(files['maze'])).start)
    # a bad file or family is refused before any scene is checked
    files['maze'].write_text('start: [0, 0]\n')
    result = probdis('scene', 'check', 'robot_maze', str(files['maze']), check=False)
    assert result.returncode == 2 and result.stdout == ''
    assert 'probdis scene check: error:' in result.stderr and 'Traceback' not in result.stderr
    result = probdis('scene', 'check', '--family', 'boxes', check=False)
    assert result.returncode == 2 and 'unknown family' in result.stderr


@pytest.mark.parametrize('name', SCENES)
def test_the_physical_arm_is_blocked_on_the_straight_move_and_follows_the_free_path(name):
    scene = load_scene(name)
    arm = PhysicsIiwa(scene)
    assert tracked(arm, np.array([scene.start, scene.goal])) > 3 * D_DIST
    assert arm.contacts()
    path = find_free_path(arm, scene.start, scene.goal, np.random.default_rng(0),
                          clearance=0.01)
    arm.reset(scene.start)
    forces = []
    assert tracked(arm, path, record=lambda a: forces.append(len(a.contacts()))) < D_DIST
    assert max(forces) == 0


def test_waste_clutter_gives_way_but_does_not_let_the_object_through():
    scene = load_scene('robot_waste')
    arm = PhysicsIiwa(scene)
    hinges = [j for j in range(arm.model.njnt) if arm.model.joint(j).name.endswith('/hinge')]
    assert len(hinges) == 6
    adr = arm.model.jnt_qposadr[hinges]
    bend = []
    gap = tracked(arm, np.array([scene.start, scene.goal]),
                  record=lambda a: bend.append(np.abs(a.data.qpos[adr]).max()))
    assert max(bend) > 0.01                      # a flap bent
    assert gap > 3 * D_DIST                      # but the crossbar is still under it


def test_a_softer_hinge_yields_more():
    """The demo's bar replaced by a flap on a hinge along its far edge."""
    doc = yaml.safe_load(scene_path('demo_hook').read_text())
    bar = doc['obstacles'][0]['position']
    gaps = {}
    for stiffness in (2.0, 2000.0):
        doc['obstacles'] = [{
            'type': 'box', 'size': [0.1, 0.3, 0.02], 'position': bar,
            'hinge': {'point': [bar[0] + 0.05, bar[1], bar[2]], 'axis': [0, 1, 0],
                      'stiffness': stiffness, 'damping': 0.1}}]
        scene = scene_from_dict(doc)
        arm = PhysicsIiwa(scene)
        assert first_collision(arm, np.array([scene.start, scene.goal])) is not None
        gaps[stiffness] = tracked(arm, np.array([scene.start, scene.goal]))
    assert gaps[2.0] < D_DIST < gaps[2000.0]


def test_a_users_own_file_is_read_and_poses_are_parsed(tmp_path):
    path = tmp_path / 'mine.yaml'
    path.write_text(yaml.safe_dump(GOOD))
    scene = load_scene(str(path))
    assert scene.name == 'mine' and scene.source == str(path)
    assert [s.kind for s in scene.grasped.shapes] == ['capsule', 'box']
    assert scene.grasped.mass == 0.4
    bar, ball = scene.obstacles
    assert bar.hinge is None and bar.shape.name == 'bar'
    np.testing.assert_allclose(bar.shape.rotation @ [0, 0, 1], [0, -1, 0], atol=1e-4)
    assert ball.hinge.stiffness == 5.0 and ball.mass == 0.2
    np.testing.assert_allclose(ball.hinge.axis, [1, 0, 0])
    PhysicsIiwa(scene).advance(scene.start, 0.05)


BAD = [
    (lambda d: d.pop('start'), 'missing start'),
    (lambda d: d.update(goal=[0.0] * 6), 'goal: needs a list of 7 numbers'),
    (lambda d: d.update(goal=[0, 3.0, 0, 0, 0, 0, 0]), 'goal: outside the joint limits at lbr_A2'),
    (lambda d: d.update(colour='red'), 'unknown keys colour'),
    (lambda d: d['obstacles'][0].update(type='cone'), 'obstacles[0]: type must be one of'),
    (lambda d: d['obstacles'].append({'type': 'box', 'size': [1, 2], 'position': [0, 0, 0]}),
     'obstacles[2]: box needs size of 3 positive numbers'),
    (lambda d: d['obstacles'].append({'type': 'box', 'size': [1, 0, 1], 'position': [0, 0, 0]}),
     'obstacles[2]: box needs size of 3 positive numbers'),
    (lambda d: d['obstacles'][0].pop('position'), 'obstacles[0]: cylinder needs position'),
    (lambda d: d['obstacles'][0].update(radius=-1),
     'obstacles[0]: cylinder needs radius positive'),
    (lambda d: d['obstacles'][0].update(quaternion=[1, 0, 0, 0]),
     'obstacles[0]: cylinder: give rpy or quaternion, not both'),
    (lambda d: d['obstacles'][0].update(size=[1, 1, 1]), 'obstacles[0]: cylinder takes no size'),
    (lambda d: d['obstacles'][0].update(mass=1.0), 'obstacles[0]: cylinder: mass is only for'),
    (lambda d: d['obstacles'][1]['hinge'].update(axis=[0, 0, 0]),
     'obstacles[1]: hinge: axis must not be zero'),
    (lambda d: d['obstacles'][1]['hinge'].pop('stiffness'), 'obstacles[1]: hinge needs stiffness'),
    (lambda d: d['obstacles'][1]['hinge'].update(damping=-1.0),
     'obstacles[1]: hinge needs damping at least 0'),
    (lambda d: d.update(obstacles={'a': 1}), 'obstacles must be a list'),
    (lambda d: d['object'].update(mass=0), 'object needs mass positive'),
    (lambda d: d['object'].update(shapes=[]), 'object needs shapes'),
    (lambda d: d['object']['shapes'][1].update(quaternion=[0, 0, 0, 0]),
     'object.shapes[1]: box: quaternion must not be zero'),
    (lambda d: d['object']['shapes'][0].update(hinge={}),
     'object.shapes[0]: capsule: unknown keys'),
]


@pytest.mark.parametrize('edit, message', BAD, ids=[m for _, m in BAD])
def test_bad_files_are_refused_naming_the_file_and_the_entry(tmp_path, edit, message):
    doc = yaml.safe_load(yaml.safe_dump(GOOD))
    edit(doc)
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(SceneError) as err:
        load_scene(path)
    assert str(err.value).startswith(f'{path}: ')
    assert message in str(err.value)


def test_unreadable_and_invalid_files_are_refused(tmp_path):
    with pytest.raises(SceneError, match='cannot read scene'):
        load_scene(tmp_path / 'missing.yaml')
    with pytest.raises(SceneError, match='cannot read scene'):
        load_scene('no_such_scene')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('start: [1, 2\n')
    with pytest.raises(SceneError, match='not valid YAML'):
        load_scene(broken)
    broken.write_bytes(b'\x99\xaf binary')     # not text: the file was not named
    with pytest.raises(SceneError, match=r'broken\.yaml: not valid YAML'):
        load_scene(broken)
    listed = tmp_path / 'list.yaml'
    listed.write_text('- 1\n')
    with pytest.raises(SceneError, match='a scene is a mapping'):
        load_scene(listed)
    assert issubclass(SceneError, ValueError)
