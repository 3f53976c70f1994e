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
percentile-bootstrap interval over the worlds (taken in world order, not the order the
workers finished in; where all or none succeeded, the exact interval: :func:`success_ci`);
the mean number of paths of the successful episodes; the planning time per path; the share
of the paths that were empty plans (no feasible path found, the arm did not move; records
older than that count are shown as unknown).  Written as ``success.png``
(like the paper's Fig. 4), ``sensitivity.png`` (success at the maximum, like its Fig. 5),
``summary.json`` and ``summary.md``.  Every method is also set against the paper's
(probabilistic) on the worlds both ran: the difference of success with a paired bootstrap
interval, and the mean paths over the worlds both solved.  Episodes of entanglement families
(``sweep --family``) are grouped by family and method instead, tabled apart and drawn in
``families.png``, a panel per family; the figures of the settings are written only where the
directory holds settings.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
import json
from pathlib import Path
import statistics

import numpy as np
from probdis_ros.experiments.sweep import EPISODES_FILE, read_episodes
from probdis_ros.model.failure_map import write_atomically

BOOTSTRAP_SAMPLES = 2000
BOOTSTRAP_SEED = 0
#: The fields the report reads from every episode record (``sweep.run_sweep`` writes them).
EPISODE_FIELDS = ('setting', 'obstacles', 'method', 'max_paths', 'success', 'paths',
                  'plan_times_s', 'wall_s')
#: The kinds of the fields the report computes with (a hand-edited "3" refused, not summed).
FIELD_TYPES = {'setting': (str,), 'obstacles': (int,), 'method': (str,), 'max_paths': (int,),
               'success': (bool,), 'paths': (int,), 'plan_times_s': (list,),
               'wall_s': (int, float)}


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


def none_of_bound(n: int, level: float = 0.95) -> float:
    """Return the exact upper bound of a share of which none of n was seen (Clopper-Pearson)."""
    return 1.0 - ((1 - level) / 2) ** (1 / n)


def success_ci(successes: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """
    Return the interval of a success rate over worlds (successes: 1 or 0 per world).

    The percentile bootstrap, but where every world succeeded (or none did): there every
    resample is alike and the bootstrap's interval has no width, as if n worlds proved a
    rate of exactly 1; the exact (Clopper-Pearson) interval of n of n is
    ``[1 - none_of_bound(n), 1]`` (0.964-1 for 100 worlds), and of 0 of n its mirror.
    """
    successes = np.asarray(successes, dtype=float)
    n = len(successes)
    if n == 0 or 0.0 < successes.mean() < 1.0:
        return bootstrap_ci(successes, level=level)
    bound = none_of_bound(n, level)
    return (1.0 - bound, 1.0) if successes.mean() == 1.0 else (0.0, bound)


def paired_ci(differences: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """
    Return the interval of a mean paired difference of success (1, 0 or -1 per pair).

    The percentile bootstrap, but where every pair ended the same (all differences 0): there
    it has no width; the difference is at most the share of pairs that differ, none of n
    seen: ``none_of_bound(n)`` either way (0.036 for 100). Where every pair differs alike
    (all 1, or all -1), the pairs that would not are bounded the same way.
    """
    differences = np.asarray(differences, dtype=float)
    if len(differences) == 0 or np.any(differences != differences[0]):
        return bootstrap_ci(differences, level=level)
    bound = none_of_bound(len(differences), level)
    if differences[0] == 0.0:
        return -bound, bound
    # every pair won (or lost) alike: as success_ci's n of n, the rest at most bound
    return (1.0 - bound, 1.0) if differences[0] > 0.0 else (-1.0, bound - 1.0)


def success_curve(records: list[dict], max_paths: int) -> dict:
    """Return success within n paths (n = 1..max_paths): rate, CI low, CI high per n."""
    paths = np.array([r['paths'] if r['success'] else max_paths + 1 for r in records])
    rate, low, high = [], [], []
    for n in range(1, max_paths + 1):
        within = (paths <= n).astype(float)
        ci = success_ci(within)
        rate.append(float(within.mean()))
        low.append(ci[0])
        high.append(ci[1])
    return {'rate': rate, 'low': low, 'high': high}


def world_order(record: dict) -> tuple:
    """Return a record's place among its group's: by world index, then world seed."""
    return (record.get('world', -1), record.get('world_seed', -1))


def group_records(records: list[dict]) -> dict[tuple, list[dict]]:
    """
    Return the records by (family, setting, obstacles, method), each group sorted by world.

    The file's order is the order the workers finished in; the bootstrap resamples by
    position, so its intervals must not depend on that order.
    """
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for record in records:
        groups[(record.get('family', ''), record['setting'], record['obstacles'],
                record['method'])].append(record)
    return {key: sorted(group, key=world_order) for key, group in sorted(groups.items())}


def summarise(records: list[dict]) -> dict:
    """Group episodes by family or setting and obstacle count, and method; compute figures."""
    cells = []
    for (family, setting, obstacles, method), group in group_records(records).items():
        max_paths = group[0]['max_paths']
        curve = success_curve(group, max_paths)
        wins = [r['paths'] for r in group if r['success']]
        times = [t for r in group for t in r['plan_times_s']]
        counted = [r for r in group if 'empty_plans' in r]
        paths = sum(r['paths'] for r in counted)
        cells.append({
            'setting': setting, 'obstacles': obstacles, 'method': method,
            **({'family': family} if family else {}),
            'episodes': len(group), 'max_paths': max_paths,
            # episodes that raised (sweep records their error): counted as unsolved
            'errored': sum('error' in r for r in group),
            'success': curve['rate'][-1], 'ci95': [curve['low'][-1], curve['high'][-1]],
            'curve': curve,
            'mean_paths_successful': statistics.fmean(wins) if wins else None,
            'plan_time_s_median': statistics.median(times) if times else None,
            'empty_plan_share': sum(r['empty_plans'] for r in counted) / paths
            if paths and len(counted) == len(group) else None,
            'episode_wall_s_mean': statistics.fmean(r['wall_s'] for r in group)})
    errored = [r for r in records if 'error' in r]
    return {'cells': cells, 'episodes': len(records), 'paired': paired_rows(records),
            'errored': [{'id': r.get('id', '?'), 'error': r['error']} for r in errored],
            'bootstrap': {'samples': BOOTSTRAP_SAMPLES, 'seed': BOOTSTRAP_SEED,
                          'level': 0.95}}


#: The paper's method, against which the paired comparisons are made.
PAPER_METHOD = 'probabilistic'


def paired(ours: list[dict], theirs: list[dict]) -> dict | None:
    """
    Compare a method's episodes (theirs) with the paper's (ours) on the worlds both ran.

    Per world, the difference of success (1, 0 or -1); its mean with a paired 95 %
    percentile-bootstrap interval (the worlds resampled, as :func:`paired_ci`); and the
    mean paths of each over the worlds both solved (each method's own successes are
    different worlds).  None if no world is in both (records without a world index pair
    with nothing).
    """
    mine = {world_order(r): r for r in ours if 'world' in r}
    other = {world_order(r): r for r in theirs if 'world' in r}
    common = sorted(set(mine) & set(other))
    if not common:
        return None
    diffs = np.array([float(other[w]['success']) - float(mine[w]['success']) for w in common])
    both = [w for w in common if mine[w]['success'] and other[w]['success']]
    ci = paired_ci(diffs)
    return {'worlds': len(common),
            'success': statistics.fmean(float(other[w]['success']) for w in common),
            'success_paper': statistics.fmean(float(mine[w]['success']) for w in common),
            'difference': float(diffs.mean()), 'difference_ci95': [ci[0], ci[1]],
            'both_solved': len(both),
            'mean_paths_both_solved': [statistics.fmean(other[w]['paths'] for w in both),
                                       statistics.fmean(mine[w]['paths'] for w in both)]
            if both else None}


def paired_rows(records: list[dict]) -> list[dict]:
    """Return every method against the paper's, paired by world, per family or setting cell."""
    groups = group_records(records)
    rows = []
    for (family, setting, obstacles, method), group in groups.items():
        ours = groups.get((family, setting, obstacles, PAPER_METHOD))
        if method == PAPER_METHOD or ours is None:
            continue
        comparison = paired(ours, group)
        if comparison is not None:
            rows.append({'setting': setting, 'obstacles': obstacles, 'method': method,
                         **({'family': family} if family else {}), **comparison})
    return rows


def paired_markdown(summary: dict, families: bool) -> str:
    """Return the paired comparisons with the paper's method (families' or settings') ('')."""
    rows = [r for r in summary.get('paired', []) if bool(r.get('family')) == families]
    if not rows:
        return ''
    where = '| family |' if families else '| setting | obstacles |'
    lines = [f'{where} method | worlds of both | success: method / probabilistic '
             '| difference, method - probabilistic (paired 95 % CI) | worlds both solved '
             '| mean paths on the worlds both solved: method / probabilistic |',
             '| --- ' * (8 if not families else 7) + '|']
    for r in rows:
        cell = f'| {r["family"]} |' if families else f'| {r["setting"]} | {r["obstacles"]} |'
        low, high = r['difference_ci95']
        both = r['mean_paths_both_solved']
        paths = '-' if both is None else f'{both[0]:.1f} / {both[1]:.1f}'
        lines.append(f'{cell} {r["method"]} | {r["worlds"]} | {r["success"]:.2f} / '
                     f'{r["success_paper"]:.2f} | {r["difference"]:+.2f} ({low:+.2f} to '
                     f'{high:+.2f}) | {r["both_solved"]} | {paths} |')
    return '\n'.join(lines) + '\n'


def _settings(summary: dict) -> dict:
    """Return the summary with the cells of the paper's settings only."""
    return {**summary, 'cells': [c for c in summary['cells'] if not c.get('family')]}


def _method_order(method: str) -> tuple:
    return (method.split(':')[0] != 'probabilistic', method)


def family_cells(summary: dict) -> list[dict]:
    """Return the cells of entanglement families, in the benchmark's order of families."""
    from probdis_ros.sim.families import FAMILIES

    cells = [c for c in summary['cells'] if c.get('family')]
    rank = {f: k for k, f in enumerate(FAMILIES)}
    return sorted(cells, key=lambda c: (rank.get(c['family'], len(rank)), c['family'],
                                        _method_order(c['method'])))


def family_table(summary: dict) -> str:
    """Return the family cells as a Markdown table (one row per family and method)."""
    lines = ['| family | method | worlds | success within max paths (95 % CI) '
             '| mean paths when successful | empty plans / paths '
             '| median plan time per path [s] |',
             '| --- | --- | --- | --- | --- | --- | --- |']
    for c in family_cells(summary):
        lines.append(f'| {c["family"]} | {c["method"]} | {c["episodes"]} | {_outcome(c)} |')
    return '\n'.join(lines) + '\n'


def _outcome(cell: dict) -> str:
    """Return a cell's success (95 % CI), mean paths, empty-plan share, plan time columns."""
    paths = '-' if cell['mean_paths_successful'] is None else \
        f'{cell["mean_paths_successful"]:.1f}'
    plan = '-' if cell['plan_time_s_median'] is None else f'{cell["plan_time_s_median"]:.3f}'
    share = cell.get('empty_plan_share')
    empty = '?' if share is None else f'{share:.2f}'
    low, high = cell['ci95']
    return f'{cell["success"]:.2f} ({low:.2f}-{high:.2f}) | {paths} | {empty} | {plan}'


def markdown_tables(summary: dict) -> str:
    """Return the tables of whatever the summary holds: settings, families, or both."""
    parts = []
    if _settings(summary)['cells']:
        parts.append(markdown_table(summary))
    if family_cells(summary):
        parts.append(family_table(summary))
    if summary.get('errored'):
        parts.append(errors_markdown(summary))
    return '\n'.join(parts)


def errors_markdown(summary: dict) -> str:
    """Return how many episodes errored (counted as unsolved above), and which ('' if none)."""
    errored = summary.get('errored') or []
    if not errored:
        return ''
    lines = [f'{len(errored)} of {summary["episodes"]} episodes errored (counted as unsolved '
             'in the tables):', '']
    lines += [f'- {e["id"]}: {e["error"]}' for e in errored]
    return '\n'.join(lines) + '\n'


def markdown_table(summary: dict) -> str:
    """Return the settings' cells as a Markdown table (a row per setting, obstacles, method)."""
    summary = _settings(summary)
    lines = ['| setting | obstacles | method | episodes | success (95 % CI) '
             '| mean paths when successful | empty plans / paths '
             '| median plan time per path [s] |',
             '| --- | --- | --- | --- | --- | --- | --- | --- |']
    for c in summary['cells']:
        lines.append(f'| {c["setting"]} | {c["obstacles"]} | {c["method"]} | '
                     f'{c["episodes"]} | {_outcome(c)} |')
    return '\n'.join(lines) + '\n'


def claims(summary: dict) -> dict:
    """
    Check the paper's two claims on a summary; return the rows and the verdicts.

    1. Probabilistic succeeds (within the maximum number of paths) at least as often as every
       baseline, per setting and obstacle count; ``clear`` where its 95 % interval lies above
       the best baseline's rate.
    2. The baselines are sensitive to their parameter: per setting and method family with
       two or more values, whether the ranking of two values flips between obstacle counts
       (one strictly better at one count, the other at another), and the largest gap
       between its values.
    """
    cells: dict[tuple, dict[str, dict]] = defaultdict(dict)
    for c in _settings(summary)['cells']:
        cells[(c['setting'], c['obstacles'])][c['method']] = c
    pairs = {(r['setting'], r['obstacles'], r['method']): r
             for r in summary.get('paired', []) if not r.get('family')}
    beats = []
    for (setting, obstacles), methods in sorted(cells.items()):
        ours = methods.get('probabilistic')
        others = {m: c for m, c in methods.items() if not m.startswith('probabilistic')}
        if ours is None or not others:
            continue
        best = max(others, key=lambda m: others[m]['success'])
        beats.append({'setting': setting, 'obstacles': obstacles,
                      'probabilistic': ours['success'], 'ci95': ours['ci95'],
                      'best_baseline': best, 'baseline': others[best]['success'],
                      'at_least_as_good': ours['success'] >= others[best]['success'],
                      'clear': ours['ci95'][0] > others[best]['success'],
                      # the same worlds: the baseline's paired difference from ours
                      'paired': pairs.get((setting, obstacles, best))})
    families: dict[tuple, dict[int, dict[str, float]]] = defaultdict(lambda: defaultdict(dict))
    for (setting, obstacles), methods in cells.items():
        for method, c in methods.items():
            families[(setting, method.split(':')[0])][obstacles][method] = c['success']
    sensitivity = []
    for (setting, family), by_count in sorted(families.items()):
        values = sorted({m for rates in by_count.values() for m in rates})
        if len(values) < 2:
            continue
        winners = {}
        for n, rates in sorted(by_count.items()):
            top = [m for m in values if rates.get(m) == max(rates.values())]
            winners[n] = top[0] if len(top) == 1 else 'tie'
        flips = any(any(r.get(a, -1) > r.get(b, 2) for r in by_count.values()) and
                    any(r.get(b, -1) > r.get(a, 2) for r in by_count.values())
                    for a in values for b in values if a < b)
        gaps = [max(rates.values()) - min(rates.values()) for rates in by_count.values()]
        sensitivity.append({'setting': setting, 'family': family, 'values': values,
                            'best_by_obstacles': winners, 'best_changes': flips,
                            'largest_gap': max(gaps)})
    return {'beats_every_baseline': beats, 'sensitivity': sensitivity,
            'all_at_least_as_good': all(b['at_least_as_good'] for b in beats)}


def claims_markdown(verdicts: dict) -> str:
    """Return the claims as two Markdown tables."""
    lines = ['| setting | obstacles | probabilistic (95 % CI) | best baseline | its rate '
             '| probabilistic >= every baseline '
             '| probabilistic - baseline, same worlds (paired 95 % CI) '
             '| mean paths on the worlds both solved: probabilistic / baseline |',
             '| --- | --- | --- | --- | --- | --- | --- | --- |']
    for b in verdicts['beats_every_baseline']:
        verdict = ('yes, clearly' if b['clear'] else 'yes') if b['at_least_as_good'] else 'NO'
        pair = b.get('paired')
        if pair is None:
            difference = paths = '-'
        else:       # the pair is baseline - probabilistic: turned round (+ 0.0: no -0.00)
            low, high = pair['difference_ci95']
            difference = (f'{-pair["difference"] + 0.0:+.2f} ({-high + 0.0:+.2f} to '
                          f'{-low + 0.0:+.2f})')
            both = pair['mean_paths_both_solved']
            paths = '-' if both is None else f'{both[1]:.1f} / {both[0]:.1f}'
        lines.append(f'| {b["setting"]} | {b["obstacles"]} | {b["probabilistic"]:.2f} '
                     f'({b["ci95"][0]:.2f}-{b["ci95"][1]:.2f}) | {b["best_baseline"]} | '
                     f'{b["baseline"]:.2f} | {verdict} | {difference} | {paths} |')
    lines += ['', '| setting | method | best value per obstacle count | ranking flips '
              '| largest gap between values |', '| --- | --- | --- | --- | --- |']
    for s in verdicts['sensitivity']:
        best = ', '.join(f'{n}: {m}' for n, m in s['best_by_obstacles'].items())
        lines.append(f'| {s["setting"]} | {s["family"]} | {best} | '
                     f'{"yes" if s["best_changes"] else "no"} | {s["largest_gap"]:.2f} |')
    return '\n'.join(lines) + '\n'


def plot_family_curves(summary: dict, out: str | Path) -> Path:
    """Draw success within n paths per method, a panel per entanglement family."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from probdis_ros.plots import _legend_below, _save

    cells = family_cells(summary)
    families = list(dict.fromkeys(c['family'] for c in cells))
    methods = sorted({c['method'] for c in cells}, key=_method_order)
    fig, axes = plt.subplots(1, len(families), squeeze=False, sharey=True,
                             figsize=(3.2 * len(families), 2.8))
    for cell in cells:
        ax = axes[0, families.index(cell['family'])]
        color = plt.cm.tab10(methods.index(cell['method']))
        n = np.arange(1, cell['max_paths'] + 1)
        ax.step(n, cell['curve']['rate'], where='post', color=color, lw=1.5,
                label=cell['method'])
        ax.fill_between(n, cell['curve']['low'], cell['curve']['high'], step='post',
                        color=color, alpha=0.15, lw=0)
    for k, family in enumerate(families):
        ax = axes[0, k]
        worlds = max(c['episodes'] for c in cells if c['family'] == family)
        ax.set_title(f'{family} ({worlds} worlds)', fontsize=9)
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        ax.set_xlabel('max. planned paths')
    axes[0, 0].set_ylabel('success rate')
    fig.suptitle('entanglement families: success within n paths '
                 '(bands: 95 % bootstrap CI over worlds)', y=1.0)
    fig.tight_layout()
    _legend_below(fig, axes, methods)
    return _save(fig, out)


def check_records(records: list, source: str | Path) -> list[dict]:
    """Return the records if each is an episode record; else ValueError naming the first not."""
    for number, record in enumerate(records, start=1):
        missing = [f for f in EPISODE_FIELDS if f not in record] \
            if isinstance(record, dict) else list(EPISODE_FIELDS)
        if missing:
            raise ValueError(f'{source}: record {number} is not an episode record (no '
                             f'{missing[0]!r})')
        wrong = [f for f, kinds in FIELD_TYPES.items() if not _of_kind(record[f], kinds)]
        if wrong:
            raise ValueError(f'{source}: record {number} has a {wrong[0]!r} of '
                             f'{record[wrong[0]]!r} (not of the kind the sweep writes)')
    return records


def _of_kind(value: object, kinds: tuple[type, ...]) -> bool:
    """Return whether value is of one of kinds (True is no int here, as JSON tells them)."""
    return isinstance(value, kinds) and (bool in kinds or not isinstance(value, bool))


def episode_key(record: dict) -> tuple:
    """Return what makes an episode one: its cell, method and world."""
    return (record.get('family', ''), record['setting'], record['obstacles'],
            record['method'], world_order(record))


def read_sweeps(directory: str | Path, others: Sequence[str | Path] = ()) -> list[dict]:
    """
    Return the episodes of DIR and of other sweep directories, refusing one run twice.

    Other directories bring other methods on the same worlds (a sweep run later, into its
    own directory), so that the report pairs them by world with DIR's; an episode (cell,
    method, world) read twice is refused, naming where (two sweeps that wrote into one
    directory, or a directory given twice), and so are episodes allowed different numbers
    of paths (a method allowed 20 would be paired with one allowed 2).
    """
    records, seen, budgets = [], {}, {}
    for source in [Path(directory), *map(Path, others)]:
        found = check_records(read_episodes(source / EPISODES_FILE), source / EPISODES_FILE)
        if not found:
            raise ValueError(f'{source / EPISODES_FILE}: no episodes (run probdis experiment '
                             'sweep first)')
        for record in found:
            key = episode_key(record)
            if key in seen:
                where = f'twice in {source}' if seen[key] == source.resolve() else \
                    f'in both {seen[key]} and {source.resolve()}'
                raise ValueError(f'{record["method"]} on world {key[-1][0]} of '
                                 f'{key[0] or key[1]} is {where}: a report reads each '
                                 'episode once (--with takes directories of other methods)')
            seen[key] = source.resolve()
            budgets.setdefault(record['max_paths'], source)
        if len(budgets) > 1:
            (first, where), (other, there) = list(budgets.items())[:2]
            raise ValueError(f'episodes allowed {first} paths ({where}) and {other} '
                             f'({there}): a report compares methods at one --max-paths')
        records += found
    return records


def write_report(directory: str | Path, others: Sequence[str | Path] = ()) -> dict:
    """
    Read DIR/episodes.jsonl (and other sweeps'); write the figures and summaries into DIR.

    The summary's ``files`` names what was written, ``sources`` the directories read.
    """
    from probdis_ros.plots import plot_sensitivity, plot_success_curves

    directory = Path(directory)
    records = read_sweeps(directory, others)
    summary = summarise(records)
    summary['sources'] = [str(directory), *map(str, others)]
    summary['claims'] = claims(summary)
    files = []
    settings = _settings(summary)
    text = []
    if settings['cells']:
        text += [markdown_table(summary), claims_markdown(summary['claims'])]
        pairs = paired_markdown(summary, families=False)
        if pairs:
            text.append(pairs)
        plot_success_curves(settings, directory / 'success.png')
        plot_sensitivity(settings, directory / 'sensitivity.png')
        files += ['success.png', 'sensitivity.png']
    if family_cells(summary):
        text.append(family_table(summary))
        pairs = paired_markdown(summary, families=True)
        if pairs:
            text.append(pairs)
        plot_family_curves(summary, directory / 'families.png')
        files.append('families.png')
    if summary['errored']:
        text.append(errors_markdown(summary))
    summary['files'] = [*files, 'summary.json', 'summary.md']
    # (a report killed midway leaves the previous summary or the new one, never half)
    write_atomically(directory / 'summary.json', json.dumps(summary, indent=1) + '\n',
                     private=False)
    write_atomically(directory / 'summary.md', '\n'.join(text), private=False)
    return summary
