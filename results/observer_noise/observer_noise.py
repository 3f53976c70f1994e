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
The external-torque observer on an idle arm whose velocities are differenced positions.

The lbr stack's velocity state is the difference of two measured positions over their FRI
time stamps, so the joint states' position noise reaches the observer's momentum divided
by the period (the mock's driver differences them too, since the sixth session of
2026-12-05).  Idle arm at the demo's start, exact efforts (its gravity), Gaussian noise on
the positions, 100 Hz, 10 s per level: the spread and the largest magnitude of the estimate per joint, and of
effort - g(q) (``static``, what the held test reads) for comparison.
Usage: python results/observer_noise/observer_noise.py
"""

import numpy as np
from probdis_ros.motion.detector import DetectorSettings, ExternalTorqueObserver, gravity_model

START = np.array([0.0, 0.4536, 0.0, -1.5328, 0.0, 1.1551, 0.0])   # demo_hook's start
RATE = 100.0
LEVELS = (1e-5, 3e-5, 1e-4, 3e-4, 1e-3)     # position noise, std. dev. [rad]


def idle(sigma: float, seconds: float = 10.0, seed: int = 1
         ) -> tuple[np.ndarray, np.ndarray]:
    """Return (estimates, statics) (N, 7) of an idle arm after the first second."""
    rng = np.random.default_rng(seed)
    settings = DetectorSettings()
    effort = gravity_model(0.0, (0.0, 0.0, 0.0))(START)
    observer = ExternalTorqueObserver(settings)
    last, estimates, statics = None, [], []
    for k in range(int(seconds * RATE)):
        q = START + rng.normal(0.0, sigma, 7)
        velocity = np.zeros(7) if last is None else (q - last) * RATE
        last = q
        estimate = observer.update(k / RATE, q, velocity, effort)
        if k >= RATE:
            estimates.append(estimate.copy())
            statics.append(observer.static.copy())
    return np.array(estimates), np.array(statics)


def main() -> None:
    print('position noise [rad] | estimate: std. dev. per joint A1..A7 [Nm] | largest |estimate| '
          '[Nm] | largest |effort - g(q)| [Nm]')
    for sigma in LEVELS:
        estimates, statics = idle(sigma)
        spread = ' '.join(f'{value:.2f}' for value in estimates.std(axis=0))
        print(f'{sigma:g} | {spread} | {np.abs(estimates).max():.2f} | '
              f'{np.abs(statics).max():.3f}')


if __name__ == '__main__':
    main()
