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
``probdis experiment sweep``: every (setting, obstacle count, world, method) episode on Dask.

Each episode is independent and reproducible from its key: the world seed depends only on
the sweep seed, the setting, the obstacle count and the world index, so every method meets
the same worlds; the loop is given the same seed, from which the world and the planner draw
independent streams (:mod:`probdis_ros.planning.seeds`).  Each record counts the paths that
were empty plans (a planner that found no feasible path, so the arm did not move). Finished
episodes are appended to ``episodes.jsonl`` at once (one JSON object per line, flushed and
synced); a rerun of the same command reads the file, drops a line cut short by a crash, and
runs only what is missing, so an interrupted sweep loses at most the episodes that were
running.  An episode that raises is recorded with its error (unsolved) and the sweep goes on.

Entanglement families (``--family``, :mod:`probdis_ros.sim.families`) run the same way; their
world ``w`` of a sweep of seed ``s`` is the family world of seed ``s + w``, so ``--seed 0
--worlds 100`` is the evaluation set (seeds 0-99) and ``--seed 1000`` a training set, and
the world seed is also the loop's seed (its planner stream is independent of the world's).

The scheduler is a LocalCluster of single-threaded worker processes by default, or any
running Dask scheduler (``--scheduler tcp://host:8786``): the work is plain functions of
plain arguments, so a lab cluster runs it unchanged.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
import json
import os
from pathlib import Path
import sys
import time
import zlib

from probdis_ros.planning.methods import Method

SETTINGS = ('2d', '3d', '3d-orient')
EPISODES_FILE = 'episodes.jsonl'


@dataclass(frozen=True)
class EpisodeKey:
    """One episode of a sweep; its world seed depends on everything but the method."""

    setting: str
    obstacles: int
    world: int
    method: str
    sweep_seed: int
    family: str = ''           # an entanglement family instead of a random setting world

    @property
    def world_seed(self) -> int:
        """Return the seed of the world and of the loop (their own streams of it)."""
        if self.family:
            return self.sweep_seed + self.world
        text = f'{self.sweep_seed}/{self.setting}/{self.obstacles}/{self.world}'
        return zlib.crc32(text.encode())

    @property
    def name(self) -> str:
        """Identify the episode: setting/obstacles/world/method, or family/world/method."""
        if self.family:
            return f'{self.family}/{self.world}/{self.method}'
        return f'{self.setting}/{self.obstacles}/{self.world}/{self.method}'


def episode_keys(settings: Iterable[str], obstacles: Iterable[int], worlds: int,
                 methods: Iterable[Method], seed: int) -> list[EpisodeKey]:
    """
    Return every episode of a sweep, world by world (so partial sweeps compare methods).

    Each once: a setting, count or method given twice (or spelled two ways) runs once.
    """
    return list(dict.fromkeys(EpisodeKey(s, n, w, str(m), seed) for s in settings
                              for n in obstacles for w in range(worlds) for m in methods))


def family_keys(families: Iterable[str], worlds: int, methods: Iterable[Method],
                seed: int) -> list[EpisodeKey]:
    """
    Return every episode of a family sweep: worlds of seeds seed..seed+worlds-1.

    World by world across the families, so that a partial sweep has as many worlds of each;
    each episode once, as :func:`episode_keys`.
    """
    from probdis_ros.sim.families import SETTING

    return list(dict.fromkeys(EpisodeKey(SETTING, 0, w, str(m), seed, family)
                              for w in range(worlds) for family in families for m in methods))


def run_episode_record(key: EpisodeKey, max_paths: int, rrt: dict | None = None) -> dict:
    """
    Run one episode (in a worker) and return its JSON record.

    An episode that raises does not stop the sweep: its record says so (``error``: the
    exception, ``success`` false, no paths) and counts as unsolved in the report; a rerun
    of the same command keeps it (it is done), another ``--out`` runs it again.
    """
    cpu0 = time.process_time()
    t0 = time.perf_counter()
    try:
        return _episode_record(key, max_paths, rrt, cpu0)
    except Exception as err:        # any failure of the episode: recorded, not raised
        return {**asdict(key), 'id': key.name, 'world_seed': key.world_seed,
                'success': False, 'paths': 0, 'failures': 0, 'empty_plans': 0,
                'max_paths': max_paths, 'plan_times_s': [], **({'rrt': rrt} if rrt else {}),
                'wall_s': time.perf_counter() - t0, 'cpu_s': time.process_time() - cpu0,
                'error': f'{type(err).__name__}: {err}'}


def _episode_record(key: EpisodeKey, max_paths: int, rrt: dict | None, cpu0: float) -> dict:
    """Run one episode and return its record (exceptions go to run_episode_record)."""
    from probdis_ros.planning.prob_rrt import RRTSettings
    from probdis_ros.sim.episode import run_episode

    method = Method.parse(key.method)
    world = _world(key.family or key.setting, key.obstacles, key.world_seed)
    t0 = time.perf_counter()
    result = run_episode(world, method, seed=key.world_seed, max_paths=max_paths,
                         settings=RRTSettings(**rrt) if rrt else None)
    return {**asdict(key), 'id': key.name, 'world_seed': key.world_seed,
            'success': result.success, 'paths': result.paths, 'failures': result.failures,
            'empty_plans': result.empty_plans,
            'max_paths': max_paths, 'plan_times_s': result.plan_times_s,
            **({'rrt': rrt} if rrt else {}),
            'wall_s': time.perf_counter() - t0, 'rejected_draws': world.rejected_draws,
            'world_obstacles': len(world.obstacles),
            # CPU time of the worker (world drawn here included): what the sweep costs
            # regardless of what else the machine was doing
            'cpu_s': time.process_time() - cpu0}


_WORLDS: dict = {}


def _world(setting: str, obstacles: int, seed: int):
    """Draw a world (of a setting or a family) once per worker process (methods share it)."""
    from probdis_ros.sim.families import FAMILIES, random_family_world
    from probdis_ros.sim.worlds import random_world

    key = (setting, obstacles, seed)
    if key not in _WORLDS:
        if len(_WORLDS) > 64:
            _WORLDS.clear()
        _WORLDS[key] = random_family_world(setting, seed) if setting in FAMILIES else \
            random_world(setting, obstacles, seed)
    return _WORLDS[key]


def read_episodes(path: Path, repair: bool = False) -> list[dict]:
    """
    Return the records of an episodes file (none if it does not exist).

    Every record is written as one line in one call, so only the last line can be cut short
    by a crash: it is ignored, and with ``repair`` cut off the file so that appending starts
    on a clean line.  A damaged line elsewhere is an error.
    """
    if not path.exists():
        return []
    data = path.read_bytes()
    end = data.rfind(b'\n') + 1
    records = []
    for number, line in enumerate(data[:end].splitlines(), start=1):
        if line.strip():
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError:
                raise ValueError(f'{path}: line {number} is not a JSON record') from None
    tail = data[end:]
    try:
        records.append(json.loads(tail))
        complete_tail = True
    except json.JSONDecodeError:
        complete_tail = False
    if repair and tail:
        with path.open('r+b') as stream:
            if complete_tail:
                stream.seek(0, os.SEEK_END)
                stream.write(b'\n')
            else:
                stream.truncate(end)
    return records


@dataclass
class SweepReport:
    """What a sweep call did."""

    total: int
    skipped: int
    ran: int
    seconds: float


def run_sweep(keys: list[EpisodeKey], out: Path, max_paths: int = 20,
              scheduler: str | None = None, workers: int | None = None,
              progress: Callable[[int, int, float], None] | None = None,
              rrt: dict | None = None) -> SweepReport:
    """
    Run the episodes of ``keys`` not yet in ``out/episodes.jsonl``; append each at once.

    ``rrt`` overrides fields of the planner's RRTSettings (``iterations``, ``plan_time``) for
    every episode (ablations; the paper's settings without); it is kept in each record, and
    a directory holds one sweep's settings only.
    """
    from dask.distributed import as_completed, Client, LocalCluster

    out.mkdir(parents=True, exist_ok=True)
    path = out / EPISODES_FILE
    records = read_episodes(path, repair=True)
    seeds = {keys[0].sweep_seed} if keys else set()
    for record in records:
        if {record.get('sweep_seed')} != seeds or record.get('max_paths') != max_paths or \
                record.get('rrt', {}) != (rrt or {}):
            raise ValueError(f'{path} holds episodes of another sweep (seed '
                             f'{record.get("sweep_seed")}, --max-paths '
                             f'{record.get("max_paths")}, planner '
                             f'{record.get("rrt", "defaults")}); use another --out')
    done = {r['id'] for r in records}
    todo = [k for k in keys if k.name not in done]
    t0 = time.monotonic()
    if not todo:
        return SweepReport(len(keys), len(keys), 0, 0.0)
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, dashboard_address=None, host='127.0.0.1')
        client = Client(cluster)
    # a shared scheduler keeps results by task key: another sweep's planner is another task
    planner = zlib.crc32(json.dumps(rrt or {}, sort_keys=True).encode())
    try:
        futures = [client.submit(run_episode_record, key, max_paths, rrt,
                                 key=f'episode-{key.name}-{key.sweep_seed}-{max_paths}-'
                                     f'{planner}',
                                 pure=False) for key in todo]
        with path.open('a') as stream:
            for finished, future in enumerate(as_completed(futures), start=1):
                record = future.result()
                stream.write(json.dumps(record) + '\n')
                stream.flush()
                os.fsync(stream.fileno())
                if 'error' in record:
                    # on a line of its own (over the progress bar, which is redrawn)
                    print(f'\rwarning: episode {record["id"]} failed ({record["error"]}); '
                          'recorded as unsolved', file=sys.stderr, flush=True)
                if progress:
                    progress(finished, len(todo), time.monotonic() - t0)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return SweepReport(len(keys), len(keys) - len(todo), len(todo), time.monotonic() - t0)


def progress_line(done: int, total: int, elapsed: float, unit: str = 'episodes') -> None:
    """Print ``[#####.....] done/total, elapsed, time left`` on one refreshed stderr line."""
    width = 30
    filled = int(width * done / total)
    left = elapsed / done * (total - done)
    end = '\n' if done == total else ''
    print(f'\r[{"#" * filled}{"." * (width - filled)}] {done}/{total} {unit}, '
          f'{_clock(elapsed)} elapsed, {_clock(left)} left ', end=end, file=sys.stderr,
          flush=True)


def _clock(seconds: float) -> str:
    minutes, secs = divmod(int(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f'{hours}:{minutes:02d}:{secs:02d}'
