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
A picture of a physics run without RViz: the scene, the flange path and the failures.

Three views of one figure: a 3-D view, from above (x-y) and from the side (x-z).
Obstacles are drawn as the scene file places them (grey rigid, orange yielding), the
flange path as the arm moved (blue, from the start o to the end x, drawn over the goal),
the goal's flange position as a star, and every failure as a red arrow in the direction
the object was blocked.  matplotlib only (Agg), so it draws on a robot PC or in CI alike.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ARROW = 0.06


def primitive_points(shape, n: int = 14) -> np.ndarray:
    """Return points on a primitive's surface in its parent frame, for outlines."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.linspace(0, np.pi, n // 2))
    if shape.kind == 'box':
        corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        local = corners * np.asarray(shape.size) / 2
    elif shape.kind == 'sphere':
        r = shape.size[0]
        local = r * np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)],
                             axis=-1).reshape(-1, 3)
    else:
        radius, length = shape.size
        ring = np.stack([radius * np.cos(u[0]), radius * np.sin(u[0])], axis=-1)
        ends = [-length / 2, length / 2]
        local = np.vstack([np.column_stack([ring, np.full(len(ring), z)]) for z in ends])
        if shape.kind == 'capsule':
            cap = radius * np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v),
                                     np.cos(v)], axis=-1).reshape(-1, 3)
            half = np.array([0.0, 0.0, length / 2])
            local = np.vstack([local, cap + half, cap - half])
    return local @ np.asarray(shape.rotation).T + np.asarray(shape.position)


def _hull(points: np.ndarray) -> np.ndarray:
    """Return the convex hull of 2-D points, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(map(tuple, np.round(points, 9)))
    if len(pts) < 3:
        return np.array(pts)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def plot_scene_run(scene, flange: np.ndarray, failures: list[tuple[np.ndarray, np.ndarray]],
                   goal_flange: np.ndarray | None, out: str | Path, title: str = '') -> Path:
    """Draw scene, flange path ``(N, 3)`` and failures ``[(x, v), ...]``; return out."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib.patches import Patch, Polygon
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from probdis_ros.plots import thin_3d_ticks

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig = plt.figure(figsize=(15, 5.2))
    ax3 = fig.add_subplot(1, 3, 1, projection='3d')
    views = [fig.add_subplot(1, 3, 2), fig.add_subplot(1, 3, 3)]
    shapes = [(o.shape, 'tab:orange' if o.hinge is not None else '0.55')
              for o in scene.obstacles]
    for shape, colour in shapes:
        points = primitive_points(shape)
        if shape.kind == 'box':      # corners in meshgrid order: faces by fixed coordinate
            corners = points.reshape(2, 2, 2, 3)
            faces = [corners[i] for i in (0, 1)] + [corners[:, i] for i in (0, 1)] + \
                [corners[:, :, i] for i in (0, 1)]
            quads = [f.reshape(4, 3)[[0, 1, 3, 2]] for f in faces]
            ax3.add_collection3d(Poly3DCollection(quads, color=colour, alpha=0.35))
        else:
            ax3.scatter(*points.T, s=3, color=colour, alpha=0.5)
        for ax, (i, j) in zip(views, [(0, 1), (0, 2)]):
            ax.add_patch(Polygon(_hull(points[:, [i, j]]), closed=True, color=colour,
                                 alpha=0.45, lw=0))
    flange = np.asarray(flange).reshape(-1, 3)
    panels = [(ax3, (0, 1, 2)), (views[0], (0, 1)), (views[1], (0, 2))]
    for ax, axes in panels:
        ax.plot(*flange[:, axes].T, color='tab:blue', lw=1.5, label='flange path')
        ax.plot(*flange[0, axes], 'o', color='tab:blue', ms=7, label='start')
        if goal_flange is not None:
            ax.plot(*np.asarray(goal_flange)[list(axes)], '*', color='tab:green', ms=13,
                    label='goal')
        # over the goal's star, where a run that got out ends
        ax.plot(*flange[-1, axes], 'x', color='navy', ms=9, mew=2, label='end', zorder=5)
        for k, (x, v) in enumerate(failures):
            x, v = np.asarray(x), np.asarray(v) / max(np.linalg.norm(v), 1e-12)
            tip = x + ARROW * v
            ax.plot(*np.stack([x, tip])[:, axes].T, color='tab:red', lw=2,
                    label='failures' if k == 0 else None)
            ax.plot(*x[list(axes)], '.', color='tab:red', ms=8)
    ax3.set_xlabel('x [m]')
    ax3.set_ylabel('y [m]')
    ax3.set_zlabel('z [m]')
    ax3.set_title('in 3-D')
    thin_3d_ticks(ax3)
    for ax, (a, b), name in zip(views, [('x', 'y'), ('x', 'z')], ['from above', 'from the side']):
        ax.set_xlabel(f'{a} [m]')
        ax.set_ylabel(f'{b} [m]')
        ax.set_aspect('equal', adjustable='datalim')
        ax.set_title(name)
        ax.grid(alpha=0.3)
    handles = views[1].get_legend_handles_labels()[0] + [
        Patch(color=colour, alpha=0.45, label=name)
        for colour, name in (('0.55', 'obstacles (hidden from the planner)'),
                             ('tab:orange', 'yielding obstacles'))
        if any(c == colour for _, c in shapes)]
    views[1].legend(handles=handles, loc='upper left', bbox_to_anchor=(1.02, 1.0), fontsize=8)
    fig.suptitle(title or scene.name)
    # room for the 3-D view's z label, which tight_layout does not see (it ran into the
    # view from above's y label)
    fig.tight_layout(w_pad=4.0)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
