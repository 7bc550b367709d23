"""stable-baselines3's PPO on schrl's Point robot (`schrl/Point-v0`): one goal per
episode, the reward is progress towards it plus a bonus on reaching it.

    bash scripts/setup-python.sh          # schrl and stable-baselines3 into .venv
    .venv/bin/python python/examples/sb3_ppo_point.py --steps 200000

Prints the fraction of 100 fresh goals reached by the trained policy (its mean
action), and saves the model to --out.
"""

import argparse

import gymnasium as gym
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env

import schrl.envs  # noqa: F401  (registers schrl/Point-v0, schrl/Car-v0, schrl/Drone-v0)


def goals_reached(model, episodes, seed):
    env = gym.make("schrl/Point-v0")
    reached = 0
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        done = False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
            reached += bool(info["reached"])
            done = terminated or truncated or info["reached"]
    return reached / episodes


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=200_000, help="environment steps of training")
    parser.add_argument("--envs", type=int, default=8, help="environments stepped together")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="ppo_point", help="where the model is saved (.zip)")
    args = parser.parse_args()
    envs = make_vec_env("schrl/Point-v0", n_envs=args.envs, seed=args.seed)
    model = PPO("MlpPolicy", envs, seed=args.seed, device="cpu", verbose=0)
    model.learn(total_timesteps=args.steps, progress_bar=False)
    model.save(args.out)
    print(f"goals reached: {goals_reached(model, 100, seed=10_000 + args.seed):.2f} of 100; model in {args.out}.zip")


if __name__ == "__main__":
    main()
