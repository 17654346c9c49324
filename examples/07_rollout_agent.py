"""Fly a trained discrete successor policy with one step of lookahead in its own model (needs the
``ppo`` extra: ``pip install -e ".[ppo]"``; about a second).

    python examples/07_rollout_agent.py

:class:`baselines.agents.RolloutAgent` tries the policy's 8 likeliest primitives at every decision
in a copy of the env rebuilt from the observation alone (goal, wind, the 3 observed thermals), lets
the policy's own choice fly on to the goal, and flies the primitive whose episode spends least:
Bertsekas' rollout algorithm, the policy as base policy (docs/learning-to-soar.md, round twenty-one). The run is the
committed ``results/ppo-score/a3-s0`` (45 min of cloning and lookahead rounds on this machine).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym

import soaring_env  # noqa: F401  (registers the env ids)
from baselines.agents import PPOAgent, RolloutAgent

RUN = Path(__file__).resolve().parents[1] / "results" / "ppo-score" / "a3-s0" / "discrete"


def fly(agent: PPOAgent | RolloutAgent, scenario: str) -> str:
    """One episode through ``env.step``: outcome and energy spent [J/kg]."""
    env = gym.make("soaring/Soaring-v0")
    obs, info = env.reset(options={"scenario": scenario})
    agent.reset(env)
    done = False
    while not done:
        action, _ = agent.predict(obs)
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    env.close()
    return f"{info['outcome']}, {info['energy_spent']:.0f} J/kg"


if __name__ == "__main__":
    for name in ("random-10000", "random-10055"):
        print(f"{name}: policy alone {fly(PPOAgent(RUN), name)}; with the rollout {fly(RolloutAgent(RUN), name)}")
