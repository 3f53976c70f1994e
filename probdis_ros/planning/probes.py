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
Ideas d, f, g, i and j of the informed method: probes around the start, for the start tree.

A random tree leaves the start along joint-space edges of up to a radian, whose end-effector
traces are long arcs: seen from the start, its ways out of a trap point wherever the arm's
kinematics happen to send them, and the same few directions come back path after path (in
training ``plate_hole`` worlds twenty paths never came within 14-63 degrees of the hole's
direction, while the straight way out through it cost the map 0.26-1.9, as little as any).
:class:`ProbeRRT` is the paper's ProbRRT whose start tree holds, before it grows, chains of
nodes along straight task-space lines from the start in ``directions`` directions spread
evenly over the sphere (a Fibonacci lattice, turned at random per plan with a draw from the
planner's stream), out to ``length``, a node every ``spacing``.  The map costs every edge
of them as it costs any other; the tree grows from them as from any node; Connect may join
the goal tree to any of them.  Nothing forces a probe: a direction that has failed costs
what the map says, so the cheapest path takes a way out not yet tried, when one is as
cheap as the rest.  The chains follow the lines by damped least squares on the end
effector's position (its orientation is left to the null space), and stop where the arm
cannot follow within its joint limits.

* straight probes (idea d) keep the object about as it was held;
* turning probes (idea f) first turn it in place by ``turn`` about an axis drawn per probe,
  then go straight holding that orientation (as far as the joints allow): an obstacle that
  blocks only the object held as before (a gated wall, a soft item, a hook under its bar)
  lets such a probe through;
* rolling (idea i, with f): the turning probes turn about the last joint's axis, half of
  them each way, instead of about random axes: the wrist's roll, which the arm can make in
  place over its whole turn and which spins an object held along the tool;
* untried (idea g): no probe is offered within ``untried`` of the direction of a failure
  it could reach.
* held after a turn (idea j, with d and f): the straight probes are offered only once a
  failure within the probes' reach was met with the object turned by more than
  ``held_after_turn`` from how it is held at the plan's start.  Until then a turn is the
  first hypothesis (a gate, a hook, a soft item: straight probes would spend a path on
  every gate of a closed box); a block met turned says a turn does not free it there (a
  knob in a slot), so holding it as it is becomes worth a path.

Draws: the lattice's turn, then (turning probes) the axes, both before the tree's own draws
and from the same stream; the paper's ProbRRT is not touched (this class overrides only
where the trees are rooted).
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from probdis_ros.model.arms import Arm, quaternion_to_rotation
from probdis_ros.model.edge_costs import EdgeCoster
from probdis_ros.model.informed_map import turn_angles
from probdis_ros.planning.prob_rrt import ProbRRT
from probdis_ros.planning.tree import Tree


@dataclass(frozen=True)
class ProbeSettings:
    """How the start is probed (first choices, not tuned; measured on training worlds)."""

    directions: int = 32        # straight lines from the start, evenly over the sphere
    length: float = 0.4         # [m] how far each goes (past the far side of a 0.36 m box)
    spacing: float = 0.05       # [m] between the nodes of a chain, or closer:
    joint_step: float = 0.15    # [rad] the longest joint-space edge of a chain
    step: float = 0.01          # [m] of the damped least squares that follow a line
    tolerance: float = 0.005    # [m] a chain stops where the flange strays farther
    damping: float = 1e-3
    turn: float = 0.6 * math.pi     # [rad] turning probes (idea f) first turn this much ...
    turn_step: float = 0.1          # [rad] ... this much at a time ...
    turn_weight: float = 0.3        # [m/rad] ... the orientation weighed this against position
    turn_joint_step: float = 0.3    # [rad] longest joint-space edge while turning in place


def even_directions(n: int, dim: int) -> np.ndarray:
    """Return n unit vectors spread evenly over the circle (dim 2) or the sphere (Fibonacci)."""
    k = np.arange(n) + 0.5
    if dim == 2:
        angle = 2 * math.pi * k / n
        return np.column_stack([np.cos(angle), np.sin(angle)])
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def random_turn(rng: np.random.Generator, dim: int) -> np.ndarray:
    """Return a uniformly random rotation matrix (dim 2 or 3), drawn from rng."""
    if dim == 2:
        angle = rng.uniform(0.0, 2 * math.pi)
        return np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    quat = rng.normal(size=4)
    return quaternion_to_rotation(quat / np.linalg.norm(quat))[0]


def rotations(axes: np.ndarray, angles: np.ndarray | float) -> np.ndarray:
    """Return the rotation matrices of unit axes ``(n, 3)`` by angles (Rodrigues)."""
    angles = np.broadcast_to(np.asarray(angles, dtype=float), (len(axes),))
    k = np.zeros((len(axes), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
    k -= np.transpose(k, (0, 2, 1))
    sin, cos = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + sin * k + (1.0 - cos) * (k @ k)


def _vee(m: np.ndarray) -> np.ndarray:
    """Return the axial vectors of the skew parts of matrices ``(..., 3, 3)``."""
    return 0.5 * np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0],
                           m[..., 1, 0] - m[..., 0, 1]], axis=-1)


def _log(m: np.ndarray) -> np.ndarray:
    """Return the rotation vectors of rotation matrices ``(n, 3, 3)``."""
    angle = np.arccos(np.clip((np.trace(m, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    sin = np.sin(angle)
    scale = np.where(sin > 1e-9, angle / np.where(sin > 1e-9, sin, 1.0), 1.0)
    return _vee(m) * scale[:, None]


#: [rad] the joint shift of the finite-difference Jacobians
JACOBIAN_SHIFT = 1e-6


def _dls_steps(arm: Arm, q: np.ndarray, target: np.ndarray, aim: np.ndarray | None,
               settings: ProbeSettings, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """
    Return configurations q moved toward the targets by damped least squares, all at once.

    Without ``aim``: two steps toward the positions ``target``.  With ``aim`` (rotation
    matrices, one per row): three steps toward the poses, the orientation weighed by
    ``settings.turn_weight``.  Finite-difference Jacobians; q is kept within the limits.
    """
    n, joints = q.shape
    shift = np.concatenate([np.zeros((1, joints)), JACOBIAN_SHIFT * np.eye(joints)])[None]
    for _ in range(2 if aim is None else 3):
        probe = (q[:, None, :] + shift).reshape(-1, joints)
        if aim is None:
            here = arm.positions(probe).reshape(n, joints + 1, -1)
            jac = np.transpose(here[:, 1:] - here[:, :1], (0, 2, 1)) / JACOBIAN_SHIFT
            error = target - here[:, 0]
        else:
            pos, rot = arm.tip_frames(probe)
            pos, rot = pos.reshape(n, joints + 1, 3), rot.reshape(n, joints + 1, 3, 3)
            moved = rot[:, 1:] @ np.transpose(rot[:, :1], (0, 1, 3, 2))
            w = settings.turn_weight
            jac = np.concatenate([pos[:, 1:] - pos[:, :1], w * _vee(moved)], axis=2)
            jac = np.transpose(jac, (0, 2, 1)) / JACOBIAN_SHIFT            # (n, 6, joints)
            error = np.concatenate([target - pos[:, 0], w * _log(
                aim @ np.transpose(rot[:, 0], (0, 2, 1)))], axis=1)
        gram = jac @ np.transpose(jac, (0, 2, 1)) + settings.damping * np.eye(error.shape[1])
        dq = np.einsum('nij,ni->nj', jac, np.linalg.solve(gram, error[..., None])[..., 0])
        q = np.clip(q + dq, lower, upper)
    return q


def last_joint_axis(arm: Arm, q: np.ndarray) -> np.ndarray:
    """Return the unit axis, in the world, about which the last joint turns the tip at q."""
    shifted = np.array([q, q + JACOBIAN_SHIFT * np.eye(len(q))[-1]])
    rot = arm.tip_frames(shifted)[1]
    axis = _vee(rot[1] @ rot[0].T)
    return axis / np.linalg.norm(axis)


def probe_chains(arm: Arm, start: np.ndarray, directions: np.ndarray,
                 settings: ProbeSettings = ProbeSettings(), lower: np.ndarray | None = None,
                 upper: np.ndarray | None = None, axes: np.ndarray | None = None
                 ) -> list[np.ndarray]:
    """
    Return, per direction, the configurations of a chain along a straight line from start.

    A node every ``spacing`` along the line, or sooner where the joints move more than
    ``joint_step`` (so that the straight joint-space edges stay near the line); a chain ends
    before the first node the arm cannot reach within ``tolerance`` (joint limits, or
    ``lower`` / ``upper`` if given; singularity).  All directions are followed at once.
    With ``axes`` (one per direction; an arm with orientation), each chain first turns the
    end effector in place toward ``settings.turn`` about its axis, then follows its line
    holding that orientation, both as far as the joints allow (the orientation weighs
    ``turn_weight`` against the position, and only the position must stay within
    ``tolerance``).
    """
    lower = arm.lower if lower is None else lower
    upper = arm.upper if upper is None else upper
    n = len(directions)
    if n == 0:              # idea g may leave no direction untried: no probe, no crash
        return []
    joints = arm.n_joints
    x0 = arm.positions(start)[0]
    q = np.tile(start, (n, 1))
    alive = np.ones(n, dtype=bool)
    nodes: list[list[np.ndarray]] = [[] for _ in range(n)]
    steps = round(settings.length / settings.step)
    every = max(1, round(settings.spacing / settings.step))
    turning = axes is not None and settings.turn > 0 and arm.task_space.has_orientation
    turns = math.ceil(settings.turn / settings.turn_step) if turning else 0
    if turning:
        r0 = arm.tip_frames(start)[1][0]
    for k in range(1, turns + steps + 1):
        along = max(0, k - turns)
        target = x0 + directions * (along * settings.step)
        aim = rotations(axes, settings.turn * min(1.0, k / turns)) @ r0 if turning else None
        q = _dls_steps(arm, q, target, aim, settings, lower, upper)
        strayed = np.linalg.norm(arm.positions(q) - target, axis=1) > settings.tolerance
        alive &= ~strayed
        if not alive.any():
            break
        last = np.array([chain[-1] if chain else start for chain in nodes])
        far = np.linalg.norm(q - last, axis=1) > (
            settings.joint_step if along else settings.turn_joint_step)
        due = k == turns if along == 0 else along % every == 0
        for i in np.flatnonzero(alive & (far | due)):
            nodes[i].append(q[i].copy())
    return [np.array(chain).reshape(-1, joints) for chain in nodes]


def add_chains(tree: Tree, chains: list[np.ndarray], arm: Arm, coster: EdgeCoster) -> int:
    """Hang each chain from the tree's root, edge by edge, costed; return the nodes added."""
    added = 0
    for chain in chains:
        if not len(chain):
            continue
        positions = arm.positions(chain)
        parent = 0
        for node, position in zip(chain, positions):
            edge = float(coster.costs(tree.nodes[parent][None], node, toward=True)[0])
            if not math.isfinite(edge):
                break
            parent = tree.append(node, position, parent, edge, tree.costs[parent] + edge)
            added += 1
    return added


class ProbeRRT(ProbRRT):
    """ProbRRT whose start tree begins with probes around the start (ideas d, f, g, i, j)."""

    def __init__(self, arm: Arm, settings=None, objective=None,
                 probes: ProbeSettings | None = None, straight: bool = True,
                 turning: bool = False, untried: float = 0.0, rolling: bool = False,
                 held_after_turn: float = 0.0, **kwargs) -> None:
        if not (straight or turning):
            raise ValueError('ProbeRRT needs straight or turning probes')
        if rolling and not turning:
            raise ValueError('rolling probes are turning probes: turning must be True')
        if held_after_turn > 0 and not (straight and turning):
            raise ValueError('held_after_turn chooses between straight and turning probes: '
                             'both must be on')
        self.probes = probes or ProbeSettings()
        self.straight, self.turning, self.untried = straight, turning, float(untried)
        self.rolling = rolling
        self.held_after_turn = float(held_after_turn)
        super().__init__(arm, settings, objective, **kwargs)

    def _roots(self, start: np.ndarray, goal: np.ndarray, capacity: int,
               coster: EdgeCoster | None = None, rng: np.random.Generator | None = None
               ) -> tuple[Tree, Tree]:
        """Root both trees; while growing, hang the probes (turned by a draw) from the start."""
        if coster is None or rng is None:          # warming up
            return super()._roots(start, goal, capacity)
        dim = self.arm.task_space.dim
        directions = even_directions(self.probes.directions, dim) @ random_turn(rng, dim).T
        keep = self._untried(directions, self.arm.positions(start)[0], coster.fmap)
        chains = []
        turning = self.turning and self.arm.task_space.has_orientation
        straight = self.straight
        if straight and turning and self.held_after_turn > 0:
            straight = self.turned_block_near(start, coster.fmap)
        if straight or not turning:        # without orientation a turn is no turn
            chains += probe_chains(self.arm, start, directions[keep], self.probes, self.low,
                                   self.high)
        if turning:
            axes = rng.normal(size=(len(directions), 3))   # drawn alike with i: same streams
            axes /= np.linalg.norm(axes, axis=1, keepdims=True)
            if self.rolling:
                signs = np.where(np.arange(len(directions)) % 2 == 0, 1.0, -1.0)
                axes = signs[:, None] * last_joint_axis(self.arm, start)
            chains += probe_chains(self.arm, start, directions[keep], self.probes, self.low,
                                   self.high, axes[keep])
        trees = super()._roots(start, goal, capacity + sum(len(chain) for chain in chains))
        add_chains(trees[0], chains, self.arm, coster)
        return trees

    def turned_block_near(self, start: np.ndarray, fmap) -> bool:
        """
        Tell whether a failure within the probes' reach of start was met turned (idea j).

        Turned: its orientation differs from the object's at start by more than
        ``held_after_turn`` [rad], the angle of the rotation between the two.
        """
        points, _, orientations = fmap.arrays()
        if not len(points):
            return False
        pose = self.arm.fk(start[None])
        _, distance = self._offsets(pose.positions[0], points)
        near = distance <= self.probes.length
        if not near.any():
            return False
        angles = turn_angles(pose.orientations[0], orientations[near])
        return bool((angles > self.held_after_turn).any())

    @staticmethod
    def _offsets(x0: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return each failure point's offset from x0 and its length (the probes' reach)."""
        ahead = points - x0
        return ahead, np.linalg.norm(ahead, axis=1)

    def _untried(self, directions: np.ndarray, x0: np.ndarray, fmap) -> np.ndarray:
        """
        Tell which directions keep a probe (all unless ``untried`` > 0).

        With ``untried`` > 0, those farther than that angle [rad] from the direction of
        every failure within the probes' reach.
        """
        keep = np.ones(len(directions), dtype=bool)
        points = fmap.arrays()[0]
        if self.untried <= 0 or not len(points):
            return keep
        ahead, distance = self._offsets(x0, points)
        # (a failure at x0 itself has no direction)
        near = (distance > 1e-9) & (distance <= self.probes.length)
        if near.any():
            seen = ahead[near] / distance[near, None]
            keep = np.max(directions @ seen.T, axis=1) < math.cos(self.untried)
        return keep
