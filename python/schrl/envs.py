"""schrl's robots as Gymnasium environments.

``RobotEnv(robot, map=None)`` is one robot chasing a random goal in an open map (empty
plane; floor for the Drone) or a named one (``"walls"``, ``"duck"``), stepped by
schrl's Rust simulator. Registered ids: ``schrl/Point-v0``, ``schrl/Car-v0``,
``schrl/Drone-v0``, and ``schrl/Doggo-v0`` in a build with MuJoCo
(``schrl.envs.MUJOCO``; ``gymnasium.make``), and the same ids with ``gymnasium.make_vec``
give :class:`RobotVecEnv`, N environments stepped together in Rust::

    import gymnasium as gym
    import schrl.envs  # registers the ids

    env = gym.make("schrl/Point-v0", render_mode="rgb_array")
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    frame = env.render()                              # [H, W, 3] uint8

    envs = gym.make_vec("schrl/Point-v0", num_envs=64, vectorization_mode="vector_entry_point")

Reward: the decrease of the distance to the goal, plus a bonus on reaching it;
``terminated`` on a collision (or a fall), ``truncated`` at the step limit;
``info``: ``reached``, ``collided``, ``fell``. ``reset(options={"start": xy, "goal":
xy})`` places the robot and the goal; :meth:`RobotEnv.set_goal` moves the goal
mid-episode (a new waypoint).

``observe_track=True`` (``gym.make(..., observe_track=True)``, both classes) ends every
observation with the robot's offset from its *track*, the straight segment from where
the goal was set (or ``set_goal(goal, origin=...)``, a planned segment's first
waypoint) to the goal: the nearest point of the segment less the robot's position, in
the robot's heading frame (forward, left; up for the Drone). schrl's Doggo controllers
observe it by default (README, *The track in the controller's observation*); the other
robots' observations, and this option's default, are the paper's.
"""

import numpy as np
import gymnasium as gym
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ._schrl import MUJOCO, NativeEnv, NativeVecEnv

# The robots of this build: the Doggo needs a wheel built with the `mujoco` feature.
ROBOTS = {"Point": "point", "Car": "car", "Drone": "drone", **({"Doggo": "doggo"} if MUJOCO else {})}
_SEED_RANGE = 2**63


def _box(bounds):
    low, high = bounds
    return spaces.Box(np.array(low, dtype=np.float64), np.array(high, dtype=np.float64), dtype=np.float64)


class RobotEnv(gym.Env):
    """One robot and its goal (see the module's documentation)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, robot="point", map=None, max_episode_steps=None, render_mode=None, observe_track=False):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self._native = NativeEnv(robot, map, bool(observe_track))
        self.robot = robot
        self.observation_space = _box(self._native.observation_bounds)
        self.action_space = _box(self._native.action_bounds)
        self.render_mode = render_mode
        if max_episode_steps is not None:
            self._native.set_max_steps(int(max_episode_steps))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        options = options or {}
        unknown = set(options) - {"start", "goal"}
        if unknown:
            raise ValueError(f"reset options: unknown {sorted(unknown)}; expected 'start' and/or 'goal'")
        start = options.get("start")
        start = None if start is None else [float(x) for x in start]
        obs = self._native.reset(int(self.np_random.integers(_SEED_RANGE)), start)
        if options.get("goal") is not None:
            obs = self._native.set_goal([float(x) for x in options["goal"]])
        return obs, {"goal": np.array(self._native.goal)}

    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        if action.shape != self.action_space.shape:
            raise ValueError(f"action: expected shape {self.action_space.shape}, got {action.shape}")
        obs, reward, terminated, truncated, info = self._native.step(action.tolist())
        return obs, float(reward), bool(terminated), bool(truncated), info

    def set_goal(self, goal, origin=None):
        """Moves the goal (a free position); returns the observation that sees it. The
        track starts at ``origin`` if given, else where the robot stands."""
        origin = None if origin is None else [float(x) for x in origin]
        return self._native.set_goal([float(x) for x in goal], origin)

    @property
    def goal_origin(self):
        """Where the track to the goal starts."""
        return np.array(self._native.goal_origin)

    @property
    def observe_track(self):
        """Whether observations end with the robot's offset from its track."""
        return bool(self._native.observe_track)

    @property
    def position(self):
        """The robot's position (x, y; x, y, z for the Drone)."""
        return np.array(self._native.position)

    @property
    def goal(self):
        """The goal."""
        return np.array(self._native.goal)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() without render_mode='rgb_array' returns nothing")
            return None
        return self._native.render()


class RobotVecEnv(VectorEnv):
    """N environments of one robot stepped together in Rust, with Gymnasium's
    next-step autoreset: the step after an episode ends resets that environment
    (its action ignored, reward 0) and returns its first observation."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs, robot="point", map=None, observe_track=False):
        self._native = NativeVecEnv(robot, int(num_envs), map, bool(observe_track))
        self.num_envs = int(num_envs)
        self.robot = robot
        self.single_observation_space = _box(self._native.observation_bounds)
        self.single_action_space = _box(self._native.action_bounds)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._autoreset[:] = False
        return self._native.reset(int(self.np_random.integers(_SEED_RANGE))), {}

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.float64)
        if actions.shape != self.action_space.shape:
            raise ValueError(f"actions: expected shape {self.action_space.shape}, got {actions.shape}")
        obs, rewards, terminated, truncated, reached = self._native.step(actions.tolist())
        for i in np.flatnonzero(self._autoreset):
            obs[i] = self._native.reset_one(int(i), int(self.np_random.integers(_SEED_RANGE)))
            rewards[i], terminated[i], truncated[i], reached[i] = 0.0, False, False, False
        self._autoreset = terminated | truncated
        return obs, rewards, terminated, truncated, {"reached": reached}


for _name, _robot in ROBOTS.items():
    _id = f"schrl/{_name}-v0"
    if _id not in gym.registry:
        gym.register(
            id=_id,
            entry_point="schrl.envs:RobotEnv",
            vector_entry_point="schrl.envs:RobotVecEnv",
            kwargs={"robot": _robot},
        )
