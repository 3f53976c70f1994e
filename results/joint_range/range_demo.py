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
The demo scene offline with and without a joint range: how far the flange travels.

python results/joint_range/range_demo.py 0      # no range (the default)
python results/joint_range/range_demo.py 0.8    # A1 within [-0.8, 0.8]
One JSON line per planner seed 0-9: success, paths, flange travel [m], largest |A1|,
simulated time [s].
"""

import json
import sys

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.physics.episode import run_physics_episode
from probdis_ros.planning import RRTSettings
from probdis_ros.planning.prob_rrt import ROBOT_JOINT_MARGIN

arm = iiwa_arm()
a1 = float(sys.argv[1])
for seed in range(10):
    ranges = {}
    if a1 > 0:
        lower, upper = arm.lower.copy(), arm.upper.copy()
        lower[0], upper[0] = -a1, a1
        ranges = {'joint_lower': tuple(lower), 'joint_upper': tuple(upper)}
    episode = run_physics_episode('demo_hook', 'informed', seed=seed,
                                  rrt=RRTSettings(joint_margin=ROBOT_JOINT_MARGIN, **ranges))
    flange = arm.fk(episode.configs[::5]).positions
    travel = float(np.linalg.norm(np.diff(flange, axis=0), axis=1).sum())
    print(json.dumps({'a1': a1, 'seed': seed, 'success': episode.success,
                      'paths': episode.paths, 'flange_m': round(travel, 2),
                      'a1_max': round(float(np.abs(episode.configs[:, 0]).max()), 2),
                      'sim_s': round(episode.sim_time_s, 1)}), flush=True)
