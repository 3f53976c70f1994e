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

"""The failure probability model P(FAIL | c, F) and failure map files."""

import json
import math

import numpy as np
from probdis_ros.model import FailureMap, FailureMapError, TaskPoints, TaskSpace
import pytest

C_FAIL = 100.0


def point_map(*failures, task_space=TaskSpace.POINT2):
    fmap = FailureMap(task_space, C_FAIL)
    for failure in failures:
        fmap.add(*failure)
    return fmap


def prob(fmap, points, quats=None):
    return fmap.probability(TaskPoints(np.atleast_2d(points), quats))


def test_empty_map_gives_zero():
    assert (prob(point_map(), [[0.1, 0.2], [0.0, 0.0]]) == 0).all()


def test_high_beyond_the_failure_low_behind_it():
    fmap = point_map(([0.0, 0.0], [1.0, 0.0]))
    beyond = prob(fmap, [0.05, 0.0])[0]
    behind = prob(fmap, [-0.05, 0.0])[0]
    side = prob(fmap, [0.0, 0.05])[0]
    assert beyond == pytest.approx(1.0 / (1.0 + C_FAIL * 0.05**2))
    assert behind == pytest.approx(0.0, abs=1e-12)
    assert behind < side < beyond
    assert side == pytest.approx(0.5**3 / (1.0 + C_FAIL * 0.05**2))


def test_at_the_failure_point_the_probability_is_one():
    assert prob(point_map(([0.3, 0.1], [0.0, 2.0])), [0.3, 0.1])[0] == pytest.approx(1.0)


def test_falls_with_distance_as_inverse_quadratic():
    fmap = point_map(([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), task_space=TaskSpace.POINT3)
    d = np.linspace(0.01, 1.0, 50)
    points = np.column_stack([np.zeros_like(d), np.zeros_like(d), d])
    np.testing.assert_allclose(prob(fmap, points), 1.0 / (1.0 + C_FAIL * d**2), rtol=1e-12)


def test_a_reach_tapers_each_failure_to_zero_there():
    fmap = point_map(([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]), task_space=TaskSpace.POINT3)
    d = np.linspace(0.01, 0.5, 50)
    points = TaskPoints(np.column_stack([np.zeros_like(d), np.zeros_like(d), d]))
    taper = np.maximum(0.0, 1.0 - (d / 0.25) ** 2) ** 2
    np.testing.assert_allclose(fmap.probability(points, reach=0.25),
                               taper / (1.0 + C_FAIL * d**2), rtol=1e-12)
    assert (fmap.probability(points, reach=0.25)[d >= 0.25] == 0).all()
    np.testing.assert_array_equal(fmap.probability(points, reach=np.inf),
                                  fmap.probability(points))


def test_direction_is_normalised():
    slow = point_map(([0.0, 0.0], [0.001, 0.0]))
    fast = point_map(([0.0, 0.0], [50.0, 0.0]))
    points = np.random.default_rng(0).uniform(-0.3, 0.3, (100, 2))
    np.testing.assert_allclose(prob(slow, points), prob(fast, points))


def test_orthogonal_orientation_halves_it():
    """Quaternions 90 degrees apart on the unit sphere (a half-turn of the flange): D = 1."""
    fmap = FailureMap(TaskSpace.POSE3, C_FAIL)
    fmap.add([0, 0, 0], [1, 0, 0], [1, 0, 0, 0])
    point = [[0.05, 0.0, 0.0]]
    same = prob(fmap, point, np.array([[1.0, 0, 0, 0]]))[0]
    turned = prob(fmap, point, np.array([[0.0, 0, 0, 1.0]]))[0]
    half_way = prob(fmap, point, np.array([[np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]]))[0]
    assert turned == pytest.approx(0.5 * same)
    assert half_way == pytest.approx(0.75 * same)
    flipped = prob(fmap, point, np.array([[-1.0, 0, 0, 0]]))[0]
    assert flipped == pytest.approx(same)


def test_maximum_over_failures():
    a = ([0.0, 0.0], [1.0, 0.0])
    b = ([0.2, 0.1], [0.0, 1.0])
    points = np.random.default_rng(1).uniform(-0.5, 0.5, (500, 2))
    both = prob(point_map(a, b), points)
    np.testing.assert_allclose(both, np.maximum(prob(point_map(a), points),
                                                prob(point_map(b), points)))


def test_values_are_probabilities():
    rng = np.random.default_rng(2)
    fmap = FailureMap(TaskSpace.POSE3, C_FAIL)
    for _ in range(19):
        quat = rng.normal(size=4)
        fmap.add(rng.uniform(-1, 1, 3), rng.normal(size=3), quat)
    quats = rng.normal(size=(2000, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    p = prob(fmap, rng.uniform(-1, 1, (2000, 3)), quats)
    assert np.all((p >= 0) & (p <= 1)) and np.isfinite(p).all()


def test_bad_failures_are_refused():
    fmap = FailureMap(TaskSpace.POINT2)
    with pytest.raises(FailureMapError, match='nonzero'):
        fmap.add([0, 0], [0, 0])
    with pytest.raises(FailureMapError, match='length 2'):
        fmap.add([0, 0, 0], [1, 0, 0])
    with pytest.raises(FailureMapError, match='needs q'):
        FailureMap(TaskSpace.POSE3).add([0, 0, 0], [1, 0, 0])
    for c_fail in (-1, 0.0, math.inf, math.nan):      # inf: 0 everywhere but at a failure
        with pytest.raises(FailureMapError, match='c_fail'):
            FailureMap(TaskSpace.POINT2, c_fail=c_fail)
    for q in ([1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0, 0.0]):
        with pytest.raises(FailureMapError):
            FailureMap(TaskSpace.POSE3).add([0, 0, 0], [1, 0, 0], q)
    assert len(fmap) == 0


def test_save_and_load_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    fmap = FailureMap(TaskSpace.POSE3, 250.0)
    for _ in range(5):
        fmap.add(rng.normal(size=3), rng.normal(size=3), rng.normal(size=4))
    path = tmp_path / 'maps' / 'map.json'
    fmap.save(path)
    loaded = FailureMap.load(path)
    assert loaded.task_space is TaskSpace.POSE3 and loaded.c_fail == 250.0
    np.testing.assert_array_equal(loaded.points, fmap.points)
    np.testing.assert_array_equal(loaded.directions, fmap.directions)
    np.testing.assert_array_equal(loaded.orientations, fmap.orientations)
    assert [p.name for p in path.parent.iterdir()] == ['map.json']


def test_a_map_saved_through_a_symbolic_link_is_written_to_the_file_it_names(tmp_path):
    # renamed over, the link became a file of its own and the file it named was not written
    fmap = point_map(([0.0, 0.0], [1.0, 0.0]))
    target, link = tmp_path / 'maps' / 'arm.json', tmp_path / 'map.json'
    fmap.save(target)
    link.symlink_to(target)
    fmap.add([0.1, 0.0], [0.0, 1.0])
    fmap.save(link)
    assert link.is_symlink() and len(FailureMap.load(target)) == 2


def test_truncated_file_gives_a_clear_error(tmp_path):
    fmap = point_map(([0.0, 0.0], [1.0, 0.0]), ([0.1, 0.0], [0.0, 1.0]))
    path = tmp_path / 'map.json'
    fmap.save(path)
    text = path.read_text()
    path.write_text(text[: len(text) // 2])
    with pytest.raises(FailureMapError, match='truncated or corrupt'):
        FailureMap.load(path)


def test_corrupt_entries_never_give_a_half_loaded_map(tmp_path):
    doc = point_map(([0.0, 0.0], [1.0, 0.0])).to_dict()
    doc['failures'].append({'x': [0.1, 'a'], 'v': [1.0, 0.0], 'q': None})
    path = tmp_path / 'map.json'
    path.write_text(json.dumps(doc))
    with pytest.raises(FailureMapError, match='failure 1'):
        FailureMap.load(path)
    for bad, message in [({'format': 'other'}, 'not a probdis-failure-map'),
                         ({**doc, 'version': 99}, 'unsupported version'),
                         ({**doc, 'version': 0}, 'unsupported version'),
                         ({k: v for k, v in doc.items() if k != 'version'},
                          'unsupported version'),
                         ({**doc, 'c_fail': True}, 'c_fail must be a number'),
                         ({**doc, 'task_space': 'point7'}, 'unknown task_space'),
                         ({**doc, 'failures': {}}, 'must be a list'),
                         # a float overflowed (an OverflowError escaped and ended the node)
                         ({**doc, 'c_fail': 10 ** 400}, 'int too large'),
                         ({**doc, 'c_fail': -5}, r'map.json: c_fail must be a positive'),
                         ({**doc, 'failures': [{'x': [10 ** 400, 0.0], 'v': [1.0, 0.0],
                                                'q': None}]}, 'failure 0')]:
        path.write_text(json.dumps(bad))
        with pytest.raises(FailureMapError, match=message):
            FailureMap.load(path)
    with pytest.raises(FailureMapError, match='cannot read'):
        FailureMap.load(tmp_path / 'missing.json')
    path.write_text('[' * 100_000)      # a RecursionError escaped and ended the node
    with pytest.raises(FailureMapError, match='nested too deeply'):
        FailureMap.load(path)


def test_a_failure_is_added_whole_beside_a_reader_of_the_arrays():
    # the planner node learns a blocked retreat while a plan runs in another thread: the plan's
    # coster reads the three arrays, which must belong to the same failures (the compiled
    # kernels read the directions by the points' count, unchecked)
    fmap = FailureMap(TaskSpace.POSE3)
    fmap.add([0.5, 0.0, 0.3], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
    seen = fmap.arrays()
    fmap.add([0.6, 0.1, 0.3], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0])
    assert [len(a) for a in seen] == [1, 1, 1]          # a snapshot stays whole
    assert [len(a) for a in fmap.arrays()] == [2, 2, 2]
    assert np.array_equal(fmap.points, fmap.arrays()[0]) and len(fmap) == 2
    # and so does a copy (the node's markers, built beside the run in another thread)
    copy = fmap.copy()
    fmap.add([0.7, 0.1, 0.3], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0])
    assert len(copy) == 2 and len(fmap) == 3 and copy.c_fail == fmap.c_fail
