"""Helpers of the Gymnasium tests: a seeded random agent and a strict ``check_env``.

Every test module here starts with ``pytest.importorskip("gymnasium")``: without the ``gym``
extra the Gymnasium tests are skipped, with the reason.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

SKIP_REASON = 'the Gymnasium layer needs the gym extra: pip install "safenav[gym]"'
EXPECTED_WARNINGS = (
    "we recommend using a symmetric and normalized space",   # the action box is (v, omega) in SI units, by design
    "is different from the unwrapped version",                # check_env on a wrapped (shielded) environment
    "Not able to test alternative render modes",              # an environment made without gymnasium.make
)

HOLD_STEPS = 40
"""The random agent holds each sampled action this many steps (2 s at 0.05 s), like a random walk."""


@dataclass
class EpisodeRecord:
    """What one episode of the random agent did."""

    observations: list[Any] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    collided: bool = False
    min_clearance: float = np.inf
    statuses: list[str] = field(default_factory=list)
    infos: list[dict] = field(default_factory=list)


def check_env_quietly(env: Any) -> None:
    """Gymnasium's ``check_env``, failing on any warning but the expected ones."""
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    unexpected = [str(w.message) for w in caught if not any(text in str(w.message) for text in EXPECTED_WARNINGS)]
    assert not unexpected


def random_episode(env: Any, seed: int, steps: int, hold: int = HOLD_STEPS) -> EpisodeRecord:
    """Run the random agent (``env.action_space.sample()``, seeded by ``reset(seed=...)``) for up to ``steps``."""
    record = EpisodeRecord()
    observation, info = env.reset(seed=seed)
    record.observations.append(observation)
    record.min_clearance = info["clearance"]
    for step in range(steps):
        if step % hold == 0:
            action = env.action_space.sample()
        observation, reward, terminated, truncated, info = env.step(action)
        record.observations.append(observation)
        record.rewards.append(reward)
        record.infos.append(info)
        record.collided |= info["collision"]
        record.min_clearance = min(record.min_clearance, info["clearance"])
        if "shield" in info:
            record.statuses.append(info["shield"]["status"])
        if terminated or truncated:
            break
    return record
