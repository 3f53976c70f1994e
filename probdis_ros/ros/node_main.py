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

"""The ``main`` of every node: spin until SIGINT/SIGTERM, report bad set-up in one line."""

from __future__ import annotations

from collections.abc import Callable
import gc
import signal
import sys

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterException,
)
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def parameter_error(err: ParameterException) -> str:
    """Return a start-up parameter refused by rclpy as one line naming it."""
    if isinstance(err, InvalidParameterTypeException):
        text = str(err).rsplit(': ', 1)[0]
        if 'INTEGER' in text and 'DOUBLE' in text:
            text += ' (write 1.0, not 1)'
        return text
    if isinstance(err, InvalidParameterValueException):
        name = str(err).rsplit(': ', 1)[-1]
        reason = str(err).split('Reason: ', 1)[-1].rsplit(': ', 1)[0]
        return f'parameter {name}: {reason}'
    return str(err)


def _no_interrupt(signum: int, frame: object) -> None:
    """Take SIGINT without a KeyboardInterrupt: rclpy's handler ends the spin."""


def run_node(name: str, factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """
    Create the node, spin it, and always destroy it (which closes its files).

    SIGINT ends it as SIGTERM does: rclpy's handler shuts the context down and the spin
    returns between callbacks.  Python's own handler, which rclpy's calls after it, would
    raise KeyboardInterrupt wherever the main thread is, and once inside the recorder it
    left half a record in the bag (``test_the_bag_is_readable_after_the_node_is_killed``).
    """
    try:
        signal.signal(signal.SIGINT, _no_interrupt)     # before rclpy.init, which chains it
    except ValueError:
        pass                 # not the main thread: no handler of ours to replace
    try:
        rclpy.init(args=args)
    except RCLError as err:            # unparsable --ros-args
        print(f'{name}: error: {str(err).splitlines()[0]}', file=sys.stderr)
        return 2
    node = None
    try:
        node = factory()
        # what start-up built (modules, compiled kernels, the node) lives as long as the
        # process: frozen, it is left out of every later full garbage collection, which
        # walked all of it and held the executor for 50-110 ms at a time (in the planner,
        # when the message of a long path was built: the arm's states waited behind it)
        gc.collect()
        gc.freeze()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass                 # SIGINT / SIGTERM: cleaned up below
    except RCLError:
        # a signal can shut the context down while spin is setting up its wait set
        if rclpy.ok(context=node.context if node is not None else None):
            raise
    except ParameterException as err:
        print(f'{name}: error: {parameter_error(err)}', file=sys.stderr)
        return 2
    except (ValueError, FileNotFoundError) as err:
        print(f'{name}: error: {err}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        try:
            rclpy.try_shutdown()
        except RCLError:
            pass             # the signal handler shut the context down at the same moment
    return 0
