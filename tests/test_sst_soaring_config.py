"""The soaring SST configuration, component by component: the zero-thrust glide angle (closed form),
the control mixture, the admissible cost bound (exhaustive enumeration), the goal completions
(tree invariants, replay) and the named configurations."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from baselines.sst import SST, SoaringSSTConfig, SSTError, SSTParams, make_planner, plan_soaring
from baselines.sst.soaring import DEFAULT_SST_CONFIG, SST_CONFIGS, SoaringProblem
from soaring_env.model import SoaringModel
from soaring_env.physics.aircraft import Aircraft, bank_angle
from soaring_env.physics.atmosphere import G, air_density
from soaring_env.scenario import paper_scenario

SAMPLERS = ("primitive", "continuous")


@pytest.fixture(scope="module")
def model() -> SoaringModel:
    return SoaringModel(paper_scenario())


def _closed_form_glide(ac: Aircraft, v: float, chi_dot: float, h_max: float) -> float:
    """Zero trim thrust: q S C_D0 + (W cos(g) / cos(phi))^2 / (q S pi AR e) + W sin(g) = 0 is a
    quadratic in s = sin(g): B s^2 - W s - (A + B) = 0 (A = drag at zero lift, B = induced drag at
    cos(g) = 1); the flight-path root is the negative one, at each end of the height range."""
    w = ac.weight
    cos_phi = math.cos(math.atan(v * chi_dot / G))
    out = []
    for h in (0.0, h_max):
        q_s = 0.5 * float(air_density(h)) * v * v * ac.wing_area
        a = q_s * ac.cd0
        b = w * w / (cos_phi * cos_phi * q_s * math.pi * ac.aspect_ratio * ac.oswald)
        s = (w - math.sqrt(w * w + 4.0 * b * (a + b))) / (2.0 * b)
        out.append(math.asin(s))
    return min(out)


@pytest.mark.parametrize("v, chi_dot", [(10.0, 0.0), (12.5, 0.3), (15.0, -0.5), (20.0, 0.628), (17.3, 0.05)])
def test_glide_angle_matches_the_closed_form(v: float, chi_dot: float) -> None:
    ac = Aircraft()
    gam = float(ac.glide_angle(v, chi_dot, 1500.0))
    assert gam == pytest.approx(_closed_form_glide(ac, v, chi_dot, 1500.0), abs=1e-12)
    bank = float(bank_angle(v, chi_dot))
    # zero up to the last bits (the kernels contract floating-point operations differently)
    assert np.all(ac.thrust(v, gam, bank, [0.0, 1500.0]) <= 1e-12)
    assert np.any(ac.thrust(v, gam + 1e-9, bank, [0.0, 1500.0]) > 1e-9)


def test_glide_angle_broadcasts_and_checks_input() -> None:
    ac = Aircraft()
    g = ac.glide_angle(np.array([10.0, 15.0, 20.0]), 0.1, 1500.0)
    assert g.shape == (3,) and np.all(g < 0)
    with pytest.raises(Exception, match="airspeed"):
        ac.glide_angle(-1.0, 0.0, 1500.0)
    with pytest.raises(Exception, match="height_max"):
        ac.glide_angle(10.0, 0.0, 20000.0)


def test_glide_actions_need_no_thrust_and_are_float32(model: SoaringModel) -> None:
    prob = SoaringProblem(model, "continuous", SoaringSSTConfig(glide_share=1.0))
    u = prob.sample_controls(np.random.default_rng(0), 2000)
    assert np.array_equal(u, u.astype(np.float32).astype(np.float64))
    c = model.action_to_control(u)
    bank = bank_angle(c[:, 0], c[:, 1])
    for h in (0.0, model.scenario.bounds.height_max):
        assert np.all(model.aircraft.thrust(c[:, 0], c[:, 2], bank, h) <= 1e-12)
    # the largest such float32: one step up needs thrust somewhere (unless already at the top of [-1, 1])
    up = np.nextafter(u[:, 2].astype(np.float32), np.float32(1.0)).astype(np.float64)
    c_up = model.action_to_control(np.stack([u[:, 0], u[:, 1], up], axis=1))
    need = model.aircraft.thrust(c_up[:, 0], c_up[:, 2], bank, 0.0) + model.aircraft.thrust(
        c_up[:, 0], c_up[:, 2], bank, model.scenario.bounds.height_max
    )
    assert np.all(need > 1e-12)


def test_mixture_shares_and_positive_density(model: SoaringModel) -> None:
    cfg = SoaringSSTConfig(glide_share=0.5, circle_share=0.3)
    prob = SoaringProblem(model, "continuous", cfg)
    n = 20000
    u = prob.sample_controls(np.random.default_rng(1), n)
    glide = prob.glide_action(u)
    share = np.mean(u[:, 2] == glide)
    assert abs(share - 0.5) < 4 * math.sqrt(0.25 / n)
    c = model.action_to_control(u)
    radius = c[:, 0] / np.maximum(np.abs(c[:, 1]), 1e-12)
    in_band = np.mean((radius >= 15.0 - 1e-6) & (radius <= 60.0 + 1e-6))
    assert in_band > 0.3  # the circle draws, plus the uniform ones that happen to be in the band
    # the uniform part still covers the whole box
    for k in range(3):
        assert u[:, k].min() < -0.99 and u[:, k].max() > 0.99


def test_paper_configuration_is_the_uniform_sampler(model: SoaringModel) -> None:
    """The paper's planner draws exactly what the uniform samplers draw (same random stream)."""
    paper = SST_CONFIGS["paper"]
    for kind in SAMPLERS:
        prob = SoaringProblem(model, kind, paper)
        a = prob.sample_controls(np.random.default_rng(3), 500)
        b = prob.sampler.sample(np.random.default_rng(3), 500)
        assert np.array_equal(a, b)
        q1 = prob.sample_targets(np.random.default_rng(4), 500)
        q2 = prob.space.sample(np.random.default_rng(4), 500)
        assert np.array_equal(q1, q2)
    assert paper.completions == 0 and not paper.cost_bound and paper.glide_share == 0.0
    assert SoaringSSTConfig() == SST_CONFIGS["seeded"] == SST_CONFIGS[DEFAULT_SST_CONFIG]
    assert SST_CONFIGS["soaring"] == dataclasses.replace(SoaringSSTConfig(), seed_width=0)
    assert paper.seed_width == 0


def test_primitive_circle_draws_are_circles(model: SoaringModel) -> None:
    cfg = SoaringSSTConfig(circle_share=1.0, circle_radius=(15.0, 60.0))
    prob = SoaringProblem(model, "primitive", cfg)
    idx = prob.sample_controls(np.random.default_rng(0), 3000)[:, 0].astype(int)
    t = model.library.table
    turn = np.minimum(np.abs(t[idx, 3]), np.abs(t[idx, 4]))
    r = t[idx, 1] / turn
    assert np.all((r >= 15.0) & (r <= 60.0)) and np.all(model.bank_ok()[idx])


def test_thermal_targets_lie_over_the_thermals(model: SoaringModel) -> None:
    prob = SoaringProblem(model, "continuous", SoaringSSTConfig(thermal_targets=1.0, thermal_target_radius=80.0))
    q = prob.sample_targets(np.random.default_rng(0), 4000)
    th = model.scenario.field.thermals[0]
    assert np.all(np.hypot(q[:, 0] - th.north, q[:, 1] - th.east) <= 80.0 + 1e-9)
    assert q[:, 2].min() >= 0.0 and q[:, 2].max() <= model.scenario.bounds.height_max


@pytest.mark.parametrize("kind", SAMPLERS)
def test_cost_bound_is_admissible_by_exhaustive_enumeration(kind: str) -> None:
    """Every plan of up to 3 edges from a start next to the thermal, over a small control set:
    at every prefix, cost-to-come + togo never exceeds the cost of any plan through it that
    reaches the goal."""
    sc = paper_scenario().replace(start=(2200.0, 0.0, 0.0, 320.0))
    m = SoaringModel(sc)
    prob = SoaringProblem(m, kind, SoaringSSTConfig())
    if kind == "primitive":
        controls = np.flatnonzero(m.bank_ok())[::12].astype(np.float64)[:, None]
    else:
        grid = [-1.0, 0.0, 1.0]
        controls = np.array(list(itertools.product(grid, grid, [-1.0, -0.11, 0.0])), dtype=np.float64)
    root = prob.root_state()[None, :]
    frontier = [(root, 0.0, [])]
    n_goal = 0
    for _ in range(3):
        nxt = []
        for x, cost, bounds in frontier:
            xs = np.repeat(x, len(controls), axis=0)
            e = prob.propagate(xs, controls)
            for k in range(len(controls)):
                if e.outcome[k] == 2:
                    continue
                c = cost + float(e.cost[k])
                if e.outcome[k] == 1:  # a complete plan: no bound along it may exceed its cost
                    assert all(bb <= c + 1e-9 for bb in bounds), "a prefix bound exceeds a plan's cost"
                    n_goal += 1
                else:
                    nxt.append((e.states[k : k + 1], c, [*bounds, c + float(e.togo[k])]))
        frontier = nxt
    assert n_goal > 0 and len(frontier) > 0


def test_cost_bound_prunes_and_keeps_k1_equal_to_reference(model: SoaringModel) -> None:
    """With everything but the completions (mixture, targets, bound), the batched core with K = 1
    builds exactly the plain reference's tree."""
    from test_sst_soaring import assert_k1_equals_reference

    cfg = SoaringSSTConfig(
        batch_size=1, completions=0, refinements=0, thermal_targets=0.3, circle_share=0.2, seed_width=0
    )
    for kind in SAMPLERS:
        assert_k1_equals_reference(model, kind, cfg, seed=5, iterations=3000)


def test_reference_sst_refuses_completions(model: SoaringModel) -> None:
    with pytest.raises(SSTError, match="completions"):
        make_planner(model, "continuous", config="soaring", reference=True)
    with pytest.raises(SSTError, match="refinements=8"):
        make_planner(model, "continuous", config=SoaringSSTConfig(completions=0, seed_width=0), reference=True)


@pytest.mark.parametrize("kind", SAMPLERS)
def test_completions_keep_the_tree_valid(kind: str, model: SoaringModel) -> None:
    """Goal completions insert chains (with inactive ancestors of the solution): the tree keeps
    every SST invariant, the solution path re-flies edge by edge, and nodes below the bound are
    never dropped by it (bounded children could not beat the best)."""
    from test_sst_core import check_tree_invariants

    problem, planner = make_planner(model, kind, config=SoaringSSTConfig(batch_size=512), seed=3)
    planner.run(max_iterations=20_000)
    st = planner.stats
    assert st.completion_edges > 0 and math.isfinite(st.best_cost) and st.bounded > 0
    check_tree_invariants(planner.tree(), problem, planner.params)


def test_root_completion_soars_at_once(model: SoaringModel) -> None:
    """The first completion (from the start) glides to the thermal, climbs and glides home: on the
    paper scenario it alone captures most of the thermal (the direct flight costs about 1,340 J/kg,
    the reference plan -1,454): -1,323 J/kg, aiming the final glide at the goal's top - r / 20."""
    res = plan_soaring(model, "continuous", max_iterations=1, seed=0)
    assert res.plan.solved and res.plan.cost < -1300.0
    assert res.plan.states[:, 3].max() > 500.0  # it climbed
    assert res.stats.completion_edges >= len(res.plan)


def test_primitive_root_completion_flies_home_through_the_model(model: SoaringModel) -> None:
    """The primitives' completion circles in the thermal, then picks each homeward primitive by its
    exact cost plus whole level edges to the goal: 1,517 J/kg on the paper scenario (the nearest
    primitive to the continuous steering gave 1,597; the direct flight costs about 1,864)."""
    res = plan_soaring(model, "primitive", max_iterations=1, seed=0)
    assert res.plan.solved and res.plan.cost < 1550.0
    assert res.plan.states[:, 3].max() > 400.0  # it climbed


def test_refinements_improve_on_the_completion(model: SoaringModel) -> None:
    """Re-completing the incumbent from its own path after one random edge (the local refinement)
    finds a primitive plan below the reference search's 1,399 J/kg where the completions alone
    stay at 1,517 (paper scenario, same seed and iteration budget); the tree stays valid."""
    from test_sst_core import check_tree_invariants

    problem, planner = make_planner(model, "primitive", config=SoaringSSTConfig(), seed=3)
    res = planner.run(max_iterations=100_000)
    assert res.solved and res.cost < 1400.0
    check_tree_invariants(planner.tree(), problem, planner.params)


def test_completions_need_a_steering_rule() -> None:
    """A problem without ``goal_controls`` simply gets no completions."""
    from test_sst_core import Car

    params = SSTParams(selection_radius=1.0, pruning_radius=0.5, batch_size=64, completions=4)
    sst = SST(Car(), params, seed=0)
    sst.run(max_iterations=2000)
    assert sst.stats.completion_edges == 0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"glide_share": 1.5}, "glide_share"),
        ({"circle_share": -0.1}, "circle_share"),
        ({"circle_radius": (60.0, 15.0)}, "circle_radius"),
        ({"circle_radius": (0.0, 15.0)}, "circle_radius"),
        ({"thermal_targets": "x"}, "thermal_targets"),
        ({"thermal_target_radius": 0.0}, "thermal_target_radius"),
        ({"cost_bound": 1}, "cost_bound"),
        ({"completions": -1}, "completions"),
        ({"completion_depth": 0}, "completion_depth"),
        ({"refinements": -1}, "refinements"),
        ({"refinements": 1.5}, "refinements"),
    ],
)
def test_bad_soaring_settings_name_the_field(kwargs: dict, match: str) -> None:
    with pytest.raises(SSTError, match=match):
        SoaringSSTConfig(**kwargs)


def test_soaring_plans_replay_and_are_deterministic(model: SoaringModel) -> None:
    from test_sst_soaring import assert_replays

    for kind in SAMPLERS:
        a = plan_soaring(model, kind, max_iterations=5000, seed=1)
        b = plan_soaring(model, kind, max_iterations=5000, seed=1)
        assert a.plan.solved and a.plan.to_dict() == b.plan.to_dict()
        assert_replays(a.plan, model.scenario)
