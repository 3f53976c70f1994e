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
Replay recorded runs through the detector with two models of where the arm should be.

``delay``: the detector as it is, the command ``motion_delay`` (0.1 s) earlier.  ``imp``:
the arm's free response in joint impedance, simulated open loop from its start: the
command through the driver's filter (:class:`SentCommand`) into
``M(q) q'' + C(q, q') q' = K (s - q) - D q'``, ``D_j = 2 zeta sqrt(K M_jj)`` (the physics
mock's law, KUKA's damping design), pinocchio's rigid-body model of the URDF, 1 ms steps;
as the mock (``imp_coupled``), without the coupling (``imp_diag``), and with the model
wrong as a real arm's may be (inertia +-30 %, stiffness 300 against 200).  The rest of the
detector unchanged (thresholds, onset rule, ``motion_delay`` for its timing).  Prints, per
run, the verdict and when, the flange at the onset from the flange at the first contact,
and the largest gap before the contact (free runs: during the motion).
Usage: python results/robot_physics/arm_model/evaluate.py RECORDS.pkl
"""

import pickle
import sys

import numpy as np
import pinocchio as pin
from probdis_ros.model import iiwa_arm
from probdis_ros.motion.detector import BlockDetector, DetectorSettings, SentCommand, Verdict
from probdis_ros.motion.jtc import DRIVER_FILTER_TAU, JtcTrajectory
from probdis_ros.resources import data_file

MODEL = pin.buildModelFromUrdf(str(data_file('urdf', 'iiwa14.urdf')))
MODEL.gravity.linear[:] = 0.0       # the controller compensates gravity
DATA = MODEL.createData()


class ImpedanceResponse:
    """The arm in joint impedance, free, under the driver's filtered command (open loop)."""

    def __init__(self, path, q0, v0, stiffness=200.0, zeta=0.7, armature=0.01,
                 coupled=True, inertia_scale=1.0, dt=0.001):
        self.sent = SentCommand(path, DRIVER_FILTER_TAU)
        self.stiffness, self.zeta, self.armature = stiffness, zeta, armature
        self.coupled, self.scale, self.dt = coupled, inertia_scale, dt
        self.q = [np.asarray(q0, float)]
        self.v = [np.zeros(7) if v0 is None else np.asarray(v0, float)]

    def _extend(self, n):
        while len(self.q) <= n:
            q, v = self.q[-1], self.v[-1]
            s = self.sent.at(np.array([(len(self.q) - 1) * self.dt]))[0]
            inertia = np.array(pin.crba(MODEL, DATA, q))
            inertia = (np.triu(inertia) + np.triu(inertia, 1).T) * self.scale
            inertia += self.armature * np.eye(7)
            damping = 2 * self.zeta * np.sqrt(self.stiffness * np.diag(inertia))
            torque = self.stiffness * (s - q) - damping * v
            if self.coupled:
                coriolis = np.array(pin.nonLinearEffects(MODEL, DATA, q, v))
                acceleration = np.linalg.solve(inertia, torque - coriolis)
            else:
                acceleration = torque / np.diag(inertia)
            v = v + self.dt * acceleration
            self.q.append(q + self.dt * v)
            self.v.append(v)

    def at(self, t):
        x = max(t, 0.0) / self.dt
        k = int(x)
        self._extend(k + 1)
        return self.q[k] * (1 - (x - k)) + self.q[k + 1] * (x - k)


def detector(record, response):
    """Return the detector of a record, its desired position the response's if given."""
    path = JtcTrajectory(record['command'], record['q0'], record['v0'])
    if response is None:
        return BlockDetector(path, record['t0'], DetectorSettings())

    class Modelled(BlockDetector):
        def _desired(self, t):
            _, v, _ = self.path.sample(t - self.settings.motion_delay)
            return model.at(t), v

    model = ImpedanceResponse(path, record['q0'], record['v0'], **response)
    return Modelled(path, record['t0'], DetectorSettings())


VARIANTS = {
    'delay0.1': None,
    'imp_coupled': {},
    'imp_diag': {'coupled': False},
    'imp_M+30%': {'inertia_scale': 1.3},
    'imp_M-30%': {'inertia_scale': 0.7},
    'imp_K300': {'stiffness': 300.0},
}

with open(sys.argv[1], 'rb') as stream:
    records = pickle.load(stream)
arm = iiwa_arm()
for (scene, scaling, free), record in sorted(records.items()):
    for name, response in VARIANTS.items():
        watch = detector(record, response)
        gaps, verdict, when = [], Verdict.MOVING, None
        for t, q in record['samples']:
            verdict = watch.update(t, q)
            gaps.append((t - record['t0'], watch.gap))
            if verdict is not Verdict.MOVING:
                when = t - record['t0']
                break
        times, gap = np.array(gaps).T
        if free:
            print(f'{scene:12s} {scaling} free    {name:12s} {verdict.value:8s} largest gap '
                  f'{gap[times <= record["duration"]].max():.3f} rad')
            continue
        contact_t, contact_x = record['contact']
        onset = 'none'
        if watch.onset is not None:
            x = arm.fk(watch.onset.config[None]).positions[0]
            onset = f'{100 * np.linalg.norm(x - contact_x):.2f} cm'
        print(f'{scene:12s} {scaling} blocked {name:12s} {verdict.value:8s} at {when:.2f} s '
              f'(contact {contact_t:.2f} s), onset {onset} from the contact, largest gap '
              f'before it {gap[times < contact_t].max():.3f} rad', flush=True)
    print()
