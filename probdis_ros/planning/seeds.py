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
Independent random streams from one seed: the world's and the planner's.

A user (or the sweep) gives one integer seed to an episode.  Drawn from one generator, the
world and the planner would share a stream: Epsilon's first coin flip would be decided by
the world's first draw, and a world could not change without changing every plan after it.
``SeedSequence(seed).spawn`` gives statistically independent children instead; the world
generator draws from the first, the loop's planner from the second.  (The loop itself and
the compliant arm draw nothing.)
"""

from __future__ import annotations

import numpy as np

WORLD = 0
PLANNER = 1
_STREAMS = 2


def stream(seed: int, which: int) -> np.random.Generator:
    """Return the generator of stream ``which`` (WORLD or PLANNER) of an integer seed."""
    return np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(_STREAMS)[which])
