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

"""Sweeps on a Dask LocalCluster (resumable after a kill) and the report's statistics."""

from dataclasses import asdict
import itertools
import json
import math
import os
from pathlib import Path
import signal
import subprocess
import time
import zlib

from conftest import probdis_command
import numpy as np
from probdis_ros.experiments.report import (
    bootstrap_ci,
    claims,
    claims_markdown,
    family_table,
    markdown_table,
    paired_ci,
    paired_markdown,
    success_ci,
    success_curve,
    summarise,
    write_report,
)
from probdis_ros.experiments.sweep import (
    episode_keys,
    EPISODES_FILE,
    family_keys,
    Method,
    read_episodes,
    run_sweep,
)
from probdis_ros.ros.robot_experiment import robot_table, state_gaps, valid
import pytest

SWEEP = ['--setting', '2d', '--obstacles', '1,10', '--worlds', '5',
         '--methods', 'probabilistic,epsilon:0.2', '--seed', '3', '--workers', '2']


def outcomes(path: Path) -> dict:
    return {r['id']: (r['world_seed'], r['success'], r['paths'], r['failures'])
            for r in read_episodes(path)}


def test_a_killed_sweep_resumes_to_the_same_episodes_without_duplicates(tmp_path):
    methods = [Method.parse('probabilistic'), Method.parse('epsilon:0.2')]
    keys = episode_keys(['2d'], [1, 10], 5, methods, 3)
    report = run_sweep(keys, tmp_path / 'whole', workers=2)
    assert report.ran == 20 and report.skipped == 0
    whole = outcomes(tmp_path / 'whole' / EPISODES_FILE)
    assert len(whole) == 20
    # methods meet the same worlds
    seeds = {(k.obstacles, k.world): set() for k in keys}
    for key in keys:
        seeds[(key.obstacles, key.world)].add(whole[key.name][0])
    assert all(len(s) == 1 for s in seeds.values())

    out = tmp_path / 'killed'
    episodes = out / EPISODES_FILE
    sweep = subprocess.Popen([*probdis_command(), 'experiment', 'sweep', *SWEEP,
                              '--out', str(out)], start_new_session=True)
    deadline = time.monotonic() + 300     # a liveness guard: kernels may compile first
    while not (episodes.exists() and len(read_episodes(episodes)) >= 5):
        assert time.monotonic() < deadline and sweep.poll() is None, 'no episodes written'
        time.sleep(0.05)
    os.killpg(sweep.pid, signal.SIGKILL)
    sweep.wait()
    partial = len(read_episodes(episodes))
    assert 5 <= partial < 20
    with episodes.open('a') as stream:          # a record cut short by the kill
        stream.write('{"setting": "2d", "obstac')
    resumed = subprocess.run([*probdis_command(), 'experiment', 'sweep', *SWEEP,
                              '--out', str(out)], capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert f'{partial} already done' in resumed.stdout
    lines = episodes.read_text().splitlines()
    assert len(lines) == 20 and all(json.loads(line) for line in lines)
    assert outcomes(episodes) == whole
    again = subprocess.run([*probdis_command(), 'experiment', 'sweep', *SWEEP,
                            '--out', str(out)], capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and '20 already done, 0 run' in again.stdout
    assert episodes.read_text().splitlines() == lines

    summary = write_report(out)
    assert {(c['obstacles'], c['method']) for c in summary['cells']} == {
        (1, 'probabilistic'), (1, 'epsilon:0.2'), (10, 'probabilistic'), (10, 'epsilon:0.2')}
    for name in ('success.png', 'sensitivity.png', 'summary.json', 'summary.md'):
        assert (out / name).stat().st_size > 0
    # every record counts its empty plans; Probabilistic and Epsilon always find a path
    assert all(r['empty_plans'] == 0 for r in read_episodes(episodes))
    assert all(c['empty_plan_share'] == 0.0 for c in summary['cells'])
    assert 'empty plans / paths' in (out / 'summary.md').read_text()


def test_the_report_shows_the_share_of_empty_plans():
    def record(world, empty, paths, **extra):
        return {'setting': '2d', 'obstacles': 1, 'method': 'hard:0.01', 'max_paths': 20,
                'success': False, 'paths': paths, 'plan_times_s': [0.01] * paths,
                'wall_s': 1.0, 'world': world, **({'empty_plans': empty} if empty is not None
                                                  else {}), **extra}

    cells = summarise([record(0, 19, 20), record(1, 1, 10)])['cells']
    assert cells[0]['empty_plan_share'] == pytest.approx(20 / 30)
    old = summarise([record(0, 19, 20), record(1, None, 10)])
    assert old['cells'][0]['empty_plan_share'] is None     # not counted: unknown, not zero


def test_a_sweep_of_another_seed_is_refused_in_the_same_directory(tmp_path):
    keys = episode_keys(['2d'], [1], 1, [Method.parse('epsilon:0.2')], 0)
    run_sweep(keys, tmp_path, workers=1)
    other = episode_keys(['2d'], [1], 1, [Method.parse('epsilon:0.2')], 1)
    with pytest.raises(ValueError, match='another sweep'):
        run_sweep(other, tmp_path, workers=1)
    # nor one whose planner settings differ (an ablation of K belongs in its own directory)
    with pytest.raises(ValueError, match='planner defaults'):
        run_sweep(keys, tmp_path, workers=1, rrt={'iterations': 400})
    # nor one that allows another number of paths (its success rates are not comparable)
    with pytest.raises(ValueError, match='--max-paths 20'):
        run_sweep(keys, tmp_path, max_paths=5, workers=1)


def test_an_episode_record_runs_the_keys_world_with_its_seed_paths_and_planner(monkeypatch):
    # every method meets the world of the key's seed and plans from that seed's own stream,
    # with the sweep's number of paths and planner settings; the record keeps what it did
    from probdis_ros.experiments import sweep
    from probdis_ros.sim import episode
    from probdis_ros.sim.worlds import random_world

    real, calls = episode.run_episode, []

    def spy(world, method, **kwargs):
        result = real(world, method, **kwargs)
        result.empty_plans = 1          # as if a plan had been empty: the record says so
        calls.append((world, kwargs, result))
        return result

    monkeypatch.setattr(episode, 'run_episode', spy)
    monkeypatch.setattr(sweep, '_WORLDS', {})       # no world drawn before
    keys = episode_keys(['2d'], [1], 2, [Method.parse('epsilon:0.2')], 3)
    for key in keys:
        record = sweep.run_episode_record(key, 2, {'iterations': 300})
        world, kwargs, result = calls[-1]
        assert world.to_dict() == random_world('2d', 1, key.world_seed).to_dict()
        assert kwargs['seed'] == key.world_seed and kwargs['max_paths'] == 2
        assert kwargs['settings'].iterations == 300
        assert 'error' not in record and record['rrt'] == {'iterations': 300}
        assert (record['success'], record['paths'], record['failures'],
                record['empty_plans'], record['plan_times_s']) == (
            result.success, result.paths, result.failures, 1, result.plan_times_s)
    assert calls[0][0].to_dict() != calls[1][0].to_dict()
    # a family's key: the family world of its seed (the sweep seed plus the world index)
    from probdis_ros.sim import families

    drawn = []

    def family_world(family, seed):
        drawn.append((family, seed))
        return random_world('2d', 1, seed)

    monkeypatch.setattr(families, 'random_family_world', family_world)
    key = family_keys(['open_box'], 2, [Method.parse('epsilon:0.2')], 1000)[1]
    assert 'error' not in sweep.run_episode_record(key, 1)
    assert drawn == [('open_box', 1001)] and calls[-1][1]['seed'] == 1001


def test_an_episode_that_raises_is_recorded_as_errored_and_the_sweep_goes_on(
        tmp_path, monkeypatch, capsys):
    from dask.distributed import LocalCluster
    from probdis_ros.sim import episode

    real = episode.run_episode

    def fails_in_world_1(world, method, seed=0, **kwargs):
        if seed == keys[1].world_seed:
            raise RuntimeError('the planner fell over')
        return real(world, method, seed=seed, **kwargs)

    keys = episode_keys(['2d'], [1], 3, [Method.parse('epsilon:0.2')], 0)
    monkeypatch.setattr(episode, 'run_episode', fails_in_world_1)
    # workers in this process (threads), so that they run the patched episode
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        report = run_sweep(keys, tmp_path, scheduler=cluster.scheduler_address)
    assert report.ran == 3
    records = {r['world']: r for r in read_episodes(tmp_path / EPISODES_FILE)}
    assert sorted(records) == [0, 1, 2]
    failed = records[1]
    assert failed['error'] == 'RuntimeError: the planner fell over'
    assert (failed['success'], failed['paths'], failed['method'], failed['world_seed'],
            failed['id']) == (False, 0, 'epsilon:0.2', keys[1].world_seed, keys[1].name)
    assert 'error' not in records[0] and 'error' not in records[2]
    warning = [line for line in capsys.readouterr().err.splitlines() if 'warning' in line]
    assert len(warning) == 1 and keys[1].name in warning[0] and 'fell over' in warning[0]
    # the report counts it as unsolved and says it errored
    summary = write_report(tmp_path)
    cell = summary['cells'][0]
    solved = sum(records[w]['success'] for w in (0, 2))
    assert (cell['episodes'], cell['errored'], cell['success']) == (3, 1, solved / 3)
    assert summary['errored'] == [{'id': keys[1].name,
                                   'error': 'RuntimeError: the planner fell over'}]
    assert '1 of 3 episodes errored (counted as unsolved' in \
        (tmp_path / 'summary.md').read_text()
    # resumed: the errored episode is done, nothing runs again
    assert run_sweep(keys, tmp_path, workers=1).ran == 0


def test_a_record_of_the_bare_informed_of_before_is_not_taken_for_todays_default(tmp_path):
    """Records labelled ``informed`` ran an older default: a resumed sweep runs it anew."""
    from probdis_ros.planning.informed import DEFAULT_IDEAS

    informed = Method.parse('informed')
    assert str(informed) == f'informed:{DEFAULT_IDEAS}' and Method.parse(str(informed)) == \
        informed
    keys = episode_keys(['2d'], [1], 1, [informed], 0)
    old = {**asdict(keys[0]), 'method': 'informed', 'id': '2d/1/0/informed',
           'world_seed': keys[0].world_seed, 'success': True, 'paths': 1, 'failures': 0,
           'empty_plans': 0, 'max_paths': 2, 'plan_times_s': [0.01], 'wall_s': 1.0}
    (tmp_path / EPISODES_FILE).write_text(json.dumps(old) + '\n')
    assert run_sweep(keys, tmp_path, max_paths=2, workers=1).ran == 1
    methods = [r['method'] for r in read_episodes(tmp_path / EPISODES_FILE)]
    assert methods == ['informed', f'informed:{DEFAULT_IDEAS}']
    # and the report keeps the two variants apart
    assert {c['method'] for c in write_report(tmp_path)['cells']} == set(methods)


def test_family_worlds_are_seeds_from_the_sweep_seed_and_go_world_by_world():
    methods = [Method.parse('probabilistic'), Method.parse('epsilon:0.2')]
    keys = family_keys(['open_box', 'clutter'], 3, methods, 1000)
    assert [k.name for k in keys[:4]] == ['open_box/0/probabilistic', 'open_box/0/epsilon:0.2',
                                          'clutter/0/probabilistic', 'clutter/0/epsilon:0.2']
    assert {(k.family, k.world, k.world_seed) for k in keys} == {
        (f, w, 1000 + w) for f in ('open_box', 'clutter') for w in range(3)}
    assert all(k.setting == '3d-orient' for k in keys)
    # a family or a method given twice (or spelled two ways) runs once
    twice = family_keys(['clutter', 'clutter'], 2,
                        [Method.parse('informed'), Method.parse('informed:adfhij')], 0)
    assert [k.name for k in twice] == ['clutter/0/informed:adfhij', 'clutter/1/informed:adfhij']
    assert len(episode_keys(['2d', '2d'], [1, 1], 2, methods + methods, 3)) == 4
    # the settings' seeds are unchanged by the families (same hash as before)
    assert episode_keys(['2d'], [1], 1, methods[:1], 3)[0].world_seed == zlib.crc32(b'3/2d/1/0')


def test_the_report_groups_families_apart_from_settings():
    def record(family, method, success, paths):
        return {'setting': '3d-orient', 'obstacles': 0, 'method': method, 'max_paths': 20,
                'success': success, 'paths': paths, 'plan_times_s': [0.1] * paths,
                'wall_s': 1.0, 'empty_plans': 0, **({'family': family} if family else {})}

    summary = summarise([record('open_box', 'probabilistic', True, 2),
                         record('open_box', 'probabilistic', False, 20),
                         record('clutter', 'probabilistic', True, 4),
                         record('', 'probabilistic', True, 1)])
    cells = {(c.get('family'), c['method']): c for c in summary['cells']}
    assert cells[('open_box', 'probabilistic')]['success'] == 0.5
    assert cells[('open_box', 'probabilistic')]['mean_paths_successful'] == 2
    assert cells[(None, 'probabilistic')]['episodes'] == 1
    rows = family_table(summary).splitlines()[2:]
    assert [r.split(' | ')[0] for r in rows] == ['| open_box', '| clutter']
    assert len(markdown_table(summary).splitlines()) == 3     # the setting cell only
    assert [b['obstacles'] for b in claims(summary)['beats_every_baseline']] == []


def test_the_bootstrap_interval_matches_the_exact_bootstrap_distribution():
    """
    Check the interval against the exact bootstrap distribution.

    Five worlds, three successes: all 5^5 resamples, enumerated, give the exact 2.5 % and
    97.5 % quantiles of the resampled success rate.
    """
    values = np.array([1.0, 0.0, 1.0, 1.0, 0.0])
    means = sorted(sum(values[list(pick)]) / 5
                   for pick in itertools.product(range(5), repeat=5))
    exact = (means[int(0.025 * len(means))], means[int(0.975 * len(means)) - 1])
    assert exact == (0.2, 1.0)
    assert bootstrap_ci(values, samples=20000) == pytest.approx(exact)
    assert bootstrap_ci(np.ones(7)) == (1.0, 1.0)
    assert bootstrap_ci(values) == bootstrap_ci(values)          # seeded


def test_a_success_rate_of_all_or_none_gets_the_exact_interval_not_a_point():
    # 100 of 100: the bootstrap's resamples are all 1; Clopper-Pearson's lower bound solves
    # p^100 = 0.025 (the binomial's chance of 100 of 100 at that p)
    low, high = success_ci(np.ones(100))
    assert high == 1.0 and low == pytest.approx(0.96378, abs=1e-5)
    assert low ** 100 == pytest.approx(0.025)
    assert success_ci(np.zeros(100)) == pytest.approx((0.0, 1.0 - low))
    # anything between: the bootstrap's, unchanged
    values = np.array([1.0] * 60 + [0.0] * 40)
    assert success_ci(values) == bootstrap_ci(values)
    # a paired difference where no pair differs: at most the share of pairs that differ
    assert paired_ci(np.zeros(100)) == pytest.approx((low - 1.0, 1.0 - low))
    diffs = np.array([1.0] * 3 + [0.0] * 97)
    assert paired_ci(diffs) == bootstrap_ci(diffs)
    # every pair won (or lost): as 100 of 100, not a point at 1
    assert paired_ci(np.ones(100)) == pytest.approx((low, 1.0))
    assert paired_ci(-np.ones(100)) == pytest.approx((-1.0, -low))
    curve = success_curve([{'success': True, 'paths': 1}] * 20, max_paths=3)
    assert curve['rate'] == [1.0] * 3 and curve['low'][0] == pytest.approx(0.025 ** (1 / 20))


def test_the_summary_does_not_depend_on_the_order_the_workers_finished_in():
    """Shuffle the records (as two workers may finish them): the same intervals."""
    rng = np.random.default_rng(7)
    records = [{'setting': '2d', 'obstacles': 1, 'method': method, 'max_paths': 20,
                'world': w, 'world_seed': 1000 + w, 'success': bool(rng.random() < 0.6),
                'paths': int(rng.integers(1, 21)), 'plan_times_s': [0.01], 'wall_s': 1.0,
                'empty_plans': 0}
               for w in range(30) for method in ('probabilistic', 'epsilon:0.2')]
    summary = summarise(records)
    for seed in range(3):
        shuffled = [records[k] for k in np.random.default_rng(seed).permutation(len(records))]
        assert summarise(shuffled) == summary


def test_success_within_n_paths_counts_only_successes_after_at_most_n_paths():
    records = [{'setting': '2d', 'obstacles': 1, 'method': 'probabilistic', 'max_paths': 4,
                'success': success, 'paths': paths, 'plan_times_s': [0.1] * paths,
                'wall_s': 1.0}
               for success, paths in [(True, 1), (True, 3), (False, 4), (True, 4)]]
    cell = summarise(records)['cells'][0]
    assert cell['curve']['rate'] == [0.25, 0.25, 0.5, 0.75]
    assert cell['success'] == 0.75 and cell['mean_paths_successful'] == pytest.approx(8 / 3)


def test_methods_parse_and_bad_ones_are_named():
    assert str(Method.parse('hard:0.01')) == 'hard:0.01'
    assert Method.parse('probabilistic') == Method('probabilistic')
    # the string a method writes reads back to the same method (records are re-parsed)
    for text in ('hard:0.0123456789', 'probabilistic:100', 'hard:0.01:250', 'epsilon:0.2'):
        assert str(Method.parse(text)) == text
    for bad, message in (('hard', 'needs its parameter'), ('rrt', 'unknown method'),
                         ('epsilon:x', 'not a number'), ('hard:2', 'outside'),
                         ('probabilistic::5', 'empty parameter'),
                         ('probabilistic:', 'empty parameter'),
                         ('informed:', 'empty parameter'),
                         ('probabilistic:inf', 'not finite'), ('hard:0.01:inf', 'not finite')):
        with pytest.raises(ValueError, match=message):
            Method.parse(bad)
    result = subprocess.run([*probdis_command(), 'experiment', 'sweep', '--methods', 'rrt',
                             '--out', 'unused'], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "unknown method 'rrt'" in result.stderr
    # a world without obstacles fails to build: every episode was recorded unsolved, exit 0
    result = subprocess.run([*probdis_command(), 'experiment', 'sweep', '--setting', '2d',
                             '--obstacles', '0,10', '--out', 'unused'], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 2 and 'at least 1' in result.stderr, result.stderr


def test_the_robot_table_counts_successes_and_averages_paths_of_successful_runs():
    records = [{'scenario': 'a', 'method': 'm', 'success': True, 'paths': 3},
               {'scenario': 'a', 'method': 'm', 'success': False, 'paths': 20},
               {'scenario': 'b', 'method': 'm', 'success': True, 'paths': 6},
               {'scenario': 'a', 'method': 'n', 'success': False, 'paths': 20}]
    assert robot_table(records, ['a', 'b'], ['m', 'n']).splitlines() == [
        '| scenario | m | n |', '| --- | --- | --- |',
        '| a | 1 / 2 | 0 / 1 |', '| b | 1 / 1 | 0 / 0 |', '| **total** | 2 / 3 | 0 / 1 |',
        '| mean paths (successful runs) | 4.5 | - |']


def test_runs_where_the_planner_fell_behind_are_left_out_of_the_robot_table():
    records = [{'scenario': 'a', 'method': 'm', 'run': 0, 'success': True, 'paths': 3,
                'max_state_gap_s': 0.01},
               {'scenario': 'a', 'method': 'm', 'run': 1, 'success': True, 'paths': 5,
                'max_state_gap_s': 2.07}]
    table = robot_table(records, ['a'], ['m'])
    assert '| a | 1 / 1 |' in table and '| mean paths (successful runs) | 3.0 |' in table
    assert '1 run(s) left out: the planner fell behind' in table
    # run again validly, the run counts once and nothing is left out
    rerun = {'scenario': 'a', 'method': 'm', 'run': 1, 'success': False, 'paths': 20,
             'max_state_gap_s': 0.01}
    table = robot_table([*records, rerun], ['a'], ['m'])
    assert '| a | 1 / 2 |' in table and 'left out' not in table


def test_the_robot_table_gives_the_median_peak_force_where_the_physics_knows_it():
    records = [{'scenario': 'a', 'method': 'm', 'success': False, 'paths': 20,
                'peak_contact_force_n': force} for force in (100.0, 300.0, 250.0)]
    assert robot_table(records, ['a'], ['m']).splitlines()[-1] == \
        '| peak contact force per run, median [N] | 250 |'


def test_the_joint_states_a_planner_missed_are_counted_from_its_bag(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import get_typestore, Stores

    store = get_typestore(Stores.ROS2_JAZZY)
    kind = 'sensor_msgs/msg/JointState'
    message = store.types[kind]
    stamps = [k * 0.01 for k in range(50)] + [0.49 + 0.5 + k * 0.01 for k in range(20)]
    with Writer(tmp_path / 'bag', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/lbr/joint_states', kind, typestore=store)
        for t in stamps:
            header = store.types['std_msgs/msg/Header'](
                stamp=store.types['builtin_interfaces/msg/Time'](sec=0, nanosec=0),
                frame_id='')
            msg = message(header=header, name=[], position=np.zeros(0), velocity=np.zeros(0),
                          effort=np.zeros(0))
            writer.write(conn, round((1000.0 + t) * 1e9), store.serialize_cdr(msg, kind))
    missed, longest = state_gaps(tmp_path / 'bag')
    assert missed == 49 and longest == pytest.approx(0.5, abs=1e-6)
    assert not valid({'max_state_gap_s': longest}) and valid({'max_state_gap_s': 0.01})


def claims_cell(obstacles, method, success, ci=(0.0, 1.0)) -> dict:
    """Return a 2-D summary cell of a claims test."""
    return {'setting': '2d', 'obstacles': obstacles, 'method': method,
            'success': success, 'ci95': list(ci)}


def test_the_claims_compare_with_the_best_baseline_and_find_ranking_flips():
    summary = {'cells': [
        claims_cell(1, 'probabilistic', 0.9, (0.8, 0.95)), claims_cell(1, 'hard:0.01', 0.5),
        claims_cell(1, 'hard:0.02', 0.7), claims_cell(1, 'epsilon:0.2', 0.6),
        claims_cell(10, 'probabilistic', 0.6, (0.5, 0.7)), claims_cell(10, 'hard:0.01', 0.65),
        claims_cell(10, 'hard:0.02', 0.4), claims_cell(10, 'epsilon:0.2', 0.6)]}
    verdicts = claims(summary)
    rows = {b['obstacles']: b for b in verdicts['beats_every_baseline']}
    assert (rows[1]['best_baseline'], rows[1]['at_least_as_good'], rows[1]['clear']) == \
        ('hard:0.02', True, True)
    assert (rows[10]['best_baseline'], rows[10]['at_least_as_good']) == ('hard:0.01', False)
    assert verdicts['all_at_least_as_good'] is False
    hard = next(f for f in verdicts['sensitivity'] if f['family'] == 'hard')
    assert hard['best_by_obstacles'] == {1: 'hard:0.02', 10: 'hard:0.01'}
    assert hard['best_changes'] and abs(hard['largest_gap'] - 0.25) < 1e-12
    assert [f['family'] for f in verdicts['sensitivity']] == ['hard']   # one epsilon value


def test_the_comparison_with_the_paper_is_paired_by_world():
    """
    Check the paired comparison on worlds where the answer is known.

    The paper's method solves worlds 0-9 in 5 paths.  ``epsilon:0.2`` solves those in 3
    paths and worlds 10-19 too, in 15: its mean over its own successes (9) is above the
    paper's (5), over the worlds both solved below (3 against 5); it succeeds in 10 more
    worlds of 20.  ``hard:0.01`` solves exactly the paper's worlds: a difference of 0 in
    every world: no world differs, so the paired interval is the exact bound on the share of
    worlds that differ, +-(1 - 0.025^(1/20)) = +-0.17 (unpaired, both rates' intervals are
    wider).
    """
    def record(method, world, success, paths):
        return {'setting': '2d', 'obstacles': 10, 'method': method, 'max_paths': 20,
                'world': world, 'world_seed': 500 + world, 'success': success,
                'paths': paths if success else 20, 'plan_times_s': [0.01], 'wall_s': 1.0,
                'empty_plans': 0}

    records = [record('probabilistic', w, w < 10, 5) for w in range(20)]
    records += [record('epsilon:0.2', w, True, 3 if w < 10 else 15) for w in range(20)]
    records += [record('hard:0.01', w, w < 10, 7) for w in range(20)]
    records.reverse()                       # the order the file holds them in does not matter
    summary = summarise(records)
    rows = {r['method']: r for r in summary['paired']}
    assert set(rows) == {'epsilon:0.2', 'hard:0.01'}
    eps, hard = rows['epsilon:0.2'], rows['hard:0.01']
    cells = {c['method']: c for c in summary['cells']}
    assert cells['epsilon:0.2']['mean_paths_successful'] == 9.0     # its own successes
    assert (eps['worlds'], eps['both_solved'], eps['mean_paths_both_solved']) == \
        (20, 10, [3.0, 5.0])
    assert (eps['success'], eps['success_paper'], eps['difference']) == (1.0, 0.5, 0.5)
    # the worlds resampled: the interval of the mean of ten 1s and ten 0s
    assert eps['difference_ci95'] == list(bootstrap_ci(np.array([0.0] * 10 + [1.0] * 10)))
    assert 0.25 < eps['difference_ci95'][0] < 0.5 < eps['difference_ci95'][1] < 0.75
    bound = 1 - 0.025 ** (1 / 20)
    assert hard['difference'] == 0.0 and hard['difference_ci95'] == pytest.approx([-bound, bound])
    assert 0.16 < bound < 0.17
    assert cells['hard:0.01']['ci95'][0] < 0.4 and cells['hard:0.01']['ci95'][1] > 0.6
    # the claims' row for the best baseline carries its paired comparison
    verdicts = claims(summary)
    beat = verdicts['beats_every_baseline'][0]
    assert beat['best_baseline'] == 'epsilon:0.2' and beat['paired'] == eps
    text = claims_markdown(verdicts)
    low, high = eps['difference_ci95']
    assert f'| -0.50 ({-high:+.2f} to {-low:+.2f}) | 5.0 / 3.0 |' in text
    table = paired_markdown(summary, families=False)
    assert f'| 2d | 10 | epsilon:0.2 | 20 | 1.00 / 0.50 | +0.50 ({low:+.2f} to {high:+.2f}) ' \
        '| 10 | 3.0 / 5.0 |' in table
    assert '| 2d | 10 | hard:0.01 | 20 | 0.50 / 0.50 | +0.00 (-0.17 to +0.17) | 10 | 7.0 / 5.0 |' \
        in table
    assert paired_markdown(summary, families=True) == ''
    # families pair the same way, in their own table
    family = [{**r, 'family': 'open_box', 'setting': '3d-orient', 'obstacles': 0}
              for r in records]
    rows = summarise(family)['paired']
    assert [(r['family'], r['method'], r['difference']) for r in rows] == [
        ('open_box', 'epsilon:0.2', 0.5), ('open_box', 'hard:0.01', 0.0)]
    assert '| open_box | epsilon:0.2 | 20 |' in paired_markdown(summarise(family), True)


def test_the_claims_take_a_tie_as_good_a_clear_win_by_the_lower_bound_and_no_variant():
    # a tie with the best baseline is "at least as good"; "clearly" only where the lower end
    # of probabilistic's interval is above the baseline's rate; probabilistic with another
    # c_fail is the paper's method too, never its baseline
    summary = {'cells': [
        claims_cell(1, 'probabilistic', 0.7, (0.55, 0.85)), claims_cell(1, 'hard:0.01', 0.7),
        claims_cell(10, 'probabilistic', 0.8, (0.65, 0.9)), claims_cell(10, 'epsilon:0.2', 0.7),
        claims_cell(10, 'probabilistic:2.0', 0.95, (0.85, 1.0))]}
    verdicts = claims(summary)
    rows = {b['obstacles']: b for b in verdicts['beats_every_baseline']}
    assert (rows[1]['best_baseline'], rows[1]['at_least_as_good'], rows[1]['clear']) == \
        ('hard:0.01', True, False)
    assert (rows[10]['best_baseline'], rows[10]['at_least_as_good'], rows[10]['clear']) == \
        ('epsilon:0.2', True, False)
    assert verdicts['all_at_least_as_good'] is True
    assert claims_markdown(verdicts).count('| yes |') == 2


def test_the_plan_time_per_path_is_the_median_over_the_cells_paths():
    def record(world, times):
        return {'setting': '2d', 'obstacles': 1, 'method': 'probabilistic', 'max_paths': 20,
                'success': True, 'paths': len(times), 'plan_times_s': times, 'wall_s': 1.0,
                'world': world, 'empty_plans': 0}

    # one slow plan among five: the median is the typical path's, not the mean's 0.208
    summary = summarise([record(0, [0.01, 0.01, 1.0]), record(1, [0.01, 0.01])])
    assert summary['cells'][0]['plan_time_s_median'] == pytest.approx(0.01)
    assert markdown_table(summary).splitlines()[-1].endswith('| 0.010 |')


def test_the_bootstrap_interval_leaves_2_5_percent_out_at_each_end():
    # 20 worlds solved of 40: a resample's successes are binomial, 40 draws at 0.5; the
    # exact 2.5 % and 97.5 % quantiles are 14 and 26 of 40 (the 5 % one, 15)
    cdf = np.cumsum([math.comb(40, k) for k in range(41)]) / 2 ** 40
    low, high = int(np.searchsorted(cdf, 0.025)), int(np.searchsorted(cdf, 0.975))
    assert (low, high) == (14, 26) and int(np.searchsorted(cdf, 0.05)) == 15
    values = np.array([1.0] * 20 + [0.0] * 20)
    assert bootstrap_ci(values, samples=20000) == pytest.approx((low / 40, high / 40))


def report_record(world, method='probabilistic'):
    """Return an episode record as the sweep writes it (the fields the report reads)."""
    return {'setting': '2d', 'obstacles': 1, 'method': method, 'max_paths': 20,
            'success': True, 'paths': 2, 'plan_times_s': [0.01, 0.01], 'wall_s': 1.0,
            'empty_plans': 0, 'world': world}


def run_report(directory):
    return subprocess.run([*probdis_command(), 'experiment', 'report', str(directory)],
                          capture_output=True, text=True, timeout=120)


def test_a_sweep_in_another_directory_is_compared_world_by_world(tmp_path):
    """The paper's method in one sweep, another method later in its own: paired by world."""
    paper, later = tmp_path / 'paper', tmp_path / 'later'
    for folder, method, solved in ((paper, 'probabilistic', {0, 1}), (later, 'informed', {1, 2})):
        folder.mkdir()
        (folder / EPISODES_FILE).write_text(''.join(
            json.dumps({**report_record(w, method), 'success': w in solved}) + '\n'
            for w in range(4)))
    result = subprocess.run([*probdis_command(), 'experiment', 'report', str(paper), '--with',
                             str(later)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    summary = json.loads((paper / 'summary.json').read_text())
    assert summary['sources'] == [str(paper), str(later)] and summary['episodes'] == 8
    (row,) = summary['paired']
    # worlds 0-3: informed - paper = -1, 0, +1, 0
    assert (row['method'], row['worlds'], row['difference'], row['both_solved']) == \
        ('informed', 4, 0.0, 1)
    assert not (later / 'summary.json').exists()
    # the same episode in both is refused, naming both directories
    with (later / EPISODES_FILE).open('a') as stream:
        stream.write(json.dumps(report_record(3)) + '\n')
    with pytest.raises(ValueError, match=f'probabilistic on world 3 of 2d is in both {paper} '
                       f'and {later}'):
        write_report(paper, [later])
    # nor is a directory read twice, or a record twice in one (two sweeps wrote to one --out)
    with pytest.raises(ValueError, match=f'world 0 of 2d is twice in {paper}'):
        write_report(paper, [paper / '..' / 'paper'])
    with (paper / EPISODES_FILE).open('a') as stream:
        stream.write(json.dumps({**report_record(0), 'success': False}) + '\n')
    with pytest.raises(ValueError, match=f'world 0 of 2d is twice in {paper}'):
        write_report(paper)


def test_the_report_refuses_methods_allowed_different_numbers_of_paths(tmp_path):
    paper, later = tmp_path / 'paper', tmp_path / 'later'
    for folder, method, paths in ((paper, 'probabilistic', 2), (later, 'informed', 20)):
        folder.mkdir()
        (folder / EPISODES_FILE).write_text(''.join(
            json.dumps({**report_record(w, method), 'max_paths': paths}) + '\n'
            for w in range(3)))
    with pytest.raises(ValueError, match=r'allowed 2 paths .* and 20 .*one --max-paths'):
        write_report(paper, [later])


def test_the_report_names_a_record_that_is_no_episode_and_an_unwritable_summary(tmp_path):
    episodes = tmp_path / EPISODES_FILE
    episodes.write_text(json.dumps(report_record(0)) + '\n{"a": 1}\n')
    result = run_report(tmp_path)
    assert result.returncode == 2 and result.stderr.count('\n') == 1, result.stderr
    assert result.stderr.startswith('probdis experiment report: error: ') and \
        'record 2 is not an episode record' in result.stderr
    # a field of the wrong kind (edited by hand): named, not a numpy traceback
    episodes.write_text(json.dumps({**report_record(0), 'paths': '3'}) + '\n')
    result = run_report(tmp_path)
    assert result.returncode == 2 and result.stderr.count('\n') == 1, result.stderr
    assert "record 1 has a 'paths' of '3'" in result.stderr
    episodes.write_text(json.dumps(report_record(0)) + '\n')
    (tmp_path / 'summary.json').mkdir()           # where the summary goes: not writable
    result = run_report(tmp_path)
    assert result.returncode == 2 and result.stderr.count('\n') == 1, result.stderr
    assert 'summary.json: is a directory' in result.stderr


def test_a_summary_that_cannot_be_written_whole_leaves_the_previous_one(tmp_path, monkeypatch):
    (tmp_path / EPISODES_FILE).write_text(''.join(json.dumps(report_record(w)) + '\n'
                                                  for w in range(3)))
    write_report(tmp_path)
    before = {name: (tmp_path / name).read_text() for name in ('summary.json', 'summary.md')}
    with (tmp_path / EPISODES_FILE).open('a') as stream:
        stream.write(json.dumps(report_record(3, 'epsilon:0.2')) + '\n')

    def disk_full(fd):
        raise OSError(28, 'No space left on device')

    monkeypatch.setattr(os, 'fsync', disk_full)     # the write does not reach the disk
    with pytest.raises(OSError, match='No space left'):
        write_report(tmp_path)
    assert {name: (tmp_path / name).read_text() for name in before} == before
    assert not [p.name for p in tmp_path.iterdir() if p.name.endswith('.tmp')]
