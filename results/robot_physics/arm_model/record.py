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
Record each physics scene's straight path into its obstacle, and the same path free.

For the study of a detector whose commanded position is the arm's own free response in
joint impedance (``evaluate.py``): the command, the arm's start, every reported joint state
(``motion.duration`` + 1 s free, + 2 s blocked: the arm presses on), and the first contact.
Usage: python results/robot_physics/arm_model/record.py SCENE[,SCENE...] OUT.pkl  (~2 min)
"""

from dataclasses import replace
import pickle
import sys

import numpy as np
from probdis_ros.physics.measure import _motion
from probdis_ros.physics.scene import load_scene
from probdis_ros.physics.simulated_robot import build_robot, RobotSettings

records = {}
for name in sys.argv[1].split(','):
    for scaling in (0.2, 0.4, 0.7):
        for free in (True, False):
            scene = load_scene(name)
            robot, _ = build_robot('physics', replace(scene, obstacles=()) if free else scene,
                                   RobotSettings())
            state = robot.joint_state()
            motion = _motion(np.array([state.position, robot.engine.scene.goal]), scaling)
            t0 = robot.time
            robot.command(motion.command)
            samples, contact = [], None
            while robot.time < t0 + motion.duration + (1.0 if free else 2.0):
                robot.step()
                reported = robot.joint_state()
                samples.append((reported.time, reported.position.copy()))
                if contact is None and sum(c.force for c in robot.engine.contacts()) > 0:
                    contact = (robot.time - t0, robot.engine.flange_pose()[0].copy())
            records[(name, scaling, free)] = dict(
                command=motion.command, q0=state.position, v0=state.velocity, t0=t0,
                samples=samples, contact=contact, duration=motion.duration)
            print(name, scaling, 'free' if free else 'blocked', 'contact at',
                  None if contact is None else round(contact[0], 3), flush=True)
with open(sys.argv[2], 'wb') as out:
    pickle.dump(records, out)
