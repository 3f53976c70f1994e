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
    answer = threading.Timer(0.5, lambda: os.write(master, b'n\n'))
    try:
        os.write(master, b'\n\n')
        time.sleep(0.2)                        # typed ahead, before the question
        prompt, _ = prompt_on(slave)
        answer.start()
        began = time.monotonic()
        assert prompt.ask(lambda: True, patience=5.0) == 'decline_path'
        assert time.monotonic() - began >= 0.4     # waited for the answer typed after it
    finally:
        answer.cancel()
        if answer.ident is not None:        # started
            answer.join()
        os.close(master)
        os.close(slave)


def test_input_of_no_answer_at_all_times_out_and_no_input_to_read_stops():
    # a stream of lines that answer nothing (`yes no |`) is no answer: the patience runs out
    read, write = os.pipe()
    done = threading.Event()

    def babble():
        while not done.is_set():
            os.write(write, b'maybe\n')
            time.sleep(0.01)

    writer = threading.Thread(target=babble)
    writer.start()
    try:
        prompt, said = prompt_on(read)
        began = time.monotonic()
        assert prompt.ask(lambda: True, patience=0.5) == 'stop'
        assert time.monotonic() - began < 2.0 and 'no answer within 0.5 s' in said[-1]
    finally:
        done.set()
        writer.join()
        os.close(read)
        os.close(write)
    # standard input closed (or absent: no file number to read)
    closed = open(os.devnull)
    closed.close()
    said = []
    assert OperatorPrompt(closed, said.append).ask(lambda: True, patience=5.0) == 'stop'
    assert 'cannot read answers' in said[-1]
