"""Batched random scenarios (distribution v2): determinism, packed rows that rebuild into identical
Scenarios, the keyword ranges, validation, single env == vector env row, and v1 left untouched;
batched task draws equal to their generators' scenarios bit for bit."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils import seeding
from hypothesis import given, settings
from hypothesis import strategies as st

import soaring_env  # noqa: F401  (registers the ids)
from soaring_env import ConfigError
from soaring_env.env import ENV_ID
from soaring_env.env.observation import P_GE, P_GH, P_GN, P_WE, P_WN, scenario_params
from soaring_env.env.scenario_batch import (
    RANDOM_SCENARIO_VERSION,
    GeneratorSampler,
    ScenarioSampler,
    draw_scenario_arrays,
    draw_width,
    generator_list,
    random_spec,
)
from soaring_env.env.vector import SoaringVectorEnv
from soaring_env.physics.thermals import PACKED_COLUMNS
from soaring_env.scenario import (
    RANDOM_MARGIN,
    Bounds,
    Scenario,
    get_scenario,
    heldout_names,
    make_climb_scenario,
    make_cross_country_scenario,
    make_scenario,
)
from soaring_env.scenario import RandomScenarioSpec as Spec

ROOT = Path(__file__).resolve().parents[1]
KWARGS = [
    {},
    {"model": "gaussian", "n_thermals": (0, 9), "drift": True},
    {"n_thermals": (0, 0), "wind_speed": (3.0, 3.0), "zi": 900.0},
    {
        "bounds": Bounds(-1000.0, 1000.0, -1500.0, 1500.0, 800.0),
        "goal_distance": (200.0, 900.0),
        "height": (5.0, 700.0),
    },
    {"lateral_spread": 0.05, "n_thermals": (2, 4)},
    {"thermal_along": (0.0, 0.1), "n_thermals": (1, 3)},
]


def _bits(a: np.ndarray) -> bytes:
    """The bytes of a float64 array: equal bytes = bit-identical (-0.0 != 0.0, NaN == NaN)."""
    return np.ascontiguousarray(a, dtype=np.float64).tobytes()


def test_version_and_width() -> None:
    assert RANDOM_SCENARIO_VERSION == 2
    assert draw_width(random_spec({})) == 10 + 3 * 5


@pytest.mark.parametrize("kw", KWARGS)
def test_draws_are_deterministic(kw: dict) -> None:
    a = draw_scenario_arrays(np.random.default_rng(3), 64, **kw)
    b = draw_scenario_arrays(np.random.default_rng(3), 64, **kw)
    for x, y in ((a.params, b.params), (a.thermals, b.thermals), (a.start, b.start)):
        assert _bits(x) == _bits(y)
    assert np.array_equal(a.n_thermals, b.n_thermals)
    c = draw_scenario_arrays(np.random.default_rng(4), 64, **kw)
    assert _bits(a.start) != _bits(c.start)
    # n draws from one generator = the same generator drawn 1 at a time
    g = np.random.default_rng(3)
    one = [draw_scenario_arrays(g, 1, **kw) for _ in range(64)]
    assert _bits(np.concatenate([o.params for o in one])) == _bits(a.params)
    assert _bits(np.concatenate([o.start for o in one])) == _bits(a.start)


@pytest.mark.parametrize("kw", KWARGS)
def test_rebuilt_scenarios_pack_back_bit_for_bit(kw: dict) -> None:
    batch = draw_scenario_arrays(np.random.default_rng(11), 200, **kw)
    assert batch.thermals.shape == (200, max(1, random_spec(kw).n_thermals[1]), PACKED_COLUMNS)
    for i in range(len(batch)):
        sc = batch.scenario(i)
        k = int(batch.n_thermals[i])
        assert isinstance(sc, Scenario) and sc.name == "random" and len(sc.field.thermals) == k
        assert _bits(scenario_params(sc)) == _bits(batch.params[i])
        assert _bits(sc.field.packed) == _bits(batch.thermals[i, :k])
        assert _bits(sc.start_state) == _bits(batch.start[i])
        assert not batch.thermals[i, k:].any()  # zero padding
        assert Scenario.from_json(sc.to_json()) == sc


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_lo=st.integers(0, 6),
    n_extra=st.integers(0, 6),
    s_lo=st.floats(0.1, 5.0),
    s_extra=st.floats(0.0, 5.0),
    w_lo=st.floats(0.0, 10.0),
    w_extra=st.floats(0.0, 10.0),
    d_lo=st.floats(151.0, 2500.0),
    d_extra=st.floats(0.0, 2000.0),
    h_lo=st.floats(1.0, 700.0),
    h_extra=st.floats(0.0, 700.0),
    model=st.sampled_from(["allen", "gaussian"]),
    drift=st.booleans(),
)
def test_draws_respect_the_ranges(
    seed: int,
    n_lo: int,
    n_extra: int,
    s_lo: float,
    s_extra: float,
    w_lo: float,
    w_extra: float,
    d_lo: float,
    d_extra: float,
    h_lo: float,
    h_extra: float,
    model: str,
    drift: bool,
) -> None:
    kw = {
        "n_thermals": (n_lo, n_lo + n_extra),
        "strength": (s_lo, s_lo + s_extra),
        "wind_speed": (w_lo, w_lo + w_extra),
        "goal_distance": (d_lo, d_lo + d_extra),
        "height": (h_lo, h_lo + h_extra),
        "model": model,
        "drift": drift,
    }
    batch = draw_scenario_arrays(np.random.default_rng(seed), 32, **kw)
    b = random_spec(kw).domain
    p, s, th, k = batch.params, batch.start, batch.thermals, batch.n_thermals
    tol = 1e-9
    for north, east in ((s[:, 0], s[:, 1]), (p[:, P_GN], p[:, P_GE])):
        assert np.all(north >= b.north_min + RANDOM_MARGIN) and np.all(north <= b.north_max - RANDOM_MARGIN)
        assert np.all(east >= b.east_min + RANDOM_MARGIN) and np.all(east <= b.east_max - RANDOM_MARGIN)
    for h in (s[:, 3], p[:, P_GH]):
        assert np.all(h >= h_lo) and np.all(h <= h_lo + h_extra)
    dist = np.hypot(p[:, P_GN] - s[:, 0], p[:, P_GE] - s[:, 1])
    assert np.all(dist >= d_lo * (1 - tol)) and np.all(dist <= (d_lo + d_extra) * (1 + tol))
    assert np.all(s[:, 2] >= -math.pi) and np.all(s[:, 2] < math.pi)
    assert np.all(k >= n_lo) and np.all(k <= n_lo + n_extra)
    wind = np.hypot(p[:, P_WN], p[:, P_WE])
    assert np.all(wind >= w_lo * (1 - tol) - tol) and np.all(wind <= (w_lo + w_extra) * (1 + tol) + tol)
    for i in range(len(batch)):
        w = th[i, : k[i], 2]
        assert np.all(w >= s_lo) and np.all(w <= s_lo + s_extra)
        sc = batch.scenario(i)  # a valid Scenario: start and goal inside, start outside the goal
        assert sc.field.model == model and sc.field.drift is drift


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"n_thermals": (3, 1)}, "n_thermals"),
        ({"n_thermals": (0, 101)}, "n_thermals"),
        ({"strength": (0.0, 1.0)}, "strength"),
        ({"wind_speed": (-1.0, 2.0)}, "wind_speed"),
        ({"goal_distance": (100.0, 200.0)}, "goal_distance"),
        ({"goal_distance": (1000.0, 9000.0)}, "goal_distance"),
        ({"height": (0.0, 100.0)}, "height"),
        ({"height": (100.0, 2000.0)}, "height"),
        ({"model": "nope"}, "model"),
        ({"zi": -1.0}, "zi"),
        ({"drift": "yes"}, "drift"),
        ({"bounds": "box"}, "bounds"),
        ({"name": 3}, "name"),
        ({"lateral_spread": -0.1}, "lateral_spread"),
        ({"lateral_spread": 1.5}, "lateral_spread"),
        ({"lateral_spread": "wide"}, "lateral_spread"),
        ({"thermal_along": (0.5, 0.2)}, "thermal_along"),
        ({"thermal_along": (-0.1, 0.5)}, "thermal_along"),
        ({"thermal_along": (0.0, 1.5)}, "thermal_along"),
        ({"thermal_along": 0.5}, "thermal_along"),
        ({"thermal_along": ("a", 0.5)}, "thermal_along"),
    ],
)
def test_bad_ranges_raise_naming_the_field(kw: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field) as batched:
        draw_scenario_arrays(np.random.default_rng(0), 4, **kw)
    with pytest.raises(ConfigError, match=field) as single:
        make_scenario(np.random.default_rng(0), **kw)
    assert str(batched.value) == str(single.value)  # one validation for both
    with pytest.raises(ConfigError, match=field):
        gym.make(ENV_ID, scenario="random", random_scenario=kw)
    with pytest.raises(TypeError):
        draw_scenario_arrays(np.random.default_rng(0), 4, thermals=3)  # not a keyword of make_scenario


def test_bad_generator_and_count_and_unsatisfiable_bounds() -> None:
    with pytest.raises(ConfigError, match="rng"):
        draw_scenario_arrays(np.random.RandomState(0), 2)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="n="):
        draw_scenario_arrays(np.random.default_rng(0), 0)
    tight = {"bounds": Bounds(-350.0, 350.0, -350.0, 350.0, 1000.0), "goal_distance": (200.0, 300.0)}
    with pytest.raises(ConfigError, match="could not draw a scenario that fits"):
        draw_scenario_arrays(np.random.default_rng(0), 2, **tight)


def test_sampler_writes_only_the_given_rows() -> None:
    sampler = ScenarioSampler({"n_thermals": (2, 2)})
    prm, th = np.full((6, 15), -7.0), np.full((6, 3, PACKED_COLUMNS), -7.0)
    nth, start = np.full(6, -1, dtype=np.int64), np.full((6, 4), -7.0)
    sampler.draw_from(np.array([4, 1]), np.random.default_rng(5), prm, th, nth, start)
    assert set(np.flatnonzero(nth >= 0)) == {1, 4} and np.all(nth[[1, 4]] == 2)
    assert np.all(prm[[0, 2, 3, 5]] == -7.0) and np.all(th[[1, 4], 2] == -7.0)  # slot 2 left alone
    ref = draw_scenario_arrays(np.random.default_rng(5), 2, n_thermals=(2, 2))
    assert _bits(start[[4, 1]]) == _bits(ref.start)  # rows in the order given
    with pytest.raises(ConfigError, match="slots"):
        sampler.draw_from(np.array([0]), np.random.default_rng(5), prm, th[:, :1], nth, start)


def test_single_env_draws_with_n_1_from_its_np_random() -> None:
    env = gym.make(ENV_ID, scenario="random", random_scenario={"model": "gaussian"})
    for seed in (0, 1, 2):
        env.reset(seed=seed)
        rng, _ = seeding.np_random(seed)
        ref = draw_scenario_arrays(rng, 2, model="gaussian")
        assert env.unwrapped.scenario == ref.scenario(0)
        env.reset()  # the same generator, on
        assert env.unwrapped.scenario == ref.scenario(1)


def test_vector_env_scenarios_equal_single_envs_and_are_lazy() -> None:
    n = 6
    venv = SoaringVectorEnv(num_envs=n, scenario="random")
    singles = [gym.make(ENV_ID, scenario="random") for _ in range(n)]
    _, info = venv.reset(seed=20)
    for i, s in enumerate(singles):
        s.reset(seed=20 + i)
    assert venv._lazy.all()  # nothing built at reset
    assert list(info["scenario"]) == ["random"] * n
    rng = np.random.default_rng(0)
    done = np.zeros(n, dtype=bool)
    resets = 0
    for step in range(60):
        a = rng.integers(0, 174, n)
        venv.step(a)
        for i, s in enumerate(singles):  # NEXT_STEP autoreset: a finished env resets one step later
            if done[i]:
                s.reset()
                done[i] = False
                resets += 1
            else:
                _, _, t1, t2, _ = s.step(int(a[i]))
                done[i] = t1 or t2
        if step % 7 == 0:
            scs = venv.scenarios
            assert not venv._lazy.any()
            for i, s in enumerate(singles):
                assert scs[i] == s.unwrapped.scenario
                assert _bits(scenario_params(scs[i])) == _bits(venv._prm[i])
            models = venv.models
            assert all(m.scenario is sc for m, sc in zip(models, scs, strict=True))
            assert venv.scenarios[0] is scs[0]  # built once per episode
    assert resets > 0


def test_vector_env_reseeding_some_envs_switches_their_generators() -> None:
    venv = SoaringVectorEnv(num_envs=3, scenario="random")
    venv.reset(seed=1)
    venv.reset(seed=[None, 9, None])
    single = gym.make(ENV_ID, scenario="random")
    single.reset(seed=9)
    assert venv.scenarios[1] == single.unwrapped.scenario
    single.reset(seed=1)
    single.reset()  # env 0 kept its generator: its second draw
    assert venv.scenarios[0] == single.unwrapped.scenario


def test_random_seed_names_stay_v1_bit_for_bit() -> None:
    """``random-<seed>`` names still draw ``make_scenario`` (v1): the published held-out scenarios
    (results/reference) and a hash of the held-out and validation sets taken before v2 existed."""
    names = heldout_names(20) + [f"random-{5000 + k}" for k in range(20)]
    text = "\n".join(get_scenario(n).to_json() for n in names)
    assert hashlib.sha256(text.encode()).hexdigest() == (
        "96d596ccbf56d7ec7985508d4f352f5bee66e5b88e8ab11b578a75d4f7fecaf3"
    )
    published = sorted((ROOT / "results" / "reference").glob("random-*.json"))
    assert len(published) == 20
    for path in published:
        d = json.loads(path.read_text())["scenario"]
        assert Scenario.from_dict(d) == get_scenario(path.stem)
    spec = Spec()
    assert spec.domain == Bounds(-3000.0, 3000.0, -3000.0, 3000.0, 1500.0)


def _line_fractions(kw: dict, seed: int) -> np.ndarray:
    """(along, across) of every thermal of 64 draws of each kind (batched and per scenario), as
    fractions of the goal distance in the start-goal frame (across unsigned)."""
    batch = draw_scenario_arrays(np.random.default_rng(seed), 64, **kw)
    singles = [make_scenario(np.random.default_rng(i), **kw) for i in range(64)]
    out = []
    for i in range(len(batch)):
        for sc in (batch.scenario(i), singles[i]):
            s0 = np.array(sc.start[:2])
            line = np.array([sc.goal.north, sc.goal.east]) - s0
            dist2 = float(line @ line)
            for t in sc.field.thermals:
                rel = np.array([t.north, t.east]) - s0
                out.append((float(rel @ line) / dist2, abs(line[0] * rel[1] - line[1] * rel[0]) / dist2))
    return np.array(out)


@pytest.mark.parametrize("spread", [0.0, 0.1, 0.3])
def test_lateral_spread_bounds_the_thermals_distance_from_the_line(spread: float) -> None:
    """Thermals lie within spread x goal distance of the start-goal line, both draws; 0: on it."""
    across = _line_fractions({"lateral_spread": spread, "n_thermals": (3, 5)}, 4)[:, 1]
    assert across.max() <= spread + 1e-9
    if spread > 0:
        assert across.max() > 0.5 * spread  # the whole band is used


def test_default_lateral_spread_keeps_the_draws_bit_for_bit() -> None:
    a = draw_scenario_arrays(np.random.default_rng(9), 16)
    b = draw_scenario_arrays(np.random.default_rng(9), 16, lateral_spread=0.3)
    assert _bits(a.thermals) == _bits(b.thermals) and _bits(a.params) == _bits(b.params)
    assert make_scenario(np.random.default_rng(9)) == make_scenario(np.random.default_rng(9), lateral_spread=0.3)


@pytest.mark.parametrize("along", [(0.0, 0.0), (0.0, 0.1), (0.45, 0.55), (0.9, 1.0)])
def test_thermal_along_places_the_thermals_along_the_line(along: tuple[float, float]) -> None:
    """Thermals lie at ``thermal_along`` fractions of the goal distance along the start-goal line
    (projected on it), both draws; the whole range is used."""
    f = _line_fractions({"thermal_along": along, "n_thermals": (3, 5)}, 5)[:, 0]
    assert along[0] - 1e-9 <= f.min() and f.max() <= along[1] + 1e-9
    assert f.max() - f.min() >= 0.8 * (along[1] - along[0])


def test_default_thermal_along_keeps_the_draws_bit_for_bit() -> None:
    """The knob's default is the constants of both draws before it existed: same bits, both draws."""
    a = draw_scenario_arrays(np.random.default_rng(11), 16)
    b = draw_scenario_arrays(np.random.default_rng(11), 16, thermal_along=(0.2, 0.8))
    assert _bits(a.thermals) == _bits(b.thermals) and _bits(a.params) == _bits(b.params)
    # a hash of the batched draws taken before the knob existed (v2 as published)
    c = draw_scenario_arrays(np.random.default_rng(11), 64)
    blob = _bits(c.thermals) + _bits(c.params) + _bits(c.start)
    assert hashlib.sha256(blob).hexdigest() == "fc4296fba8545b2b78553db8e82af4aa0fdf1c42062be5e8834e32f02148de60"
    explicit = make_scenario(np.random.default_rng(11), thermal_along=(0.2, 0.8))
    assert make_scenario(np.random.default_rng(11)) == explicit


GEN_CASES = [
    (make_scenario, {"lifecycle": (600.0, 1200.0), "birth_window": (-200.0, 100.0)}),
    (make_scenario, {"strength_variation": (0.1, 0.3), "drift": True, "model": "gaussian", "n_thermals": (0, 8)}),
    (make_scenario, {"bounds": Bounds(-1000.0, 1000.0, -1500.0, 1500.0, 800.0), "goal_distance": (1500.0, 2000.0)}),
    (make_climb_scenario, {}),
    (make_cross_country_scenario, {}),
    (make_climb_scenario, {"lifecycle": (600.0, 1200.0), "birth_window": (-300.0, 300.0)}),
    (make_cross_country_scenario, {"strength_variation": (0.0, 0.5), "drift": True}),
    (
        make_climb_scenario,
        {
            "lifecycle": (400.0, 900.0),
            "strength_variation": (0.1, 0.4),
            "variation_period": (60.0, 200.0),
            "model": "gaussian",
            "drift": True,
            "wind_speed": (1.0, 5.0),
            "n_thermals": (0, 2),
        },
    ),
    (make_cross_country_scenario, {"lifecycle": (900.0, 1800.0), "rise_time": 200.0, "goal_distance": (3e3, 3e4)}),
]


@pytest.mark.parametrize(("generator", "kw"), GEN_CASES)
def test_generator_draws_are_the_generators_scenarios_bit_for_bit(generator, kw: dict) -> None:
    """A batched draw of a generator (goal reaching v1, climb, cross-country) makes exactly the
    generator's calls: the rows are those of the Scenario the Python generator gives from the same
    state (rejected tries included), and the generator ends in the same state."""
    n = 60
    sampler = GeneratorSampler(generator, kw)
    gens = [np.random.default_rng(s) for s in range(n)]
    twins = [np.random.default_rng(s) for s in range(n)]
    prm = np.zeros((n, scenario_params(make_scenario(np.random.default_rng(0))).size))
    th = np.zeros((n, sampler.max_thermals, PACKED_COLUMNS))
    nth = np.zeros(n, dtype=np.int64)
    start = np.zeros((n, 4))
    rows = np.arange(n, dtype=np.int64)[::-1].copy()  # any order: each row reads its own generator
    sampler.draw_each(rows, generator_list(gens), prm, th, nth, start)
    for i in range(n):
        sc = generator(twins[i], **kw)
        assert _bits(prm[i]) == _bits(scenario_params(sc))
        assert nth[i] == len(sc.field.thermals)
        assert _bits(th[i, : nth[i]]) == _bits(sc.field.packed)
        assert _bits(start[i]) == _bits(np.array(sc.start))
        assert gens[i].bit_generator.state == twins[i].bit_generator.state


def test_generator_sampler_input_is_checked() -> None:
    with pytest.raises(ConfigError, match="no batched draws"):
        GeneratorSampler(get_scenario, {})
    with pytest.raises(ConfigError, match="does not fit"):
        GeneratorSampler(make_scenario, {"bounds": Bounds(0.0, 500.0, 0.0, 500.0, 800.0)})
    with pytest.raises(ConfigError, match="unexpected keyword"):
        GeneratorSampler(make_climb_scenario, {"goal_distance": (1.0, 2.0)})
    for bad in ("abc", [("height", (1.0, 2.0))]):
        with pytest.raises(ConfigError, match="kwargs"):
            GeneratorSampler(make_climb_scenario, bad)
    with pytest.raises(ConfigError, match="keywords must be strings"):
        GeneratorSampler(make_climb_scenario, {1: 2})
    with pytest.raises(ConfigError, match="height"):
        GeneratorSampler(make_climb_scenario, {"height": "low"})
    with pytest.raises(ConfigError, match="corridor"):
        GeneratorSampler(make_cross_country_scenario, {"corridor": -1.0})
    sampler = GeneratorSampler(make_cross_country_scenario, {})
    assert sampler.max_thermals == 31  # round(2 per km x 15 km) + 1
    tables = (np.zeros((2, 15)), np.zeros((2, 31, PACKED_COLUMNS)), np.zeros(2, dtype=np.int64), np.zeros((2, 4)))
    gens = generator_list([np.random.default_rng(0), np.random.default_rng(1)])
    for bad in (np.array([2]), np.array([-1]), np.array([0.0]), [0]):
        with pytest.raises(ConfigError, match="rows"):
            sampler.draw_each(bad, gens, *tables)  # no write outside the tables
    small = np.zeros((1, 3, PACKED_COLUMNS))
    with pytest.raises(ConfigError, match="slots"):
        sampler.draw_each(np.zeros(1, dtype=np.int64), generator_list([np.random.default_rng(0)]), *(
            np.zeros((1, 15)), small, np.zeros(1, dtype=np.int64), np.zeros((1, 4))))  # fmt: skip


@pytest.mark.parametrize("env_id", ["soaring/ThermalClimbContinuous-v0", "soaring/CrossCountry-v0"])
def test_task_vector_env_draws_in_batches_and_builds_scenarios_on_demand(env_id: str) -> None:
    """The native task env draws its resets in one call and builds each Scenario only when asked:
    the same Scenario (and battery) as the single env of the same seed, episode after episode."""
    n = 4
    venv = gym.make_vec(env_id, num_envs=n)
    singles = [gym.make(env_id) for _ in range(n)]
    venv.reset(seed=30)
    for i, s in enumerate(singles):
        s.reset(seed=30 + i)
    assert venv._gen_sampler is not None and venv._lazy.all()
    rng = np.random.default_rng(3)
    done = np.zeros(n, dtype=bool)
    resets = 0
    for step in range(40):
        a = (
            rng.integers(0, 174, n)
            if isinstance(singles[0].action_space, gym.spaces.Discrete)
            else rng.uniform(-1, 1, (n, 3)).astype(np.float32)
        )
        venv.step(a)
        for i, s in enumerate(singles):
            if done[i]:
                s.reset()
                done[i] = False
                resets += 1
            else:
                _, _, t1, t2, _ = s.step(a[i])
                done[i] = t1 or t2
        if step % 5 == 0:
            for i, (sc, s) in enumerate(zip(venv.scenarios, singles, strict=True)):
                assert sc == s.unwrapped.scenario
                assert venv.battery[i] == s.unwrapped.battery
    assert resets > 0
