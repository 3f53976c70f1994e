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

"""probdis bench quality: ProbRRT beside OMPL's BIT* (the optional ompl wheel)."""

import argparse
import json
import sys

import numpy as np
from probdis_ros.bench import add_quality_command, bench_quality, straight_path_map
import pytest


def quality_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    add_quality_command(parser.add_subparsers())
    return parser


def test_bench_quality_scores_both_planners_on_a_tiny_budget():
    pytest.importorskip('ompl')
    maps = [('straight-5', *straight_path_map(5))]
    result = bench_quality(budgets=(0.01,), seeds=1, maps=maps)
    entry = result['maps'][0]
    assert entry['failures'] == 5 and entry['straight_cost'] > 0
    for name in ('probrrt', 'bitstar'):
        (row,) = entry['planners'][name]
        assert row['budget_s'] == 0.01 and np.isfinite(row['median_cost'])
        assert 0.0 < row['median_success_probability'] <= 1.0
        assert row['median_cost'] <= entry['straight_cost'] + 1e-9
    assert set(entry['verdict']) >= {'at_or_below_every_budget', 'first_budget_reaching_it_s'}


def test_the_command_prints_json(capsys):
    pytest.importorskip('ompl')
    args = quality_parser().parse_args(['quality', '--budgets', '0.01', '--seeds', '1',
                                        '--json'])
    assert args.handler(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [m['map'] for m in doc['maps']] == ['episode-19a', 'episode-19b', 'straight-19']


def test_without_ompl_the_command_says_how_to_install_it(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, 'ompl', None)      # import ompl raises ImportError
    args = quality_parser().parse_args(['quality', '--seeds', '1'])
    assert args.handler(args) == 2
    assert 'pip install -r .ci/requirements/bench.txt' in capsys.readouterr().err
