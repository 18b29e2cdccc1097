"""Scenarios, and every filter in closed loop in the simulator over them.

The closed-loop matrix is the safety claim measured end to end: each tutorial controller
with its robot and world (and the buggy stop-at-wall), RandomWalk in clutter and GoToGoal
through clutter on each preset, 20 seeds each (``-m slow``); CI runs two seeds of every cell.
"""

from __future__ import annotations

import math

import pytest

from safenav import UnknownName
from safenav.episode import EpisodeConfig, run_episode
from safenav.filters import make_filter
from safenav.scenarios import SCENARIO_NAMES, SCENARIOS, scenario, scenario_name
from safenav.worlds import TUTORIALS

DT = 0.05

CELLS = [(name, policy) for name in SCENARIO_NAMES for policy in scenario(name).policies]


def test_registry_covers_the_tutorials_clutter_and_goals():
    assert {"stop_at_wall", "obstacle_avoidance", "wall_follower"} <= set(SCENARIO_NAMES)
    tutorial_policy = {tutorial.robot: tutorial.policy for tutorial in TUTORIALS.values()}
    for robot in ("rosbot", "puzzlebot", "m2wr"):
        assert "random_walk" in scenario(f"clutter_{robot}").policies
        assert tutorial_policy[robot] in scenario(f"clutter_{robot}").policies
        assert scenario(f"goal_{robot}").policies == ("go_to_goal",)
        assert scenario(f"goal_{robot}").world(0).goal is not None
    assert "stop_at_wall_buggy" in scenario("stop_at_wall").policies


def test_seeds_perturb_the_tutorial_start_and_draw_new_random_worlds():
    tutorial = scenario("stop_at_wall")
    assert tutorial.world(0).start != tutorial.world(1).start
    assert tutorial.world(3).start == tutorial.world(3).start
    assert abs(tutorial.world(1).start.x) <= 0.1 and abs(tutorial.world(1).start.yaw) <= 0.1
    clutter = scenario("clutter_puzzlebot")
    assert clutter.world(0).obstacles != clutter.world(1).obstacles


def test_unknown_names_list_the_known_ones():
    with pytest.raises(UnknownName, match="unknown scenario 'mars'; expected one of: clutter_m2wr"):
        scenario("mars")
    world = scenario("wall_follower").world(0)
    with pytest.raises(UnknownName, match="expected one of: wall_follower"):
        scenario("wall_follower").policy("go_to_goal", world, 0)


def test_the_table_is_built_once_and_read_only():
    assert tuple(SCENARIOS) == SCENARIO_NAMES and scenario("goal_m2wr") is SCENARIOS["goal_m2wr"]
    with pytest.raises(TypeError):
        SCENARIOS["moon"] = SCENARIOS["goal_m2wr"]
    for name, tutorial in TUTORIALS.items():   # the tutorial scenarios come from the tutorial table
        task = scenario(name)
        assert (task.robot_name, task.duration, task.description) == (tutorial.robot, tutorial.duration,
                                                                       tutorial.description)
        assert task.policies[0] == tutorial.policy and tutorial.published_policy in task.policies
        assert not task.has_goal
    assert [name for name in SCENARIO_NAMES if SCENARIOS[name].has_goal] == ["goal_rosbot", "goal_puzzlebot",
                                                                               "goal_m2wr"]


@pytest.mark.parametrize(("world", "robot", "expected"), [
    ("stop_at_wall", None, "stop_at_wall"),
    ("wall_follower", "rosbot", "wall_follower"),   # a tutorial world keeps its name whatever the robot
    ("clutter", None, "clutter_rosbot"),
    ("goal", "m2wr", "goal_m2wr"),
])
def test_the_command_line_names_a_scenario_by_world_and_robot(world, robot, expected):
    assert scenario_name(world, robot) == expected


def test_a_world_that_is_neither_lists_both_kinds():
    with pytest.raises(UnknownName, match="unknown world 'moon'; expected one of: clutter, goal, obstacle_avoidance"):
        scenario_name("moon")


def closed_loop_cases(filters: tuple[str, ...]) -> list:
    cases = []
    for filter_name in filters:
        for name, policy in CELLS:
            for seed in range(20):
                marks = [pytest.mark.sim] + ([pytest.mark.slow] if seed >= 2 else [])
                cases.append(pytest.param(name, policy, filter_name, seed, marks=marks,
                                          id=f"{filter_name}-{name}-{policy}-{seed}"))
    return cases


@pytest.mark.parametrize(("name", "policy", "filter_name", "seed"), closed_loop_cases(("cbf", "mpc")))
def test_filtered_robot_never_collides_and_keeps_its_margin(name, policy, filter_name, seed):
    """Acceleration limits are active (the simulator ramps) and the filter gets the odometry velocity."""
    task = scenario(name)
    robot = task.robot
    world = task.world(seed)
    # The MPC without its compute budget: on a loaded machine a call over the budget follows the
    # last verified plan (status fallback, "deadline"), which makes the episode depend on the
    # machine's load. The deadline has its own tests (tests/filters/test_mpc_deadline.py, with an
    # injected clock); the time per call is measured in benchmarks/filter_latency.py.
    settings = {"budget": math.inf} if filter_name == "mpc" else {}
    safety_filter = make_filter(filter_name, robot, DT, **settings)
    result = run_episode(world, robot, task.policy(policy, world, seed), safety_filter,
                         config=EpisodeConfig(duration=task.duration), seed=seed)
    metrics = result.metrics
    assert not metrics.collided, f"collision at t={metrics.collision_time}"
    assert metrics.min_clearance >= safety_filter.margin - 0.01
    assert metrics.fallbacks == 0
