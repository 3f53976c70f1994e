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
Methods: the method string parsed, and its planner built, in one place.

``probabilistic[:C_FAIL]``, ``hard:Y[:C_HARD]``, ``epsilon:X`` and ``informed[:IDEAS]``
name a method and its parameter everywhere (the CLI, the sweep, the robot experiment, the
planner node: :meth:`Method.for_node`).  A :class:`Method` knows the C_FAIL of the
map its loop learns (``probabilistic:C`` sets it; the others use the default) and builds
its planner: ProbRRT with an objective, or Epsilon, and its map and loop (the paper's, but
for ``informed``: :mod:`probdis_ros.planning.informed`, whose ideas are letters, e.g.
``informed:ab``).  A bare ``informed`` is the default ideas, and its string names them
(``informed:`` and ``DEFAULT_IDEAS``), so records never mix it with an older default.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from probdis_ros.model.arms import Arm, TaskSpace
from probdis_ros.model.failure_map import DEFAULT_C_FAIL, FailureMap
from probdis_ros.model.path_cost import DEFAULT_LENGTH_WEIGHT
from probdis_ros.planning.disentangle import Disentangler
from probdis_ros.planning.epsilon import DEFAULT_EPSILON, EpsilonPlanner
from probdis_ros.planning.informed import (
    check_ideas,
    DEFAULT_IDEAS,
    informed_loop,
    informed_map,
    informed_planner,
    LOCAL_REACH,
)
from probdis_ros.planning.objectives import (
    DEFAULT_THRESHOLD,
    FailureProbabilityObjective,
    HARD_C_FAIL,
    HardThresholdObjective,
)
from probdis_ros.planning.prob_rrt import ProbRRT, RRTSettings

METHODS = ('probabilistic', 'hard', 'epsilon', 'informed')
#: The method of the planner node, ``probdis sim`` and the robot experiment (README).
DEFAULT_METHOD = 'informed'
#: The informed ideas the planner node runs: the planner's own.  b, c and e change what the
#: map learns, and the node's map file keeps failures only (README "The failure map").
NODE_IDEAS = 'adfghij'
_USAGE = 'probabilistic[:C_FAIL], hard:Y[:C_HARD], epsilon:X, informed[:IDEAS]'


def _number(text: str, whole: str, low: float, high: float) -> float:
    try:
        number = float(text)
    except ValueError:
        raise ValueError(f'{whole!r}: {text!r} is not a number') from None
    if not (low < number <= high and math.isfinite(number)):
        raise ValueError(f'{whole!r}: {text} is outside ({low:g}, {high:g}] or not finite')
    return number


def _text(number: float) -> str:
    """Return a parameter as the method string writes it: short, and read back exactly."""
    text = repr(float(number))
    return text[:-2] if text.endswith('.0') else text


@dataclass(frozen=True)
class Method:
    """A method and its parameter: probabilistic[:C_FAIL], hard:Y[:C_HARD], epsilon:X, informed."""

    name: str
    value: float | None = None
    c_hard: float | None = None     # hard only: C_FAIL of its forbidden regions
    ideas: str | None = None        # informed only: its ideas' letters (None: the default's)

    def __post_init__(self) -> None:
        # a bare informed is today's default ideas, and says so (str: informed:IDEAS): the
        # default changed over time, and a record of an older default is another variant
        if self.name == 'informed' and self.ideas is None:
            object.__setattr__(self, 'ideas', DEFAULT_IDEAS)
        # the node's threshold 0 and epsilon 0 reached here as a bare name's values
        high = math.inf if self.name == 'probabilistic' else 1.0
        if self.value is not None and not 0 < self.value <= high:
            raise ValueError(f'{self.name} takes a parameter in (0, {high:g}], got '
                             f'{self.value}')

    @classmethod
    def parse(cls, text: str) -> Method:
        """Parse ``name[:value[:c_hard]]``; ValueError names what is wrong."""
        name, colon, rest = text.strip().partition(':')
        value, _, c_hard = rest.partition(':')
        if name not in METHODS:
            raise ValueError(f'unknown method {name!r} in {text!r} ({_USAGE})')
        if colon and not value and name in ('probabilistic', 'informed'):
            # 'probabilistic:' read as bare: a value meant and lost gave the default silently
            raise ValueError(f'{text!r}: an empty parameter ({_USAGE})')
        if name == 'informed':
            if c_hard:
                raise ValueError(f'{text!r}: only hard takes a second parameter ({_USAGE})')
            return cls(name, ideas=check_ideas(value) if value else None)
        if not value:
            if name != 'probabilistic':
                raise ValueError(f'{name} needs its parameter, e.g. {name}:0.01')
            return cls(name)
        if c_hard and name != 'hard':
            raise ValueError(f'{text!r}: only hard takes a second parameter ({_USAGE})')
        high = float('inf') if name == 'probabilistic' else 1.0
        return cls(name, _number(value, text, 0.0, high),
                   _number(c_hard, text, 0.0, float('inf')) if c_hard else None)

    @classmethod
    def from_parameters(cls, name: str, threshold: float = DEFAULT_THRESHOLD,
                        epsilon: float = DEFAULT_EPSILON, c_fail: float | None = None
                        ) -> Method:
        """Return the method of separate parameters (the node's, the CLI's flags)."""
        if name not in METHODS:
            raise ValueError(f'unknown method {name!r}; choose one of {", ".join(METHODS)}')
        value = {'probabilistic': c_fail, 'hard': threshold, 'epsilon': epsilon,
                 'informed': None}[name]
        return cls(name, None if value is None else float(value))

    @classmethod
    def for_node(cls, text: str, threshold: float = DEFAULT_THRESHOLD,
                 epsilon: float = DEFAULT_EPSILON) -> Method:
        """
        Return the method of the planner node's ``method`` parameter; ValueError if it cannot.

        A bare name takes Y and X from the node's ``threshold`` and ``epsilon``; a string
        with its parameter (``hard:0.02``, ``informed:adfhi``) is parsed as everywhere.
        """
        return cls.resolve(text, threshold, epsilon).checked_for_node()

    def checked_for_node(self) -> Method:
        """Return this method if the planner node can run it; ValueError naming why not."""
        if self.name == 'probabilistic' and self.value is not None:
            raise ValueError(f'{self}: the planner node takes C_FAIL from its c_fail parameter '
                             f'(method probabilistic, c_fail {_text(self.value)})')
        return self.checked_for_map_file('the planner node')

    def checked_for_map_file(self, planner: str) -> Method:
        """Return this method if it plans on a map file's failures alone; else ValueError."""
        foreign = sorted(set(self.idea_letters) - set(NODE_IDEAS))
        if foreign:
            raise ValueError(f'{self}: {planner} runs the informed ideas {NODE_IDEAS!r} only '
                             f'({", ".join(foreign)} change what the map learns, and its map '
                             'file keeps failures only)')
        return self

    @classmethod
    def resolve(cls, text: str, threshold: float = DEFAULT_THRESHOLD,
                epsilon: float = DEFAULT_EPSILON, c_fail: float | None = None) -> Method:
        """Return the method of a string (``hard:0.02``), or of a bare name and the values."""
        if ':' in text:
            return cls.parse(text)
        return cls.from_parameters(text.strip(), threshold, epsilon, c_fail)

    def __str__(self) -> str:
        if self.name == 'informed':
            return f'{self.name}:{self.idea_letters}'
        if self.value is None:
            return self.name
        text = f'{self.name}:{_text(self.value)}'
        return text if self.c_hard is None else f'{text}:{_text(self.c_hard)}'

    def map_c_fail(self, default: float = DEFAULT_C_FAIL) -> float:
        """Return the C_FAIL of the failure map the loop learns with this method."""
        return self.value if self.name == 'probabilistic' and self.value else default

    def objective(self, length_weight: float = DEFAULT_LENGTH_WEIGHT):
        """Return the objective the planner minimises (None for Epsilon: no search)."""
        if self.name == 'informed' and 'h' in self.idea_letters:
            return FailureProbabilityObjective(length_weight, LOCAL_REACH)
        if self.name in ('probabilistic', 'informed'):
            return FailureProbabilityObjective(length_weight)
        if self.name == 'hard':
            return HardThresholdObjective(
                DEFAULT_THRESHOLD if self.value is None else self.value,
                HARD_C_FAIL if self.c_hard is None else self.c_hard)
        return None

    def planner(self, arm: Arm, settings: RRTSettings | None = None,
                length_weight: float = DEFAULT_LENGTH_WEIGHT):
        """Return the planner of this method for an arm."""
        if self.name == 'epsilon':
            settings = settings or RRTSettings()
            return EpsilonPlanner(arm, DEFAULT_EPSILON if self.value is None else self.value,
                                  joint_margin=settings.joint_margin,
                                  joint_lower=settings.joint_lower,
                                  joint_upper=settings.joint_upper)
        if self.name == 'informed':
            return informed_planner(self.idea_letters, arm, settings,
                                    self.objective(length_weight))
        return ProbRRT(arm, settings, self.objective(length_weight))

    @property
    def idea_letters(self) -> str:
        """Return the informed method's ideas ('' for the other methods)."""
        if self.name != 'informed':
            return ''
        return DEFAULT_IDEAS if self.ideas is None else self.ideas

    def failure_map(self, task_space: TaskSpace, c_fail: float | None = None) -> FailureMap:
        """Return the empty map this method's loop learns (c_fail overrides its C_FAIL)."""
        c_fail = self.map_c_fail() if c_fail is None else c_fail
        if self.name == 'informed':
            return informed_map(self.idea_letters, task_space, c_fail)
        return FailureMap(task_space, c_fail)

    def disentangler(self, arm: Arm, planner, goal: np.ndarray, fmap: FailureMap,
                     **kwargs) -> Disentangler:
        """Return this method's loop (the paper's, but informed's also learns free motion)."""
        if self.name == 'informed':
            return informed_loop(arm, planner, goal, fmap, **kwargs)
        return Disentangler(arm, planner, goal, fmap, **kwargs)


def make_planner(method: str | Method, arm: Arm, settings: RRTSettings | None = None,
                 threshold: float = DEFAULT_THRESHOLD, epsilon: float = DEFAULT_EPSILON,
                 length_weight: float = DEFAULT_LENGTH_WEIGHT):
    """Return the planner of a method string (``hard:0.02``) or name with its parameter."""
    if isinstance(method, str):
        method = Method.resolve(method, threshold, epsilon)
    return method.planner(arm, settings, length_weight)
