"""RandomWalk: within the limits, held, seeded, uniform."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav import preset
from safenav.reference import RandomWalk
from tests.strategies import presets, seeds

# ------------------------------------------------------------------ RandomWalk


@given(
    presets,
    st.integers(1, 7),
    seeds,
    st.booleans(),
    st.integers(1, 60),
)
def test_random_walk_stays_within_limits_and_holds_each_command(name, hold_steps, seed, forward_only, n):
    robot = preset(name)
    policy = RandomWalk(robot, hold_steps=hold_steps, seed=seed, forward_only=forward_only)
    commands = [policy(robot.scan()) for _ in range(n)]
    array = np.array(commands)
    assert np.all(array >= robot.lower) and np.all(array <= robot.upper)
    if forward_only:
        assert np.all(array[:, 0] >= 0.0)
    for i in range(1, n):
        assert (commands[i] == commands[i - 1]) is (i % hold_steps != 0)
    assert policy.command == commands[-1] and policy.calls == n


@given(seeds, st.integers(1, 5))
def test_random_walk_same_seed_same_sequence(seed, hold_steps):
    robot = preset("puzzlebot")
    scan = robot.scan()
    first = RandomWalk(robot, hold_steps=hold_steps, seed=seed)
    second = RandomWalk(robot, hold_steps=hold_steps, seed=seed)
    other = RandomWalk(robot, hold_steps=hold_steps, seed=seed + 1)
    sequence = [first(scan) for _ in range(20)]
    assert [second(scan) for _ in range(20)] == sequence
    assert [other(scan) for _ in range(20)] != sequence
    first.reset(seed)
    assert [first(scan) for _ in range(20)] == sequence


def test_random_walk_reset_without_a_seed_continues_the_stream():
    robot = preset("rosbot")
    policy = RandomWalk(robot, hold_steps=3, seed=7)
    first = policy(robot.scan())
    policy.reset()
    assert policy.state == "idle" and policy.command is None
    assert policy(robot.scan()) != first
    assert policy.state == "new command"
    policy(robot.scan())
    assert policy.state == "hold"


def test_random_walk_draws_uniformly_over_the_limits():
    robot = preset("m2wr")
    policy = RandomWalk(robot, hold_steps=1, seed=3)
    draws = np.array([policy(robot.scan()) for _ in range(4000)])
    for column, low, high in ((0, robot.v_min, robot.v_max), (1, -robot.omega_max, robot.omega_max)):
        values = (draws[:, column] - low) / (high - low)  # uniform on [0, 1)
        assert values.min() < 0.01 and values.max() > 0.99
        assert values.mean() == pytest.approx(0.5, abs=0.02)
        assert np.histogram(values, bins=4, range=(0, 1))[0] == pytest.approx([1000] * 4, rel=0.1)
