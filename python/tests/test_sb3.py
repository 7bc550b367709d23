"""stable-baselines3 on schrl's robots: its own environment checker passes, and its PPO
steps schrl/Point-v0 and learns from it (a tiny budget: the policy changes)."""

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.env_util import make_vec_env

import schrl.envs  # registers the ids


@pytest.mark.parametrize("name", list(schrl.envs.ROBOTS))
def test_sb3s_checker_passes(name):
    check_env(gym.make(f"schrl/{name}-v0").unwrapped, warn=False)


def test_sb3_ppo_trains_on_point():
    envs = make_vec_env("schrl/Point-v0", n_envs=2, seed=0)
    model = PPO("MlpPolicy", envs, n_steps=64, batch_size=64, n_epochs=2, seed=0, device="cpu")
    obs = envs.reset()
    before, _ = model.predict(obs, deterministic=True)
    model.learn(total_timesteps=256)
    after, _ = model.predict(obs, deterministic=True)
    assert model.num_timesteps == 256
    assert not np.allclose(before, after)
