"""Scenarios, and every filter in closed loop in the simulator over them.

The closed-loop matrix is the safety claim measured end to end: each tutorial controller
with its robot and world (and the buggy stop-at-wall), RandomWalk in clutter and GoToGoal
through clutter, through a door and round a dead end on each preset, 20 seeds each (``-m slow``),
with the CBF and the MPC, plain and with the deadlock escape; CI runs two seeds of every cell of
the plain filters and the first seed of every go-to-goal cell of the escape rows.
"""

from __future__ import annotations

import numpy as np
import pytest

from safenav import UnknownName
from safenav.episode import EpisodeConfig, run_episode
from safenav.experiments.runner import reproducible_settings
from safenav.filters import make_filter
from safenav.filters.defaults import default_margin
from safenav.scenarios import SCENARIO_NAMES, SCENARIOS, door_width, scenario, scenario_name
from safenav.worlds import START_CLEARANCE, TUTORIALS, Wall, gap, reachable

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
    assert [name for name in SCENARIO_NAMES if SCENARIOS[name].has_goal] == [
        f"{kind}_{robot}" for kind in ("goal", "door", "dead_end") for robot in ("rosbot", "puzzlebot", "m2wr")]


@pytest.mark.parametrize(("world", "robot", "expected"), [
    ("stop_at_wall", None, "stop_at_wall"),
    ("wall_follower", "rosbot", "wall_follower"),   # a tutorial world keeps its name whatever the robot
    ("clutter", None, "clutter_rosbot"),
    ("goal", "m2wr", "goal_m2wr"),
    ("door", "puzzlebot", "door_puzzlebot"),
    ("dead_end", None, "dead_end_rosbot"),
])
def test_the_command_line_names_a_scenario_by_world_and_robot(world, robot, expected):
    assert scenario_name(world, robot) == expected


def test_a_world_that_is_neither_lists_both_kinds():
    with pytest.raises(UnknownName, match="unknown world 'moon'; expected one of: clutter, dead_end, door, goal, "
                                          "obstacle_avoidance"):
        scenario_name("moon")


@pytest.mark.parametrize("robot", ["rosbot", "puzzlebot", "m2wr"])
def test_door_scenario_door_is_two_radius_plus_margin_plus_5_cm_with_the_goal_behind(robot):
    task = scenario(f"door_{robot}")
    spec = task.robot
    expected = 2 * (spec.radius + default_margin(spec)) + 0.05
    assert door_width(spec) == pytest.approx(expected, abs=1e-15)
    assert task.policies == ("go_to_goal",) and task.has_goal
    for seed in range(5):
        world = task.world(seed)
        assert world == task.world(seed)
        low, high = [o for o in world.obstacles if isinstance(o, Wall)][4:]
        assert gap(low, high) == pytest.approx(expected, abs=1e-12)
        assert world.start.x < 0.0 < world.goal[0]                       # start in front, goal behind
        assert world.clearance(world.start, spec.radius) >= START_CLEARANCE
        assert reachable(world, spec.radius, world.start, world.goal)
    assert len({task.world(seed).start for seed in range(5)}) == 5


@pytest.mark.parametrize("robot", ["rosbot", "puzzlebot", "m2wr"])
def test_dead_end_scenario_puts_a_trap_between_start_and_goal(robot):
    task = scenario(f"dead_end_{robot}")
    spec = task.robot
    assert task.policies == ("go_to_goal",) and task.has_goal
    for seed in range(5):
        world = task.world(seed)
        assert world == task.world(seed)
        line = np.linspace(world.start[:2], world.goal, 1001)
        assert np.any(world.signed_distance(line) < 0.0)                 # the straight way is blocked
        assert world.clearance(world.start, spec.radius) >= START_CLEARANCE
        assert reachable(world, spec.radius, world.start, world.goal)
    assert len({task.world(seed).goal for seed in range(5)}) == 5


def closed_loop_cases(filters: tuple[str, ...], ci_cells: list | None = None, ci_seeds: int = 2) -> list:
    """Every cell with each filter on 20 seeds; CI (not slow) runs ``ci_seeds`` of the random walk in clutter
    (where CI found a hole before), one seed of every other cell of ``ci_cells`` (all by default): the default
    suite's time budget."""
    cases = []
    for filter_name in filters:
        for name, policy in CELLS:
            seeds = ci_seeds if policy == "random_walk" else 1
            for seed in range(20):
                in_ci = seed < seeds and (ci_cells is None or (name, policy) in ci_cells)
                marks = [pytest.mark.sim] + ([] if in_ci else [pytest.mark.slow])
                cases.append(pytest.param(name, policy, filter_name, seed, marks=marks,
                                          id=f"{filter_name}-{name}-{policy}-{seed}"))
    return cases


GOAL_CELLS = [(name, policy) for name, policy in CELLS if name.startswith("goal_")]
"""The go-to-goal cells through clutter, where the escape drives: CI runs the escape rows there (the door and
dead-end cells with the escape run under ``-m slow``)."""


@pytest.mark.parametrize(("name", "policy", "filter_name", "seed"),
                         closed_loop_cases(("cbf", "mpc")) +
                         closed_loop_cases(("cbf+escape", "mpc+escape"), ci_cells=GOAL_CELLS, ci_seeds=1))
def test_filtered_robot_never_collides_and_keeps_its_margin(name, policy, filter_name, seed):
    """Acceleration limits are active (the simulator ramps) and the filter gets the odometry velocity.

    The escape rows too: the escape's commands go through the same filter, so they keep its margin.
    """
    task = scenario(name)
    robot = task.robot
    world = task.world(seed)
    # The MPC without its compute budget: on a loaded machine a call over the budget follows the
    # last verified plan (status fallback, "deadline"), which makes the episode depend on the
    # machine's load. The deadline has its own tests (tests/filters/test_mpc_deadline.py, with an
    # injected clock); the time per call is measured in benchmarks/filter_latency.py.
    safety_filter = make_filter(filter_name, robot, DT, **reproducible_settings(filter_name))
    result = run_episode(world, robot, task.policy(policy, world, seed), safety_filter,
                         config=EpisodeConfig(duration=task.duration), seed=seed)
    metrics = result.metrics
    assert not metrics.collided, f"collision at t={metrics.collision_time}"
    assert metrics.min_clearance >= safety_filter.margin - 0.01
    assert metrics.fallbacks == 0
