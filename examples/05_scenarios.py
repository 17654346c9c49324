"""Scenarios by name, by seed and from a JSON file -- one namespace wherever a scenario is taken.

    python examples/05_scenarios.py

``soaring_env.get_scenario``, ``gym.make(..., scenario=...)``, ``env.reset(options={"scenario": ...})``
and the evaluation (``scripts/evaluate.py --scenarios ...``) all accept:

* ``"paper"`` -- the paper's figure-2 setting (one thermal between start and goal);
* ``"random-<seed>"`` -- a random scenario drawn with that seed (``random-10000`` onwards is the
  held-out test set; the envs pass their ``random_scenario`` keywords);
* a path to a scenario JSON file (``Scenario.save`` writes one);
* and in the envs ``"random"``: a new random scenario at every reset.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from pathlib import Path

import gymnasium as gym

import soaring_env
from baselines.agents import HeuristicAgent
from soaring_env import ConfigError, Thermal
from soaring_env.scenario import Scenario


def describe(sc: Scenario) -> str:
    f = sc.field
    n, e, _, h = sc.start
    return (
        f"{sc.name!r}: {len(f.thermals)} {f.model} thermal(s) of w* {[round(t.strength, 2) for t in f.thermals]} m/s, "
        f"wind {math.hypot(f.wind_north, f.wind_east):.1f} m/s; start ({n:.0f}, {e:.0f}) m at {h:.0f} m, "
        f"goal ({sc.goal.north:.0f}, {sc.goal.east:.0f}) m at {sc.goal.height:.0f} m"
    )


def fly(env: gym.Env, options: dict | None = None) -> str:
    """One episode of the hand-written heuristic (head for the goal, circle in lift)."""
    obs, info = env.reset(seed=0, options=options)
    agent = HeuristicAgent()
    agent.reset(env, 0)
    while True:
        obs, _, terminated, truncated, info = env.step(agent.predict(obs)[0])
        if terminated or truncated:
            return (
                f"{env.unwrapped.scenario.name}: heuristic {info['outcome']} after {info['time']:.0f} s, "
                f"energy spent {info['energy_spent']:.0f} J/kg"
            )


if __name__ == "__main__":
    print(describe(soaring_env.get_scenario("paper")))
    print(describe(soaring_env.get_scenario("random-10000")))
    # same seed, other draw ranges: the keywords of soaring_env.make_scenario
    print(describe(soaring_env.get_scenario("random-10000", {"n_thermals": (5, 5), "wind_speed": (0.0, 0.0)})))

    # A scenario of your own: the paper's, with a second thermal and a crosswind, saved as JSON.
    paper = soaring_env.get_scenario("paper")
    field = dataclasses.replace(
        paper.field, thermals=(*paper.field.thermals, Thermal(north=2300.0, east=-300.0, strength=2.0)), wind_east=3.0
    )
    mine = paper.replace(name="two-thermals", field=field)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "two_thermals.json"
        mine.save(path)
        print(describe(soaring_env.get_scenario(str(path))))

        env = gym.make("soaring/Soaring-v0", scenario=str(path))  # pinned for every episode
        print("gym.make(scenario=<json>):   ", fly(env))
        print("reset(options=random-10001):", fly(env, options={"scenario": "random-10001"}))
        env.close()

    try:
        soaring_env.get_scenario("everest")
    except ConfigError as exc:  # unknown names list the known names and forms
        print("error:", exc)
