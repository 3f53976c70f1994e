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

"""Benchmarks behind ``probdis bench``: measured figures anyone can rerun."""

from __future__ import annotations

import os
import platform
import statistics
import time

import numpy as np
from probdis_ros.model import arm_for_setting


def machine() -> str:
    """Name the CPU, core count and Python in one line, for reports of measured figures."""
    cpu = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as info:
            for line in info:
                if line.startswith('model name'):
                    cpu = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    return f'{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}'


def bench_fk(setting: str = '3d-orient', configs: int = 200_000, repeats: int = 5,
             seed: int = 0) -> dict:
    """
    Measure batched FK: median configurations per second over repeats, one thread.

    The first call (which compiles the kernel) is excluded.
    """
    if configs < 1 or repeats < 1:
        raise ValueError('configs and repeats must be at least 1')
    arm = arm_for_setting(setting)
    batch = arm.random_configurations(np.random.default_rng(seed), configs)
    arm.fk(batch[:8])
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        arm.fk(batch)
        rates.append(configs / (time.perf_counter() - start))
    return {'configs_per_s': statistics.median(rates), 'setting': setting,
            'configs': configs, 'repeats': repeats, 'machine': machine()}
