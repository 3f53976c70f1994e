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

"""The operator's answers in ``probdis demo --confirm``: scripted, typed, late, or none."""

import os
import pty
import threading
import time

from probdis_ros.ros.operator_prompt import OperatorPrompt, QUESTION


def prompt_on(fd):
    said = []
    return OperatorPrompt(os.fdopen(fd, 'r', closefd=False), said.append), said


def test_piped_answers_are_a_script_taken_in_order_and_the_end_of_input_stops():
    read, write = os.pipe()
    os.write(write, b'n\nmaybe\n\ny\ns')       # all at once: one read holds several lines
    os.close(write)
    prompt, said = prompt_on(read)
    waiting = lambda: True                   # noqa: E731
    answers = [prompt.ask(waiting, patience=5.0) for _ in range(5)]
    assert answers == ['decline_path', 'confirm_path', 'confirm_path', 'stop', 'stop']
    assert said.count(QUESTION) == 6           # 'maybe' is asked again
    os.close(read)


def test_no_answer_within_patience_stops_and_a_path_that_no_longer_waits_drops_the_question():
    read, write = os.pipe()                    # a pipe nobody writes to, never closed
    prompt, said = prompt_on(read)
    began = time.monotonic()
    assert prompt.ask(lambda: True, patience=0.6) == 'stop'
    assert 0.6 <= time.monotonic() - began < 2.0
    assert 'no answer within 0.6 s: stopping the run' in said[-1]
    asked = iter([True, True, False])
    assert prompt.ask(lambda: next(asked), patience=30.0) is None
    os.close(read)
    os.close(write)


def test_at_a_terminal_lines_typed_before_the_question_are_dropped():
    # a double Enter on the last path must not send the next one unseen
    master, slave = pty.openpty()
    try:
        os.write(master, b'\n\n')
        time.sleep(0.2)                        # typed ahead, before the question
        prompt, _ = prompt_on(slave)
        threading.Timer(0.5, lambda: os.write(master, b'n\n')).start()
        began = time.monotonic()
        assert prompt.ask(lambda: True, patience=5.0) == 'decline_path'
        assert time.monotonic() - began >= 0.4     # waited for the answer typed after it
    finally:
        os.close(master)
        os.close(slave)
