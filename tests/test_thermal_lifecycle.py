"""Thermal life cycle and strength fluctuation: the envelope's closed form, the updraft's linearity
in the strength, steady thermals' numbers unchanged (hard-coded values of the code before these
options), random scenarios (old seeds unchanged, new options reproducible), JSON, the rollout and
observation of dying thermals, the bounds, and validation of every new field."""

from __future__ import annotations

import dataclasses
import json
import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from baselines.reference.beam import ReferenceConfig, control_set, thermal_values
from baselines.sst.planner import plan_soaring
from baselines.sst.soaring import S_H, S_T, SoaringProblem
from soaring_env import Aircraft, ConfigError, Thermal, WindField, rollout
from soaring_env.env import ENV_ID
from soaring_env.env.observation import N_BASE, N_THERMAL_FEATURES
from soaring_env.model import SoaringModel
from soaring_env.physics.thermals import COL_DYNAMIC, COL_PEAK, MIN_PERIOD, PACKED_COLUMNS
from soaring_env.scenario import GoalRegion, Scenario, get_scenario, make_scenario, paper_scenario

LIFE = {"birth": 100.0, "lifetime": 1000.0, "rise": 200.0, "decay": 300.0}  # death at 1100 s
CIRCLE = 107  # spiral at 10 m/s, level: circles a thermal core


# --- the envelope and the fluctuation ------------------------------------------------------------------
@pytest.mark.parametrize(
    ("t", "expected"),
    [
        (-50.0, 0.0),  # unborn
        (100.0, 0.0),  # at birth
        (150.0, math.sin(math.pi / 8) ** 2),  # a quarter into the rise
        (200.0, 0.5),  # mid-rise
        (300.0, 1.0),  # mature from birth + rise
        (600.0, 1.0),
        (800.0, 1.0),  # until death - decay
        (950.0, 0.5),  # mid-decay
        (1100.0, 0.0),  # at death
        (5000.0, 0.0),  # dead
    ],
)
def test_envelope_closed_form(t: float, expected: float) -> None:
    th = Thermal(0.0, 0.0, 2.0, **LIFE)
    assert th.factor(t) == pytest.approx(expected, abs=1e-15)
    assert th.strength_at(t) == pytest.approx(2.0 * expected, abs=1e-15)
    assert th.alive(t) == (100.0 < t < 1100.0)
    assert th.death == 1100.0 and not th.steady


def test_abrupt_ramps_and_fluctuation() -> None:
    box = Thermal(0.0, 0.0, birth=10.0, lifetime=50.0)  # rise = decay = 0: a box car
    assert [box.factor(t) for t in (10.0, 10.001, 35.0, 59.999, 60.0)] == [0.0, 1.0, 1.0, 1.0, 0.0]
    a, p, phi = 0.3, 250.0, 0.7
    fl = Thermal(0.0, 0.0, 2.0, amplitude=a, period=p, phase=phi)  # steady life, fluctuating
    assert not fl.steady and fl.alive(-1e9) and fl.peak_strength == pytest.approx(2.6)
    for t in (-400.0, 0.0, 62.5, 1234.5):
        assert fl.factor(t) == pytest.approx(1.0 + a * math.sin(2.0 * math.pi * t / p + phi), rel=1e-14)
    both = Thermal(0.0, 0.0, 2.0, amplitude=a, period=p, phase=phi, **LIFE)
    for t in (150.0, 500.0, 950.0, 2000.0):
        assert both.factor(t) == pytest.approx(Thermal(0.0, 0.0, **LIFE).factor(t) * fl.factor(t), rel=1e-14)


def _grid(rng: np.random.Generator, centre: tuple[float, float], n: int = 4000) -> tuple[np.ndarray, ...]:
    """Points around a centre at all heights (incl. Allen's downdraft band 0.5 < z/zi <= 0.9)."""
    r = rng.uniform(0.0, 300.0, n)
    a = rng.uniform(-math.pi, math.pi, n)
    return centre[0] + r * np.cos(a), centre[1] + r * np.sin(a), rng.uniform(1.0, 1399.0, n)


@pytest.mark.parametrize("model", ["allen", "gaussian"])
def test_updraft_is_the_steady_one_times_the_factor(model: str, rng: np.random.Generator) -> None:
    """Allen's updraft is linear in w*: wbar, w_peak = 3 wbar / (1 + r1/r2 + (r1/r2)^2) and the
    downdraft wd wbar all scale with it, the shape ws does not depend on it; a Gaussian's is W times
    its shape. So at any time the updraft is the steady thermal's times E(t) (1 + a sin(...))."""
    steady = Thermal(100.0, -50.0, 2.3, 90.0)
    dyn = dataclasses.replace(steady, amplitude=0.4, period=300.0, phase=1.0, **LIFE)
    fs = WindField(thermals=(steady,), model=model)
    fd = WindField(thermals=(dyn,), model=model)
    n, e, h = _grid(rng, (100.0, -50.0))
    w0 = fs.updraft(n, e, h)
    assert np.any(w0 < 0.0) == (model == "allen")  # the downdraft term is covered
    for t in (0.0, 150.0, 200.0, 517.0, 950.0, 1100.0, 3000.0):
        np.testing.assert_allclose(fd.updraft(n, e, h, t), dyn.factor(t) * w0, rtol=1e-12, atol=1e-15)


def test_gaussian_sums_each_thermal_at_its_own_factor(rng: np.random.Generator) -> None:
    a = Thermal(0.0, 0.0, 2.0, 100.0, amplitude=0.5, period=200.0)
    b = Thermal(120.0, 0.0, 3.0, 150.0, **LIFE)
    both = WindField(thermals=(a, b), model="gaussian")
    sa = WindField(thermals=(dataclasses.replace(a, amplitude=0.0),), model="gaussian")
    sb = WindField(thermals=(Thermal(120.0, 0.0, 3.0, 150.0),), model="gaussian")
    n, e, h = _grid(rng, (60.0, 0.0))
    for t in (0.0, 150.0, 700.0, 1200.0):
        want = a.factor(t) * sa.updraft(n, e, h) + b.factor(t) * sb.updraft(n, e, h)
        np.testing.assert_allclose(both.updraft(n, e, h, t), want, rtol=1e-12, atol=1e-15)


def test_allen_skips_unborn_and_dead_thermals(rng: np.random.Generator) -> None:
    """Allen's updraft comes from the nearest thermal only; one that does not exist now is absent,
    so the next nearest living one rules there."""
    near = Thermal(0.0, 0.0, 3.0, **LIFE)
    other = Thermal(60.0, 0.0, 2.0)
    f = WindField(thermals=(near, other))
    alone = WindField(thermals=(other,))
    n, e, h = _grid(rng, (0.0, 0.0))
    for t in (0.0, 100.0, 1100.0, 2000.0):
        np.testing.assert_array_equal(f.updraft(n, e, h, t), alone.updraft(n, e, h, t))
    assert not np.array_equal(f.updraft(n, e, h, 500.0), alone.updraft(n, e, h, 500.0))
    np.testing.assert_array_equal(f.alive(2000.0), [False, True])
    np.testing.assert_array_equal(f.strengths(500.0), [3.0, 2.0])
    np.testing.assert_array_equal(f.strengths(2000.0), [0.0, 2.0])


# --- steady thermals: the numbers of before ------------------------------------------------------------
# Computed with the code before the life cycle existed (commit a883b93). Heights are compared bit for
# bit; costs to 1e-14 relative, since the propulsive energy's trapezoid sum was regrouped into loops
# that vectorize (2026-12-06), which moves its last bit.
PAPER_ROLLOUT_H = [378.68655948555073, 478.9162164050425, 300.0]
PAPER_ROLLOUT_COST = [-472.5040754465891, 4129.42128639149, 372.83696422141816]
GAUSS_ROLLOUT_H = [368.27908065351755, -179.65326388638965]
GAUSS_ROLLOUT_COST = [-370.55369544197475, 3723.126680291463]
PAPER_UPDRAFT = [1.7641252367938534, 0.6387083096999557]
RANDOM_10000 = (
    '{"name": "random-10000", "start": [-1034.7606756700795, 243.37653295452236, -0.771892258014109, '
    '267.9629220106015], "goal": {"north": 1213.0223010254315, "east": -925.1652896185087, "height": '
    '514.5277884601801, "radius": 150.0}, "bounds": {"north_min": -3000.0, "north_max": 3000.0, "east_min": '
    '-3000.0, "east_max": 3000.0, "height_max": 1500.0}, "field": {"model": "allen", "zi": 1400.0, '
    '"wind_north": 0.13863247949963572, "wind_east": -0.1405948044619154, "drift": false, "thermals": '
    '[{"north": 244.23255097804534, "east": -899.524874043143, "strength": 2.107659239849142, "radius": '
    '80.0}, {"north": 454.1544406511986, "east": -886.1786905437601, "strength": 1.8872284675401634, '
    '"radius": 80.0}, {"north": -96.83817292373384, "east": -9.19513065356972, "strength": '
    '2.175238180882178, "radius": 80.0}, {"north": -209.33103836397532, "east": 43.93018676673995, '
    '"strength": 1.7258427740497644, "radius": 80.0}, {"north": -125.33947996307143, "east": '
    '592.5596447410742, "strength": 2.0800564373366743, "radius": 80.0}]}}'
)


def _gauss_field(**extra: Any) -> WindField:
    return WindField(
        thermals=(Thermal(0.0, 0.0, 2.0, 80.0, **extra), Thermal(150.0, 40.0, 3.0, 120.0, **extra)),
        model="gaussian",
        wind_east=1.0,
        drift=True,
    )


def test_steady_numbers_are_those_of_before(aircraft: Aircraft) -> None:
    sc = paper_scenario()
    st0 = np.array([[1500.0, 230.0, 0.3, 300.0], [1400.0, 250.0, -1.0, 900.0], [1000.0, 0.0, 0.0, 300.0]])
    r = rollout(st0, sc.field, aircraft, primitive=np.array([CIRCLE, 60, 7]), t0=np.array([0.0, 100.0, 5.0]))
    assert r.final[:, 3].tolist() == PAPER_ROLLOUT_H
    np.testing.assert_allclose(r.cost, PAPER_ROLLOUT_COST, rtol=1e-14, atol=0.0)
    st1 = np.array([[10.0, -40.0, 0.3, 300.0], [100.0, 0.0, 2.0, 200.0]])
    r = rollout(st1, _gauss_field(), aircraft, primitive=np.array([CIRCLE, 120]), t0=np.array([0.0, 30.0]))
    assert r.final[:, 3].tolist() == GAUSS_ROLLOUT_H
    np.testing.assert_allclose(r.cost, GAUSS_ROLLOUT_COST, rtol=1e-14, atol=0.0)
    assert [float(sc.field.updraft(1510.0, 240.0, 800.0)), float(sc.field.updraft(1560.0, 250.0, 1000.0))] == (
        PAPER_UPDRAFT
    )
    assert json.dumps(get_scenario("random-10000").to_dict()) == RANDOM_10000


def test_explicit_defaults_and_the_dynamic_path_give_the_same_numbers(aircraft: Aircraft) -> None:
    """Explicit default fields pack identically; and a thermal on the dynamic path whose factor is
    exactly 1 (alive for ever, no fluctuation) reproduces the steady numbers bit for bit."""
    defaults = {"birth": 0.0, "lifetime": None, "rise": 0.0, "decay": 0.0, "amplitude": 0.0, "phase": 0.0}
    plain, explicit = _gauss_field(), _gauss_field(**defaults)
    assert plain == explicit and plain.steady
    np.testing.assert_array_equal(plain.packed, explicit.packed)
    assert plain.packed.shape == (2, PACKED_COLUMNS) and not plain.packed[:, COL_DYNAMIC].any()
    np.testing.assert_array_equal(plain.packed[:, :4], [[0.0, 0.0, 2.0, 80.0], [150.0, 40.0, 3.0, 120.0]])
    forever = {"birth": -1e7, "lifetime": 1e8}
    st1 = np.array([[10.0, -40.0, 0.3, 300.0], [100.0, 0.0, 2.0, 200.0]])
    for steady, dyn in (
        (plain, _gauss_field(**forever)),
        (paper_scenario().field, WindField(thermals=(Thermal(1500.0, 250.0, 2.56, **forever),))),
    ):
        assert dyn.packed[:, COL_DYNAMIC].all()
        np.testing.assert_array_equal(dyn.packed[:, :4], steady.packed[:, :4])
        c = steady.centres()[0]
        x = np.array([[c[0] + 10.0, c[1] - 20.0, 0.3, 300.0], *st1])
        a = rollout(x, steady, aircraft, primitive=np.array([CIRCLE, CIRCLE, 120]), t0=np.array([0.0, 0.0, 30.0]))
        b = rollout(x, dyn, aircraft, primitive=np.array([CIRCLE, CIRCLE, 120]), t0=np.array([0.0, 0.0, 30.0]))
        np.testing.assert_array_equal(a.states, b.states)
        np.testing.assert_array_equal(a.cost, b.cost)


# --- random scenarios ------------------------------------------------------------------------------------
TIME_OPTIONS: dict[str, Any] = {
    "lifecycle": (600.0, 1800.0),
    "rise_time": 90.0,
    "birth_window": (-600.0, 900.0),
    "strength_variation": (0.1, 0.4),
    "variation_period": (200.0, 800.0),
}


def test_random_scenarios_with_the_options_off_are_those_of_before() -> None:
    assert json.dumps(make_scenario(np.random.default_rng(10000), name="random-10000").to_dict()) == RANDOM_10000
    off = {"lifecycle": None, "strength_variation": None, "rise_time": 120.0, "birth_window": (0.0, 0.0)}
    for seed in range(20):
        a = make_scenario(np.random.default_rng(seed))
        b = make_scenario(np.random.default_rng(seed), **off)
        assert a == b and a.field.steady


@pytest.mark.parametrize(
    "options",
    [
        TIME_OPTIONS,
        {"lifecycle": (300.0, 300.0), "rise_time": 150.0},
        {"strength_variation": (0.0, 0.9)},
    ],
)
def test_random_time_options_are_reproducible_and_drawn_last(options: dict[str, Any]) -> None:
    for seed in range(12):
        sc = make_scenario(np.random.default_rng(seed), **options)
        assert sc == make_scenario(np.random.default_rng(seed), **options)
        base = make_scenario(np.random.default_rng(seed))
        # the new numbers come after every old draw: all else is the steady scenario's
        strip = {"birth": 0.0, "lifetime": None, "rise": 0.0, "decay": 0.0, "amplitude": 0.0, "period": 600.0}
        assert (
            sc.replace(
                field=dataclasses.replace(
                    sc.field, thermals=tuple(dataclasses.replace(t, phase=0.0, **strip) for t in sc.field.thermals)
                )
            )
            == base
        )
        for t in sc.field.thermals:
            if "lifecycle" in options:
                lo, hi = options["lifecycle"]
                assert lo <= t.lifetime <= hi and t.rise == t.decay == options["rise_time"]  # type: ignore[operator]
                b0, b1 = options.get("birth_window", (0.0, 0.0))
                assert b0 <= t.birth <= b1
            else:
                assert t.lifetime is None
            if "strength_variation" in options:
                assert options["strength_variation"][0] <= t.amplitude <= options["strength_variation"][1]
                p0, p1 = options.get("variation_period", (300.0, 900.0))
                assert p0 <= t.period <= p1 and -math.pi <= t.phase <= math.pi
            else:
                assert t.amplitude == 0.0
    assert get_scenario("random-7", TIME_OPTIONS) == make_scenario(
        np.random.default_rng(7), **TIME_OPTIONS, name="random-7"
    )


# --- JSON ----------------------------------------------------------------------------------------------------
def test_json_round_trip_with_the_new_fields() -> None:
    th = Thermal(100.0, -3.3, 1.7, 55.5, birth=-12.5, lifetime=987.25, rise=33.0, decay=44.0)
    fl = Thermal(1e-7, 2500.0, 4.0, 300.0, amplitude=0.25, period=123.456, phase=-2.0)
    sc = paper_scenario().replace(field=WindField(thermals=(th, fl, Thermal(5.0, 6.0))))
    text = sc.to_json()
    back = Scenario.from_json(text)
    assert back == sc and back.to_json() == text
    ths = json.loads(text)["field"]["thermals"]
    assert set(ths[0]) == {"north", "east", "strength", "radius", "birth", "lifetime", "rise", "decay"}
    assert set(ths[1]) == {"north", "east", "strength", "radius", "amplitude", "period", "phase"}
    assert set(ths[2]) == {"north", "east", "strength", "radius"}  # steady: the JSON of before
    d = json.loads(text)
    d["field"]["thermals"][1]["lifetime"] = None  # null: steady life
    assert Scenario.from_dict(d).field.thermals[1] == fl


def test_old_json_without_the_new_keys_loads() -> None:
    old = json.loads(RANDOM_10000)
    sc = Scenario.from_dict(old)
    assert sc == get_scenario("random-10000") and sc.field.steady
    assert all(t.lifetime is None and t.amplitude == 0.0 for t in sc.field.thermals)


# --- the rollout, the observation, the bounds and the planners ---------------------------------------------
def _circling_start(t: Thermal) -> np.ndarray:
    return np.array([t.north, t.east - 16.0, 0.0, 300.0])


def test_no_lift_after_death(aircraft: Aircraft) -> None:
    """An edge circling a thermal's core after its death sees no lift: it flies as in still air."""
    th = Thermal(1500.0, 250.0, 2.56, **LIFE)
    f = WindField(thermals=(th,))
    still = WindField()
    x = _circling_start(th)
    dead = rollout(x, f, aircraft, primitive=CIRCLE, t0=1100.0)
    calm = rollout(x, still, aircraft, primitive=CIRCLE, t0=1100.0)
    np.testing.assert_array_equal(dead.states, calm.states)
    assert dead.cost[0] == calm.cost[0] and dead.final[0, 3] == 300.0
    unborn = rollout(x, f, aircraft, primitive=CIRCLE, t0=-500.0)
    np.testing.assert_array_equal(unborn.states, calm.states)
    mature = rollout(x, f, aircraft, primitive=CIRCLE, t0=500.0)
    steady = rollout(x, WindField(thermals=(Thermal(1500.0, 250.0, 2.56),)), aircraft, primitive=CIRCLE, t0=500.0)
    np.testing.assert_array_equal(mature.states, steady.states)  # factor exactly 1 while mature
    assert mature.final[0, 3] > 350.0
    # an edge across its death (1100 s): climbs until then, then no more lift
    dying = rollout(x, f, aircraft, primitive=CIRCLE, t0=1090.0)
    h = dying.states[0, :, 3]
    assert h[0] > 300.0 and np.all(np.diff(h[10:]) == 0.0)


def test_updraft_bound_holds_at_all_times(rng: np.random.Generator) -> None:
    for model in ("allen", "gaussian"):
        for seed in range(6):
            kw = {"n_thermals": (3, 8), "strength_variation": (0.5, 0.95), "lifecycle": (400.0, 900.0)}
            f = make_scenario(np.random.default_rng(seed), model=model, **kw).field
            want = 1.2 * max(t.peak_strength for t in f.thermals) if model == "allen" else None
            if want is not None:
                assert f.updraft_bound == want
            else:
                assert f.updraft_bound == pytest.approx(sum(t.peak_strength for t in f.thermals))
            c = f.centres()[rng.integers(0, len(f.thermals), 20000)]
            n = c[:, 0] + rng.normal(0.0, 60.0, len(c))
            e = c[:, 1] + rng.normal(0.0, 60.0, len(c))
            h = rng.uniform(0.0, 1400.0, len(c))
            t = rng.uniform(-600.0, 2000.0, len(c))
            w = f.updraft(n, e, h, t)
            assert np.abs(w).max() <= f.updraft_bound
            assert w.max() > 0.5 * f.updraft_bound / (1.2 if model == "allen" else len(f.thermals))
            assert np.all(f.packed[:, COL_PEAK] == [t.peak_strength for t in f.thermals])


def test_end_height_cap_uses_the_peak_strength() -> None:
    g = GoalRegion(north=3000.0, east=0.0, height=300.0, radius=150.0)
    sc = paper_scenario().replace(goal=g)
    for amp in (0.0, 0.5):
        th = Thermal(3000.0, 0.0, 2.0, amplitude=amp, period=100.0)
        m = SoaringModel(scenario=sc.replace(field=WindField(thermals=(th,))))
        lib = m.library
        assert m.end_height_cap() == min(
            450.0 + 1.2 * 2.0 * (1.0 + amp) * (lib.duration - lib.duration / lib.n_points), 1500.0
        )


def _thermal_slots(obs: np.ndarray) -> np.ndarray:
    return obs[N_BASE:].reshape(-1, N_THERMAL_FEATURES)


def test_observation_lists_only_living_thermals_at_their_current_strength() -> None:
    dead = Thermal(1000.0, 0.0, 3.0, birth=-1000.0, lifetime=500.0)  # nearer the start, but dead
    born_later = Thermal(1100.0, 0.0, 3.0, birth=100.0, lifetime=2000.0, rise=0.0)
    fluct = Thermal(1500.0, 250.0, 2.0, amplitude=0.5, period=120.0, phase=0.3)
    ref = Thermal(1500.0, 250.0, 2.0)
    sc = paper_scenario().replace(field=WindField(thermals=(dead, born_later, fluct)))
    env = gym.make(ENV_ID, scenario=sc)
    obs, _ = env.reset(seed=0)
    slots = _thermal_slots(obs)
    assert slots[0, 0] == 1.0 and slots[0, 1] == pytest.approx(1.5)  # the fluctuating one, 1.5 km north
    np.testing.assert_array_equal(slots[1:], 0.0)  # the dead and the unborn one hold no slot
    steady_env = gym.make(ENV_ID, scenario=sc.replace(field=WindField(thermals=(ref,))))
    obs0, _ = steady_env.reset(seed=0)
    assert slots[0, 3] == pytest.approx(_thermal_slots(obs0)[0, 3] * fluct.factor(0.0), rel=1e-6)
    for _ in range(4):  # 120 s later: the thermal born at 100 s is there
        obs, *_ = env.step(7)
    assert env.unwrapped.time == 120.0
    slots = _thermal_slots(obs)
    assert slots[:2, 0].tolist() == [1.0, 1.0] and slots[2, 0] == 0.0
    env.close()
    steady_env.close()


@pytest.mark.filterwarnings("ignore:.*render_mode:UserWarning")
def test_render_with_a_life_cycle() -> None:
    sc = paper_scenario().replace(
        field=WindField(thermals=(Thermal(1500.0, 250.0, 2.56, birth=20.0, lifetime=600.0, rise=60.0, decay=60.0),))
    )
    env = gym.make(ENV_ID, scenario=sc, render_mode="rgb_array")
    env.reset(seed=0)
    before = env.render()  # unborn: no column, a faint marker
    env.step(7)
    env.step(7)
    after = env.render()
    assert before.shape == after.shape == (640, 960, 3) and not np.array_equal(before, after)
    env.close()


def test_planners_on_a_life_cycle_scenario() -> None:
    """SST and the reference search plan through the same kernel; their heuristics skip thermals
    that are dead when they would be used (smoke test: they run and return valid plans)."""
    sc = make_scenario(np.random.default_rng(3), lifecycle=(300.0, 900.0), birth_window=(-900.0, 300.0))
    m = SoaringModel(scenario=sc)
    res = plan_soaring(m, max_iterations=256, config={"batch_size": 64}, partial=True)
    assert np.all(np.isfinite(res.plan.trajectory))  # and its edges re-fly to the tree's nodes
    for sampler in ("primitive", "continuous"):  # the steering rule at times with and without living thermals
        problem = SoaringProblem(m, sampler)
        x = np.repeat(problem.root_state()[None, :], 4, axis=0)
        x[:, S_H] = 60.0  # too low to glide home: a living thermal is worth a detour
        x[:, S_T] = [0.0, 300.0, 900.0, 1e6]  # at 1e6 s every thermal is dead: fly home
        u = problem.goal_controls(x)
        assert u.shape[0] == 4 and np.all(np.isfinite(u))
    rows = thermal_values(m, control_set(m, "primitive", ReferenceConfig()))
    alive_later = [t for t in sc.field.thermals if t.death > max(0.0, t.birth + t.rise)]
    assert rows.shape[0] <= len(alive_later)


# --- validation -----------------------------------------------------------------------------------------------
anything = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1e4, 1e4),
    st.integers(-(10**6), 10**6),
    st.text(max_size=3),
    st.sampled_from(["3", "nan", ""]),
    st.booleans(),
    st.none(),
    st.lists(st.floats(-10, 10), max_size=3),
    st.just(np.float32(2.0)),
)
NEW_THERMAL_FIELDS = ("birth", "lifetime", "rise", "decay", "amplitude", "period", "phase")


@settings(max_examples=150, deadline=None)
@given(name=st.sampled_from(NEW_THERMAL_FIELDS), value=anything, with_life=st.booleans())
def test_bad_thermal_fields(name: str, value: Any, with_life: bool) -> None:
    kw: dict[str, Any] = {"lifetime": 2000.0, "rise": 100.0, "decay": 100.0} if with_life else {}
    kw[name] = value
    try:
        th = Thermal(0.0, 0.0, **kw)
    except ConfigError as exc:
        # the field itself, or the lifetime it needs / it is too short for
        assert f"thermal.{name}" in str(exc) or "thermal.lifetime" in str(exc), str(exc)
        return
    for f in NEW_THERMAL_FIELDS:
        v = getattr(th, f)
        assert (f == "lifetime" and v is None) or (type(v) is float and math.isfinite(v)), (f, v)
    assert 0.0 <= th.amplitude < 1.0 and th.period >= MIN_PERIOD and th.rise >= 0.0 and th.decay >= 0.0
    if th.lifetime is not None:
        assert th.lifetime >= th.rise + th.decay
    else:
        assert th.birth == th.rise == th.decay == 0.0
    w = WindField(thermals=(th,)).updraft(np.zeros(5), np.zeros(5), 300.0, np.linspace(-3000.0, 3000.0, 5))
    assert np.all(np.isfinite(w))


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"lifetime": 100.0, "rise": 60.0, "decay": 60.0}, "thermal.lifetime=100.0 is shorter than rise"),
        ({"lifetime": -5.0}, "thermal.lifetime=-5.0 must be > 0"),
        ({"lifetime": 100.0, "rise": -1.0}, "thermal.rise=-1.0 must be >= 0"),
        ({"birth": 10.0}, "thermal.birth=10.0 needs a thermal.lifetime"),
        ({"amplitude": 1.0}, r"thermal.amplitude=1.0 is outside the allowed range \[0, 1\)"),
        ({"period": 5.0}, "thermal.period=5.0 must be >= 10"),
        ({"phase": math.nan}, "thermal.phase=nan is not finite"),
        ({"lifetime": "600"}, "thermal.lifetime='600' has type str"),
    ],
)
def test_thermal_messages(kw: dict[str, Any], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        Thermal(0.0, 0.0, **kw)


pairs = st.one_of(
    st.tuples(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True, allow_infinity=True)),
    st.tuples(st.floats(-2000.0, 5000.0), st.floats(-2000.0, 5000.0)),
    st.tuples(st.floats(0.0, 1.2), st.floats(0.0, 1.2)),
    st.just((1.0,)),
    st.just("1,2"),
    st.just(("1", "2")),
    st.just(5),
    st.none(),
)
RANDOM_TIME_FIELDS = ("lifecycle", "rise_time", "birth_window", "strength_variation", "variation_period")


@settings(max_examples=150, deadline=None)
@given(name=st.sampled_from(RANDOM_TIME_FIELDS), value=st.one_of(pairs, anything), with_options=st.booleans())
def test_bad_random_time_options(name: str, value: Any, with_options: bool) -> None:
    kw: dict[str, Any] = {"lifecycle": (600.0, 900.0), "strength_variation": (0.0, 0.5)} if with_options else {}
    kw[name] = value
    try:
        sc = make_scenario(np.random.default_rng(0), **kw)
    except ConfigError as exc:
        assert name in str(exc), str(exc)
        return
    SoaringModel(scenario=sc)
    assert Scenario.from_json(sc.to_json()) == sc


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"lifecycle": (100.0, 500.0)}, r"lifecycle=\(100.0, 500.0\) allows lifetimes shorter than rise \+ decay"),
        ({"lifecycle": (0.0, 500.0), "rise_time": 0.0}, "lifecycle=.* must have low > 0"),
        ({"rise_time": 60.0}, "rise_time=60.0 needs lifecycle"),
        ({"birth_window": (0.0, 600.0)}, "birth_window=.* needs lifecycle"),
        ({"variation_period": (60.0, 90.0)}, "variation_period=.* needs strength_variation"),
        ({"strength_variation": (0.5, 1.0)}, "strength_variation=.* must have high < 1"),
        ({"strength_variation": (0.5, 0.2)}, "strength_variation=.* must be a pair"),
        ({"strength_variation": (0.1, 0.2), "variation_period": (5.0, 60.0)}, "variation_period=.* must be a pair"),
    ],
)
def test_random_time_option_messages(kw: dict[str, Any], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        make_scenario(np.random.default_rng(0), **kw)


def test_env_config_takes_the_new_keywords() -> None:
    env = gym.make(ENV_ID, scenario="random", random_scenario=TIME_OPTIONS)
    obs, _ = env.reset(seed=4)
    assert np.all(np.isfinite(obs))
    assert not env.unwrapped.scenario.field.steady
    env.close()
    with pytest.raises(ConfigError, match="rise_time"):
        gym.make(ENV_ID, scenario="random", random_scenario={"rise_time": 30.0})


def test_native_vector_env_equals_sync_with_life_cycles() -> None:
    """The batched env reads the same packed columns as the single env (thermal tables padded to
    the widest scenario of the batch)."""
    kw = {"num_envs": 4, "scenario": "random", "random_scenario": {**TIME_OPTIONS, "n_thermals": (0, 6)}}
    sync = gym.make_vec(ENV_ID, vectorization_mode="sync", **kw)
    native = gym.make_vec(ENV_ID, **kw)
    assert np.array_equal(sync.reset(seed=5)[0], native.reset(seed=5)[0])
    rng = np.random.default_rng(2)
    for _ in range(60):
        a = rng.integers(0, 174, 4)
        r1, r2 = sync.step(a), native.step(a)
        for x, y in zip(r1[:4], r2[:4], strict=True):
            assert np.array_equal(x, y)
    sync.close()
    native.close()
