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
``probdis experiment report``: success curves with bootstrapped confidence intervals.

For every (setting, obstacle count, method): the success rate within n planned paths for
n = 1..max (an episode succeeded within n if it succeeded after at most n paths), with a 95 %
percentile-bootstrap interval over the worlds; the mean number of paths of the successful
episodes; the planning time per path.  Written as ``success.png`` (like the paper's Fig. 4),
``sensitivity.png`` (success at the maximum, like its Fig. 5), ``summary.json`` and
``summary.md``.
"""

from __future__ import annotations

from collections import defaultdict
import json
from pathlib import Path
import statistics

import numpy as np
from probdis_ros.experiments.sweep import EPISODES_FILE, read_episodes

BOOTSTRAP_SAMPLES = 2000
BOOTSTRAP_SEED = 0


def bootstrap_ci(values: np.ndarray, samples: int = BOOTSTRAP_SAMPLES,
                 seed: int = BOOTSTRAP_SEED, level: float = 0.95) -> tuple[float, float]:
    """
    Return the percentile-bootstrap interval of the mean of values (reproducible by seed).

    ``samples`` resamples of the values with replacement; the interval is the
    ``(1 - level) / 2`` and ``(1 + level) / 2`` quantiles of their means.
    """
    values = np.asarray(values, dtype=float)
    if len(values) == 0:
        return (float('nan'), float('nan'))
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, len(values), size=(samples, len(values)))
    means = values[picks].mean(axis=1)
    low, high = np.quantile(means, [(1 - level) / 2, (1 + level) / 2])
    return float(low), float(high)


def success_curve(records: list[dict], max_paths: int) -> dict:
    """Return success within n paths (n = 1..max_paths): rate, CI low, CI high per n."""
    paths = np.array([r['paths'] if r['success'] else max_paths + 1 for r in records])
    rate, low, high = [], [], []
    for n in range(1, max_paths + 1):
        within = (paths <= n).astype(float)
        ci = bootstrap_ci(within)
        rate.append(float(within.mean()))
        low.append(ci[0])
        high.append(ci[1])
    return {'rate': rate, 'low': low, 'high': high}


def summarise(records: list[dict]) -> dict:
    """Group episodes by setting, obstacle count and method; compute every figure."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for record in records:
        groups[(record['setting'], record['obstacles'], record['method'])].append(record)
    cells = []
    for (setting, obstacles, method), group in sorted(groups.items()):
        max_paths = group[0]['max_paths']
        curve = success_curve(group, max_paths)
        wins = [r['paths'] for r in group if r['success']]
        times = [t for r in group for t in r['plan_times_s']]
        cells.append({
            'setting': setting, 'obstacles': obstacles, 'method': method,
            'episodes': len(group), 'max_paths': max_paths,
            'success': curve['rate'][-1], 'ci95': [curve['low'][-1], curve['high'][-1]],
            'curve': curve,
            'mean_paths_successful': statistics.fmean(wins) if wins else None,
            'plan_time_s_median': statistics.median(times) if times else None,
            'episode_wall_s_mean': statistics.fmean(r['wall_s'] for r in group)})
    return {'cells': cells, 'episodes': len(records),
            'bootstrap': {'samples': BOOTSTRAP_SAMPLES, 'seed': BOOTSTRAP_SEED,
                          'level': 0.95}}


def markdown_table(summary: dict) -> str:
    """Return the summary as a Markdown table (one row per setting, obstacles, method)."""
    lines = ['| setting | obstacles | method | episodes | success (95 % CI) '
             '| mean paths when successful | median plan time per path [s] |',
             '| --- | --- | --- | --- | --- | --- | --- |']
    for c in summary['cells']:
        paths = '-' if c['mean_paths_successful'] is None else \
            f'{c["mean_paths_successful"]:.1f}'
        plan = '-' if c['plan_time_s_median'] is None else f'{c["plan_time_s_median"]:.3f}'
        lines.append(f'| {c["setting"]} | {c["obstacles"]} | {c["method"]} | '
                     f'{c["episodes"]} | {c["success"]:.2f} ({c["ci95"][0]:.2f}-'
                     f'{c["ci95"][1]:.2f}) | {paths} | {plan} |')
    return '\n'.join(lines) + '\n'


def write_report(directory: str | Path) -> dict:
    """Read DIR/episodes.jsonl; write the PNGs, summary.json and summary.md into DIR."""
    from probdis_ros.plots import plot_sensitivity, plot_success_curves

    directory = Path(directory)
    records = read_episodes(directory / EPISODES_FILE)
    if not records:
        raise ValueError(f'{directory / EPISODES_FILE}: no episodes (run probdis experiment '
                         'sweep first)')
    summary = summarise(records)
    (directory / 'summary.json').write_text(json.dumps(summary, indent=1) + '\n')
    (directory / 'summary.md').write_text(markdown_table(summary))
    plot_success_curves(summary, directory / 'success.png')
    plot_sensitivity(summary, directory / 'sensitivity.png')
    return summary
