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
The package installs three ways and finds its config and URDF in each.

colcon build (as on a ROS machine), ``pip install .`` and the editable install that
``make`` uses.  Each runs the real installed ``probdis`` executable.
"""

import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import sysconfig
import time

from catkin_pkg.package import parse_package
from conftest import copy_source_tree, next_domain, ROOT, run_probdis
import probdis_ros
import pytest

BIN = Path(sys.executable).parent


def test_package_xml_declares_every_dependency():
    package = parse_package(str(ROOT / 'package.xml'))
    assert package.package_format == 3 and package.name == 'probdis_ros'
    assert package.get_build_type() == 'ament_python'
    run = {d.name for d in package.exec_depends}
    for key in ('rclpy', 'sensor_msgs', 'trajectory_msgs', 'std_msgs', 'std_srvs',
                'visualization_msgs', 'diagnostic_msgs', 'python3-numpy', 'pinocchio',
                'geometry_msgs', 'rcl_interfaces', 'rosgraph_msgs', 'launch_ros',
                'robot_state_publisher', 'rviz2'):
        assert key in run, key
    # rosdep has no pip keys for these on Ubuntu 24.04: `rosdep install` would stop at them
    assert not [key for key in run if key.endswith('-pip')]
    tests = {d.name for d in package.test_depends}
    assert {'ament_copyright', 'ament_flake8', 'ament_pep257', 'python3-pytest'} <= tests


def _pins(name: str) -> dict[str, str]:
    """Return a requirements file's pins, package (extras dropped) to version."""
    pins = {}
    for line in (ROOT / '.ci' / 'requirements' / name).read_text().splitlines():
        if line.strip() and not line.startswith('#'):
            package, version = line.split('==')
            pins[package.split('[')[0].lower()] = version.strip()
    return pins


def test_a_robot_pc_installs_the_versions_the_tests_run_with():
    # the robot PC takes numpy, matplotlib and pinocchio from apt, the rest from PyPI
    # (ros-machine.txt): pinned as here, so that it runs the code the tests ran
    robot, tested = _pins('ros-machine.txt'), _pins('pypi.txt')
    assert set(robot) == {'numba', 'llvmlite', 'ruckig', 'rosbags', 'mujoco', 'dask'}
    assert {package: tested[package] for package in robot} == robot
    assert _pins('numpy1-pinocchio.txt')['pin'] == tested['pin']


@pytest.mark.ros
def test_colcon_build_installs_the_executable_and_the_share_files(tmp_path):
    source = copy_source_tree(tmp_path / 'src' / 'probdis_ros')
    build = subprocess.run(
        [str(BIN / 'colcon'), 'build', '--base-paths', str(source.parent)],
        cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout + build.stderr
    install = tmp_path / 'install'
    exe = install / 'probdis_ros' / 'lib' / 'probdis_ros' / 'probdis'
    assert exe.exists()
    share = install / 'probdis_ros' / 'share' / 'probdis_ros'
    assert (share / 'urdf' / 'iiwa14.urdf').exists()
    assert (share / 'config' / 'planner.yaml').exists()
    assert (share / 'config' / 'planner_t1.yaml').exists()
    assert (share / 'config' / 'scenes' / 'demo_hook.yaml').exists()
    assert (share / 'config' / 'launch' / 'probdis_mock.launch.py').exists()
    assert (share / 'config' / 'rviz' / 'probdis.rviz').exists()
    script = f'source {install}/setup.bash && {exe} --help >/dev/null && {exe} info --json'
    env = {k: v for k, v in os.environ.items() if k not in ('AMENT_PREFIX_PATH', 'PYTHONPATH')}
    run = subprocess.run(['bash', '-c', script], capture_output=True, text=True, timeout=120,
                         env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    info = json.loads(run.stdout)
    assert info['found_by'] == 'ament index'
    assert Path(info['share']) == share
    # ros2 run probdis_ros planner_node, without the ros2 CLI: the installed executable, with
    # the README's parameter files for the real arm in T1 (a name the node does not declare
    # would end it, exit 2)
    node = install / 'probdis_ros' / 'lib' / 'probdis_ros' / 'planner_node'
    env['ROS_DOMAIN_ID'] = str(next_domain())
    started = subprocess.Popen(
        ['bash', '-c', f'source {install}/setup.bash && exec {node} --ros-args --params-file '
                       f'{share}/config/planner.yaml --params-file '
                       f'{share}/config/planner_t1.yaml -p map_file:={tmp_path}/map.json'],
        env=env, stderr=subprocess.PIPE, text=True)
    try:
        # a fresh install compiles the planner's kernels at the first start (tens of seconds)
        deadline = time.monotonic() + 240
        for line in started.stderr:
            if 'probdis_planner ready' in line or time.monotonic() > deadline:
                break
        assert 'probdis_planner ready' in line
    finally:
        started.send_signal(signal.SIGINT)
        assert started.wait(20) == 0


def test_pip_install_puts_data_files_under_the_prefix(tmp_path):
    source = copy_source_tree(tmp_path / 'src')
    venv = tmp_path / 'venv'
    subprocess.run([sys._base_executable, '-m', 'venv', '--without-pip', str(venv)], check=True)
    site = Path(sysconfig.get_path('purelib', vars={'base': str(venv), 'platbase': str(venv)}))
    # the new environment borrows this one's libraries (numpy, pinocchio, ...), not its code
    here = sysconfig.get_path('purelib')
    (site / 'borrow.pth').write_text(f'import site; site.addsitedir({here!r})\n')
    install = subprocess.run(
        [sys.executable, '-m', 'pip', '--python', str(venv / 'bin' / 'python'), 'install',
         '--quiet', '--no-deps', '--no-build-isolation', str(source)],
        capture_output=True, text=True, timeout=600)
    assert install.returncode == 0, install.stdout + install.stderr
    env = {k: v for k, v in os.environ.items() if k not in ('AMENT_PREFIX_PATH', 'PYTHONPATH')}
    run = subprocess.run([str(venv / 'bin' / 'probdis'), 'info', '--json'], capture_output=True,
                         text=True, timeout=120, env=env, cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    info = json.loads(run.stdout)
    assert info['found_by'] == 'python prefix'
    assert Path(info['share']) == venv / 'share' / 'probdis_ros'
    assert Path(info['urdf']).exists()


@pytest.mark.skipif(Path(probdis_ros.__file__).resolve().parent.parent != ROOT,
                    reason='the package under test is not the editable install of this tree')
def test_editable_install_reads_the_source_tree():
    assert (BIN / 'probdis').exists(), 'the editable install must put probdis next to python'
    info = json.loads(run_probdis('info', '--json').stdout)
    assert info['found_by'] == 'source tree' and Path(info['share']) == ROOT
