"""The round-nine probe (:mod:`baselines.cli.probe_lookahead`): its edge model is the env's, its plans fly."""

from __future__ import annotations

import importlib
from types import ModuleType

import gymnasium as gym
import numpy as np
import pytest

import soaring_env  # noqa: F401  (registers the envs)


def _probe() -> ModuleType:
    return importlib.import_module("baselines.cli.probe_lookahead")


def test_beam_plans_fly_and_their_first_edge_costs_what_the_env_charges() -> None:
    """A tiny beam on the paper scenario: every chosen primitive is allowed, the rebuilt field's
    cost of it is the env's edge cost, and the episode reaches the goal."""
    probe = _probe()
    env = gym.make("soaring/Soaring-v0")
    look = probe.Lookahead(env)
    obs, _ = env.reset(seed=0)
    for _ in range(40):
        a, predicted = probe.beam_action(look, obs, width=4, depth=12, glide_ratio=15.0)
        assert look.allowed[a]
        obs, _, term, trunc, info = env.step(a)
        assert abs(predicted - info["edge_cost"]) < 1e-6  # [J/kg]: the same rollout in the same air
        if term or trunc:
            break
    assert info["outcome"] == "goal"


def test_straight_glide_estimate_closed_form() -> None:
    """Level with the goal and 1.5 km away at glide ratio 15: 100 m of height bought with fuel."""
    probe = _probe()
    est = probe.to_go_estimate(np.array([0.0, 0.0, 0.0, 300.0]), np.array([1500.0, 0.0, 300.0]), 15.0, 0.8)
    assert np.isclose(est, probe.G * 100.0 / 0.8)


@pytest.mark.parametrize(
    "args",
    [
        ["--width", "0"],
        ["--depth", "0"],
        ["--glide-ratio", "-1"],
        ["--top", "0"],
        ["--mode", "rerank", "--policy", "nowhere.zip"],
    ],
)
def test_bad_options_are_refused(args: list[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        _probe().main(args)
    assert exc.value.code == 2
