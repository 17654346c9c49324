"""OMPL's control::SST and control::RRT through our propagator (briefly; skipped without the
``ompl`` extra): results come back from the subprocess, costs only improve, and the best plan's
actions replay through ``env.step`` to the cost OMPL reports."""

from __future__ import annotations

import math

import numpy as np
import pytest

from baselines.sst.ompl_bridge import OMPL_PLANNERS, ompl_available, run_ompl
from soaring_env.scenario import paper_scenario

pytestmark = pytest.mark.skipif(not ompl_available(), reason='OMPL is not installed (pip install -e ".[ompl]")')

#: 800 m from the goal, beside the thermal: OMPL finds solutions within a second or two.
NEAR = paper_scenario().replace(start=(2200.0, 0.0, 0.0, 320.0))


@pytest.mark.parametrize("planner", OMPL_PLANNERS)
@pytest.mark.parametrize("sampler", ["primitive", "continuous"])
def test_ompl_plans_replay_through_the_env(sampler: str, planner: str) -> None:
    gym = pytest.importorskip("gymnasium")
    import soaring_env.env  # noqa: F401  (registers the ids)

    r = run_ompl(NEAR, sampler, planner, time_limit=2.0, seed=1)
    assert r["iterations"] > 100 and r["elapsed"] >= 2.0
    costs = [c for _, c in r["history"]]
    assert costs == sorted(costs, reverse=True)
    if not r["solved"]:
        assert math.isinf(r["best_cost"]) and r["actions"] == []
        return
    env_id = "soaring/Soaring-v0" if sampler == "primitive" else "soaring/SoaringContinuous-v0"
    env = gym.make(env_id)
    env.reset(seed=0, options={"scenario": NEAR})
    term = False
    info: dict = {}
    for a in r["actions"]:
        act = int(a[0]) if sampler == "primitive" else np.asarray(a, np.float32)
        _, _, term, trunc, info = env.step(act)
        assert not trunc
    assert term and info["energy_spent"] == pytest.approx(r["best_cost"], rel=1e-12, abs=1e-9)


def test_bad_ompl_arguments_name_the_field() -> None:
    with pytest.raises(Exception, match="planner"):
        run_ompl(NEAR, "primitive", "prm", time_limit=1.0)
    with pytest.raises(Exception, match="time_limit"):
        run_ompl(NEAR, "primitive", "sst", time_limit=0.0)
