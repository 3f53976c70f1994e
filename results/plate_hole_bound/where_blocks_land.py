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
Where the default's blocks land on the plate_hole worlds of seeds 5000-5099 (a diagnosis).

Reruns each recorded `informed` episode of results/families_fresh (checking it ends as
recorded) and prints, per episode, each block's side of the box and its place on it;
`--summary FILE` sums such a file up.  From the repository's root:

    python results/plate_hole_bound/where_blocks_land.py > blocks.jsonl
    python results/plate_hole_bound/where_blocks_land.py --summary blocks.jsonl
"""

import json
import sys

import numpy as np
from probdis_ros.sim.families import HOLE_MARGIN


def rerun() -> None:
    from probdis_ros.planning.methods import Method
    from probdis_ros.sim.episode import run_episode
    from probdis_ros.sim.families import random_family_world

    episodes = [json.loads(line) for line in open('results/families_fresh/episodes.jsonl')]
    for e in episodes:
        if e['family'] != 'plate_hole' or not e['method'].startswith('informed'):
            continue
        seed = e['world_seed']
        world = random_family_world('plate_hole', seed)
        result = run_episode(world, Method.parse(e['method']), seed=seed, max_paths=20)
        p = world.params
        axes, center = np.array(p['axes']), np.array(p['center'])
        half = np.array(p['half_size'])
        points = np.array([x[:3] for x in result.loop.fmap.points]).reshape(-1, 3)
        local = (points - center) @ axes.T
        k = np.argmax(np.abs(local) / half, axis=1)
        print(json.dumps({
            'seed': seed, 'success': result.success, 'paths': result.paths,
            'as_recorded': [result.success, result.paths] == [e['success'], e['paths']],
            'plate': p['plate_side'], 'r': p['hole_radius'], 'half': half.tolist(),
            'sides': [f'{"+-"[int(x[i] < 0)]}{"xyz"[i]}' for x, i in zip(local, k)],
            'local': local.round(4).tolist(),
            'to_hole': np.linalg.norm(points - np.array(p['hole_center']), axis=1)
            .round(4).tolist()}), flush=True)


def summary(path: str) -> None:
    rows = [json.loads(line) for line in open(path)]
    print(f'{sum(r["as_recorded"] for r in rows)} of {len(rows)} episodes ended as recorded')
    fail = [r for r in rows if not r['success']]
    hits = in_room = in_band = 0
    near, uniform_room, uniform_band = [], [], []
    for r in fail:
        half, rr = np.array(r['half']), r['r']
        seen = []
        for side, x in zip(r['sides'], r['local']):
            k = 'xyz'.index(side[1])
            ij = [m for m in range(3) if m != k]
            u = np.abs(np.array(x)[ij])
            hits += 1
            in_room += bool(np.all(u <= np.maximum(half[ij] - rr - HOLE_MARGIN, 0)))
            in_band += bool(np.any(u > half[ij] - 0.03))
            same = [np.linalg.norm(np.array(x) - np.array(y)) for s, y in seen if s == side]
            if same:
                near.append(min(same) / rr)
            seen.append((side, x))
        area = room = band = 0.0
        for k in range(3):
            ij = [m for m in range(3) if m != k]
            side_area = np.prod(2 * half[ij])
            area += side_area
            room += np.prod(2 * np.maximum(half[ij] - rr - HOLE_MARGIN, 0))
            band += side_area - np.prod(np.maximum(2 * half[ij] - 0.06, 0))
        uniform_room.append(room / area)
        uniform_band.append(band / area)
    plate = [sum(s == r['plate'] for s in r['sides']) for r in fail]
    nearest = [min(d for s, d in zip(r['sides'], r['to_hole']) if s == r['plate']) / r['r']
               for r in fail if r['plate'] in r['sides']]
    sides = [len(set(r['sides'])) for r in fail]
    print(f'{len(fail)} episodes not out; blocks on the plate per episode: '
          f'{np.mean(plate):.1f} ({sum(plate) / hits:.0%} of the blocks); '
          f'all six sides blocked in {sum(s == 6 for s in sides)}')
    print('nearest block on the plate, in hole radii from its centre (10/25/50/75 %): '
          + ', '.join(f'{v:.2f}' for v in np.percentile(nearest, [10, 25, 50, 75])))
    print(f'blocks where a hole could be centred: {in_room / hits:.0%} (spread evenly over '
          f'the sides: {np.mean(uniform_room):.0%}); within 3 cm of a side\'s edge: '
          f'{in_band / hits:.0%} (evenly: {np.mean(uniform_band):.0%})')
    near = np.array(near)
    print(f'blocks within 1 hole radius of an earlier one on the same side: '
          f'{np.mean(near < 1):.0%}, within 2: {np.mean(near < 2):.0%}')


if __name__ == '__main__':
    if len(sys.argv) == 3 and sys.argv[1] == '--summary':
        summary(sys.argv[2])
    else:
        rerun()
