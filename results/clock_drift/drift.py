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

"""Dating error and first stale refusal beside an arm clock 100 ppm slow, 2 h at 10 Hz."""
import numpy as np
from probdis_ros.model import iiwa_arm
from probdis_ros.motion import state_check
from probdis_ros.motion.state_check import BadJointStateError, StateCheck

ARM = iiwa_arm()
NAMES = [f'lbr_A{i}' for i in range(1, 8)]
Q = np.array([0.3, 0.2, 0.0, -1.1, 0.0, 0.6, 0.0])
for drift in (0.0, state_check.CLOCK_DRIFT):
    state_check.CLOCK_DRIFT = drift
    rng = np.random.default_rng(1)
    check = StateCheck(NAMES, ARM.lower, ARM.upper, ARM.velocity_limits, late=0.5)
    rate, worst, first, at_hour = 1 - 1e-4, 0.0, None, None
    for t in np.arange(0.0, 7200.0, 0.1):
        now, stamp = t + rng.uniform(0.0005, 0.003), 1000.0 + rate * t
        try:
            check.check(now, NAMES, Q, stamp=stamp)
        except BadJointStateError as err:
            first = first or (t, str(err))
            continue
        err = check.measured_at(now, stamp) - t
        worst = max(worst, abs(err))
        if at_hour is None and t >= 3600:
            at_hour = err
    print(f'CLOCK_DRIFT {drift}: dating error at 1 h {at_hour * 1e3:+.2f} ms, '
          f'worst {worst * 1e3:.2f} ms, refused {check.refused}, first refusal {first}')
