"""The environments under Gymnasium's vector environments, shielded and not."""

from __future__ import annotations

import numpy as np
import pytest

from tests.gym.conftest import SKIP_REASON

gymnasium = pytest.importorskip("gymnasium", reason=SKIP_REASON)

from safenav.gym import SafetyShield  # noqa: E402 - after the importorskip

N_ENVS = 2
STEPS = 40


def _maker(shielded: bool):
    def make():
        import gymnasium

        import safenav.gym  # noqa: F401 - registers the ids in a fresh worker process

        env = gymnasium.make("safenav/ObstacleAvoidance-v0", info_scan=False)
        return SafetyShield(env) if shielded else env

    return make


def _rollout(vector, actions: np.ndarray) -> tuple[list, list, list]:
    observations, rewards, shield_statuses = [vector.reset(seed=4)[0]], [], []
    for action in actions:
        observation, reward, _, _, info = vector.step(action)
        observations.append(observation)
        rewards.append(reward)
        shield_statuses.append(info.get("shield", {}).get("status"))
    return observations, rewards, shield_statuses


@pytest.mark.parametrize("shielded", [False, True], ids=["plain", "shielded"])
def test_sync_and_async_vector_envs_give_the_episodes_of_the_single_envs(shielded: bool) -> None:
    rng = np.random.default_rng(0)
    single = _maker(shielded)()
    actions = rng.uniform(single.action_space.low, single.action_space.high,
                          (STEPS, N_ENVS, 2)).astype(np.float32)
    runs = []
    for vector_class in (gymnasium.vector.SyncVectorEnv, gymnasium.vector.AsyncVectorEnv):
        vector = vector_class([_maker(shielded) for _ in range(N_ENVS)])
        assert vector.single_action_space == single.action_space
        runs.append(_rollout(vector, actions))
        vector.close()
    (sync_obs, sync_rewards, sync_status), (async_obs, async_rewards, async_status) = runs
    for a, b in zip(sync_obs, async_obs, strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    np.testing.assert_array_equal(sync_rewards, async_rewards)
    # Sub-environment i of reset(seed=4) is the single environment reset with seed 4 + i.
    for index in range(N_ENVS):
        observation, _ = single.reset(seed=4 + index)
        np.testing.assert_array_equal(observation["lidar"], sync_obs[0]["lidar"][index])
        for step in range(5):
            observation, reward, _, _, _ = single.step(actions[step, index])
            assert reward == sync_rewards[step][index]
    single.close()
    if shielded:
        assert all(status is not None and set(status) <= {"ok", "recovering", "slack"} for status in sync_status)
        np.testing.assert_array_equal(sync_status, async_status)
