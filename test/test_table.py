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

"""The table the arm stands on: heights of the arm, and no plan through the table."""

from itertools import pairwise

import numpy as np
from probdis_ros.model import FailureMap, iiwa_arm
from probdis_ros.model.edge_costs import EdgeCoster, ReferenceEdgeCoster
from probdis_ros.model.path_cost import edge_points
from probdis_ros.model.table import lowest_heights_reference, ROBOT_TABLE, Table
from probdis_ros.planning import EpsilonPlanner, Method, ProbRRT
from probdis_ros.sim.compliant_arm import CompliantArm
from probdis_ros.sim.worlds import ScenarioError, world_from_dict
import pytest

FREE = iiwa_arm()
ARM = FREE.on_table(ROBOT_TABLE)
RNG_CONFIGS = np.random.default_rng(7).uniform(FREE.lower, FREE.upper, (400, 7))


def dense(path: np.ndarray, step: float = 0.005) -> np.ndarray:
    """Return the path's configurations every step rad (and its start)."""
    return np.vstack([path[:1]] + [edge_points(a, b, step)[0] for a, b in pairwise(path)])


def dipping_pairs(n: int, seed: int = 3) -> list[tuple[np.ndarray, np.ndarray]]:
    """Return n random (start, goal) above the table whose straight move goes below it."""
    rng = np.random.default_rng(seed)
    pairs = []
    while len(pairs) < n:
        start, goal = rng.uniform(FREE.lower, FREE.upper, (2, 7))
        if ARM.above_table(np.array([start, goal])).all() and \
                not ARM.above_table(dense(np.array([start, goal]))).all():
            pairs.append((start, goal))
    return pairs


def test_joint_frames_are_pinocchios():
    import pinocchio as pin
    from probdis_ros.resources import data_file

    model = pin.buildModelFromUrdf(str(data_file('urdf', 'iiwa14.urdf')))
    data = model.createData()
    positions, rotations = FREE.joint_frames(RNG_CONFIGS[:20])
    for q, p, r in zip(RNG_CONFIGS[:20], positions, rotations):
        pin.forwardKinematics(model, data, q)
        for j in range(7):
            assert np.allclose(data.oMi[j + 1].translation, p[j], atol=1e-12)
            assert np.allclose(data.oMi[j + 1].rotation, r[j], atol=1e-12)


def test_the_lowest_point_is_the_lowest_of_the_urdf_shapes_surfaces():
    # the kernel's closed form against the numpy reference and against points on the
    # shapes' surfaces (each cylinder's rims, each sphere's surface), sampled finely
    heights = FREE.lowest_heights(RNG_CONFIGS)
    reference = lowest_heights_reference(FREE.joint_frames(RNG_CONFIGS),
                                         FREE.tip_frames(RNG_CONFIGS)[0], FREE.shapes)
    assert np.allclose(heights, reference, atol=1e-12)
    angles = np.linspace(0, 2 * np.pi, 721)
    ring = np.stack([np.cos(angles), np.sin(angles), 0 * angles], axis=1)
    sphere = np.random.default_rng(0).normal(size=(20000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    positions, rotations = FREE.joint_frames(RNG_CONFIGS[:40])
    tips = FREE.tip_frames(RNG_CONFIGS[:40])[0]
    for n in range(40):
        lowest = tips[n, 2]
        for joint, *center, _, _, _, half, radius in FREE.shapes:
            j = int(joint) - 1
            if half == 0:
                local = np.asarray(center) + radius * sphere
            else:                 # a cylinder along z (the iiwa's): its two rims
                local = np.vstack([np.asarray(center) + radius * ring + [0, 0, s * half]
                                   for s in (-1, 1)])
            world = positions[n, j] + local @ rotations[n, j].T
            lowest = min(lowest, world[:, 2].min())
        assert heights[n] <= lowest + 1e-12
        assert heights[n] >= lowest - 2e-3


def test_the_planner_keeps_every_part_of_the_arm_above_the_table():
    # starts and goals above the table whose straight move dips below it: without the
    # table the plans go through it (so this can fail); with it, never below the floor at
    # the points costed, nor below the table top between them
    dipped = 0
    for tried, (start, goal) in enumerate(dipping_pairs(6)):
        fmap = FailureMap(ARM.task_space)
        middle = ARM.fk((start + goal) / 2)
        fmap.add(middle.positions[0], np.array([0.0, 0.0, 1.0]), middle.orientations[0])
        free = ProbRRT(FREE).plan(start, goal, fmap, np.random.default_rng(tried))
        dipped += ARM.lowest_heights(dense(free.path)).min() < 0
        plan = ProbRRT(ARM).plan(start, goal, fmap, np.random.default_rng(tried))
        assert plan is not None
        costed = np.vstack([plan.path[:1]] + [edge_points(a, b)[0]
                                              for a, b in pairwise(plan.path)])
        assert ARM.lowest_heights(costed).min() >= ROBOT_TABLE.floor
        assert ARM.lowest_heights(dense(plan.path)).min() >= ROBOT_TABLE.height
    assert dipped >= 2


def test_the_compiled_planner_equals_the_reference_on_a_table():
    rng = np.random.default_rng(11)
    fmap = FailureMap(ARM.task_space)
    poses = ARM.fk(ARM.random_configurations(rng, 5))
    for p, q in zip(poses.positions, poses.orientations):
        fmap.add(p, rng.normal(size=3), q)
    for seed, (start, goal) in enumerate(dipping_pairs(2, seed=5)):
        fast = ProbRRT(ARM).plan(start, goal, fmap, np.random.default_rng(seed))
        slow = ProbRRT(ARM, coster_type=ReferenceEdgeCoster, compiled=False).plan(
            start, goal, fmap, np.random.default_rng(seed))
        assert len(fast.path) > 2          # around the table, not straight through it
        assert np.array_equal(fast.path, slow.path)
        assert fast.cost == pytest.approx(slow.cost, rel=1e-9)


def test_an_edge_through_the_table_costs_infinity_and_one_near_it_may_only_rise():
    low = RNG_CONFIGS[np.argmin(ARM.lowest_heights(RNG_CONFIGS))]
    high = np.array([0.0, 0.3, 0.0, -1.0, 0.0, 0.8, 0.0])
    assert ARM.lowest_heights(low)[0] < 0 < ROBOT_TABLE.floor < ARM.lowest_heights(high)[0]
    fmap = FailureMap(ARM.task_space)
    for coster in (EdgeCoster(ARM, fmap), ReferenceEdgeCoster(ARM, fmap)):
        assert coster.cost(high, low) == np.inf
        # an arm left in the table (it cannot be, but a start near it can) may leave upwards
        assert np.isfinite(coster.cost(low, high))
        assert coster.cheapest(np.array([high, high]), low) == (-1, np.inf)
    assert EdgeCoster(FREE, fmap).cost(high, low) < np.inf


def test_a_goal_in_the_table_is_refused_and_so_is_a_world_that_starts_there():
    low = RNG_CONFIGS[np.argmin(ARM.lowest_heights(RNG_CONFIGS))]
    high = np.array([0.0, 0.3, 0.0, -1.0, 0.0, 0.8, 0.0])
    with pytest.raises(ValueError, match='below the table'):
        ProbRRT(ARM).plan(high, low, FailureMap(ARM.task_space), np.random.default_rng(0))
    doc = {'setting': '3d-orient', 'start': low.tolist(), 'goal': high.tolist(),
           'obstacles': [], 'table': {'height': 0.0}}
    with pytest.raises(ScenarioError, match='below the table'):
        world_from_dict(doc)
    world = world_from_dict({**doc, 'start': high.tolist(), 'goal': high.tolist()})
    assert world.arm.table == Table(0.0) and world.to_dict()['table']['clearance'] == 0.05
    with pytest.raises(ScenarioError, match='table'):
        world_from_dict({**doc, 'start': high.tolist(), 'table': {'height': 0, 'up': 1}})


def test_the_simulated_arm_stops_at_the_table_and_epsilon_never_goes_there():
    low = RNG_CONFIGS[np.argmin(ARM.lowest_heights(RNG_CONFIGS))]
    high = np.array([0.0, 0.3, 0.0, -1.0, 0.0, 0.8, 0.0])
    sim = CompliantArm(ARM, [])
    run = sim.execute(np.array([high, low]))
    assert run.blocked and run.segment == 0 and sim.collides(low) and not sim.collides(high)
    assert abs(ARM.lowest_heights(run.config)[0] - ROBOT_TABLE.height) < 0.01
    assert not CompliantArm(FREE, []).execute(np.array([high, low])).blocked
    planner = EpsilonPlanner(ARM, epsilon=0.5)
    rng = np.random.default_rng(0)
    for _ in range(30):
        path = planner.plan(high, low, FailureMap(ARM.task_space), rng).path
        assert ARM.lowest_heights(dense(path)[::8]).min() >= ROBOT_TABLE.floor - 0.03


def test_the_robots_methods_plan_above_the_table():
    planner = Method.parse('informed').planner(ARM)
    start = np.array([0.0, 0.7, 0.0, -1.3, 0.0, 0.9, 0.0])
    goal = np.array([1.2, 1.0, 0.0, -0.6, 0.0, 1.2, 0.0])
    plan = planner.plan(start, goal, FailureMap(ARM.task_space), np.random.default_rng(0))
    assert ARM.lowest_heights(dense(plan.path)).min() >= ROBOT_TABLE.height


def test_a_grasped_objects_ball_about_the_tip_is_kept_above_the_table_too():
    held = FREE.on_table(ROBOT_TABLE, object_radius=0.3)
    tips = FREE.tip_frames(RNG_CONFIGS)[0][:, 2]
    assert np.allclose(held.lowest_heights(RNG_CONFIGS),
                       np.minimum(FREE.lowest_heights(RNG_CONFIGS), tips - 0.3))
    assert len(FREE.shapes) == len(ARM.shapes) == len(held.shapes) - 1      # FREE unchanged
    with pytest.raises(ValueError, match='object_radius'):
        FREE.on_table(ROBOT_TABLE, object_radius=-1.0)


def test_the_physics_mock_has_the_table_top_the_arm_stands_on():
    import mujoco
    from probdis_ros.physics import load_scene
    from probdis_ros.physics.model import build_mjcf, TABLE
    from probdis_ros.physics.settings import PhysicsSettings

    scene = load_scene('demo_hook')
    low = RNG_CONFIGS[np.argmin(ARM.lowest_heights(RNG_CONFIGS))]

    def table_contacts(q, settings=None):
        settings = settings or PhysicsSettings()
        model = mujoco.MjModel.from_xml_string(build_mjcf(scene, settings))
        data = mujoco.MjData(model)
        data.qpos[:7] = q
        mujoco.mj_forward(model, data)
        if settings.table_height is None:
            return None
        table = model.geom(TABLE).id
        return sum(table in (c.geom1, c.geom2) for c in data.contact[:data.ncon])

    assert table_contacts(scene.start) == 0      # the base stands on it without a contact
    assert table_contacts(low) > 0
    assert table_contacts(low, PhysicsSettings(table_height=None)) is None
    # the contacts a physics episode sums as peak_table_force_n name the table top
    from probdis_ros.physics import PhysicsIiwa

    arm = PhysicsIiwa(scene)
    arm.reset(low)
    arm.advance(low, 0.002)                     # one step: the table pushes the links out
    assert sum(c.force for c in arm.contacts() if c.scene_geom == TABLE) > 1.0


def test_probdis_sim_reports_how_low_the_arm_went_with_and_without_the_table(capsys):
    import json

    from probdis_ros import cli

    # a training world whose way out went below the base's plane before the table
    lowest = {}
    for flag in ((), ('--no-table',)):
        assert cli.main(['sim', '--family', 'open_box', '--seed', '1005', '--json',
                         '--method', 'probabilistic', *flag]) == 0
        lowest[flag] = json.loads(capsys.readouterr().out)['lowest_m']
    assert lowest[()] >= ROBOT_TABLE.floor > ROBOT_TABLE.height > lowest[('--no-table',)]
    assert cli.main(['sim', '--engine', 'physics', '--no-table']) == 2


def test_rviz_shows_the_table_top_and_the_floor_above_it():
    from probdis_ros.ros.markers import markers_msg
    from rclpy.clock import Clock

    def plates(arm):
        msg = markers_msg(arm, FailureMap(arm.task_space), None, Clock())
        return [m.pose.position.z for m in msg.markers if m.ns == 'table']

    assert plates(FREE) == []
    assert plates(ARM) == pytest.approx([ROBOT_TABLE.height - 0.001, ROBOT_TABLE.floor - 0.001])
