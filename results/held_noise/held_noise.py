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
The held test against torque noise: idle arms called held, held arms found (detector alone).

An arm that never moves while a path pulls it: held by something (the impedance's spring,
200 Nm/rad x the pull, on the efforts) or idle (no controller runs the command: the
efforts stay as they were), with Gaussian noise per sample and joint; 100 Hz states.
Usage: python results/held_noise/held_noise.py [TRIALS]
"""

import sys

import numpy as np
from probdis_ros.motion.detector import BlockDetector, DetectorSettings, Verdict
from probdis_ros.motion.jtc import JtcTrajectory, TrajectoryCommand

HELD = np.array([0.0, 0.7, 0.0, -1.3, 0.0, 0.9, 0.0])
TIMES = np.linspace(0.0, 1.0, 11)


def verdicts(direction: np.ndarray, spring: float, noise: float, trials: int) -> dict:
    """Return how often each verdict ended the command."""
    command = JtcTrajectory(TrajectoryCommand(TIMES, HELD + np.outer(TIMES, direction)),
                            HELD, np.zeros(7))
    rng = np.random.default_rng(1)
    counts: dict = {}
    for _ in range(trials):
        detector = BlockDetector(command, 0.0, DetectorSettings(), expect_motion=True)
        found = Verdict.MOVING
        for t in np.arange(0.01, 3.0, 0.01):
            pull = command.sample(t - detector.settings.motion_delay)[0] - HELD
            found = detector.update(t, HELD, spring * pull + rng.normal(0.0, noise, 7))
            if found is not Verdict.MOVING:
                break
        counts[found.value] = counts.get(found.value, 0) + 1
    return counts


if __name__ == '__main__':
    trials = int(sys.argv[1]) if len(sys.argv) > 1 else 300
    every, a2 = np.full(7, 0.3), np.array([0, 0.4, 0, 0, 0, 0, 0.0])
    for name, direction, spring, noises in (
            ('idle, every joint pulled', every, 0.0, (0.5, 1.0, 1.5, 2.0, 3.0)),
            ('held, every joint pulled', every, 200.0, (1.0, 3.0, 5.0)),
            ('held, A2 pulled', a2, 200.0, (1.0, 3.0, 5.0))):
        for noise in noises:
            print(f'{name}, noise {noise} Nm: {verdicts(direction, spring, noise, trials)}',
                  flush=True)
