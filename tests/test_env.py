"""The single Gymnasium envs: API conformance, exact agreement with the model API, bad input."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import matplotlib
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import soaring_env
from soaring_env import ConfigError, SoaringEnvConfig
from soaring_env.env import CONTINUOUS_ENV_ID, ENV_ID, MAX_EPISODE_STEPS, register_envs
from soaring_env.env._kernels import classify_batch
from soaring_env.env.observation import scenario_params
from soaring_env.model import CRASH, FLYING, OUT_OF_BOUNDS, SoaringModel
from soaring_env.physics import Thermal, WindField
from soaring_env.primitives import N_PRIMITIVES
from soaring_env.scenario import Bounds, GoalRegion, Scenario, make_scenario, paper_scenario

matplotlib.use("Agg")

IDS = (ENV_ID, CONTINUOUS_ENV_ID)
STEP_KEYS = {
    "energy_spent",
    "edge_cost",
    "fuel",
    "potential",
    "kinetic",
    "height",
    "airspeed",
    "bank_angle",
    "updraft",
    "time",
    "outcome",
    "is_success",
    "reward_terms",
}
TERM_KEYS = {"energy", "progress", "goal", "crash", "out_of_bounds"}
# primitive indices (see PrimitiveLibrary): 20 m/s straight, gamma -45 / -15 / 0 / +15 deg
DIVE, GLIDE, LEVEL, CLIMB = 5, 6, 7, 8


def _sample(env: gym.Env, rng: np.random.Generator):
    if isinstance(env.action_space, gym.spaces.Discrete):
        return int(rng.integers(0, N_PRIMITIVES))
    return rng.uniform(-1.0, 1.0, size=3).astype(np.float32)


# --- registration and conformance -----------------------------------------------------------------
def test_registration_is_idempotent_and_complete() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_envs()
        register_envs()
    for env_id in IDS:
        spec = gym.spec(env_id)
        assert spec.max_episode_steps is None  # the env owns its step limit (max_steps)
        assert spec.vector_entry_point is not None
    assert isinstance(gym.make(ENV_ID).action_space, gym.spaces.Discrete)
    assert gym.make(ENV_ID).action_space.n == 174
    box = gym.make(CONTINUOUS_ENV_ID).action_space
    assert box.shape == (3,) and box.dtype == np.float32 and np.all(box.low == -1) and np.all(box.high == 1)
    assert gym.make("soaring_env:soaring/Soaring-v0").spec.id == ENV_ID


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_check_env_without_warnings(env_id: str) -> None:
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(env_id).unwrapped)
    assert [str(w.message) for w in caught] == []


@pytest.mark.parametrize("env_id", IDS)
def test_sb3_check_env_without_warnings(env_id: str) -> None:
    from stable_baselines3.common.env_checker import check_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(env_id).unwrapped)
        check_env(gym.make(env_id, scenario="random", observe_thermals=False))
    assert [str(w.message) for w in caught] == []


@pytest.mark.parametrize("env_id", IDS)
def test_spaces_and_info_contract(env_id: str) -> None:
    env = gym.make(env_id)
    space = env.observation_space
    assert space.dtype == np.float32 and np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and space.contains(obs)
    assert info["energy_spent"] == 0.0 and info["is_success"] is False
    u = env.unwrapped
    assert isinstance(u.model, SoaringModel) and u.scenario.name == "paper"
    assert u.field is u.scenario.field and len(u.field.thermals) == 1
    assert u.state.dtype == np.float64 and u.state.shape == (4,) and u.time == 0.0
    assert math.isnan(u.airspeed_prev)
    assert len(u.observation_names) == space.shape[0] == 11 + 5 * 3
    action = LEVEL if env_id == ENV_ID else np.array([1.0, 0.0, 0.0], dtype=np.float32)
    obs, reward, terminated, truncated, info = env.step(action)
    assert set(info) == STEP_KEYS and set(info["reward_terms"]) == TERM_KEYS
    assert type(reward) is float and terminated is False and truncated is False
    for key in STEP_KEYS - {"outcome", "is_success", "reward_terms"}:
        assert type(info[key]) is float, key
    assert all(type(v) is float for v in info["reward_terms"].values())
    assert info["outcome"] == "flying" and info["is_success"] is False
    assert info["airspeed"] == 20.0 and info["time"] == 30.0 == u.time
    assert u.airspeed_prev == 20.0
    assert info["edge_cost"] == info["fuel"] + info["potential"] + info["kinetic"]
    # level flight at 20 m/s with no lift: only fuel, no height change
    assert info["fuel"] > 0 and info["potential"] == 0.0 and info["kinetic"] == 0.0
    assert u.decode_observation(obs)["goal_north"] == pytest.approx((3000.0 - 600.0) / 1000.0, rel=1e-6)


def test_observation_values_in_the_paper_scenario() -> None:
    env = gym.make(ENV_ID)
    obs, _ = env.reset(seed=0)
    d = env.unwrapped.decode_observation(obs)
    assert d["goal_north"] == 3.0 and d["goal_east"] == 0.0 and d["goal_up"] == 0.0
    assert d["sin_course"] == 0.0 and d["cos_course"] == 1.0 and d["height"] == pytest.approx(0.3)
    assert d["airspeed"] == 0.0 and d["edge_lift"] == 0.0
    assert d["thermal_0_present"] == 1.0 and d["thermal_1_present"] == 0.0
    assert d["thermal_0_north"] == pytest.approx(1.5) and d["thermal_0_east"] == pytest.approx(0.25)
    prof = env.unwrapped.field.allen_profile(300.0, 2.56)
    assert d["thermal_0_peak"] == pytest.approx(prof["w_peak"] / 5.0, rel=1e-6)
    assert d["thermal_0_radius"] == pytest.approx(prof["r2"] / 1000.0, rel=1e-6)
    hidden = gym.make(ENV_ID, observe_thermals=False)
    assert hidden.observation_space.shape == (11,)
    assert np.array_equal(hidden.reset(seed=0)[0], obs[:11])


# --- exact agreement with the model API ------------------------------------------------------------
def _replay_primitives(model: SoaringModel, actions: list[int]) -> tuple[list[np.ndarray], list[float]]:
    state = np.array(model.scenario.start)
    t, v_prev = 0.0, None
    states, costs = [], []
    for a in actions:
        r = model.rollout_primitive(state, a, t0=t, airspeed_prev=v_prev)
        code, k = model.classify(r)
        state = r.states[0, k[0]]
        states.append(state)
        costs.append(float(r.cost[0]))
        t += model.library.duration
        v_prev = model.library.table[a, 1]
        if code[0] != FLYING:
            break
    return states, costs


def test_replaying_primitives_reproduces_the_model_exactly() -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    model = env.unwrapped.model
    # toward the thermal, circle in it, glide to the goal (the path of the README picture)
    plan = [57, 163, 2, *([77] * 15), 50, 6, 7]
    want_states, want_costs = _replay_primitives(model, plan)
    got_costs = []
    for a in plan[: len(want_states)]:
        _, _, terminated, _, info = env.step(a)
        got_costs.append(info["edge_cost"])
        assert np.array_equal(env.unwrapped.state, want_states[len(got_costs) - 1])
    assert got_costs == want_costs
    assert terminated and info["outcome"] == "goal" and info["is_success"] is True
    assert info["energy_spent"] == sum(want_costs)  # the same left-to-right float sum


def test_replaying_controls_reproduces_the_model_exactly() -> None:
    env = gym.make(CONTINUOUS_ENV_ID)
    env.reset(seed=0)
    model = env.unwrapped.model
    rng = np.random.default_rng(3)
    state, t, v_prev = np.array(model.scenario.start), 0.0, None
    for _ in range(6):
        a = rng.uniform(-1, 1, 3).astype(np.float32)
        a[2] = abs(a[2]) * 0.3  # keep climbing gently: stay airborne
        r = model.rollout_control(state, model.action_to_control(a), t0=t, airspeed_prev=v_prev)
        code, k = model.classify(r)
        state, t, v_prev = r.states[0, k[0]], t + 30.0, model.action_to_control(a)[0]
        _, _, terminated, _, info = env.step(a)
        assert np.array_equal(env.unwrapped.state, state)
        assert info["edge_cost"] == r.cost[0] and info["bank_angle"] == r.max_bank[0]
        assert terminated == (code[0] != FLYING)
        if terminated:
            break


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1))
def test_classify_kernel_equals_model_classify(seed: int) -> None:
    rng = np.random.default_rng(seed)
    sc = make_scenario(rng)
    model = SoaringModel(scenario=sc)
    b = 64
    states = np.empty((b, 4))
    states[:, 0] = rng.uniform(sc.bounds.north_min - 300, sc.bounds.north_max + 300, b)
    states[:, 1] = rng.uniform(sc.bounds.east_min - 300, sc.bounds.east_max + 300, b)
    states[:, 2] = rng.uniform(-np.pi, np.pi, b)
    states[:, 3] = rng.uniform(0.0, sc.bounds.height_max + 100, b)  # rollout() refuses starts below ground
    states[:8, :2] = [sc.goal.north, sc.goal.east]  # some edges start at the goal
    states[:8, 3] = sc.goal.height + rng.uniform(-200, 200, 8)
    r = model.rollout_primitive(states, rng.integers(0, N_PRIMITIVES, b))
    codes = np.empty(b, dtype=np.int64)
    ks = np.empty(b, dtype=np.int64)
    classify_batch(r.states, np.tile(scenario_params(sc), (b, 1)), codes, ks)
    want_codes, want_ks = model.classify(r)
    assert np.array_equal(codes, want_codes) and np.array_equal(ks, want_ks)


# --- determinism, invariants -------------------------------------------------------------------------
def _episode(env: gym.Env, seed: int, n: int) -> list:
    rng = np.random.default_rng(seed)
    out = [env.reset(seed=seed)]
    for _ in range(n):
        step = env.step(_sample(env, rng))
        out.append(step)
        if step[2] or step[3]:
            out.append(env.reset())
    return out


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("scenario", ["paper", "random"])
def test_same_seed_gives_identical_episodes(env_id: str, scenario: str) -> None:
    a = _episode(gym.make(env_id, scenario=scenario), 7, 60)
    b = _episode(gym.make(env_id, scenario=scenario), 7, 60)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x[0], y[0]) and x[1:] == y[1:]
    if scenario == "random":
        c = _episode(gym.make(env_id, scenario=scenario), 8, 60)
        assert not np.array_equal(a[0][0], c[0][0])


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31 - 1),
    continuous=st.booleans(),
    observe_thermals=st.booleans(),
    model=st.sampled_from(["allen", "gaussian"]),
    drift=st.booleans(),
)
def test_random_flights_keep_invariants(
    seed: int, continuous: bool, observe_thermals: bool, model: str, drift: bool
) -> None:
    env = gym.make(
        CONTINUOUS_ENV_ID if continuous else ENV_ID,
        scenario="random",
        random_scenario={"model": model, "drift": drift, "n_thermals": (0, 8)},
        observe_thermals=observe_thermals,
    )
    space = env.observation_space
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    assert space.contains(obs)
    total_cost = fuel = potential = kinetic = 0.0
    for _ in range(120):
        action = _sample(env, rng)
        if not continuous and rng.random() < 0.7:  # mostly valid primitives: longer flights
            action = int(rng.choice(np.flatnonzero(env.unwrapped.action_masks())))
        obs, reward, terminated, truncated, info = env.step(action)
        assert space.contains(obs) and np.all(np.isfinite(obs))
        assert math.isfinite(reward) and reward == sum(info["reward_terms"].values())
        assert all(math.isfinite(v) for k, v in info.items() if isinstance(v, float)), info
        assert info["edge_cost"] == info["fuel"] + info["potential"] + info["kinetic"]
        total_cost += info["edge_cost"]
        fuel, potential, kinetic = fuel + info["fuel"], potential + info["potential"], kinetic + info["kinetic"]
        assert info["energy_spent"] == total_cost
        assert info["energy_spent"] == pytest.approx(fuel + potential + kinetic, rel=1e-9, abs=1e-6)
        assert info["reward_terms"]["energy"] == -info["edge_cost"] / 1000.0
        assert info["is_success"] == (info["outcome"] == "goal")
        assert terminated == (info["outcome"] != "flying")
        assert info["fuel"] >= 0.0 and info["kinetic"] >= 0.0
        if terminated or truncated:
            obs, info = env.reset()
            assert space.contains(obs)
            total_cost = fuel = potential = kinetic = 0.0


# --- episode end ------------------------------------------------------------------------------------
def test_crash_terminates_at_the_ground_contact_point() -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    obs, _reward, terminated, truncated, info = env.step(DIVE)  # 424 m down from 300 m
    assert terminated and not truncated and info["outcome"] == "crash" and not info["is_success"]
    assert info["reward_terms"]["crash"] == -25.0 and -15.0 < info["height"] <= 0.0
    assert info["potential"] == pytest.approx(9.80665 * 424.26, rel=1e-3)  # the full edge is charged
    assert env.observation_space.contains(obs)
    with pytest.raises(RuntimeError, match="reset"):
        env.unwrapped.step(LEVEL)


def test_goal_and_out_of_bounds_terminate() -> None:
    sc = Scenario(start=(0.0, 0.0, 0.0, 300.0), goal=GoalRegion(north=700.0, east=0.0, height=300.0, radius=150.0))
    env = gym.make(ENV_ID)
    env.reset(options={"scenario": sc})
    _, _reward, terminated, _, info = env.step(LEVEL)  # 20 m per point: 560 m is the first inside
    assert terminated and info["outcome"] == "goal" and info["is_success"] is True
    assert info["reward_terms"]["goal"] == 25.0 and env.unwrapped.state[0] == pytest.approx(560.0)
    narrow = Scenario(bounds=Bounds(-100.0, 4000.0, -100.0, 100.0, 1500.0))
    env.reset(options={"scenario": narrow})
    _, _, terminated, _, info = env.step(67)  # 20 m/s, +90 deg curve (radius 382 m): leaves the strip
    assert terminated and info["outcome"] == "out_of_bounds"
    assert info["reward_terms"]["out_of_bounds"] == -25.0


def test_truncation_only_by_the_time_limit() -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    spiral_level_10 = 70 + 2 * 5 + 2  # 10 m/s, -720 deg, gamma 0: circles in place
    for i in range(MAX_EPISODE_STEPS):
        _, _, terminated, truncated, info = env.step(spiral_level_10)
        assert not terminated
        assert truncated == (i == MAX_EPISODE_STEPS - 1)
    assert info["time"] == MAX_EPISODE_STEPS * 30.0
    with pytest.raises(RuntimeError, match="reset"):  # after truncation, as after termination
        env.step(spiral_level_10)
    env.reset(seed=0)
    env.step(spiral_level_10)


@pytest.mark.parametrize("env_id", [ENV_ID, CONTINUOUS_ENV_ID])
@pytest.mark.parametrize("limit", [1, 3, None])
def test_max_steps_is_the_envs_own_limit(env_id: str, limit: int | None) -> None:
    """``gym.make(id, max_steps=N)`` truncates at N in the single env and the native vector env;
    ``None`` never truncates; bad values are named errors."""
    action = 70 + 2 * 5 + 2 if env_id == ENV_ID else np.zeros(3, np.float32)  # a level spiral; straight
    env = gym.make(env_id, max_steps=limit, scenario=Scenario(start=(0.0, -2000.0, 0.0, 1000.0)))
    env.reset(seed=0)
    n = 5 if limit is None else limit
    for i in range(n):
        _, _, terminated, truncated, _ = env.step(action)
        assert not terminated and truncated == (limit is not None and i == limit - 1)
    venv = gym.make_vec(env_id, num_envs=2, max_steps=limit, scenario=Scenario(start=(0.0, -2000.0, 0.0, 1000.0)))
    venv.reset(seed=0)
    for i in range(n):
        _, _, terminated, truncated, _ = venv.step(np.stack([action, action]))
        assert not terminated.any() and truncated.tolist() == [limit is not None and i == limit - 1] * 2
    for bad in (0, -1, 2.5, "40", True):
        with pytest.raises(ConfigError, match="max_steps"):
            gym.make(env_id, max_steps=bad)


# --- scenarios, options and configuration -------------------------------------------------------------
def test_reset_options_pin_a_scenario_for_one_episode() -> None:
    env = gym.make(ENV_ID)
    custom = paper_scenario().replace(name="moved", start=(100.0, 50.0, 0.5, 400.0))
    _obs, info = env.reset(options={"scenario": custom})
    assert env.unwrapped.scenario is custom and info["scenario"] == "moved"
    assert np.array_equal(env.unwrapped.state, [100.0, 50.0, 0.5, 400.0])
    env.reset(options={"scenario": custom.to_dict()})
    assert env.unwrapped.scenario == custom
    env.reset(options={"scenario": "paper"})
    assert env.unwrapped.scenario.name == "paper"
    env.reset(seed=1, options={"scenario": "random"})
    assert env.unwrapped.scenario.name == "random"
    env.reset()
    assert env.unwrapped.scenario.name == "paper"  # back to the configured mode


def test_config_object_and_keywords() -> None:
    cfg = SoaringEnvConfig(goal_bonus=50.0, n_obs_thermals=2)
    env = gym.make(ENV_ID, config=cfg, crash_penalty=40.0)
    assert env.unwrapped.config.goal_bonus == 50.0 and env.unwrapped.config.crash_penalty == 40.0
    assert env.observation_space.shape == (21,)
    env.reset(seed=0)
    assert env.step(DIVE)[4]["reward_terms"]["crash"] == -40.0
    env = gym.make(ENV_ID, config={"scenario": "random", "random_scenario": {"n_thermals": (3, 3)}})
    env.reset(seed=4)
    assert len(env.unwrapped.field.thermals) == 3
    assert soaring_env.SoaringEnv is type(gym.make(ENV_ID).unwrapped)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"scenario": "nowhere"}, "unknown"),
        ({"goal_bonus": float("nan")}, "finite"),
        ({"n_obs_thermals": -1}, "n_obs_thermals"),
        ({"duration": 0.0}, "duration"),
        ({"max_bank_deg": 95.0}, "max_bank_deg"),
        ({"wingspan": 3.0}, "unknown config field"),
        ({"random_scenario": {"n_thermal": (1, 2)}}, "unknown key"),
        ({"random_scenario": {"strength": (3.0, 1.0)}}, "strength"),
        ({"render_size": (10, 10)}, "render_size"),
        ({"render_mode": "ascii"}, "render_mode"),
    ],
)
@pytest.mark.filterwarnings("ignore:.*render_mode:UserWarning")
def test_bad_configuration_is_explained(kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        gym.make(ENV_ID, **kwargs)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: GoalRegion(height=-10.0), "below the ground"),
        (lambda: Scenario(start=(0.0, 0.0, 0.0, 300.0), bounds=Bounds(100.0, 4000.0, -100.0, 100.0)), "outside"),
        (lambda: Scenario(goal=GoalRegion(north=9000.0)), "outside the domain"),
        (lambda: Scenario(field=WindField(thermals=(Thermal(0.0, 0.0, strength=-1.0),))), "strength"),
    ],
)
def test_invalid_scenarios_are_explained(make, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        make()


def test_invalid_scenario_dicts_and_options_are_explained() -> None:
    env = gym.make(ENV_ID)
    bad = paper_scenario().to_dict()
    bad["goal"]["height"] = -5.0
    with pytest.raises(ConfigError, match="below the ground"):
        env.reset(options={"scenario": bad})
    with pytest.raises(ConfigError, match="unknown reset option"):
        env.reset(options={"scenery": "paper"})
    with pytest.raises(ConfigError, match="unknown"):
        env.reset(options={"scenario": "atlantis"})
    with pytest.raises(ConfigError, match="Scenario"):
        env.reset(options={"scenario": 42})


@pytest.mark.parametrize(
    "action", [174, -1, 3.0, float("nan"), np.array([1, 2]), np.float32(2.0), True, "7", None, np.int64(200)]
)
def test_bad_discrete_actions_are_explained(action) -> None:
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    with pytest.raises(ConfigError, match=r"0\.\.173"):
        env.step(action)
    env.step(np.int64(LEVEL))
    env.step(np.array(LEVEL))


@pytest.mark.parametrize(
    "action",
    [
        np.array([1.5, 0.0, 0.0], dtype=np.float32),
        np.array([np.nan, 0.0, 0.0]),
        np.array([np.inf, 0.0, 0.0]),
        np.zeros(2, dtype=np.float32),
        np.zeros((1, 3), dtype=np.float32),
        np.array(["a", "b", "c"]),
        np.array([1 + 1j, 0, 0]),
        7,
    ],
)
def test_bad_continuous_actions_are_explained(action) -> None:
    env = gym.make(CONTINUOUS_ENV_ID).unwrapped
    env.reset(seed=0)
    with pytest.raises(ConfigError, match=r"\[-1, 1\]"):
        env.step(action)
    env.step([1.0, 0.0, 0.0])  # lists are fine


# --- action masks -----------------------------------------------------------------------------------
def test_action_masks_mark_exactly_the_invalid_primitives() -> None:
    env = gym.make(ENV_ID, max_bank_deg=45.0)
    env.reset(seed=0)
    u = env.unwrapped
    mask = u.action_masks()
    assert mask.dtype == np.bool_ and mask.shape == (N_PRIMITIVES,)
    r = u.model.rollout_primitive(u.state, np.arange(N_PRIMITIVES))
    code, _ = u.model.classify(r)
    bank_ok = r.max_bank <= math.radians(45.0) + 1e-12
    assert np.array_equal(mask, (code != CRASH) & (code != OUT_OF_BOUNDS) & bank_ok)
    assert not mask[DIVE] and mask[LEVEL] and not mask.all()
    assert u.model.bank_ok().sum() < N_PRIMITIVES  # 45 deg removes the tightest spirals
    assert not hasattr(gym.make(CONTINUOUS_ENV_ID).unwrapped, "action_masks")


def test_action_masks_never_mask_everything() -> None:
    box = Scenario(bounds=Bounds(-10.0, 10.0, -10.0, 10.0, 1500.0), goal=GoalRegion(8.0, 8.0, 300.0, 1.0))
    env = gym.make(ENV_ID)
    env.reset(options={"scenario": box})  # a 20 m box: every primitive leaves it
    u = env.unwrapped
    r = u.model.rollout_primitive(u.state, np.arange(N_PRIMITIVES))
    code, k = u.model.classify(r)
    assert np.all(code == OUT_OF_BOUNDS)
    mask = u.action_masks()
    assert mask.any() and np.all(k[mask] == k[u.model.bank_ok()].max())
    assert np.all(u.model.bank_ok()[mask])


def test_maskable_ppo_sees_the_masks() -> None:
    from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported

    env = gym.make(ENV_ID)
    env.reset(seed=0)
    assert is_masking_supported(env)
    assert get_action_masks(env).shape == (N_PRIMITIVES,)


# --- rendering --------------------------------------------------------------------------------------
def test_rgb_array_frame_and_human_mode(tmp_path) -> None:
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(57)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (640, 960, 3)
    assert frame.std() > 20  # a picture, not a blank canvas
    env.step(DIVE)
    crash = env.render()
    assert crash.shape == frame.shape and not np.array_equal(crash, frame)
    env.close()
    human = gym.make(ENV_ID, render_mode="human")
    human.reset(seed=0)
    human.step(LEVEL)
    assert human.render() is None
    human.close()
    with pytest.warns(UserWarning, match="render"):
        none_env = gym.make(ENV_ID)
        none_env.reset(seed=0)
        assert none_env.render() is None


def test_record_video(tmp_path) -> None:
    pytest.importorskip("moviepy")
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(
        gym.make(ENV_ID, render_mode="rgb_array", render_size=(480, 320)),
        str(tmp_path / "videos"),
        episode_trigger=lambda e: True,
        disable_logger=True,
    )
    env.reset(seed=0)
    for a in (57, 163, DIVE):
        if env.step(a)[2]:
            break
    env.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1))
def test_rollouts_are_batch_invariant_near_thermals(seed: int) -> None:
    """Model calls with B = 1 and in a batch, and the env's kernel path, agree bit for bit.

    Guards the replay contract: numba compiles one kernel per read-only/writable flag pattern of
    the inputs, and with fast-math these could round differently.
    """
    rng = np.random.default_rng(seed)
    sc = make_scenario(rng, n_thermals=(1, 5))
    m = SoaringModel(scenario=sc)
    prop = m.propagator
    b = 24
    th = np.array([[t.north, t.east] for t in sc.field.thermals])[rng.integers(0, len(sc.field.thermals), b)]
    x = np.column_stack([th + rng.uniform(-150, 150, (b, 2)), rng.uniform(-3, 3, b), rng.uniform(100, 1300, b)])
    p = rng.integers(0, N_PRIMITIVES, b)
    batch = m.rollout_primitive(x, p, t0=30.0, airspeed_prev=10.0)
    env_out, env_terms = prop.run(x.copy(), np.full(b, 30.0), np.full(b, 10.0), prop.ctrl_table[p])
    assert np.array_equal(env_out, batch.states) and np.array_equal(env_terms[:, 3], batch.cost)
    for i in range(0, b, 5):
        one = m.rollout_primitive(x[i], int(p[i]), t0=30.0, airspeed_prev=10.0)
        assert np.array_equal(one.states[0], batch.states[i]) and one.cost[0] == batch.cost[i]


def test_energy_weight_scales_only_the_energy_reward() -> None:
    """``energy_weight`` multiplies the energy term; the flight and its J/kg bookkeeping are unchanged."""
    a, b = gym.make(ENV_ID, energy_weight=1.0), gym.make(ENV_ID, energy_weight=3.0)
    a.reset(seed=0)
    b.reset(seed=0)
    for action in (7, 57, 120):
        ra, rb = a.step(action), b.step(action)
        assert np.array_equal(ra[0], rb[0]) and ra[4]["energy_spent"] == rb[4]["energy_spent"]
        assert rb[4]["reward_terms"]["energy"] == pytest.approx(3.0 * ra[4]["reward_terms"]["energy"])
        assert rb[4]["reward_terms"]["progress"] == ra[4]["reward_terms"]["progress"]
    with pytest.raises(ConfigError, match="energy_weight"):
        gym.make(ENV_ID, energy_weight=-1.0)


def _action(env_id: str, rng: np.random.Generator) -> int | np.ndarray:
    return int(rng.integers(N_PRIMITIVES)) if env_id == ENV_ID else rng.uniform(-0.3, 0.3, 3).astype(np.float32)


@pytest.mark.parametrize("env_id", IDS)
def test_settle_height_makes_a_truncated_flight_pay_as_if_it_ended_at_the_goal_top(env_id: str) -> None:
    """Closed form: with ``settle_height`` the energy and settlement rewards of a truncated episode
    sum to ``w (g (h_top - h_start) - fuel - kinetic) / 1 kJ/kg``; other steps are
    unchanged, and the native vector env pays the same."""
    w, n_steps, seeds = 2.0, 6, (5, 6, 7)
    kw = {"energy_weight": w, "max_steps": n_steps, "scenario": "random"}
    plain = [gym.make(env_id, **kw) for _ in seeds]
    settled = [gym.make(env_id, settle_height=True, **kw) for _ in seeds]
    vec = gym.make_vec(env_id, num_envs=len(seeds), settle_height=True, **kw)
    vec.reset(seed=list(seeds))
    for e, f, seed in zip(plain, settled, seeds, strict=True):
        e.reset(seed=seed)
        f.reset(seed=seed)
    rng = np.random.default_rng(0)
    fuel_kinetic = np.zeros(len(seeds))
    total = np.zeros(len(seeds))
    done = np.zeros(len(seeds), dtype=bool)
    n_truncated = 0
    for _ in range(n_steps):
        actions = [_action(env_id, rng) for _ in seeds]
        rv = vec.step(np.array(actions))
        for i, (e, f) in enumerate(zip(plain, settled, strict=True)):
            if done[i]:
                continue
            rp, rs = e.step(actions[i]), f.step(actions[i])
            assert np.array_equal(rp[0], rs[0]) and rv[1][i] == rs[1]
            terms = rs[4]["reward_terms"]
            fuel_kinetic[i] += rs[4]["fuel"] + rs[4]["kinetic"]
            total[i] += terms["energy"] + terms["settlement"]
            if rs[3] and not rs[2]:  # truncated by the step limit
                sc = f.unwrapped.scenario
                h_top = sc.goal.height + sc.goal.radius
                expect = w * (9.80665 * (h_top - sc.start[3]) - fuel_kinetic[i]) / 1000.0
                assert total[i] == pytest.approx(expect, rel=1e-9, abs=1e-9)
                assert rs[1] == pytest.approx(rp[1] + terms["settlement"]) and terms["settlement"] != 0.0
                n_truncated += 1
            else:
                assert terms["settlement"] == 0.0 and rs[1] == rp[1]
            done[i] = rs[2] or rs[3]
    assert n_truncated >= 1
    with pytest.raises(ConfigError, match="settle_height"):
        gym.make(env_id, settle_height="yes")
    with pytest.raises(ConfigError, match="settle_height"):
        gym.make("soaring/ThermalClimbContinuous-v0", settle_height=True)
    for env in (*plain, *settled, vec):
        env.close()


def test_reset_with_the_last_airspeed_resumes_mid_flight() -> None:
    """``reset(options={"airspeed_prev": v})``: an episode started at a state reached mid-flight
    flies its next edge exactly as the original episode does (the speed change paid, the observed
    airspeed shown); without it the first edge pays no speed change. Bad values name the option."""
    env = gym.make(ENV_ID)
    base = env.unwrapped
    sc = paper_scenario()
    env.reset(options={"scenario": sc})
    env.step(2)  # straight, level, 10 m/s
    v = float(base.airspeed_prev)
    resumed = sc.replace(start=tuple(float(s) for s in base.state))
    *_, flown = env.step(7)  # straight, level, 20 m/s: a speed change
    obs, _ = env.reset(options={"scenario": resumed, "airspeed_prev": v})
    names = list(base.observation_names)
    assert v == 10.0 and obs[names.index("airspeed")] * base.config.speed_scale == pytest.approx(v)
    *_, again = env.step(7)
    assert flown["kinetic"] > 0.0
    for key in ("edge_cost", "fuel", "kinetic", "potential", "height"):
        assert again[key] == pytest.approx(flown[key], rel=1e-9, abs=1e-9), key
    env.reset(options={"scenario": resumed})
    *_, fresh = env.step(7)
    assert fresh["kinetic"] == 0.0
    for bad in ("fast", -1.0, 0.0, float("nan"), True, [12.0]):
        with pytest.raises(ConfigError, match="airspeed_prev"):
            env.reset(options={"scenario": "paper", "airspeed_prev": bad})
    with pytest.raises(ConfigError, match="allowed: 'scenario', 'airspeed_prev'"):
        env.reset(options={"scenery": "paper"})
