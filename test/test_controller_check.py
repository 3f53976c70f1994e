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

"""Reading the controller's settings: answers, silence, a controller that goes mid-call."""

from types import SimpleNamespace

from probdis_ros.ros import controller_check
from probdis_ros.ros.controller_check import ControllerSetting, POLL
import pytest
from rcl_interfaces.msg import ParameterType, ParameterValue


class Future:
    """A call's future, answered by the test (or never)."""

    def __init__(self, name):
        self.name, self.callbacks, self.value = name, [], None

    def add_done_callback(self, callback):
        self.callbacks.append(callback)

    def answer(self, value):
        self.value = value
        for callback in self.callbacks:
            callback(self)

    def result(self):
        values = [] if self.value is None else [self.value]
        return SimpleNamespace(values=values)


class Client:
    """The controller node's get_parameters, as the test makes it answer."""

    def __init__(self):
        self.ready, self.calls, self.removed = True, [], []

    def service_is_ready(self):
        return self.ready

    def call_async(self, request):
        self.calls.append(Future(request.names[0]))
        return self.calls[-1]

    def remove_pending_request(self, future):
        self.removed.append(future)


@pytest.fixture
def setting(monkeypatch):
    client = Client()
    node = SimpleNamespace(create_client=lambda *args: client)
    clock = [100.0]
    monkeypatch.setattr(controller_check.time, 'monotonic', lambda: clock[0])
    return ControllerSetting(node, '/lbr/joint_trajectory_controller', ['lbr_A1']), client, clock


def answer_all(client, values):
    for future in list(client.calls):
        value = values.get(future.name)
        if isinstance(value, bool):
            future.answer(ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value))
        elif value is not None:
            future.answer(ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                         double_value=value))
        else:
            future.answer(None)      # undeclared: the node answers nothing
    client.calls.clear()


def test_the_controllers_start_and_holds_are_read(setting):
    check, client, _ = setting
    check.poll()
    answer_all(client, {'interpolate_from_desired_state': True,
                        'constraints.goal_time': 0.0, 'constraints.lbr_A1.trajectory': 0.3})
    assert check.value is True and check.holds == {'constraints.lbr_A1.trajectory': 0.3}
    assert 'constraints.lbr_A1.trajectory 0.3' in check.refusal(True)
    assert 'from its last command' in check.refusal(False)


@pytest.mark.parametrize('open_loop', [True, False])
def test_a_controller_with_open_loop_control_alone_is_read_by_it(setting, open_loop):
    # a JTC released before interpolate_from_desired_state: its open_loop_control was read
    # and dropped, and a measured-start planner started against a desired-start JTC
    check, client, _ = setting
    check.poll()
    answer_all(client, {'open_loop_control': open_loop, 'constraints.goal_time': 0.0})
    assert check.value is open_loop and check.problem == ''
    assert bool(check.refusal(False)) is open_loop and bool(check.refusal(True)) is not open_loop
    setting[2][0] += POLL                        # later neither answers: not known
    check.poll()
    answer_all(client, {})
    assert check.value is None and 'open_loop_control' in check.problem


def test_a_command_timeout_is_a_hold_the_desired_start_cannot_see(setting):
    # JTC's cmd_timeout holds the measured position a while after each trajectory's end
    check, client, _ = setting
    check.poll()
    answer_all(client, {'interpolate_from_desired_state': True, 'cmd_timeout': 0.5,
                        'constraints.goal_time': 0.0, 'constraints.lbr_A1.trajectory': 0.0})
    assert check.holds == {'cmd_timeout': 0.5}
    assert 'cmd_timeout 0.5' in check.refusal(True)


def test_a_controller_that_goes_mid_call_is_no_longer_believed(setting):
    check, client, clock = setting
    check.poll()
    answer_all(client, {'interpolate_from_desired_state': True, 'open_loop_control': False,
                        'constraints.goal_time': 0.0, 'constraints.lbr_A1.trajectory': 0.0})
    assert check.value is True and check.refusal(True) == ''
    clock[0] += POLL
    check.poll()                       # asked again: the controller never answers
    hung = list(client.calls)
    assert len(hung) == 5
    clock[0] += POLL
    check.poll()                       # the hung batch is dropped, a new one asked
    assert client.removed == hung
    clock[0] += POLL
    check.poll()
    assert check.value is None and 'has not answered' in check.refusal(True)
    for future in hung:                # late answers of a dropped batch change nothing
        future.answer(ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=False))
    assert check.value is None


def test_a_path_tolerance_below_the_arms_lag_is_named(setting):
    # with the measured start JTC's path tolerance is a safety net; below the arm's lag in
    # free motion JTC holds mid-path and the planner takes every path for blocked
    check, client, _ = setting
    check.poll()
    answer_all(client, {'interpolate_from_desired_state': False,
                        'constraints.lbr_A1.trajectory': 0.02})
    assert check.refusal(False) == ''
    assert check.below_lag({'lbr_A1': 0.2}) == 'lbr_A1 0.02 < 0.20'
    assert check.below_lag({'lbr_A1': 0.01}) == ''
    check.holds = {}                                        # 0: no tolerance, no hold
    assert check.below_lag({'lbr_A1': 0.2}) == ''


def test_either_start_parameter_true_is_the_desired_start(setting):
    # JTC (Jazzy) starts from its last command when either is true: one answered false and
    # the deprecated open_loop_control true still start there
    check, client, _ = setting
    check.poll()
    answer_all(client, {'interpolate_from_desired_state': False, 'open_loop_control': True,
                        'constraints.goal_time': 0.0})
    assert check.value is True and 'from its last command' in check.refusal(False)


def test_a_goal_time_and_whole_number_constraints_are_holds(setting):
    # a hold on the goal time is JTC's own hold as much as a path tolerance; a number the
    # node holds as an integer is a number all the same
    check, client, _ = setting
    check.poll()
    answer_all(client, {'interpolate_from_desired_state': True, 'constraints.goal_time': 0.5})
    assert check.holds == {'constraints.goal_time': 0.5}
    assert 'constraints.goal_time 0.5' in check.refusal(True)
    setting[2][0] += POLL
    check.poll()
    for future in list(client.calls):
        if future.name == 'cmd_timeout':
            future.answer(ParameterValue(type=ParameterType.PARAMETER_INTEGER,
                                         integer_value=2))
        elif future.name == 'interpolate_from_desired_state':
            future.answer(ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=True))
        else:
            future.answer(None)
    assert check.holds == {'cmd_timeout': 2.0}


def test_the_controller_is_asked_once_a_poll_period_and_believed_while_it_answers(setting):
    # asked at every tick of the node, the controller got a batch of calls every few ms;
    # a controller answering every period must stay known, and one that goes is unknown at once
    check, client, clock = setting
    assert check.first_answer_due()
    check.poll()
    answer_all(client, {'interpolate_from_desired_state': True, 'constraints.goal_time': 0.0})
    assert not check.first_answer_due()
    check.poll()
    assert client.calls == []                  # answered, and not due again yet
    for _ in range(4):                         # 4 periods, past 2.5: still answering
        clock[0] += POLL
        check.poll()
        assert check.value is True            # while asked again: still the last answer
        answer_all(client, {'interpolate_from_desired_state': True})
        assert check.value is True and check.refusal(True) == ''
    client.ready = False                       # the controller's node went
    check.poll()
    assert check.value is None and 'does not answer' in check.refusal(True)


def test_a_young_node_waits_for_the_controllers_first_answer_a_while_only(setting):
    check, _, clock = setting
    clock[0] += 2 * POLL - 0.1
    assert check.first_answer_due()
    clock[0] += 0.2
    assert not check.first_answer_due()


def test_a_controller_node_with_a_trailing_slash_or_none_at_all(monkeypatch):
    made = []
    node = SimpleNamespace(create_client=lambda kind, name: made.append(name) or Client())
    ControllerSetting(node, '/lbr/joint_trajectory_controller/', ['lbr_A1'])
    assert made == ['/lbr/joint_trajectory_controller/get_parameters']
    # '': the user opted out of the check: no client, never refused, never asked
    skipped = ControllerSetting(node, '', ['lbr_A1'])
    skipped.poll()
    assert len(made) == 1 and skipped.refusal(True) == '' and skipped.refusal(False) == ''
    assert not skipped.first_answer_due()
