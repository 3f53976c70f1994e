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

"""The entanglement families as physical scenes: same obstacles, a free start, an episode."""

from dataclasses import replace
import json

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.physics import load_scene, PhysicsIiwa, scene_from_dict, SceneError
from probdis_ros.physics.episode import run_physics_episode
from probdis_ros.physics.family_scenes import (
    CLEARANCE,
    family_scene,
    OBJECT_RADIUS,
    THICKNESS,
)
from probdis_ros.physics.oracle import first_collision
from probdis_ros.planning import Method
from probdis_ros.planning.prob_rrt import ROBOT_JOINT_MARGIN
from probdis_ros.run import goal_problem
from probdis_ros.sim.families import FAMILIES, random_family_world
import pytest

SEED = 0
WORLDS = {family: random_family_world(family, SEED) for family in FAMILIES}
SCENES = {family: family_scene(world) for family, world in WORLDS.items()}


@pytest.mark.parametrize('family', FAMILIES)
def test_the_scene_keeps_every_obstacle_where_the_world_has_it(family):
    world, scene = WORLDS[family], SCENES[family]
    assert scene.name == f'{family}-seed{SEED}' and scene.object_only
    np.testing.assert_array_equal(scene.start, world.start)
    np.testing.assert_array_equal(scene.goal, world.goal)
    assert len(scene.obstacles) == len(world.obstacles) > 0
    for i, (kinematic, physical) in enumerate(zip(world.obstacles, scene.obstacles)):
        shape = physical.shape
        if kinematic.kind == 'ball':
            assert shape.kind == 'sphere' and shape.name == f'ball_{i}'
            np.testing.assert_allclose(shape.position, kinematic.center, atol=1e-12)
            assert kinematic.radius - OBJECT_RADIUS - CLEARANCE <= shape.size[0] \
                <= kinematic.radius
        else:   # a flat disc: a thin cylinder on its plane, its axis the disc's normal
            assert shape.kind == 'cylinder' and shape.name == f'disc_{i}'
            assert shape.size == (kinematic.radius, THICKNESS)
            np.testing.assert_allclose(abs(shape.rotation[:, 2] @ kinematic.normal), 1.0)
            offset = shape.position - kinematic.center
            np.testing.assert_allclose(offset - (offset @ kinematic.normal) *
                                       kinematic.normal, 0.0, atol=1e-12)
            assert THICKNESS / 2 - 1e-12 <= np.linalg.norm(offset) <= \
                THICKNESS / 2 + OBJECT_RADIUS + CLEARANCE
        if kinematic.orientation is None:
            assert physical.gate is None
        else:
            np.testing.assert_allclose(physical.gate.orientation, kinematic.orientation)
            assert physical.gate.tolerance == world.orientation_tolerance


@pytest.mark.parametrize('family', FAMILIES)
def test_the_start_is_free_in_mujoco_and_the_straight_move_is_blocked(family):
    scene = SCENES[family]
    arm = PhysicsIiwa(scene)
    assert not arm.in_collision(scene.start) and not arm.in_collision(scene.goal)
    assert first_collision(arm, np.array([scene.start, scene.goal]), resolution=0.004) \
        is not None
    # the kinematic world leaves the links out: solid links cross the trap's walls
    if family in ('open_box', 'closed_box', 'plate_hole'):
        assert PhysicsIiwa(replace(scene, object_only=False)).in_collision(scene.start)


def test_an_item_grazing_the_start_is_made_to_clear_the_object():
    world = random_family_world('clutter', 1)      # an item 1.4 mm from the flange point
    scene = family_scene(world)
    assert '; 1 made to clear the object at the start' in scene.description
    assert not PhysicsIiwa(scene).in_collision(scene.start)
    index, kept = next((i, o) for i, o in enumerate(scene.obstacles)
                       if o.shape.size[0] < world.obstacles[i].radius)
    full = replace(kept, shape=replace(kept.shape, size=(world.obstacles[index].radius,)))
    raw = replace(scene, obstacles=(*scene.obstacles[:index], full,
                                    *scene.obstacles[index + 1:]))
    assert PhysicsIiwa(raw).in_collision(scene.start)


def test_a_goal_near_a_joint_limit_is_moved_in_to_the_planner_nodes_margin():
    world = random_family_world('closed_box', 8007)     # the goal's A1 0.9 mrad from its limit
    scene, arm = family_scene(world), world.arm
    assert 'lbr_A1' in goal_problem(arm, world.goal, ROBOT_JOINT_MARGIN)
    assert goal_problem(arm, scene.goal, ROBOT_JOINT_MARGIN) == ''
    moved = scene.goal - world.goal
    assert np.flatnonzero(moved).tolist() == [0]
    np.testing.assert_allclose(min(scene.goal[0] - arm.lower[0], arm.upper[0] - scene.goal[0]),
                               ROBOT_JOINT_MARGIN, atol=1e-12)
    assert f"goal moved {abs(moved[0]):.4f} rad in from lbr_A1's limit" in scene.description
    assert not PhysicsIiwa(scene).in_collision(scene.goal)
    # an episode refuses the world's own goal, as the planner node does
    with pytest.raises(ValueError, match=r'goal lbr_A1 .* nearer than 0.035 \(joint_margin\)'):
        run_physics_episode(replace(scene, goal=world.goal), 'probabilistic', max_paths=1)


def test_a_gated_wall_opens_to_a_turned_object_and_closes_again():
    scene = SCENES['closed_box']
    arm = PhysicsIiwa(scene)
    assert arm.gates_solid().all()
    turned = scene.start + np.array([0, 0, 0, 0, 0, 0, np.pi / 2 *
                                     (1 if scene.start[6] < 0 else -1)])
    arm.advance(turned, 1.5)
    assert not arm.gates_solid().any()
    assert not (arm.model.geom_conaffinity[arm._gate_geom]).any()
    arm.advance(scene.start, 1.5)
    assert arm.gates_solid().all() and arm.model.geom_conaffinity[arm._gate_geom].all()


def test_a_gate_turned_shut_around_the_object_waits_until_the_object_is_out():
    arm_model = iiwa_arm()
    start = np.array([0.0, 0.5, 0.0, -1.4, 0.0, 1.0, -0.8])
    turned = start + np.array([0, 0, 0, 0, 0, 0, np.pi / 2])
    out = turned + np.array([0, 0, 0, 0.3, 0, 0, 0])
    pose = arm_model.fk(np.array([start, turned]))
    ball = {'type': 'sphere', 'radius': 0.03, 'position': pose.positions[0].tolist(),
            'gate': {'orientation': pose.orientations[1].tolist(), 'tolerance': 0.3}}
    scene = scene_from_dict({'start': start.tolist(), 'goal': out.tolist(), 'object_only': True,
                             'object': {'mass': 0.4, 'shapes': [
                                 {'type': 'sphere', 'radius': 0.005, 'position': [0, 0, 0]}]},
                             'obstacles': [ball]})
    arm = PhysicsIiwa(scene)

    def shut():
        return bool(arm.model.geom_conaffinity[arm._gate_geom][0])

    assert not arm.gates_solid()[0] and not shut()        # open: held turned away
    assert arm.in_collision(turned) and not arm.in_collision(start)
    arm.advance(turned, 1.0)           # turned toward the gate, inside the ball: stays open
    assert arm.gates_solid()[0] and not shut()
    assert max((c.force for c in arm.contacts()), default=0.0) == 0.0
    arm.advance(out, 2.0)              # out of the ball, still held like the gate: shut
    assert arm.gates_solid()[0] and shut()
    assert np.linalg.norm(arm.flange_pose()[0] - pose.positions[0]) > 0.04


def test_a_family_name_is_a_scene_and_gates_are_read_from_files():
    scene = load_scene('hook_bar-seed2')
    assert scene.name == 'hook_bar-seed2' and len(scene.obstacles) > 0
    with pytest.raises(SceneError, match='cannot read scene'):
        load_scene('nope-seed2')
    doc = {'start': [0.0] * 7, 'goal': [0.1] * 7, 'object_only': True, 'obstacles': [
        {'type': 'sphere', 'radius': 0.05, 'position': [0.5, 0, 0.5],
         'gate': {'orientation': [2, 0, 0, 0], 'tolerance': 0.3}}]}
    gate = scene_from_dict(doc).obstacles[0].gate
    np.testing.assert_allclose(gate.orientation, [1, 0, 0, 0])
    assert gate.solid(np.array([1.0, 0, 0, 0])) and not gate.solid(np.array([0.0, 1, 0, 0]))
    doc['obstacles'][0]['gate'] = {'orientation': [1, 0, 0, 0], 'tolerance': 2}
    with pytest.raises(SceneError, match=r'obstacles\[0\]: gate needs tolerance at most 1'):
        scene_from_dict(doc)
    with pytest.raises(SceneError, match='object_only must be true or false'):
        scene_from_dict({**doc, 'object_only': 'yes', 'obstacles': []})


def test_an_offline_physics_episode_on_a_family_world_reaches_a_verdict():
    episode = run_physics_episode(SCENES['hook_bar'], 'probabilistic', seed=0, max_paths=1)
    assert episode.outcome in ('gave_up', 'succeeded') and episode.paths == 1
    assert len(episode.failures) >= 1 and episode.contact_force.max() > 10.0


def test_an_offline_physics_episode_plans_as_the_planner_node_does_with_what_it_is_given():
    # the node's defaults (its goal tolerance, retreat, joint margin and table), unless the
    # caller gives others; the seed chooses the planner's draws
    from probdis_ros.model.table import ROBOT_TABLE
    from probdis_ros.planning.disentangle import DEFAULT_MIN_RETREAT, ROBOT_GOAL_TOLERANCE

    scene = SCENES['hook_bar']
    loop = run_physics_episode(scene, 'probabilistic', seed=3, max_paths=1).loop
    assert (loop.seed, loop.max_paths, loop.goal_tolerance, loop.min_retreat) == (
        3, 1, ROBOT_GOAL_TOLERANCE, DEFAULT_MIN_RETREAT)
    assert loop.planner.planner.settings.joint_margin == ROBOT_JOINT_MARGIN
    assert loop.arm.table is ROBOT_TABLE and loop.fmap.c_fail == Method.parse(
        'probabilistic').map_c_fail()
    other = run_physics_episode(scene, 'probabilistic', seed=4, max_paths=1,
                                goal_tolerance=0.02, min_retreat=0.05, table=None,
                                c_fail=7.0).loop
    assert (other.seed, other.goal_tolerance, other.min_retreat, other.fmap.c_fail) == (
        4, 0.02, 0.05, 7.0)
    assert other.arm.table is None
    assert not np.array_equal(loop.attempts[0].path, other.attempts[0].path)


def test_the_robot_experiment_runs_the_maps_informed_ideas_offline_only(probdis, tmp_path):
    # b changes what the map learns, which the planner node's map file cannot keep
    args = ('experiment', 'robot', '--family', 'hook_bar', '--worlds', '1', '--seed', '0',
            '--methods', 'informed:b', '--json')
    records = json.loads(probdis(*args, '--offline', '--out', str(tmp_path / 'offline'),
                                 timeout=300).stdout)
    assert [(r['method'], r['offline']) for r in records] == [('informed:b', True)]
    assert records[0]['paths'] >= 1
    bad = probdis(*args, '--out', str(tmp_path / 'nodes'), check=False)
    assert bad.returncode == 2 and 'run these with --offline' in bad.stderr
    assert 'map' in bad.stderr


def test_the_robot_experiment_runs_family_worlds_offline(probdis, tmp_path):
    out = tmp_path / 'runs'
    records = json.loads(probdis('experiment', 'robot', '--offline', '--family', 'hook_bar',
                                 '--worlds', '1', '--seed', '0', '--methods', 'probabilistic',
                                 '--out', str(out), '--json', timeout=300).stdout)
    assert [(r['scenario'], r['run']) for r in records] == [('hook_bar-seed0', 0)]
    assert records[0]['offline'] and records[0]['paths'] >= 1
    for args, message in (
            (('--family', 'nope'), "unknown family 'nope'"),
            (('--family', 'all', '--scenarios', 'demo_hook'), 'not both'),
            (('--worlds', '2'), '--worlds and --seed choose the worlds of --family'),
            (('--family', 'all', '--engine', 'kinematic'), '(--engine physics)')):
        bad = probdis('experiment', 'robot', '--offline', *args, '--out', str(out),
                      check=False)
        assert bad.returncode == 2 and message in bad.stderr, bad.stderr
    bad = probdis('sim', '--engine', 'physics', '--family', 'nope', check=False)
    assert bad.returncode == 2 and "unknown family 'nope'" in bad.stderr
