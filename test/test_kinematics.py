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

"""Forward kinematics: compiled chain against pinocchio and yourdfpy, planar arm by hand."""

from pathlib import Path

import numpy as np
import pinocchio as pin
from probdis_ros.model import arm_for_setting, iiwa_arm, PlanarArm
from probdis_ros.model.arms import rotation_to_quaternion
from probdis_ros.resources import data_file
import pytest
import yourdfpy

URDF = data_file('urdf', 'iiwa14.urdf')


def random_configs(arm, n, seed=0):
    return arm.random_configurations(np.random.default_rng(seed), n)


def same_rotation(q1, q2):
    """Quaternions q and -q are the same rotation."""
    return min(np.abs(q1 - q2).max(), np.abs(q1 + q2).max())


def test_urdf_joints_and_limits_match_the_iiwa14_datasheet():
    arm = iiwa_arm()
    assert arm.joint_names == tuple(f'lbr_A{i}' for i in range(1, 8))
    deg = [170, 120, 170, 120, 170, 120, 175]
    np.testing.assert_allclose(arm.upper, np.radians(deg), atol=1e-6)
    np.testing.assert_allclose(arm.lower, -np.radians(deg), atol=1e-6)
    np.testing.assert_allclose(arm.velocity_limits, np.radians([85, 85, 100, 75, 130, 135, 135]),
                               atol=1e-6)


def test_zero_configuration_is_the_arm_straight_up():
    pose = iiwa_arm().fk(np.zeros(7))
    np.testing.assert_allclose(pose.positions[0], [0, 0, 0.36 + 0.42 + 0.40 + 0.126], atol=1e-12)
    np.testing.assert_allclose(pose.orientations[0], [1, 0, 0, 0], atol=1e-12)


def test_flange_pose_matches_pinocchio_at_random_configurations():
    arm = iiwa_arm()
    configs = random_configs(arm, 200, seed=1)
    pose = arm.fk(configs)
    model = pin.buildModelFromUrdf(str(URDF))
    data = model.createData()
    frame = model.getFrameId('lbr_link_ee')
    for q, x, quat in zip(configs, pose.positions, pose.orientations):
        pin.framesForwardKinematics(model, data, q)
        placement = data.oMf[frame]
        np.testing.assert_allclose(x, placement.translation, atol=1e-12)
        xyzw = pin.Quaternion(placement.rotation).coeffs()
        assert same_rotation(quat, np.r_[xyzw[3], xyzw[:3]]) < 1e-9


def test_pinocchio_and_yourdfpy_agree_on_the_urdf():
    robot = yourdfpy.URDF.load(str(URDF), load_meshes=False, build_collision_scene_graph=False)
    assert robot.actuated_joint_names == list(iiwa_arm().joint_names)
    model = pin.buildModelFromUrdf(str(URDF))
    data = model.createData()
    frame = model.getFrameId('lbr_link_ee')
    for q in random_configs(iiwa_arm(), 50, seed=2):
        robot.update_cfg(q)
        pin.framesForwardKinematics(model, data, q)
        np.testing.assert_allclose(robot.get_transform('lbr_link_ee', 'lbr_link_0'),
                                   data.oMf[frame].homogeneous, atol=1e-12)


def test_batch_equals_loop():
    for setting in ('2d', '3d', '3d-orient'):
        arm = arm_for_setting(setting)
        configs = random_configs(arm, 64, seed=3)
        batch = arm.fk(configs)
        for i, q in enumerate(configs):
            one = arm.fk(q)
            np.testing.assert_array_equal(one.positions[0], batch.positions[i])
            if batch.orientations is not None:
                np.testing.assert_array_equal(one.orientations[0], batch.orientations[i])


def test_task_spaces_of_the_three_settings():
    assert arm_for_setting('2d').fk(np.zeros(7)).positions.shape == (1, 2)
    assert arm_for_setting('3d').fk(np.zeros(7)).orientations is None
    assert arm_for_setting('3d-orient').fk(np.zeros((5, 7))).orientations.shape == (5, 4)
    with pytest.raises(ValueError, match='unknown setting'):
        arm_for_setting('4d')


def test_planar_arm_by_hand():
    arm = PlanarArm(link_lengths=(0.1,) * 7)
    q = np.array([np.pi / 2, -np.pi / 2, 0, 0, 0, 0, np.pi / 2])
    # link 1 points up (0, 0.1); links 2-6 point right (0.5, 0); link 7 points up (0, 0.1)
    np.testing.assert_allclose(arm.fk(q).positions[0], [0.5, 0.2], atol=1e-12)
    np.testing.assert_allclose(arm.fk(np.zeros(7)).positions[0], [0.7, 0.0], atol=1e-12)
    np.testing.assert_allclose(arm.link_points(q)[-1], [0.5, 0.2], atol=1e-12)


def test_wrong_joint_count_is_refused_with_a_clear_message():
    with pytest.raises(ValueError, match='expected configurations with 7 joints'):
        iiwa_arm().fk(np.zeros(6))


def test_limits_mask_and_random_configurations_stay_inside():
    arm = iiwa_arm()
    configs = random_configs(arm, 1000, seed=4)
    assert arm.within_limits(configs).all()
    outside = configs[:3].copy()
    outside[:, 1] = arm.upper[1] + 0.01
    assert not arm.within_limits(outside).any()


def test_quaternions_are_unit_with_nonnegative_w():
    quats = iiwa_arm().fk(random_configs(iiwa_arm(), 500, seed=5)).orientations
    np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-12)
    assert (quats[:, 0] >= 0).all()


def test_rotation_to_quaternion_near_half_turns():
    # rotations by pi about x, y and z: w = 0 and the sign must come out consistent
    for axis in np.eye(3):
        rot = 2 * np.outer(axis, axis) - np.eye(3)
        quat = rotation_to_quaternion(rot[None])[0]
        assert same_rotation(quat, np.r_[0.0, axis]) < 1e-12


def rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Return the rotation matrix of angle about a unit axis (Rodrigues)."""
    cross = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                      [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def test_rotation_to_quaternion_of_half_turns_about_diagonal_axes():
    """Shepperd's method: signs from the matrix, not from rounding noise near half-turns."""
    from probdis_ros.model.arms import quaternion_to_rotation

    rng = np.random.default_rng(7)
    axes = [np.array([1.0, 1.0, 0.0]) / np.sqrt(2), np.array([1.0, 1.0, 1.0]) / np.sqrt(3),
            np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])]
    axes += list(rng.normal(size=(30, 3)))
    rotations = []
    for axis in axes:
        axis = axis / np.linalg.norm(axis)
        for angle in (np.pi, np.pi - 1e-9, np.pi - 1e-5, np.pi / 2):
            rotations.append(rotation_about(axis, angle))
    rotations = np.array(rotations)
    quats = rotation_to_quaternion(rotations)
    np.testing.assert_allclose(np.linalg.norm(quats, axis=1), 1.0, atol=1e-12)
    assert (quats[:, 0] >= 0).all()
    back = quaternion_to_rotation(quats)
    assert np.abs(back - rotations).max() < 1e-12


@pytest.mark.parametrize('setting', ['3d', '3d-orient'])
def test_positions_alone_are_the_chain_kernels_positions(setting):
    """The positions-only kernel skips the flange joint and the rotations, not a bit."""
    from probdis_ros.model.kinematics import chain_kernel, position_joints

    arm = arm_for_setting(setting)
    configs = random_configs(arm, 20_000, seed=5)
    positions = np.empty((len(configs), 3))
    chain_kernel(configs, *arm.kernel_params(), positions, np.empty((len(configs), 3, 3)))
    np.testing.assert_array_equal(arm.positions(configs), positions)
    np.testing.assert_array_equal(arm.positions(configs), arm.fk(configs).positions)
    rows = np.arange(len(configs)) % 3 == 0
    some = arm.positions(configs, rows)
    np.testing.assert_array_equal(some[rows], positions[rows])
    assert not some[~rows].any()
    _, codes, *_, tip_offset, _ = arm.kernel_params()
    assert position_joints(codes, tip_offset) == 6     # the flange joint turns in place


def test_the_fast_sines_and_cosines_are_libms_within_two_ulp():
    """The samples' kinematics may use them: off by rounding, never by a wrong quadrant."""
    from probdis_ros.model.fast_math import sincos_into

    x = np.concatenate([np.random.default_rng(7).uniform(-7.0, 7.0, 200_000),
                        np.arange(-8, 9) * (np.pi / 4), [0.0, -0.0, 1e-300, 3.05, -3.05]])
    sines, cosines = np.empty_like(x), np.empty_like(x)
    sincos_into(x, sines, cosines)
    for fast, exact in ((sines, np.sin(x)), (cosines, np.cos(x))):
        error = np.abs(fast - exact)
        assert error.max() <= 2.3e-16 * 4           # absolute, also where the value is ~0
        big = np.abs(exact) > 1e-3
        assert (error[big] <= 2 * np.spacing(np.abs(exact[big]))).all()


@pytest.mark.parametrize('setting', ['2d', '3d', '3d-orient'])
def test_sample_positions_are_the_positions_to_rounding(setting):
    """The planner's samples are posed fast, within 1e-15 m, and only the rows asked."""
    arm = arm_for_setting(setting)
    configs = random_configs(arm, 5_000, seed=8)
    rows = np.arange(len(configs)) % 4 != 1
    fast = arm.sample_positions(configs, rows)
    exact = arm.positions(configs)
    np.testing.assert_allclose(fast[rows], exact[rows], rtol=0, atol=1e-15)
    assert not fast[~rows].any()


def test_planar_positions_of_some_rows():
    arm = PlanarArm()
    configs = random_configs(arm, 50, seed=6)
    rows = np.arange(50) % 2 == 1
    some = arm.positions(configs, rows)
    np.testing.assert_array_equal(some[rows], arm.fk(configs[rows]).positions)
    assert not some[~rows].any()


def test_a_change_to_any_kernel_file_drops_every_cached_kernel(tmp_path):
    """Numba alone would keep a caller's machine code when only its callee's file changed."""
    import shutil

    from probdis_ros.model import kernel_cache

    sources = tmp_path / 'src'
    sources.mkdir()
    for name in kernel_cache.KERNEL_FILES:
        shutil.copy(Path(kernel_cache.__file__).parent / name, sources / name)
    before = kernel_cache.kernel_digest(sources)
    with open(sources / 'edge_kernels.py', 'a') as f:
        f.write('# changed\n')
    after = kernel_cache.kernel_digest(sources)
    assert after != before

    cache = tmp_path / 'cache'
    cache.mkdir()
    names = ['tree_kernels.grow_kernel-175.py311.nbi', 'tree_kernels.grow_kernel-175.py311.1.nbc',
             'fast_math.sincos-60.py311.nbi', 'other.kernel-1.py311.nbi', 'tree_kernels.pyc']
    for name in names:
        (cache / name).write_text('x')
    assert kernel_cache.drop_stale_kernels(cache, before)         # no stamp yet: dropped
    assert sorted(p.name for p in cache.iterdir()) == [
        'other.kernel-1.py311.nbi', kernel_cache.STAMP, 'tree_kernels.pyc']
    (cache / names[0]).write_text('x')
    assert not kernel_cache.drop_stale_kernels(cache, before)     # same sources: kept
    assert (cache / names[0]).exists()
    assert kernel_cache.drop_stale_kernels(cache, after)          # edge_kernels.py changed
    assert not (cache / names[0]).exists()


def test_every_file_with_compiled_kernels_is_in_the_caches_digest():
    from probdis_ros.model import kernel_cache

    package = Path(kernel_cache.__file__).parents[1]
    compiled = {path.relative_to(package).as_posix() for path in package.rglob('*.py')
                if 'numba.njit' in path.read_text()}
    assert compiled == {f'model/{name}' for name in kernel_cache.KERNEL_FILES}
