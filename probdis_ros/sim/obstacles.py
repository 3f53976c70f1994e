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
Hidden obstacles and the contact test of a moving end-effector.

The end-effector is a point moving along a polyline in task space (the forward kinematics of
a finely discretised joint path).  Contact is tested on every straight piece of that
polyline, not at its vertices, so an obstacle of any thickness between two vertices, even a
flat disc, is hit and never jumped over.

Obstacles, as in the paper's three settings:

* ``disc`` in 2-D: a filled circle in the plane.
* ``ball`` in 3-D: a solid sphere.
* ``disc`` in 3-D: a flat, zero-thickness disc with a normal; the point is blocked where it
  crosses the disc.

With an ``orientation`` (quaternion w, x, y, z) an obstacle blocks only while the
end-effector orientation is similar to it: ``D_ORIENT(q_ee, q_obs) < orientation_tolerance``
with ``D_ORIENT = (2 / pi) arccos(|q_ee . q_obs|)``, so it can be passed by turning the
grasped object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from probdis_ros.model.failure_map import unit


@dataclass(frozen=True)
class Obstacle:
    """One hidden obstacle: a 2-D disc, a 3-D ball, or a flat 3-D disc (with normal)."""

    kind: str
    center: np.ndarray
    radius: float
    normal: np.ndarray | None = None
    orientation: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Check the shape is complete and consistent."""
        center = np.asarray(self.center, dtype=float)
        if self.kind not in ('disc', 'ball'):
            raise ValueError(f"obstacle kind must be 'disc' or 'ball', got {self.kind!r}")
        if center.shape not in ((2,), (3,)) or not np.all(np.isfinite(center)):
            raise ValueError(f'obstacle center must be 2 or 3 finite numbers, got {self.center}')
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f'obstacle radius must be positive, got {self.radius}')
        if self.kind == 'ball' and center.shape != (3,):
            raise ValueError('a ball is 3-D: its center needs 3 numbers')
        object.__setattr__(self, 'center', center)
        if self.kind == 'disc' and center.shape == (3,):
            normal = np.asarray(self.normal if self.normal is not None else [np.nan] * 3,
                                dtype=float)
            if normal.shape != (3,) or not np.all(np.isfinite(normal)) or \
                    np.linalg.norm(normal) == 0:
                raise ValueError('a 3-D disc needs a nonzero normal of 3 numbers')
            object.__setattr__(self, 'normal', unit(normal))
        if self.orientation is not None:
            quat = np.asarray(self.orientation, dtype=float)
            if quat.shape != (4,) or not np.all(np.isfinite(quat)) or np.linalg.norm(quat) == 0:
                raise ValueError('obstacle orientation must be a nonzero quaternion (w, x, y, z)')
            object.__setattr__(self, 'orientation', unit(quat))

    @property
    def dim(self) -> int:
        """Return the dimension of the obstacle's space."""
        return len(self.center)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Return which points are inside (a flat disc contains nothing)."""
        points = np.atleast_2d(points)
        if self.kind == 'disc' and self.dim == 3:
            return np.zeros(len(points), dtype=bool)
        return ((points - self.center) ** 2).sum(axis=1) < self.radius ** 2

    def first_hit(self, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        """
        Return, per segment p0[i] -> p1[i], the fraction t in [0, 1] of first contact.

        inf where the segment does not touch the obstacle; 0 where it starts inside a ball
        and goes deeper.  One that starts inside and moves outward is free: an end-effector
        that passed into a ball turned away from it and then turned into it is stuck only
        against going on, as a compliant arm pressed into clutter can still pull back out.
        """
        if self.kind == 'disc' and self.dim == 3:
            return self._plane_hit(p0, p1)
        d = p1 - p0
        f = p0 - self.center
        a = (d * d).sum(axis=1)
        b = 2 * (f * d).sum(axis=1)
        c = (f * f).sum(axis=1) - self.radius ** 2
        disc = b * b - 4 * a * c
        t = np.full(len(p0), np.inf)
        inside = c < 0
        t[inside & (b < 0)] = 0.0
        ok = ~inside & (disc >= 0) & (a > 0)
        root = (-b[ok] - np.sqrt(disc[ok])) / (2 * a[ok])
        hit = (root >= 0) & (root <= 1)
        t[np.flatnonzero(ok)[hit]] = root[hit]
        return t

    def _plane_hit(self, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        s0 = (p0 - self.center) @ self.normal
        s1 = (p1 - self.center) @ self.normal
        t = np.full(len(p0), np.inf)
        crossing = ((s0 > 0) & (s1 <= 0)) | ((s0 < 0) & (s1 >= 0))
        frac = s0[crossing] / (s0[crossing] - s1[crossing])
        where = p0[crossing] + frac[:, None] * (p1[crossing] - p0[crossing])
        within = ((where - self.center) ** 2).sum(axis=1) <= self.radius ** 2
        t[np.flatnonzero(crossing)[within]] = frac[within]
        return t

    def blocks_orientation(self, quats: np.ndarray | None, tolerance: float) -> np.ndarray | bool:
        """Return where an end-effector with these orientations is blocked by this obstacle."""
        if self.orientation is None or quats is None:
            return True
        dots = np.clip(np.abs(quats @ self.orientation), 0.0, 1.0)
        return (2.0 / np.pi) * np.arccos(dots) < tolerance

    def to_dict(self) -> dict:
        """Return the obstacle as a scenario-file entry."""
        entry = {'type': self.kind, 'center': self.center.tolist(), 'radius': float(self.radius)}
        if self.normal is not None:
            entry['normal'] = self.normal.tolist()
        if self.orientation is not None:
            entry['orientation'] = self.orientation.tolist()
        return entry


def first_contact(obstacles: list[Obstacle], points: np.ndarray, quats: np.ndarray | None,
                  orientation_tolerance: float) -> tuple[int, float] | None:
    """
    Return (segment index, fraction) of the first contact along a polyline, or None.

    points ``(M, d)`` are the polyline's vertices; quats ``(M, 4)`` the end-effector
    orientation at each vertex (orientation gating uses the segment's start).
    """
    if len(points) < 2 or not obstacles:
        return None
    p0, p1 = points[:-1], points[1:]
    q0 = None if quats is None else quats[:-1]
    best = (np.inf, np.inf)
    for obstacle in obstacles:
        t = obstacle.first_hit(p0, p1)
        gate = obstacle.blocks_orientation(q0, orientation_tolerance)
        if gate is not True:
            t = np.where(gate, t, np.inf)
        hits = np.flatnonzero(np.isfinite(t))
        if len(hits):
            seg = int(hits[0])
            if (seg, t[seg]) < best:
                best = (seg, float(t[seg]))
    if not np.isfinite(best[0]):
        return None
    return int(best[0]), best[1]
