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
Command-line access to a running planner without the ros2 CLI: services, parameters, status.

Each call uses its own rclpy context and a short-lived node, so it works from a plain
process (``probdis start``) as well as inside ``probdis demo``.
"""

from __future__ import annotations

import json
import math
import os
import time

from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
import rclpy
from rclpy.context import Context
from rclpy.exceptions import NameValidationException
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String
from std_srvs.srv import Trigger

PLANNER = '/probdis_planner'
#: [s] for a service found by a client to find the client's reply reader too (a reply sent
#: before that is lost), waited before each request
REPLY_MATCH = 0.3
#: Why a planner may be slow to offer its services (said by the client and the demo).
FIRST_START = ("a planner's first start after an install compiles its kernels, 20-50 s "
               'on two cores; later starts take seconds')


class NoAnswerError(TimeoutError):
    """A request reached the service but no answer came back: it may have taken effect."""


def check_timeout(timeout: float) -> float:
    """
    Return timeout [s] if finite: a NaN or infinite deadline is never passed.

    One of 0 or less looks once (the demo's waits count down to it); the CLI refuses those.
    """
    if not math.isfinite(timeout):
        raise ValueError(f'timeout must be a finite number of seconds, got {timeout}')
    return timeout


class PlannerClient:
    """Calls the planner's services and reads its status."""

    def __init__(self, planner: str = PLANNER) -> None:
        self.planner = planner
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f'probdis_client_{os.getpid()}', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.latest: dict | None = None
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        try:
            self.node.create_subscription(String, f'{planner}/status', self._on_status, latched)
        except NameValidationException as err:
            self.close()
            # rclpy's message spans lines (the name, a caret under the fault): keep the reason
            reason = str(err).splitlines()[0].partition(': ')[2].rstrip(':')
            raise ValueError(f'{planner!r} is not a valid planner node name '
                             f'({reason})') from None

    def _on_status(self, msg: String) -> None:
        self.latest = json.loads(msg.data)

    def call(self, service: str, timeout: float = 10.0) -> tuple[bool, str]:
        """
        Call ``<planner>/<service>`` (std_srvs/Trigger), waiting up to timeout for each step.

        TimeoutError if the service is not there within timeout [s]; :class:`NoAnswerError`
        if it was called but its answer did not come within timeout of the call.
        """
        response = self._request(Trigger, service, Trigger.Request(), timeout)
        return bool(response.success), response.message

    def parameters(self, names: list[str], timeout: float = 10.0) -> dict[str, object]:
        """Return the planner's parameters by name; KeyError names one it does not have."""
        response = self._request(GetParameters, 'get_parameters',
                                 GetParameters.Request(names=names), timeout)
        if len(response.values) != len(names):      # rclpy answers none for an unknown name
            raise KeyError(f'{self.planner} has no parameter '
                           f'{names[0] if len(names) == 1 else "among " + ", ".join(names)}')
        values = {}
        for name, value in zip(names, response.values, strict=True):
            if value.type == ParameterType.PARAMETER_NOT_SET:
                raise KeyError(f'{self.planner} has no parameter {name}')
            values[name] = parameter_value_to_python(value)
        return values

    def parameter_names(self, timeout: float = 10.0) -> list[str]:
        """Return the names of the planner's parameters, sorted."""
        response = self._request(ListParameters, 'list_parameters', ListParameters.Request(),
                                 timeout)
        return sorted(response.result.names)

    def set_parameter(self, name: str, value: object, timeout: float = 10.0
                      ) -> tuple[bool, str]:
        """
        Set one parameter of the planner; return (accepted, reason).

        Whole numbers are taken as decimals where the parameter holds decimals (a goal of
        ``[0, 1, ...]``, as ros2 param set would refuse), so the value keeps its type.
        """
        def decimal(v: object) -> object:
            return float(v) if isinstance(v, int) and not isinstance(v, bool) else v

        current = self.parameters([name], timeout)[name]
        if isinstance(current, float):
            value = decimal(value)
        elif isinstance(current, list) and current and isinstance(current[0], float) and \
                isinstance(value, list):
            value = [decimal(v) for v in value]
        try:
            message = Parameter(name, value=value).to_parameter_msg()
        except (TypeError, ValueError) as err:
            return False, f'{value!r} is not a parameter value ({err})'
        response = self._request(SetParameters, 'set_parameters',
                                 SetParameters.Request(parameters=[message]), timeout)
        result = response.results[0]
        return bool(result.successful), result.reason

    def _request(self, kind, service: str, request, timeout: float):
        """Call ``<planner>/<service>`` of type kind; return its response (see call)."""
        check_timeout(timeout)
        client = self.node.create_client(kind, f'{self.planner}/{service}')
        try:
            deadline = time.monotonic() + timeout
            while not client.service_is_ready():
                if time.monotonic() > deadline:
                    raise TimeoutError(f'no {self.planner}/{service} service within '
                                       f'{timeout:g} s; is the planner running? '
                                       f'({FIRST_START})')
                self.executor.spin_once(timeout_sec=0.05)
            # a server the client has found must find the client's reply reader too, and a
            # reply sent before that is lost (rmw: "failed to send response (timeout)"; seen
            # in CI under load): let discovery finish before the request
            settle = time.monotonic() + REPLY_MATCH
            while time.monotonic() < settle:
                self.executor.spin_once(timeout_sec=0.05)
            # the answer has its own time: a service that came up just before the deadline
            # has not had the time to answer (it did not answer is not it was not called)
            deadline = time.monotonic() + timeout
            future = client.call_async(request)
            while not future.done():
                if time.monotonic() > deadline:
                    raise NoAnswerError(f'{self.planner}/{service} did not answer within '
                                        f'{timeout:g} s; the call may have taken effect '
                                        f'(probdis status tells)')
                self.executor.spin_once(timeout_sec=0.05)
            return future.result()
        finally:
            self.node.destroy_client(client)

    def status(self, timeout: float = 5.0, newer_than: dict | None = None) -> dict:
        """Wait for the latest status document (one differing from newer_than, if given)."""
        check_timeout(timeout)
        deadline = time.monotonic() + timeout
        while self.latest is None or (newer_than is not None and self.latest == newer_than):
            if time.monotonic() > deadline:
                if self.latest is not None:
                    return self.latest
                raise TimeoutError(f'no status from {self.planner} within {timeout:g} s')
            self.executor.spin_once(timeout_sec=0.05)
        return self.latest

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()

    def __enter__(self) -> PlannerClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
