"""Train MaskablePPO for a few thousand steps on random scenarios, then evaluate it (needs the
``ppo`` extra: ``pip install -e ".[ppo]"``).

    python examples/04_train_ppo.py                         # 8,192 steps (about 15 s)
    SOARING_EXAMPLES_QUICK=1 python examples/04_train_ppo.py  # 2,048 steps

:class:`soaring_env.env.sb3.SoaringSB3VecEnv` is the natively batched env behind stable-baselines3's
``VecEnv`` interface; ``action_masks()`` (primitives that would crash or leave the domain are
masked) is what sb3-contrib's MaskablePPO asks it for. So few steps teach little -- the point is
the API; ``scripts/train_ppo.py`` trains the baselines for minutes (``baselines.ppo``: body-frame
observations, validation, checkpoints) and ``baselines.agents.PPOAgent`` loads what it saves.
"""

from __future__ import annotations

import os

import gymnasium as gym
import torch
from sb3_contrib import MaskablePPO

import soaring_env  # noqa: F401  (registers the env ids)
from soaring_env.env.sb3 import SoaringSB3VecEnv
from soaring_env.scenario import heldout_names

QUICK = bool(os.environ.get("SOARING_EXAMPLES_QUICK"))
STEPS = 2_048 if QUICK else 8_192


def evaluate(model: MaskablePPO, scenario: str) -> str:
    """One deterministic episode on ``scenario`` through a single env; a one-line summary."""
    env = gym.make("soaring/Soaring-v0", scenario=scenario)
    obs, _ = env.reset(seed=0)
    while True:
        action, _ = model.predict(obs, action_masks=env.unwrapped.action_masks(), deterministic=True)
        obs, _, terminated, truncated, info = env.step(int(action))
        if terminated or truncated:
            break
    env.close()
    end = info["outcome"] if terminated else "time limit"
    return f"{scenario:13s} {end:13s} energy spent {info['energy_spent']:8.0f} J/kg"


if __name__ == "__main__":
    torch.set_num_threads(1)  # the env, not the small MLP, is the bottleneck on a few cores
    venv = SoaringSB3VecEnv(num_envs=8, scenario="random")  # a new random scenario at every reset
    model = MaskablePPO("MlpPolicy", venv, n_steps=128, batch_size=256, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=STEPS)
    print(f"trained {model.num_timesteps:,} steps")
    for name in ["paper", *heldout_names(3)]:  # held-out: seeds training never draws
        print(evaluate(model, name))
    venv.close()
