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
The torque ceiling on the physics demo, with and without the driver's torque filter.

The lbr stack filters the measured joint torques before they reach the efforts
(``measured_torque_tau``, 0.1 s as it ships); the mock does so too (``RobotSettings.
torque_tau``).  Each line: the demo scene (``demo_hook``), the default method, planner seed
S, at most 6 paths, a torque ceiling of CEILING Nm with the hook's load data (0.4 kg at
0.12 m), the filter's time constant TAU; the outcome, the failures' reasons (a retreat
called blocked says ``retreat:``), the run's largest estimate and the contacts' largest
true torque.  About 10 s of CPU per episode.
Usage: python results/torque_filter/torque_ceiling_demo.py CEILING TAU[,TAU...] SEEDS
"""

from dataclasses import replace
import json
import sys

from probdis_ros.physics.episode import run_physics_episode
from probdis_ros.physics.simulated_robot import RobotSettings
from probdis_ros.run import RunSettings


def main(ceiling: float, taus: list[float], seeds: int) -> None:
    """Print one JSON line per episode."""
    defaults = RunSettings()
    detection = replace(defaults.detection, torque_ceiling=ceiling, load_mass=0.4,
                        load_com=(0.0, 0.0, 0.12))
    for seed in range(seeds):
        for tau in taus:
            episode = run_physics_episode(
                'demo_hook', 'informed', seed=seed, max_paths=6,
                run_settings=replace(defaults, detection=detection),
                robot_settings=RobotSettings(torque_tau=tau))
            print(json.dumps(dict(
                seed=seed, tau=tau, success=episode.success, paths=episode.paths,
                failures=len(episode.failures),
                why=[failure.get('why', '') for failure in episode.failures],
                estimated_peak_nm=round(float(episode.estimated_torque_peak.max()), 1),
                contact_peak_nm=round(float(episode.external_torque_peak.max()), 1),
                message=episode.message)), flush=True)


if __name__ == '__main__':
    main(float(sys.argv[1]), [float(t) for t in sys.argv[2].split(',')], int(sys.argv[3]))
