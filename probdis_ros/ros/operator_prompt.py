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
``probdis demo --confirm``: the operator's answer to each path, read from standard input.

An answer must be about the path on screen: at a terminal, lines typed before the question
are dropped (a double Enter would otherwise send the next path unseen), while input from a
pipe or file is a script of answers, taken in order.  The question never outlives its path:
it is dropped once the path no longer waits (stopped from elsewhere, a node gone), and it
gives up, stopping the run, after ``patience`` seconds without an answer (input that never
ends, as a pipe nobody writes to, would otherwise hold the demo for good).
"""

from __future__ import annotations

from collections.abc import Callable
import os
import select
import sys
import termios
import time
from typing import TextIO

#: What the operator types, and the planner service it calls (an empty line: confirm).
ANSWERS = {'': 'confirm_path', 'y': 'confirm_path', 'n': 'decline_path', 's': 'stop'}
QUESTION = 'demo: send this path? [Enter/y] send, [n] plan another, [s] stop: '
#: How often the question looks whether its path still waits [s].
POLL = 0.25


class OperatorPrompt:
    """Ask, on a stream (standard input), what to do with each path awaiting confirmation."""

    def __init__(self, stream: TextIO | None = None,
                 say: Callable[[str], None] | None = None) -> None:
        """Read from stream's file descriptor (unbuffered: select() must see every line)."""
        self.stream = stream or sys.stdin
        self.say = say or (lambda text: print(text, end='', file=sys.stderr, flush=True))
        self._pending = b''
        self._ended = False

    def ask(self, still_waiting: Callable[[], bool], patience: float) -> str | None:
        """
        Return the service the answer calls, or None once the path no longer waits.

        Enter or y sends the path, n plans another, s stops the run; so does the end of the
        input, and no answer within patience [s] (said on the terminal).
        """
        try:
            fd = self.stream.fileno()
            if os.isatty(fd):
                termios.tcflush(fd, termios.TCIFLUSH)
                self._pending = b''
        except (AttributeError, ValueError, OSError) as error:    # no input to read
            self.say(f'demo: cannot read answers from standard input ({error}): stopping '
                     f'the run\n')
            return 'stop'
        self.say(QUESTION)
        deadline = time.monotonic() + patience
        while True:
            try:
                line = self._line(fd)
            except OSError as error:          # closed under us, or not readable
                self.say(f'\ndemo: standard input failed ({error}): stopping the run\n')
                return 'stop'
            if line is not None:
                service = ANSWERS.get(line.strip().lower())
                if service:
                    return service
                self.say(QUESTION)
            if self._ended and not self._pending:
                return 'stop'
            if not still_waiting():
                self.say('(no longer waits)\n')
                return None
            if time.monotonic() > deadline:
                self.say(f'\ndemo: no answer within {patience:g} s: stopping the run\n')
                return 'stop'

    def _line(self, fd: int) -> str | None:
        """Return the next whole line, waiting up to POLL for input; None: none yet."""
        if b'\n' not in self._pending and not self._ended:
            ready, _, _ = select.select([fd], [], [], POLL)
            if ready:
                chunk = os.read(fd, 4096)
                self._pending += chunk
                self._ended = not chunk
        if b'\n' in self._pending:
            line, self._pending = self._pending.split(b'\n', 1)
            return line.decode(errors='replace')
        if self._ended and self._pending:        # a last line without its newline
            line, self._pending = self._pending, b''
            return line.decode(errors='replace')
        return None
