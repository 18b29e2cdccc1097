"""One seed per episode, independent random streams for everything random in it.

An episode has one integer seed. Each random part of it draws from its own stream,
spawned from that seed by :class:`numpy.random.SeedSequence` (``SeedSequence(seed).spawn``):

==============  ==================================================================
stream          drawn by
==============  ==================================================================
``world``       :func:`~safenav.worlds.random_world`, and the start jitter of the tutorial scenarios
``sensor``      the simulator's range noise and beam dropout
``actuation``   the simulator's actuation noise
``policy``      random nominal policies (:class:`~safenav.reference.RandomWalk`)
==============  ==================================================================

Every part is given the *episode* seed and takes its own stream from it, so the same
seed gives the same episode, and changing one part (more noise draws, another policy)
leaves the others' draws alone: ``random_world(7, robot)`` is the world of episode 7
whatever the simulator or the policy does with their streams::

    from safenav.seeding import generator

    rng = generator(seed, "sensor")     # the sensor-noise stream of episode ``seed``
"""

from __future__ import annotations

import numpy as np

from safenav._checks import choice, optional_integer

__all__ = ["STREAMS", "generator", "stream"]

STREAMS = ("world", "sensor", "actuation", "policy")
"""The streams of an episode, in the order they are spawned (a new stream goes at the end)."""


def stream(seed: int | None, name: str) -> np.random.SeedSequence:
    """The seed sequence of stream ``name`` of the episode ``seed``.

    Args:
        seed: the episode's seed, an integer >= 0; ``None`` takes fresh entropy from the
            operating system (a different episode every time).
        name: one of :data:`STREAMS`.

    Raises:
        InvalidConfig: ``seed`` is not ``None`` or an integer >= 0.
        UnknownName: ``name`` is not a stream.
    """
    seed = optional_integer("seed", seed, low=0)
    choice("random stream", name, STREAMS)
    return np.random.SeedSequence(seed).spawn(len(STREAMS))[STREAMS.index(name)]


def generator(seed: int | None, name: str) -> np.random.Generator:
    """A generator drawing stream ``name`` of the episode ``seed`` (see :func:`stream`)."""
    return np.random.default_rng(stream(seed, name))

