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
How close the iiwa's flange and its links come to the arm's own links (the planner does not check).

The URDF's collision shapes as capsules (a cylinder's capsule holds it: a clearance here is
never larger than the real one), the base's cylinder included; pairs of links at least three
joints apart.  Over random configurations within the joint limits and above the table
(the planner's samples), and along the paths the default method drove in the kinematic
simulator on family worlds.  Usage: python results/self_collision/own_links.py [N] [WORLDS]
"""

import sys

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.model.table import ROBOT_TABLE
from probdis_ros.sim.episode import run_episode
from probdis_ros.sim.families import FAMILIES, random_family_world

ARM = iiwa_arm()
#: lbr_link_0's collision cylinder (fixed to the base, so not among the kernels' shapes)
BASE = np.array([[0, 0, 0, 0.07875, 0, 0, 1, 0.07875, 0.11]])


def capsules(configs: np.ndarray):
    """Return segment ends (N, S, 2, 3), radii (S,) and joints (S,) of every shape, base too."""
    pos, rot = ARM.joint_frames(configs)
    ends, radii, joints = [], [], []
    for row in np.vstack([BASE, ARM.shapes]):
        j = int(row[0])
        if j == 0:
            c, a = np.broadcast_to(row[1:4], (len(configs), 3)), np.broadcast_to(row[4:7], (len(configs), 3))
        else:
            c = pos[:, j - 1] + np.einsum('nij,j->ni', rot[:, j - 1], row[1:4])
            a = np.einsum('nij,j->ni', rot[:, j - 1], row[4:7])
        ends.append(np.stack([c - row[7] * a, c + row[7] * a], axis=1))
        radii.append(row[8])
        joints.append(j)
    return np.stack(ends, axis=1), np.array(radii), np.array(joints)


def segment_distance(p, q, samples: int = 41) -> np.ndarray:
    """Return the distance between segments p (N, 2, 3) and q (N, 2, 3), sampled finely."""
    t = np.linspace(0.0, 1.0, samples)[None, :, None]
    a = p[:, :1] + t * (p[:, 1:] - p[:, :1])
    b = q[:, :1] + t * (q[:, 1:] - q[:, :1])
    return np.linalg.norm(a[:, :, None] - b[:, None, :], axis=-1).min(axis=(1, 2))


def clearances(configs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return per configuration the flange's clearance to links 0-3 and the least link-link one."""
    ends, radii, joints = capsules(configs)
    flange = ARM.tip_frames(configs)[0]
    flange_clear = np.full(len(configs), np.inf)
    link_clear = np.full(len(configs), np.inf)
    for i in range(len(radii)):
        if joints[i] <= 3:
            point = np.stack([flange, flange], axis=1)
            flange_clear = np.minimum(flange_clear,
                                      segment_distance(point, ends[:, i]) - radii[i])
        for k in range(i + 1, len(radii)):
            if joints[k] - joints[i] >= 3:
                link_clear = np.minimum(link_clear, segment_distance(ends[:, i], ends[:, k]) -
                                        radii[i] - radii[k])
    return flange_clear, link_clear


def report(name: str, configs: np.ndarray) -> None:
    flange, links = clearances(configs)
    print(f'{name}: {len(configs)} configurations')
    print(f'  flange to links 0-3 [m]: least {flange.min():.3f}, 0.1 % {np.percentile(flange, 0.1):.3f}, '
          f'1 % {np.percentile(flange, 1):.3f}')
    for reach in (0.15, 0.2, 0.25, 0.3):
        print(f'  an object reaching {reach} m from the flange could touch them at '
              f'{np.mean(flange < reach):.2%} of the configurations')
    print(f'  links three or more joints apart [m]: least clearance {links.min():.3f}, '
          f'in contact at {np.mean(links < 0):.2%}')


if __name__ == '__main__':
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    worlds = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    rng = np.random.default_rng(0)
    samples = ARM.random_configurations(rng, n)
    report('random, above the table', samples[ARM.on_table(ROBOT_TABLE).above_table(samples)])
    traces = []
    for family in FAMILIES:
        for seed in range(5000, 5000 + worlds):
            episode = run_episode(random_family_world(family, seed), 'informed', seed=0)
            traces += episode.traces
    report(f'paths driven by the default method (5 families x {worlds} worlds, seeds 5000-)',
           np.vstack(traces))
