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
The informed failure map: a failure teaches about the surface it hit, free motion too.

The paper's map keeps each failure a point whose probability falls off to its sides (the
``(alpha / pi)^3`` factor is 1/8 beside it): a wall hit once is remembered as a spot, and
the next path tries the same wall a few centimetres away (seen in the entanglement
families: nine tries on one wall, two of them 6 mm apart).  This map keeps the paper's
kernel (the compiled edge costs read it unchanged) and changes only what it is made of:

* surface (idea b): failures close together that move into one plane (three or more on
  it, or two) reveal a wall: *virtual* failures fill that plane, every ``surface_spacing``
  within ``surface_radius`` of each of them, facing along its normal, so that every
  approach beyond the wall is ahead of one whatever its angle (a real failure's cone
  follows the motion that hit, and is 1/8 beside it).  A lone failure stays a point.
* free (idea c): motions the object made without contact are remembered (task-space points
  with their orientation); a virtual failure that such a point lies just beyond (within
  ``free_radius``, ahead of it, object turned alike within ``free_turn``) is dropped, and
  none is made there later: the wall does not reach that far.  Real failures stay (the
  kernel has no negative term; a measured block is never forgotten).
* adaptive C_FAIL (idea e): every real failure that repeats an earlier one (within
  ``repeat_radius``, direction within 45 degrees) widens the map: ``C_FAIL`` is divided by
  ``1 + repeat_gain * repeats``, down to ``c_fail_min``.

Old virtual failures stay when a better plane is found later.  ``len(map)`` counts the
real failures only (what episodes report); :attr:`points` and its siblings hold real and
virtual ones, which is what the planner costs.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from probdis_ros.model.arms import TaskSpace
from probdis_ros.model.failure_map import DEFAULT_C_FAIL, FailureMap


@dataclass(frozen=True)
class MapIdeas:
    """Which of the map's ideas are on, and their parameters (chosen on training worlds)."""

    surface: bool = False
    free: bool = False
    adaptive: bool = False
    surface_reach: float = 0.08      # [m] failures this near, moving alike, share a surface
    plane_tolerance: float = 0.01    # [m] how far from a fitted plane its failures may be
    surface_facing: float = 0.2      # a member's motion has at least this normal component
    surface_radius: float = 0.04     # [m] the surface is filled this far around each member
    surface_spacing: float = 0.02    # [m] between virtual failures
    free_radius: float = 0.03        # [m] a free point this near a virtual failure ...
    free_turn: float = 0.35          # [rad] ... turned at most this much from it drops it
    repeat_radius: float = 0.05      # [m] a failure this near an alike one is a repeat
    repeat_gain: float = 0.5
    c_fail_min: float = 25.0         # [1/m^2] the widest the adaptive map gets


def _plane_basis(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return two unit vectors spanning the plane perpendicular to unit v (3-D or 2-D)."""
    if len(v) == 2:
        return np.array([-v[1], v[0]]), np.zeros(2)
    helper = np.eye(3)[int(np.argmin(np.abs(v)))]
    e1 = np.cross(v, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(v, e1)


def turn_angles(q: np.ndarray, qs: np.ndarray) -> np.ndarray:
    """Return the rotation angles [rad] between unit quaternion q and each of qs."""
    return 2.0 * np.arccos(np.clip(np.abs(qs @ q), 0.0, 1.0))


class InformedMap(FailureMap):
    """A failure map whose failures also reveal surfaces, and that learns from free motion."""

    def __init__(self, task_space: TaskSpace, c_fail: float = DEFAULT_C_FAIL,
                 ideas: MapIdeas | None = None) -> None:
        super().__init__(task_space, c_fail)
        self.ideas = ideas or MapIdeas()
        self.base_c_fail = float(c_fail)
        self.virtual = np.empty(0, dtype=bool)
        self.repeats = 0
        self.free_points = np.empty((0, self.task_space.dim))
        self.free_orientations = np.empty((0, 4))

    def __len__(self) -> int:
        return int((~self.virtual).sum())

    def clear(self) -> None:
        """Forget every failure and every free motion."""
        self.__init__(self.task_space, self.base_c_fail, self.ideas)

    def _append(self, x: np.ndarray, v: np.ndarray, q: np.ndarray | None,
                virtual: bool) -> None:
        super().add(x, v, q)
        self.virtual = np.append(self.virtual, virtual)

    def add(self, x: np.ndarray, v: np.ndarray, q: np.ndarray | None = None) -> None:
        """Record a blocked movement, and what it reveals (a surface, a repeat)."""
        ideas = self.ideas
        real = ~self.virtual
        earlier = (self.points[real], self.directions[real])
        self._append(x, v, q, False)
        x, v, q = self.points[-1], self.directions[-1], self.orientations[-1]
        if ideas.adaptive and len(earlier[0]):
            near = np.linalg.norm(earlier[0] - x, axis=1) < ideas.repeat_radius
            alike = earlier[1] @ v > math.cos(math.pi / 4)
            if np.any(near & alike):
                self.repeats += 1
                self.c_fail = max(ideas.c_fail_min,
                                  self.base_c_fail / (1.0 + ideas.repeat_gain * self.repeats))
        if ideas.surface:
            self._reveal_surface(x, v, q)

    def _reveal_surface(self, x: np.ndarray, v: np.ndarray, q: np.ndarray) -> None:
        """
        Cover the surface that a failure and its alike neighbours lie on with virtual ones.

        The neighbours are the real failures within ``surface_reach`` moving the same way
        (positive dot product).  Three or more that lie on a plane (within ``plane_tolerance``)
        give it by least squares; otherwise the nearest one and this failure give a plane
        through both, facing their mean direction.  The plane's normal, turned to face the
        motions, is the virtual failures' direction: every approach beyond the surface is
        ahead of one, whatever its angle.  They fill, every ``surface_spacing``, the plane
        within ``surface_radius`` of each member (not the whole plane: a hole or an edge may
        be near).
        """
        ideas = self.ideas
        real = ~self.virtual
        real[-1] = False
        gap = np.linalg.norm(self.points[real] - x, axis=1)
        alike = (gap < ideas.surface_reach) & (self.directions[real] @ v > 0.0)
        if not alike.any():
            return
        members = np.vstack([x, self.points[real][alike]])
        motions = np.vstack([v, self.directions[real][alike]])
        mean = motions.sum(axis=0)
        normal = None
        if len(members) >= 3:
            centred = members - members.mean(axis=0)
            _, _, axes = np.linalg.svd(centred, full_matrices=False)
            if axes.shape[0] == members.shape[1] and \
                    np.abs(centred @ axes[-1]).max() <= ideas.plane_tolerance:
                normal = axes[-1]
        if normal is None:
            nearest = 1 + int(np.argmin(gap[alike]))
            along = members[nearest] - x
            along /= np.linalg.norm(along)
            members, motions = members[[0, nearest]], motions[[0, nearest]]
            mean = motions.sum(axis=0)
            normal = mean - (mean @ along) * along
        norm = float(np.linalg.norm(normal))
        if norm < 1e-9:
            return
        normal = normal / norm * (1.0 if normal @ mean >= 0 else -1.0)
        if np.any(motions @ normal < ideas.surface_facing):
            return      # some member moves almost along the plane: not one wall
        basis = _plane_basis(normal)
        steps = int(ideas.surface_radius / ideas.surface_spacing)
        offsets = [a * basis[0] + b * basis[1] for a in range(-steps, steps + 1)
                   for b in (range(-steps, steps + 1) if len(x) == 3 else (0,))
                   if 0 < math.hypot(a, b) * ideas.surface_spacing <= ideas.surface_radius]
        offsets = ideas.surface_spacing * np.array(offsets)
        for member in members:
            for point in member + offsets:
                close = np.linalg.norm(self.points[self.virtual] - point, axis=1)
                if np.any(close < 0.5 * ideas.surface_spacing) or \
                        self._contradicted(point, normal, q):
                    continue
                self._append(point, normal, q, True)
            if not np.any(np.linalg.norm(self.points[self.virtual] - member, axis=1) < 1e-9):
                self._append(member, normal, q, True)

    def _contradicted(self, point: np.ndarray, v: np.ndarray, q: np.ndarray,
                      free: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
        """Tell whether free motion (default: all remembered) went just beyond point."""
        points, orientations = free or (self.free_points, self.free_orientations)
        if not (self.ideas.free and len(points)):
            return False
        ahead = points - point
        hit = (np.einsum('nd,nd->n', ahead, ahead) < self.ideas.free_radius ** 2) & \
            (ahead @ v > 0.0)
        if self.task_space.has_orientation and np.any(hit):
            hit &= turn_angles(q, orientations) <= self.ideas.free_turn
        return bool(np.any(hit))

    def observe_free(self, positions: np.ndarray, orientations: np.ndarray | None) -> None:
        """Remember task-space poses the object passed without contact; drop what they refute."""
        if not self.ideas.free or len(positions) == 0:
            return
        positions = np.asarray(positions, dtype=float).reshape(-1, self.task_space.dim)
        if orientations is None:
            orientations = np.tile([1.0, 0.0, 0.0, 0.0], (len(positions), 1))
        orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
        self.free_points = np.vstack([self.free_points, positions])
        self.free_orientations = np.vstack([self.free_orientations, orientations])
        new = (positions, orientations)
        keep = np.array([not (virtual and self._contradicted(x, v, q, new)) for x, v, q, virtual
                         in zip(self.points, self.directions, self.orientations, self.virtual)],
                        dtype=bool)
        if not keep.all():
            self.points, self.directions = self.points[keep], self.directions[keep]
            self.orientations, self.virtual = self.orientations[keep], self.virtual[keep]
