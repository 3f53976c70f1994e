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

"""Every default of the physics-simulated iiwa in one place (the model and the arm read it)."""

from __future__ import annotations

from dataclasses import dataclass
import math


@dataclass(frozen=True)
class PhysicsSettings:
    """
    Controller and simulation parameters of :class:`probdis_ros.physics.arm.PhysicsIiwa`.

    The impedance law is KUKA's: ``tau = K (q_set - q) - D qdot + g(q)``, with
    ``D_j = 2 damping_ratio sqrt(K_j M_jj(q))`` and the total clipped to the URDF efforts.
    """

    #: Joint stiffness K [Nm/rad]: the lbr stack's robot application sets 200 on every joint.
    stiffness: tuple[float, ...] = (200.0,) * 7
    #: Damping ratio of KUKA's joint impedance (0.7 is Sunrise's default).
    damping_ratio: float = 0.7
    #: Physics step [s].  Stable at 2 ms too (tests); 1 ms keeps contacts stiff.
    timestep: float = 0.001
    #: Real minus the controller's assumed object mass [kg]: the load-model error.
    object_mass_error: float = 0.0
    #: Reflected motor inertia per joint [kg m^2].  Not published by KUKA; a small value
    #: (A7's own link inertia is ~0.001).  Franka gives its FR3 0.21-0.61 (as quoted in
    #: Drake's franka_description README), so the iiwa's motors may well reflect more,
    #: though joint-torque feedback in KUKA's impedance control may hide some of it from
    #: the links.  The implicit damping already keeps A7 from the limit cycle of an
    #: explicit PD (DESIGN.md "Facts: a physics-simulated iiwa"): measured
    #: stable with 0 too, at 1 and 2 ms.
    armature: tuple[float, ...] = (0.01,) * 7
    #: Dry friction [Nm] in every joint that the impedance law leaves (MuJoCo's
    #: frictionloss): what of gear friction and model error KUKA's joint-torque feedback
    #: does not remove; at 200 Nm/rad each Nm holds a joint 0.005 rad from its command at
    #: rest.  0: none (the ideal arm).
    joint_friction: float = 0.0
    #: Rotational stiffness of the grasp [Nm/rad] about each flange axis: the object turns
    #: in the gripper when pressed; 0: welded to the flange (the planner's assumption).
    grasp_stiffness: float = 0.0
    #: Sliding friction coefficient between the robot (and object) and the scene.
    friction: float = 0.5
    #: Friction that holds under sustained load: MuJoCo's elliptic friction cones with this
    #: ratio of frictional to normal impedance, plus no-slip iterations (measured: a blocked
    #: arm pressing 40 N with a pyramidal cone crept 4.4 mm in 3 s; with these, 0.0 mm).
    impratio: float = 10.0
    noslip_iterations: int = 5
    #: Contact stiffness as MuJoCo's solref time constant [s] (>= 2 timesteps).
    contact_timeconst: float = 0.005
    #: How often [s] the configuration-dependent damping D(q) is recomputed within advance().
    damping_update: float = 0.01
    #: Height [m] of the table top the base stands on, a plane the arm and the object touch
    #: like any obstacle (the planner's own table check keeps them 5 cm above it); None:
    #: no table in a scene.
    table_height: float | None = 0.0

    def __post_init__(self) -> None:
        """Refuse values the simulation cannot run with."""
        if len(self.stiffness) != 7 or min(self.stiffness) <= 0:
            raise ValueError('stiffness must be 7 positive values (Nm/rad)')
        if len(self.armature) != 7 or min(self.armature) < 0:
            raise ValueError('armature must be 7 values >= 0 (kg m^2)')
        if not 0 <= self.joint_friction < math.inf:
            raise ValueError('joint_friction must be >= 0 (Nm)')
        if not self.grasp_stiffness >= 0:
            raise ValueError('grasp_stiffness must be >= 0 (Nm/rad; 0: a rigid grasp)')
        if self.damping_ratio < 0:
            raise ValueError('damping_ratio must be >= 0')
        if not 0 < self.timestep <= 0.01:
            raise ValueError('timestep must be in (0, 0.01] s')
        if self.contact_timeconst < 2 * self.timestep:
            raise ValueError('contact_timeconst must be at least two timesteps')
        if self.friction < 0 or self.noslip_iterations < 0 or self.damping_update <= 0:
            raise ValueError('friction, noslip_iterations must be >= 0, damping_update > 0')
