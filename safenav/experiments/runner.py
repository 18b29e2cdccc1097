"""Running experiments: one episode from its spec, or many on a pool of processes or a Ray cluster.

Each process builds its own PyBullet client. The outcomes come back in the order of the
specs, whatever the number of workers and the backend, so the same specs give the same numbers.

Backends (:data:`BACKENDS`):

* ``"process"`` (default, no extra): a local :class:`~concurrent.futures.ProcessPoolExecutor`.
* ``"ray"`` (``pip install "safenav[distributed]"``): every episode a Ray task, results streamed
  back as they finish. ``address=None`` starts a local Ray with ``workers`` CPUs (or uses the Ray
  already initialised in this process); ``address="auto"`` joins the cluster this machine belongs
  to (``ray start --head`` on one machine, ``ray start --address=HEAD:6379`` on the others), and
  ``"ray://HEAD:10001"`` connects a remote client. Every node needs safenav (same version) and
  its extras installed: Ray ships the task, not the library.

:func:`run_jobs` runs any picklable function over any items the same way; :func:`run_specs` is it
applied to :func:`run_spec`.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import IO, Any, TypeVar

import numpy as np

from safenav._checks import argument_type, choice, integer
from safenav._optional import require
from safenav.episode import EpisodeConfig, EpisodeMetrics, Trajectory, run_episode
from safenav.errors import InvalidConfig
from safenav.experiments.specs import EpisodeSpec
from safenav.filters import ESCAPE_SUFFIX, make_filter
from safenav.scenarios import scenario, scenario_for
from safenav.sim_bullet import SimConfig
from safenav.worlds import World

__all__ = ["BACKENDS", "EpisodeOutcome", "Progress", "add_sweep_options", "reproducible_settings", "run_jobs",
           "run_spec", "run_specs"]

BACKENDS = ("process", "ray")
"""Where :func:`run_jobs` runs: a local process pool (the default), or Ray tasks (the ``distributed`` extra)."""

Item = TypeVar("Item")
Result = TypeVar("Result")


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


def reproducible_settings(filter_name: str) -> dict[str, Any]:
    """Filter settings under which an episode depends only on its seed, not on the machine's load.

    The MPC's compute budget makes a call that runs over it follow the last verified plan (status
    ``fallback``, "deadline"): right on a robot, but on a loaded machine (a sweep on every core) the
    same seed then gives another episode. Sweeps that compare filters run it without the budget
    (``budget=inf``); the deadline has its own tests.
    """
    return {"budget": math.inf} if filter_name.removesuffix(ESCAPE_SUFFIX) == "mpc" else {}


def add_sweep_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--workers``, ``--backend``, ``--address`` and ``--no-progress`` to a sweep's command line.

    Pass them on as ``run_jobs(..., args.workers, progress=not args.no_progress, backend=args.backend,
    address=args.address)`` (:func:`run_jobs`, :func:`run_specs`).
    """
    parser.add_argument("--workers", type=argument_type(integer, low=1), default=None,
                        help="processes, or the CPUs of a local Ray (default: one per core)")
    parser.add_argument("--backend", choices=BACKENDS, default="process",
                        help="where the episodes run (default: process; ray needs safenav[distributed])")
    parser.add_argument("--address", default=None,
                        help="with --backend ray: the cluster to join (auto, ray://HOST:10001); default: a local Ray")
    parser.add_argument("--no-progress", action="store_true", help="no progress")


def run_specs(specs: Sequence[EpisodeSpec], workers: int | None = None, *, progress: bool = True,
              description: str = "episodes", backend: str = "process",
              address: str | None = None) -> list[EpisodeOutcome]:
    """Run every spec, on ``workers`` processes or on Ray, with progress on standard error.

    Each episode depends only on its spec, so the outcomes do not depend on the number of
    workers, the backend, or the order in which they finish. The specs were checked when they
    were made (:class:`EpisodeSpec`); an episode that fails anyway fails the run, and the queued
    ones are not started.

    Args:
        specs: the episodes.
        workers: processes (``None``: one per core; 1 runs in this process with the process
            backend); with a local Ray, its CPUs.
        progress: show the progress (:class:`Progress`: a bar on a terminal, plain lines otherwise).
        description: the progress label.
        backend: one of :data:`BACKENDS`.
        address: the Ray cluster to join (``"auto"``, ``"ray://host:10001"``); ``None`` starts a
            local one. Only with ``backend="ray"``.

    Returns:
        The outcomes, in the order of ``specs``.

    Raises:
        InvalidConfig: ``workers`` is not an integer >= 1, or an address without Ray.
        UnknownName: an unknown backend.
        MissingDependency: Ray is not installed (``pip install "safenav[distributed]"``).
    """
    return run_jobs(run_spec, specs, workers, progress=progress, description=description, cost=_cost,
                    backend=backend, address=address)


def run_jobs(function: Callable[[Item], Result], items: Sequence[Item], workers: int | None = None, *,
             progress: bool = True, description: str = "episodes", cost: Callable[[Item], float] | None = None,
             backend: str = "process", address: str | None = None) -> list[Result]:
    """``[function(item) for item in items]``, on a process pool or on Ray, with progress; in the order of ``items``.

    Args:
        function: a module-level (picklable) function of one item; it must depend on nothing else
            for the results not to depend on where they ran.
        items: its arguments (picklable).
        workers: see :func:`run_specs`.
        progress: show the progress.
        description: the progress label.
        cost: a rough relative cost of an item; the most costly start first (a shorter tail).
        backend: one of :data:`BACKENDS`.
        address: see :func:`run_specs`.

    Raises:
        InvalidConfig: ``workers`` is not an integer >= 1, or an address without Ray.
        UnknownName: an unknown backend.
    """
    backend = choice("backend", backend, BACKENDS)
    workers = (os.cpu_count() or 1) if workers is None else integer("workers", workers, low=1)
    if address is not None and backend != "ray":
        raise InvalidConfig(f"address={address!r} is for the Ray backend; expected backend='ray', got {backend!r}")
    order = sorted(range(len(items)), key=lambda i: -cost(items[i])) if cost is not None else range(len(items))
    results: list[Any] = [_MISSING] * len(items)
    with Progress(len(items), description, enabled=progress) as bar:
        if backend == "ray":
            finished = _on_ray(function, items, order, workers, address)
        elif workers == 1 or len(items) <= 1:
            finished = ((index, function(items[index])) for index in range(len(items)))
        else:
            finished = _on_pool(function, items, order, workers)
        for index, result in finished:
            results[index] = result
            bar.update()
    return results


_MISSING = object()


def _on_pool(function: Callable[[Item], Result], items: Sequence[Item], order: Sequence[int],
             workers: int) -> Iterator[tuple[int, Result]]:
    with ProcessPoolExecutor(max_workers=min(workers, len(items))) as pool:
        futures = {pool.submit(function, items[index]): index for index in order}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        except BaseException:
            # A job failed or the user pressed Ctrl-C: do not start the queued ones.
            pool.shutdown(wait=True, cancel_futures=True)
            raise


def _on_ray(function: Callable[[Item], Result], items: Sequence[Item], order: Sequence[int], workers: int,
            address: str | None) -> Iterator[tuple[int, Result]]:
    """Every item a Ray task; results yielded as they finish. A local Ray started here is shut down at the end."""
    ray = require("ray", extra="distributed", purpose="sweeps on a Ray cluster (--backend ray)")
    started = not ray.is_initialized()
    if started:
        options: dict[str, Any] = {"address": address, "include_dashboard": False, "log_to_driver": False,
                                   "configure_logging": False}
        if address is None:
            options["num_cpus"] = workers
        try:
            with _quiet_stderr():
                ray.init(**options)
        except ConnectionError as error:
            raise InvalidConfig(f"no Ray cluster answers at address={address!r} ({error}); expected the address of "
                                "a running cluster (`ray start --head` on its head node), or no address for a "
                                "local Ray") from error
    try:
        task = ray.remote(num_cpus=1)(_call)
        shipped = ray.put(function)   # once, not with every task
        pending = {task.remote(shipped, items[index]): index for index in order}
        try:
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                for reference in done:
                    yield pending.pop(reference), ray.get(reference)
        except BaseException:
            for reference in pending:
                ray.cancel(reference, force=True)
            raise
    finally:
        if started:
            ray.shutdown()


def _call(function: Callable[[Item], Result], item: Item) -> Result:
    """A Ray task: ``function(item)`` (Ray cannot make a task of a built-in or a callable object itself)."""
    return function(item)


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Ray prints a banner and warnings on start; a sweep's output is its progress and its table."""
    with open(os.devnull, "w") as null, contextlib.redirect_stderr(null):
        yield
