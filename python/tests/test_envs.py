"""schrl.envs: Gymnasium's checker passes, ids are registered, episodes are seeded,
goals and starts can be set, frames render, the vector env steps and autoresets."""

import os

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import schrl.envs
from schrl.envs import ROBOTS, RobotEnv, RobotVecEnv


def test_the_doggo_is_there_exactly_when_built_with_mujoco():
    # CI builds a second wheel with SCHRL_PYTHON_FEATURES=mujoco and says so here.
    assert ("Doggo" in ROBOTS) == schrl.envs.MUJOCO
    if os.environ.get("SCHRL_EXPECT_MUJOCO") == "1":
        assert schrl.envs.MUJOCO, "the wheel was built without the mujoco feature"
    if not schrl.envs.MUJOCO:
        with pytest.raises(ValueError, match="mujoco"):
            RobotEnv("doggo")


@pytest.mark.parametrize("robot", list(ROBOTS.values()))
def test_gymnasiums_checker_passes(robot):
    check_env(gym.make(f"schrl/{robot.title()}-v0", render_mode="rgb_array").unwrapped, skip_render_check=False)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_ids_are_registered(name):
    env = gym.make(f"schrl/{name}-v0")
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    assert "goal" in info
    vec = gym.make_vec(f"schrl/{name}-v0", num_envs=4, vectorization_mode="vector_entry_point")
    obs, _ = vec.reset(seed=3)
    assert obs.shape == (4,) + env.observation_space.shape


def rollout(env, seed, steps=200):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    out = [obs]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        out.append(obs)
        if terminated or truncated:
            break
    return np.array(out)


def test_the_same_seed_gives_the_same_episode():
    a, b, c = (rollout(RobotEnv("car"), s) for s in (5, 5, 6))
    np.testing.assert_array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(a, c)


def test_starts_and_goals_can_be_set_and_driving_at_the_goal_reaches_it():
    env = RobotEnv("point")
    env.reset(seed=0, options={"start": [0.0, 0.0], "goal": [1.0, 0.0]})
    np.testing.assert_allclose(env.position, [0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(env.goal, [1.0, 0.0])
    # The goal-following reward: moving towards the goal is paid, reaching it ends in a bonus.
    reached, total = False, 0.0
    for _ in range(400):
        to_goal = env.goal - env.position
        # Point: turn towards the goal, drive forwards.
        heading = env.unwrapped._native.heading
        bearing = np.arctan2(to_goal[1], to_goal[0]) - heading
        turn = np.clip(np.arctan2(np.sin(bearing), np.cos(bearing)), -1, 1)
        _, reward, terminated, truncated, info = env.step(np.array([1.0 if abs(turn) < 0.5 else 0.0, turn]))
        total += reward
        if info["reached"]:
            reached = True
            break
        assert not terminated
    assert reached and total > 1.0
    with pytest.raises(ValueError, match="unknown"):
        env.reset(seed=0, options={"begin": [0, 0]})
    with pytest.raises(ValueError):
        env.step(np.zeros(5))


@pytest.mark.parametrize("robot", list(ROBOTS.values()))
def test_the_track_offset_points_from_the_robot_to_its_segment_in_its_own_frame(robot):
    plain, tracked = RobotEnv(robot), RobotEnv(robot, observe_track=True)
    dim = len(tracked.position)
    assert tracked.observe_track and not plain.observe_track
    assert tracked.observation_space.shape[0] == plain.observation_space.shape[0] + dim
    check_env(tracked, skip_render_check=True)
    start = [0.0, 0.0, 1.0][:dim]
    obs, _ = tracked.reset(seed=4, options={"start": start, "goal": [2.0, 0.0, 1.0][:dim]})
    # Right after a reset the track starts where the robot stands: no offset.
    np.testing.assert_allclose(tracked.goal_origin, tracked.position)
    np.testing.assert_allclose(obs[-dim:], 0.0, atol=1e-9)
    # A segment along y = 1 from x = -1 to 1, the robot near the origin: the offset is
    # (0, 1 - y) in the world, turned into the robot's heading frame (forward, left).
    x, y = tracked.position[:2]
    assert abs(x) < 0.5 and abs(y) < 0.5
    obs = tracked.set_goal([1.0, 1.0, 1.0][:dim], origin=[-1.0, 1.0, 1.0][:dim])
    np.testing.assert_allclose(tracked.goal_origin, [-1.0, 1.0, 1.0][:dim])
    heading = tracked.unwrapped._native.heading
    np.testing.assert_allclose(obs[-dim:][:2], (1.0 - y) * np.array([np.sin(heading), np.cos(heading)]), atol=1e-9)
    if dim == 3:
        np.testing.assert_allclose(obs[-1], 1.0 - tracked.position[2], atol=1e-9)
    # The vector env observes the same extra entries.
    vec = RobotVecEnv(2, robot=robot, observe_track=True)
    assert vec.single_observation_space.shape == tracked.observation_space.shape


def test_frames_are_rgb_arrays():
    env = RobotEnv("drone", map="duck", render_mode="rgb_array")
    env.reset(seed=1)
    for _ in range(10):
        env.step(env.action_space.sample())
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 3


def test_the_vector_env_steps_in_rust_and_autoresets_on_the_next_step():
    vec = RobotVecEnv(8, robot="point")
    obs, _ = vec.reset(seed=0)
    singles = [RobotEnv("point") for _ in range(8)]
    assert obs.shape == (8, singles[0].observation_space.shape[0])
    vec.action_space.seed(0)
    ended = np.zeros(8, dtype=bool)
    for _ in range(1200):
        obs, rewards, terminated, truncated, info = vec.step(vec.action_space.sample())
        assert rewards.shape == (8,) and terminated.dtype == bool
        if ended.any():
            # The step after an end resets: no reward, not done.
            assert np.all(rewards[ended] == 0.0) and not np.any((terminated | truncated)[ended])
        ended = terminated | truncated
    assert vec.single_observation_space.contains(obs[0].astype(np.float64))
    with pytest.raises(ValueError, match="expected shape"):
        vec.step(np.zeros((3, 2)))
