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

"""The ``probdis`` command line, run as a real process."""

from itertools import pairwise
import json
import subprocess

import numpy as np
from probdis_ros.model import FailureMap, TaskSpace


def test_help_lists_the_subcommands(probdis):
    out = probdis('--help').stdout
    for command in ('info', 'fk', 'bench', 'map'):
        assert command in out


def test_sweep_help_names_every_idea_of_the_informed_method(probdis):
    from probdis_ros.planning.informed import IDEAS
    out = ' '.join(probdis('experiment', 'sweep', '--help').stdout.split())
    assert f'letters of {IDEAS})' in out


def test_fk_json_at_zero_is_straight_up(probdis):
    doc = json.loads(probdis('fk', '--json', *['0'] * 7).stdout)
    np.testing.assert_allclose(doc['position'], [0, 0, 1.306], atol=1e-9)
    np.testing.assert_allclose(doc['quaternion_wxyz'], [1, 0, 0, 0], atol=1e-9)
    assert doc['within_limits'] is True


def test_fk_planar_and_limit_warning(probdis):
    doc = json.loads(probdis('fk', '--setting', '2d', '--json', *['0'] * 7).stdout)
    np.testing.assert_allclose(doc['position'], [0.7, 0.0], atol=1e-12)
    result = probdis('fk', '0', '3', '0', '0', '0', '0', '0')
    assert 'outside the joint limits' in result.stderr


def test_fk_with_the_wrong_joint_count_is_a_clear_error(probdis):
    result = probdis('fk', '0.1', '0.2', '0.3', check=False)
    assert result.returncode == 2
    assert 'has 7 joints' in result.stderr and 'got 3 values' in result.stderr
    assert 'Traceback' not in result.stderr


def test_bench_fk_json_prints_the_figure(probdis):
    result = probdis('bench', 'fk', '--json', '--configs', '5000', '--repeats', '2')
    doc = json.loads(result.stdout)
    assert list(doc) == ['configs_per_s']
    assert isinstance(doc['configs_per_s'], float) and doc['configs_per_s'] > 0


def test_map_plot_writes_a_png(probdis, tmp_path):
    out = tmp_path / 'figs' / 'map.png'
    result = probdis('map', 'plot', '--out', str(out))
    assert out.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert '3 failures' in result.stdout


def test_map_plot_of_a_saved_map(probdis, tmp_path):
    fmap = FailureMap(TaskSpace.POINT2)
    fmap.add([0.1, 0.2], [0.0, 1.0])
    fmap.save(tmp_path / 'map.json')
    probdis('map', 'plot', '--map', str(tmp_path / 'map.json'), '--out', str(tmp_path / 'm.png'))
    assert (tmp_path / 'm.png').stat().st_size > 1000


def test_map_plot_refuses_bad_maps_clearly(probdis, tmp_path):
    fmap = FailureMap(TaskSpace.POINT3)
    fmap.add([0.1, 0.2, 0.3], [0.0, 1.0, 0.0])
    fmap.save(tmp_path / 'map3d.json')
    result = probdis('map', 'plot', '--map', str(tmp_path / 'map3d.json'), check=False)
    assert result.returncode == 2 and 'draws 2-D maps' in result.stderr
    (tmp_path / 'bad.json').write_text('{"format": "probdis-failure-map", "vers')
    result = probdis('map', 'plot', '--map', str(tmp_path / 'bad.json'), check=False)
    assert result.returncode == 2 and 'truncated or corrupt' in result.stderr


def test_sim_json_prints_the_episode(probdis):
    result = probdis('sim', '--setting', '2d', '--obstacles', '10', '--seed', '4', '--json')
    doc = json.loads(result.stdout)
    assert list(doc) == ['success', 'paths', 'failures', 'empty_plans', 'plan_times_s']
    assert 0 <= doc['empty_plans'] <= doc['paths']
    assert isinstance(doc['success'], bool) and 1 <= doc['paths'] <= 20
    assert len(doc['plan_times_s']) == doc['paths']
    again = json.loads(probdis('sim', '--setting', '2d', '--obstacles', '10', '--seed', '4',
                               '--json').stdout)
    assert (again['success'], again['paths'], again['failures']) == \
        (doc['success'], doc['paths'], doc['failures'])


def test_sim_of_the_shipped_scenario_with_a_plot(probdis, tmp_path):
    out = tmp_path / 'demo.png'
    from probdis_ros.planning.informed import DEFAULT_IDEAS

    result = probdis('sim', '--scenario', 'demo_2d', '--plot', str(out))
    # the default method, named by its ideas
    assert f'demo_2d: informed:{DEFAULT_IDEAS}: disentangled' in result.stdout
    assert out.read_bytes()[:4] == b'\x89PNG'


def test_sim_baselines_and_bad_input(probdis, tmp_path):
    for method in ('hard', 'epsilon', 'hard:0.02:3000'):
        doc = json.loads(probdis('sim', '--method', method, '--seed', '1', '--max-paths', '3',
                                 '--json').stdout)
        assert doc['paths'] <= 3
    # with a scenario the seed is the planner's: the same seed, the same episode
    runs = [json.loads(probdis('sim', '--scenario', 'demo_2d', '--seed', '1',
                               '--json').stdout) for _ in range(2)]
    assert [(r['success'], r['paths'], r['failures']) for r in runs] == \
        [(runs[0]['success'], runs[0]['paths'], runs[0]['failures'])] * 2
    (tmp_path / 'bad.yaml').write_text('setting: 2d\nstart: [0, 0]\n')
    result = probdis('sim', '--scenario', str(tmp_path / 'bad.yaml'), check=False)
    assert result.returncode == 2 and 'missing goal, obstacles' in result.stderr
    result = probdis('sim', '--setting', '3d', '--plot', str(tmp_path / 'x.png'), check=False)
    assert result.returncode == 2 and 'draws 2-D episodes' in result.stderr
    result = probdis('sim', '--method', 'hard:2', check=False)
    assert result.returncode == 2 and 'outside' in result.stderr


def test_bench_plan_json_prints_both_medians(probdis):
    doc = json.loads(probdis('bench', 'plan', '--seeds', '2', '--large', '0', '--json',
                             timeout=300).stdout)
    assert list(doc) == ['median_s_empty_map', 'median_s_19_failures']
    assert all(isinstance(v, float) and v > 0 for v in doc.values())


def test_plan_prints_a_path_on_a_saved_map(probdis, tmp_path):
    from probdis_ros.model import FailureMap, TaskSpace

    fmap = FailureMap(TaskSpace.POINT2, 100.0)
    fmap.add([0.0, 0.7], [1.0, 0.0])
    fmap.save(tmp_path / 'map.json')
    start = ['2.17', '0', '0', '0', '0', '0', '0']
    goal = ['0.97', '0', '0', '0', '0', '0', '0']
    args = ('plan', '--map', str(tmp_path / 'map.json'), '--start', *start, '--goal', *goal,
            '--iterations', '30', '--seed', '2', '--json')
    doc = json.loads(probdis(*args).stdout)
    assert list(doc) == ['path', 'cost', 'success_probability', 'plan_time_s', 'arm']
    assert doc['arm'] == 'planar'       # a 2-D map: the simulator's arm, said so
    assert doc['path'][0] == [float(v) for v in start]
    assert doc['path'][-1] == [float(v) for v in goal]
    assert 0 < doc['success_probability'] <= 1 and doc['cost'] > 0
    assert json.loads(probdis(*args).stdout)['path'] == doc['path']      # seeded
    result = probdis('plan', '--map', str(tmp_path / 'map.json'), '--start', '0', '--goal',
                     *goal, check=False)
    assert result.returncode == 2 and '--start needs 7 joint values' in result.stderr
    result = probdis(*args[:-1], '--plan-time', '0.1', check=False)
    assert result.returncode == 2 and 'not allowed with' in result.stderr


def test_plan_keeps_the_iiwa_above_its_table_as_the_planner_node_does(probdis, tmp_path):
    # plan took no table: it planned to a goal 7.5 cm below the table top, through it
    from probdis_ros.model import arm_for_setting, FailureMap
    from probdis_ros.model.table import ROBOT_TABLE

    arm = arm_for_setting('3d-orient')
    fmap = FailureMap(arm.task_space)
    fmap.save(tmp_path / 'map.json')
    start = ['0', '0.454', '0', '-1.533', '0', '1.155', '0']
    low = ['0', '2.0', '0', '0', '0', '0', '0']
    args = ('plan', '--map', str(tmp_path / 'map.json'), '--start', *start, '--goal', *low,
            '--iterations', '30', '--json')
    result = probdis(*args, check=False)
    assert result.returncode == 2 and 'below the table' in result.stderr, result.stderr
    assert len(json.loads(probdis(*args, '--no-table').stdout)['path']) >= 2
    high = ['0.5', '0.3', '0', '-1.2', '0', '0.8', '0']
    path = np.array(json.loads(probdis(*args[:12], *high, '--iterations', '30',
                                       '--json').stdout)['path'])
    steps = np.concatenate([a + np.linspace(0, 1, 50)[:, None] * (b - a)
                            for a, b in pairwise(path)])
    # every edge point 5 cm above the top (the clearance); between them, above the top
    assert arm.on_table(ROBOT_TABLE).lowest_heights(steps).min() > ROBOT_TABLE.height
    outside = ['4.0', *start[1:]]
    result = probdis(*args[:4], *outside, *args[11:], check=False)
    assert result.returncode == 2 and 'A1 at 4 rad is outside its limits' in result.stderr
    near = ['2.966', *high[1:]]             # 1.1 mrad inside A1's limit, as the node refuses
    result = probdis(*args[:12], *near, '--json', check=False)
    assert result.returncode == 2 and 'lbr_A1 at 2.96600 rad lies 0.00106 rad from its ' \
        'limit 2.96706, nearer than 0.035 (joint_margin)' in result.stderr, result.stderr
    # the node's margin from the joint limits: informed's probes from a wrist near its limit
    # put via points on it (the driver ends its session there); a map of 19 failures about
    # the workspace and 10 on the straight way
    rng = np.random.default_rng(4)
    pose = arm.fk(arm.random_configurations(rng, 19))
    for x, q in zip(pose.positions, pose.orientations):
        fmap.add(x, rng.normal(size=3), q)
    ends = np.array([[0.3, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0], [-0.9, 0.4, 0.3, -1.0, 0.5, 1.0, 0.4]])
    pose = arm.fk(ends[0] + np.linspace(0, 1, 10)[:, None] * (ends[1] - ends[0]))
    for x, q in zip(pose.positions, pose.orientations):
        fmap.add(x, np.array([0.0, 0.0, 1.0]), q)
    fmap.save(tmp_path / 'map.json')
    ends[0, 5] = arm.upper[5] - 0.05
    doc = json.loads(probdis(*args[:3], '--start', *map(str, ends[0]), '--goal',
                             *map(str, ends[1]), '--iterations', '100', '--seed', '0',
                             '--method', 'informed', '--json').stdout)
    via = np.array(doc['path'])[1:-1]
    assert doc['arm'] == 'iiwa14' and len(via)
    assert np.minimum(via - arm.lower, arm.upper - via).min() >= 0.035 - 1e-9
    # the ideas that change what the map learns do nothing on a map file: refused
    result = probdis(*args, '--method', 'informed:ab', check=False)
    assert result.returncode == 2 and 'probdis plan runs the informed ideas' in result.stderr


def test_the_robot_experiment_offline_is_deterministic_and_takes_detector_overrides(
        probdis, tmp_path):
    # with joint-state noise and latency too: the run index seeds the noise
    args = ('experiment', 'robot', '--offline', '--runs', '2', '--scenarios', 'demo_hook',
            '--methods', 'probabilistic', '--detection', 'gap_ceiling=0.6', '--fault',
            'noise=0.001', '--fault', 'latency=0.02', '--json')
    runs = [json.loads(probdis(*args, '--out', str(tmp_path / name), timeout=300).stdout)
            for name in ('a', 'b')]
    for records in runs:
        assert [r['run'] for r in records] == [0, 1]
        assert all(r['offline'] and r['detection'] == {'gap_ceiling': 0.6} and
                   r['faults'] == {'noise': 0.001, 'latency': 0.02} and
                   r['bag'] is None for r in records)
        assert max(r['peak_contact_force_n'] for r in records) > 0     # seed 1 touches
    keys = ('success', 'paths', 'failures', 'peak_contact_force_n', 'sim_time_s')
    assert [[r[k] for k in keys] for r in runs[0]] == [[r[k] for k in keys] for r in runs[1]]
    bad = probdis('experiment', 'robot', '--offline', '--detection', 'ceiling=1',
                  '--out', str(tmp_path / 'c'), check=False)
    assert bad.returncode == 2 and "'ceiling=1': not a detector threshold" in bad.stderr
    for fault, said in (('lag=1', "'lag=1': not a fault of the mock"),
                        ('latency=-1', 'latency must be non-negative'),
                        ('grasp_stiffness=x', "'x' is not a number"),
                        ('stiffness=0', 'stiffness must be 7 positive values'),
                        ('damping_ratio=-1', 'damping_ratio must be >= 0')):
        bad = probdis('experiment', 'robot', '--offline', '--fault', fault,
                      '--out', str(tmp_path / 'c'), check=False)
        assert bad.returncode == 2 and said in bad.stderr, bad.stderr
    bad = probdis('experiment', 'robot', '--engine', 'kinematic', '--fault', 'armature=0.1',
                  '--out', str(tmp_path / 'c'), check=False)
    assert bad.returncode == 2 and 'a fault of the physics arm' in bad.stderr
    bad = probdis('experiment', 'robot', '--offline', '--engine', 'kinematic',
                  '--scenarios', 'demo_iiwa', '--out', str(tmp_path / 'c'), check=False)
    assert bad.returncode == 2 and '--offline runs the physics scenes' in bad.stderr
    bad = probdis('experiment', 'robot', '--restarts', '2', '--out', str(tmp_path / 'c'),
                  check=False)
    assert bad.returncode == 2 and '--restarts needs --offline' in bad.stderr
    bad = probdis('experiment', 'robot', '--offline', '--restarts', '-1',
                  '--out', str(tmp_path / 'c'), check=False)
    assert bad.returncode == 2 and '--restarts must be a number >= 0' in bad.stderr
    bad = probdis('experiment', 'robot', '--detection', 'gap_ceiling=0.05',
                  '--out', str(tmp_path / 'c'), check=False)
    assert bad.returncode == 2 and 'must exceed d_dist' in bad.stderr
    # what the node refuses, refused before the nodes start (they were refused after a retry)
    bad = probdis('experiment', 'robot', '--detection', 'speed_allowance=0.2',
                  '--out', str(tmp_path / 'c'), check=False)
    assert bad.returncode == 2 and 'speed_allowance: not a parameter of the planner node' in \
        bad.stderr
    bad = probdis('experiment', 'robot', '--velocity-scaling', '0.005',
                  '--out', str(tmp_path / 'c'), check=False)
    assert bad.returncode == 2 and '--velocity-scaling in [0.01, 0.7]' in bad.stderr


def test_sim_draws_a_family_world_from_the_seed(probdis):
    runs = [json.loads(probdis('sim', '--family', 'hook_bar', '--seed', '2', '--max-paths', '3',
                               '--json').stdout) for _ in range(2)]
    assert runs[0] == {**runs[1], 'plan_times_s': runs[0]['plan_times_s']}
    assert 1 <= runs[0]['paths'] <= 3
    bad = probdis('sim', '--family', 'nope', check=False)
    assert bad.returncode == 2 and "unknown family 'nope'" in bad.stderr
    bad = probdis('sim', '--family', 'open_box', '--setting', '2d', check=False)
    assert bad.returncode == 2 and '--family draws its own world' in bad.stderr


def one_line_error(result, command: str, text: str) -> None:
    """Assert a refusal: exit 2, one stderr line naming the command and saying text."""
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert result.stderr.count('\n') == 1, result.stderr
    assert result.stderr.startswith(f'probdis {command}: error: ') and text in result.stderr, \
        result.stderr


def test_nan_negative_and_empty_values_are_refused_naming_the_flag(probdis, tmp_path):
    for args, command, text in [
            (('fk', 'nan', '0', '0', '0', '0', '0', '0'), 'fk', 'got nan'),
            (('sim', '--seed', '-1'), 'sim', '--seed must be a number >= 0, got -1'),
            (('sim', '--jtc-start', 'desired'), 'sim', '--jtc-start needs --engine physics'),
            (('bench', 'physics', '--seconds', '-1'), 'bench physics',
             '--seconds must be a positive number, got -1'),
            (('demo', '--timeout', '0'), 'demo', '--timeout must be a positive number, got 0'),
            (('demo', '--timeout', '-5'), 'demo', '--timeout must be a positive'),
            (('demo', '--arm-clock-offset', 'inf'), 'demo',
             '--arm-clock-offset must be within +-1e6 s, got inf'),
            (('experiment', 'sweep', '--plan-time', 'nan', '--out', str(tmp_path / 's')),
             'experiment sweep', '--plan-time must be a positive number, got nan'),
            (('experiment', 'sweep', '--methods', ',', '--out', str(tmp_path / 's')),
             'experiment sweep', "--methods ',' names no method"),
            (('experiment', 'robot', '--offline', '--methods', ' , ',
              '--out', str(tmp_path / 'r')), 'experiment robot', 'names no method')]:
        one_line_error(probdis(*args, check=False, timeout=60), command, text)
    assert not (tmp_path / 'r' / 'robot_runs.jsonl').exists()


def test_plan_refuses_nan_and_plans_with_the_c_fail_of_its_method(probdis, tmp_path):
    fmap = FailureMap(TaskSpace.POINT2, 100.0)
    fmap.add([0.0, 0.7], [1.0, 0.0])
    fmap.save(tmp_path / 'map.json')
    ends = ('plan', '--map', str(tmp_path / 'map.json'), '--start', '2.17', *['0'] * 6,
            '--goal', '0.97', *['0'] * 6, '--seed', '2', '--json')
    args = (*ends, '--iterations', '30')

    def cost(method):
        return json.loads(probdis(*args, '--method', method).stdout)['cost']

    # the map was saved with C_FAIL 100: probabilistic:100 is the map's own, :5 is not
    assert cost('probabilistic:100') == cost('probabilistic')
    assert cost('probabilistic:5') != cost('probabilistic')
    one_line_error(probdis(*ends, '--plan-time', 'nan', check=False), 'plan',
                   '--plan-time must be a positive number, got nan')
    bad_start = list(args)
    bad_start[bad_start.index('2.17')] = 'nan'
    one_line_error(probdis(*bad_start, check=False), 'plan', '--start values must be finite')
    assert 'informed' in ' '.join(probdis('plan', '--help').stdout.split())


def test_outputs_that_cannot_be_written_are_refused_before_the_work(probdis, tmp_path):
    afile = tmp_path / 'afile'
    afile.write_text('not a folder\n')
    for args, command, text in [
            (('experiment', 'sweep', '--out', str(afile)), 'experiment sweep',
             f'--out {afile}: not a directory'),
            (('experiment', 'sweep', '--out', str(afile / 'x')), 'experiment sweep',
             f'{afile} is not a directory'),
            (('experiment', 'robot', '--offline', '--out', str(afile)), 'experiment robot',
             f'--out {afile}: not a directory'),
            (('map', 'plot', '--out', str(afile / 'map.png')), 'map plot',
             f'{afile} is not a directory'),
            (('map', 'plot', '--out', str(tmp_path)), 'map plot', 'is a directory'),
            (('sim', '--plot', str(afile / 'sim.png')), 'sim', f'{afile} is not a directory'),
            (('sim', '--engine', 'physics', '--plot', str(tmp_path)), 'sim', 'is a directory')]:
        one_line_error(probdis(*args, check=False, timeout=60), command, text)
    assert afile.read_text() == 'not a folder\n'


def test_a_reader_that_stops_reading_ends_the_command_quietly(tmp_path):
    from conftest import probdis_command

    # `probdis ... | head -0`: stdout is closed before anything is written to it
    process = subprocess.Popen([*probdis_command(), 'fk', *['0'] * 7], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    process.stdout.close()
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 1 and stderr == ''


def test_the_robot_experiment_refuses_a_folder_of_runs_with_other_settings(probdis, tmp_path):
    record = {'scenario': 'demo_hook', 'method': 'probabilistic', 'run': 0, 'seed': 0,
              'engine': 'physics', 'velocity_scaling': 0.2, 'success': True, 'paths': 3,
              'failures': 2, 'wall_s': 1.0, 'bag': None, 'offline': True, 'detection': {}}
    runs = tmp_path / 'robot_runs.jsonl'
    runs.write_text(json.dumps(record) + '\n')
    args = ('experiment', 'robot', '--offline', '--runs', '1', '--scenarios', 'demo_hook',
            '--methods', 'probabilistic', '--out', str(tmp_path))
    for extra, text in [(('--detection', 'gap_ceiling=0.6'),
                         "detection {}, not {'gap_ceiling': 0.6}"),
                        (('--velocity-scaling', '0.5'), 'velocity_scaling 0.2, not 0.5'),
                        # runs from before the setting was kept started from the measured state
                        (('--jtc-start', 'desired'), "jtc_start 'measured', not 'desired'")]:
        one_line_error(probdis(*args, *extra, check=False), 'experiment robot',
                       f'{runs} holds runs of another experiment ({text})')
    assert runs.read_text() == json.dumps(record) + '\n'
    # the same settings: the run is there, nothing runs again
    assert '| demo_hook | 1 / 1 |' in probdis(*args).stdout


def test_an_offline_run_that_fails_is_tried_again_offline(tmp_path, monkeypatch, capsys):
    from probdis_ros import cli
    from probdis_ros.ros import robot_experiment

    calls = []

    def flaky(scenario, method, run, velocity_scaling, detection, jtc_start, faults,
              cartesian_speed_limit, restarts, guard_holds):
        calls.append((scenario, str(method), run, faults, cartesian_speed_limit, restarts,
                      guard_holds))
        if len(calls) == 1:
            raise RuntimeError('the simulation did not start')
        return {'success': True, 'paths': 2, 'failures': 1, 'bag': None}

    monkeypatch.setattr(robot_experiment, 'offline_run', flaky)
    status = cli.main(['experiment', 'robot', '--offline', '--runs', '1', '--scenarios',
                       'demo_hook', '--methods', 'informed:af', '--out', str(tmp_path),
                       '--fault', 'latency=0.02', '--cartesian-speed-limit', '0.2',
                       '--restarts', '2', '--guard-holds', '--json'])
    faults = {'latency': 0.02}
    assert status == 0 and calls == [('demo_hook', 'informed:af', 0, faults, 0.2, 2, True)] * 2
    records = json.loads(capsys.readouterr().out)
    assert [(r['success'], r['offline'], r['faults'], r['cartesian_speed_limit'],
             r['restarts'], r['guard_holds']) for r in records] == [(True, True, faults, 0.2, 2,
                                                                    True)]
    # a directory of runs with other faults is refused, naming them
    status = cli.main(['experiment', 'robot', '--offline', '--runs', '1', '--scenarios',
                       'demo_hook', '--methods', 'informed:af', '--out', str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 2 and "faults {'latency': 0.02}, not {}" in err
    assert 'cartesian_speed_limit 0.2, not 0.0' in err and 'restarts 2, not 0' in err
    assert 'guard_holds True, not False' in err


def test_the_robot_table_counts_only_the_runs_asked_for(tmp_path, monkeypatch, capsys):
    from probdis_ros import cli
    from probdis_ros.ros import robot_experiment

    def record(run, success):
        return {'scenario': 'demo_hook', 'method': 'probabilistic', 'run': run, 'seed': run,
                'engine': 'physics', 'velocity_scaling': 0.2, 'success': success,
                'paths': 3, 'failures': 2, 'wall_s': 1.0, 'bag': None, 'offline': True,
                'detection': {}}

    # an earlier --runs 3 left runs 0-2; run 0 failed, runs 1 and 2 succeeded
    (tmp_path / 'robot_runs.jsonl').write_text(
        ''.join(json.dumps(record(run, run > 0)) + '\n' for run in range(3)))

    def no_run(*args):
        raise AssertionError('every run asked for is done')

    monkeypatch.setattr(robot_experiment, 'offline_run', no_run)
    args = ['experiment', 'robot', '--offline', '--runs', '1', '--scenarios', 'demo_hook',
            '--methods', 'probabilistic', '--out', str(tmp_path)]
    assert cli.main([*args, '--json']) == 0
    assert [r['run'] for r in json.loads(capsys.readouterr().out)] == [0]
    assert cli.main(args) == 0
    assert '| demo_hook | 0 / 1 |' in capsys.readouterr().out

    # --against: the same runs of another experiment, paired run by run (the runs there
    # beyond those asked for are left out: run 0 only)
    other = tmp_path / 'other'
    other.mkdir()
    (other / 'robot_runs.jsonl').write_text(
        ''.join(json.dumps({**record(run, True), 'paths': 5}) + '\n' for run in range(3)))
    args[args.index('--runs') + 1] = '2'
    assert cli.main([*args, '--against', str(other)]) == 0
    out = capsys.readouterr().out
    assert '| probabilistic | 2 | 1 / 2 | -0.500 (-1.000 to +0.000) | 0 / 1 | 3.0 / 5.0 |' in out
    assert cli.main([*args, '--against', str(tmp_path / 'none')]) == 2
    assert 'no robot_runs.jsonl there' in capsys.readouterr().err


def test_a_robot_run_of_the_bare_informed_of_before_is_run_again(
        tmp_path, monkeypatch, capsys):
    from probdis_ros import cli
    from probdis_ros.planning.informed import DEFAULT_IDEAS
    from probdis_ros.ros import robot_experiment

    old = {'scenario': 'demo_hook', 'method': 'informed', 'run': 0, 'seed': 0,
           'engine': 'physics', 'velocity_scaling': 0.2, 'success': False, 'paths': 20,
           'failures': 20, 'wall_s': 1.0, 'bag': None, 'offline': True, 'detection': {}}
    (tmp_path / 'robot_runs.jsonl').write_text(json.dumps(old) + '\n')
    calls = []

    def offline(scenario, method, run, velocity_scaling, detection, jtc_start, faults,
                cartesian_speed_limit, restarts, guard_holds):
        calls.append((scenario, str(method), run))
        return {'success': True, 'paths': 2, 'failures': 1, 'bag': None}

    monkeypatch.setattr(robot_experiment, 'offline_run', offline)
    args = ['experiment', 'robot', '--offline', '--runs', '1', '--scenarios', 'demo_hook',
            '--methods', 'informed', '--out', str(tmp_path)]
    assert cli.main([*args, '--json']) == 0
    assert calls == [('demo_hook', f'informed:{DEFAULT_IDEAS}', 0)]
    records = json.loads(capsys.readouterr().out)
    assert [(r['method'], r['success']) for r in records] == \
        [(f'informed:{DEFAULT_IDEAS}', True)]
    assert cli.main(args) == 0 and calls == [calls[0]]      # now done
    assert '| demo_hook | 1 / 1 |' in capsys.readouterr().out
