"""Evaluation harness: names are checked, runs are deterministic and resumable, reports are written."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import soaring_env  # noqa: F401  (registers the envs)
from baselines.agents import (
    Agent,
    HeuristicAgent,
    RandomAgent,
    SSTPlannerAgent,
    ThermallingAgent,
    action_mask_of,
    flattest_glide,
)
from baselines.evaluation import (
    AGENT_NAMES,
    CONTINUOUS_ID,
    DISCRETE_ID,
    EvalConfig,
    agent_spec,
    check_agent_name,
    check_scenario_name,
    circling_fractions,
    heldout_names,
    load_results,
    markdown_table,
    resolve_scenario,
    run_episode,
    run_evaluation,
    summarize,
    write_report,
)
from soaring_env._validation import ConfigError

#: Fields that depend on the machine's speed, not on the seeds.
TIMING = {"compute_total_s", "compute_plan_s", "compute_per_decision_s"}


def _strip(results: dict[str, Any]) -> list[dict[str, Any]]:
    return [{k: v for k, v in e.items() if k not in TIMING} for e in results["episodes"]]


# --- names ----------------------------------------------------------------------------------------------
def test_unknown_agent_is_refused_with_the_known_names() -> None:
    with pytest.raises(ConfigError, match=r"agent 'alphago' is unknown; known: sst-primitives, sst-continuous"):
        check_agent_name("alphago")
    with pytest.raises(ConfigError, match="heuristic"):
        EvalConfig(agents=("heuristic", "alphago"))


def test_unknown_scenario_is_refused_with_the_known_names() -> None:
    with pytest.raises(ConfigError, match=r"scenario 'moon' is unknown; known: paper, random-<seed>"):
        check_scenario_name("moon")
    with pytest.raises(ConfigError, match="paper"):
        EvalConfig(agents=("heuristic",), scenarios=("paper", "random-x"))
    assert check_scenario_name("random-10003") == "random-10003"


def _script(name: str) -> Any:
    """The command-line module behind ``scripts/<name>.py``."""
    return importlib.import_module(f"baselines.cli.{name}")


def test_evaluate_script_refuses_unknown_names(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    main = _script("evaluate").main
    assert main(["--agents", "nobody", "--out", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "agent 'nobody' is unknown; known:" in err and "random" in err
    assert main(["--agents", "random", "--scenarios", "atlantis", "--out", str(tmp_path), "--quiet"]) == 2
    assert "scenario 'atlantis' is unknown; known: paper" in capsys.readouterr().err


def test_ppo_agent_without_a_model_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="needs a trained model"):
        agent_spec("ppo-masked", EvalConfig(agents=("ppo-masked",)))
    with pytest.raises(ConfigError, match="no trained model"):
        agent_spec("ppo-masked", EvalConfig(agents=("ppo-masked",), ppo_dirs={"ppo-masked": str(tmp_path)}))


def test_rollout_agent_is_opt_in_checked_and_evaluated(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``ppo-discrete-rollout`` (docs/learning-to-soar.md, round twenty-one): its candidate count is checked and
    recorded with its episodes (a change redoes them on resume); a run that is not a successor
    policy is refused; ``scripts/evaluate.py`` flies it (committed run ``a3-s0``) and never picks
    a run directory up for it by default."""
    run = str(Path(__file__).resolve().parents[1] / "results" / "ppo-score" / "a3-s0" / "discrete")
    name = "ppo-discrete-rollout"
    for bad in (0, True, 2.5, "8"):
        with pytest.raises(ConfigError, match="rollout_candidates"):
            EvalConfig(agents=(name,), ppo_dirs={name: run}, rollout_candidates=bad)  # type: ignore[arg-type]
    spec = agent_spec(name, EvalConfig(agents=(name,), ppo_dirs={name: run}, ppo_model="final", rollout_candidates=3))
    assert spec.settings["rollout_candidates"] == 3
    other = tmp_path / "other"
    other.mkdir()
    cfg = json.loads((Path(run) / "config.json").read_text())
    cfg["config"]["policy"] = "mlp"
    (other / "config.json").write_text(json.dumps(cfg))
    (other / "model.zip").write_bytes((Path(run) / "model.zip").read_bytes())
    with pytest.raises(ConfigError, match="needs a successor policy"):
        agent_spec(name, EvalConfig(agents=(name,), ppo_dirs={name: str(other)}, ppo_model="final"))
    main = _script("evaluate").main
    out = tmp_path / "ev"
    argv = ["--agents", "ppo-discrete", name, "--scenarios", "random-10", "--seeds", "0", "--ppo-model", "final"]
    argv += ["--ppo-dir", f"ppo-discrete={run}", "--ppo-dir", f"{name}={run}", "--out", str(out), "--quiet"]
    assert main([*argv, "--rollout-candidates", "4"]) == 0
    eps = {e["agent"]: e for e in load_results(out)["episodes"]}
    assert eps[name]["success"] and eps[name]["energy_spent"] <= eps["ppo-discrete"]["energy_spent"]
    assert main([*argv, "--rollout-candidates", "0"]) == 2
    assert "rollout_candidates=0" in capsys.readouterr().err
    root = tmp_path / "root"
    (root / "discrete").mkdir(parents=True)
    for f in ("config.json", "model.zip"):
        (root / "discrete" / f).write_bytes((Path(run) / f).read_bytes())
    argv = ["--scenarios", "paper", "--seeds", "0", "--ppo-root", str(root), "--ppo-model", "final"]
    argv += ["--sst-budget", "none", "--sst-iterations", "20", "--out", str(tmp_path / "all"), "--quiet"]
    assert main(argv) == 0  # every agent by default: the run is picked up as ppo-discrete only
    ran = {e["agent"] for e in load_results(tmp_path / "all")["episodes"]}
    assert "ppo-discrete" in ran and name not in ran
    assert main(["--list"]) == 0 and name in capsys.readouterr().out


def test_heldout_scenarios_are_seeded_and_named() -> None:
    names = heldout_names(3)
    assert names == ["random-10000", "random-10001", "random-10002"]
    a, b = resolve_scenario(names[1]), resolve_scenario(names[1])
    assert a == b and a.name == "random-10001"
    assert resolve_scenario(names[0]) != a
    assert resolve_scenario("paper").name == "paper"


# --- agents ---------------------------------------------------------------------------------------------
def test_agents_follow_the_protocol() -> None:
    for agent in (RandomAgent(), HeuristicAgent(), SSTPlannerAgent(max_iterations=10)):
        assert isinstance(agent, Agent)
    assert set(AGENT_NAMES) >= {"sst-primitives", "sst-continuous", "heuristic", "random", "ppo-masked"}


def test_random_agent_is_seeded_and_respects_masks() -> None:
    env = gym.make(DISCRETE_ID)
    sc = resolve_scenario("paper").replace(start=(0.0, 0.0, 0.0, 60.0))  # low: many primitives crash
    env.reset(seed=0, options={"scenario": sc})
    mask = action_mask_of(env)
    assert mask is not None and 0 < mask.sum() < mask.size
    a, b = RandomAgent(), RandomAgent()
    a.reset(env, 7)
    b.reset(env, 7)
    acts = [int(a.predict(None)[0]) for _ in range(50)]
    assert acts == [int(b.predict(None)[0]) for _ in range(50)]
    assert all(mask[i] for i in acts)
    cont = gym.make(CONTINUOUS_ID)
    cont.reset(seed=0)
    a.reset(cont, 1)
    act, _ = a.predict(None)
    assert cont.action_space.contains(act)


@pytest.mark.parametrize("env_id", [DISCRETE_ID, CONTINUOUS_ID])
def test_heuristic_reaches_the_goal_of_the_paper_scenario(env_id: str) -> None:
    env = gym.make(env_id)
    agent = HeuristicAgent()
    rec = run_episode(env, agent, resolve_scenario("paper"), seed=0)
    assert rec["success"] and rec["outcome"] == "goal"
    assert 0.0 < rec["energy_spent"] < 10_000.0
    assert rec["flight_time"] == pytest.approx(30.0 * rec["decisions"])
    assert rec["path"][0] == [0.0, 0.0, 300.0]


def test_heuristic_circles_in_lift() -> None:
    env = gym.make(DISCRETE_ID)
    sc = resolve_scenario("paper")
    th = sc.field.thermals[0]
    # Start in the thermal's core, low, with the goal far away: the rule must circle (a spiral).
    sc = sc.replace(start=(th.north, th.east, 0.0, 300.0))
    env.reset(seed=0, options={"scenario": sc})
    agent = HeuristicAgent()
    agent.reset(env, 0)
    v, turn, gamma = agent.intent()
    assert v == 10.0
    assert abs(turn) >= 2 * np.pi - 1e-9 and gamma == 0.0
    action, _ = agent.predict(None)
    assert "spiral" in env.unwrapped.model.library.describe(int(action))


def _still_air(start_height: float, wind_north: float = 0.0) -> Any:
    """The paper scenario without its thermals (3 km to the goal at 300 m, radius 150 m), from ``start_height``."""
    from soaring_env.physics import WindField

    sc = resolve_scenario("paper")
    field = WindField(zi=sc.field.zi, wind_north=wind_north)
    return sc.replace(field=field, start=(0.0, 0.0, 0.0, start_height))


def test_heuristic_glides_at_zero_thrust_where_the_glide_reaches() -> None:
    """From 400 m the flattest glide reaches the goal region 3 km away: the continuous heuristic flies
    it at the best-L/D airspeed without the motor and without a speed change, so every edge costs
    exactly the height it loses, g dh."""
    env = gym.make(CONTINUOUS_ID)
    obs, _ = env.reset(seed=0, options={"scenario": _still_air(400.0)})
    agent = HeuristicAgent()
    agent.reset(env, 0)
    v_best, glide = flattest_glide(env.unwrapped.model)
    done, steps, info = False, 0, {}
    while not done:
        v, turn, gamma = agent.intent()
        assert (v, turn, gamma) == (v_best, 0.0, glide)
        obs, _, terminated, truncated, info = env.step(agent.predict(obs)[0])
        done, steps = terminated or truncated, steps + 1
        assert info["fuel"] == 0.0 and info["kinetic"] == 0.0
        assert info["edge_cost"] == pytest.approx(info["potential"], rel=1e-12)
    assert info["is_success"] and steps == 7  # 3 km less the region's radius at 15.5 m/s, 30 s a step


@pytest.mark.parametrize("env_id", [DISCRETE_ID, CONTINUOUS_ID])
def test_heuristic_arrives_low_where_the_motor_must_help(env_id: str) -> None:
    """From 200 m, below the region (150-450 m) less the glide's loss, the motor has to help: the rule
    aims at the region's lower part (a metre climbed under power costs 1 / eta of its potential
    energy) and never higher than the start, and it spends less than the v1 rule's fast cruise to
    the upper half did (2.3-2.8 kJ/kg on the paper scenario)."""
    env = gym.make(env_id)
    rec = run_episode(env, HeuristicAgent(), _still_air(200.0), seed=0)
    assert rec["success"]
    assert 150.0 < rec["final_height"] <= 200.0 + 1e-6
    assert rec["energy_spent"] < 2_000.0


def test_heuristic_climbs_only_to_the_glide_into_the_goal() -> None:
    """:meth:`HeuristicAgent.climb_useful` in closed form: a climb pays below the height from which
    the cruise reaches the region's top (goal height + ARRIVE x radius) -- at the flattest glide on
    the continuous env, level on the primitives -- and not above it."""
    from baselines.agents import ARRIVE

    for env_id in (DISCRETE_ID, CONTINUOUS_ID):
        env = gym.make(env_id)
        model_env: Any = env.unwrapped
        env.reset(seed=0, options={"scenario": _still_air(300.0)})
        slope = 0.0 if env_id == DISCRETE_ID else -math.tan(flattest_glide(model_env.model)[1])
        need = 300.0 + ARRIVE * 150.0 + slope * (3000.0 - 150.0)
        for h, useful in ((need - 1.0, True), (need + 1.0, False)):
            env.reset(seed=0, options={"scenario": _still_air(h)})
            agent = HeuristicAgent()
            agent.reset(env, 0)
            assert agent.climb_useful() is useful, (env_id, h, need)


@pytest.mark.parametrize("wind", [-6.0, 6.0])
def test_heuristic_flies_faster_into_a_headwind(wind: float) -> None:
    """The speed to fly: into a headwind faster than the best-L/D airspeed (each second in the air
    costs more ground), with a tailwind slower."""
    env = gym.make(CONTINUOUS_ID)
    env.reset(seed=0, options={"scenario": _still_air(400.0, wind_north=wind)})  # the goal lies north
    agent = HeuristicAgent()
    agent.reset(env, 0)
    v, _, _ = agent.cruise()
    v_still = flattest_glide(env.unwrapped.model)[0]
    assert (v > v_still) if wind < 0 else (v < v_still)


def test_heuristic_settings_key_the_records() -> None:
    """The heuristic's records are keyed by its rule's version, the thermalling agent's by its cruise's too."""
    assert HeuristicAgent().settings() == {"rule": HeuristicAgent.RULE}
    assert ThermallingAgent().settings()["cruise"] == HeuristicAgent.RULE


def _climb_on_a_thermal(offset: float = 40.0, wind_north: float = 0.0) -> tuple[gym.Env, Any]:
    """The thermal-climb env on a scenario with one thermal ``offset`` m north of the start."""
    from soaring_env.physics import Thermal, WindField
    from soaring_env.scenario import Bounds, Scenario

    thermal = Thermal(north=offset, east=0.0, strength=3.0)
    field = WindField(thermals=(thermal,), model="allen", zi=1400.0, wind_north=wind_north)
    sc = Scenario(
        name="one-thermal",
        field=field,
        start=(0.0, 0.0, 0.0, 400.0),
        goal=None,
        bounds=Bounds(-3000.0, 3000.0, -3000.0, 3000.0, 1500.0),
    )
    env = gym.make("soaring/ThermalClimbContinuous-v0", scenario=sc)
    env.reset(seed=0)
    return env, sc


def test_thermalling_agent_senses_lift_only_where_it_flew() -> None:
    """It reads the field only at flown points at the times it passed them, finds the thermal's
    centre by a Gaussian fitted to its log, circles there and climbs."""
    env, sc = _climb_on_a_thermal()
    base: Any = env.unwrapped
    queried: list[tuple[float, float, float]] = []
    real = type(sc.field).updraft

    def spy(self: Any, n: Any, e: Any, h: Any, t: Any) -> Any:
        pts = zip(np.atleast_1d(n).tolist(), np.atleast_1d(e).tolist(), np.atleast_1d(h).tolist(), strict=True)
        queried.extend(pts)
        return real(self, n, e, h, t)

    agent = ThermallingAgent()
    agent.reset(env, 0)
    obs = None
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(type(sc.field), "updraft", spy)
        for _ in range(40):
            n0 = len(queried)
            action, _ = agent.predict(obs)
            flown = {tuple(np.round(p[[0, 1, 3]], 9)) for p in np.asarray(base.path)}
            assert all(tuple(np.round(q, 9)) in flown for q in queried[n0:])  # only points it flew through
            obs, *_ = env.step(action)
    centre = agent.centre()
    assert centre is not None and np.hypot(centre[0] - 40.0, centre[1]) < 25.0
    assert base.state[3] > 400.0  # it climbed
    circling, in_lift = circling_fractions(base)
    assert circling > 0.8 and in_lift > 0.8


@given(
    w=st.floats(0.5, 5.0),
    r=st.floats(30.0, 120.0),
    cn=st.floats(-60.0, 60.0),
    ce=st.floats(-60.0, 60.0),
)
@settings(max_examples=40, deadline=None)
def test_gaussian_thermal_fit_recovers_the_thermal(w: float, r: float, cn: float, ce: float) -> None:
    """Noise-free lift of a Gaussian thermal sampled on two 25 m circles 40 m apart (an orbit that
    walked), some sample within R of its centre: the fit, started at the samples' lift-weighted
    centroid with R guessed 60 m, recovers W, the centre and R -- also where the centre lies outside
    the flown circles, which the centroid cannot leave. (Sampled only in its far tail, beyond about
    1.3 R, a thermal is not always recovered.)"""
    from baselines.agents import fit_gaussian_thermal

    a = np.linspace(0.0, 2.0 * np.pi, 40, endpoint=False)
    n = np.concatenate([25.0 * np.cos(a), 5.0 + 25.0 * np.cos(a)])
    e = np.concatenate([25.0 * np.sin(a), 40.0 + 25.0 * np.sin(a)])
    assume(float(np.hypot(n - cn, e - ce).min()) < r)
    lift = w * np.exp(-((n - cn) ** 2 + (e - ce) ** 2) / r**2)
    weight = lift - lift.min()
    start = float(weight @ n / weight.sum()), float(weight @ e / weight.sum())
    fit = fit_gaussian_thermal(n, e, lift, start, 60.0)
    assert fit is not None
    assert fit[0] == pytest.approx(w, rel=1e-3)
    assert math.hypot(fit[1] - cn, fit[2] - ce) < 0.1
    assert fit[3] == pytest.approx(r, rel=1e-3)


def test_gaussian_thermal_fit_refuses_bad_samples() -> None:
    """Unequal or too few samples, NaN, strings and a radius <= 0: a ConfigError naming what is wrong."""
    from baselines.agents import fit_gaussian_thermal

    ok = np.zeros(5)
    for args, match in (
        ((ok, ok[:4], ok, (0.0, 0.0), 60.0), "as many samples"),
        ((ok[:2], ok[:2], ok[:2], (0.0, 0.0), 60.0), "at least 3"),
        ((ok, ok, np.full(5, np.nan), (0.0, 0.0), 60.0), "finite"),
        ((ok, ok, ["a"] * 5, (0.0, 0.0), 60.0), "numbers"),
        ((ok, ok, ok, (0.0, 0.0), 0.0), "radius"),
    ):
        with pytest.raises(ConfigError, match=match):
            fit_gaussian_thermal(*args)


def test_thermalling_agent_finds_and_works_the_core_in_wind() -> None:
    """Entering 60 m beside a thermal in a 3 m/s wind (the aircraft drifts 15 m a step, the thermal
    stays), it fits the centre to within 10 m, keeps circling and climbs 300 m in 300 s."""
    env, _ = _climb_on_a_thermal(offset=60.0, wind_north=3.0)
    base: Any = env.unwrapped
    agent = ThermallingAgent()
    agent.reset(env, 0)
    h0 = float(base.state[3])
    for _ in range(60):
        action, _ = agent.predict(None)
        env.step(action)
    centre = agent.centre()
    assert agent._circling and centre is not None
    assert math.hypot(centre[0] - 60.0, centre[1]) < 10.0
    assert float(base.state[3]) > h0 + 300.0


def test_thermalling_circles_the_way_a_shadowed_policy_turns() -> None:
    """Shadowing a policy that circles the other way round (a DAgger round), the controller takes
    that way from the flown path instead of commanding the circle reversed; flying itself, every
    circling edge turns its own way round, so its own episodes are unchanged by that rule."""
    env, _ = _climb_on_a_thermal()
    own = ThermallingAgent()
    own.reset(env, 0)
    actions, entered = [], None
    for k in range(30):
        action, _ = own.predict(None)
        if own._circling:
            entered = k if entered is None else entered
            turned = own._edge_turn()
            assert k == entered or np.sign(turned) == own._side  # the path turns its own way round
        actions.append(action)
        env.step(action)
    assert entered is not None and entered < 10
    side = own._side
    env.reset(seed=0)
    shadow = ThermallingAgent()
    shadow.reset(env, 0)
    mirrored = [np.array([a[0], -a[1], a[2]], dtype=np.float32) for a in actions[entered + 1 : entered + 4]]
    flown = actions[: entered + 1] + mirrored  # it enters as itself, then the policy circles the other way
    for action in flown:
        shadow.predict(None)
        env.step(action)
    action, _ = shadow.predict(None)
    assert shadow._circling and shadow._side == -side
    assert np.sign(action[1]) == -side


def test_thermalling_search_spiral_turns_one_way() -> None:
    """Without lift the search follows its spiral by pure pursuit two steps ahead: every turn after
    the first step goes the same way round (aiming one step ahead zigzagged)."""
    env, _ = _climb_on_a_thermal(offset=2500.0)  # nothing within reach
    agent = ThermallingAgent()
    agent.reset(env, 0)
    turns = []
    for _ in range(40):
        _, turn, _ = agent.intent()
        action, _ = agent.predict(None)
        env.step(action)
        turns.append(turn)
    signs = {float(np.sign(t)) for t in turns[2:] if abs(t) > 1e-6}
    assert len(signs) == 1


def test_thermalling_arm_search_is_a_function_of_the_position() -> None:
    """``search="arm"`` takes the spiral's phase from the aircraft's position, ``search="time"``
    its radius from the flight time: an agent that has searched for 20 steps and a fresh one
    command the same from the same state, where the default spiral (its own phase) does not; all
    turn one way; the time search flies out at the radius r = sqrt(spacing v t / pi) within one
    spacing; bad values raise."""
    env, sc = _climb_on_a_thermal(offset=2500.0)  # nothing within reach
    commands = {}
    for search in ("spiral", "arm", "time"):
        env.reset(seed=0)
        flown = ThermallingAgent(search=search)
        flown.reset(env, 0)
        turns = []
        for _ in range(20):
            action, _ = flown.predict(None)
            turns.append(flown.intent()[1])
            env.step(action)
        fresh = ThermallingAgent(search=search)
        fresh.reset(env, 0)
        commands[search] = (flown.intent(), fresh.intent())
        assert len({float(np.sign(t)) for t in turns[2:] if abs(t) > 1e-6}) == 1
        if search == "time":
            base: Any = env.unwrapped
            v = flattest_glide(base.model)[0]
            r_t = math.sqrt(flown.search_spacing * v * float(base.time) / math.pi)
            r = math.hypot(float(base.state[0]) - sc.start[0], float(base.state[1]) - sc.start[1])
            assert abs(r - r_t) < flown.search_spacing, (r, r_t)
    assert commands["arm"][0] == commands["arm"][1] and commands["time"][0] == commands["time"][1]
    assert commands["spiral"][0] != commands["spiral"][1]
    assert ThermallingAgent(search="arm").settings()["search"] == "arm"
    assert "search" not in ThermallingAgent().settings()  # the default's records stay current
    for bad in ("ring", 1, None):
        with pytest.raises(ConfigError, match="search"):
            ThermallingAgent(search=bad)  # type: ignore[arg-type]


def test_thermalling_sensor_noise_is_seeded_and_single_peaks_do_not_enter() -> None:
    """``sensor_noise`` is drawn from the reset's seed (same seed, same episode; another seed, another);
    without it the log is the field's exact lift; the entry test averages ``entry_samples`` samples, so
    one noisy peak of 0.5 m/s among zeros does not start a circle, where the single-sample test would."""
    env, _ = _climb_on_a_thermal(offset=2500.0)  # nothing within reach: only noise
    base: Any = env.unwrapped

    def fly(agent: ThermallingAgent, seed: int) -> list[Any]:
        env.reset(seed=0)
        agent.reset(env, seed)
        acts = []
        for _ in range(15):
            action, _ = agent.predict(None)
            env.step(action)
            acts.append(np.asarray(action).tolist())
        return acts

    noisy = ThermallingAgent(sensor_noise=0.3)
    assert fly(noisy, 7) == fly(noisy, 7)
    assert fly(noisy, 7) != fly(noisy, 8)
    env2, sc2 = _climb_on_a_thermal(offset=40.0)  # in lift: the samples are the field's, or not
    for agent in (ThermallingAgent(), ThermallingAgent(sensor_noise=0.3)):
        env2.reset(seed=0)
        agent.reset(env2, 0)
        env2.step(agent.predict(None)[0])
        edge = np.asarray(agent._last_edge())
        exact = sc2.field.updraft(edge[:, 0], edge[:, 1], np.asarray(env2.unwrapped.path)[-10:, 3], edge[:, 2])
        assert np.array_equal(edge[:, 3], exact) == (agent.sensor_noise == 0.0)
    exact = ThermallingAgent()
    spike = [(0.0, 10.0 * i, 0.0, 0.5 if i == 4 else 0.0) for i in range(10)]
    assert exact._smoothed(spike).max() < exact.enter_lift
    assert ThermallingAgent(entry_samples=1)._smoothed(spike).max() >= exact.enter_lift
    assert base.steps == 15


def test_thermalling_entry_now_reads_the_lift_at_the_aircraft() -> None:
    """``entry="now"`` decides entering on the edge's last sample alone, the lift at the aircraft: a
    peak earlier on the edge does not enter (the default's smoothed edge does), lift where the
    aircraft is does; the setting keys the records only when not the default; bad values raise."""
    now, edge_rule = ThermallingAgent(entry="now"), ThermallingAgent()
    edge = [(0.0, float(k), float(k), w) for k, w in enumerate([0.0, 0.5, 0.5, 0.5, 0.0])]
    assert now._smoothed(edge).max() < now.enter_lift <= edge_rule._smoothed(edge).max()
    edge[-1] = (0.0, 4.0, 4.0, 0.3)
    assert now._smoothed(edge).max() >= now.enter_lift
    assert now.settings()["entry"] == "now" and "entry" not in edge_rule.settings()
    for bad in ("peak", 0):
        with pytest.raises(ConfigError, match="entry"):
            ThermallingAgent(entry=bad)  # type: ignore[arg-type]


def test_thermalling_settings_key_the_records() -> None:
    """The records key the agent by its rule and every setting: a changed default flies again."""
    a, b = ThermallingAgent().settings(), ThermallingAgent(radius=30.0).settings()
    assert a["rule"] == ThermallingAgent.RULE and a["radius"] == 25.0
    assert a != b and json.loads(json.dumps(a)) == a
    with pytest.raises(ConfigError, match="entry_samples"):
        ThermallingAgent(entry_samples=0)
    with pytest.raises(ConfigError, match="sensor_noise"):
        ThermallingAgent(sensor_noise=-0.1)


def test_thermalling_climb_needs_time_to_reach_the_goal() -> None:
    """With a goal and a time limit a climb is useful only while the goal can still be reached at the
    slowest airspeed, in the wind, with half as much time again to spare."""
    sc = resolve_scenario("paper")
    env = gym.make(CONTINUOUS_ID)
    env.reset(seed=0, options={"scenario": sc})
    agent = ThermallingAgent()
    agent.reset(env, 0)
    base: Any = env.unwrapped
    assert base.episode_steps is not None and agent.climb_useful()
    base.steps = base.episode_steps - 1  # one step left: the goal is kilometres away
    assert not agent.climb_useful()


def test_circling_fractions_closed_forms() -> None:
    """A level spiral all episode is all circling; a straight glide none; lift needs an updraft."""
    env, _ = _climb_on_a_thermal(offset=2000.0)  # the thermal is far away: no lift here
    base: Any = env.unwrapped
    straight = base.model.control_to_action(np.array([15.0, 0.0, 0.0])).astype(np.float32)
    for _ in range(6):
        env.step(straight)
    assert circling_fractions(base) == (0.0, 0.0)
    env.reset(seed=0)
    turn = base.model.control_to_action(np.array([15.0, 0.3, 0.0])).astype(np.float32)  # 17 deg/s
    for _ in range(6):
        env.step(turn)
    assert circling_fractions(base) == (1.0, 0.0)
    env2, _ = _climb_on_a_thermal(offset=0.0)
    b2: Any = env2.unwrapped
    for _ in range(6):
        env2.step(b2.model.control_to_action(np.array([13.0, 0.3, 0.0])).astype(np.float32))  # 43 m circles
    assert circling_fractions(b2) == (1.0, 1.0)


# --- runs -----------------------------------------------------------------------------------------------
def _small_config(**kw: Any) -> EvalConfig:
    base: dict[str, Any] = {
        "agents": ("sst-primitives", "sst-continuous", "heuristic", "heuristic-continuous", "random"),
        "scenarios": ("paper", "random-10000"),
        "seeds": (0, 1),
        "sst_time_budget": None,  # an iteration budget alone: deterministic plans
        "sst_iterations": 300,
    }
    base.update(kw)
    return EvalConfig(**base)


def test_evaluation_is_deterministic_for_fixed_seeds(tmp_path: Path) -> None:
    cfg = _small_config()
    r1 = run_evaluation(cfg, tmp_path / "a", resume=False)
    r2 = run_evaluation(cfg, tmp_path / "b", resume=False)
    assert len(r1["episodes"]) == 5 * 2 * 2
    assert _strip(r1) == _strip(r2)
    # Non-trivial: the planners and the heuristic solve these; the random agent's seeds matter.
    assert all(e["success"] for e in r1["episodes"] if e["agent"] != "random")
    rand = [e for e in r1["episodes"] if e["agent"] == "random" and e["scenario"] == "paper"]
    assert rand[0]["path"] != rand[1]["path"]
    # The results file on disk is what was returned.
    assert _strip(load_results(tmp_path / "a")) == _strip(r1)


def test_every_agent_is_scored_through_env_step(tmp_path: Path) -> None:
    """The recorded energy and flight time are the env's own (info / unwrapped.time)."""
    res = run_evaluation(_small_config(seeds=(0,)), tmp_path, resume=False)
    for e in res["episodes"]:
        assert e["flight_time"] == pytest.approx(30.0 * e["decisions"])
        assert e["terminated"] or e["truncated"]
        assert e["env_id"] == (CONTINUOUS_ID if e["agent"].endswith("continuous") else DISCRETE_ID)
        assert e["compute_total_s"] >= e["compute_plan_s"] >= 0.0
        assert len(e["path"]) >= e["decisions"] + 1


def test_evaluation_resumes(tmp_path: Path) -> None:
    cfg = _small_config(agents=("heuristic", "random"), seeds=(0,))
    first = run_evaluation(cfg, tmp_path)
    more = run_evaluation(_small_config(agents=("heuristic", "random"), seeds=(0, 3)), tmp_path)
    assert len(more["episodes"]) == 2 * 2 * 2
    old = {(e["agent"], e["scenario"], e["seed"]): e for e in first["episodes"]}
    for e in more["episodes"]:
        k = (e["agent"], e["scenario"], e["seed"])
        if k in old:  # reused, not re-run: even the timings are identical
            assert e == old[k]
    data = json.loads((tmp_path / "results.json").read_text())
    assert len(data["episodes"]) == 8
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary files


def test_report_table_and_plots(tmp_path: Path) -> None:
    res = run_evaluation(_small_config(seeds=(0,)), tmp_path, resume=False)
    rows = {r["agent"]: r for r in summarize(res)}
    assert rows["sst-primitives"]["energy_ratio"] == pytest.approx(1.0)
    assert rows["sst-continuous"]["common"] == 2
    assert rows["random"]["episodes"] == 2
    table = markdown_table(res)
    assert table.startswith("| agent | success |")
    for a in ("sst-primitives", "sst-continuous", "heuristic", "heuristic-continuous", "random"):
        assert f"| {a} |" in table
    files = write_report(res, tmp_path)
    for f in files:
        assert f.is_file() and f.stat().st_size > 0
    assert {f.name for f in files} == {"results.md", "boxplots.png", "trajectories.png"}


def test_every_episode_carries_its_regret(tmp_path: Path) -> None:
    from baselines.evaluation import attach_regret, bootstrap_ci
    from baselines.reference import SamplerReference, ScenarioReference

    cfg = _small_config(agents=("heuristic", "heuristic-continuous", "random"), seeds=(0, 1))
    scen = {name: resolve_scenario(name) for name in cfg.scenarios}

    def ref(best: float, direct: float) -> SamplerReference:
        return SamplerReference(best, direct, [], [], 0.0, {}, 0, 0.0)

    refs = {
        name: ScenarioReference(sc, -1500.0, {"primitive": ref(-1000.0, 2000.0), "continuous": ref(-500.0, 1500.0)})
        for name, sc in scen.items()
    }
    res = run_evaluation(cfg, tmp_path, resume=False, references=refs)
    on_disk = load_results(tmp_path)
    for ep in res["episodes"]:
        if not ep["success"]:
            assert ep["regret"] is None
            continue
        best, direct = (-1000.0, 2000.0) if ep["env_id"] == DISCRETE_ID else (-500.0, 1500.0)
        assert ep["regret"] == pytest.approx((ep["energy_spent"] - best) / (direct - best))
    assert [e["regret"] for e in on_disk["episodes"]] == [e["regret"] for e in res["episodes"]]
    rows = {r["agent"]: r for r in summarize(res)}
    h = rows["heuristic"]
    regs = [e["regret"] for e in res["episodes"] if e["agent"] == "heuristic" and e["regret"] is not None]
    assert h["regret_median"][0] == pytest.approx(float(np.median(regs)))
    assert h["regret_median"][1] <= h["regret_median"][0] <= h["regret_median"][2]
    assert "regret, median [95 % CI]" in markdown_table(res)
    # the median of all episodes counts a failure as unbounded regret (every scenario has a reference)
    for agent, row in rows.items():
        mine = [e for e in res["episodes"] if e["agent"] == agent]
        allr = [e["regret"] if e["success"] else math.inf for e in mine]
        assert row["regret_all_n"] == len(mine)
        assert row["regret_all_median"][0] == float(np.median(allr))
        lo, mid, hi = row["regret_all_median"][1], row["regret_all_median"][0], row["regret_all_median"][2]
        assert not math.isnan(lo) and not math.isnan(hi) and lo <= mid <= hi
    assert any(not e["success"] for e in res["episodes"] if e["agent"] == "random")
    assert "median of all episodes (failure = inf)" in markdown_table(res)
    ci = bootstrap_ci([0.1, 0.2, math.inf, math.inf, math.inf], np.median)
    assert ci[0] == math.inf and ci[1] <= ci[2] and not any(math.isnan(x) for x in ci)
    # a reference made for another scenario is not used
    other = {n: ScenarioReference(resolve_scenario("random-5"), r.lower_bound, r.samplers) for n, r in refs.items()}
    assert all(e["regret"] is None for e in attach_regret(res, other)["episodes"])
    assert bootstrap_ci([], np.median)[0] != bootstrap_ci([], np.median)[0]  # NaN for no data
    assert bootstrap_ci([1.0, 2.0, 3.0], np.mean) == bootstrap_ci([1.0, 2.0, 3.0], np.mean)  # seeded
