"""Property-based bad-input suite over the public constructors and entry points.

Every case either raises a :class:`ConfigError` whose message names the offending field, or is
valid and gives finite results. No case may hang: each example runs under hypothesis' deadline of
one second (the kernels are compiled, or loaded from the cache, before the first example).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import soaring_env.env.core as env_core
from baselines.sst.agent import SSTAgent
from baselines.sst.planner import plan_soaring
from soaring_env import Aircraft, ConfigError, PrimitiveLibrary, SoaringEnvConfig, Thermal, WindField, rollout
from soaring_env.model import SoaringModel
from soaring_env.primitives import MAX_HEIGHT
from soaring_env.scenario import Bounds, Scenario, make_scenario, paper_scenario

FAST = settings(max_examples=60, deadline=1000, suppress_health_check=[HealthCheck.too_slow])

# Warm the kernels up (compile or load from the on-disk cache) outside the deadline.
_FIELD = WindField(thermals=(Thermal(north=0.0, east=0.0, strength=2.56),))
rollout([0.0, 0.0, 0.0, 300.0], _FIELD, Aircraft(), primitive=107)
rollout([0.0, 0.0, 0.0, 300.0], _FIELD, Aircraft(), control=(15.0, 0.01, 0.1), duration=10.0)
plan_soaring(SoaringModel(), max_iterations=64, config={"batch_size": 64})

#: Anything a user might pass where a number belongs.
anything = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1e4, 1e4),
    st.integers(-(10**6), 10**6),
    st.text(max_size=4),
    st.sampled_from(["3", "1e3", "nan", "", "2.5"]),
    st.booleans(),
    st.none(),
    st.lists(st.floats(-10, 10), max_size=3),
    st.just(np.float32(2.0)),
    st.just(np.int64(3)),
)


def _names_field(exc: ConfigError, name: str) -> None:
    assert name in str(exc), f"error does not name {name!r}: {exc}"


def _all_floats(obj: Any, names: tuple[str, ...]) -> None:
    for n in names:
        v = getattr(obj, n)
        assert type(v) is float and math.isfinite(v), f"{n}={v!r} stored as {type(v).__name__}"


# --- physics constructors ---------------------------------------------------------------------------
THERMAL_FIELDS = ("north", "east", "strength", "radius")
WIND_FIELDS = ("zi", "wind_north", "wind_east")
AIRCRAFT_FIELDS = (
    "mass",
    "wing_area",
    "aspect_ratio",
    "oswald",
    "cd0",
    "cl0",
    "eta_ec",
    "eta_p",
    "stall_speed",
    "cl_max",
)


@FAST
@given(name=st.sampled_from(THERMAL_FIELDS), value=anything)
def test_thermal_fields(name: str, value: Any) -> None:
    kw: dict[str, Any] = {"north": 0.0, "east": 0.0, name: value}
    try:
        th = Thermal(**kw)
    except ConfigError as exc:
        _names_field(exc, f"thermal.{name}")
        return
    _all_floats(th, THERMAL_FIELDS)


@FAST
@given(name=st.sampled_from((*WIND_FIELDS, "drift", "model", "thermals")), value=anything)
def test_wind_field_fields(name: str, value: Any) -> None:
    try:
        f = WindField(**{name: value})
    except ConfigError as exc:
        _names_field(exc, name)
        return
    _all_floats(f, WIND_FIELDS)
    r = rollout([0.0, 0.0, 0.0, 300.0], f, Aircraft(), primitive=7)
    assert np.all(np.isfinite(r.states)) and np.isfinite(r.cost[0])


@FAST
@given(name=st.sampled_from((*AIRCRAFT_FIELDS, "thrust_model")), value=anything)
def test_aircraft_fields(name: str, value: Any) -> None:
    try:
        ac = Aircraft(**{name: value})
    except ConfigError as exc:
        _names_field(exc, name)
        return
    _all_floats(ac, tuple(n for n in AIRCRAFT_FIELDS if not (n == "cl_max" and ac.cl_max is None)))
    r = rollout([0.0, 0.0, 0.0, 300.0], _FIELD, ac, primitive=107)
    assert np.all(np.isfinite(r.states)) and np.isfinite(r.cost[0])


@FAST
@given(name=st.sampled_from(("duration", "n_points")), value=st.one_of(anything, st.integers(0, 10**9)))
def test_library_fields(name: str, value: Any) -> None:
    try:
        PrimitiveLibrary(**{name: value})
    except ConfigError as exc:
        _names_field(exc, name)


# --- rollout ----------------------------------------------------------------------------------------
heights = st.one_of(st.floats(-100.0, 12000.0), st.sampled_from([0.0, 10500.0, 10999.0, 11000.0, 44000.0, 44400.0]))
state_rows = st.tuples(st.floats(-5e3, 5e3), st.floats(-5e3, 5e3), st.floats(-10.0, 10.0), heights).map(list)
states_arg = st.one_of(
    state_rows,
    st.lists(state_rows, min_size=0, max_size=5),
    st.just([[1.0, 2.0, 3.0]]),
    st.just("0 0 0 300"),
    st.just([["a", 0.0, 0.0, 300.0]]),
    st.just([[0.0, 0.0, 0.0, math.nan]]),
)
per_row = st.one_of(
    st.floats(0.0, 1e4),
    st.floats(allow_nan=True, allow_infinity=True),
    st.lists(st.floats(1.0, 30.0), min_size=0, max_size=6),
    st.just([[1.0]]),
    st.just("1"),
    st.none(),
)


@FAST
@given(
    states=states_arg,
    t0=per_row,
    vp=per_row,
    duration=st.one_of(st.none(), st.floats(-1.0, 4000.0), st.sampled_from([1e-300, 1e-3, 0.01, 3600.0, math.inf])),
    max_substep=st.one_of(st.floats(-1.0, 10.0), st.sampled_from([1e-12, 1e-3, 0.5, "0.5", math.nan])),
    primitive=st.one_of(st.integers(-2, 180), st.lists(st.integers(0, 173), max_size=4), st.just(1.5), st.just("1")),
    use_control=st.booleans(),
)
def test_rollout_arguments(
    states: Any, t0: Any, vp: Any, duration: Any, max_substep: Any, primitive: Any, use_control: bool
) -> None:
    kw: dict[str, Any] = {"t0": 0.0 if t0 is None else t0, "airspeed_prev": vp, "max_substep": max_substep}
    if use_control:
        kw.update(control=(15.0, 0.02, 0.3), duration=duration)
    else:
        kw.update(primitive=primitive)
    names = ("states", "t0", "airspeed_prev", "duration", "max_substep", "primitive", "control")
    try:
        r = rollout(states, _FIELD, Aircraft(), **kw)
    except ConfigError as exc:
        assert any(n in str(exc) for n in names) or "do not broadcast" in str(exc), str(exc)
        return
    assert len(r) >= 1
    for a in (r.states, r.fuel, r.potential, r.kinetic, r.cost, r.max_bank, r.min_height):
        assert np.all(np.isfinite(a))
    assert np.all(r.states[..., 3] < MAX_HEIGHT)


@pytest.mark.parametrize("h", [10950.0, 44000.0, 44400.0])
def test_no_physics_above_the_troposphere(h: float) -> None:
    with pytest.raises(ConfigError, match="states height"):
        rollout([0.0, 0.0, 0.0, h], WindField(), Aircraft(), primitive=4)  # 20 m/s, +45 deg
    if h >= MAX_HEIGHT:
        with pytest.raises(ConfigError, match=r"bounds\.height_max"):
            Bounds(height_max=h)


def test_ceiling_leaves_room_for_one_edge() -> None:
    sc = paper_scenario().replace(bounds=Bounds(height_max=10800.0))
    with pytest.raises(ConfigError, match=r"bounds\.height_max=10800.*could climb"):
        SoaringModel(scenario=sc)
    with pytest.raises(ConfigError, match=r"bounds\.height_max"):
        gym.make("soaring/Soaring-v0", scenario=sc)


# --- scenarios --------------------------------------------------------------------------------------
def _mutations() -> st.SearchStrategy[tuple[str, Any]]:
    paths = [
        "name",
        "start",
        "goal",
        "bounds",
        "field",
        "goal.north",
        "goal.height",
        "goal.radius",
        "bounds.height_max",
        "bounds.north_min",
        "field.zi",
        "field.model",
        "field.drift",
        "field.wind_north",
        "field.thermals",
        "extra",
        "goal.extra",
        "field.extra",
    ]
    return st.tuples(st.sampled_from(paths), st.one_of(anything, st.just({}), st.just("delete")))


@FAST
@given(mutation=_mutations())
def test_scenario_from_dict(mutation: tuple[str, Any]) -> None:
    d = paper_scenario().to_dict()
    path, value = mutation
    *parents, key = path.split(".")
    target = d
    for p in parents:
        target = target[p]
    if value == "delete":
        target.pop(key, None)
    else:
        target[key] = value
    try:
        sc = Scenario.from_dict(d, source="case.json")
    except ConfigError as exc:
        assert "case.json" in str(exc), str(exc)
        # the key itself, its parent object, or (for consistency between fields) the domain
        assert key in str(exc) or (parents and parents[-1] in str(exc)) or "domain" in str(exc), str(exc)
        return
    assert Scenario.from_dict(sc.to_dict()) == sc
    _all_floats(sc.bounds, ("north_min", "north_max", "east_min", "east_max", "height_max"))


@FAST
@given(name=st.sampled_from(("field", "start", "goal", "bounds", "name")), value=anything)
def test_scenario_types(name: str, value: Any) -> None:
    try:
        Scenario(**{name: value})
    except ConfigError as exc:
        _names_field(exc, name if name != "start" else "start")


pairs = st.one_of(
    st.tuples(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True, allow_infinity=True)),
    st.tuples(st.floats(0.0, 5000.0), st.floats(0.0, 5000.0)),
    st.tuples(st.integers(-3, 300), st.integers(-3, 300)),
    st.just((1.0,)),
    st.just("1,2"),
    st.just((1, 2, 3)),
    st.just(("1", "2")),
    st.just(5),
)
RANDOM_FIELDS = ("n_thermals", "strength", "wind_speed", "goal_distance", "height")


@FAST
@given(name=st.sampled_from(RANDOM_FIELDS), value=pairs, seed=st.integers(0, 2**32 - 1))
def test_random_scenario_ranges(name: str, value: Any, seed: int) -> None:
    try:
        sc = make_scenario(np.random.default_rng(seed), **{name: value})
    except ConfigError as exc:
        assert name in str(exc) or "could not draw" in str(exc), str(exc)
        return
    assert len(sc.field.thermals) <= 100
    SoaringModel(scenario=sc)


@FAST
@given(name=st.sampled_from(("model", "zi", "drift", "bounds", "name")), value=anything)
def test_random_scenario_scalars(name: str, value: Any) -> None:
    try:
        make_scenario(np.random.default_rng(0), **{name: value})
    except ConfigError as exc:
        _names_field(exc, name)


# --- env ---------------------------------------------------------------------------------------------
ENV_FIELDS = tuple(
    f.name for f in dataclasses.fields(SoaringEnvConfig) if f.name not in ("scenario", "random_scenario", "aircraft")
)


@FAST
@given(name=st.sampled_from(ENV_FIELDS), value=st.one_of(anything, st.integers(0, 10**7)))
def test_env_config_fields(name: str, value: Any) -> None:
    try:
        SoaringEnvConfig(**{name: value})
    except ConfigError as exc:
        _names_field(exc, name)


def test_path_history_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(env_core, "MAX_PATH_EDGES", 5)
    big = Bounds(north_min=-1e6, north_max=1e6, east_min=-1e6, east_max=1e6, height_max=1500.0)
    env = env_core.SoaringEnv(scenario=paper_scenario().replace(bounds=big), max_steps=None)  # endless episodes
    env.reset(seed=0)
    for _ in range(50):
        _, _, terminated, _, _ = env.step(97)  # 10 m/s level circle: flies forever
        assert not terminated
    assert len(env._path) == 6 and all(len(v) == 6 for v in env.history.values())
    assert env.path.shape[1] == 4 and np.all(np.isfinite(env.path))


# --- planner -----------------------------------------------------------------------------------------
@settings(max_examples=30, deadline=1000, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.one_of(st.integers(-5, 2**64), st.none(), st.just(1.5), st.just("1")),
    config=st.one_of(
        st.none(),
        st.just({"batch_size": 64}),
        st.just({"batch_size": 0}),
        st.just({"batch": 64}),
        st.just({"selection_radius": "500"}),
        st.just({"mask_primitives": "yes"}),
        st.just([64]),
    ),
    t0=st.one_of(st.just(0.0), st.floats(allow_nan=True, allow_infinity=True), st.just("0")),
    vp=st.one_of(st.none(), st.floats(-5.0, 30.0), st.just("15")),
    budget=st.one_of(st.just((None, 64)), st.just((None, None)), st.just((-1.0, None)), st.just((None, 0))),
)
def test_plan_soaring_arguments(seed: Any, config: Any, t0: Any, vp: Any, budget: tuple[Any, Any]) -> None:
    names = ("seed", "config", "batch_size", "batch", "selection_radius", "mask_primitives", "t0", "airspeed_prev")
    names += ("time_limit", "max_iterations")
    try:
        res = plan_soaring(
            SoaringModel(), seed=seed, config=config, t0=t0, airspeed_prev=vp, time_limit=budget[0],
            max_iterations=budget[1],
        )  # fmt: skip
    except ConfigError as exc:
        assert any(n in str(exc) for n in names), str(exc)
        return
    assert math.isfinite(res.plan.cost)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"seed": -1}, "seed=-1"),
        ({"seed": "0"}, "seed='0'"),
        ({"config": {"radius": 1}}, "radius"),
        ({"time_limit": 0}, "time_limit"),
    ],
)  # fmt: skip
def test_sst_agent_arguments(kw: dict[str, Any], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        SSTAgent(gym.make("soaring/Soaring-v0"), **kw)


# --- random-action fuzz --------------------------------------------------------------------------------
@pytest.mark.slow
def test_random_action_fuzz_million_steps() -> None:
    """10^6 random-action steps (batched env, random scenarios, both action kinds): no NaN, every
    observation inside its space, energy bookkeeping consistent."""
    total = 0
    for env_id, until in (("soaring/Soaring-v0", 500_000), ("soaring/SoaringContinuous-v0", 1_000_000)):
        envs = gym.make_vec(env_id, 512, vectorization_mode="vector_entry_point", scenario="random")
        envs.action_space.seed(0)
        obs, _ = envs.reset(seed=0)
        space = envs.single_observation_space
        while total < until:
            obs, reward, _, _, info = envs.step(envs.action_space.sample())
            assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
            assert np.all(obs >= space.low) and np.all(obs <= space.high)
            assert np.all(np.isfinite(info["energy_spent"]))
            total += envs.num_envs
        envs.close()
    assert total >= 1_000_000


# --- agents and adapters of the agents issue -------------------------------------------------------
@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"radius": "x"}, "radius"),
        ({"radius": float("nan")}, "radius"),
        ({"radius": -5.0}, "radius"),
        ({"enter_lift": float("inf")}, "enter_lift"),
        ({"exit_lift": 2.0}, "exit_lift"),  # above enter_lift
        ({"exit_window": 0.0}, "exit_window"),
        ({"search_spacing": 0.0}, "search_spacing"),
        ({"tabu_time": True}, "tabu_time"),
        ({"ceiling": 1.5}, "ceiling"),
    ],
)  # fmt: skip
def test_thermalling_agent_arguments(kw: dict[str, Any], match: str) -> None:
    from baselines.agents import HeuristicAgent, ThermallingAgent

    with pytest.raises(ConfigError, match=match):
        ThermallingAgent(**kw)
    with pytest.raises(ConfigError, match="lift_threshold"):
        HeuristicAgent(lift_threshold="0.8")  # type: ignore[arg-type]
    HeuristicAgent(lift_threshold=math.inf)  # the direct flyer


def test_sb3_adapter_and_init_from_arguments(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from baselines.ppo import TrainConfig
    from soaring_env.env.sb3 import SoaringSB3VecEnv

    for bad in (3, None.__class__, "soaring/Nope-v0"):
        with pytest.raises(ConfigError, match="env_id"):
            SoaringSB3VecEnv(2, env_id=bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="init_from"):
        TrainConfig(init_from=5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="init_from"):
        TrainConfig(init_from=str(tmp_path))


@pytest.mark.parametrize("value", ["0", "-1", "100000"])
def test_bench_env_rejects_bad_thread_counts_before_measuring(value: str, capsys: pytest.CaptureFixture) -> None:
    from baselines.cli.bench_env import main

    with pytest.raises(SystemExit) as err:
        main(["--threads", value])
    assert err.value.code == 2 and "--threads" in capsys.readouterr().err
