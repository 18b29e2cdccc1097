"""The collision benchmark: the quick sweep end to end, and its one-line errors."""

import csv
import json

import pytest
from PIL import Image

from benchmarks import collision_rates
from benchmarks.common import opt_in_settings
from safenav.filters import make_filter
from safenav.robot import preset
from safenav.scenarios import scenario

REQUIRED_KEYS = {"scenario", "robot", "policy", "filter", "episodes", "collisions", "collision_rate",
                 "min_clearance", "intervention", "progress", "goal_success", "stuck_time", "fallbacks",
                 "filter_p50_us", "filter_p99_us", "deadlocked_episodes", "deadlock_rate", "deadlock_rate_ci",
                 "deadlock_time", "escapes_started", "escapes_succeeded", "escape_time", "omega_chatter",
                 "v_reversals"}


@pytest.mark.sim
@pytest.mark.slow   # 30-50 s; the command also runs in tests/benchmarks/test_forms.py and on Ray
def test_quick_collision_benchmark(tmp_path, capsys):
    out = tmp_path / "rates.json"
    code = collision_rates.main(["--quick", "--json", str(out), "--csv", str(tmp_path / "rates.csv"),
                                 "--plots", str(tmp_path / "plots"), "--no-progress"])
    assert code == 0
    report = json.loads(out.read_text())
    cells = report["cells"]
    assert cells and all(set(cell) >= REQUIRED_KEYS for cell in cells)
    assert report["config"]["odometry"] is False
    assert report["config"]["quick"] is True and report["config"]["episodes"] == sum(c["episodes"] for c in cells)
    naive = [cell for cell in cells if cell["filter"] == "none"]
    cbf = [cell for cell in cells if cell["filter"] == "cbf"]
    assert any(cell["collisions"] > 0 for cell in naive)
    assert cbf and all(cell["collisions"] == 0 for cell in cbf), [c for c in cbf if c["collisions"]]
    escaped = [cell for cell in cells if cell["filter"] in ("cbf+escape", "mpc+escape")]
    assert escaped and all(cell["collisions"] == 0 for cell in escaped), [c for c in escaped if c["collisions"]]
    assert [cell["filter"] for cell in cells[:7]] == ["none", "zones", "zones+escape", "cbf", "cbf+escape", "mpc",
                                                      "mpc+escape"]
    assert all(cell["escapes_started"] == 0 for cell in cells if "escape" not in cell["filter"])
    summary = report["summary"]
    assert sum(group["episodes"] for group in summary) == report["config"]["episodes"]
    assert {tuple(group["group"]) for group in summary} == {
        (scenario(cell["scenario"]).world_kind, cell["filter"]) for cell in cells}
    assert all(cell["filter_p50_us"] is None for cell in naive)
    assert all(cell["filter_p50_us"] > 0 and cell["filter_p99_us"] >= cell["filter_p50_us"] for cell in cbf)
    stdout = capsys.readouterr().out
    assert "| stop_at_wall | rosbot | stop_at_wall_buggy | none |" in stdout
    assert "| goal_rosbot | go_to_goal | cbf+escape |" in stdout          # the liveness table
    assert "| goal | mpc+escape |" in stdout                               # the summary
    with (tmp_path / "rates.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(cells) and "min_clearance_p5" in rows[0] and "collision_rate_ci_high" in rows[0]
    pngs = sorted((tmp_path / "plots").glob("*.png"))
    assert {p.name for p in pngs} >= {"collision_rates.png", "clearance_histogram.png",
                                      "trajectories_stop_at_wall.png"}
    for png in pngs:
        with Image.open(png) as image:
            image.verify()


def test_benchmark_rejects_unknown_names(capsys):
    assert collision_rates.main(["--scenarios", "moon", "--filters", "none"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("collision_rates: error: unknown scenario 'moon'; expected one of:")
    assert "\n" not in error


def _one_episode(tmp_path, capsys, scenario_name: str, filters: str, *options: str) -> tuple[str, dict]:
    """A sweep of one 1 s episode per filter with ``options``: what it printed, and its JSON."""
    out = tmp_path / "rates.json"
    code = collision_rates.main(["--scenarios", scenario_name, "--filters", filters, "--seeds", "1", "--duration",
                                 "1", "--workers", "1", *options, "--no-progress", "--json", str(out)])
    assert code == 0
    return capsys.readouterr().out, json.loads(out.read_text())


def _usage_error(capsys, *argv: str) -> str:
    """The one-line usage error of a bad option (argparse's exit code 2)."""
    with pytest.raises(SystemExit) as exit_info:
        collision_rates.main(list(argv))
    assert exit_info.value.code == 2
    return capsys.readouterr().err


@pytest.mark.sim
def test_odometry_gives_the_filters_the_pose_and_the_report_says_so(tmp_path, capsys):
    printed, report = _one_episode(tmp_path, capsys, "wall_follower", "cbf", "--odometry")
    assert "the filters get the measured velocity and the odometry pose" in printed
    assert report["config"]["odometry"] is True and report["cells"][0]["collisions"] == 0


#: Numeric options of the sweep: the scenario they run on, a value, what the header then prints, the JSON key and
#: value, and a bad value with its usage error. ``--range-noise`` replaces the presets' noise in the simulator only.
CHECKED_OPTIONS = [
    ("door_m2wr", "--range-noise", "0", "lidar range noise 0 m", "range_noise", 0.0,
     "-0.1", "--range-noise: must be a finite number >= 0 and <= 1, got -0.1"),
    ("goal_rosbot", "--cbf-smoothing", "1", "the CBF smooths its commands by 1", "cbf_smoothing", 1.0,
     "-1", "--cbf-smoothing: must be a finite number >= 0 and <= 100, got -1"),
]


@pytest.mark.sim
@pytest.mark.parametrize(("scenario", "option", "value", "printed_text", "key", "recorded", "bad", "error_text"),
                         CHECKED_OPTIONS, ids=[row[1] for row in CHECKED_OPTIONS])
def test_a_numeric_option_is_printed_recorded_in_the_json_and_checked(tmp_path, capsys, scenario, option, value,
                                                                        printed_text, key, recorded, bad, error_text):
    printed, report = _one_episode(tmp_path, capsys, scenario, "cbf", option, value)
    assert printed_text in printed
    assert report["config"][key] == recorded
    error = _usage_error(capsys, "--scenarios", scenario, "--filters", "cbf", f"{option}={bad}")
    assert error_text in error


@pytest.mark.sim
def test_mpc_lookahead_reaches_the_mpc_rows_only(tmp_path, capsys):
    printed, report = _one_episode(tmp_path, capsys, "goal_rosbot", "cbf,mpc", "--mpc-lookahead", "0.1")
    assert "the MPC plans a look-ahead of 0.1 m" in printed
    assert report["config"]["mpc_lookahead"] == 0.1
    specs = collision_rates.episode_specs(collision_rates.matrix(["goal_rosbot"], None, ["cbf", "mpc"]), range(1))
    assert all("lookahead" not in spec.filter_options for spec in specs)   # the default filters, unchanged
    _usage_error(capsys, "--scenarios", "goal_rosbot", "--filters", "mpc", "--mpc-lookahead=-1")


def test_the_opt_in_settings_reach_their_own_rows_only():
    specs = collision_rates.episode_specs(
        collision_rates.matrix(["goal_rosbot"], None, ["zones", "cbf", "cbf+escape", "mpc", "mpc+escape"]), range(1))
    assert collision_rates.tuned(specs) == specs          # the defaults: every filter as shipped
    tuned = {spec.filter: dict(spec.filter_options) for spec in collision_rates.tuned(
        specs, mpc_reference="cbf", mpc_lookahead=0.1, cbf_smoothing=2.0, mpc_hold=False)}
    assert tuned["cbf"] == tuned["cbf+escape"] == {"smoothing": 2.0}
    assert tuned["mpc"] == tuned["mpc+escape"] == {"reference": "cbf", "lookahead": 0.1, "hold_stop": False}
    assert tuned["zones"] == {}


@pytest.mark.sim
def test_mpc_no_hold_reaches_the_mpc_rows_only_and_is_recorded(tmp_path, capsys):
    printed, report = _one_episode(tmp_path, capsys, "goal_rosbot", "cbf,mpc", "--mpc-no-hold")
    assert "the MPC without its hold" in printed
    assert report["config"]["mpc_hold"] is False
    built = make_filter("mpc", preset("rosbot"), 0.05, **opt_in_settings("mpc", mpc_hold=False))
    assert built.config.hold_stop is False
    assert make_filter("mpc", preset("rosbot"), 0.05).config.hold_stop is True     # the shipped MPC holds


@pytest.mark.sim
def test_a_body_model_is_measured_with_the_footprint_truth_and_the_mpc_refuses_the_polygon(tmp_path, capsys):
    printed, report = _one_episode(tmp_path, capsys, "goal_m2wr", "cbf,mpc", "--body", "cover")
    assert "body model cover; clearance measured for the footprint" in printed
    assert (report["config"]["body"], report["config"]["truth"]) == ("cover", "footprint")
    tuned = {spec.filter: dict(spec.filter_options) for spec in collision_rates.tuned(
        collision_rates.episode_specs(collision_rates.matrix(["goal_m2wr"], None, ["zones", "cbf", "mpc+escape"]),
                                      range(1)), body="cover")}
    assert tuned == {"zones": {}, "cbf": {"body": "cover"}, "mpc+escape": {"body": "cover"}}
    printed, report = _one_episode(tmp_path, capsys, "goal_m2wr", "cbf", "--truth", "disk")
    assert (report["config"]["body"], report["config"]["truth"]) == ("disk", "disk")
    printed, report = _one_episode(tmp_path, capsys, "goal_m2wr", "cbf")
    assert (report["config"]["body"], report["config"]["truth"]) == ("disk", "auto")
    assert "clearance measured for the footprint (the disk of a round robot)" in printed
    assert collision_rates.main(["--scenarios", "goal_m2wr", "--filters", "cbf,mpc", "--body", "polygon"]) == 2
    assert "--body polygon: the MPC's body models are disk, cover" in capsys.readouterr().err


@pytest.mark.sim
def test_first_seed_runs_more_episodes_of_the_same_cells(tmp_path, capsys):
    """``--first-seed 20 --seeds 1`` runs seed 20, the episode a 21-seed sweep runs last (same world, same result)."""
    printed, report = _one_episode(tmp_path, capsys, "goal_rosbot", "cbf", "--first-seed", "20")
    assert report["config"]["seeds"] == [20] and "x 1 seeds from 20" in printed
    (cell,) = report["cells"]
    assert cell["seeds"] == [20]
    assert "--first-seed" in _usage_error(capsys, "--first-seed", "-1")
