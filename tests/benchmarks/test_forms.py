"""The simulator's benchmarks run both as ``python -m benchmarks.NAME`` and ``python benchmarks/NAME.py``.

(``collision_rates``, ``robustness``, ``sim_speed`` and ``soak`` on a tiny run; every other benchmark,
the filters', the ROS node's and the Gymnasium ones, answers ``--help`` in both forms.)

Each runs a tiny configuration and writes its JSON; the script form runs from another folder, so it
must find this checkout by itself (not the installed safenav, not the current directory).
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

TINY = {
    "collision_rates": ["--scenarios", "stop_at_wall", "--policies", "stop_at_wall_buggy", "--filters", "none",
                        "--seeds", "1", "--duration", "0.5", "--workers", "1", "--no-progress"],
    "robustness": ["--faults", "dropout", "--filters", "cbf", "--scenarios", "clutter_rosbot", "--seeds", "1",
                   "--duration", "0.3", "--margins", "0", "--workers", "1", "--no-progress"],
    "sim_speed": ["--worlds", "1", "--steps", "5", "--warmup", "1", "--threads", "1", "--processes", "1",
                  "--obstacles", "3"],
    "soak": ["--steps", "30", "--warmup", "2", "--window", "10"],
}
"""A run of each benchmark that takes a second or two."""

EXPECTED_KEYS = {"collision_rates": "cells", "robustness": "records", "sim_speed": "rows", "soak": "soak"}


def test_every_benchmark_here_is_in_the_checkout():
    modules = {path.stem for path in (ROOT / "benchmarks").glob("*.py")}
    assert set(TINY) <= modules, set(TINY) - modules


@pytest.mark.sim
@pytest.mark.parametrize("form", ["module", "script"])
@pytest.mark.parametrize("name", sorted(TINY))
def test_benchmark_runs_in_both_forms(name, form, tmp_path):
    out = tmp_path / "out.json"
    if form == "module":
        command, cwd = [sys.executable, "-m", f"benchmarks.{name}"], ROOT
    else:
        command, cwd = [sys.executable, str(ROOT / "benchmarks" / f"{name}.py")], tmp_path
    result = subprocess.run([*command, *TINY[name], "--json", str(out)], cwd=cwd, capture_output=True, text=True,
                            timeout=300, check=False)
    assert result.returncode == 0, result.stderr
    assert EXPECTED_KEYS[name] in json.loads(out.read_text())
    assert "Traceback" not in result.stderr and "Warning" not in result.stderr + result.stdout
    assert "pybullet build time" not in result.stderr + result.stdout


HELP_ONLY = sorted({path.stem for path in (ROOT / "benchmarks").glob("*.py")} - set(TINY) - {"__init__", "common"})
"""The other benchmarks (the filters', the ROS node's, the Gymnasium ones): their ``--help`` in both forms."""


@pytest.mark.parametrize("form", ["module", "script"])
@pytest.mark.parametrize("name", HELP_ONLY)
def test_every_other_benchmark_answers_help_in_both_forms(name, form, tmp_path):
    if form == "module":
        command, cwd = [sys.executable, "-m", f"benchmarks.{name}"], ROOT
    else:
        command, cwd = [sys.executable, str(ROOT / "benchmarks" / f"{name}.py")], tmp_path
    result = subprocess.run([*command, "--help"], cwd=cwd, capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"usage: {name}"), result.stdout[:200]
