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
An arm that lets go of its command: blocks told from a driver that holds the arm.

A driver whose command guard holds the arm (``guard_holds``: it sends the measured
position) is tripped here at a random time per run (a joint's speed trips it on a real arm,
too rarely to measure by), on the physics family scenes of seeds SEED..SEED+WORLDS-1 (every
family), with five sets of the mock's faults, two trip times per scene and fault set,
``informed``, offline.  Each run goes twice: with the detector's let-go tests (an arm at
rest short of its command, one that coasts past a ceiling, a command that never moved an arm
pressing on nothing) and without them (every arm taken to press: the detector before them,
as without efforts; 2026-12-07 fourth session the first, fifth session all three).  Printed per
setting: the failures learned after the trip (none is real: the arm is held), the runs
stopped on an arm that let go, and at every gap block of an arm that moved, before the
trip, the torque it pressed toward its command with (``BlockDetector._pressing``; the test
needs 5 Nm, ``HELD_TORQUE_RISE``) and how many of them were called let go, and at every
retreat before the trip under which the arm never moved, the torque it pressed with either
way (on anything: the retreat's spring, the command before) and how many were called not
executed; and which
commands and tests the failures after the trip were learned on, with the test.
Usage: python results/let_go/let_go.py --seed 7000 --worlds 4   (the training worlds)
       python results/let_go/let_go.py --seed 9100 --worlds 4   (the evaluation worlds)
"""

import argparse
from collections import Counter
import math
from multiprocessing import Pool

import numpy as np
from probdis_ros.motion import detector
from probdis_ros.physics.episode import run_physics_episode
from probdis_ros.physics.family_scenes import family_scene_name
from probdis_ros.physics.simulated_robot import RobotSettings, SimulatedRobot, with_faults
from probdis_ros.run import RunSettings
from probdis_ros.sim.families import FAMILIES

FAULTS = ({}, {'command_latency': 0.2}, {'stiffness': 100.0},
          {'effort_noise': 1.0, 'noise': 1e-4}, {'joint_friction': 3.0})
TRIPS = 2                   # trip times per scene and fault set
TRIP_SPAN = (0.3, 8.0)      # [s, simulated] the trip's time is drawn from

_guard = SimulatedRobot._command_guard
_pressing = detector.BlockDetector._pressing
_gap_block = detector.BlockDetector._gap_block
_state: dict = {}


def _tripping_guard(robot: SimulatedRobot, sent: np.ndarray, moved: np.ndarray) -> str | None:
    if robot.engine.time >= _state['trip_at']:
        return 'tripped (this measurement)'
    return _guard(robot, sent, moved)


def _recorded_gap_block(self: detector.BlockDetector, reason: str) -> detector.Verdict:
    verdict = _gap_block(self, reason)
    if not _state['robot'].guard_trips and verdict is not detector.Verdict.MOVING:
        if self.started:
            _state['blocks'].append((_pressing(self), verdict is detector.Verdict.NOT_EXECUTED))
        elif not self.expect_motion:
            _state['retreats'].append((_pressing(self, either_way=True),
                                       verdict is detector.Verdict.NOT_EXECUTED))
    return verdict


def _build(original):
    def build(*args, **kwargs):
        robot, line = original(*args, **kwargs)
        _state['robot'] = robot
        return robot, line
    return build


def kind(why: str) -> str:
    """Return what a failure's reason says: a path's or a retreat's, and which test."""
    tests = (('has not moved', 'never moved'), ('ceiling', 'gap over a ceiling'),
             ('stalled', 'stall'), ('after the end', 'gap after the end'),
             ('torque', 'torque'))
    test = next((name for text, name in tests if text in why), why)
    return f'{"retreat" if why.startswith("retreat") else "path"}: {test}'


def one(job: tuple[str, dict, float, bool]) -> dict:
    """Run one scene with a trip at trip_at; let_go False: without the let-go test."""
    scene, faults, trip_at, let_go = job
    _state.update(trip_at=trip_at, blocks=[], retreats=[])
    # without: every arm presses (harder than any threshold), as the detector before it saw it
    detector.BlockDetector._pressing = _pressing if let_go else \
        (lambda self, either_way=False: math.inf)
    robot, physics = with_faults(faults, RobotSettings(seed=0, guard_holds=True))
    episode = run_physics_episode(scene, 'informed', seed=0, run_settings=RunSettings(),
                                  robot_settings=robot, physics_settings=physics,
                                  time_limit=120.0)
    return {'let_go': let_go, 'fault': next(iter(faults), 'none'),
            'after_trip': sum(f['t'] >= trip_at for f in episode.failures),
            'kinds': [kind(f['why']) for f in episode.failures if f['t'] >= trip_at],
            'stopped_let_go': 'let go of the command' in episode.message,
            'blocks': [(p, let) for p, let in _state['blocks'] if p is not None],
            'retreats': [(p, let) for p, let in _state['retreats'] if p is not None]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seed', type=int, required=True)
    parser.add_argument('--worlds', type=int, default=4)
    args = parser.parse_args()
    import probdis_ros.physics.episode as episode_module
    episode_module.build_robot = _build(episode_module.build_robot)
    SimulatedRobot._command_guard = _tripping_guard
    detector.BlockDetector._gap_block = _recorded_gap_block
    rng = np.random.default_rng(args.seed)
    trips = [(family_scene_name(family, seed), faults, float(rng.uniform(*TRIP_SPAN)))
             for family in FAMILIES for seed in range(args.seed, args.seed + args.worlds)
             for faults in FAULTS for _ in range(TRIPS)]
    # each trip twice, at the same time: without the test and with it
    jobs = [(*trip, let_go) for trip in trips for let_go in (False, True)]
    with Pool(2) as pool:
        results = pool.map(one, jobs, chunksize=1)
    print(f'{len(jobs) // 2} runs per setting, seeds {args.seed}..'
          f'{args.seed + args.worlds - 1}, each family\n')
    print('| fault | failures learned after the trip, without / with the test | '
          'runs learning any | runs stopped on an arm that let go (with) |')
    print('| --- | --- | --- | --- |')
    for fault in [next(iter(f), 'none') for f in FAULTS] + ['all']:
        rows = [r for r in results if fault in ('all', r['fault'])]
        cells = [[r for r in rows if r['let_go'] is let_go] for let_go in (False, True)]
        learned = [sum(r['after_trip'] for r in cell) for cell in cells]
        runs = [sum(r['after_trip'] > 0 for r in cell) for cell in cells]
        print(f'| {fault} | {learned[0]} / {learned[1]} | {runs[0]} / {runs[1]} | '
              f'{sum(r["stopped_let_go"] for r in cells[1])} |')
    kinds = Counter(k for r in results if r['let_go'] for k in r['kinds'])
    print('\nWith the test, the failures learned after the trip, by command and test: ' +
          ', '.join(f'{name} {count}' for name, count in kinds.most_common()))
    for key, what, how in (('blocks', 'gap blocks of an arm that moved', 'toward the command'),
                           ('retreats', 'retreats under which the arm never moved',
                            'either way, on the joints the retreat pulls')):
        blocks = [block for r in results if r['let_go'] for block in r[key]]
        pressing = np.array([p for p, _ in blocks] or [np.nan])
        print(f'\nWith the test, {what}, before the trip: {len(blocks)}; called let go or not '
              f'executed: {sum(let for _, let in blocks)}; pressing {how} [Nm, L1]: below 5 '
              f'in {int((pressing < 5).sum())}, lowest five '
              f'{np.round(np.sort(pressing)[:5], 1).tolist()}, median {np.median(pressing):.1f}')


if __name__ == '__main__':
    main()
