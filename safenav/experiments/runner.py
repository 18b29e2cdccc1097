"""Running experiments: one episode from its spec, or many on a pool of processes with a progress bar.

Each process builds its own PyBullet client. The outcomes come back in the order of the
specs, whatever the number of workers, so the same specs give the same numbers.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import IO, Any

import numpy as np

from safenav._checks import integer
from safenav._optional import require
from safenav.episode import EpisodeConfig, EpisodeMetrics, Trajectory, run_episode
from safenav.experiments.specs import EpisodeSpec
from safenav.filters import make_filter
from safenav.scenarios import scenario, scenario_for
from safenav.sim_bullet import SimConfig
from safenav.worlds import World

__all__ = ["EpisodeOutcome", "Progress", "run_spec", "run_specs"]


@dataclass(frozen=True, eq=False)
class EpisodeOutcome:
    """One episode's spec and what happened.

    Attributes:
        spec: the episode.
        robot: the preset that ran it.
        world: the world it ran in (drawn from the spec's seed).
        metrics: the episode's metrics.
        trajectory: the per-step record when ``spec.record``, else ``None``.
        wall_time: wall-clock time of the episode [s].
    """

    spec: EpisodeSpec
    robot: str
    world: World
    metrics: EpisodeMetrics
    trajectory: Trajectory | None
    wall_time: float

    def collision_point(self) -> np.ndarray | None:
        """Where the base was when the body first touched an obstacle ``(x, y)`` [m]; ``None`` if it did not
        or the episode was not recorded."""
        if self.trajectory is None or self.metrics.collision_time is None:
            return None
        index = int(np.searchsorted(self.trajectory.time, self.metrics.collision_time - 1e-9))
        return self.trajectory.pose[min(index, len(self.trajectory.pose) - 1), :2]


def run_spec(spec: EpisodeSpec) -> EpisodeOutcome:
    """Run one episode from its spec (in this process, with its own simulator)."""
    task = scenario_for(spec.scenario, spec.robot, spec.policy)
    robot = task.robot
    world = task.world(spec.seed)
    policy = task.policy(spec.policy, world, spec.seed)
    sim = SimConfig(gui=spec.gui, **dict(spec.sim_options))
    config = EpisodeConfig(duration=task.duration if spec.duration is None else spec.duration, sim=sim)
    safety_filter = make_filter(spec.filter, robot, sim.control_dt, **dict(spec.filter_options))
    start = time.perf_counter()
    result = run_episode(world, robot, policy, safety_filter, config=config, seed=spec.seed,
                         record=spec.record or spec.record_scans, record_scans=spec.record_scans)
    return EpisodeOutcome(spec, robot.name, world, result.metrics, result.trajectory, time.perf_counter() - start)


def _cost(spec: EpisodeSpec) -> float:
    """A rough relative cost, to start the longest episodes first (a shorter tail)."""
    duration = scenario(spec.scenario).duration if spec.duration is None else spec.duration
    return duration * {"none": 0.5, "mpc": 3.0}.get(spec.filter, 1.0)


class Progress:
    """Counts finished episodes on a stream: a tqdm bar on a terminal, plain lines otherwise.

    Written to a file or a pipe (a log, CI), a bar would be one long line of carriage
    returns; there it prints ``description: done/total (percent), elapsed`` at every tenth.

    Args:
        total: episodes to count.
        description: the label.
        stream: where to write (standard error by default).
        enabled: ``False`` writes nothing.
    """

    def __init__(self, total: int, description: str, stream: IO[str] | None = None, enabled: bool = True) -> None:
        self.total = total
        self.description = description
        self.stream = sys.stderr if stream is None else stream
        self.done = 0
        self._start = time.perf_counter()
        self._bar: Any = None
        self._enabled = enabled and total > 0
        if self._enabled and _is_terminal(self.stream):
            tqdm = require("tqdm", extra="sim", purpose="the progress bar of safenav.experiments").tqdm
            self._bar = tqdm(total=total, desc=description, unit="ep", file=self.stream, dynamic_ncols=True)

    def update(self) -> None:
        """One more episode finished."""
        self.done += 1
        if self._bar is not None:
            self._bar.update()
        elif self._enabled and math.floor(10 * self.done / self.total) > math.floor(10 * (self.done - 1) / self.total):
            elapsed = time.perf_counter() - self._start
            print(f"{self.description}: {self.done}/{self.total} ({100 * self.done / self.total:.0f} %), "
                  f"{elapsed:.0f} s", file=self.stream, flush=True)

    def close(self) -> None:
        """Finish the bar (plain lines need no closing)."""
        if self._bar is not None:
            self._bar.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _is_terminal(stream: IO[str]) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):   # no isatty, or closed
        return False


def run_specs(specs: Sequence[EpisodeSpec], workers: int | None = None, *, progress: bool = True,
              description: str = "episodes") -> list[EpisodeOutcome]:
    """Run every spec, on ``workers`` processes, with progress on standard error.

    Each episode depends only on its spec, so the outcomes do not depend on the number of
    workers or on the order in which they finish. The specs were checked when they were made
    (:class:`EpisodeSpec`); an episode that fails anyway fails the run, and the queued ones
    are not started.

    Args:
        specs: the episodes.
        workers: processes (``None``: one per core; 1 runs in this process).
        progress: show the progress (:class:`Progress`: a bar on a terminal, plain lines otherwise).
        description: the progress label.

    Returns:
        The outcomes, in the order of ``specs``.

    Raises:
        InvalidConfig: ``workers`` is not an integer >= 1.
    """
    workers = (os.cpu_count() or 1) if workers is None else integer("workers", workers, low=1)
    outcomes: list[EpisodeOutcome | None] = [None] * len(specs)
    with Progress(len(specs), description, enabled=progress) as bar:
        if workers == 1 or len(specs) <= 1:
            for index, spec in enumerate(specs):
                outcomes[index] = run_spec(spec)
                bar.update()
        else:
            order = sorted(range(len(specs)), key=lambda i: -_cost(specs[i]))
            with ProcessPoolExecutor(max_workers=min(workers, len(specs))) as pool:
                futures = {pool.submit(run_spec, specs[index]): index for index in order}
                try:
                    for future in as_completed(futures):
                        outcomes[futures[future]] = future.result()
                        bar.update()
                except BaseException:
                    # An episode failed or the user pressed Ctrl-C: do not start the queued ones.
                    pool.shutdown(wait=True, cancel_futures=True)
                    raise
    return [outcome for outcome in outcomes if outcome is not None]
