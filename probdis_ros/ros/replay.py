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
``probdis replay``: rerun the blocked-motion detector on a recorded bag.

Any rosbag2 bag (MCAP or sqlite3, metadata v8 or v9, written by probdis or by
``ros2 bag record`` on the real arm) with joint states and commanded trajectories: the same
detector as the live planner (:class:`probdis_ros.motion.detector.BlockDetector`) judges every
command against the joint states that followed it, and every block becomes a failure, so the
failure map is rebuilt exactly as the planner built it.  Joint states pass the planner's
gate (:class:`probdis_ros.motion.state_check.StateCheck`) and are dated as it dates them, by
their stamps on the recording's clock, so a bag from ``ros2 bag record`` on a busy machine,
whose states arrived in bursts, is judged as the planner judged it.  No rclpy: bags are read by
:mod:`probdis_ros.ros.bag_source` (rosbags, and record by record for a damaged MCAP file).

Commands are classified like the planner sends them: a one-point command at the measured
position is a hold, the first motion after a block is the retreat, every other motion is a
planned path.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
import json
from pathlib import Path

import numpy as np
from probdis_ros.model import FailureMap, iiwa_arm
from probdis_ros.motion.cartesian_speed import point_speeds
from probdis_ros.motion.detector import (
    BlockDetector,
    DetectorSettings,
    ExternalTorqueObserver,
    StateStream,
    Verdict,
)
from probdis_ros.motion.jtc import (
    JTC_STARTS,
    JtcTrajectory,
    moved_onto_clock,
    taken_trajectory,
)
from probdis_ros.motion.profiles import edge_reached
from probdis_ros.motion.state_check import StateCheck, values_by_name
from probdis_ros.planning.disentangle import failure_from_block
from probdis_ros.ros import JOINT_NAMES, JOINT_STATES_TOPIC, TRAJECTORY_TOPIC
from probdis_ros.ros.bag_source import Bag, BagError
from probdis_ros.ros.messages import (
    BadJointStateError,
    command_from_msg,
    stamp_seconds,
)
from probdis_ros.ros.recorder import RECORDING_SUFFIX

FINISHED = ('succeeded', 'gave_up', 'stopped')
JOINT_STATE_TYPE = 'sensor_msgs/msg/JointState'
TRAJECTORY_TYPE = 'trajectory_msgs/msg/JointTrajectory'
#: [s] a state the planner recorded within this of the time the replay dates it at was dated
#: alike (rounding); beyond it, the planner knew a delivery the bag does not show (a rise of
#: the clocks' offset, DRIFT_NOISE 1e-4 s or more), and its time is the one recorded
REDATING_TOLERANCE = 1e-5
#: The motion delays ``probdis replay --calibrate`` tries [s]: 0 to 0.4 s by 0.01 s (an arm
#: in joint impedance at 200 Nm/rad lagged its command by up to 0.24 s on the physics mock)
CALIBRATION_DELAYS = tuple(round(0.01 * k, 2) for k in range(41))
#: Peak gaps within this [rad], or this share of the least, are as good as the least
EQUAL_GAP, EQUAL_SHARE = 0.001, 0.02


class ReplayError(Exception):
    """A bag that cannot be replayed (with what was readable before the problem)."""

    def __init__(self, message: str, partial: ReplayResult | None = None) -> None:
        super().__init__(message)
        self.partial = partial


class SettingsError(ValueError):
    """Detector overrides that do not fit (the defaults, or the settings the bag recorded)."""


def detector_settings(recorded: dict, overrides: dict) -> DetectorSettings:
    """
    Return the recorded detector settings changed by overrides.

    A recording that cannot be used is the bag's problem (ValueError); overrides that do
    not fit it are the caller's (:class:`SettingsError`), not damage of the bag.
    """
    settings = DetectorSettings(**recorded)
    try:
        return replace(settings, **overrides)
    except (TypeError, ValueError) as err:
        raise SettingsError(str(err)) from None


@dataclass
class Block:
    """
    A detected block: time since the bag's start [s], configuration, flange, retreat or not.

    ``retreat``: it stopped a retreat (else a path).  Which edge of the planned path it began
    on is the live run's to say: the message holds the timed motion, not the via points it
    was timed from.
    """

    t: float
    config: np.ndarray
    x: np.ndarray
    retreat: bool = False


@dataclass
class ReplayResult:
    """What the detector found in a bag."""

    runs: int = 0
    paths: int = 0
    success: bool = False
    blocks: list[Block] = field(default_factory=list)
    fmap: FailureMap | None = None
    times: list[float] = field(default_factory=list)
    gaps: list[float] = field(default_factory=list)
    configs: list[np.ndarray] = field(default_factory=list)
    velocities: list[np.ndarray | None] = field(default_factory=list)   # as reported
    problems: list[str] = field(default_factory=list)
    settings: DetectorSettings | None = None    # what the detector ran with
    # per joint, the largest external torque estimated (ExternalTorqueObserver, load data
    # as recorded) until the run ended [Nm]; None: no efforts
    torque_peak: np.ndarray | None = None
    # (time, that estimate) at every joint state that carries efforts, for the plot
    torques: list[tuple[float, np.ndarray]] = field(default_factory=list)
    # the largest L1 gap [rad] with which a command ended done, the arm at rest: what friction
    # and model error leave on the arm; a free path ending above d_dist reads as blocked
    rest_gap: float = 0.0

    @property
    def peak_gap(self) -> float:
        """
        Return the largest L1 gap [rad] between the arm and its command, ``motion_delay`` before.

        On a bag of free motion, the ``motion_delay`` that gives the least is the arm's lag.
        """
        return max(self.gaps, default=0.0)

    @property
    def peak_point_speed(self) -> float:
        """
        Return the fastest [m/s] any point of the arm moved (URDF collision shapes, flange).

        What KUKA's Cartesian speed monitoring would compare with its limit (T1: README
        "Pointing it at the real arm"), from the joint states' velocities, or the slope of
        their positions where a state carries none.
        """
        if len(self.configs) < 2:
            return 0.0
        q, t = np.array(self.configs), np.array(self.times)
        slope = np.zeros_like(q)
        slope[1:] = np.diff(q, axis=0) / np.maximum(np.diff(t), 1e-9)[:, None]
        v = np.array([slope[k] if v is None else v for k, v in enumerate(self.velocities)])
        return float(point_speeds(iiwa_arm(), q, v).max())

    def summary(self) -> dict:
        """Return the JSON summary of ``probdis replay --json``."""
        return {'paths': self.paths,
                'blocks': [{'t': b.t, 'x': b.x.tolist(), 'retreat': b.retreat}
                           for b in self.blocks],
                'failures': len(self.fmap) if self.fmap is not None else 0,
                'success': self.success, 'peak_gap_rad': self.peak_gap,
                'rest_gap_rad': self.rest_gap,
                'peak_point_speed_mps': self.peak_point_speed,
                'peak_external_torque_nm': None if self.torque_peak is None else
                [round(float(t), 1) for t in self.torque_peak]}


def replay(bag: str | Path, joint_states_topic: str = JOINT_STATES_TOPIC,
           trajectory_topic: str = TRAJECTORY_TOPIC, joint_names: list[str] | None = None,
           settings: DetectorSettings | None = None, orientation: bool = True,
           overrides: dict | None = None) -> ReplayResult:
    """
    Replay a bag; raise ReplayError (carrying the partial result) on a damaged bag.

    The detector runs with settings, or else with those the recording planner ran with (its
    status carries them) or the defaults, changed by overrides (e.g. ``{'d_dist': 0.1}``):
    :class:`SettingsError` if they do not fit, before the bag is read where the defaults
    already refuse them.
    """
    if settings is None:
        detector_settings({}, overrides or {})
    arm = iiwa_arm(with_orientation=orientation)
    result = ReplayResult(fmap=FailureMap(arm.task_space))
    try:
        source = Bag(bag)
    except BagError as err:
        raise ReplayError(str(err)) from None
    with source:
        for topic, msgtype in ((joint_states_topic, JOINT_STATE_TYPE),
                               (trajectory_topic, TRAJECTORY_TYPE)):
            if topic not in source.topics and source.damage:
                raise ReplayError(f'{bag}: {source.damage}', _finish(result))
            if topic not in source.topics:
                raise ReplayError(f'{bag}: no {topic} topic (the bag has '
                                  f'{", ".join(sorted(source.topics)) or "no topics"})')
            if source.topics[topic] != msgtype:
                raise ReplayError(f'{bag}: {topic} carries {source.topics[topic]}, '
                                  f'not {msgtype}')
        if source.notice:
            result.problems.append(source.notice)
        status, dated = _planner_status(source, result.problems)
        # the arm's names as the commands give them (a robot_name other than lbr's)
        names = list(joint_names or _commanded_names(source, trajectory_topic) or JOINT_NAMES)
        try:
            _run(source, [joint_states_topic, trajectory_topic, *status], trajectory_topic,
                 status, dated, names, arm, settings, result, source.start_ns * 1e-9,
                 overrides or {})
        except BagError as err:
            raise ReplayError(f'{bag}: {err}', _finish(result)) from None
        except SettingsError:
            raise
        except Exception as err:
            raise ReplayError(f'{bag}: damaged bag after {len(result.times)} joint states '
                              f'({err})', _finish(result)) from None
        if source.damage:
            raise ReplayError(f'{bag}: {source.damage}', _finish(result))
        if not result.times and source.count([joint_states_topic]):
            refused = next((p for p in result.problems if 'joint state refused' in p), '')
            raise ReplayError(f'{bag}: every joint state was refused ({refused}); joints named '
                              f'{", ".join(names)}')
    return _finish(result)


def _commanded_names(source: Bag, trajectory_topic: str) -> list[str] | None:
    """Return the joint names of the first command in the bag (None: none usable)."""
    for message in source.messages([trajectory_topic]):
        try:
            names = list(source.deserialize(message).joint_names)
        except BagError:
            return None
        return names if len(set(names)) == len(JOINT_NAMES) == len(names) else None
    return None


def _finish(result: ReplayResult) -> ReplayResult:
    """Count a recording without status messages (the real arm's) as one run."""
    if result.runs == 0 and result.paths:
        result.runs = 1
    return result


def _planner_status(source: Bag, problems: list[str]) -> tuple[set[str], bool]:
    """
    Return the recording planner's status topic (or none) and whether it made the bag.

    A planner's own bag says so (``<node>/recording``, naming its status topic): its joint
    states are dated as the planner dated them.  Another recorder's holds receive times,
    and may hold the statuses of other planners too (``ros2 bag record -a`` in a cell of two
    arms, whose other "succeeded" ended this arm's run): one status is taken, several none.
    """
    strings = {t for t, m in source.topics.items() if m == 'std_msgs/msg/String'}
    for marker in sorted(t for t in strings if t.endswith(RECORDING_SUFFIX)):
        for message in source.messages([marker]):
            try:
                named = json.loads(source.deserialize(message).data).get('status')
            except (BagError, ValueError, AttributeError):
                break
            if named in strings:
                return {named}, True
            break
    status = {t for t in strings if t.endswith('/probdis_planner/status')}
    if len(status) > 1:
        problems.append(f'statuses of {len(status)} planners recorded ({", ".join(sorted(status))}'
                        f'): runs are told from the commands alone')
        return set(), False
    return status, False


def _run(source: Bag, topics: list[str], trajectory_topic: str, status_topics: set[str],
         dated: bool, names: list[str], arm, given: DetectorSettings | None, result: ReplayResult,
         t0: float, overrides: dict) -> None:
    # the detector the live planner ran (its status carries it), unless the caller chose one
    settings = result.settings = given or detector_settings({}, overrides)
    observer = ExternalTorqueObserver(settings)         # the live run's estimate
    state_stream = StateStream()                        # ... and the states' stream
    states = StateCheck(names, arm.lower, arm.upper, arm.velocity_limits)
    limits = (arm.lower, arm.upper)
    measured = None
    measured_velocity = None
    early = None               # a command recorded before the first joint state
    detector = None
    kind = ''
    after_block = False
    pressed = False            # the last motion ended blocked: the next may not move at all
    last_path_done = False
    ended = False              # the planner said the run is over: what follows is its stop
    status_paths: list[int] = []
    previous = None            # the state of the last status message
    jtc_start = 'measured'     # where JTC starts a command, as the live planner modelled it
    running = None             # the last command as JTC ran it, and when it was sent
    # the planner records each state at the time it dated it (its stamp moved by the
    # stream's quickest delivery as the node knew it, from long before the bag began):
    # where a re-dating from the bag alone differs beyond rounding (by a millisecond once: a
    # live block at a gap 3e-5 rad past its ceiling was missed), that recorded time is the
    # detector's; other recorders' bags hold receive times, dated as the planner dates them
    offset = 0.0               # the recording's clock less the arm's (stamped commands)
    for message in source.messages(topics):
        t = message.stamp_ns * 1e-9 - t0
        msg = source.deserialize(message)
        if message.topic in status_topics:
            state = json.loads(msg.data)
            if given is None and isinstance(state.get('detection'), dict):
                known = {f.name for f in fields(DetectorSettings)}
                recorded = {k: v for k, v in state['detection'].items() if k in known}
                settings = result.settings = observer.settings = \
                    detector_settings(recorded, overrides)
            if state.get('jtc_start') in JTC_STARTS:
                jtc_start = state['jtc_start']
            starting = state.get('state') == 'planning' and state.get('paths') == 0
            if starting and (previous is None or previous in FINISHED or previous == 'idle'):
                result.runs += 1
                status_paths.append(0)
            previous = state.get('state')
            if status_paths:           # the last word of a run (a withdrawn plan lowers it)
                status_paths[-1] = int(state.get('paths', 0))
            ended = state.get('state') in FINISHED
            if ended and state.get('state') != 'succeeded':
                # given up or stopped, the live run judged nothing after: its last command
                # was the stop (a path's end it had judged at a state before the status,
                # which the replay may judge a state later: kept)
                detector, kind = None, 'hold'
            continue
        if message.topic == trajectory_topic:
            try:
                command = command_from_msg(msg, names)
            except ValueError as err:
                result.problems.append(f'{t:.3f} s: command refused: {err}')
                continue
            if measured is None:       # JTC starts it from the first state it reads
                early = (t, command)   # (its stamp moved by the offset that state shows)
                continue
            command = moved_onto_clock(command, offset - t0)    # on the recording's clock
            if command is None:
                result.problems.append(f'{t:.3f} s: command refused: stamped, it ends in the past')
                continue
            last = None
            if jtc_start == 'desired' and running is not None:
                last = running[0].sample(t - running[1])
            timed = taken_trajectory(command, t, measured, measured_velocity, last)
            running = (timed, t)
            pressed_start = None
            if last is not None and np.abs(last[0] - measured).sum() > settings.d_dist:
                pressed_start = (last[0], measured.copy())
            if ended or (len(timed.points) == 2 and
                         np.abs(timed.points[1] - measured).sum() <= settings.d_dist):
                detector, kind = None, 'hold'       # a hold or the stop that ends a run
                continue
            if after_block:
                kind, after_block = 'retreat', False
            else:
                kind = 'path'
                result.paths += 1
                last_path_done = False
            # as the live run: a path from a free arm must move it (one the controller takes
            # late is judged from when it began)
            detector = BlockDetector(timed, t, settings, expect_motion=kind == 'path' and
                                     not pressed and pressed_start is None,
                                     pressed_start=pressed_start, limits=limits,
                                     stream=state_stream)
            continue
        # the live planner's gate, and its dating: by stamp on the recording's clock
        received, stamp = t + t0, stamp_seconds(msg)
        try:
            q, v = states.check(received, msg.name, msg.position, msg.velocity, stamp)
        except BadJointStateError as err:
            result.problems.append(f'{t:.3f} s: joint state refused: {err}')
            continue
        redated = states.measured_at(received, stamp) - t0
        if not dated or abs(t - redated) <= REDATING_TOLERANCE:
            t = redated                # as the planner computed it, to the last bit
        offset = states.clock_offset + (t - redated)
        measured, measured_velocity = q, v
        state_stream.add(t)
        if early is not None:
            sent, command = early
            command, early = moved_onto_clock(command, offset - t0), None
            if command is None:
                result.problems.append(f'{sent:.3f} s: command refused: stamped, it ends in '
                                       f'the past')
            else:
                running = (JtcTrajectory(command, q, measured_velocity, sent), sent)
                # a path from a free arm, as the live run's first one
                detector, kind = (BlockDetector(running[0], sent, settings, expect_motion=True,
                                                limits=limits, stream=state_stream),
                                  'path')
                result.paths += 1
                result.problems.append(f'{sent:.3f} s: command before any joint state: '
                                       f'started from the first one, at {t:.3f} s')
        result.times.append(t)
        result.configs.append(q)
        result.velocities.append(v)
        # the measured torques, where the driver sends them (the torque ceiling's estimate);
        # the peak, as the live run's, while the run drives the arm
        effort = values_by_name(msg.name, msg.effort, names)
        external = None if effort is None else observer.update(t, q, v, effort)
        if external is not None:
            result.torques.append((t, external))
        if external is not None and not ended:
            pushed = np.abs(external)
            result.torque_peak = pushed if result.torque_peak is None else \
                np.maximum(result.torque_peak, pushed)
        if detector is None:
            result.gaps.append(0.0)
            continue
        verdict = detector.update(t, q, external, observer.static)
        result.gaps.append(detector.gap)
        if verdict is not Verdict.MOVING:
            pressed = verdict is Verdict.BLOCKED
        if verdict is Verdict.DONE:
            if kind == 'path':
                last_path_done = True
            result.rest_gap = max(result.rest_gap, detector.gap)
            detector = None
        elif verdict is Verdict.NOT_EXECUTED:
            result.problems.append(f'{t:.3f} s: {detector.reason}: nothing executed the command')
            detector = None
            # the live run stops here: its next command is the stop, recorded before the
            # status that says so (taken for a new path, a stop that ran to its end was
            # counted as a path done: a run stopped live replayed as disentangled)
            ended = True
        elif verdict is Verdict.BLOCKED:
            # the live run's rule: the failure is where the block began, moving the way the
            # command moved then; a blocked retreat is a block too
            onset = detector.onset
            config = onset.config if onset is not None else q
            when = onset.time if onset is not None else t
            # on the edge of the command the arm was on (Motion.edge_reached): its samples'
            points = detector.path.points
            latest = detector.path.segment_at(when - detector.start_time)
            segment = edge_reached(points, config, latest)
            direction = onset.velocity if onset is not None and segment == latest else \
                np.zeros_like(q)
            if not np.any(direction):
                direction = points[segment + 1] - points[segment]
            detector = None
            if not np.any(direction):
                continue
            x, v, quat = failure_from_block(arm, config, direction)
            result.fmap.add(x, v, quat)
            result.blocks.append(Block(t, config.copy(), x, retreat=kind == 'retreat'))
            after_block = kind == 'path'
    if status_paths:
        result.paths = sum(status_paths)
    result.success = last_path_done


@dataclass
class Calibration:
    """
    The peak gap of a free move at each motion delay tried, and the delay that fits best.

    ``best``: of the delays at which the bag reads as one free move (one path, no block),
    the one with the least peak gap, the arm's own lag (README, "Pointing it at the real arm",
    step 4); where the delays about it give gaps as small (``equal``), their middle.
    """

    delays: list[float]
    peak_gaps: list[float]
    blocks: list[int]
    best: float
    equal: tuple[float, float]   # the delays about the least gap with gaps as good [s]
    rest_gap: float          # the largest gap at rest after a command at the best delay [rad]
    d_dist: float

    @property
    def best_gap(self) -> float:
        """Return the peak gap at the best delay [rad]."""
        return self.peak_gaps[self.delays.index(self.best)]

    def summary(self) -> dict:
        """Return the JSON summary of ``probdis replay --calibrate --json``."""
        return {'motion_delay_s': self.best, 'peak_gap_rad': self.best_gap,
                'equally_good_s': list(self.equal), 'rest_gap_rad': self.rest_gap,
                'd_dist_rad': self.d_dist,
                'tried': [{'motion_delay_s': d, 'peak_gap_rad': g, 'blocks': b}
                          for d, g, b in zip(self.delays, self.peak_gaps, self.blocks)]}


def calibrate(bag: str | Path, joint_states_topic: str = JOINT_STATES_TOPIC,
              trajectory_topic: str = TRAJECTORY_TOPIC, overrides: dict | None = None,
              delays: tuple[float, ...] = CALIBRATION_DELAYS,
              progress=None) -> Calibration:
    """
    Replay a bag of a free move at each of delays; raise ReplayError where it cannot tell.

    One replay per delay, with the detector's other settings as recorded (or overrides);
    ``progress(done, total)`` is called after each.  A bag without a path, or that is not one
    free move (one path, no block) at any delay, tells no delay.
    """
    results = []
    for k, delay in enumerate(delays):
        results.append(replay(bag, joint_states_topic, trajectory_topic,
                              overrides={**(overrides or {}), 'motion_delay': delay}))
        if progress is not None:
            progress(k + 1, len(delays))
    if not any(r.paths for r in results):
        raise ReplayError(f'{bag}: no path in the bag: record a free move of the arm '
                          f'(one path to a goal with nothing in reach)')
    # one path and no block: a block the detector sees at a short delay goes unseen at a
    # long one (the retreat then reads as a second path), and its gap is no lag
    free = [k for k, r in enumerate(results) if not r.blocks and r.paths == 1]
    if not free:
        raise ReplayError(
            f'{bag}: not one free move at any motion_delay from {delays[0]:g} to '
            f'{delays[-1]:g} s (a block, or more than one path): record one path to a goal '
            f'with nothing in reach; where the live run called it blocked, record it again '
            f'with a longer motion_delay (0.3 s); or d_dist is below what the arm keeps at rest')
    least = min(free, key=lambda k: results[k].peak_gap)
    # delays about the least whose gaps tell nothing apart (an arm that lags like a filter,
    # not a pure delay, has a flat bottom): the middle, since an arm lagging more than
    # motion_delay is what the detector may call blocked (README, the allowance)
    near = results[least].peak_gap + max(EQUAL_GAP, EQUAL_SHARE * results[least].peak_gap)
    low = high = least
    while low - 1 in free and results[low - 1].peak_gap <= near:
        low -= 1
    while high + 1 in free and results[high + 1].peak_gap <= near:
        high += 1
    best = (low + high) // 2
    return Calibration(list(delays), [r.peak_gap for r in results],
                       [len(r.blocks) for r in results], delays[best],
                       (delays[low], delays[high]), results[best].rest_gap,
                       results[best].settings.d_dist)
