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

"""RViz markers: failures as arrows, the planned path, samples of the map, the table."""

from __future__ import annotations

import math

from geometry_msgs.msg import Point
import numpy as np
from probdis_ros.model import Arm, FailureMap, TaskPoints
from probdis_ros.sim.compliant_arm import densify
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

FRAME = 'lbr_link_0'
ARROW_LENGTH = 0.05
MAP_SAMPLES = 400
#: [m] side of the square drawn for the table top about the base (the planner's is endless)
TABLE_SIDE = 2.0


def _point(x: np.ndarray) -> Point:
    return Point(x=float(x[0]), y=float(x[1]), z=float(x[2]) if len(x) > 2 else 0.0)


def markers_msg(arm: Arm, fmap: FailureMap, path: np.ndarray | None, clock,
                seed: int = 0, reach: float = math.inf) -> MarkerArray:
    """
    Build the marker array: failures, the planned path (if any), map samples and the table.

    The samples are coloured by the probability the planner prices (``reach``: its
    objective's, infinite for the paper's kernel).
    """
    stamp = clock.now().to_msg()
    out = MarkerArray()
    clear = Marker(action=Marker.DELETEALL)
    out.markers.append(clear)
    for i, (x, v) in enumerate(zip(fmap.points, fmap.directions)):
        arrow = Marker(type=Marker.ARROW, action=Marker.ADD, ns='failures', id=i)
        arrow.header.frame_id, arrow.header.stamp = FRAME, stamp
        arrow.points = [_point(x), _point(x + ARROW_LENGTH * v)]
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.008, 0.016, 0.02
        arrow.color = ColorRGBA(r=0.9, g=0.1, b=0.1, a=1.0)
        out.markers.append(arrow)
    if path is not None and len(path) > 1:
        line = Marker(type=Marker.LINE_STRIP, action=Marker.ADD, ns='planned_path', id=0)
        line.header.frame_id, line.header.stamp = FRAME, stamp
        line.points = [_point(x) for x in arm.fk(densify(np.asarray(path), 0.05)[0]).positions]
        line.scale.x = 0.006
        line.color = ColorRGBA(r=0.1, g=0.3, b=0.9, a=1.0)
        out.markers.append(line)
    if len(fmap):
        rng = np.random.default_rng(seed)
        centre = fmap.points[rng.integers(len(fmap), size=MAP_SAMPLES)]
        samples = centre + rng.normal(scale=0.08, size=centre.shape)
        quats = None
        if fmap.task_space.has_orientation:
            quats = fmap.orientations[rng.integers(len(fmap), size=MAP_SAMPLES)]
        prob = fmap.probability(TaskPoints(samples, quats), reach=reach)
        cloud = Marker(type=Marker.POINTS, action=Marker.ADD, ns='failure_map', id=0)
        cloud.header.frame_id, cloud.header.stamp = FRAME, stamp
        cloud.scale.x = cloud.scale.y = 0.01
        cloud.points = [_point(x) for x in samples]
        cloud.colors = [ColorRGBA(r=float(p), g=0.0, b=float(1 - p), a=0.3 + 0.7 * float(p))
                        for p in prob]
        out.markers.append(cloud)
    if arm.table is not None:    # the top, and the floor the planner keeps the arm above
        for i, (z, alpha) in enumerate(((arm.table.height, 0.5), (arm.table.floor, 0.15))):
            plate = Marker(type=Marker.CUBE, action=Marker.ADD, ns='table', id=i)
            plate.header.frame_id, plate.header.stamp = FRAME, stamp
            plate.pose.position = _point(np.array([0.0, 0.0, z - 0.001]))
            plate.pose.orientation.w = 1.0
            plate.scale.x = plate.scale.y = TABLE_SIDE
            plate.scale.z = 0.002
            plate.color = ColorRGBA(r=0.8, g=0.75, b=0.65, a=alpha)
            out.markers.append(plate)
    return out


def scene_markers(scene, stamp) -> MarkerArray:
    """
    Build markers of a physics scene: obstacles in the base frame, the object at the flange.

    Obstacles are drawn where the scene file puts them (a yielding one is not followed as it
    turns); the grasped object is locked to the flange frame, which robot_state_publisher
    moves with the arm.
    """
    from probdis_ros.model.arms import rotation_to_quaternion
    out = MarkerArray()
    shapes = [(o.shape, FRAME, 'obstacles', (0.55, 0.55, 0.6) if o.hinge is None
               else (0.85, 0.65, 0.2)) for o in scene.obstacles]
    if scene.grasped is not None:
        shapes += [(s, 'lbr_link_ee', 'grasped_object', (0.2, 0.7, 0.3))
                   for s in scene.grasped.shapes]
    for shape, frame, ns, (r, g, b) in shapes:
        parts = [(shape.position, shape.rotation, shape.kind, shape.size)]
        if shape.kind == 'capsule':     # RViz has no capsule: a cylinder and two balls
            radius, length = shape.size
            axis = shape.rotation[:, 2] * length / 2
            parts = [(shape.position, shape.rotation, 'cylinder', shape.size),
                     (shape.position + axis, shape.rotation, 'sphere', (radius,)),
                     (shape.position - axis, shape.rotation, 'sphere', (radius,))]
        for position, rotation, kind, size in parts:
            marker = Marker(action=Marker.ADD, ns=ns, id=len(out.markers), frame_locked=True)
            marker.type = {'box': Marker.CUBE, 'sphere': Marker.SPHERE,
                           'cylinder': Marker.CYLINDER}[kind]
            marker.header.frame_id, marker.header.stamp = frame, stamp
            marker.pose.position = _point(position)
            w, x, y, z = np.asarray(rotation_to_quaternion(np.asarray(rotation))).reshape(4)
            marker.pose.orientation.w, marker.pose.orientation.x = float(w), float(x)
            marker.pose.orientation.y, marker.pose.orientation.z = float(y), float(z)
            if kind == 'box':
                marker.scale.x, marker.scale.y, marker.scale.z = (float(v) for v in size)
            elif kind == 'sphere':
                marker.scale.x = marker.scale.y = marker.scale.z = 2 * float(size[0])
            else:
                marker.scale.x = marker.scale.y = 2 * float(size[0])
                marker.scale.z = float(size[1])
            marker.color = ColorRGBA(r=r, g=g, b=b, a=0.8)
            out.markers.append(marker)
    return out
