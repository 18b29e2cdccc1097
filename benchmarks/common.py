"""Helpers shared by the benchmarks: timing statistics, tables, JSON output, machine description."""

from __future__ import annotations

import datetime
import json
import os
import platform
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from safenav.experiments import markdown


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
