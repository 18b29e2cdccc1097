"""One seed per episode: independent streams for the world, the sensor, the actuation and the policy."""

import numpy as np
import pytest
from hypothesis import given

from safenav import InvalidConfig, UnknownName, preset
from safenav.reference import RandomWalk
from safenav.scenarios import scenario
from safenav.seeding import STREAMS, generator, stream
from safenav.worlds import random_world
from tests.strategies import seeds


@given(seeds)
def test_a_stream_is_the_spawned_child_of_the_episode_seed(seed):
    children = np.random.SeedSequence(seed).spawn(len(STREAMS))
    for index, name in enumerate(STREAMS):
        assert stream(seed, name).generate_state(4).tolist() == children[index].generate_state(4).tolist()
        assert generator(seed, name).random(3).tolist() == generator(seed, name).random(3).tolist()


def test_the_streams_of_one_seed_differ_from_each_other_and_from_the_plain_seed():
    draws = [generator(7, name).random(4).tolist() for name in STREAMS]
    draws.append(np.random.default_rng(7).random(4).tolist())   # what a user's own policy would draw
    assert len({tuple(d) for d in draws}) == len(STREAMS) + 1


def test_no_seed_draws_fresh_entropy():
    assert generator(None, "policy").random(4).tolist() != generator(None, "policy").random(4).tolist()


@pytest.mark.parametrize(("seed", "name", "error", "message"), [
    (-1, "world", InvalidConfig, "seed must be an integer >= 0 or None, got -1"),
    (1.5, "world", InvalidConfig, "seed must be an integer >= 0 or None, got 1.5"),
    (True, "world", InvalidConfig, "seed must be an integer >= 0 or None, got True"),
    (0, "wind", UnknownName, "unknown random stream 'wind'; expected one of: actuation, policy, sensor, world"),
])
def test_bad_seeds_and_streams(seed, name, error, message):
    with pytest.raises(error, match=message):
        stream(seed, name)


def test_each_part_of_an_episode_draws_its_own_stream():
    robot = preset("puzzlebot")
    assert scenario("clutter_puzzlebot").world(11) == random_world(11, robot, n_obstacles=30)
    expected = generator(11, "policy").uniform(robot.lower, robot.upper)
    assert tuple(RandomWalk(robot, seed=11)(robot.scan())) == pytest.approx(tuple(expected), abs=0)
    jitter = generator(11, "world").uniform(-0.1, 0.1, 2)
    start = scenario("stop_at_wall").world(11).start
    assert (start.x, start.y) == pytest.approx(tuple(jitter), abs=1e-15)
