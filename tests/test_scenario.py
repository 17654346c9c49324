"""Scenarios: the paper scenario, JSON round trips, random scenarios (determinism and validity) and
validation of every scenario parameter."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from soaring_env import ConfigError, Thermal, WindField
from soaring_env.scenario import Bounds, GoalRegion, Scenario, get_scenario, make_scenario, paper_scenario


def test_paper_scenario_geometry() -> None:
    sc = paper_scenario()
    assert sc.name == "paper"
    assert sc == get_scenario("paper")
    assert sc.start == (0.0, 0.0, 0.0, 300.0)
    np.testing.assert_array_equal(sc.start_state, [0.0, 0.0, 0.0, 300.0])
    assert sc.start_state.dtype == np.float64
    (th,) = sc.field.thermals
    assert sc.field.model == "allen" and sc.field.zi == 1400.0 and th.strength == 2.56
    # one thermal between the start and the goal
    assert 0.0 < th.north < sc.goal.north
    assert bool(sc.bounds.contains(th.north, th.east, 300.0))
    assert not bool(sc.goal.contains(*sc.start_state[[0, 1, 3]]))


def test_paper_json_round_trip(tmp_path: Path) -> None:
    sc = paper_scenario()
    text = sc.to_json()
    assert json.loads(text)["name"] == "paper"
    back = Scenario.from_json(text)
    assert back == sc
    assert back.to_json() == text
    path = tmp_path / "sub" / "paper.json"
    sc.save(path)
    assert Scenario.load(path) == sc
    assert path.read_text() == text
    assert [p.name for p in path.parent.iterdir()] == ["paper.json"]  # no temporary file left behind


def test_round_trip_preserves_every_field(tmp_path: Path) -> None:
    sc = Scenario(
        field=WindField(
            thermals=(Thermal(100.125, -3.3, 1.7, 55.5), Thermal(1e-7, 2500.0, 4.0, 300.0)),
            model="gaussian",
            zi=987.654321,
            wind_north=-2.5,
            wind_east=0.1 + 0.2,
            drift=True,
        ),
        start=(10.0, -20.0, -3.0, 123.456),
        goal=GoalRegion(north=2000.0, east=-1000.0, height=456.0, radius=75.0),
        bounds=Bounds(-500.0, 2500.0, -1500.0, 500.0, 2000.0),
        name="custom-øæ",
    )
    back = Scenario.from_json(sc.to_json())
    assert back == sc
    assert back.field.wind_east == 0.1 + 0.2  # floats survive bit for bit
    assert back.field.drift is True and back.field.model == "gaussian"
    sc.save(tmp_path / "s.json")
    assert Scenario.load(tmp_path / "s.json") == sc
    # a changed field breaks equality: the comparison is not vacuous
    assert Scenario.from_json(sc.to_json().replace("987.654321", "987.0")) != sc


def test_make_scenario_deterministic() -> None:
    a = make_scenario(np.random.default_rng(7))
    b = make_scenario(np.random.default_rng(7))
    assert a == b
    assert a.to_json() == b.to_json()
    many = [make_scenario(np.random.default_rng(seed)).to_json() for seed in range(20)]
    assert len(set(many)) == 20
    # the draw depends only on the generator state: continuing one generator gives new scenarios
    g = np.random.default_rng(7)
    first, second = make_scenario(g), make_scenario(g)
    assert first == a and second != a


def _check_valid(sc: Scenario, *, n_thermals: tuple[int, int] = (1, 5)) -> None:
    b = sc.bounds
    n, e, chi, h = sc.start
    assert all(math.isfinite(v) for v in sc.start)
    assert -math.pi <= chi < math.pi
    assert 200.0 <= h <= 600.0 and 200.0 <= sc.goal.height <= 600.0
    margin = 300.0
    for pn, pe in ((n, e), (sc.goal.north, sc.goal.east)):
        assert b.north_min + margin <= pn <= b.north_max - margin
        assert b.east_min + margin <= pe <= b.east_max - margin
    dist = math.hypot(sc.goal.north - n, sc.goal.east - e)
    assert 1500.0 <= dist <= 3500.0
    assert not bool(sc.goal.contains(n, e, h))
    assert n_thermals[0] <= len(sc.field.thermals) <= n_thermals[1]
    wind = math.hypot(sc.field.wind_north, sc.field.wind_east)
    assert 0.0 <= wind <= 4.0 + 1e-12
    seg = np.array([sc.goal.north - n, sc.goal.east - e])
    for th in sc.field.thermals:
        assert 1.5 <= th.strength <= 3.5
        rel = np.array([th.north - n, th.east - e])
        along = float(rel @ seg) / dist**2
        across = abs(float(rel[0] * seg[1] - rel[1] * seg[0])) / dist
        assert 0.2 - 1e-9 <= along <= 0.8 + 1e-9  # in the band between start and goal
        assert across <= 0.3 * dist + 1e-6
    # constructing it again from its parts validates everything once more
    assert Scenario.from_dict(sc.to_dict()) == sc


@pytest.mark.parametrize("seed", range(40))
def test_random_scenarios_valid(seed: int) -> None:
    _check_valid(make_scenario(np.random.default_rng(seed)))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_lo=st.integers(0, 3),
    extra=st.integers(0, 3),
    model=st.sampled_from(["allen", "gaussian"]),
    drift=st.booleans(),
)
def test_random_scenarios_valid_property(seed: int, n_lo: int, extra: int, model: str, drift: bool) -> None:
    sc = make_scenario(
        np.random.default_rng(seed), n_thermals=(n_lo, n_lo + extra), model=model, zi=1200.0, drift=drift
    )
    _check_valid(sc, n_thermals=(n_lo, n_lo + extra))
    assert sc.field.model == model and sc.field.drift is drift and sc.field.zi == 1200.0
    assert Scenario.from_json(sc.to_json()) == sc


def test_make_scenario_rejects_bad_ranges() -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(ConfigError, match="n_thermals"):
        make_scenario(rng, n_thermals=(3, 1))
    with pytest.raises(ConfigError, match="strength"):
        make_scenario(rng, strength=(3.0, 1.0))
    with pytest.raises(ConfigError, match="wind_speed"):
        make_scenario(rng, wind_speed=(0.0, math.inf))
    with pytest.raises(ConfigError, match="goal_distance"):
        make_scenario(rng, goal_distance=(1000.0, 50000.0))
    with pytest.raises(ConfigError, match="model='dryden'"):
        make_scenario(rng, model="dryden")


# ----------------------------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"start": (-5000.0, 0.0, 0.0, 300.0)}, r"start position \(north=-5000"),
        ({"start": (0.0, 9000.0, 0.0, 300.0)}, r"start position \(north=0, east=9000"),
        ({"start": (0.0, 0.0, 0.0, 0.0)}, r"start position .*height=0\)"),
        ({"start": (0.0, 0.0, 0.0, -20.0)}, r"start position .*height=-20\)"),
        ({"start": (0.0, 0.0, 0.0, 1600.0)}, r"start position .*height=1600\)"),
        ({"start": (0.0, 0.0, math.nan, 300.0)}, r"start\[2\]=nan"),
        ({"start": (0.0, math.inf, 0.0, 300.0)}, r"start\[1\]=inf"),
        ({"start": (0.0, 0.0, 300.0)}, r"start=\(0\.0, 0\.0, 300\.0\)"),
        ({"start": (3000.0, 0.0, 0.0, 300.0)}, r"start lies inside the goal"),
        ({"goal": GoalRegion(north=9000.0)}, r"goal centre \(north=9000"),
        ({"goal": GoalRegion(height=2000.0)}, r"goal centre .*height=2000\)"),
    ],
)
def test_scenario_validation(kwargs: dict[str, object], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        Scenario(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"height": 0.0}, r"goal\.height=0\.0"),
        ({"height": -10.0}, r"goal\.height=-10\.0"),
        ({"height": math.nan}, r"goal\.height=nan"),
        ({"north": math.inf}, r"goal\.north=inf"),
        ({"east": math.nan}, r"goal\.east=nan"),
        ({"radius": 0.0}, r"goal\.radius=0\.0"),
        ({"radius": -1.0}, r"goal\.radius=-1\.0"),
    ],
)
def test_goal_validation(kwargs: dict[str, float], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        GoalRegion(**kwargs)


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        ((math.nan, 1.0, 0.0, 1.0, 10.0), r"bounds\.north_min=nan"),
        ((0.0, math.inf, 0.0, 1.0, 10.0), r"bounds\.north_max=inf"),
        ((0.0, 1.0, 0.0, 1.0, 0.0), r"bounds\.height_max=0\.0"),
        ((0.0, 1.0, 0.0, 1.0, -5.0), r"bounds\.height_max=-5\.0"),
        ((1.0, 1.0, 0.0, 1.0, 10.0), r"bounds\.north_max=1\.0"),
        ((0.0, 1.0, 2.0, -1.0, 10.0), r"bounds\.east_max=-1\.0"),
    ],
)
def test_bounds_validation(args: tuple[float, ...], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        Bounds(*args)


def test_bounds_and_goal_geometry() -> None:
    b = Bounds(-100.0, 100.0, -50.0, 50.0, 500.0)
    inside = b.contains([0.0, -100.0, 100.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 50.0, 0.0, 0.0], [1.0] * 4 + [0.0, 501.0])
    assert inside.tolist() == [True, True, True, True, False, False]
    np.testing.assert_array_equal(b.low, [-100.0, -50.0, 0.0])
    np.testing.assert_array_equal(b.high, [100.0, 50.0, 500.0])
    g = GoalRegion(north=10.0, east=20.0, height=30.0, radius=5.0)
    assert float(g.distance(13.0, 24.0, 30.0)) == pytest.approx(5.0)
    assert bool(g.contains(13.0, 24.0, 30.0)) and not bool(g.contains(13.0, 24.1, 30.0))


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.pop("goal"), r"lacks the key\(s\) \['goal'\]"),
        (lambda d: d["field"].update(thermals=[{"north": 0.0}]), r"field\.thermals\[0\] lacks the key\(s\) \['east'\]"),
        (lambda d: d["field"].update(colour="blue"), r"field has unknown key\(s\) \['colour'\]"),
        (lambda d: d["bounds"].update(north_minimum=0.0), r"bounds has unknown key\(s\) \['north_minimum'\]"),
        (lambda d: d.update(extra=1), r"unknown key\(s\) \['extra'\]"),
        (lambda d: d.update(goal=[1, 2]), r"goal must be an object"),
        (lambda d: d["field"].update(wind_north="3"), r"wind_north='3' has type str"),
        (lambda d: d.update(start="0,0,0,300"), r"start='0,0,0,300' must be a list"),
        (lambda d: d.update(name=7), r"name=7 has type int"),
    ],
)
def test_from_dict_malformed(mutate: object, match: str) -> None:
    d = paper_scenario().to_dict()
    mutate(d)  # type: ignore[operator]
    with pytest.raises(ConfigError, match=match):
        Scenario.from_dict(d)


def test_load_names_the_file(tmp_path: Path) -> None:
    p = tmp_path / "broken.json"
    p.write_text('{"name": "x", ')
    with pytest.raises(ConfigError, match=r"broken\.json.*not valid JSON"):
        Scenario.load(p)
    d = paper_scenario().to_dict()
    del d["bounds"]["height_max"]
    d["bounds"]["ceiling"] = 1.0
    p.write_text(json.dumps(d))
    with pytest.raises(ConfigError, match=r"broken\.json.*bounds has unknown key\(s\) \['ceiling'\]"):
        Scenario.load(p)
    with pytest.raises(ConfigError, match=r"cannot read scenario file.*missing\.json"):
        Scenario.load(tmp_path / "missing.json")


def test_from_json_invalid_values_name_the_field() -> None:
    d = paper_scenario().to_dict()
    d["field"]["thermals"][0]["radius"] = -3.0
    with pytest.raises(ConfigError, match=r"thermal\.radius=-3\.0"):
        Scenario.from_dict(d)
    d = paper_scenario().to_dict()
    d["field"]["model"] = "dryden"
    with pytest.raises(ConfigError, match="model='dryden'"):
        Scenario.from_json(json.dumps(d))


def test_get_scenario_unknown() -> None:
    with pytest.raises(ConfigError, match=r"'nope'.*paper"):
        get_scenario("nope")


def test_replace_revalidates() -> None:
    sc = paper_scenario()
    moved = sc.replace(start=(100.0, 0.0, 0.0, 300.0))
    assert moved.start == (100.0, 0.0, 0.0, 300.0) and moved.goal == sc.goal
    with pytest.raises(ConfigError, match="start position"):
        sc.replace(start=(0.0, 0.0, 0.0, -1.0))


# --- one namespace of scenario names ----------------------------------------------------------------
def test_scenario_names_resolve_everywhere_alike(tmp_path: Path) -> None:
    """A name, ``random-<seed>`` and a JSON path give the same scenario in get_scenario, gym.make,
    env.reset(options=...), the vector env and the evaluation (which re-exports get_scenario)."""
    import gymnasium as gym

    import soaring_env
    from baselines import evaluation

    path = tmp_path / "mine.json"
    mine = make_scenario(np.random.default_rng(3), name="mine")
    mine.save(path)
    expected = {
        "paper": paper_scenario(),
        "random-10000": make_scenario(np.random.default_rng(10_000), name="random-10000"),
        str(path): mine,
    }
    assert soaring_env.get_scenario is get_scenario and evaluation.resolve_scenario is get_scenario
    assert get_scenario(path) == mine  # a PathLike too
    env = gym.make("soaring/Soaring-v0")
    venv = gym.make_vec("soaring/Soaring-v0", num_envs=2, vectorization_mode="vector_entry_point")
    for name, sc in expected.items():
        assert get_scenario(name) == sc
        assert evaluation.check_scenario_name(name) == name
        assert gym.make("soaring/Soaring-v0", scenario=name).unwrapped.scenario == sc
        env.reset(seed=0, options={"scenario": name})
        assert env.unwrapped.scenario == sc
        venv.reset(seed=0, options={"scenario": name})
        assert all(s == sc for s in venv.unwrapped.scenarios)
    env.close()
    venv.close()
    # a pathlib.Path in gym.make is stored as a string (configs are saved as JSON)
    assert gym.make("soaring/Soaring-v0", scenario=path).unwrapped.config.scenario == str(path)


def test_random_seed_names_follow_the_random_scenario_keywords() -> None:
    import gymnasium as gym

    kw = {"n_thermals": (4, 4), "wind_speed": (0.0, 0.0)}
    sc = get_scenario("random-10001", kw)
    assert len(sc.field.thermals) == 4 and sc.name == "random-10001"
    assert sc == get_scenario("random-10001", {**kw, "name": "ignored"})  # the name is the seed's
    env = gym.make("soaring/Soaring-v0", scenario="random-10001", random_scenario=kw)
    assert env.unwrapped.scenario == sc
    env.reset(seed=0, options={"scenario": "random-10002"})
    assert len(env.unwrapped.scenario.field.thermals) == 4
    assert get_scenario("random-10001") != sc  # without the keywords: the default distribution


def test_heldout_names_live_with_the_scenarios() -> None:
    from baselines import evaluation
    from soaring_env.scenario import HELDOUT_SEED0, heldout_names

    assert heldout_names(2) == ["random-10000", "random-10001"] and HELDOUT_SEED0 == 10_000
    assert evaluation.heldout_names is heldout_names and evaluation.HELDOUT_SEED0 == HELDOUT_SEED0


@pytest.mark.parametrize(
    ("name", "match"),
    [
        ("nope", r"scenario 'nope' is unknown; known: paper, random-<seed> .*\*\.json.*'random'"),
        ("random-", "unknown"),
        ("random-x1", "unknown"),
        ("random", r"names no single scenario.*random-<seed>"),
        ("missing.json", r"cannot read scenario file 'missing\.json'"),
        (42, "has type int"),
    ],
)
def test_unknown_scenario_names_list_the_forms(name: object, match: str) -> None:
    import gymnasium as gym

    with pytest.raises(ConfigError, match=match):
        get_scenario(name)  # type: ignore[arg-type]
    if name != "random":  # (the envs' mode)
        with pytest.raises(ConfigError):
            gym.make("soaring/Soaring-v0", scenario=name)
        with pytest.raises(ConfigError):
            gym.make("soaring/Soaring-v0").reset(options={"scenario": name})
