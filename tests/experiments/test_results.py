"""Resuming a sweep from its results file: interrupted runs keep what finished, a resume runs only the rest.

The interruptions are made deterministic: a job that raises ``KeyboardInterrupt`` (Ctrl-C) or kills
its own process (``SIGKILL``: a killed worker, a lost node) when it reaches a marked item.
"""

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from safenav import InvalidConfig
from safenav.experiments.results import ResultsFile
from safenav.experiments.runner import run_jobs

ROOT = Path(__file__).resolve().parents[2]


def square_or_stop(item):
    """``value ** 2``, logging the call to ``log``; stops when ``value`` is the one the ``marker`` file names.

    Args:
        item: ``(value, log, marker)``; the marker file holds ``"<value> interrupt"`` (Ctrl-C) or
            ``"<value> kill"`` (SIGKILL of this process), or does not exist (never stops). The log and
            the mark live in files so that the same item (the same key in the results file) behaves
            differently between runs.
    """
    value, log, marker = item
    stop = Path(marker).read_text() if Path(marker).exists() else ""
    if stop and value == int(stop.split()[0]):
        if stop.split()[1] == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        raise KeyboardInterrupt
    with open(log, "a") as handle:
        handle.write(f"{value}\n")
    return value ** 2


def _items(tmp_path, count=8):
    return [(value, str(tmp_path / "calls.log"), str(tmp_path / "stop")) for value in range(count)]


def _calls(tmp_path):
    path = tmp_path / "calls.log"
    calls = [int(line) for line in path.read_text().split()] if path.exists() else []
    path.unlink(missing_ok=True)
    return calls


@pytest.mark.parametrize("workers", [1, 2])
def test_an_interrupted_sweep_resumes_with_only_the_jobs_that_did_not_finish(tmp_path, workers):
    items, results = _items(tmp_path), tmp_path / "results.jsonl"
    (tmp_path / "stop").write_text("5 interrupt")
    with pytest.raises(KeyboardInterrupt):
        run_jobs(square_or_stop, items, workers, progress=False, results=results)
    finished = _calls(tmp_path)
    assert 5 not in finished and (workers == 2 or finished == [0, 1, 2, 3, 4])
    assert len(ResultsFile(results, resume=True)) == len(finished)
    (tmp_path / "stop").unlink()
    assert run_jobs(square_or_stop, items, workers, progress=False, results=results, resume=True) == \
           [value ** 2 for value in range(8)]
    rerun = _calls(tmp_path)
    assert sorted(rerun + finished) == list(range(8)), "every job ran exactly once over the two runs"
    assert run_jobs(square_or_stop, items, workers, progress=False, results=results, resume=True) == \
           [value ** 2 for value in range(8)]
    assert _calls(tmp_path) == [], "a finished sweep resumes without running anything"


def test_a_killed_sweep_keeps_every_finished_job(tmp_path):
    items, results = _items(tmp_path), tmp_path / "results.jsonl"
    (tmp_path / "stop").write_text("3 kill")
    script = (f"import sys; sys.path[:0] = [{str(ROOT)!r}, {str(Path(__file__).parent)!r}]\n"
              "from test_results import square_or_stop\n"
              "from safenav.experiments.runner import run_jobs\n"
              f"run_jobs(square_or_stop, {items!r}, 1, progress=False, results={str(results)!r})\n")
    killed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert _calls(tmp_path) == [0, 1, 2]
    assert [json.loads(line)["key"] for line in results.read_text().splitlines()] == [repr(item) for item in items[:3]]
    (tmp_path / "stop").unlink()
    assert run_jobs(square_or_stop, items, 1, progress=False, results=results, resume=True) == \
           [value ** 2 for value in range(8)]
    assert _calls(tmp_path) == [3, 4, 5, 6, 7]


def test_a_line_cut_short_by_the_interruption_is_dropped_and_the_job_runs_again(tmp_path):
    items, results = _items(tmp_path, 4), tmp_path / "results.jsonl"
    run_jobs(square_or_stop, items, 1, progress=False, results=results)
    _calls(tmp_path)
    lines = results.read_text().splitlines(keepends=True)
    results.write_text("".join(lines[:2]) + lines[2][:40])     # the write of the third job was cut short
    assert run_jobs(square_or_stop, items, 1, progress=False, results=results, resume=True) == [0, 1, 4, 9]
    assert _calls(tmp_path) == [2, 3]
    assert len(results.read_text().splitlines()) == 4


def test_a_results_file_is_not_overwritten_or_mixed_without_resume(tmp_path):
    results = tmp_path / "results.jsonl"
    run_jobs(abs, [-1, -2], 1, progress=False, results=results)
    with pytest.raises(InvalidConfig, match=r"results file '.*results.jsonl' already holds results; expected a new "
                                            r"file, or resume=True \(--resume\)"):
        run_jobs(abs, [-1, -2], 1, progress=False, results=results)
    # another function's jobs with the same items are not taken for these
    assert run_jobs(str, [-1, -2], 1, progress=False, results=results, resume=True) == ["-1", "-2"]


def test_a_file_that_is_not_a_results_file_is_a_clear_error(tmp_path):
    results = tmp_path / "results.jsonl"
    results.write_text('{"function": "abs", "key": "1", "result": "bm90IGEgcGlja2xl"}\nnot json\n')
    with pytest.raises(InvalidConfig, match=r"line 1 of results file .* is not a results line .*expected the file "
                                            r"a sweep wrote"):
        run_jobs(abs, [1], 1, progress=False, results=results, resume=True)


@pytest.mark.parametrize("name", ["collision_rates", "robustness", "stop_metrics", "moving_obstacles", "falsify"])
def test_resume_without_a_results_file_is_a_clear_error_on_the_command_line(name, capsys):
    import importlib

    benchmark = importlib.import_module(f"benchmarks.{name}")
    assert benchmark.main(["--resume"]) == 2
    error = capsys.readouterr().err.strip()
    assert error == f"{name}: error: --resume needs the sweep's results file; expected --results PATH as well"


@pytest.mark.sim
def test_a_resumed_collision_sweep_prints_the_uninterrupted_tables(tmp_path, capsys):
    """A part of the sweep (the first seed) ran before the interruption; the resume runs the rest."""
    from benchmarks import collision_rates

    argv = ["--scenarios", "stop_at_wall,clutter_puzzlebot", "--filters", "none,cbf", "--duration", "1.0",
            "--workers", "2", "--no-progress"]
    results = tmp_path / "results.jsonl"

    def tables(*extra):
        path = tmp_path / "out.json"
        assert collision_rates.main([*argv, *extra, "--json", str(path)]) == 0
        printed = capsys.readouterr().out
        cells = [{k: v for k, v in cell.items() if k not in ("filter_p50_us", "filter_p99_us", "episode_wall_s")}
                 for cell in json.loads(path.read_text())["cells"]]
        return printed, cells

    tables("--seeds", "1", "--results", str(results))
    assert len(results.read_text().splitlines()) == 8
    resumed, resumed_cells = tables("--seeds", "2", "--results", str(results), "--resume")
    assert "resumed: 8 of 16 episodes taken from" in resumed and "8 run now" in resumed
    assert len(results.read_text().splitlines()) == 16
    fresh, fresh_cells = tables("--seeds", "2")
    assert resumed_cells == fresh_cells

    def safety_table(printed):
        return printed[printed.index("| scenario"):printed.index("liveness")]
    assert safety_table(resumed) == safety_table(fresh)
