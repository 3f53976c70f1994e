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

"""The physics-simulated iiwa: kinematics, KUKA's joint impedance, contact and friction."""

import mujoco
import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.physics import PhysicsIiwa, PhysicsSettings, scene_from_dict
from probdis_ros.physics.model import build_mjcf, iiwa_urdf
import pytest

ARM = iiwa_arm()
D_DIST = 0.04        # the planner's blocked threshold (L1 over joints)
START = np.array([0.0, 0.7, 0.0, -1.3, 0.0, 0.9, 0.0])   # flange 0.66 m out, pointing down
BAR = {'type': 'capsule', 'radius': 0.015, 'length': 0.13, 'position': [0, 0, 0.08]}
# (the last two reach below the table top: tests at rest run in FREE_SPACE, without it)
REST_CONFIGS = [np.zeros(7), START, np.array([1.0, -1.2, 2.0, 1.5, -2.0, 1.8, 3.0]),
                np.array([-2.5, 1.9, -0.5, -2.0, 1.0, -1.9, -2.9])]
FREE_SPACE = PhysicsSettings(table_height=None)


def gap(setpoint, q):
    return float(np.abs(np.asarray(setpoint) - q).sum())


def bar_scene(mass=0.5, box=True, goal=START):
    """Return a scene: a bar pointing down from the flange, a rigid slab 3 cm below it."""
    pos, rot = ARM.tip_frames(START)
    tip = pos[0] + 0.15 * rot[0][:, 2]
    obstacles = [{'type': 'box', 'size': [0.3, 0.3, 0.05], 'name': 'slab',
                  'position': (tip - [0, 0, 0.055]).tolist()}] if box else []
    return scene_from_dict({'start': START.tolist(), 'goal': np.asarray(goal).tolist(),
                            'object': {'mass': mass, 'shapes': [BAR]},
                            'obstacles': obstacles})


def ramp(arm, q_from, q_to, duration, record=None):
    """Move the setpoint linearly at 100 Hz (what a caller's controller would do)."""
    n = round(duration / 0.01)
    for k in range(1, n + 1):
        setpoint = q_from + (q_to - q_from) * k / n
        arm.advance(setpoint, 0.01)
        if record is not None:
            record(arm)
    return setpoint


def test_simulated_flange_equals_the_urdf_kinematics_at_random_configurations():
    arm = PhysicsIiwa(bar_scene())
    for q in ARM.random_configurations(np.random.default_rng(3), 200):
        arm.reset(q)
        pos, rot = arm.flange_pose()
        ref_pos, ref_rot = ARM.tip_frames(q)
        np.testing.assert_allclose(pos, ref_pos[0], atol=1e-9)
        np.testing.assert_allclose(rot, ref_rot[0], atol=1e-9)
        np.testing.assert_array_equal(arm.q, q)


def test_model_takes_limits_efforts_and_masses_from_the_urdf():
    arm = PhysicsIiwa()
    urdf = iiwa_urdf()
    np.testing.assert_allclose(arm.lower, ARM.lower)
    np.testing.assert_allclose(arm.upper, ARM.upper)
    np.testing.assert_allclose(arm.effort, [320, 320, 176, 176, 110, 40, 40])
    masses = [arm.model.body(f'lbr_link_{i}').mass[0] for i in range(1, 8)]
    np.testing.assert_allclose(masses, [5.76, 6.35, 3.5, 3.5, 3.5, 1.8, 1.2])
    assert masses == [urdf.links[f'lbr_link_{i}'].inertial.mass for i in range(1, 8)]
    assert 'lbr_link_0/collision_0' in build_mjcf()


def test_damping_is_kukas_law_from_the_joint_space_inertia():
    settings = PhysicsSettings(stiffness=(300.0, 200, 200, 200, 100, 50, 20), damping_ratio=0.5)
    arm = PhysicsIiwa(settings=settings)
    arm.reset(START)
    full = np.zeros((7, 7))
    mujoco.mj_fullM(arm.model, arm.data, full)
    expected = 2 * 0.5 * np.sqrt(np.array(settings.stiffness) * np.diag(full))
    np.testing.assert_allclose(-arm.model.actuator_biasprm[:, 2], expected, rtol=1e-12)
    np.testing.assert_allclose(arm.model.actuator_gainprm[:, 0], settings.stiffness)


@pytest.mark.parametrize('timestep', [0.001, 0.002])
def test_at_rest_gravity_compensation_holds_without_drift_or_limit_cycle(timestep):
    arm = PhysicsIiwa(bar_scene(box=False), PhysicsSettings(timestep=timestep,
                                                            table_height=None))
    for q in REST_CONFIGS:
        arm.reset(q)
        peak = 0.0
        for _ in range(200):
            arm.advance(q, 0.01)
            peak = max(peak, float(np.abs(arm.qdot).max()))
        assert arm.time == pytest.approx(2.0)
        assert gap(q, arm.q) < 1e-9
        assert peak < 1e-9


@pytest.mark.parametrize('timestep', [0.001, 0.002])
def test_a_free_move_ends_with_the_gap_back_under_d_dist_and_no_oscillation(timestep):
    arm = PhysicsIiwa(bar_scene(box=False), PhysicsSettings(timestep=timestep))
    q0 = np.array([0.2, 0.3, -0.4, -1.2, 0.3, 0.6, -0.5])
    arm.reset(q0)
    lag = []
    setpoint = ramp(arm, q0, q0 + 0.45, 1.5, lambda a: lag.append(gap(a.setpoint, a.q)))
    assert max(lag) > D_DIST          # it lags while moving (0.3 rad/s on every joint)
    hold = []
    for _ in range(150):
        arm.advance(setpoint, 0.01)
        hold.append((gap(setpoint, arm.q), float(np.abs(arm.qdot).max())))
    gaps, speeds = np.array(hold).T
    settled = int(np.argmax(gaps < D_DIST))
    assert gaps[settled] < D_DIST and settled < 50               # within 0.5 s
    assert np.all(gaps[settled:] < D_DIST)                       # and stays there
    assert np.all(np.diff(gaps[50:]) <= 1e-9)                    # decaying, not swinging
    assert speeds[-50:].max() < 0.01 and gaps[-1] < 0.005


def blocked_run(settings=None, seconds=3.0):
    """Push the bar into the slab (A2 forward 0.3 rad in 1 s), then hold; return records."""
    goal = START + np.array([0, 0.3, 0, 0, 0, 0, 0])
    arm = PhysicsIiwa(bar_scene(goal=goal), settings)
    forces, torque_ratio = [], []

    def record(a):
        forces.append(sum(c.force for c in a.contacts()))
        torque_ratio.append(float((np.abs(a.tau_measured) / a.effort).max()))

    setpoint = ramp(arm, START, goal, 1.0, record)
    arm.advance(setpoint, 0.5)
    settled = (arm.q, arm.flange_pose()[0])
    for _ in range(round(seconds / 0.01)):
        arm.advance(setpoint, 0.01)
        record(arm)
    return arm, setpoint, settled, np.array(forces), np.array(torque_ratio)


def test_a_blocked_arm_stalls_well_above_d_dist_and_friction_does_not_creep():
    arm, setpoint, (q_settled, x_settled), forces, torque_ratio = blocked_run()
    assert gap(setpoint, arm.q) > 3 * D_DIST
    assert np.linalg.norm(arm.flange_pose()[0] - x_settled) < 1e-3    # < 1 mm in 3 s
    assert gap(q_settled, arm.q) < 1e-3
    contacts = arm.contacts()
    assert contacts
    assert {(c.robot_geom, c.scene_geom) for c in contacts} == {('object/0', 'slab')}
    assert forces[-1] > 10 and forces.max() < 1000
    for c in contacts:
        assert c.normal[2] > 0.9 and c.force > 0            # the slab pushes the bar up
        assert c.robot_body == 'grasped_object' and c.scene_body == 'slab'
    assert torque_ratio.max() <= 1 + 1e-9


def test_external_torque_is_the_contact_force_mapped_to_the_joints():
    arm, *_ = blocked_run(seconds=0.2)
    # no joint is at a limit, so all constraint force is contact force
    np.testing.assert_allclose(arm.tau_external, arm.data.qfrc_constraint[:7], atol=1e-6)
    assert abs(arm.tau_external[1]) > 5                    # A2 is held back
    # a ball under the bar: MuJoCo lists the scene's geom first in that contact (a sphere
    # before the bar's capsule), so the robot is the contact's second geom
    pos, rot = ARM.tip_frames(START)
    ball = {'type': 'sphere', 'radius': 0.05,
            'position': (pos[0] + 0.15 * rot[0][:, 2] - [0, 0, 0.066]).tolist()}
    goal = START + np.array([0, 0.3, 0, 0, 0, 0, 0])
    arm = PhysicsIiwa(scene_from_dict({'start': START.tolist(), 'goal': goal.tolist(),
                                       'object': {'mass': 0.5, 'shapes': [BAR]},
                                       'obstacles': [ball]}))
    ramp(arm, START, goal, 1.0)
    arm.advance(goal, 0.2)
    assert arm.model.geom(int(arm.data.contact.geom[0][1])).name == 'object/0'
    np.testing.assert_allclose(arm.tau_external, arm.data.qfrc_constraint[:7], atol=1e-6)
    assert abs(arm.tau_external[1]) > 5
    (contact,) = arm.contacts()
    assert contact.normal @ (contact.position - ball['position']) > 0   # out of the ball


def test_torques_never_exceed_the_urdf_efforts_even_when_the_law_asks_for_more():
    stiff = PhysicsSettings(stiffness=(5000.0,) * 7)
    arm, setpoint, _, _, torque_ratio = blocked_run(stiff, seconds=0.5)
    assert torque_ratio.max() == pytest.approx(1.0)           # some drive saturates
    tau = arm.tau_measured
    assert np.all(np.abs(tau) <= arm.effort + 1e-9)
    assert np.any(np.abs(5000.0 * (setpoint - arm.q)) > arm.effort)


def test_measured_torque_at_rest_is_the_gravity_torque_and_external_torque_zero():
    arm = PhysicsIiwa(bar_scene(mass=1.0, box=False), FREE_SPACE)
    for q in REST_CONFIGS:
        arm.reset(q)
        arm.advance(q, 0.05)
        np.testing.assert_allclose(arm.tau_measured, arm.data.qfrc_bias[:7], atol=1e-9)
        assert np.abs(arm.tau_measured[1:4]).max() > 1.0 or abs(q[1]) < 0.1
        np.testing.assert_array_equal(arm.tau_external, np.zeros(7))
        assert arm.contacts() == []


def test_a_load_model_error_of_1_kg_leaves_a_gap_above_d_dist_at_rest():
    results = {}
    for error in (0.0, 1.0, -1.0):
        arm = PhysicsIiwa(bar_scene(mass=1.5, box=False),
                          PhysicsSettings(object_mass_error=error))
        arm.advance(START, 2.0)
        results[error] = arm.q - START
        assert np.abs(arm.qdot).max() < 1e-3
    assert np.abs(results[0.0]).sum() < 1e-9
    assert np.abs(results[1.0]).sum() > D_DIST                 # a false block
    height = {e: ARM.positions(START + dq)[0, 2] for e, dq in results.items()}
    assert height[1.0] < height[0.0] < height[-1.0]            # too heavy sags, too light lifts


def test_in_collision_is_kinematic_and_leaves_the_simulation_alone():
    goal = START + np.array([0, 0.3, 0, 0, 0, 0, 0])
    runs = []
    for probe in (False, True):
        arm = PhysicsIiwa(bar_scene(goal=goal))
        for k in range(1, 31):
            if probe:
                assert not arm.in_collision(START)
                assert arm.in_collision(goal)
            arm.advance(START + (goal - START) * k / 30, 0.01)
        runs.append((arm.q, arm.qdot, arm.time))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


def test_in_collision_clearance_counts_near_misses():
    arm = PhysicsIiwa(bar_scene())
    assert not arm.in_collision(START)
    # the bar's lowest point is 1.6 cm above the slab
    assert arm.in_collision(START, clearance=0.02)
    assert not arm.in_collision(START, clearance=0.012)


def test_a_long_advance_is_the_same_as_one_per_period_and_damping_follows_the_arm():
    # D(q) is recomputed every damping_update (10 ms) within one call too: holding a
    # setpoint for 1 s in one call moves the arm as 100 calls of 10 ms do, and at the end
    # the damping is KUKA's law at where the arm went, not where the call began
    goal = START + np.array([0.5, -0.6, 0.4, 0.9, 0.3, -0.5, 0.5])
    once, per_period = PhysicsIiwa(bar_scene(box=False)), PhysicsIiwa(bar_scene(box=False))
    once.advance(goal, 1.0)
    for _ in range(100):
        per_period.advance(goal, 0.01)
    np.testing.assert_array_equal(once.q, per_period.q)
    np.testing.assert_array_equal(once.qdot, per_period.qdot)
    full = np.zeros((7, 7))
    mujoco.mj_fullM(once.model, once.data, full)
    expected = 2 * 0.7 * np.sqrt(200.0 * np.diag(full))
    np.testing.assert_allclose(-once.model.actuator_biasprm[:, 2], expected, rtol=0.02)


def test_advance_keeps_the_callers_clock_with_durations_that_are_not_whole_steps():
    arm = PhysicsIiwa()
    for _ in range(40):
        arm.advance(np.zeros(7), 0.0125)
    assert arm.time == pytest.approx(0.5, abs=1e-12)
    with pytest.raises(ValueError):
        arm.advance(np.full(7, np.nan), 0.01)
    with pytest.raises(ValueError, match='negative'):
        PhysicsIiwa(bar_scene(mass=0.5), PhysicsSettings(object_mass_error=0.6))
    PhysicsIiwa(bar_scene(mass=0.5), PhysicsSettings(object_mass_error=0.5))  # no load data


def test_settings_refuse_values_the_simulation_cannot_run_with():
    for bad in ({'stiffness': (200.0,) * 6}, {'timestep': 0.0}, {'damping_ratio': -1.0},
                {'timestep': 0.004, 'contact_timeconst': 0.005}):
        with pytest.raises(ValueError):
            PhysicsSettings(**bad)


def _object_turn_in_grasp(arm):
    """Return the angle [rad] between the object's frame and the flange's."""
    from probdis_ros.physics.model import OBJECT_BODY
    relative = arm.flange_pose()[1].T @ arm.data.body(OBJECT_BODY).xmat.reshape(3, 3)
    return float(np.arccos(np.clip((np.trace(relative) - 1) / 2, -1.0, 1.0)))


def test_a_grasp_that_gives_turns_the_object_when_pressed_and_a_welded_one_does_not():
    goal = START + np.array([0, 0.25, 0, 0, 0, 0, 0])       # the bar's tip into the slab
    turns, forces = {}, {}
    for stiffness in (0.0, 20.0):
        arm = PhysicsIiwa(bar_scene(), PhysicsSettings(grasp_stiffness=stiffness))
        assert arm.model.nv == 7 + (3 if stiffness else 0)
        ramp(arm, START, goal, 1.0)
        arm.advance(goal, 0.5)
        turns[stiffness] = _object_turn_in_grasp(arm)
        forces[stiffness] = np.abs(arm.tau_external).max()
        assert arm.q.shape == (7,)
    assert turns[0.0] < 1e-9 and forces[0.0] > 1.0                 # pressed, not turned
    # pressed, the spring gives: about torque / stiffness (a few degrees at 20 Nm/rad)
    assert 0.02 < turns[20.0] < 0.5
    with pytest.raises(ValueError, match='grasp_stiffness'):
        PhysicsSettings(grasp_stiffness=-1.0)


def test_a_gate_given_as_either_sign_of_its_quaternion_is_one_gate():
    # q and -q are one orientation: a gate written either way is solid to the object held so
    pos = ARM.tip_frames(START)[0]
    quat = ARM.fk(START[None]).orientations[0]
    for sign in (1.0, -1.0):
        wall = {'type': 'sphere', 'radius': 0.03, 'position': (pos[0] + [0, 0, -0.3]).tolist(),
                'gate': {'orientation': (sign * quat).tolist(), 'tolerance': 0.1}}
        arm = PhysicsIiwa(scene_from_dict({'start': START.tolist(), 'goal': START.tolist(),
                                           'obstacles': [wall]}))
        assert arm.gates_solid().all(), sign


def test_a_hinged_obstacle_turns_about_its_files_axis_and_its_weight_does_not_turn_it():
    # clutter that yields: the hinge's axis and point are given in the base frame, whatever
    # the obstacle's own rotation; the hinge carries its weight, so at rest it keeps its pose
    flap = {'type': 'box', 'size': [0.16, 0.24, 0.02], 'position': [0.5, 0.2, 0.3],
            'rpy': [0.0, 0.0, 0.7], 'mass': 0.3,
            'hinge': {'point': [0.5, 0.08, 0.3], 'axis': [1, 0, 0], 'stiffness': 20.0,
                      'damping': 0.5}}
    arm = PhysicsIiwa(scene_from_dict({'start': START.tolist(), 'goal': START.tolist(),
                                       'obstacles': [flap]}), FREE_SPACE)
    hinge = arm.model.joint('obstacles[0]/hinge').id
    np.testing.assert_allclose(arm.data.xaxis[hinge], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(arm.data.xanchor[hinge], [0.5, 0.08, 0.3], atol=1e-12)
    arm.advance(START, 1.0)
    assert abs(arm.data.qpos[arm.model.jnt_qposadr[hinge]]) < 1e-9
