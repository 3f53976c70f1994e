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
The compiled (numba) kernels of the ROS-free core, by job; this module only re-exports.

* :mod:`probdis_ros.model.kinematics`: forward kinematics of chains, quaternions.
* :mod:`probdis_ros.model.edge_kernels`: edge costs along straight joint-space edges.
* :mod:`probdis_ros.model.fast_math`: inlined, vectorisable arccos and rotation angle.
* :mod:`probdis_ros.model.tree_kernels`: the ProbRRT tree loop (and its sampling).

Import from those modules; the names here stay for code written before the split.
"""

from probdis_ros.model.edge_kernels import (
    AT_FAILURE,
    cheapest_edge_kernel,
    CHUNK,
    edge_cost_kernel,
    edge_costs_kernel,
)
from probdis_ros.model.kinematics import AXIS_CHAIN, CHAIN, chain_kernel, PLANAR, quaternion_kernel
from probdis_ros.model.tree_kernels import farthest_kernel

__all__ = [
    'AT_FAILURE',
    'AXIS_CHAIN',
    'CHAIN',
    'CHUNK',
    'PLANAR',
    'chain_kernel',
    'cheapest_edge_kernel',
    'edge_cost_kernel',
    'edge_costs_kernel',
    'farthest_kernel',
    'quaternion_kernel',
]
