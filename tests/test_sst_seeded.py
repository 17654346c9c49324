"""The seeded SST (``SST_CONFIGS["seeded"]``): the reference search's budget, ``SST.insert_path``
and :class:`~baselines.sst.planner.SeededSST` -- determinism with an iteration budget, never worse
than its seed or its own first round, plans that replay through ``env.step``, bad settings."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from test_reference import TINY

from baselines.reference import ReferenceConfig, search
from baselines.sst import SST, SeededSST, SoaringSSTConfig, SSTError, make_planner, plan_soaring
from baselines.sst.core import SSTParams
from baselines.sst.planner import seed_widths
from baselines.sst.soaring import SST_CONFIGS, SoaringProblem
from soaring_env.model import SoaringModel

#: A seeded configuration small enough for tests: beams of 2 and 4 nodes in 90 % of the budget, plans
#: of at most 8 edges (the tiny scenario's goal is 1-3 primitives away); no polish (its own test).
SMALL = dataclasses.replace(
    SST_CONFIGS["seeded"], seed_width=4, seed_start_width=2, seed_share=0.9, batch_size=512, max_edges=8, seed_polish=0
)


@pytest.fixture(scope="module")
def tiny() -> SoaringModel:
    return SoaringModel(scenario=TINY)


@pytest.mark.parametrize("kind", ["primitive", "continuous"])
def test_search_rollout_budget_is_exact_and_deterministic(tiny: SoaringModel, kind: str) -> None:
    cfg = ReferenceConfig(beam_width=16, start_width=4, max_edges=8)
    full = search(tiny, kind, cfg)
    budget = full.rollouts // 3
    a = search(tiny, kind, cfg, max_rollouts=budget)
    b = search(tiny, kind, cfg, max_rollouts=budget)
    assert 0 < a.rollouts <= budget < full.rollouts
    assert a.cost == b.cost and a.plan.to_dict() == b.plan.to_dict()
    # a budget too small for the first depth of the first beam: nothing flown, no plan
    none = search(tiny, kind, cfg, max_rollouts=1)
    assert none.rollouts == 0 and not none.plan.solved and math.isinf(none.cost)


def test_search_time_budget_stops_early(tiny: SoaringModel) -> None:
    cfg = ReferenceConfig(beam_width=8, start_width=4, max_edges=8)
    full = search(tiny, "continuous", cfg)
    short = search(tiny, "continuous", cfg, time_limit=1e-6)  # past it before the first depth
    assert short.rollouts == 0 < full.rollouts


@pytest.mark.parametrize("kind", ["primitive", "continuous"])
def test_search_seeded_with_a_planner_plan_is_never_worse(tiny: SoaringModel, kind: str) -> None:
    """A continuous SST plan's controls lie off the search's grid: they join it, so the seeded beam
    keeps the plan's nodes and returns it or better, even at width 1."""
    sst = plan_soaring(tiny, kind, max_iterations=3000, seed=0, config=SoaringSSTConfig(batch_size=512, max_edges=8))
    assert sst.plan.solved
    res = search(
        tiny, kind, ReferenceConfig(beam_width=1, start_width=1, max_edges=8), seed_controls=[sst.plan.controls()]
    )
    assert res.plan.solved and res.cost <= sst.plan.cost


@pytest.mark.parametrize(
    ("kind", "seed"),
    [
        ("primitive", [[500.0]]),
        ("primitive", [[1.5]]),
        ("primitive", [[-1.0]]),
        ("continuous", [[0.0, 1.5, 0.0]]),
        ("continuous", [[0.0, float("nan"), 0.0]]),
        ("continuous", [[0.0, 0.0]]),
        ("continuous", "abc"),
    ],
)
def test_bad_seed_controls_name_the_field(tiny: SoaringModel, kind: str, seed: object) -> None:
    with pytest.raises(SSTError, match=r"seed_controls\[0\]"):
        search(tiny, kind, ReferenceConfig(beam_width=2, start_width=2, max_edges=4), seed_controls=[seed])  # type: ignore[list-item]


def test_search_from_a_given_start_matches_the_scenario_start(tiny: SoaringModel) -> None:
    cfg = ReferenceConfig(beam_width=8, start_width=8, max_edges=6)
    a = search(tiny, "primitive", cfg)
    b = search(tiny, "primitive", cfg, start=np.asarray(TINY.start_state))
    assert a.plan.to_dict() == b.plan.to_dict()


@pytest.mark.parametrize("kind", ["primitive", "continuous"])
def test_insert_path_adds_a_better_solution_as_a_path(tiny: SoaringModel, kind: str) -> None:
    ref = search(tiny, kind, ReferenceConfig(beam_width=16, start_width=16, max_edges=8))
    assert ref.plan.solved
    u = ref.plan.controls()
    _, sst = make_planner(tiny, kind, config=SoaringSSTConfig(completions=0, refinements=0, batch_size=16))
    assert isinstance(sst, SST)
    assert sst.insert_path(u, seconds=0.5, edges=123)
    res = sst.result()
    assert res.solved and res.cost == ref.cost
    assert np.array_equal(res.controls, u)
    st = sst.stats
    assert st.seed_edges == 123 and st.iterations == 123 and st.elapsed == 0.5
    assert st.cost_history == [(0.5, 123, ref.cost)]
    # the tree stays valid: the path's nodes are active or inactive ancestors of the solution
    tree = sst.tree()
    assert set(np.unique(tree.status)) <= {tree.ACTIVE, tree.INACTIVE, tree.SOLUTION}
    # the same path again, a prefix that does not reach the goal, and an empty one: no change
    assert not sst.insert_path(u)
    assert not sst.insert_path(u[:-1])
    assert not sst.insert_path(u[:0])
    assert sst.result().cost == ref.cost and len(sst.stats.cost_history) == 1


def test_insert_path_bad_input(tiny: SoaringModel) -> None:
    _, sst = make_planner(tiny, "continuous", config=SoaringSSTConfig(batch_size=16))
    for bad, field in (("abc", "controls"), ([[0.0, 0.0]], "controls"), ([[0.0, np.nan, 0.0]], "controls")):
        with pytest.raises(SSTError, match=field):
            sst.insert_path(bad)
    with pytest.raises(SSTError, match="seconds"):
        sst.insert_path(np.zeros((1, 3)), seconds=-1.0)
    with pytest.raises(SSTError, match="edges"):
        sst.insert_path(np.zeros((1, 3)), edges=-5)


def test_insert_path_keeps_a_better_incumbent(tiny: SoaringModel) -> None:
    _, sst = make_planner(tiny, "continuous", config=SoaringSSTConfig(batch_size=512), seed=0)
    sst.run(max_iterations=2048)
    best = sst.result()
    worse = search(tiny, "continuous", ReferenceConfig(beam_width=1, start_width=1, max_edges=8))
    if worse.plan.solved and worse.cost >= best.cost:
        assert not sst.insert_path(worse.plan.controls())
    assert sst.result().cost == best.cost


@pytest.mark.parametrize("kind", ["primitive", "continuous"])
def test_seeded_plans_are_deterministic_replay_and_beat_their_seed(tiny: SoaringModel, kind: str) -> None:
    from test_sst_soaring import assert_replays

    a = plan_soaring(tiny, kind, max_iterations=40_000, seed=3, config=SMALL)
    _, planner = make_planner(tiny, kind, config=SMALL, seed=3)
    assert isinstance(planner, SeededSST)
    b = planner.run(max_iterations=40_000)
    assert a.plan.solved and a.plan.cost == b.cost and np.array_equal(a.plan.controls(), b.controls)
    timing = ("elapsed", "cost_history", "time_to_first_solution", "iterations_per_second")
    assert {k: v for k, v in a.stats.to_dict().items() if k not in timing} == {
        k: v for k, v in b.stats.to_dict().items() if k not in timing
    }
    assert [(n, c) for _, n, c in a.stats.cost_history] == [(n, c) for _, n, c in b.stats.cost_history]
    assert 0 < a.stats.seed_edges <= 36_000 and a.stats.iterations >= 40_000
    assert [w for w, *_ in planner.seed_searches] == [2, 4]
    assert sum(n for _, _, n, _ in planner.seed_searches) == a.stats.seed_edges
    costs = [c for _, c, _, _ in planner.seed_searches]
    assert costs[1] <= costs[0]  # each beam is seeded with the best plan so far
    assert b.cost <= min(costs)
    assert_replays(a.plan, tiny.scenario)


def test_seeded_sst_is_never_worse_than_its_first_round(tiny: SoaringModel) -> None:
    """The seed only adds nodes: the first round's incumbent survives, and later calls of ``run``
    continue plain SST."""
    _, plain = make_planner(tiny, "primitive", config=dataclasses.replace(SMALL, seed_width=0), seed=5)
    first = plain.run(max_iterations=SMALL.batch_size).cost
    _, seeded = make_planner(tiny, "primitive", config=SMALL, seed=5)
    seeded.run(max_iterations=4000)
    assert seeded.result().cost <= first
    n = seeded.stats.seed_edges
    seeded.run(max_iterations=500)
    assert seeded.stats.seed_edges == n


def test_seeded_sst_with_a_time_budget(tiny: SoaringModel) -> None:
    res = plan_soaring(tiny, "continuous", time_limit=2.0, seed=0, config=SMALL)
    assert res.plan.solved and res.stats.seed_edges > 0
    # the record is in time order and only improves
    costs = [c for _, _, c in res.stats.cost_history]
    times = [t for t, _, _ in res.stats.cost_history]
    assert costs == sorted(costs, reverse=True) and times == sorted(times)


def test_seeded_planner_problem_is_the_soaring_problem(tiny: SoaringModel) -> None:
    problem, planner = make_planner(tiny, "continuous", config="seeded")
    assert isinstance(problem, SoaringProblem) and isinstance(planner, SeededSST)
    assert planner.params == SSTParams(
        selection_radius=500.0, pruning_radius=250.0, batch_size=1024, completions=8, completion_depth=20,
        refinements=8,
    )  # fmt: skip
    assert isinstance(make_planner(tiny, "continuous", config="soaring")[1], SST)
    assert not isinstance(make_planner(tiny, "continuous", config="soaring")[1], SeededSST)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"seed_width": -1}, "seed_width"),
        ({"seed_width": 2.5}, "seed_width"),
        ({"seed_start_width": 0}, "seed_start_width"),
        ({"seed_scout_width": -1}, "seed_scout_width"),
        ({"seed_scout_width": "8"}, "seed_scout_width"),
        ({"seed_share": 1.5}, "seed_share"),
        ({"seed_share": "half"}, "seed_share"),
        ({"seed_width": 64, "seed_share": 0.0}, "seed_share"),
        ({"seed_progress_weight": -1.0}, "seed_progress_weight"),
    ],
)
def test_bad_seed_settings_name_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(SSTError, match=field):
        SoaringSSTConfig(**kwargs)


def test_seed_widths() -> None:
    """The scout beam first when it is narrower than the doubling's start, then the doubling up to
    seed_width (which ends it even when not a power of two times the start)."""
    base = SST_CONFIGS["seeded"]
    assert seed_widths(base) == [8, 32, 64, 128, 256, 512]
    assert seed_widths(dataclasses.replace(base, seed_scout_width=0)) == [32, 64, 128, 256, 512]
    assert seed_widths(dataclasses.replace(base, seed_start_width=8)) == [8, 16, 32, 64, 128, 256, 512]
    assert seed_widths(dataclasses.replace(base, seed_width=100)) == [8, 32, 64, 100]
    assert seed_widths(dataclasses.replace(base, seed_width=16)) == [8, 16]
    assert seed_widths(SST_CONFIGS["soaring"]) == []


def test_bad_seeded_planner_input(tiny: SoaringModel) -> None:
    with pytest.raises(SSTError, match="seed_width"):
        make_planner(tiny, "continuous", config="seeded", reference=True)
    with pytest.raises(SSTError, match=r"named configuration.*'seeded'"):
        make_planner(tiny, "continuous", config="seeeded")
    with pytest.raises(SSTError, match="time_limit"):
        plan_soaring(tiny, "continuous", config=SMALL, time_limit=-1.0)
    with pytest.raises(SSTError, match="max_rollouts"):
        search(tiny, "continuous", ReferenceConfig(beam_width=4, start_width=4), max_rollouts=0)
    with pytest.raises(SSTError, match="time_limit"):
        search(tiny, "continuous", ReferenceConfig(beam_width=4, start_width=4), time_limit=float("nan"))


def test_acting_settings_leave_out_the_seed_fields_only_when_off() -> None:
    """Results keyed by a configuration (evaluation, ablation) must not go stale when a setting that
    is off is added: the soaring configuration's key has no ``seed_*`` fields, the seeded one's has."""
    from baselines.evaluation import EvalConfig, agent_spec

    soar, seeded = SST_CONFIGS["soaring"].acting_settings(), SST_CONFIGS["seeded"].acting_settings()
    assert not any(k.startswith("seed_") for k in soar)
    assert {k: v for k, v in seeded.items() if not k.startswith("seed_")} == soar
    assert seeded["seed_width"] == SST_CONFIGS["seeded"].seed_width > 0
    assert dataclasses.replace(SST_CONFIGS["soaring"], seed_share=0.5).acting_settings() == soar
    assert agent_spec("sst-soaring-continuous", EvalConfig()).settings["config"] == soar
    assert agent_spec("sst-seeded-continuous", EvalConfig()).settings["config"] == SST_CONFIGS[
        "seeded"
    ].acting_settings("continuous")


@pytest.mark.parametrize("kind", ["primitive", "continuous"])
def test_search_stops_a_beam_that_cannot_finish_within_the_budget(kind: str) -> None:
    """From its third depth a beam is projected to the end (every remaining depth like the next):
    one that would overrun the budget stops at once, says so, and leaves the rest of the budget
    unspent (on ``paper`` no goal lies within 10 edges, so the 4-wide beam stays full)."""
    paper = SoaringModel()
    cfg = ReferenceConfig(beam_width=4, start_width=4, max_edges=10)
    full = search(paper, kind, cfg)
    m = full.n_controls
    assert not full.stopped and full.rollouts == m + 9 * 4 * m  # the root's m, then 4 m per depth
    short = search(paper, kind, cfg, max_rollouts=full.rollouts - 1)
    assert short.stopped and short.rollouts == m + 4 * m  # the first two depths, then the projection
    assert not short.plan.solved


def test_seeded_planner_with_a_budget_too_small_for_a_beam_is_sst() -> None:
    """An iteration budget that no beam fits into: the first beam stops after two depths and the
    rest goes to SST, which still plans."""
    paper = SoaringModel()
    cfg = dataclasses.replace(SST_CONFIGS["seeded"], seed_start_width=4, seed_polish=0)
    _, planner = make_planner(paper, "primitive", config=cfg, seed=0)
    assert isinstance(planner, SeededSST)
    res = planner.run(max_iterations=20_000)
    m = int(paper.allowed_primitives().sum())
    assert [(w, n) for w, _, n, _ in planner.seed_searches] == [(4, m + 4 * m)]
    assert math.isinf(planner.seed_searches[0][1]) and res.stats.seed_edges == m + 4 * m
    assert res.solved


def test_seeded_planner_polishes_its_primitive_plan(tiny: SoaringModel) -> None:
    """``seed_polish``: after the beams (in ``seed_share - seed_polish_share``) the tree's best plan
    is polished and inserted -- recorded as a width-0 search, counted in the seed edges, the result
    no worse than the polished plan, deterministic with an iteration budget, replayed through
    ``env.step``."""
    from test_sst_soaring import assert_replays

    kind = "primitive"
    cfg = dataclasses.replace(SMALL, seed_polish=2, seed_polish_share=0.3)
    a = plan_soaring(tiny, kind, max_iterations=40_000, seed=3, config=cfg)
    _, planner = make_planner(tiny, kind, config=cfg, seed=3)
    b = planner.run(max_iterations=40_000)
    assert a.plan.solved and a.plan.cost == b.cost and np.array_equal(a.plan.controls(), b.controls)
    widths = [w for w, *_ in planner.seed_searches]
    assert widths[-1] == 0 and 0 not in widths[:-1]  # the beams, then the polish
    assert sum(n for _, _, n, _ in planner.seed_searches) == planner.stats.seed_edges
    assert b.cost <= planner.seed_searches[-1][1] <= min(c for _, c, _, _ in planner.seed_searches[:-1])
    assert_replays(a.plan, tiny.scenario)
    off = SoaringSSTConfig(seed_polish=0, seed_polish_share=0.5)  # the share does nothing then
    assert off.acting_settings() == SoaringSSTConfig(seed_polish=0).acting_settings()
    assert not any(k.startswith("seed_polish") for k in off.acting_settings())
    assert SoaringSSTConfig().acting_settings()["seed_polish"] == 2  # the default polishes
    # ... the primitives only: continuous results stay keyed without the polish fields
    assert SoaringSSTConfig().acting_settings("continuous") == off.acting_settings()
    assert SoaringSSTConfig().acting_settings("primitive") == SoaringSSTConfig().acting_settings()
    from baselines.evaluation import EvalConfig, agent_spec

    assert "seed_polish" not in agent_spec("sst-seeded-continuous", EvalConfig()).settings["config"]
    assert agent_spec("sst-seeded-primitives", EvalConfig()).settings["config"]["seed_polish"] == 2


def test_seeded_planner_does_not_polish_continuous_plans(tiny: SoaringModel) -> None:
    """With the continuous sampler ``seed_polish`` does nothing: the beams keep all of
    ``seed_share`` and the plan is the one without it, bit for bit."""
    on = dataclasses.replace(SMALL, seed_polish=2, seed_polish_share=0.3)
    a = plan_soaring(tiny, "continuous", max_iterations=40_000, seed=3, config=on)
    b = plan_soaring(tiny, "continuous", max_iterations=40_000, seed=3, config=SMALL)
    assert a.plan.solved and a.plan.cost == b.plan.cost and np.array_equal(a.plan.controls(), b.plan.controls())
    assert a.stats.seed_edges == b.stats.seed_edges


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"seed_polish": 3}, "seed_polish"),
        ({"seed_polish": "2"}, "seed_polish"),
        ({"seed_polish": -1}, "seed_polish"),
        ({"seed_polish_share": 1.5}, "seed_polish_share"),
        ({"seed_polish": 2, "seed_polish_share": 0.75}, "seed_polish_share"),  # all of seed_share
        ({"seed_polish": 2, "seed_polish_share": 0.0}, "seed_polish_share"),
    ],
)
def test_bad_polish_settings_name_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(SSTError, match=field):
        SoaringSSTConfig(**kwargs)
