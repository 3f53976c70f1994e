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
An estimate (RESULTS.md "Planner speed"): how many failures a chunk's bound lets through.

For 300 chunks of 16 points (0.04 rad steps along random joint-space lines of the iiwa),
counts the failures whose bound exceeds the chunk's final least maximum (the fewest any
order of evaluation could reach) under the kernels' bounding sphere and under a capsule
(the chord of the chunk's tip points widened by their largest distance to it; alpha's
maximum along the chord sampled at 400 points, so an estimate, not a bound), and the
distinct failures that give some point its maximum.  Usage: python capsule_bound.py 19|400
"""

import sys, numpy as np
from probdis_ros.bench import nineteen_failure_map, learned_failure_map
from probdis_ros.model import arm_for_setting
arm = arm_for_setting('3d-orient')
n = int(sys.argv[1])
start, goal, fmap = nineteen_failure_map() if n == 19 else learned_failure_map(n, across_episodes=True)
C = fmap.c_fail
F, U, Q = fmap.points, fmap.directions, fmap.orientations
rng = np.random.default_rng(1)
def per_failure(x, q):
    d = F[None] - x[:, None]
    d2 = (d * d).sum(-1); dist = np.sqrt(d2)
    c = np.einsum('nfd,fd->nf', d, U) / dist
    a = np.arccos(np.clip(c, -1, 1))
    p = (a / np.pi) ** 3 / (1 + C * d2)
    dots = np.abs(q @ Q.T)
    return p * (1 - 0.5 * (2 / np.pi) * np.arccos(np.clip(dots, 0, 1))), a
def orient_bound(q):
    # the kernel's: angle to the middle pose minus the chunk's spread
    mid = q[len(q) // 2]
    half = lambda a, b: 2 * np.arccos(np.clip(np.abs(a @ b.T), 0, 1))
    spread = half(q, mid[None]).max()
    ang = half(mid[None], Q)[0]
    return 1 - 0.5 * np.maximum(0, ang - spread) / np.pi
tot = {'sphere': 0, 'capsule': 0, 'winners': 0}
chunks = 300
lo, hi = arm.lower, arm.upper
for k in range(chunks):
    a = rng.uniform(lo, hi); b = rng.uniform(lo, hi)
    step = (b - a) / np.linalg.norm(b - a) * 0.04
    qs = a + step * np.arange(1, 17)[:, None]
    poses = arm.fk(qs)
    x, q = poses.positions, poses.orientations
    p, _ = per_failure(x, q)
    pmax = p.max(1); least = pmax.min()
    ob = orient_bound(q)
    # sphere about the mean
    c0 = x.mean(0); r = np.sqrt(((x - c0) ** 2).sum(1)).max()
    D = np.linalg.norm(F - c0, axis=1)
    cc = np.einsum('fd,fd->f', F - c0, U) / D
    al = np.minimum(np.pi, np.arccos(np.clip(cc, -1, 1)) + np.arcsin(np.minimum(1, r / D)))
    gap = np.maximum(0, D - r)
    sb = np.where(D <= r, 1.0, (al / np.pi) ** 3) / (1 + C * gap ** 2) * ob
    # capsule: chord A-B and the largest distance of the points to it
    A, B = x[0], x[-1]
    ts = np.linspace(0, 1, 400)[:, None]
    seg = A + ts * (B - A)
    t = np.clip(((x - A) @ (B - A)) / max((B - A) @ (B - A), 1e-30), 0, 1)
    rc = np.linalg.norm(x - (A + t[:, None] * (B - A)), axis=1).max()
    dseg = np.linalg.norm(F[:, None] - seg[None], axis=2)           # (F, 400)
    Ds = dseg.min(1)
    cseg = np.einsum('fsd,fd->fs', F[:, None] - seg[None], U) / dseg
    alseg = np.arccos(np.clip(cseg, -1, 1)).max(1)
    alc = np.minimum(np.pi, alseg + np.arcsin(np.minimum(1, rc / Ds)))
    gapc = np.maximum(0, Ds - rc)
    cb = np.where(Ds <= rc, 1.0, (alc / np.pi) ** 3) / (1 + C * gapc ** 2) * ob
    tot['sphere'] += (sb > least).sum(); tot['capsule'] += (cb > least).sum()
    tot['winners'] += len(set(p.argmax(1).tolist()))
print(n, 'failures; per chunk, passing the bound against the final least maximum:',
      {k: round(float(v) / chunks, 2) for k, v in tot.items()})
