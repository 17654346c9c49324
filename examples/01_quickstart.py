"""Quick start: the two Gymnasium envs, a random and a heuristic policy, and the energy they spend.

    python examples/01_quickstart.py

``soaring/Soaring-v0`` flies one of 174 motion primitives per step (``Discrete(174)``);
``soaring/SoaringContinuous-v0`` holds a normalized (airspeed, turn rate, path angle) in [-1, 1]^3
for the same 30 s. Both start on the ``"paper"`` scenario: one thermal between the start and a
goal 3 km north. The first run compiles the numba kernels (the package says so on stderr).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import soaring_env  # noqa: F401  (importing it registers the env ids)
from baselines.agents import HeuristicAgent


def fly(env: gym.Env, policy: str, seed: int = 0) -> None:
    """One episode; ``policy`` is ``"random"`` or ``"heuristic"`` (head for the goal, circle in lift)."""
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    agent = HeuristicAgent()
    agent.reset(env, seed)
    done, ret = False, 0.0
    while not done:
        if policy == "heuristic":
            action, _ = agent.predict(obs)
        elif env.action_space.shape == ():  # discrete: a random primitive among the safe ones
            action = int(rng.choice(np.flatnonzero(env.unwrapped.action_masks())))
        else:
            action = rng.uniform(-1.0, 1.0, size=3).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        ret += float(reward)
        done = terminated or truncated
    # info (SI units): energy_spent [J/kg] over the episode, outcome "goal" / "crash" / ..., time [s]
    end = info["outcome"] if terminated else "time limit"  # truncated after 40 steps (20 min)
    print(
        f"  {policy:9s}: {end:13s} after {info['time']:5.0f} s, "
        f"energy spent {info['energy_spent']:8.1f} J/kg, return {ret:6.2f}"
    )


if __name__ == "__main__":
    for env_id in ("soaring/Soaring-v0", "soaring/SoaringContinuous-v0"):
        env = gym.make(env_id)
        print(f"{env_id}: actions {env.action_space}, observations {env.observation_space.shape}")
        for policy in ("random", "heuristic"):
            fly(env, policy)
        env.close()
