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
Pictures: the 2-D failure probability map (the paper's Fig. 6).

matplotlib is imported lazily and always with the Agg backend, so plotting works on a robot
PC without a display.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from probdis_ros.model import FailureMap, TaskPoints, TaskSpace


def example_map(c_fail: float = 100.0) -> FailureMap:
    """Build a map of failures around a disc at (0.3, 0.1), r = 0.08, hit from three sides."""
    fmap = FailureMap(TaskSpace.POINT2, c_fail)
    centre, radius = np.array([0.3, 0.1]), 0.08
    for approach in (0.0, 0.6, -0.7):
        v = np.array([np.cos(approach), np.sin(approach)])
        fmap.add(centre - radius * v, v)
    return fmap


def probability_grid(fmap: FailureMap, extent: tuple[float, float, float, float],
                     resolution: int = 300) -> np.ndarray:
    """Evaluate ``P(FAIL)`` on a ``resolution x resolution`` grid over (x0, x1, y0, y1)."""
    xs = np.linspace(extent[0], extent[1], resolution)
    ys = np.linspace(extent[2], extent[3], resolution)
    gx, gy = np.meshgrid(xs, ys)
    points = np.column_stack([gx.ravel(), gy.ravel()])
    return fmap.probability(TaskPoints(points)).reshape(resolution, resolution)


def auto_extent(fmap: FailureMap, margin: float = 0.25) -> tuple[float, float, float, float]:
    """Return a square view (x0, x1, y0, y1) around the failures."""
    if len(fmap) == 0:
        return (-margin, margin, -margin, margin)
    lo = fmap.points.min(axis=0) - margin
    hi = fmap.points.max(axis=0) + margin
    half = max(hi - lo) / 2
    mid = (lo + hi) / 2
    return (mid[0] - half, mid[0] + half, mid[1] - half, mid[1] + half)


def plot_map(fmap: FailureMap, out: str | Path,
             extent: tuple[float, float, float, float] | None = None,
             title: str = 'Failure probability map') -> Path:
    """Draw P(FAIL) (dark = likely blocked), failures (red) and their directions (blue)."""
    if fmap.task_space is not TaskSpace.POINT2:
        raise ValueError(f'map plot draws 2-D maps; this map is {fmap.task_space.value}')
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    extent = extent or auto_extent(fmap)
    grid = probability_grid(fmap, extent)
    fig, ax = plt.subplots(figsize=(5.5, 5))
    image = ax.imshow(grid, origin='lower', extent=extent, cmap='gray_r', vmin=0.0, vmax=1.0)
    fig.colorbar(image, ax=ax, label='P(FAIL)', shrink=0.8)
    if len(fmap):
        scale = 0.08 * (extent[1] - extent[0])
        ax.quiver(fmap.points[:, 0], fmap.points[:, 1], fmap.directions[:, 0] * scale,
                  fmap.directions[:, 1] * scale, color='tab:blue', angles='xy',
                  scale_units='xy', scale=1, width=0.008, label='blocked direction')
        ax.plot(fmap.points[:, 0], fmap.points[:, 1], 'o', color='tab:red', label='failure')
        ax.legend(loc='upper left', fontsize=8)
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(title)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120, bbox_inches='tight')
    plt.close(fig)
    return out


def plot_episode(result, out: str | Path) -> Path:
    """
    Draw a 2-D episode like the paper's Fig. 2.

    The arm at start (grey) and goal (green), the end-effector traces of the executed paths
    (blue, the last one darkest), the planned path of the last attempt (dashed orange), failures
    (red), the final probability map (dark = likely blocked) and the hidden obstacles
    (black outlines, for the viewer only).
    """
    world = result.world
    if world.setting != '2d':
        raise ValueError(f'--plot draws 2-D episodes; this one is {world.setting}')
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib.patches import Circle
    import matplotlib.pyplot as plt

    arm = world.arm
    reach = float(arm.link_lengths.sum())
    extent = (-reach, reach, -reach, reach)
    fig, ax = plt.subplots(figsize=(6.5, 6))
    grid = probability_grid(result.loop.fmap, extent, resolution=240)
    ax.imshow(grid, origin='lower', extent=extent, cmap='gray_r', vmin=0.0, vmax=1.0)
    for k, obstacle in enumerate(world.obstacles):
        ax.add_patch(Circle(obstacle.center, obstacle.radius, fill=False, color='black', lw=1.2,
                            label='hidden obstacles' if k == 0 else None))
    for k, trace in enumerate(result.traces):
        xy = arm.fk(trace).positions
        alpha = 0.25 + 0.75 * (k + 1) / len(result.traces)
        ax.plot(xy[:, 0], xy[:, 1], color='tab:blue', alpha=alpha, lw=1.5,
                label='executed paths' if k == len(result.traces) - 1 else None)
    if result.loop.attempts:     # drawn over the last trace, which it follows where it got out
        planned = arm.fk(_dense(result.loop.attempts[-1].path)).positions
        ax.plot(planned[:, 0], planned[:, 1], '--', color='tab:orange', lw=1,
                label='last plan', zorder=3)
    arms = ((world.start, 'grey', 'start'), (world.goal, 'tab:green', 'goal'))
    for config, color, label in arms:
        links = arm.link_points(config)
        ax.plot(links[:, 0], links[:, 1], '-o', color=color, lw=2, ms=3, label=label)
    fmap = result.loop.fmap
    if len(fmap):
        ax.plot(fmap.points[:, 0], fmap.points[:, 1], 'o', color='tab:red', ms=4,
                label='failures')
    outcome = 'success' if result.success else 'not disentangled'
    ax.set_title(f'{world.name or "2-D episode"}: {outcome} after {result.paths} paths')
    ax.set_xlim(extent[:2])
    ax.set_ylim(extent[2:])
    ax.set_aspect('equal')
    ax.set_xlabel('x (links of 0.1)')
    ax.set_ylabel('y')
    ax.legend(loc='lower left', fontsize=8)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120, bbox_inches='tight')
    plt.close(fig)
    return out


def _dense(path: np.ndarray, step: float = 0.02) -> np.ndarray:
    from probdis_ros.sim.compliant_arm import densify

    return densify(np.asarray(path), step)[0]


def thin_3d_ticks(ax3) -> None:
    """Keep four ticks on a 3-D view's x and y axes (their labels ran together)."""
    from matplotlib.ticker import MaxNLocator

    for axis in (ax3.xaxis, ax3.yaxis):
        axis.set_major_locator(MaxNLocator(4))


def plot_replay(result, out: str | Path, d_dist: float) -> Path:
    """
    Draw a replay: the L1 joint gap over time with the blocks, and the flange path.

    Where the joint states carry efforts, a panel between them draws the external-torque
    estimate per joint (efforts less gravity and dynamics): how hard the arm pressed,
    against its level in free motion (the load data's error and the model's).
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from probdis_ros.model import iiwa_arm

    panels = 3 if result.torques else 2
    fig = plt.figure(figsize=(5.5 * panels, 4.5))
    ax = fig.add_subplot(1, panels, 1)
    ax.plot(result.times, result.gaps, lw=1, color='tab:blue', label='|desired - actual|_1')
    ax.axhline(d_dist, color='grey', ls='--', lw=1, label='d_dist')
    _mark_blocks(ax, result.blocks)
    ax.set_xlabel('time since the bag started [s]')
    ax.set_ylabel('joint gap [rad]')
    ax.legend(fontsize=8)
    if result.torques:
        axt = fig.add_subplot(1, panels, 2)
        times = [t for t, _ in result.torques]
        torques = np.array([tau for _, tau in result.torques])
        for j in range(torques.shape[1]):
            axt.plot(times, torques[:, j], lw=1, label=f'A{j + 1}')
        _mark_blocks(axt, result.blocks)
        axt.set_xlabel('time since the bag started [s]')
        axt.set_ylabel('external torque estimate [Nm]')
        axt.legend(fontsize=7, ncol=4)
    ax3 = fig.add_subplot(1, panels, panels, projection='3d')
    if result.configs:
        xyz = iiwa_arm().fk(np.array(result.configs)).positions
        ax3.plot(xyz[:, 0], xyz[:, 1], xyz[:, 2], color='tab:blue', lw=1)
    if result.blocks:
        x = np.array([b.x for b in result.blocks])
        ax3.scatter(x[:, 0], x[:, 1], x[:, 2], color='black', marker='x', s=30,
                    label='blocks')
        ax3.legend(fontsize=8)
    ax3.set_xlabel('x [m]')
    ax3.set_ylabel('y [m]')
    ax3.set_zlabel('z [m]')
    thin_3d_ticks(ax3)
    ax3.set_title('flange path')
    fig.suptitle(f'{result.paths} path(s), {len(result.blocks)} block(s), '
                 f'{"success" if result.success else "not disentangled"}')
    return _save(fig, out)


def plot_calibration(fit, out: str | Path) -> Path:
    """Draw a free move's peak gap at each motion delay, the blocked ones and the best."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    delays, gaps = np.array(fit.delays), np.array(fit.peak_gaps)
    blocked = np.array(fit.blocks) > 0
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    ax.plot(delays, gaps, color='tab:blue', lw=1, marker='.', label='peak gap, free')
    if blocked.any():
        ax.plot(delays[blocked], gaps[blocked], ls='none', marker='x', color='tab:red',
                label='read as blocked')
    low, high = fit.equal
    if high > low:
        ax.axvspan(low, high, color='tab:green', alpha=0.15, label='as good as the least')
    ax.axvline(fit.best, color='black', ls=':', lw=1.2,
               label=f'best: {fit.best:g} s, {fit.best_gap:.3f} rad')
    ax.set_xlabel('motion_delay [s]')
    ax.set_ylabel('peak L1 gap to the command [rad]')
    ax.set_ylim(bottom=0.0)
    ax.legend(fontsize=8)
    ax.set_title('the lag of the arm: the motion_delay of the least peak gap')
    return _save(fig, out)


def _mark_blocks(ax, blocks) -> None:
    """Draw a vertical black dotted line at each block's time (no joint's colour)."""
    for k, block in enumerate(blocks):
        ax.axvline(block.t, color='black', ls=':', lw=1.2, label='block' if k == 0 else None)


def _grid(summary: dict):
    """
    Return the settings, each setting's obstacle counts and the methods of a summary, sorted.

    Counts are per setting: the paper runs the orientation setting with more obstacles.
    """
    cells = summary['cells']
    order = {'2d': 0, '3d': 1, '3d-orient': 2}
    settings = sorted({c['setting'] for c in cells}, key=lambda s: order.get(s, 9))
    counts = {s: sorted({c['obstacles'] for c in cells if c['setting'] == s}) for s in settings}
    methods = sorted({c['method'] for c in cells},
                     key=lambda m: (m.split(':')[0] != 'probabilistic', m))
    return settings, counts, methods


def _legend_below(fig, axes, methods: list[str]) -> None:
    """Put one legend for the whole figure under its panels."""
    handles, labels = axes.flat[0].get_legend_handles_labels()
    for ax in axes.flat[1:]:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            if label not in labels:
                handles.append(handle)
                labels.append(label)
    ordered = [(handles[labels.index(m)], m) for m in methods if m in labels]
    fig.legend([h for h, _ in ordered], [m for _, m in ordered], loc='lower center',
               ncol=len(ordered), fontsize=8, bbox_to_anchor=(0.5, -0.04), frameon=False)


def plot_success_curves(summary: dict, out: str | Path) -> Path:
    """Draw success rate against the number of planned paths, one panel per cell (Fig. 4)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    settings, counts, methods = _grid(summary)
    columns = max(len(c) for c in counts.values())
    fig, axes = plt.subplots(len(settings), columns, squeeze=False, sharex=True,
                             sharey=True, figsize=(3.2 * columns, 2.6 * len(settings)))
    colors = {m: plt.cm.tab10(k) for k, m in enumerate(methods)}
    for cell in summary['cells']:
        ax = axes[settings.index(cell['setting']),
                  counts[cell['setting']].index(cell['obstacles'])]
        n = np.arange(1, cell['max_paths'] + 1)
        curve = cell['curve']
        ax.step(n, curve['rate'], where='post', color=colors[cell['method']], lw=1.5,
                label=cell['method'])
        ax.fill_between(n, curve['low'], curve['high'], step='post',
                        color=colors[cell['method']], alpha=0.15, lw=0)
    for r, setting in enumerate(settings):
        for k in range(columns):
            ax = axes[r, k]
            if k >= len(counts[setting]):
                ax.set_visible(False)
                continue
            ax.set_title(f'{setting}, {counts[setting][k]} obstacles', fontsize=9)
            ax.set_ylim(0, 1.02)
            ax.grid(alpha=0.3)
            ax.set_xlabel('max. planned paths')
            if k == 0:
                ax.set_ylabel('success rate')
    fig.suptitle('success within n paths (bands: 95 % bootstrap CI over worlds)', y=1.0)
    fig.tight_layout()
    _legend_below(fig, axes, methods)
    return _save(fig, out)


def plot_sensitivity(summary: dict, out: str | Path) -> Path:
    """Draw success at the maximum number of paths per method, with CIs (Fig. 5)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    settings, counts, methods = _grid(summary)
    fig, axes = plt.subplots(1, len(settings), squeeze=False, sharey=True,
                             figsize=(4.6 * len(settings), 3.4))
    width = 0.8 / len(methods)
    for s, setting in enumerate(settings):
        ax = axes[0, s]
        for m, method in enumerate(methods):
            cells = {c['obstacles']: c for c in summary['cells']
                     if c['setting'] == setting and c['method'] == method}
            x = np.arange(len(counts[setting])) + (m - (len(methods) - 1) / 2) * width
            rate = np.array([cells[n]['success'] if n in cells else np.nan
                             for n in counts[setting]])
            low = np.array([cells[n]['ci95'][0] if n in cells else np.nan
                            for n in counts[setting]])
            high = np.array([cells[n]['ci95'][1] if n in cells else np.nan
                             for n in counts[setting]])
            ax.bar(x, rate, width, yerr=[rate - low, high - rate], capsize=2, label=method,
                   color=plt.cm.tab10(m))
        ax.set_xticks(np.arange(len(counts[setting])), [str(n) for n in counts[setting]])
        ax.set_xlabel('obstacles')
        ax.set_title(setting)
        ax.set_ylim(0, 1.05)
        ax.grid(axis='y', alpha=0.3)
    axes[0, 0].set_ylabel('success within the maximum paths')
    fig.tight_layout()
    _legend_below(fig, axes, methods)
    return _save(fig, out)


def _save(fig, out: str | Path) -> Path:
    import matplotlib.pyplot as plt

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches='tight')
    plt.close(fig)
    return out
