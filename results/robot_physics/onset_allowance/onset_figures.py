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
Where the detector locates a block: each physics scene's straight path into its obstacle.

Per scene, velocity scaling and command latency (JTC takes the command that late): when the
arm first touched and when the block was detected (seconds after the command), how far the
flange at the detector's onset lies from the flange at the first contact, and how far the
flange moved on from contact to detection (``probdis bench physics`` prints the same for
one scene at 0.2 and 0.7).  A few seconds of CPU per line.
Usage: python results/robot_physics/onset_allowance/onset_figures.py SCENE[,SCENE...]
"""

import sys

from probdis_ros.physics import measure
from probdis_ros.physics.simulated_robot import RobotSettings

for scene in sys.argv[1].split(','):
    for scaling in (0.2, 0.4, 0.7):
        for latency in (0.0, 0.03):
            block = measure.straight_block(scene, scaling, RobotSettings(command_latency=latency))
            error = block.onset_error_m
            onset = 'none' if error is None else f'{100 * error:.2f} cm'
            print(f'{scene} scaling {scaling} latency {latency}: {block.verdict}, contact '
                  f'{block.contact_s:.2f} s, detected {block.detected_s:.2f} s, onset {onset} '
                  f'from the contact, flange moved {100 * block.flange_moved_m:.1f} cm',
                  flush=True)
