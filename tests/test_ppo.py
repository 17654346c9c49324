"""PPO baselines: a tiny run trains, saves, loads and evaluates end to end; wrappers and config."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

import soaring_env  # noqa: F401  (registers the envs)
from baselines.agents import Agent, PPOAgent
from baselines.evaluation import EvalConfig, resolve_scenario, run_evaluation
from baselines.ppo import (
    ALGOS,
    CONTINUOUS_ID,
    DISCRETE_ID,
    TASKS,
    BodyFrame,
    BodyFrameObservation,
    FinalGlide,
    GoalDistanceShaping,
    ScenarioCycle,
    TrainConfig,
    body_frame,
    plot_learning_curve,
    train,
    turn_curve,
    validation_scenarios,
)
from soaring_env._validation import ConfigError

TIMING = {"compute_total_s", "compute_plan_s", "compute_per_decision_s"}


def _tiny(algo: str) -> TrainConfig:
    return TrainConfig(
        algo=algo,
        total_timesteps=1024,
        n_envs=2,
        n_steps=128,
        batch_size=64,
        n_epochs=2,
        eval_freq=512,
        n_eval_scenarios=3,
        checkpoint_freq=512,
        progress_bar=False,
    )


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One tiny run per algorithm (a few seconds each)."""
    root = tmp_path_factory.mktemp("ppo")
    return {algo: train(_tiny(algo), root / algo) for algo in ALGOS}


@pytest.mark.parametrize("algo", list(ALGOS))
def test_tiny_run_writes_the_run_directory(trained: dict[str, Path], algo: str) -> None:
    out = trained[algo]
    for name in ("model.zip", "best_model.zip", "config.json", "eval_log.json", "evaluations.npz"):
        assert (out / name).is_file(), name
    assert (out / "learning_curve.png").stat().st_size > 0
    assert list((out / "checkpoints").glob("*.zip"))
    rec = json.loads((out / "config.json").read_text())
    assert rec["status"] == "done" and rec["algo"] == algo and rec["env_id"] == ALGOS[algo]
    assert rec["timesteps_done"] >= 1024
    # The saved configuration is exactly the one trained with.
    assert TrainConfig.from_dict(rec["config"]) == _tiny(algo)
    log = json.loads((out / "eval_log.json").read_text())
    assert [r["timesteps"] for r in log] == [512, 1024]
    assert all(0.0 <= r["success_rate"] <= 1.0 for r in log)


@pytest.mark.parametrize("algo", list(ALGOS))
def test_trained_agent_acts_through_the_agent_interface(trained: dict[str, Path], algo: str, tmp_path: Path) -> None:
    agent = PPOAgent(trained[algo])
    assert isinstance(agent, Agent) and agent.name == f"ppo-{algo}"
    env = gym.make(agent.env_id)
    obs, _ = env.reset(seed=0, options={"scenario": resolve_scenario("paper")})
    agent.reset(env, 0)
    action, state = agent.predict(obs)
    assert state is None and env.action_space.contains(action)
    if algo == "masked":
        assert env.unwrapped.action_masks()[int(action)]
    # End to end through the evaluation, twice: deterministic for fixed seeds.
    name = f"ppo-{algo}"
    cfg = EvalConfig(agents=(name,), scenarios=("paper", "random-10000"), seeds=(0,), ppo_dirs={name: trained[algo]})
    r1 = run_evaluation(cfg, tmp_path / "a", resume=False)
    r2 = run_evaluation(cfg, tmp_path / "b", resume=False)
    strip = [[{k: v for k, v in e.items() if k not in TIMING} for e in r["episodes"]] for r in (r1, r2)]
    assert strip[0] == strip[1] and len(strip[0]) == 2
    assert all(e["decisions"] >= 1 for e in r1["episodes"])


def test_train_config_validation() -> None:
    with pytest.raises(ValueError, match="algo='sac' is unknown; known: discrete, masked, continuous"):
        TrainConfig(algo="sac")
    with pytest.raises(ValueError, match="scenario"):
        TrainConfig(env_kwargs={"scenario": "paper"})
    with pytest.raises(ValueError, match="vec_env"):
        TrainConfig(vec_env="ray")


def test_goal_shaping_is_potential_based() -> None:
    """With gamma = 1 the shaping telescopes to phi(s_T) - phi(s_0) = d_0 / scale on termination."""
    env = GoalDistanceShaping(gym.make(DISCRETE_ID), weight=1.0, gamma=1.0)
    env.reset(seed=0)
    d0 = float(np.linalg.norm(env.unwrapped.scenario.start_state[[0, 1, 3]] - env.unwrapped.scenario.goal.centre))
    total = 0.0
    for _ in range(100):
        _, _, terminated, truncated, info = env.step(2)  # straight and level, slow
        total += info["shaping"]
        if terminated or truncated:
            break
    assert terminated
    assert total == pytest.approx(d0 / 1000.0)


def test_scenario_cycle_and_validation_set() -> None:
    scs = validation_scenarios(3)
    assert [s.name for s in scs] == ["random-5000", "random-5001", "random-5002"]
    env = ScenarioCycle(gym.make(DISCRETE_ID), scs)
    seen = []
    for _ in range(4):
        env.reset()
        seen.append(env.unwrapped.scenario.name)
    assert seen == ["random-5000", "random-5001", "random-5002", "random-5000"]


def test_learning_curve_of_several_runs(trained: dict[str, Path], tmp_path: Path) -> None:
    logs = [trained[a] / "eval_log.json" for a in ALGOS]
    png = plot_learning_curve(logs, tmp_path / "curve.png", labels=list(ALGOS))
    assert png.stat().st_size > 0


def test_body_frame_rotates_into_the_aircraft_frame() -> None:
    env = BodyFrameObservation(gym.make(DISCRETE_ID))
    sc = resolve_scenario("paper").replace(start=(0.0, 0.0, np.pi / 2, 300.0))  # heading east, goal north
    obs, _ = env.reset(seed=0, options={"scenario": sc})
    assert env.observation_space.contains(obs)
    ahead, right = obs[0], obs[1]
    assert ahead == pytest.approx(0.0, abs=1e-6) and right == pytest.approx(-3.0, abs=1e-6)  # goal on the left
    dist, sin_err, cos_err = obs[-3:]
    assert dist == pytest.approx(3.0) and sin_err == pytest.approx(-1.0) and cos_err == pytest.approx(0.0, abs=1e-6)
    batch = body_frame(np.zeros((2, obs.shape[0] - 3), dtype=np.float32) + np.float32(0.5))
    assert batch.shape == (2, obs.shape[0])


def test_turn_curve_keeps_the_envelope_and_refines_small_turns() -> None:
    a = turn_curve(np.array([0.2, 0.5, -0.3], dtype=np.float32), 3.0)
    assert a[0] == pytest.approx(0.2) and a[2] == pytest.approx(-0.3) and a[1] == pytest.approx(0.125)
    assert turn_curve(np.array([0.0, -1.0, 1.0]), 3.0)[1] == -1.0


@pytest.mark.parametrize(("task", "algo"), [("climb", "continuous"), ("xc", "continuous"), ("xc", "grid")])
def test_tiny_task_run_trains_saves_loads_and_evaluates(task: str, algo: str, tmp_path: Path) -> None:
    """PPO on a task: the task's env id and validation scenarios, the observation layout saved with
    the run, and the trained policy scored by the task table (through env.step, deterministic) under
    its algo's label; two runs of one algo on one task id are refused."""
    from baselines.tasks import TaskJob, run_task_job, task_jobs

    cfg = dataclasses.replace(_tiny(algo), task=task)
    assert cfg.env_id == TASKS[task][1] and cfg.family == task and cfg.body_frame is True
    run = train(cfg, tmp_path / task)
    record = json.loads((run / "config.json").read_text())
    assert record["env_id"] == cfg.env_id and "time_left" in record["observation_names"]
    label = "ppo" if algo == "continuous" else f"ppo-{algo}"
    jobs = task_jobs([cfg.env_id], 1, ["random"], ppo_runs=[str(run)])
    assert [j.agent for j in jobs] == ["random", label]
    with pytest.raises(ConfigError, match=f"two {label} runs"):
        task_jobs([cfg.env_id], 1, ["random"], ppo_runs=[str(run), str(run)])
    job = TaskJob(cfg.env_id, f"{task}-10000", label, 0, run=str(run))
    a, b = run_task_job(job), run_task_job(job)
    assert a["agent"] == label and a["energy_spent"] == b["energy_spent"] and a["decisions"] >= 1
    assert validation_scenarios(2, None, task)[0].name == f"{task}-5000"


def test_body_frame_of_any_layout() -> None:
    """BodyFrame finds the pairs by name: on the goal layout it is body_frame exactly; on the climb
    layout (no goal entries) it rotates the wind and thermal offsets and appends nothing."""
    env = gym.make("soaring/Soaring-v0", scenario="random")
    obs = np.array([env.reset(seed=s)[0] for s in range(5)])
    bf = BodyFrame(env.unwrapped.observation_names)
    assert np.array_equal(bf(obs), body_frame(obs))
    climb = gym.make("soaring/ThermalClimbContinuous-v0")
    o, _ = climb.reset(seed=1)
    names = climb.unwrapped.observation_names
    t = BodyFrame(names)(o)
    assert t.shape == o.shape
    s, c = o[names.index("sin_course")], o[names.index("cos_course")]
    n, e = o[names.index("thermal_0_north")], o[names.index("thermal_0_east")]
    assert t[names.index("thermal_0_north")] == pytest.approx(n * c + e * s, abs=1e-6)  # ahead
    assert t[names.index("thermal_0_east")] == pytest.approx(-n * s + e * c, abs=1e-6)  # right
    with pytest.raises(ValueError, match="task"):
        TrainConfig(task="soar")


def test_final_glide_margin_closed_form_and_wind() -> None:
    """The margin is the height over the goal centre less distance x the flattest glide's slope in
    still air (closed form); a headwind or a crosswind lowers it, a tailwind raises it; a wind the
    aircraft cannot fly against gives the lower bound; it is clipped to +-3 height units."""
    env = gym.make("soaring/SoaringContinuous-v0")
    fg = FinalGlide.of(env)
    slope = math.tan(-max(fg.angles))  # the flattest glide's height lost per metre
    assert 0.03 < slope < 0.1  # L/D between 10 and 33
    one = np.ones(1)

    def m(n: float, e: float, up: float, wn: float = 0.0, we: float = 0.0) -> float:
        return float(fg.margin(n * one, e * one, up * one, wn * one, we * one)[0])

    # 2 km north, 100 m above the goal centre, no wind (positions in km, wind in units of 10 m/s)
    assert m(2.0, 0.0, -0.1) == pytest.approx((100.0 - 2000.0 * slope) / 1000.0, rel=1e-12)
    assert m(0.0, 0.0, -0.1) == pytest.approx(0.1)  # at the goal: the height over it
    assert m(-1.4, 1.4, -0.1) == pytest.approx((100.0 - 1979.898987 * slope) / 1000.0, rel=1e-6)  # bearing
    still = m(2.0, 0.0, -0.1)
    assert m(2.0, 0.0, -0.1, wn=-0.5) < still < m(2.0, 0.0, -0.1, wn=0.5)  # head- and tailwind
    assert m(2.0, 0.0, -0.1, we=0.5) < still and m(2.0, 0.0, -0.1, we=0.5) == pytest.approx(m(2.0, 0.0, -0.1, we=-0.5))
    assert m(2.0, 0.0, -0.1, wn=-4.0) == -FinalGlide.BOUND  # 40 m/s headwind: no glide gets there
    assert m(0.0, 0.0, -3.0) == FinalGlide.BOUND


def test_final_glide_bad_input() -> None:
    """Bad polars, scales and inputs are ConfigErrors naming the field; the model's glide polar
    checks its size."""
    fg = FinalGlide.of(gym.make("soaring/SoaringContinuous-v0"))
    one = np.ones(2)
    with pytest.raises(ConfigError, match="goal_up"):
        fg.margin(one, one, np.array([0.0, np.nan]), one, one)
    with pytest.raises(ConfigError, match="wind_east"):
        fg.margin(one, one, one, one, ["a", "b"])
    with pytest.raises(ConfigError, match="shape"):
        fg.margin(one, one, one, one, np.ones(3))
    for bad in (
        {"airspeeds": ()},
        {"airspeeds": (10.0, -1.0)},
        {"angles": (0.1, -0.1)},
        {"angles": (float("nan"), -0.1)},
        {"position_scale": 0.0},
        {"height_scale": "1000"},
        {"wind_scale": float("inf")},
    ):
        base = {"airspeeds": (10.0, 20.0), "angles": (-0.1, -0.1), "position_scale": 1e3, "height_scale": 1e3,
                "wind_scale": 10.0}  # fmt: skip
        with pytest.raises(ConfigError, match=next(iter(bad))):
            FinalGlide(**{**base, **bad})  # type: ignore[arg-type]
    model = gym.make("soaring/SoaringContinuous-v0").unwrapped.model
    for n in (1, 0, 2.5, "21", True):
        with pytest.raises(ConfigError, match="n="):
            model.straight_glides(n)
    speeds, angles = model.straight_glides(5)
    assert speeds.shape == angles.shape == (5,) and np.all(angles < 0.0)


def test_final_glide_in_the_body_frame() -> None:
    """With ``final_glide`` the body frame appends the margin (mirror-invariant, inside the space);
    the saved run's transform gives the wrapper's observations; tasks without a goal refuse it."""
    from baselines.ppo import observation_transform, policy_frame

    env = BodyFrameObservation(gym.make("soaring/SoaringContinuous-v0", scenario="random"), final_glide=True)
    plain = BodyFrameObservation(gym.make("soaring/SoaringContinuous-v0", scenario="random"))
    assert env.observation_space.shape[0] == plain.observation_space.shape[0] + 1
    record = {"config": {"body_frame": True, "final_glide": True, "env_kwargs": {}}, "env_id": CONTINUOUS_ID}
    fn = observation_transform(record)
    assert fn is not None
    raw_env = gym.make("soaring/SoaringContinuous-v0", scenario="random")
    env.action_space.seed(0)
    for seed in range(4):
        o, _ = env.reset(seed=seed)
        p, _ = plain.reset(seed=seed)
        raw, _ = raw_env.reset(seed=seed)
        assert np.array_equal(o[:-1], p) and np.array_equal(fn(raw), o) and env.observation_space.contains(o)
        for _ in range(3):
            a = env.action_space.sample()
            o, _, term, trunc, _ = env.step(a)
            raw, *_ = raw_env.step(a)
            assert np.array_equal(fn(raw), o) and env.observation_space.contains(o)
            if term or trunc:
                break
    names = env.unwrapped.observation_names
    assert policy_frame(env, True).mirror_signs(names)[-1] == 1.0
    with pytest.raises(ConfigError, match="goal"):
        policy_frame(gym.make("soaring/ThermalClimbContinuous-v0"), True)
    with pytest.raises(ValueError, match="final_glide"):
        TrainConfig(task="climb", final_glide=True)
    with pytest.raises(ValueError, match="final_glide"):
        TrainConfig(final_glide="yes")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="final_glide"):
        policy_frame(env, "yes")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("env_id", "exponent"),
    [
        ("soaring/SoaringContinuous-v0", 3.0),
        ("soaring/Soaring-v0", 1.0),
        ("soaring/ThermalClimbContinuous-v0", 1.0),
        ("soaring/CrossCountry-v0", 1.0),
    ],
)
def test_native_training_env_equals_sb3_dummy_vec_env(env_id: str, exponent: float) -> None:
    """The natively batched training env (the default ``vec_env``) gives SB3's DummyVecEnv's
    transitions bit for bit: body-frame observations, turn curve, terminal observations, episode
    statistics, for goal reaching and the tasks."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv

    from baselines.ppo import make_native_train_env, make_train_env

    n = 3
    native = make_native_train_env(env_id, n, {}, True, exponent)
    dummy = make_vec_env(
        make_train_env,
        n_envs=n,
        seed=3,
        vec_env_cls=DummyVecEnv,
        env_kwargs={"env_id": env_id, "body_frame": True, "turn_exponent": exponent},
    )
    native.seed(3)
    dummy.seed(3)
    assert native.observation_space == dummy.observation_space
    assert np.array_equal(native.reset(), dummy.reset())
    rng = np.random.default_rng(0)
    episodes = 0
    for _ in range(150):
        space = native.action_space
        if isinstance(space, gym.spaces.Discrete):
            a = rng.integers(0, space.n, n)
        else:
            a = rng.uniform(-1.0, 1.0, (n, *space.shape)).astype(np.float32)
        r1, r2 = native.step(a), dummy.step(a)
        for x, y in zip(r1[:3], r2[:3], strict=True):
            assert np.array_equal(x, y)
        for i1, i2 in zip(r1[3], r2[3], strict=True):
            for key in ("terminal_observation", "is_success", "TimeLimit.truncated", "episode"):
                assert (key in i1) == (key in i2), key
            if "terminal_observation" in i1:
                assert np.array_equal(i1["terminal_observation"], i2["terminal_observation"])
            if "episode" in i1:
                episodes += 1
                assert i1["episode"]["l"] == i2["episode"]["l"]
                assert i1["episode"]["r"] == pytest.approx(i2["episode"]["r"], abs=1e-5)
    assert episodes > 0


def test_native_vec_env_is_the_default_and_refuses_shaping() -> None:
    assert TrainConfig().vec_env == "native"
    with pytest.raises(ValueError, match="shaping"):
        TrainConfig(shaping=1.0)
    TrainConfig(shaping=1.0, vec_env="dummy")


def test_turn_curve_is_the_same_for_one_action_and_a_batch() -> None:
    rng = np.random.default_rng(0)
    batch = rng.uniform(-1.0, 1.0, (4096, 3)).astype(np.float32)
    for p in (3.0, 2.5):
        assert np.array_equal(turn_curve(batch, p), np.stack([turn_curve(a, p) for a in batch]))


def test_init_from_continues_an_earlier_run(trained: dict[str, Path], tmp_path: Path) -> None:
    """A curriculum stage starts from an earlier run's weights; a missing or unfitting run is refused."""
    with pytest.raises(ValueError, match="init_from"):
        TrainConfig(init_from=str(tmp_path / "nowhere"))
    cfg = dataclasses.replace(_tiny("continuous"), total_timesteps=256, init_from=str(trained["continuous"]))
    run = train(cfg, tmp_path / "stage2")
    assert json.loads((run / "config.json").read_text())["config"]["init_from"] == str(trained["continuous"])
    with pytest.raises(ValueError, match="does not fit"):
        train(dataclasses.replace(_tiny("discrete"), init_from=str(trained["continuous"])), tmp_path / "bad")


def test_a_terminated_run_stops_gracefully_and_keeps_its_model(tmp_path: Path) -> None:
    """SIGTERM during training ends the run as a wall-clock cap would: model.zip and config.json
    are written, with the signal recorded (a killed run used to lose everything since its last
    checkpoint)."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "run"
    code = (
        "from baselines.ppo import TrainConfig, train\n"
        "train(TrainConfig(algo='continuous', total_timesteps=10**8, n_envs=2, n_steps=64, batch_size=64,"
        " n_epochs=1, eval_freq=10**9, n_eval_scenarios=1, checkpoint_freq=0, progress_bar=False),"
        f" {str(out)!r})\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[1])
    try:
        deadline = time.monotonic() + 120
        while not (out / "config.json").exists():  # written when training starts
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.2)
        time.sleep(2.0)  # well into learn()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=120) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
    record = json.loads((out / "config.json").read_text())
    assert record["status"] == "done" and record["stopped_by_signal"] == "SIGTERM"
    assert not record["stopped_by_wall_clock"] and record["timesteps_done"] > 0
    assert (out / "model.zip").is_file()


def test_critic_warmup_moves_the_critic_alone(trained: dict[str, Path], tmp_path: Path) -> None:
    """``critic_warmup``: the PPO updates on the first steps leave every parameter but the value
    function's exactly as ``init_from`` loaded them; without it the same run moves the policy."""
    import torch

    from baselines.ppo import CRITIC_PREFIXES, load_model

    for bad in (-1, True, 1.5, "100"):
        with pytest.raises(ValueError, match="critic_warmup"):
            TrainConfig(critic_warmup=bad)  # type: ignore[arg-type]
    start = load_model(trained["discrete"] / "model.zip", "discrete").policy.state_dict()
    base = dataclasses.replace(
        _tiny("discrete"), total_timesteps=512, eval_freq=10**6, checkpoint_freq=0, init_from=str(trained["discrete"])
    )  # two updates of 256 steps
    runs = {w: train(dataclasses.replace(base, critic_warmup=w), tmp_path / f"w{w}") for w in (0, 256, 512)}
    after = {w: load_model(run / "model.zip", "discrete").policy.state_dict() for w, run in runs.items()}
    actor = [n for n in start if not n.startswith(CRITIC_PREFIXES)]
    critic = [n for n in start if n.startswith(CRITIC_PREFIXES)]
    assert actor and critic
    assert all(torch.equal(after[512][n], start[n]) for n in actor)  # both updates: the critic alone
    assert any(not torch.equal(after[256][n], start[n]) for n in actor)  # the second update moves the policy
    assert any(not torch.equal(after[0][n], start[n]) for n in actor)
    for w in (0, 256, 512):
        assert any(not torch.equal(after[w][n], after[512][n]) for n in actor) == (w != 512)
    assert any(not torch.equal(after[512][n], start[n]) for n in critic)  # the critic learnt (from afresh)
    assert json.loads((runs[512] / "config.json").read_text())["config"]["critic_warmup"] == 512
