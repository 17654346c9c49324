"""The reference's local search (``baselines.reference.polish``) and how the yardstick applies it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from test_reference import SUBSET, TINY, _enumerate  # (tests/ is on sys.path)
from test_sst_soaring import assert_replays

from baselines.reference import ReferenceConfig, compute_reference, load_reference, search
from baselines.reference import polish as polish_module
from baselines.reference.polish import polish
from baselines.reference.runner import run_references
from baselines.sst.core import EDGE_GOAL, EDGE_VALID
from baselines.sst.soaring import SoaringProblem
from soaring_env._validation import ConfigError
from soaring_env.model import SoaringModel


@pytest.fixture(scope="module")
def tiny() -> SoaringModel:
    return SoaringModel(scenario=TINY)


def _goal_plans(model: SoaringModel, prims: tuple[int, ...], depth: int) -> list[tuple[float, tuple[int, ...]]]:
    """Every primitive sequence of at most ``depth`` edges that reaches the goal (at its last edge),
    with its cost: the brute force the polish is checked against."""
    problem = SoaringProblem(model, "primitive")
    out = []
    paths = [((), problem.root_state()[None, :], 0.0)]
    for _ in range(depth):
        nxt = []
        for seq, x, j in paths:
            e = problem.propagate(np.repeat(x, len(prims), axis=0), np.array(prims, np.float64)[:, None])
            for q, p in enumerate(prims):
                if e.outcome[q] == EDGE_GOAL:
                    out.append((j + float(e.cost[q]), (*seq, p)))
                elif e.outcome[q] == EDGE_VALID:
                    nxt.append(((*seq, p), e.states[q : q + 1], j + float(e.cost[q])))
        paths = nxt
    return out


def test_polish_reaches_the_enumerated_optimum_from_every_plan(tiny: SoaringModel) -> None:
    """Depth 2 on plans of at most 2 edges: one move can replace the whole plan, so from every plan
    that reaches the goal the polish must end at the brute-force optimum (and depth 1 never worse)."""
    plans = _goal_plans(tiny, SUBSET, 2)
    exact = _enumerate(tiny, SUBSET, 2)
    assert len(plans) > 5 and min(c for c, _ in plans) == pytest.approx(exact, abs=1e-9)
    cfg = ReferenceConfig(max_edges=2, primitives=SUBSET)
    for cost, seq in plans[:: max(1, len(plans) // 12)]:
        u = np.array(seq, np.float64)[:, None]
        res = polish(tiny, "primitive", u, cfg, depth=2)
        assert res.cost == pytest.approx(exact, abs=1e-9)
        assert res.plan.solved and res.plan.cost == res.cost
        assert polish(tiny, "primitive", u, cfg, depth=1).cost <= cost + 1e-9


@pytest.mark.parametrize("sampler", ["primitive", "continuous"])
def test_polished_plans_are_no_worse_replay_and_are_deterministic(tiny: SoaringModel, sampler: str) -> None:
    """From a one-node beam's plan: never worse, replays through ``env.step`` at its cost, the same
    plan twice."""
    cfg = ReferenceConfig(beam_width=1, start_width=1, max_edges=8)
    start = search(tiny, sampler, cfg)
    assert start.plan.solved
    a = polish(tiny, sampler, start.plan.controls(), cfg, depth=1)
    b = polish(tiny, sampler, start.plan.controls(), cfg, depth=1)
    assert a.cost <= start.cost
    assert (
        a.plan.actions == b.plan.actions
        if sampler == "primitive"
        else np.array_equal(a.plan.controls(), b.plan.controls())
    )
    assert a.cost == b.cost and a.rollouts == b.rollouts
    assert_replays(a.plan, TINY)


def test_reach_test_drops_only_plans_that_cannot_reach_the_goal(tiny: SoaringModel, monkeypatch) -> None:
    """The necessary test that spares flying tails (``_Reach``) changes the work, never the result."""
    cfg = ReferenceConfig(beam_width=1, start_width=1, max_edges=6, primitives=SUBSET)
    u = search(tiny, "primitive", cfg).plan.controls()
    u = np.concatenate([u[:1], u])[:6] if len(u) < 6 else u  # a longer, worse start: more to polish
    try:
        fast = polish(tiny, "primitive", u, cfg, depth=2)
    except ConfigError:  # the lengthened plan does not reach the goal: polish the search's own
        u = search(tiny, "primitive", cfg).plan.controls()
        fast = polish(tiny, "primitive", u, cfg, depth=2)
    monkeypatch.setattr(polish_module._Reach, "from_node", lambda self, a: None)
    slow = polish(tiny, "primitive", u, cfg, depth=2)
    assert slow.cost == fast.cost and slow.plan.actions == fast.plan.actions
    assert slow.rollouts > fast.rollouts


def test_max_rounds_bounds_the_moves(tiny: SoaringModel) -> None:
    cfg = ReferenceConfig(max_edges=2, primitives=SUBSET)
    cost, seq = max(_goal_plans(tiny, SUBSET, 2))
    u = np.array(seq, np.float64)[:, None]
    none = polish(tiny, "primitive", u, cfg, depth=2, max_rounds=0)
    assert none.cost == pytest.approx(cost, abs=1e-9) and none.plan.actions == seq and none.stopped
    assert not polish(tiny, "primitive", u, cfg, depth=2).stopped


def test_bad_polish_input(tiny: SoaringModel) -> None:
    u = search(tiny, "primitive", ReferenceConfig(beam_width=1, start_width=1, max_edges=6)).plan.controls()
    for depth in (0, 3, "2", 1.5):
        with pytest.raises(ConfigError, match="depth"):
            polish(tiny, "primitive", u, depth=depth)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="max_rounds"):
        polish(tiny, "primitive", u, depth=1, max_rounds=-1)
    with pytest.raises(ConfigError, match="sampler"):
        polish(tiny, "spline", u, depth=1)
    with pytest.raises(ConfigError, match="controls"):
        polish(tiny, "primitive", u[:-1], depth=1)  # stops short of the goal
    for bad in ([[500.0]], [[math.nan]], [["x"]]):
        with pytest.raises(ConfigError, match="controls"):
            polish(tiny, "primitive", np.array(bad, dtype=object), depth=1)
    with pytest.raises(ConfigError, match="controls"):
        polish(tiny, "continuous", np.full((2, 3), 2.0), depth=1)
    for bad_polish in (-1, 3, "1", None):
        with pytest.raises(ConfigError, match="polish"):
            ReferenceConfig(polish=bad_polish)  # type: ignore[arg-type]


def test_compute_reference_polishes_and_records_the_depth() -> None:
    """``polish=2``: no worse than without, depth recorded per action set (continuous at most 1)."""
    cfg = ReferenceConfig(beam_width=5, start_width=5, max_edges=6)
    plain = compute_reference(TINY, ("primitive", "continuous"), cfg)
    done = compute_reference(TINY, ("primitive", "continuous"), dataclasses.replace(cfg, polish=2))
    for s, depth in (("primitive", 2), ("continuous", 1)):
        assert done.samplers[s].best_cost <= plain.samplers[s].best_cost
        assert done.samplers[s].settings["polish"] == depth and plain.samplers[s].settings["polish"] == 0
        assert done.samplers[s].rollouts > plain.samplers[s].rollouts
    assert done.samplers["primitive"].best_cost < plain.samplers["primitive"].best_cost  # it helps here


def test_stored_references_are_polished_not_recomputed(tmp_path) -> None:
    """A file computed without the polish is brought up to date by polishing its plan -- the same
    reference as computing it afresh with the polish (the search before it is deterministic) -- and
    a file computed with other settings is recomputed."""
    cfg = ReferenceConfig(beam_width=5, start_width=5, max_edges=6)
    run_references([TINY], tmp_path, samplers=("primitive",), config=cfg, progress=False)
    stored = load_reference(tmp_path / "tiny.json").samplers["primitive"]
    pol = dataclasses.replace(cfg, polish=2)
    got = run_references([TINY], tmp_path, samplers=("primitive",), config=pol, progress=False)["tiny"]
    fresh = compute_reference(TINY, ("primitive",), pol)
    a, b = got.samplers["primitive"], fresh.samplers["primitive"]
    assert dataclasses.replace(a, seconds=0.0) == dataclasses.replace(b, seconds=0.0)
    assert a.best_cost < stored.best_cost and a.seconds >= stored.seconds
    # done now: a rerun loads it as it is
    again = run_references([TINY], tmp_path, samplers=("primitive",), config=pol, progress=False)["tiny"]
    assert again == got


def test_polish_budgets(tiny: SoaringModel) -> None:
    """A rollout budget is never exceeded and gives the same plan every time; a spent time budget
    returns the plan it was given (or one of its round's moves); from a given start state the
    polish plans as from the scenario's start."""
    cfg = ReferenceConfig(max_edges=2, primitives=SUBSET)
    cost, seq = max(_goal_plans(tiny, SUBSET, 2))
    u = np.array(seq, np.float64)[:, None]
    full = polish(tiny, "primitive", u, cfg, depth=2)
    budget = full.rollouts // 2
    a = polish(tiny, "primitive", u, cfg, depth=2, max_rollouts=budget)
    b = polish(tiny, "primitive", u, cfg, depth=2, max_rollouts=budget)
    assert a.rollouts <= budget and a.stopped and a.cost <= cost
    assert a.cost == b.cost and a.plan.actions == b.plan.actions
    late = polish(tiny, "primitive", u, cfg, depth=2, time_limit=1e-9)
    assert late.stopped and late.cost == pytest.approx(cost, abs=1e-9)
    moved = polish(tiny, "primitive", u, cfg, depth=2, start=np.array(TINY.start), t0=0.0)
    assert moved.cost == full.cost and moved.plan.actions == full.plan.actions
    for kw in ({"max_rollouts": 0}, {"time_limit": -1.0}, {"time_limit": math.nan}):
        with pytest.raises(ConfigError, match=next(iter(kw))):
            polish(tiny, "primitive", u, cfg, depth=2, **kw)
