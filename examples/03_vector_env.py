"""The natively batched vector env: many episodes per step in one numba rollout call.

    python examples/03_vector_env.py

``gym.make_vec("soaring/SoaringContinuous-v0", num_envs=B)`` builds
:class:`soaring_env.env.SoaringContinuousVectorEnv` (numpy over all B envs, one kernel call per
step) instead of B Python envs; its transitions equal those of B single envs reset with
``seed + i``. With ``scenario="random"`` every env draws a new scenario at every reset from its own
generator. Finished envs reset on the next step (gymnasium's default ``AutoresetMode.NEXT_STEP``:
that step ignores the action and returns reward 0). The policy here is a vectorized steering rule
on the observation: turn towards the goal and set the path angle that arrives at its height.
"""

from __future__ import annotations

import math
import os
import time

import gymnasium as gym
import numpy as np

import soaring_env  # noqa: F401  (registers the env ids)

QUICK = bool(os.environ.get("SOARING_EXAMPLES_QUICK"))
NUM_ENVS, STEPS = (64, 100) if QUICK else (256, 400)
MAX_TURN = math.radians(1080.0)  # action[1] = +-1: +-1080 deg of turn over one 30 s step
MAX_GAMMA = math.radians(45.0)  # action[2] = +-1: path angle +-45 deg


def steer(obs: np.ndarray) -> np.ndarray:
    """(B, obs) -> (B, 3) actions. Observation entries (see the env's docstring): 0, 1 goal minus
    position north / east [km], 2 goal minus own height [km], 3, 4 sin / cos of the course."""
    bearing = np.arctan2(obs[:, 1], obs[:, 0])
    error = (bearing - np.arctan2(obs[:, 3], obs[:, 4]) + np.pi) % (2 * np.pi) - np.pi
    gamma = np.arctan2(obs[:, 2], np.maximum(np.hypot(obs[:, 0], obs[:, 1]), 0.3))
    speed = np.full(len(obs), -0.5)  # 12.5 m/s: near the best glide
    return np.stack([speed, np.clip(error / MAX_TURN, -1, 1), np.clip(gamma / MAX_GAMMA, -1, 1)], 1).astype(np.float32)


if __name__ == "__main__":
    envs = gym.make_vec("soaring/SoaringContinuous-v0", num_envs=NUM_ENVS, scenario="random")
    obs, info = envs.reset(seed=0)
    print(type(envs.unwrapped).__name__, "observations", obs.shape, "actions", envs.action_space.shape)
    finished = successes = 0
    energy: list[float] = []
    t0 = time.perf_counter()
    for _ in range(STEPS):
        obs, rewards, terminated, truncated, info = envs.step(steer(obs))
        done = terminated | truncated
        finished += int(done.sum())
        successes += int(info["is_success"].sum())
        energy.extend(info["energy_spent"][info["is_success"]])  # [J/kg] of episodes that reached the goal
    dt = time.perf_counter() - t0
    print(f"{STEPS * NUM_ENVS:,} env steps in {dt:.2f} s ({STEPS * NUM_ENVS / dt:,.0f} steps/s)")
    print(
        f"{finished} episodes ended, {successes} at the goal"
        + (f", median energy spent {np.median(energy):.0f} J/kg" if energy else "")
    )
    envs.close()
