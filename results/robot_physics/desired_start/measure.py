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

"""Measure jtc_start measured vs desired on the physics mock (one JSON line per run)."""
import json
import sys
import time

import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.physics import simulated_robot
from probdis_ros.physics.episode import run_physics_episode
from probdis_ros.run import RunSettings

LIMITS = iiwa_arm().velocity_limits
LOG = {}


def wrapped(step):
    def run(self):
        step(self)
        LOG.setdefault('cmd', []).append(self.commanded.copy())
        LOG.setdefault('sent', []).append(self.filter.value.copy())
    return run


simulated_robot.SimulatedRobot.step = wrapped(simulated_robot.SimulatedRobot.step)


def peak_speed(values, period=0.01):
    values = np.array(values)
    if len(values) < 2:
        return 0.0, 0
    over = np.abs(np.diff(values, axis=0)) / period / LIMITS
    per = over.max(axis=1)
    return float(per.max()), int((per > 1.0).sum())


def main(out, scenes, seeds, starts, max_paths=20):
    for seed in seeds:
        for scene in scenes:
            for start in starts:
                LOG.clear()
                wall = time.perf_counter()
                ep = run_physics_episode(scene, 'informed', seed=seed, max_paths=max_paths,
                                         run_settings=RunSettings(jtc_start=start))
                cmd, ncmd = peak_speed(LOG['cmd'])
                sent, nsent = peak_speed(LOG['sent'])
                # extra press after a block: force peak in the 0.5 s after each learned
                # block minus the force when it was declared
                extra = 0.0
                for f in ep.failures:
                    k = int(np.searchsorted(ep.times, f['t']))
                    window = ep.contact_force[k:k + 50]
                    if len(window):
                        extra = max(extra, float(window.max() - ep.contact_force[min(
                            k, len(ep.contact_force) - 1)]))
                record = {
                    'scene': scene, 'seed': seed, 'jtc_start': start,
                    'success': ep.success, 'outcome': ep.outcome, 'paths': ep.paths,
                    'failures': len(ep.failures),
                    'retreat_blocked': sum(f['why'].startswith('retreat')
                                           for f in ep.failures),
                    'peak_force': round(float(ep.contact_force.max(initial=0.0)), 1),
                    'extra_press_force': round(extra, 1),
                    'cmd_peak': round(cmd, 3), 'cmd_periods_over': ncmd,
                    'sent_peak': round(sent, 3), 'sent_periods_over': nsent,
                    'sim_time_s': round(ep.sim_time_s, 2),
                    'wall_s': round(time.perf_counter() - wall, 1), 'message': ep.message}
                with open(out, 'a') as fh:
                    fh.write(json.dumps(record) + '\n')
                print(json.dumps(record), flush=True)


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2].split(','), [int(s) for s in sys.argv[3].split(',')],
         sys.argv[4].split(','))
