"""Plan with the SST planner on the ``paper`` scenario, then fly the plan through ``env.step``.

    python examples/02_plan_sst.py              # 20,000 iterations per sampler (a few seconds)
    SOARING_EXAMPLES_QUICK=1 python examples/02_plan_sst.py   # 2,000 iterations

The planner knows the thermal field: it plans on the env's own flight model
(``env.unwrapped.model``), so replaying the plan's actions through ``env.step`` reproduces its
predicted energy exactly. An iteration budget (rather than a time budget) makes the plan the same
on every machine. The default planner (``SST_CONFIGS["seeded"]``) gives 75 % of the budget to
seeding beam searches, but its narrowest beam flies up to about 56,000 (primitive) or 150,000
(continuous) edges, so with budgets this small it stops that beam after two depths and plans as
the soaring SST; ``max_iterations=500_000`` or ``time_limit=20`` lets the beams run. If
``results/reference/paper.json`` exists (``scripts/reference.py``), the
regret is printed too: 0 = the best known plan, 1 = no better than ignoring the thermal.
"""

from __future__ import annotations

import os
from pathlib import Path

import gymnasium as gym

import soaring_env  # noqa: F401  (registers the env ids)
from baselines.reference import load_reference
from baselines.sst import plan_soaring

QUICK = bool(os.environ.get("SOARING_EXAMPLES_QUICK"))
ITERATIONS = 2_000 if QUICK else 20_000
REFERENCE = Path(__file__).resolve().parents[1] / "results" / "reference" / "paper.json"

if __name__ == "__main__":
    reference = load_reference(REFERENCE) if REFERENCE.is_file() else None
    # sampler "primitive" plans over the 174 primitives (Soaring-v0), "continuous" over the
    # continuous envelope (SoaringContinuous-v0)
    for env_id, sampler in (("soaring/Soaring-v0", "primitive"), ("soaring/SoaringContinuous-v0", "continuous")):
        env = gym.make(env_id, scenario="paper")
        env.reset(seed=0)
        result = plan_soaring(env.unwrapped.model, sampler, max_iterations=ITERATIONS, seed=0)
        plan, stats = result.plan, result.stats
        print(
            f"{sampler:10s}: {stats.iterations:,} iterations in {stats.elapsed:.2f} s, "
            f"solved={plan.solved}, {len(plan)} steps, predicted cost {plan.cost:8.1f} J/kg, "
            f"flight time {plan.flight_time:.0f} s"
        )
        info: dict = {}
        for action in plan.actions:  # the plan is a list of env actions
            _, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        # negative energy: the aircraft left the thermal with more energy than it started with
        print(f"{'':10s}  replayed through env.step: {info['outcome']}, energy spent {info['energy_spent']:8.1f} J/kg")
        if reference is not None:
            print(f"{'':10s}  regret vs the reference search: {reference.regret(plan.cost, sampler):.2f}")
        env.close()
