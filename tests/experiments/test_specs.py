"""Specs: the matrix in table order, bad selections that list the known names, specs checked when made."""

import pickle
import re

import pytest

from safenav import InvalidConfig, UnknownName
from safenav.experiments import Cell, EpisodeSpec, episode_specs, matrix, scenario_for
from safenav.filters import FILTER_NAMES
from safenav.scenarios import SCENARIO_NAMES, scenario

KNOWN_FILTERS = re.escape(", ".join(sorted(FILTER_NAMES)))   # as an unknown name lists the filters' table


def test_matrix_covers_every_scenario_and_policy_in_registry_order():
    cells = matrix()
    pairs = list(dict.fromkeys((cell.scenario, cell.policy) for cell in cells))
    assert pairs == [(name, policy) for name in SCENARIO_NAMES for policy in scenario(name).policies]
    assert len(cells) == 4 * len(pairs)
    assert [cell.filter for cell in cells[:4]] == ["none", "zones", "cbf", "mpc"]


def test_matrix_selects_policies_across_scenarios():
    cells = matrix(policies=["random_walk"], filters=["cbf"])
    assert [cell.scenario for cell in cells] == ["clutter_rosbot", "clutter_puzzlebot", "clutter_m2wr"]
    assert {cell.policy for cell in cells} == {"random_walk"}


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: matrix(scenarios=["moon"]), UnknownName, "unknown scenario 'moon'; expected one of: clutter_m2wr"),
    (lambda: matrix(policies=["dance"]), UnknownName, "unknown policy 'dance'; expected one of: go_to_goal"),
    (lambda: matrix(filters=["magic"]), UnknownName, f"unknown filter 'magic'; expected one of: {KNOWN_FILTERS}"),
    (lambda: matrix(scenarios=["stop_at_wall"], policies=["go_to_goal"]), InvalidConfig, "no scenario"),
    (lambda: scenario_for("stop_at_wall", robot="r2d2"), UnknownName, "unknown robot 'r2d2'"),
    (lambda: scenario_for("wall_follower", policy="go_to_goal"), InvalidConfig, "needs a world with a goal"),
])
def test_bad_selections_say_what_is_known(call, error, message):
    with pytest.raises(error, match=message):
        call()


def test_scenario_for_swaps_the_robot_and_allows_another_policy():
    task = scenario_for("stop_at_wall", robot="puzzlebot", policy="random_walk")
    assert task.robot.name == "puzzlebot"
    assert "random_walk" in task.policies and "stop_at_wall" in task.policies
    assert task.world(3) == scenario("stop_at_wall").world(3)
    same = scenario_for("stop_at_wall")
    assert (same.robot_name, same.policies, same.duration) == ("rosbot", scenario("stop_at_wall").policies, 12.0)


def test_episode_specs_are_in_cell_then_seed_order():
    cells = [Cell("stop_at_wall", "stop_at_wall", "none"), Cell("stop_at_wall", "stop_at_wall", "cbf")]
    specs = episode_specs(cells, range(3), duration=2.0, record_seeds=[1])
    assert [(s.filter, s.seed) for s in specs] == [("none", 0), ("none", 1), ("none", 2),
                                                   ("cbf", 0), ("cbf", 1), ("cbf", 2)]
    assert [s.record for s in specs] == [False, True, False] * 2
    assert {s.duration for s in specs} == {2.0}


SPEC = {"scenario": "stop_at_wall", "policy": "stop_at_wall", "filter": "cbf", "seed": 0}


@pytest.mark.parametrize(("changes", "error", "message"), [
    ({"scenario": "moon"}, UnknownName, "unknown scenario 'moon'; expected one of: clutter_m2wr"),
    ({"policy": "dance"}, UnknownName, "unknown policy 'dance'; expected one of: go_to_goal"),
    ({"filter": "magic"}, UnknownName, f"unknown filter 'magic'; expected one of: {KNOWN_FILTERS}"),
    ({"robot": "r2d2"}, UnknownName, "unknown robot 'r2d2'; expected one of: m2wr, puzzlebot, rosbot"),
    ({"scenario": "wall_follower", "policy": "go_to_goal"}, InvalidConfig, "needs a world with a goal"),
    ({"seed": -1}, InvalidConfig, r"EpisodeSpec\.seed must be an integer >= 0, got -1"),
    ({"seed": 2.5}, InvalidConfig, r"EpisodeSpec\.seed must be an integer >= 0, got 2\.5"),
    ({"duration": -1.0}, InvalidConfig, r"EpisodeSpec\.duration must be a finite number > 0, got -1\.0"),
    ({"record": 1}, InvalidConfig, r"EpisodeSpec\.record must be True or False, got 1"),
    ({"odometry": "yes"}, InvalidConfig, r"EpisodeSpec\.odometry must be True or False, got 'yes'"),
    ({"sim_options": {"dropout": 1.5}}, InvalidConfig, r"SimConfig\.dropout must be a finite number >= 0 and < 1"),
    ({"sim_options": {"base": "hover"}}, UnknownName, "unknown base model .* 'hover'; expected one of: instant, lag"),
    ({"sim_options": {"colour": "red"}}, InvalidConfig, "EpisodeSpec.sim_options: .*'colour'"),
    ({"filter_options": [1, 2]}, InvalidConfig, r"EpisodeSpec\.filter_options must be \(name, value\) pairs"),
    ({"filter_options": [(1, 2)]}, InvalidConfig, r"EpisodeSpec\.filter_options names must be strings, got 1"),
])
def test_a_spec_is_checked_when_it_is_made(changes, error, message):
    with pytest.raises(error, match=message):
        EpisodeSpec(**(SPEC | changes))


def test_a_spec_is_plain_data_that_survives_pickling():
    spec = EpisodeSpec(**SPEC, sim_options={"dropout": 0.1, "base": "lag"}, filter_options=[("margin", 0.1)])
    assert spec.sim_options == (("dropout", 0.1), ("base", "lag")) and spec.filter_options == (("margin", 0.1),)
    assert pickle.loads(pickle.dumps(spec)) == spec
    assert spec.cell == Cell("stop_at_wall", "stop_at_wall", "cbf")
    other = EpisodeSpec("goal_rosbot", "random_walk", "none", 3, robot="m2wr")   # not its own policy, but fits
    assert other.policy == "random_walk" and other.robot == "m2wr"
