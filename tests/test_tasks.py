"""The tasks (thermal climb, cross-country), the stall limit, the physical envelope, observation tiers."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import soaring_env  # noqa: F401  (registers the ids)
from soaring_env import ConfigError
from soaring_env.env import ENV_IDS, TASK_ENVS, CrossCountryConfig, ThermalClimbConfig
from soaring_env.env.observation import sensor_noise
from soaring_env.model import SoaringModel
from soaring_env.physics.aircraft import TEMPEST_CL_MAX, Aircraft
from soaring_env.primitives import COL_AIRSPEED, ControlEnvelope, PrimitiveLibrary
from soaring_env.scenario import Scenario, get_scenario, make_climb_scenario, make_cross_country_scenario

TASK_IDS = tuple(f"soaring/{k}" for k in TASK_ENVS)


def _actions(space: gym.Space, rng: np.random.Generator, n: int) -> np.ndarray:
    if isinstance(space, gym.spaces.Discrete):
        return rng.integers(0, space.n, n)
    return rng.uniform(-1, 1, (n, 3)).astype(np.float32)


def test_every_id_is_registered() -> None:
    assert set(ENV_IDS) <= set(gym.registry)
    assert len(ENV_IDS) == 6
    for env_id in TASK_IDS:
        assert gym.spec(env_id).max_episode_steps is None  # the tasks truncate by time_limit


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_gymnasium_and_sb3_check_env(env_id: str) -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id)
        gym_check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(gym.make(env_id).unwrapped, warn=True)


@pytest.mark.parametrize("env_id", TASK_IDS)
@pytest.mark.parametrize("noise", [0.0, 0.3])
def test_native_batched_equals_single_envs(env_id: str, noise: float) -> None:
    """Same seeds, same actions: the batched env's transitions equal n single envs' (sync)."""
    n = 3
    kw = {
        "history_length": 2,
        "sensor_noise": noise,
        "observe_thermals": noise == 0.0,
        "history_positions": noise > 0,
        "observe_start": noise > 0,
    }
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", **kw)
    native = gym.make_vec(env_id, num_envs=n, **kw)
    o1, _ = sync.reset(seed=5)
    o2, _ = native.reset(seed=5)
    assert np.array_equal(o1, o2)
    rng = np.random.default_rng(1)
    ends = 0
    for _ in range(40):
        a = _actions(sync.single_action_space, rng, n)
        r1, r2 = sync.step(a), native.step(a)
        for x, y in zip(r1[:4], r2[:4], strict=True):
            assert np.array_equal(x, y)
        ends += int(np.sum(r1[2] | r1[3]))
    assert ends > 0


@pytest.mark.parametrize("env_id", TASK_IDS)
def test_same_seed_same_episode(env_id: str) -> None:
    def run() -> list[float]:
        env = gym.make(env_id, sensor_noise=0.2, history_length=3)
        obs, _ = env.reset(seed=3)
        env.action_space.seed(3)
        out = [float(obs.sum())]
        for _ in range(15):
            obs, r, term, trunc, _ = env.step(env.action_space.sample())
            out += [float(obs.sum()), float(r)]
            if term or trunc:
                obs, _ = env.reset()
        return out

    assert run() == run()


def test_history_positions_of_a_straight_glide_in_closed_form() -> None:
    """In a steady wind with a constant control the aircraft's ground velocity is constant, so
    edge j back was sensed (its time midpoint) (j + 1/2) edges behind: -(j + 1/2) d, d the ground
    displacement of one edge; in the aircraft's frame that is straight behind (ahead < 0, right 0
    but for the wind's crab). Slots not flown yet read zero."""
    from baselines.ppo import BodyFrame

    h = 4
    env = gym.make(
        "soaring/ThermalClimbContinuous-v0", observe_thermals=False, history_length=h, history_positions=True
    )
    names = env.unwrapped.observation_names
    north = [names.index(f"history_{j}_north") for j in range(h)]
    east = [names.index(f"history_{j}_east") for j in range(h)]
    obs, _ = env.reset(seed=0, options={"scenario": "climb-10001"})
    assert not obs[north + east].any()
    scale = env.unwrapped.config.position_scale
    start = env.unwrapped.state[:2].copy()
    for k in range(1, h + 2):
        obs, *_ = env.step(np.array([0.0, 0.0, 0.0], dtype=np.float32))  # straight, mid-envelope speed
        d = (env.unwrapped.state[:2] - start) / k  # one edge's ground displacement [m]
        for j in range(h):
            want = -(j + 0.5) * d / scale if j < k else np.zeros(2)
            assert np.allclose([obs[north[j]], obs[east[j]]], want, atol=1e-6)
    frame = BodyFrame(names)
    body = frame(obs)
    ahead = body[north]
    assert np.all(ahead < 0) and np.all(np.diff(ahead) < 0)  # further behind, edge by edge


def test_observe_start_gives_the_start_relative_to_the_aircraft() -> None:
    env = gym.make(
        "soaring/ThermalClimbContinuous-v0", observe_thermals=False, observe_start=True, position_scale=200.0
    )
    names = env.unwrapped.observation_names
    i, k = names.index("start_north"), names.index("start_east")
    obs, _ = env.reset(seed=2)
    start = env.unwrapped.scenario.start_state[:2].copy()
    assert obs[i] == 0.0 and obs[k] == 0.0
    rng = np.random.default_rng(0)
    for _ in range(20):
        obs, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 3).astype(np.float32))
        if term or trunc:
            break
        want = (start - env.unwrapped.state[:2]) / 200.0
        assert np.allclose(obs[[i, k]], np.clip(want, -10, 10), atol=1e-6)
    with pytest.raises(ConfigError, match="observe_start"):
        gym.make("soaring/ThermalClimb-v0", observe_start="no")


def test_history_positions_need_the_history_and_extend_it() -> None:
    env = gym.make("soaring/ThermalClimb-v0", observe_thermals=False, history_length=2, history_positions=True)
    names = env.unwrapped.observation_names
    assert names[-10:] == [f"history_{j}_{n}" for j in range(2) for n in ("lift", "climb", "turn", "north", "east")]
    plain = gym.make("soaring/ThermalClimb-v0", observe_thermals=False, history_length=2)
    assert len(plain.unwrapped.observation_names) == len(names) - 4


def test_sensor_noise_is_gaussian_and_counter_based() -> None:
    keys = np.arange(20_000, dtype=np.uint64) * np.uint64(7919)
    z = sensor_noise(keys, np.full(keys.size, 3, dtype=np.uint64), 0.5)
    assert z.shape == (keys.size, 2) and np.all(np.isfinite(z))
    assert abs(z.mean()) < 0.02 and abs(z.std() - 0.5) < 0.02
    # a step's noise depends only on (key, step): any batch order gives the same numbers
    perm = np.random.default_rng(0).permutation(keys.size)
    z2 = sensor_noise(keys[perm], np.full(keys.size, 3, dtype=np.uint64), 0.5)
    assert np.array_equal(z2, z[perm])
    assert not np.array_equal(z, sensor_noise(keys, np.full(keys.size, 4, dtype=np.uint64), 0.5))


def test_climb_energy_bookkeeping_and_time_limit() -> None:
    """Rewards sum to -(energy spent) / 1000 and the terminal penalties; the env truncates at
    time_limit and refuses a step after it."""
    env = gym.make("soaring/ThermalClimbContinuous-v0", time_limit=60.0)
    obs, info = env.reset(seed=0)
    names = env.unwrapped.observation_names
    assert "goal_north" not in names and names[8] == "time_left" and obs[8] == 1.0
    total, steps = 0.0, 0
    trunc = term = False
    while not (term or trunc):
        obs, r, term, trunc, info = env.step(np.array([0.0, 0.3, 0.2], np.float32))  # level turn
        total += r
        steps += 1
        assert set(info["reward_terms"]) == {"energy", "crash", "out_of_bounds"}
    assert trunc and not term and steps == 12 and info["time"] == pytest.approx(60.0)
    assert obs[8] == 0.0
    assert total == pytest.approx(-info["energy_spent"] / 1000.0, abs=1e-9)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(3, np.float32))


def test_climb_circling_in_lift_gains_energy() -> None:
    """A zero-thrust circle over a strong thermal's core gains energy; the same circle far from
    it loses some: the task rewards thermalling."""
    sc = make_climb_scenario(
        np.random.default_rng(0), n_thermals=(1, 1), thermal_radius=0.0, strength=(3.0, 3.0), wind_speed=(0.0, 0.0)
    )
    env = gym.make("soaring/ThermalClimbContinuous-v0", scenario=sc, time_limit=300.0)
    model = env.unwrapped.model
    glide = float(model.aircraft.glide_angle(12.5, 9.80665 * math.tan(math.radians(30)) / 12.5, 1500.0))
    a = model.control_to_action(np.array([12.5, 9.80665 * math.tan(math.radians(30)) / 12.5, glide]))
    a = np.clip(a, -1, 1).astype(np.float32)
    env.reset(seed=0)
    ret = 0.0
    for _ in range(60):
        _, r, term, trunc, info = env.step(a)
        ret += r
        if term or trunc:
            break
    assert info["outcome"] == "flying" and ret > 1.0  # > 1 kJ/kg (100 m) gained in 300 s


def test_cross_country_battery_runs_out() -> None:
    env = gym.make("soaring/CrossCountryContinuous-v0")
    _, info = env.reset(seed=2)
    u = env.unwrapped
    g = u.scenario.goal
    d = math.hypot(g.north, g.east)
    assert 8000 <= d <= 15000
    assert u.battery == pytest.approx(0.25 * d * 9.80665 / (Aircraft().max_lift_to_drag * 0.8))
    used = 0.0
    term = False
    while not term:  # full power climb: the battery runs out long before the goal
        _, _, term, _, info = env.step(np.array([1.0, 0.0, 1.0], np.float32))
        used += info["fuel"] + info["kinetic"]
        assert info["battery_left"] == pytest.approx(u.battery - used)
    assert info["outcome"] == "battery_empty" and info["reward_terms"]["battery_empty"] == -25.0
    assert info["battery_left"] <= 0.0


def test_cross_country_rewards_add_up() -> None:
    """Sum of rewards = -energy / 1000 + the telescoped progress (3-D goal distance, per km) + the
    terminal term; energy_spent = the summed edge costs."""
    env = gym.make("soaring/CrossCountryContinuous-v0")
    _, _ = env.reset(seed=4)
    u = env.unwrapped
    g = u.scenario.goal
    d0 = float(g.distance(*u.state[[0, 1, 3]]))
    total, costs, term, trunc = 0.0, 0.0, False, False
    rng = np.random.default_rng(0)
    while not (term or trunc):
        _, r, term, trunc, info = env.step(rng.uniform(-1, 1, 3).astype(np.float32))
        total += r
        costs += info["edge_cost"]
        assert r == pytest.approx(sum(info["reward_terms"].values()), abs=1e-12)
    d1 = float(g.distance(*u.state[[0, 1, 3]]))
    penalty = {"battery_empty": -25.0, "crash": -25.0, "out_of_bounds": -25.0, "goal": 25.0}[info["outcome"]]
    assert info["energy_spent"] == pytest.approx(costs, rel=1e-12)
    assert total == pytest.approx(-costs / 1000.0 + (d0 - d1) / 1000.0 + penalty, abs=1e-9)


def test_stall_limit_masks_the_slow_primitives() -> None:
    lib = PrimitiveLibrary()
    model = SoaringModel(aircraft=Aircraft(cl_max=TEMPEST_CL_MAX))
    ok = model.stall_ok()
    # closed form at the 1,500 m ceiling: C_L = 2 m g cos(gamma) / (rho v^2 S cos(phi))
    t = lib.table
    v, gam = t[:, COL_AIRSPEED], t[:, 2]
    phi = np.arctan(v * np.maximum(np.abs(t[:, 3]), np.abs(t[:, 4])) / 9.80665)
    rho = 1.225 * (1 - 0.0065 * 1500 / 288.15) ** 4.2559
    cl = 2 * 6.4 * 9.80665 * np.cos(gam) / (rho * v**2 * 0.668 * np.cos(phi))
    assert np.array_equal(ok, cl <= TEMPEST_CL_MAX)
    assert not ok[(v == 10.0) & (np.abs(gam) < 0.5)].any() and ok[v == 20.0].all()
    assert SoaringModel().stall_ok().all()  # the paper's model: no limit
    env = gym.make("soaring/ThermalClimb-v0")
    env.reset(seed=0)
    masks = env.unwrapped.action_masks()
    assert not masks[~ok].any()
    # closed form: C_L of level wings-level flight at the stall speed is cl_max at sea level
    vs = math.sqrt(2 * Aircraft().weight / (1.225 * Aircraft().wing_area * TEMPEST_CL_MAX))
    assert float(Aircraft().lift_coefficient(vs, 0.0, 0.0, 0.0)) == pytest.approx(TEMPEST_CL_MAX)
    assert vs == pytest.approx(11.0, abs=0.02)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1))
def test_physical_envelope_is_flyable_and_invertible(a0: float, a1: float, a2: float) -> None:
    ac = Aircraft(cl_max=TEMPEST_CL_MAX)
    env = ControlEnvelope.physical(ac, max_bank_deg=60.0, height_max=1500.0)
    c = env.to_control(np.array([a0, a1, a2]))
    v, chi_dot, gamma = c
    bank = math.atan(v * chi_dot / 9.80665)
    assert 12.0 <= v <= 25.0 and abs(bank) <= math.radians(60) + 1e-12
    assert math.radians(-30) - 1e-12 <= gamma <= math.radians(20) + 1e-12
    assert float(ac.lift_coefficient(v, 0.0, bank, 1500.0)) <= TEMPEST_CL_MAX * (1 + 1e-9)
    assert np.allclose(env.to_action(c), [a0, a1, a2], atol=1e-9)
    lo, hi = env.bounds()
    assert np.all(c >= lo - 1e-12) and np.all(c <= hi + 1e-12)


def test_paper_envelope_maps_as_before() -> None:
    lib = PrimitiveLibrary()
    env = ControlEnvelope.paper(lib)
    lo, hi = lib.control_bounds()
    a = np.random.default_rng(0).uniform(-1, 1, (100, 3))
    assert np.array_equal(env.to_control(a), lo + 0.5 * (a + 1.0) * (hi - lo))


def test_task_scenarios_are_reproducible_and_named() -> None:
    a = get_scenario("climb-10000")
    assert a == get_scenario("climb-10000") and a.goal is None and a.name == "climb-10000"
    assert Scenario.from_dict(a.to_dict()) == a
    b = get_scenario("xc-10000")
    assert b.goal is not None and 8000 <= math.hypot(b.goal.north, b.goal.east) <= 15000
    assert 3 <= len(a.field.thermals) <= 6 and 100 <= a.start[3] <= 300
    for t in a.field.thermals:
        assert math.hypot(t.north, t.east) <= 1000.0
    # another family's name in a task env takes no task keywords
    env = gym.make("soaring/ThermalClimb-v0", random_scenario={"n_thermals": (2, 2)}, scenario="random-3")
    assert env.unwrapped.scenario.name == "random-3"


@pytest.mark.parametrize(
    ("env_id", "kwargs", "match"),
    [
        ("soaring/CrossCountry-v0", {"battery_fraction": 0.0}, "battery_fraction"),
        ("soaring/CrossCountry-v0", {"battery_fraction": -1.0}, "battery_fraction"),
        ("soaring/CrossCountry-v0", {"battery_fraction": "a"}, "battery_fraction"),
        ("soaring/ThermalClimb-v0", {"time_limit": 10.0}, "time_limit"),
        ("soaring/ThermalClimbContinuous-v0", {"duration": 0.5}, "duration"),
        ("soaring/ThermalClimbContinuous-v0", {"duration": 60.0}, "duration"),
        ("soaring/ThermalClimbContinuous-v0", {"envelope": "paper"}, "envelope='physical'"),
        ("soaring/ThermalClimbContinuous-v0", {"airspeed_range": (8.0, 20.0)}, "stalls"),
        ("soaring/ThermalClimb-v0", {"random_scenario": {"goal_distance": (1, 2)}}, "goal_distance"),
        ("soaring/ThermalClimb-v0", {"random_scenario": {"height": (0.0, 100.0)}}, "height"),
        ("soaring/CrossCountry-v0", {"random_scenario": {"corridor": -1.0}}, "corridor"),
        ("soaring/ThermalClimb-v0", {"history_length": -1}, "history_length"),
        ("soaring/ThermalClimb-v0", {"history_positions": True}, "history_length > 0"),
        ("soaring/ThermalClimb-v0", {"history_length": 2, "history_positions": "yes"}, "history_positions"),
        ("soaring/ThermalClimb-v0", {"sensor_noise": float("nan")}, "sensor_noise"),
        ("soaring/Soaring-v0", {"envelope": "fancy"}, "envelope"),
    ],
)
def test_bad_generator_settings_are_explained(env_id: str, kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        gym.make(env_id, **kwargs)


def test_task_configs_are_frozen_dataclasses_with_own_defaults() -> None:
    c = ThermalClimbConfig()
    assert c.scenario == "random" and c.time_limit == 600.0 and c.aircraft.cl_max == TEMPEST_CL_MAX
    x = CrossCountryConfig()
    assert x.battery_fraction == 0.25 and x.position_scale == 2000.0
    with pytest.raises(ConfigError, match="ThermalClimbConfig"):
        gym.make("soaring/ThermalClimb-v0", config=x)
    assert make_cross_country_scenario(np.random.default_rng(1)) == make_cross_country_scenario(
        np.random.default_rng(1)
    )


@pytest.mark.parametrize("env_id", ["soaring/Soaring-v0", "soaring/ThermalClimbContinuous-v0"])
def test_thermal_realism_options_are_reproducible_and_batched_alike(env_id: str) -> None:
    """Life cycles and fluctuations drawn from each env's generator: the same per seed, and the
    batched env equal to single envs (goal reaching draws these one Scenario at a time; the task
    envs in batches that give the same scenarios)."""
    kw = {
        "scenario": "random",
        "random_scenario": {
            "lifecycle": (400.0, 900.0),
            "birth_window": (-300.0, 300.0),
            "strength_variation": (0.1, 0.4),
        },
    }
    sync = gym.make_vec(env_id, num_envs=3, vectorization_mode="sync", **kw)
    native = gym.make_vec(env_id, num_envs=3, **kw)
    o1, _ = sync.reset(seed=9)
    o2, _ = native.reset(seed=9)
    assert np.array_equal(o1, o2)
    thermals = native.scenarios[0].field.thermals
    assert thermals and all(t.lifetime is not None and t.amplitude > 0 for t in thermals)
    rng = np.random.default_rng(2)
    for _ in range(25):
        a = _actions(sync.single_action_space, rng, 3)
        for x, y in zip(sync.step(a)[:4], native.step(a)[:4], strict=True):
            assert np.array_equal(x, y)
    a, b = gym.make_vec(env_id, num_envs=3, **kw), gym.make_vec(env_id, num_envs=3, **kw)
    a.reset(seed=9)
    b.reset(seed=9)
    assert a.scenarios == b.scenarios and a.scenarios[0].field.thermals == thermals
    b.reset(seed=10)
    assert b.scenarios[0] != a.scenarios[0]


def test_tasks_script_writes_replays_and_resumes(tmp_path, capsys) -> None:
    """A tiny task table end to end: the reference's plan replays bit for bit (checked inside),
    results.json / table.md / the figure are written, a rerun redoes nothing, bad input is refused."""
    import json

    from baselines.cli.tasks import main

    args = ["--envs", "soaring/ThermalClimbContinuous-v0", "soaring/CrossCountryContinuous-v0"]
    args += ["--scenarios", "1", "--beam-width", "20", "--agents", "reference", "random", "--workers", "1"]
    args += ["--out", str(tmp_path), "--no-progress"]
    assert main(args) == 0
    eps = json.loads((tmp_path / "results.json").read_text())["episodes"]
    assert len(eps) == 4 and {e["agent"] for e in eps} == {"reference", "random"}
    climb_ref = next(e for e in eps if e["agent"] == "reference" and "Climb" in e["env_id"])
    assert climb_ref["energy_gained"] == climb_ref["reference"]["predicted_energy"]
    assert (tmp_path / "table.md").read_text().count("\n") == 6
    assert (tmp_path / "trajectories.png").stat().st_size > 10_000
    capsys.readouterr()
    assert main(args) == 0
    assert "(4 done)" in capsys.readouterr().out
    val = tmp_path / "validation"
    assert main([*args[:-3], "--out", str(val), "--no-progress", "--split", "validation", "--envs", args[2]]) == 0
    names = {e["scenario"] for e in json.loads((val / "results.json").read_text())["episodes"]}
    assert names == {"xc-5000"} and not (val / "trajectories.png").exists()  # validation: no test scenario
    for bad in (["--scenarios", "0"], ["--envs", "soaring/Nope-v0"], ["--split", "test"]):
        with pytest.raises(SystemExit):
            main([*bad, "--out", str(tmp_path)])


def test_episode_steps_is_the_step_or_time_limit_whichever_ends_first() -> None:
    """``episode_steps``: goal reaching's 40 steps; a task's time limit over Ts (600 s / 30 s, 3600 s /
    10 s); a smaller ``max_steps`` wins; what the planners plan within (SST and the reference)."""
    assert gym.make("soaring/Soaring-v0").unwrapped.episode_steps == 40
    assert gym.make("soaring/Soaring-v0", max_steps=None).unwrapped.episode_steps is None
    climb = gym.make("soaring/ThermalClimb-v0").unwrapped
    assert climb.episode_steps == round(climb.config.time_limit / 30.0)
    xc = gym.make("soaring/CrossCountryContinuous-v0").unwrapped
    assert xc.episode_steps == round(xc.config.time_limit / xc.config.duration) == 360
    assert gym.make("soaring/CrossCountryContinuous-v0", max_steps=7).unwrapped.episode_steps == 7
    env = gym.make("soaring/CrossCountryContinuous-v0", max_steps=3)
    env.reset(seed=0)
    steps = 0
    while True:
        steps += 1
        *_, terminated, truncated, _ = env.step(np.zeros(3, np.float32))
        if terminated or truncated:
            break
    assert steps == 3 and truncated


def test_sst_flies_where_a_goal_exists_within_the_episode_and_deterministically() -> None:
    """The tasks table's SST: cross-country ids only, its iteration budget and configuration in the
    record's settings; on the physical envelope its seeding beams use a grid inside it; its plans
    stay within the env's steps (``episode_steps``), and a rerun flies the same episode."""
    from baselines.agents import SSTPlannerAgent
    from baselines.evaluation import run_episode
    from baselines.reference.beam import envelope_grid
    from baselines.tasks import TaskJob, markdown_table, task_jobs

    ids = ["soaring/ThermalClimbContinuous-v0", "soaring/CrossCountryContinuous-v0", "soaring/CrossCountry-v0"]
    jobs = task_jobs(ids, 1, ["sst", "random"], sst_iterations=5000)
    assert [(j.env_id, j.agent) for j in jobs] == [
        (ids[0], "random"),
        (ids[1], "sst"),
        (ids[1], "random"),
        (ids[2], "random"),  # SST_SKIPPED: no primitive plan within the battery exists
    ]
    row = {"env_id": ids[1], "agent": "sst", "episodes": 1, "no_plan": 0, "success": 1, "outcomes": {"goal": 1}}
    row |= {"energy_gained_median": (1.0, 1.0, 1.0), "fraction_of_reference_median": (math.nan,) * 3}
    row |= {"battery_left_median": 0.5, "circling_in_lift": 0.5}
    assert "SST does not fly `CrossCountry-v0`: no primitive plan" in markdown_table([row])
    s = jobs[1].settings()
    assert s["iterations"] == 5000 and s["planner"] == "seeded" and s["config"]["seed_width"] > 0
    assert s["battery_aware"] is True
    assert TaskJob(ids[1], "xc-10000", "sst", 0, sst_iterations=6000).settings() != s
    assert envelope_grid(gym.make(ids[1]).unwrapped.model)["speeds"][0] >= 12.0  # the physical envelope
    assert envelope_grid(gym.make("soaring/SoaringContinuous-v0").unwrapped.model) == {}  # the paper's
    sc = get_scenario("xc-10000")
    recs = []
    for _ in range(2):
        env = gym.make(ids[1], max_steps=4)
        agent = SSTPlannerAgent(time_limit=None, max_iterations=5000, name="sst")
        recs.append(run_episode(env, agent, sc, 0))
        assert agent.planner.plan_ is not None and len(agent.planner.plan_) <= 4
    assert recs[0]["decisions"] == 4 and recs[0]["truncated"]
    assert recs[0]["energy_spent"] == recs[1]["energy_spent"] and recs[0]["path"] == recs[1]["path"]


def test_sst_agent_plans_with_the_battery_left(monkeypatch: pytest.MonkeyPatch) -> None:
    """SSTAgent hands the cross-country env's battery left to the planner (None without a battery)."""
    import baselines.sst.agent as agent_mod
    from baselines.sst import SSTAgent

    seen: list = []
    real = agent_mod.plan_soaring

    def spy(*args, **kwargs):
        seen.append(kwargs["battery"])
        return real(*args, **kwargs)

    monkeypatch.setattr(agent_mod, "plan_soaring", spy)
    env = gym.make("soaring/CrossCountryContinuous-v0", max_steps=3)
    env.reset(seed=0)
    env.step(np.array([0.0, 0.0, 1.0], np.float32))  # a powered climb: the battery left is below the budget
    SSTAgent(env, time_limit=None, max_iterations=500).plan()
    assert seen == [env.unwrapped.battery_left] and 0.0 < seen[0] < env.unwrapped.battery
    env = gym.make("soaring/SoaringContinuous-v0", max_steps=3)
    env.reset(seed=0)
    SSTAgent(env, time_limit=None, max_iterations=500).plan()
    assert seen[1] is None


@pytest.mark.parametrize("env_id", ["soaring/ThermalClimb-v0", "soaring/CrossCountry-v0"])
def test_a_primitive_past_the_stall_limit_ends_the_episode(env_id: str) -> None:
    """The primitive task ids have a stall limit: flying a primitive the masks remove for it ends
    the episode ("stall", the crash penalty), in the single and the batched env alike; an allowed
    primitive flies on. Goal reaching (no stall limit) has no such outcome."""
    env = gym.make(env_id)
    env.reset(seed=3)
    stalls = ~env.unwrapped.model.stall_ok()
    masks = env.unwrapped.action_masks()
    bad, good = int(np.flatnonzero(stalls)[0]), int(np.flatnonzero(masks)[0])
    assert stalls.sum() == 69 and not masks[stalls].any()
    *_, terminated, _, info = env.step(bad)
    assert terminated and info["outcome"] == "stall" and info["reward_terms"]["stall"] == -25.0
    env.reset(seed=3)
    *_, terminated, _, info = env.step(good)
    assert not terminated and info["reward_terms"]["stall"] == 0.0
    vec = gym.make_vec(env_id, num_envs=2)
    vec.reset(seed=[3, 4])
    _, _, terminated, _, infos = vec.step(np.array([bad, good]))
    assert terminated.tolist() == [True, False] and list(infos["outcome"]) == ["stall", "flying"]
    goal = gym.make("soaring/Soaring-v0")
    goal.reset(seed=0)
    assert "stall" not in goal.step(0)[4]["reward_terms"]
