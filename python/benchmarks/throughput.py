"""Environment steps per second from Python: one `schrl.envs.RobotEnv` stepped from a
Python loop, and `RobotVecEnv` (N environments stepped in Rust per call).
Run: .venv/bin/python python/benchmarks/throughput.py [--seconds 3] (BENCHMARKS.md)."""

import argparse
import time

import numpy as np

from schrl.envs import RobotEnv, RobotVecEnv


def rate(step, steps_per_call, seconds):
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step()
        calls += 1
    return calls * steps_per_call / (time.perf_counter() - start)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    for robot in ["point", "car", "drone"]:
        env = RobotEnv(robot)
        env.reset(seed=0)
        actions = rng.uniform(env.action_space.low, env.action_space.high, size=(1024,) + env.action_space.shape)
        k = [0]

        def single():
            k[0] += 1
            _, _, terminated, truncated, _ = env.step(actions[k[0] % 1024])
            if terminated or truncated:
                env.reset()

        print(f"{robot}: single env {rate(single, 1, args.seconds):,.0f} steps/s")
        for n in [16, 256]:
            vec = RobotVecEnv(n, robot=robot)
            vec.reset(seed=0)
            batch = rng.uniform(vec.single_action_space.low, vec.single_action_space.high,
                                size=(n,) + vec.single_action_space.shape)
            print(f"{robot}: vector env, {n} envs {rate(lambda: vec.step(batch), n, args.seconds):,.0f} steps/s")


if __name__ == "__main__":
    main()
