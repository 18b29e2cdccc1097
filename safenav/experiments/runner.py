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
applied to :func:`run_spec`; a :class:`JobRunner` runs batch after batch on one pool or one Ray (a
search that asks for a generation at a time).

Resuming: with ``results=PATH`` every finished job is appended to a JSON-lines file as it finishes
(:mod:`safenav.experiments.results`); after an interruption (Ctrl-C, a killed worker, a lost Ray
node) the same sweep with ``resume=True`` takes the jobs already in the file from it and runs only
the others, so its outcomes equal an uninterrupted run's.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed, wait
from dataclasses import dataclass, replace
from pathlib import Path
from types import ModuleType
from typing import IO, Any, TypeVar

import numpy as np

from safenav._checks import argument_type, choice, integer, writable_file
from safenav._optional import require
from safenav.episode import EpisodeConfig, EpisodeMetrics, Trajectory, run_episode
from safenav.errors import InvalidConfig
from safenav.experiments.results import ResultsFile, job_name
from safenav.experiments.specs import EpisodeSpec
from safenav.filters import make_filter, unescaped
from safenav.scenarios import scenario, scenario_for
from safenav.sim_bullet import SimConfig
from safenav.worlds import World

__all__ = ["BACKENDS", "EpisodeOutcome", "JobRunner", "Progress", "add_sweep_options", "reproducible_settings",
           "reproducible_specs", "run_jobs", "run_spec", "run_specs", "spec_cost", "sweep_settings"]

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
    config = EpisodeConfig(duration=task.duration if spec.duration is None else spec.duration, sim=sim,
                           give_pose=spec.odometry)
    safety_filter = make_filter(spec.filter, robot, sim.control_dt, **dict(spec.filter_options))
    start = time.perf_counter()
    result = run_episode(world, robot, policy, safety_filter, config=config, seed=spec.seed,
                         record=spec.record or spec.record_scans, record_scans=spec.record_scans)
    return EpisodeOutcome(spec, robot.name, world, result.metrics, result.trajectory, time.perf_counter() - start)


def spec_cost(spec: EpisodeSpec) -> float:
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

    The compute budget of the MPC and of the CBF makes a call that cannot end within it follow the
    last verified plan or brake (status ``fallback``, "deadline"): right on a robot, but on a loaded
    machine (a sweep on every core) the same seed then gives another episode. Sweeps that compare
    filters run them without the budget (``budget=inf``); the deadline has its own tests.
    """
    return {"budget": math.inf} if unescaped(filter_name) in ("mpc", "cbf") else {}


def reproducible_specs(specs: Iterable[EpisodeSpec]) -> list[EpisodeSpec]:
    """``specs`` with each filter run without its compute budget (:func:`reproducible_settings` added to the
    spec's own filter options): each episode then depends on its seed alone, not on the machine's load."""
    return [replace(spec, filter_options={**dict(spec.filter_options), **reproducible_settings(spec.filter)})
            for spec in specs]


def add_sweep_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--workers``, ``--backend``, ``--address``, ``--results``, ``--resume`` and ``--no-progress``.

    Pass them on with :func:`sweep_settings`: ``run_jobs(function, items, **sweep_settings(args))``.
    """
    parser.add_argument("--workers", type=argument_type(integer, low=1), default=None,
                        help="processes, or the CPUs of a local Ray (default: one per core)")
    parser.add_argument("--backend", choices=BACKENDS, default="process",
                        help="where the episodes run (default: process; ray needs safenav[distributed])")
    parser.add_argument("--address", default=None,
                        help="with --backend ray: the cluster to join (auto, ray://HOST:10001); default: a local Ray")
    parser.add_argument("--results", metavar="PATH", default=None,
                        help="stream every finished episode to this JSON-lines file, so an interrupted sweep can "
                             "resume (docs/distributed.md)")
    parser.add_argument("--resume", action="store_true",
                        help="with --results: reuse the episodes already in the file and run only the others")
    parser.add_argument("--no-progress", action="store_true", help="no progress")


def sweep_settings(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of :func:`run_jobs` (and :class:`JobRunner`) from :func:`add_sweep_options`' options.

    Raises:
        InvalidConfig: ``--resume`` without ``--results``, or a results path that cannot be written.
    """
    if args.resume and args.results is None:
        raise InvalidConfig("--resume needs the sweep's results file; expected --results PATH as well")
    if args.results is not None:
        writable_file("--results", args.results)
    return {"workers": args.workers, "backend": args.backend, "address": args.address,
            "progress": not args.no_progress, "results": args.results, "resume": args.resume}


def run_specs(specs: Sequence[EpisodeSpec], workers: int | None = None, *, progress: bool = True,
              description: str = "episodes", backend: str = "process", address: str | None = None,
              results: str | os.PathLike[str] | None = None, resume: bool = False) -> list[EpisodeOutcome]:
    """Run every spec, on ``workers`` processes or on Ray, with progress on standard error.

    Each episode depends only on its spec, so the outcomes do not depend on the number of
    workers, the backend, the order in which they finish, or on a resume. The specs were checked
    when they were made (:class:`EpisodeSpec`); an episode that fails anyway fails the run, and
    the queued ones are not started.

    Args:
        specs: the episodes.
        workers: processes (``None``: one per core; 1 runs in this process with the process
            backend); with a local Ray, its CPUs.
        progress: show the progress (:class:`Progress`: a bar on a terminal, plain lines otherwise).
        description: the progress label.
        backend: one of :data:`BACKENDS`.
        address: the Ray cluster to join (``"auto"``, ``"ray://host:10001"``); ``None`` starts a
            local one. Only with ``backend="ray"``.
        results: a JSON-lines file every finished episode is appended to as it finishes
            (:class:`~safenav.experiments.results.ResultsFile`).
        resume: reuse the episodes already in ``results``; run only the others.

    Returns:
        The outcomes, in the order of ``specs``.

    Raises:
        InvalidConfig: ``workers`` is not an integer >= 1, an address without Ray, ``resume``
            without ``results``, or ``results`` holds results and ``resume`` is not set.
        UnknownName: an unknown backend.
        MissingDependency: Ray is not installed (``pip install "safenav[distributed]"``).
    """
    return run_jobs(run_spec, specs, workers, progress=progress, description=description, cost=spec_cost,
                    backend=backend, address=address, results=results, resume=resume)


def run_jobs(function: Callable[[Item], Result], items: Sequence[Item], workers: int | None = None, *,
             progress: bool = True, description: str = "episodes", cost: Callable[[Item], float] | None = None,
             backend: str = "process", address: str | None = None, results: str | os.PathLike[str] | None = None,
             resume: bool = False) -> list[Result]:
    """``[function(item) for item in items]``, on a process pool or on Ray, with progress; in the order of ``items``.

    One batch on a :class:`JobRunner` (which keeps its pool or its Ray between batches).

    Args:
        function: a module-level (picklable) function of one item; it must depend on nothing else
            for the results not to depend on where they ran.
        items: its arguments (picklable; ``repr`` names an item in the results file).
        workers: see :func:`run_specs`.
        progress: show the progress.
        description: the progress label.
        cost: a rough relative cost of an item; the most costly start first (a shorter tail).
        backend: one of :data:`BACKENDS`.
        address: see :func:`run_specs`.
        results: see :func:`run_specs`.
        resume: see :func:`run_specs`.

    Raises:
        InvalidConfig: ``workers`` is not an integer >= 1, an address without Ray, or a results
            file that cannot be used (see :func:`run_specs`).
        UnknownName: an unknown backend.
    """
    with JobRunner(workers, backend=backend, address=address, results=results, resume=resume,
                   progress=progress, description=description) as runner:
        return runner.map(function, items, cost=cost)


_MISSING = object()


class JobRunner:
    """Runs batches of jobs on a process pool or on Ray, keeping the backend up between batches.

    A search that asks for a batch at a time (the falsifier's CMA-ES generations) starts its
    pool or its Ray once. Finished jobs are appended to the results file as they finish, and on
    ``resume`` the jobs already there are taken from it instead of being run.

    Args:
        workers: processes (``None``: one per core; 1 runs in this process with the process
            backend); with a local Ray, its CPUs.
        backend: one of :data:`BACKENDS`.
        address: the Ray cluster to join; ``None`` starts a local one (only with ``backend="ray"``).
        results: the results file (:class:`~safenav.experiments.results.ResultsFile`), or ``None``.
        resume: reuse the results already in ``results``.
        progress: show the progress of each batch.
        description: the progress label.
        ship: packages Ray uploads to its workers (``runtime_env`` ``py_modules``) when this runner
            starts or joins Ray: code the jobs import that is not installed there, such as a checkout's
            ``benchmarks``. A Ray already initialised in this process keeps its own runtime environment.

    Raises:
        InvalidConfig: ``workers`` is not an integer >= 1, an address without Ray, ``resume``
            without ``results``, or ``results`` holds results and ``resume`` is not set.
        UnknownName: an unknown backend.
    """

    def __init__(self, workers: int | None = None, *, backend: str = "process", address: str | None = None,
                 results: str | os.PathLike[str] | None = None, resume: bool = False, progress: bool = True,
                 description: str = "episodes", ship: Sequence[ModuleType] = ()) -> None:
        self.backend = choice("backend", backend, BACKENDS)
        self.workers = (os.cpu_count() or 1) if workers is None else integer("workers", workers, low=1)
        if address is not None and self.backend != "ray":
            raise InvalidConfig(f"address={address!r} is for the Ray backend; expected backend='ray', "
                                f"got {self.backend!r}")
        if resume and results is None:
            raise InvalidConfig("resume=True needs the results file to resume from; expected results=PATH")
        self.address = address
        self.progress = progress
        self.description = description
        self.ship = tuple(ship)
        self.results = None if results is None else ResultsFile(results, resume=resume)
        self.reused = 0
        """Jobs taken from the results file instead of being run, over every batch so far."""
        self._pool: ProcessPoolExecutor | None = None
        self._ray: Any = None
        self._ray_started = False

    def __enter__(self) -> JobRunner:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Shut the pool (or the local Ray started here) down and close the results file."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._ray_started:
            self._ray.shutdown()
            self._ray_started = False
        if self.results is not None:
            self.results.close()

    def map(self, function: Callable[[Item], Result], items: Sequence[Item], *,
            cost: Callable[[Item], float] | None = None) -> list[Result]:
        """``[function(item) for item in items]`` in the order of ``items``; see :func:`run_jobs`."""
        name = job_name(function)
        keys = [repr(item) for item in items] if self.results is not None else []
        outputs: list[Any] = [_MISSING] * len(items)
        if self.results is not None:
            for index, key in enumerate(keys):
                outputs[index] = self.results.get(name, key, _MISSING)
        order = sorted(range(len(items)), key=lambda i: -cost(items[i])) if cost is not None else range(len(items))
        todo = [index for index in order if outputs[index] is _MISSING]
        self.reused += len(items) - len(todo)

        with Progress(len(todo), self.description, enabled=self.progress) as bar:
            def finish(index: int, result: Any) -> None:
                outputs[index] = result
                if self.results is not None:
                    self.results.add(name, keys[index], result)
                bar.update()

            if self.backend == "ray":
                self._on_ray(function, items, todo, finish)
            elif self.workers == 1 or len(todo) <= 1:
                for index in todo:
                    finish(index, function(items[index]))
            else:
                self._on_pool(function, items, todo, finish, outputs)
        return outputs

    def _on_pool(self, function: Callable[[Item], Result], items: Sequence[Item], todo: Sequence[int],
                 finish: Callable[[int, Any], None], outputs: list[Any]) -> None:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers)
        futures = {self._pool.submit(function, items[index]): index for index in todo}
        try:
            for future in as_completed(futures):
                finish(futures[future], future.result())
        except BaseException:
            # A job failed or the user pressed Ctrl-C: start none of the queued jobs, keep those that finish.
            for future in futures:
                future.cancel()
            wait(futures)
            for future, index in futures.items():
                if outputs[index] is _MISSING and not future.cancelled() and future.exception() is None:
                    finish(index, future.result())
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
            raise

    def _on_ray(self, function: Callable[[Item], Result], items: Sequence[Item], todo: Sequence[int],
                finish: Callable[[int, Any], None]) -> None:
        """Every job a Ray task; results taken as they finish."""
        ray = self._start_ray()
        task = ray.remote(num_cpus=1)(_call)
        shipped = ray.put(function)   # once per batch, not with every task
        pending = {task.remote(shipped, items[index]): index for index in todo}
        try:
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                for reference in done:
                    finish(pending.pop(reference), ray.get(reference))
        except BaseException:
            for reference in pending:
                ray.cancel(reference, force=True)
            raise

    def _start_ray(self) -> Any:
        """Ray, initialised once: a local one with ``workers`` CPUs, the cluster at ``address``, or the
        Ray already initialised in this process (left running at the end)."""
        if self._ray is not None:
            return self._ray
        ray = require("ray", extra="distributed", purpose="sweeps on a Ray cluster (--backend ray)")
        if not ray.is_initialized():
            options: dict[str, Any] = {"address": self.address, "include_dashboard": False, "log_to_driver": False,
                                       "configure_logging": False}
            if self.address is None:
                options["num_cpus"] = self.workers
            if self.ship:
                options["runtime_env"] = {"py_modules": [str(Path(module.__file__).parent)
                                                         for module in self.ship if module.__file__]}
            try:
                with _quiet_stderr():
                    ray.init(**options)
            except ConnectionError as error:
                raise InvalidConfig(f"no Ray cluster answers at address={self.address!r} ({error}); expected the "
                                    "address of a running cluster (`ray start --head` on its head node; one with "
                                    "token authentication also needs RAY_AUTH_MODE=token and its token, see "
                                    "docs/distributed.md), or no address for a local Ray") from error
            self._ray_started = True
        self._ray = ray
        return ray


def _call(function: Callable[[Item], Result], item: Item) -> Result:
    """A Ray task: ``function(item)`` (Ray cannot make a task of a built-in or a callable object itself)."""
    return function(item)


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Ray prints a banner and warnings on start; a sweep's output is its progress and its table."""
    with open(os.devnull, "w") as null, contextlib.redirect_stderr(null):
        yield
