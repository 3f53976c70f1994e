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
The held test against torque noise: idle arms called held, held arms found.

An arm that never moves while a path pulls it: held by something (the impedance's spring,
200 Nm/rad x the pull, on the efforts) or idle (no controller runs the command: the
efforts stay as they were), with Gaussian noise per sample and joint; 100 Hz states.  The
efforts go through the external-torque observer as in a run; the held test takes
effort - g(q) (``static``, as the run does), or with ``--estimate`` the observer's
low-passed estimate (as the run did before 2026-12-05's fourth session).
Usage: python results/held_noise/held_noise.py [TRIALS] [--estimate]
"""

import sys

import numpy as np
from probdis_ros.motion.detector import (
    BlockDetector,
    DetectorSettings,
    ExternalTorqueObserver,
    Verdict,
)
from probdis_ros.motion.gravity import GravityModel
from probdis_ros.motion.jtc import JtcTrajectory, TrajectoryCommand

HELD = np.array([0.0, 0.7, 0.0, -1.3, 0.0, 0.9, 0.0])
TIMES = np.linspace(0.0, 1.0, 11)


def verdicts(direction: np.ndarray, spring: float, noise: float, trials: int,
             estimate: bool = False) -> dict:
    """Return how often each verdict ended the command."""
    gravity = GravityModel()(HELD)
    command = JtcTrajectory(TrajectoryCommand(TIMES, HELD + np.outer(TIMES, direction)),
                            HELD, np.zeros(7))
    rng = np.random.default_rng(1)
    counts: dict = {}
    for _ in range(trials):
        detector = BlockDetector(command, 0.0, DetectorSettings(), expect_motion=True)
        observer = ExternalTorqueObserver(detector.settings)
        found = Verdict.MOVING
        for t in np.arange(0.01, 3.0, 0.01):
            pull = command.sample(t - detector.settings.motion_delay)[0] - HELD
            effort = gravity + spring * pull + rng.normal(0.0, noise, 7)
            external = observer.update(t, HELD, np.zeros(7), effort)
            found = detector.update(t, HELD, external, external if estimate else observer.static)
            if found is not Verdict.MOVING:
                break
        counts[found.value] = counts.get(found.value, 0) + 1
    return counts


if __name__ == '__main__':
    args = [a for a in sys.argv[1:] if a != '--estimate']
    trials = int(args[0]) if args else 300
    estimate = '--estimate' in sys.argv
    print('held test on', 'the observer\'s estimate' if estimate else 'effort - g(q)')
    every, a2 = np.full(7, 0.3), np.array([0, 0.4, 0, 0, 0, 0, 0.0])
    for name, direction, spring, noises in (
            ('idle, every joint pulled', every, 0.0, (0.5, 1.0, 1.5, 2.0, 3.0)),
            ('held, every joint pulled', every, 200.0, (1.0, 3.0, 5.0)),
            ('held, A2 pulled', a2, 200.0, (1.0, 3.0, 5.0))):
        for noise in noises:
            found = verdicts(direction, spring, noise, trials, estimate)
            print(f'{name}, noise {noise} Nm: {found}', flush=True)
