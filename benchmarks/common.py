"""Helpers shared by the benchmarks: timing statistics, tables, JSON output, machine description.

Importing this module also silences qpsolvers' advice warnings (``SparseConversionWarning``:
"for best performance, build your matrix as a csc_matrix"): a benchmark reports times, and the
advice, printed once per process, ends up in the middle of its tables.

Every benchmark runs both as ``python -m benchmarks.NAME`` and as ``python benchmarks/NAME.py``;
for the second form it starts with::

    if __package__ in (None, ""):   # python benchmarks/NAME.py: import from this checkout
        sys.path[0] = str(Path(__file__).resolve().parents[1])
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

import safenav
from safenav._checks import argument_type, writable_file
from safenav.errors import SafeNavError
from safenav.experiments.runner import JobRunner, add_sweep_options, sweep_settings
from safenav.experiments.tables import markdown
from safenav.filters import unescaped

warnings.filterwarnings("ignore", category=UserWarning, module=r"qpsolvers(\..*)?$")


def run_cli(parser: argparse.ArgumentParser, argv: Sequence[str] | None,
            run: Callable[[argparse.Namespace], int]) -> int:
    """Parse ``argv`` and run; a :class:`~safenav.errors.SafeNavError` becomes one line on standard error.

    Returns:
        ``run``'s exit code, or 2 after a SafeNavError (``<prog>: error: <message>``; an unknown name,
        a bad value, an unwritable output). Argparse's own usage errors exit with 2 as well.
    """
    args = parser.parse_args(argv)
    try:
        return run(args)
    except SafeNavError as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2


SHIPPED = (sys.modules[__package__ or "benchmarks"], safenav)
"""What Ray uploads to its workers for a benchmark's jobs: this ``benchmarks`` package (it is not in the
wheel) and the ``safenav`` this process imported, so the workers run the very code the driver runs
(a checkout's, not an older installed one). Compiled dependencies must be installed on every node."""


def add_real_time_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--real-time``: keep the filters' compute budgets, which a sweep takes away otherwise
    (:func:`~safenav.experiments.runner.reproducible_settings`)."""
    parser.add_argument("--real-time", action="store_true",
                        help="keep the filters' compute budgets: a call preempted past its budget brakes or follows "
                             "its last plan, as on a robot, and the results then depend on the machine's load")


def sweep_parser(prog: str, description: str, add_options: Callable[[argparse.ArgumentParser], None], *,
                 real_time: bool = False) -> argparse.ArgumentParser:
    """A sweep's command line: its own options, then where it runs (``--workers``, ``--backend``,
    ``--address``, ``--results``, ``--resume``, ``--no-progress``), then ``--json PATH``.

    Args:
        prog: the program name (``safenav bench NAME`` passes its own).
        description: the help text (the module's docstring, kept as written).
        add_options: adds the sweep's own options to the parser.
        real_time: add ``--real-time`` (keep the filters' compute budgets; see
            :func:`~safenav.experiments.runner.reproducible_settings`).
    """
    parser = argparse.ArgumentParser(prog=prog, description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_options(parser)
    if real_time:
        add_real_time_option(parser)
    add_sweep_options(parser)
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON")
    return parser


def where(args: argparse.Namespace) -> str:
    """Where a sweep of :func:`sweep_parser` runs, for its first line: ``2 processes``, ``Ray (auto)``."""
    if args.backend == "ray":
        return f"Ray ({args.address or f'local, {args.workers or os.cpu_count()} CPUs'})"
    return f"{args.workers or os.cpu_count()} processes"


def run_sweep(args: argparse.Namespace, function: Callable[[Any], Any], jobs: Sequence[Any], *,
              description: str, cost: Callable[[Any], float] | None = None) -> tuple[list[Any], float]:
    """Run a sweep's jobs where its options say, after checking that its outputs can be written.

    ``--json`` and ``--results`` are checked before the first job; with ``--resume`` the jobs
    already in the results file are taken from it, and a line says how many.

    Returns:
        The results in the order of ``jobs``, and the wall-clock time [s].
    """
    if args.json is not None:
        writable_file("--json", args.json)
    started = time.perf_counter()
    with JobRunner(**sweep_settings(args), description=description, ship=SHIPPED) as runner:
        results = runner.map(function, jobs, cost=cost)
    if args.resume:
        print(f"resumed: {runner.reused} of {len(jobs)} episodes taken from {args.results}, "
              f"{len(jobs) - runner.reused} run now")
    return results, time.perf_counter() - started


def summary(samples_s: Sequence[float] | np.ndarray) -> dict[str, float]:
    """Median, p99, mean and count of durations given in seconds, reported in microseconds."""
    values = np.asarray(samples_s, dtype=float) * 1e6
    if values.size == 0:
        return {"n": 0, "median_us": float("nan"), "p99_us": float("nan"), "mean_us": float("nan")}
    return {
        "n": int(values.size),
        "median_us": float(np.median(values)),
        "p99_us": float(np.percentile(values, 99)),
        "mean_us": float(values.mean()),
    }


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub-flavoured markdown table (:func:`safenav.experiments.markdown`); floats get sensible digits."""

    def cell(value: Any) -> Any:
        if isinstance(value, float):
            if value != value:  # NaN
                return "–"
            return f"{value:.0f}" if abs(value) >= 100 else f"{value:.3g}"
        return value

    return markdown(headers, [[cell(value) for value in row] for row in rows])


def opt_in_settings(filter_name: str, *, mpc_reference: str | None = None, mpc_lookahead: float = 0.0,
                    cbf_smoothing: float = 0.0, body: str = "disk", mpc_hold: bool = True) -> dict[str, Any]:
    """A benchmark's opt-in settings that apply to ``filter_name`` (with or without the escape): the MPC's
    reference (``None``: the filter's own, :data:`safenav.filters.ESCAPE_PRESETS` inside the escape),
    look-ahead and hold (``False``: ``MPCConfig.hold_stop`` off), the CBF's smoothing, both filters' body model;
    empty for the defaults, and for every other filter."""
    base = unescaped(filter_name)
    shape = {} if body == "disk" else {"body": body}
    if base == "mpc":
        return ({} if mpc_reference is None else {"reference": mpc_reference}) | (
            {"lookahead": mpc_lookahead} if mpc_lookahead else {}) | ({} if mpc_hold else {"hold_stop": False}) | shape
    if base == "cbf":
        return ({"smoothing": cbf_smoothing} if cbf_smoothing else {}) | shape
    return {}


def names(text: str) -> list[str]:
    """A comma-separated list of names (an argparse ``type=``): ``"cbf, mpc"`` -> ``["cbf", "mpc"]``."""
    return [name.strip() for name in text.split(",") if name.strip()]


def numbers(check: Callable[..., float], **bounds: Any) -> Callable[[str], list[float]]:
    """An argparse ``type=`` for comma-separated numbers, each passed through a check of :mod:`safenav._checks`."""
    parse = argument_type(check, **bounds)

    def parse_all(text: str) -> list[float]:
        return [parse(item) for item in names(text)]

    return parse_all


def machine() -> dict[str, Any]:
    """What the numbers were measured on."""
    return {
        "date": datetime.date.today().isoformat(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
    }


def write_json(path: str | os.PathLike[str] | None, payload: dict[str, Any]) -> None:
    """Write ``payload`` (plus the machine description) as JSON when ``path`` is given."""
    if path is None:
        return
    payload = {**payload, "machine": machine()}
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(payload, indent=2, default=float) + "\n")
    print(f"wrote {target}")
