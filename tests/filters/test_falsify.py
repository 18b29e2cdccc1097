"""The falsifier's short seeded run (the long one is ``python -m benchmarks.falsify``, BENCHMARKS.md)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.falsify import (
    GEOMETRIES,
    N_COORDINATES,
    SEARCHED_NOMINALS,
    TOLERANCE,
    Episode,
    _arcs,
    _cell_key,
    _cells,
    _scan,
    _swept_scan,
    decode,
    episodes_per_cell,
    run,
    search,
)
from safenav import preset
from safenav.experiments.runner import reproducible_settings
from safenav.filters import make_filter
from safenav.geometry import Pose2D, unicycle_step
from safenav.robot import RobotSpec
from safenav.synthetic import Circle, Scene, Segment, swept_scan

CELLS = [
    dict(robot="m2wr", filter_name="cbf", base="ramp_limit", dt=0.05, give_velocity=True),
    dict(robot="m2wr", filter_name="mpc", base="lag", dt=0.05, give_velocity=True),
    dict(robot="rosbot", filter_name="cbf", base="instant", dt=0.1, give_velocity=False),
    dict(robot="puzzlebot", filter_name="mpc", base="ramp", dt=0.02, give_velocity=True),
    # The MPC's look-ahead control disk is planned, never verified: the guarantee is still the body's.
    dict(robot="rosbot", filter_name="mpc", base="ramp_limit", dt=0.05, give_velocity=True,
         settings={"lookahead": 0.1}),
    # The CBF's narrow body, switched on and off by the adversary: the guarantee is the footprint's.
    dict(robot="rosbot", filter_name="cbf", base="lag", dt=0.05, give_velocity=True,
         settings={"narrow_body": "cover"}),
    # The odometry pose as the ROS nodes pass it, in a frame far away whose heading crosses the wrap at +-pi.
    dict(robot="m2wr", filter_name="mpc+escape", base="ramp_limit", dt=0.05, give_velocity=True, give_pose=True),
    # Called early (a node triggered by a faster lidar: each command held half as long as planned) and late (three
    # periods apart: every command, braking too, planned for the measured period).
    dict(robot="rosbot", filter_name="cbf", base="ramp_limit", dt=0.05, give_velocity=True, call_period=0.5),
    dict(robot="puzzlebot", filter_name="mpc", base="ramp_limit", dt=0.05, give_velocity=True, call_period=3.0),
    # A turning lidar, each beam measured from where the robot was then, the stamp the first beam's.
    dict(robot="rosbot", filter_name="cbf", base="ramp_limit", dt=0.05, give_velocity=True, sweep="stated"),
    dict(robot="m2wr", filter_name="mpc", base="ramp", dt=0.05, give_velocity=True, sweep="stated"),
]


def _cell_id(cell: dict) -> str:
    every = f"-every-{cell['call_period']:g}dt" if "call_period" in cell else ""
    sweep = f"-sweep-{cell['sweep']}" if "sweep" in cell else ""
    return (f"{cell['robot']}-{cell['filter_name']}-{cell['base']}{'-pose' if cell.get('give_pose') else ''}{every}"
            f"{sweep}")


@pytest.mark.parametrize("cell", CELLS, ids=_cell_id)
def test_short_adversarial_search_finds_no_violation(cell):
    cell = dict(cell, geometry=GEOMETRIES, nominal=SEARCHED_NOMINALS)
    margin = make_filter(cell["filter_name"], preset(cell["robot"]), cell["dt"], **cell.get("settings", {})).margin
    found = search(cell, episodes=16, seed=7, margin=margin)
    valid = [item for item in found if item.outcome.valid]
    assert len(valid) >= 4, "the search must mostly start inside the assumptions"
    worst = min(valid, key=lambda item: item.outcome.objective)
    assert not any(item.outcome.violated for item in valid), worst.episode.to_json()


def test_an_episode_replays_from_its_json_line_exactly():
    episode = decode([0.3] * 18 + [0.8, 0.3], robot="m2wr", filter_name="cbf", base="lag", dt=0.05,
                     give_velocity=True, geometry="poles", nominal="bang_bang", margin=0.04,
                     settings=reproducible_settings("cbf"))   # two runs compared: no compute budget
    assert episode.passage == pytest.approx((0.05 + 1.95 * 0.3, (0.8 - 0.25) / 0.75))
    again = Episode.from_json(episode.to_json())
    assert again == episode
    assert run(again)[0] == run(episode)[0]
    posed = decode([0.3] * 9 + [0.9, 0.8, 0.1] + [0.3] * 6 + [0.8, 0.3], robot="m2wr", filter_name="cbf",
                   base="lag", dt=0.05, give_velocity=True, geometry="poles", nominal="bang_bang", margin=0.04,
                   give_pose=True)
    assert posed.odometry_frame == pytest.approx((800.0, -800.0, math.pi - 0.24))   # near the wrap, far away
    assert Episode.from_json(posed.to_json()) == posed


def test_the_adversary_switches_the_cbfs_passage_flag():
    """The narrow look-ahead is in the search: a schedule of the ``passage`` flag reaches the filter."""
    base = dict(robot="rosbot", filter="cbf", base="ramp_limit", dt=0.05, segments=((0.5, -2.0, 0.5, 2.0),),
                nominal="arc", params=(0.8, 0.0), duration=2.0)
    flagged, log = run(Episode(**base, passage=(0.4, 0.5)), record=True)
    plain, plain_log = run(Episode(**base), record=True)
    assert not flagged.contact and flagged.min_clearance >= flagged.margin - TOLERANCE
    assert any("look-ahead 0 m" in row["message"] for row in log)
    assert not any("look-ahead 0 m" in row["message"] for row in plain_log)
    assert flagged.min_clearance < plain.min_clearance      # the flag lets the body nearer the wall


def test_the_adversary_switches_the_cbfs_narrow_body_and_the_footprint_is_measured():
    """With ``narrow_body`` in the settings the passage schedule sets ``narrow`` too: the m2wr drives at a door only
    its cover fits (the search's doors are that narrow then), the footprint, not the disk, is measured."""
    door = 2.0 * (make_filter("cbf", preset("m2wr"), 0.05).narrow_half_width + 0.02)
    segments = ((0.9, -3.0, 0.9, -0.5 * door), (0.9, 0.5 * door, 0.9, 3.0))
    base = dict(robot="m2wr", filter="cbf", base="ramp_limit", dt=0.05, segments=segments, nominal="arc",
                params=(0.5, 0.0), duration=5.0, passage=(10.0, 1.0))
    narrow, log = run(Episode(**base, settings={"narrow_body": "cover"}), record=True)
    held, held_log = run(Episode(**base), record=True)
    assert not held.contact and held.min_clearance >= held.margin - TOLERANCE
    assert narrow.valid and not narrow.contact and narrow.min_clearance >= narrow.margin - TOLERANCE
    assert any("(a narrow gap)" in row["message"] for row in log)
    assert not any("(a narrow gap)" in row["message"] for row in held_log)
    # Through the door (the footprint 2 cm beyond the margin from each post); the disk stands in front of it.
    assert log[-1]["pose"][0] > 0.9 and held_log[-1]["pose"][0] < 0.7   # its disk at the posts, 0.24 m off the line
    assert narrow.min_clearance < 0.09 + 1e-3
    cells = _cells(["m2wr", "puzzlebot"], ["cbf", "cbf+escape", "mpc"], ["ramp"], [0.05], GEOMETRIES,
                   SEARCHED_NOMINALS, ("disk",), narrow_body="cover")
    assert [cell["settings"].get("narrow_body") for cell in cells] == ["cover", "cover", "cover", None, None, None]
    assert _cell_key(cells[0]) == "m2wr/cbf/narrow-cover"


def test_a_naive_robot_is_caught():
    """The search is not blind: with the filter switched off, the same kind of search finds contacts."""
    episode = Episode(robot="rosbot", filter="zones", base="ramp_limit", dt=0.05, segments=((0.6, -2.0, 0.6, 2.0),),
                      nominal="arc", params=(1.0, 0.0), duration=3.0, settings=dict(stop_distance=0.0,
                                                                                      slowdown_distance=0.0))
    outcome, _ = run(episode)
    assert outcome.valid and outcome.violated


def test_searches_that_take_turns_find_what_each_finds_alone():
    """Cells searched in rounds (one generation of each in turn, as on a process pool or Ray) ask the same
    episodes as each search alone: CMA-ES's draws from numpy's global generator stay per search."""
    from benchmarks.falsify import CellSearch, search_cells

    cells = [dict(robot="rosbot", filter_name="cbf", base="ramp", dt=0.05, give_velocity=True),
             dict(robot="m2wr", filter_name="cbf", base="instant", dt=0.1, give_velocity=False)]
    cells = [dict(cell, geometry=GEOMETRIES, nominal=SEARCHED_NOMINALS, settings=reproducible_settings("cbf"))
             for cell in cells]     # no compute budget: a call preempted past it would brake in one run only
    alone = [search(cell, episodes=12, seed=seed, margin=0.04) for seed, cell in enumerate(cells)]
    in_turns = search_cells([CellSearch(cell, episodes=12, seed=seed, margin=0.04) for seed, cell in enumerate(cells)])
    assert [[f.episode for f in found] for found in in_turns] == [[f.episode for f in found] for found in alone]
    assert [[f.outcome for f in found] for found in in_turns] == [[f.outcome for f in found] for found in alone]


def test_an_interrupted_falsification_resumes_to_the_same_report(tmp_path, capsys):
    from benchmarks import falsify

    argv = ["--episodes", "24", "--robots", "rosbot", "--filters", "cbf", "--dts", "0.05", "--bases", "ramp", "lag",
            "--bodies", "disk", "--seed", "3", "--workers", "1", "--no-progress"]
    results = tmp_path / "results.jsonl"

    def report(*extra):
        path = tmp_path / "falsify.json"
        falsify.main([*argv, *extra, "--json", str(path)])
        written = json.loads(path.read_text())
        written.pop("seconds")
        return written

    whole = report("--results", str(results))
    lines = results.read_text().splitlines(keepends=True)
    assert len(lines) == 2 + 24     # two cells' margins, then every episode
    results.write_text("".join(lines[:13]))   # stopped after the margins and 11 episodes
    capsys.readouterr()
    assert report("--results", str(results), "--resume") == whole
    assert "resumed: 13 jobs taken from" in capsys.readouterr().out
    assert len(results.read_text().splitlines()) == 2 + 24


@pytest.mark.parametrize(("episodes", "cells", "each"), [(20000, 180, 112), (24, 2, 12), (25, 2, 13), (3, 8, 1)])
def test_the_episodes_asked_for_are_spread_over_the_cells_rounded_up(episodes, cells, each):
    assert episodes_per_cell(episodes, cells) == each
    assert each * cells >= episodes


def test_a_robot_of_your_own_is_searched_from_its_json_file_and_its_episodes_replay(tmp_path, capsys):
    from benchmarks import falsify
    from safenav.robot import RobotSpec

    robot = preset("puzzlebot").replace(name="my_bot", v_max=0.8, a_max=0.5, radius=0.15)
    spec_file = tmp_path / "my_bot.json"
    spec_file.write_text(json.dumps(robot.to_dict()))
    path = tmp_path / "falsify.json"
    code = falsify.main(["--episodes", "6", "--robots", "--robot-spec", str(spec_file), "--filters", "cbf",
                         "--dts", "0.05", "--bases", "lag", "--bodies", "disk", "--workers", "1", "--no-progress",
                         "--worst", "1", "--json", str(path)])
    written = json.loads(path.read_text())
    assert code == 0 and list(written["summary"]) == ["my_bot/cbf"]
    assert written["summary"]["my_bot/cbf"]["episodes"] == 6
    worst = Episode.from_json(json.dumps(written["worst"][0]["episode"]))
    assert RobotSpec.from_dict(worst.robot) == robot
    assert run(worst)[0].objective == pytest.approx(written["worst"][0]["objective"])
    assert "my_bot" in capsys.readouterr().out


def test_a_bad_robot_file_names_the_file_and_the_field(tmp_path):
    from benchmarks import falsify
    from safenav.errors import InvalidConfig

    spec_file = tmp_path / "bad.json"
    spec_file.write_text(json.dumps({**preset("rosbot").to_dict(), "wheel_base": 0.2}))
    with pytest.raises(InvalidConfig, match=r"bad\.json: RobotSpec: unknown field 'wheel_base'"):
        falsify.load_robots([str(spec_file)])


def test_the_poles_are_as_thin_as_the_filter_claims_to_see_in_time_and_stand_as_far_as_it_must():
    """A2: a pole at least ``smallest_obstacle`` wide is seen by the time it is ``horizon_reach`` away. The
    decoder's thinnest poles are that wide, out to that reach; ``--min-obstacle-width`` tells the cells."""
    fast = json.loads((Path(__file__).resolve().parents[2] / "benchmarks" / "robots" / "fast_slow_braking.json")
                      .read_text())
    for settings in ({}, {"min_obstacle_width": 0.02}):
        safety = make_filter("mpc", RobotSpec.from_dict(fast), 0.05, **settings)
        low = decode([0.0] * 20, robot=fast, filter_name="mpc", base="ramp", dt=0.05, give_velocity=True,
                     geometry="poles", nominal="arc", margin=safety.margin, settings=settings)
        far = decode([0.999] * 3 + [0.0] * 17, robot=fast, filter_name="mpc", base="ramp", dt=0.05,
                     give_velocity=True, geometry="poles", nominal="arc", margin=safety.margin, settings=settings)
        assert 2.0 * low.circles[0][2] == pytest.approx(safety.smallest_obstacle, rel=1e-3)
        assert math.hypot(*far.circles[0][:2]) > safety.horizon_reach() > 7.0
    cells = _cells(["rosbot"], ["cbf", "mpc+escape", "zones"], ["ramp"], [0.05], ["poles"], ["arc"],
                   min_obstacle_width=0.02)
    assert [cell["settings"].get("min_obstacle_width") for cell in cells] == [0.02, 0.02, None]
    assert _cell_key(cells[0]) == "rosbot/cbf/width-0.02"


def test_the_cells_run_without_compute_budgets_unless_asked_for_real_time():
    """The same seed gives the same report under any load: the CBF and MPC cells (escape or not) run without
    their compute budgets; with ``--real-time`` they keep them (the default, half the period), and the zones,
    which have none, get nothing either way. A cell's name does not change."""
    filters, reproducible = ["cbf", "mpc+escape", "zones"], [math.inf, math.inf, None]
    for real_time, budgets in ((False, reproducible), (True, [None] * 3)):
        cells = _cells(["rosbot"], filters, ["ramp"], [0.05], ["poles"], ["arc"], real_time=real_time)
        assert [cell["settings"].get("budget") for cell in cells] == budgets
        assert [_cell_key(cell) for cell in cells] == ["rosbot/cbf", "rosbot/mpc+escape", "rosbot/zones"]
        assert make_filter("cbf", preset("rosbot"), 0.05, **cells[0]["settings"]).budget == (
            math.inf if not real_time else 0.025)


def test_the_cells_are_searched_again_with_the_filter_called_early_and_late():
    """``--call-periods``: every cell again with the filter called every that many ``dt`` (the filter told the
    time), after the others, so that theirs keep their indices (and seeds); the episodes hold each command that long."""
    cells = _cells(["rosbot"], ["cbf"], ["ramp_limit"], [0.05], ["poles"], ["arc"], call_periods=(0.5, 1.0, 3.0))
    assert [cell.get("call_period") for cell in cells] == [None, 0.5, 3.0]
    assert [_cell_key(cell) for cell in cells] == ["rosbot/cbf", "rosbot/cbf/called-every-0.5dt",
                                                    "rosbot/cbf/called-every-3dt"]
    for cell, period in zip(cells, (None, 0.025, 0.15), strict=True):
        episode = decode(np.full(N_COORDINATES, 0.3), margin=0.05, **cell)
        assert episode.period == (None if period is None else pytest.approx(period))
        _, log = run(dataclasses.replace(episode, duration=0.3), record=True)
        assert len(log) == round(0.3 / (period or 0.05))
        assert ("late" in {row["status"] for row in log[1:]}) == (period == 0.15)    # the first call has no period


def test_the_cells_are_searched_again_with_a_turning_lidar_whose_last_beam_is_measured_when_the_scan_is_taken():
    """``--sweeps``: every cell again with a turning lidar (after the others, so that theirs keep their seeds); its
    scan's last beam is where an instant one looks from, its first one ``scan_time`` earlier, the stamp its time."""
    cells = _cells(["rosbot"], ["cbf"], ["ramp_limit"], [0.05], ["poles"], ["arc"], sweeps=("stated", "unstated"))
    assert [_cell_key(cell) for cell in cells] == ["rosbot/cbf", "rosbot/cbf/sweep-stated", "rosbot/cbf/sweep-unstated"]
    episode = decode(np.full(N_COORDINATES, 0.3), margin=0.05, **cells[1])
    assert Episode.from_json(episode.to_json()) == episode and episode.sweep == "stated"
    robot, scene = preset("rosbot"), Scene((Segment((0.8, -2.0), (0.8, 2.0)),), (Circle((0.0, 0.9), 0.1),))

    def poses_at(times: np.ndarray) -> np.ndarray:
        return _arcs(np.zeros((times.size, 3)), np.tile((0.8, 2.5), (times.size, 1)), times)

    def pose_at(time: float) -> Pose2D:
        return unicycle_step(Pose2D(), 0.8, 2.5, time)

    rng = np.random.default_rng(0)
    stated = _swept_scan(robot, scene, poses_at, 0.4, 0.0, rng, stated=True)
    unstated = _swept_scan(robot, scene, poses_at, 0.4, 0.0, rng, stated=False)
    # ... beam by beam as safenav.synthetic.swept_scan casts it
    np.testing.assert_allclose(stated.ranges, swept_scan(robot, scene, pose_at, stated.stamp).ranges, atol=1e-9)
    step = robot.lidar.scan_time / robot.lidar.n_beams
    assert stated.stamp == pytest.approx(0.4 - (robot.lidar.n_beams - 1) * step)
    assert stated.time_increment == pytest.approx(step) and unstated.time_increment == 0.0
    np.testing.assert_array_equal(stated.ranges, unstated.ranges)
    instant = _scan(robot, scene, pose_at(0.4), 0.0, rng, 0.4)
    assert stated.ranges[-1] == pytest.approx(instant.ranges[-1], abs=1e-12)
    assert not np.allclose(stated.ranges[: robot.lidar.n_beams // 2], instant.ranges[: robot.lidar.n_beams // 2])
