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
The table the arm stands on: no part of the arm, nor its tip, goes below it.

The planner cannot see the clutter, but it knows where the arm is mounted.  Without this
the planner's joint-space RRT sends the arm through the table top: in the kinematic
simulator 20 of 80 episodes of the shipped robot scenarios and the entanglement families
(seeds 0-9 and 1000-1009) took links or the flange down to 28 cm below the base's plane, in
19 of them on the path that reached the goal; about 12 % of the trees' nodes lay below it.
A real arm would strike the table.

The arm's shape is its URDF's collision geometry (spheres, cylinders, capsules; a box by
its bounding sphere), read with pinocchio, each shape carried by the joint frame its link
follows; the lowest point of each is exact (:func:`probdis_ros.model.kinematics.lowest_height`).
The planner treats a configuration whose lowest point is below the table's ``floor``
(``height + clearance``) like a certain failure: an edge through one costs infinity, so no
tree, Connect, rewiring, probe or refinement keeps it (:mod:`probdis_ros.model.edge_kernels`).
An edge that starts lower (an arm already near the table) may leave upwards, never sink.
Edges are checked at their points, every ``delta`` (0.04 rad): between two points a part of
the iiwa moves at most about 1.3 m/rad x 0.04 rad = 5 cm, which the default clearance covers.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

#: [m] kept between the table top and every collision shape and the tip, by default
DEFAULT_CLEARANCE = 0.05
#: columns of a shape row: joint (1-based), center (3), unit axis (3), half length, radius
SHAPE_COLUMNS = 9


@dataclass(frozen=True)
class Table:
    """A horizontal table top at ``height`` [m] in the base frame, kept ``clearance`` from."""

    height: float = 0.0
    clearance: float = DEFAULT_CLEARANCE

    def __post_init__(self) -> None:
        """Refuse a table the check cannot use."""
        if not math.isfinite(self.height):
            raise ValueError(f'table height must be finite, got {self.height}')
        if not (math.isfinite(self.clearance) and self.clearance >= 0):
            raise ValueError(f'table clearance must be >= 0, got {self.clearance}')

    @property
    def floor(self) -> float:
        """Return the lowest height any part of the arm may reach [m]."""
        return self.height + self.clearance


#: The table of the robot's setup (planner node, robot experiment, physics runs, family
#: worlds, the shipped robot scenarios): the plane the base lbr_link_0 stands on.
ROBOT_TABLE = Table()


def collision_shapes(model, urdf: str) -> np.ndarray:
    """
    Return the URDF's collision shapes of the moving links as rows (S, SHAPE_COLUMNS).

    ``model`` is the pinocchio model built from ``urdf``.  Rows are in chain order (the
    kernels walk them joint by joint); shapes fixed to the base are left out (they never
    move).  A mesh is refused: its lowest point needs its vertices.
    """
    import pinocchio as pin

    geometry = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION)
    rows = []
    for item in geometry.geometryObjects:
        if item.parentJoint < 1:
            continue
        shape = item.geometry
        kind = type(shape).__name__
        center = np.asarray(item.placement.translation, dtype=float)
        axis = np.asarray(item.placement.rotation, dtype=float)[:, 2]
        ball = np.zeros(3), 0.0        # a sphere's axis and half length
        if kind == 'Sphere':
            rows.append([item.parentJoint, *center, *ball[0], ball[1], shape.radius])
        elif kind == 'Cylinder':
            rows.append([item.parentJoint, *center, *axis, shape.halfLength, shape.radius])
        elif kind == 'Capsule':         # its lowest point is one of its end balls'
            for end in (center + shape.halfLength * axis, center - shape.halfLength * axis):
                rows.append([item.parentJoint, *end, *ball[0], ball[1], shape.radius])
        elif kind == 'Box':             # its bounding sphere: lower than the box, never higher
            rows.append([item.parentJoint, *center, *ball[0], ball[1],
                         float(np.linalg.norm(shape.halfSide))])
        else:
            raise ValueError(f'{urdf}: collision geometry {item.name} is a {kind}; the table '
                             'check takes spheres, cylinders, capsules and boxes')
    rows.sort(key=lambda row: row[0])
    return np.ascontiguousarray(np.array(rows, dtype=float).reshape(-1, SHAPE_COLUMNS))


def lowest_heights_reference(frames: tuple[np.ndarray, np.ndarray], tips: np.ndarray,
                             shapes: np.ndarray) -> np.ndarray:
    """
    Return the lowest height of the shapes and the tips, from joint frames, with numpy.

    ``frames``: positions (N, J, 3) and rotations (N, J, 3, 3) of the joint frames (joint j
    at index j - 1); ``tips`` (N, 3).  The straightforward evaluation the kernel is tested
    against.
    """
    positions, rotations = frames
    low = tips[:, 2].copy()
    for joint, cx, cy, cz, ax, ay, az, half, radius in shapes:
        j = int(joint) - 1
        z = positions[:, j, 2] + rotations[:, j, 2, :] @ np.array([cx, cy, cz])
        uz = rotations[:, j, 2, :] @ np.array([ax, ay, az])
        bottom = z - half * np.abs(uz) - radius * np.sqrt(np.maximum(0.0, 1.0 - uz * uz))
        low = np.minimum(low, bottom)
    return low
