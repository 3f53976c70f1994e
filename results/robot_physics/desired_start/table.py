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

import json, sys
import numpy as np
rows = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
scenes = ['demo_hook', 'robot_waste', 'robot_maze', 'robot_bunny']
print('scene | start | n | success | paths (mean, succ only) | failures | retreat blocked | peak force max/median N | extra press after block max N | JTC cmd peak xlim (max) | periods >lim | filtered peak xlim | periods >lim | driver stopped')
for scene in scenes + ['all']:
    for start in ['measured', 'desired']:
        r = [x for x in rows if x['jtc_start'] == start and (scene == 'all' or x['scene'] == scene)]
        if not r: continue
        s = [x for x in r if x['success']]
        print(f"{scene} | {start} | {len(r)} | {len(s)} | {np.mean([x['paths'] for x in s]) if s else float('nan'):.1f} | "
              f"{sum(x['failures'] for x in r)} | {sum(x['retreat_blocked'] for x in r)} | "
              f"{max(x['peak_force'] for x in r):.0f}/{np.median([x['peak_force'] for x in r]):.0f} | "
              f"{max(x['extra_press_force'] for x in r):.0f} (median {np.median([x['extra_press_force'] for x in r if x['failures']] or [0]):.0f}) | "
              f"{max(x['cmd_peak'] for x in r):.2f} | {sum(x['cmd_periods_over'] for x in r)} | "
              f"{max(x['sent_peak'] for x in r):.2f} | {sum(x['sent_periods_over'] for x in r)} | "
              f"{sum('driver stopped' in x['message'] for x in r)}")
