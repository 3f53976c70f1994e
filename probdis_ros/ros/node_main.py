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
import difflib
import gc
import signal
import sys
import threading

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterException,
)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

#: [s] the longest the spin waits before it looks whether a signal asked it to end.
SIGNAL_CHECK = 0.05


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


def ros_args_error(err: RCLError) -> str:
    """Return rcl's refusal of the ROS arguments as one line, with the fix where it is known."""
    text = str(err).splitlines()[0]
    if 'Sequence should be of same type' in text:
        text += ' (write every number of a list with a decimal point: 0.0, not 0)'
    return text


def refuse_unknown_parameters(node: Node) -> None:
    """
    Raise ValueError (exit 2) for a start-up value of a parameter the node does not have.

    rclpy drops such values without a word: a misspelt ``table_height`` on the real arm would
    run with the default table, 0 m.
    """
    declared = set(node.get_parameters_by_prefix(''))   # every declared parameter
    # rclpy has no public list of the start-up values (they are the node's overrides)
    unknown = sorted(set(node._parameter_overrides) - declared)
    if unknown:
        guesses = [difflib.get_close_matches(name, declared, n=1) for name in unknown]
        said = ', '.join(f'{name} (did you mean {guess[0]}?)' if guess else name
                         for name, guess in zip(unknown, guesses))
        raise ValueError(f'not a parameter of {node.get_name()}: {said}')


def run_node(name: str, factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """
    Create the node, spin it, and always halt and destroy it (which closes its files).

    SIGINT and SIGTERM only ask the spin to end, between callbacks (a KeyboardInterrupt
    raised wherever the main thread was once left half a record in the bag,
    ``test_the_bag_is_readable_after_the_node_is_killed``); the context stays up until the
    node's ``halt(reason)``, if it has one, has run: the planner commands a decelerating
    stop there, which a context already shut down by rclpy's own handler could not publish
    (the arm ran the rest of its path unsupervised).  An error out of a callback halts it
    too before the node goes.
    """
    try:
        stray = remove_ros_args(sys.argv if args is None else args)[1:]
    except RCLError as err:            # unparsable --ros-args, a --params-file not there
        print(f'{name}: error: {ros_args_error(err)}', file=sys.stderr)
        return 2
    if stray:
        # rclpy ignores them: a goal given as "-p goal:=[...]" without --ros-args was lost,
        # and the node ran with its defaults
        print(f'{name}: error: {" ".join(stray)!r} is not a ROS argument: parameters and '
              f'remappings go after --ros-args (--ros-args -p name:=value)', file=sys.stderr)
        return 2
    ending = threading.Event()
    options = None

    def end(signum: int, frame: object) -> None:
        ending.set()
    try:
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, end)
        options = SignalHandlerOptions.NO       # ours, not rclpy's
    except ValueError:
        pass                 # not the main thread: rclpy's handlers, as a host expects
    try:
        rclpy.init(args=args, signal_handler_options=options)
    except RCLError as err:            # unparsable --ros-args
        print(f'{name}: error: {ros_args_error(err)}', file=sys.stderr)
        return 2
    node = None
    reason = 'SIGINT or SIGTERM'
    try:
        node = factory()
        # what start-up built (modules, compiled kernels, the node) lives as long as the
        # process: frozen, it is left out of every later full garbage collection, which
        # walked all of it and held the executor for 50-110 ms at a time (in the planner,
        # when the message of a long path was built: the arm's states waited behind it)
        gc.collect()
        gc.freeze()
        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        while not ending.is_set() and rclpy.ok(context=node.context):
            executor.spin_once(timeout_sec=SIGNAL_CHECK)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass                 # SIGINT / SIGTERM: cleaned up below
    except RCLError:
        # a signal can shut the context down while spin is setting up its wait set
        if rclpy.ok(context=node.context if node is not None else None):
            reason = 'an error'
            raise
    except ParameterException as err:
        print(f'{name}: error: {parameter_error(err)}', file=sys.stderr)
        reason = 'a parameter error'
        return 2
    except (ValueError, FileNotFoundError) as err:
        print(f'{name}: error: {err}', file=sys.stderr)
        reason = 'an error'
        return 2
    except BaseException:
        reason = 'an error'
        raise
    finally:
        if node is not None:
            _halt(name, node, reason)
            node.destroy_node()
        try:
            rclpy.try_shutdown()
        except RCLError:
            pass             # the signal handler shut the context down at the same moment
    return 0


def _halt(name: str, node: Node, reason: str) -> None:
    """Let the node bring what it drives to rest before it goes (its ``halt``, if any)."""
    halt = getattr(node, 'halt', None)
    if halt is None or not rclpy.ok(context=node.context):
        return
    try:
        halt(f'{name} is shutting down ({reason})')
    except Exception as err:     # the node goes anyway; say why nothing was stopped
        print(f'{name}: error: could not halt: {err!r}', file=sys.stderr)
