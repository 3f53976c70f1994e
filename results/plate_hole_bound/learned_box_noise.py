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
The learned-box search of `probdis experiment bound` with its stops known less exactly.

In the kinematic simulator a block's place is exact; a real arm in joint impedance knows
where it was blocked to a centimetre or so (it swings 1.5-6.7 cm about a contact before a
block is detected: DESIGN.md).  Each stop the search sees is moved by a normal error of
SIGMA per axis (drawn per world from the seed's own stream), its face tolerance widened
to 2 SIGMA; whether a line gets out is still decided by the exact simulator.  From the
repository's root (about 6 min):

    python results/plate_hole_bound/learned_box_noise.py 5000 100 > learned_box_noise.txt
"""

import sys

import numpy as np
import probdis_ros.experiments.hole_search as hole_search
from probdis_ros.sim.families import random_family_world

SIGMAS = (0.0, 0.005, 0.01, 0.02)


def box_is_right(box, params: dict, place: float = 0.005, turn: float = 2.0) -> bool:
    """Tell whether a learnt box is the world's within place [m] and turn [degrees]."""
    match = np.abs(box.axes @ np.array(params['axes']).T)
    order = match.argmax(axis=1)
    if sorted(order) != [0, 1, 2] or match.max(axis=1).min() < np.cos(np.radians(turn)):
        return False
    return bool(np.linalg.norm(box.center - np.array(params['center'])) < place and
                np.abs(box.half - np.array(params['half_size'])[order]).max() < place)


def main(first: int, count: int) -> None:
    """Print success within 5, 10, 20 paths and mean paths per stop error."""
    exact = hole_search.first_stop
    worlds = [(seed, random_family_world('plate_hole', seed))
              for seed in range(first, first + count)]
    print(f'plate_hole seeds {first}-{first + count - 1}, the learned-box search')
    print('| stop error per axis [m] | within 5 | within 10 | within 20 | mean paths (when out '
          'within 20) | box learnt | right (5 mm, 2 deg) | lines to learn it |')
    print('| --- | --- | --- | --- | --- | --- | --- | --- |')
    for sigma in SIGMAS:
        taken, learnt, right, spent = [], 0, 0, []
        for seed, world in worlds:
            rng = np.random.default_rng([seed, 7])

            def seen(world, start, direction, length=1.0, rng=rng, sigma=sigma):
                stop = exact(world, start, direction, length)
                return None if stop is None else stop + rng.normal(scale=sigma, size=3)

            hole_search.first_stop = seen
            hole_search.ON_FACE = max(0.002, 2 * sigma)
            lines, box = hole_search.learned_box_lines(world, world.params['hole_radius'], seed)
            start = world.arm.fk(world.start).positions[0]
            out = exact(world, start, lines[-1]) is None
            taken.append(len(lines) if out else 10**6)
            if box is not None:
                learnt += 1
                spent.append(box.lines)
                right += box_is_right(box, world.params)
        taken = np.array(taken)
        within = [np.mean(taken <= n) for n in (5, 10, 20)]
        mean = taken[taken <= 20].mean() if (taken <= 20).any() else float('nan')
        print(f'| {sigma} | {within[0]:.2f} | {within[1]:.2f} | {within[2]:.2f} | {mean:.1f} | '
              f'{learnt} | {right} | {min(spent)}-{max(spent)} |', flush=True)
    hole_search.first_stop = exact


if __name__ == '__main__':
    main(int(sys.argv[1]), int(sys.argv[2]))
