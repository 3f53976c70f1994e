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
Read from joint_trajectory_controller's node where it starts a command and whether it holds.

The planner models where JTC starts each new command: the measured state, or its last command
(``interpolate_from_desired_state``, or the deprecated ``open_loop_control``, true).  A
planner that models the other start than the controller runs either drives a pressed-in arm
back into what blocked it or takes the release of a block for a new block, so ``~/start`` is
refused when the two differ.  Modelling the last command also needs JTC never to hold by
itself: on a path tolerance (``constraints.<joint>.trajectory``) or goal time
(``constraints.goal_time``) violation, or ``cmd_timeout`` after a trajectory's end, it holds
the *measured* position, which becomes its last command unseen by the planner, and the next
command would step from there to where the planner thinks the command is (into what blocked
the arm).  The controller's parameters are
read through its node's parameter service (``<controller_node>/get_parameters``), one call
per name (a node answers nothing when one name is undeclared), asked again every ``POLL``
seconds so that a controller started or reconfigured later is seen.
"""

from __future__ import annotations

import time

from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from rclpy.node import Node

PARAMETER = 'interpolate_from_desired_state'
#: JTC (Jazzy) starts from its last command when either is true (the second is deprecated).
STARTS = (PARAMETER, 'open_loop_control')
#: How often the controller's parameters are asked for [s] (wall clock).
POLL = 2.0
#: [s] how long after the node came up a controller that has not answered yet is still being
#: found (discovery, the first call): a start then is checked once it answers, not warned.
FIRST_ANSWER = 2 * POLL


def _value(values: list) -> bool | float | None:
    """Return a GetParameters answer's one boolean or number (None: not declared)."""
    if len(values) != 1:
        return None
    v = values[0]
    if v.type == ParameterType.PARAMETER_BOOL:
        return bool(v.bool_value)
    if v.type == ParameterType.PARAMETER_DOUBLE:
        return float(v.double_value)
    if v.type == ParameterType.PARAMETER_INTEGER:
        return float(v.integer_value)
    return None


class ControllerSetting:
    """What the controller's node said last: where it starts commands, when it holds."""

    def __init__(self, node: Node, controller_node: str, joints: list[str]) -> None:
        self.controller_node = controller_node.rstrip('/')
        self.value: bool | None = None       # starts from its last command (None: unknown)
        self.holds: dict[str, float] = {}    # its non-zero hold constraints, once read
        self.problem = 'not asked yet'       # why the value is not known
        self.skipped = not self.controller_node     # controller_node '': the user opted out
        self._names = list(STARTS) + ['constraints.goal_time', 'cmd_timeout'] + [
            f'constraints.{joint}.trajectory' for joint in joints]
        self._asked_at = -float('inf')
        self._answers: dict[str, bool | float | None] = {}
        self._waiting = 0
        self._batch = 0                       # answers of an abandoned batch are dropped
        self._futures: list = []
        self._answered_at = -float('inf')
        self._created = time.monotonic()
        self._client = None
        if self.skipped:
            self.problem = 'controller_node is empty: not checked'
        else:
            self._client = node.create_client(GetParameters,
                                              f'{self.controller_node}/get_parameters')

    def first_answer_due(self) -> bool:
        """Tell whether the controller may not have been found yet: the node is that young."""
        return self._client is not None and self._answered_at == -float('inf') and \
            time.monotonic() - self._created < FIRST_ANSWER

    def poll(self) -> None:
        """Ask the controller again when due (call from a timer; never blocks)."""
        if self._client is None:
            return
        if self._waiting:
            if time.monotonic() - self._asked_at < POLL:
                return
            # a call that never returns (the controller went mid-call): abandon the batch
            for future in self._futures:
                self._client.remove_pending_request(future)
            self._waiting, self._batch, self._futures = 0, self._batch + 1, []
            if self._answered_at == -float('inf'):
                self.problem = f'{self.controller_node} did not answer within {POLL:g} s'
        if time.monotonic() - self._answered_at > 2.5 * POLL:
            self.value = None          # an answer this old may no longer hold
            if self.problem == '':
                self.problem = f'{self.controller_node} has not answered for {2.5 * POLL:g} s'
        if not self._client.service_is_ready():
            self.value = None
            self.problem = f'{self.controller_node}/get_parameters does not answer'
            return
        if time.monotonic() - self._asked_at < POLL:
            return
        self._asked_at = time.monotonic()
        self._answers, self._waiting = {}, len(self._names)
        self._batch += 1
        self._futures = []
        for name in self._names:
            future = self._client.call_async(GetParameters.Request(names=[name]))
            self._futures.append(future)
            future.add_done_callback(
                lambda done, name=name, batch=self._batch: self._answered(name, done, batch))

    def _answered(self, name: str, future, batch: int) -> None:
        if batch != self._batch:
            return
        try:
            self._answers[name] = _value(future.result().values)
        except Exception:              # a failed call: not known
            self._answers[name] = None
        self._waiting -= 1
        if self._waiting:
            return
        # a JTC released before interpolate_from_desired_state has open_loop_control alone
        starts = [v for n in STARTS if isinstance(v := self._answers.get(n), bool)]
        if not starts:
            self.value = None
            self.problem = f'{self.controller_node} has no boolean {" or ".join(STARTS)}'
            return
        self.value = any(starts)
        self.holds = {n: v for n in self._names[len(STARTS):]
                      if isinstance(v := self._answers.get(n), float) and v > 0}
        self.problem = ''
        self._answered_at = time.monotonic()

    def below_lag(self, lags: dict[str, float]) -> str:
        """
        Return the path tolerances (``constraints.<joint>.trajectory``) below lags ('' none).

        lags: per joint, how far the arm in joint impedance lags its command in free motion
        [rad].  JTC holds mid-path where a joint lags beyond its tolerance, and the planner,
        whose command goes on, takes every path for blocked: a false failure each.
        """
        tight = [f'{joint} {self.holds[name]:g} < {lag:.2f}' for joint, lag in lags.items()
                 if 0 < self.holds.get(name := f'constraints.{joint}.trajectory', 0.0) < lag]
        return ', '.join(tight)

    def refusal(self, planner_value: bool) -> str:
        """
        Return why a run must not start with planner_value ('' when it may).

        A planner that models the last command must know the controller does too and never
        holds by itself (else a command would step from where JTC is to where the planner
        thinks it is, into what blocked the arm): unknown is refused.  One that models the
        measured state may start unconfirmed (the node warns): a controller that starts from
        its last command then steps back to the arm, as a measured start does.
        """
        if self.value is None:
            if not planner_value or self.skipped:
                return ''
            return (f"could not read joint_trajectory_controller's {PARAMETER} "
                    f'({self.problem}); this planner models it true and starts only once it '
                    f'has seen the controller agree: set controller_node to the '
                    f"controller's node (or, at your own risk, to '' to skip the check)")
        if self.value != planner_value:
            return ('joint_trajectory_controller starts each command from its '
                    f"{'last command' if self.value else 'measured state'} "
                    f'({self.controller_node}: {" or ".join(STARTS)} '
                    f"{'true' if self.value else 'false'}), this planner models the "
                    f"{'last command' if planner_value else 'measured state'} "
                    f'(interpolate_from_desired_state {str(planner_value).lower()}): set them '
                    f'alike (a planner that models the other start would drive a blocked arm '
                    f'back into what it hit, or take its release for a new block); not '
                    f'starting')
        if planner_value and self.holds:
            named = ', '.join(f'{n} {v:g}' for n, v in self.holds.items())
            return (f'joint_trajectory_controller holds the measured position by itself '
                    f'(on a tolerance violation, or cmd_timeout after a trajectory ends) '
                    f'with {named} ({self.controller_node}), and a planner that '
                    f'models its last command would not see it: with {PARAMETER} set '
                    f"these to 0 in the controller's parameter file and load it again (JTC "
                    f'takes them when it is configured: a value set at run time is read here '
                    f'but not used there; README, "Pointing it at the real arm"); not '
                    f'starting')
        return ''
