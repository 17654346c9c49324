"""Evaluation: agents x scenarios x seeds -> a results file, a markdown table and plots.

Every agent -- the SST planners, PPO, the random agent and the heuristic -- is executed and scored
through ``env.step`` of the same registered envs, on the same scenarios (passed with
``env.reset(seed=seed, options={"scenario": sc})``). The SST planners know the thermal field (they
plan on the env's model); PPO sees the observation (which lists the nearest thermals); the
heuristic senses only the updraft around the aircraft; the random agent sees nothing.

Per episode: success (``info["is_success"]``), energy spent [J/kg] (``info["energy_spent"]``),
flight time [s] (``env.unwrapped.time``), number of decisions, return, and compute time: the
agent's ``reset`` (where a planner plans) plus all its ``predict`` calls, in total and per
decision. The flown path (every output point of every edge) is kept for plots.

Scenario names: those of :func:`soaring_env.scenario.get_scenario` -- ``"paper"``, a ``.json`` path,
``"random-<seed>"`` -- ``make_scenario(np.random.default_rng(seed))``; the held-out set is
``random-10000``, ``random-10001``, ... (:func:`heldout_names`), disjoint from the validation
seeds used during training (5000+) and from the training scenarios (drawn from each env's own
``np_random`` stream).

Results are written atomically (:func:`soaring_env.scenario.atomic_write_text`) after every
episode; a rerun with the same output directory resumes, reusing the episodes whose agent
settings (budget, model file) are unchanged. The episodes can run in parallel (``workers``, and
``backend="ray"`` for a Ray cluster: :mod:`baselines.backends`); the file is the same, but for the
timings, as the serial one.
"""

from __future__ import annotations

import hashlib
import json
import math
import platform
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from baselines._runs import holds_dir_lock, progress_bar, read_json
from baselines.backends import check_backend, run_jobs
from baselines.reference.bounds import regret
from baselines.reference.yardstick import ScenarioReference
from soaring_env._validation import ConfigError, check_int
from soaring_env.scenario import HELDOUT_SEED0 as HELDOUT_SEED0
from soaring_env.scenario import Scenario, atomic_write_text, check_scenario_name
from soaring_env.scenario import get_scenario as resolve_scenario
from soaring_env.scenario import heldout_names as heldout_names

DISCRETE_ID = "soaring/Soaring-v0"
CONTINUOUS_ID = "soaring/SoaringContinuous-v0"
RESULTS_FILE = "results.json"
TABLE_FILE = "results.md"
SCHEMA = 1
#: The agent whose energy the others are compared with, on the episodes both solve.
REFERENCE_AGENT = "sst-primitives"
#: Known agent names, in table order.
AGENT_NAMES = (
    "sst-primitives",
    "sst-continuous",
    "sst-soaring-primitives",
    "sst-soaring-continuous",
    "sst-seeded-primitives",
    "sst-seeded-continuous",
    "ppo-discrete",
    "ppo-discrete-rollout",
    "ppo-masked",
    "ppo-continuous",
    "ppo-grid",
    "heuristic",
    "heuristic-continuous",
    "thermalling",
    "thermalling-continuous",
    "random",
)
#: env settings that change only the reward (a PPO run's are not carried into its evaluation env)
REWARD_ONLY_KWARGS = (
    "energy_weight",
    "goal_bonus",
    "crash_penalty",
    "out_of_bounds_penalty",
    "progress_weight",
    "settle_height",
)
#: PPO agent name -> training algorithm (see :data:`baselines.ppo.ALGOS`).
PPO_AGENTS = {
    "ppo-discrete": "discrete",
    "ppo-discrete-rollout": "discrete",  # the discrete successor policy improved online (RolloutAgent)
    "ppo-masked": "masked",
    "ppo-continuous": "continuous",
    "ppo-grid": "grid",
}
#: PPO agents that fly a run's policy with decision-time lookahead, not as it is (opt-in: a run
#: directory is never picked up for them by default).
ROLLOUT_AGENTS = ("ppo-discrete-rollout",)
#: Which saved model of a PPO run an agent uses (:func:`ppo_model_path`).
PPO_MODELS = ("best", "final", "bc")


@dataclass(frozen=True)
class EvalConfig:
    """What to evaluate and how.

    :param agents: agent names (see :data:`AGENT_NAMES`).
    :param scenarios: scenario names (``"paper"``, ``"random-<seed>"``).
    :param seeds: episode seeds: ``env.reset(seed=...)`` and ``agent.reset(env, seed)``.
    :param sst_time_budget: SST planning budget per planning call [s] (None: iterations only).
    :param sst_iterations: SST iteration budget per planning call (None: time only). With a time
        budget the results depend on the machine's speed; an iteration budget alone is deterministic.
    :param ppo_dirs: PPO agent name -> run directory of :func:`baselines.ppo.train`.
    :param ppo_model: ``"best"`` (best validation return during training), ``"final"`` or ``"bc"``.
    :param env_kwargs: extra ``gym.make`` keywords for every env (must match PPO training).
    :param keep_paths: store the flown path of every episode (for trajectory plots).
    :param rollout_candidates: primitives the rollout agents try per decision
        (:class:`baselines.agents.RolloutAgent`; 8 measured on ``val100``, docs/learning-to-soar.md round twenty-one).
    """

    agents: tuple[str, ...] = ("sst-primitives", "sst-continuous", "heuristic", "random")
    scenarios: tuple[str, ...] = ("paper",)
    seeds: tuple[int, ...] = (0,)
    sst_time_budget: float | None = 20.0
    sst_iterations: int | None = None
    ppo_dirs: Mapping[str, str] = field(default_factory=dict)
    ppo_model: str = "best"
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    keep_paths: bool = True
    rollout_candidates: int = 8

    def __post_init__(self) -> None:
        object.__setattr__(self, "rollout_candidates", check_int("rollout_candidates", self.rollout_candidates, 1))
        object.__setattr__(self, "agents", tuple(self.agents))
        object.__setattr__(self, "scenarios", tuple(self.scenarios))
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))
        object.__setattr__(self, "ppo_dirs", {k: str(v) for k, v in dict(self.ppo_dirs).items()})
        object.__setattr__(self, "env_kwargs", dict(self.env_kwargs))
        for a in self.agents:
            check_agent_name(a)
        for s in self.scenarios:
            check_scenario_name(s)
        for k in self.ppo_dirs:
            if k not in PPO_AGENTS:
                raise ConfigError(f"ppo_dirs key {k!r} is not a PPO agent; known: {', '.join(PPO_AGENTS)}")
        if not self.agents or not self.scenarios or not self.seeds:
            raise ConfigError("agents, scenarios and seeds must each name at least one")
        if len(set(self.agents)) != len(self.agents) or len(set(self.scenarios)) != len(self.scenarios):
            raise ConfigError("agents and scenarios must not repeat")
        if self.sst_time_budget is None and self.sst_iterations is None:
            raise ConfigError("SST needs a budget: sst_time_budget and/or sst_iterations")
        if self.ppo_model not in PPO_MODELS:
            raise ConfigError(f"ppo_model={self.ppo_model!r} is unknown; known: {', '.join(PPO_MODELS)}")


# --- names ----------------------------------------------------------------------------------------
def check_agent_name(name: str) -> str:
    """``name`` if it is a known agent, else a :class:`ConfigError` listing the known ones."""
    if name not in AGENT_NAMES:
        raise ConfigError(f"agent {name!r} is unknown; known: {', '.join(AGENT_NAMES)}")
    return name


# The scenario names (check_scenario_name, resolve_scenario = soaring_env.scenario.get_scenario,
# heldout_names, HELDOUT_SEED0) live in soaring_env.scenario, the one namespace of scenario names.


# --- agents -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AgentSpec:
    """How to build one agent: its env and a factory. ``settings`` fingerprint it for resuming;
    ``env_kwargs`` are the agent's own env settings, over the evaluation's (a PPO run's training
    env: its control interval, envelope, step limit), recorded in ``settings``."""

    name: str
    env_id: str
    factory: Callable[[], Any]
    settings: Mapping[str, Any]
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)

    def env_settings(self, config: EvalConfig) -> dict[str, Any]:
        """The ``gym.make`` keywords of this agent's env under ``config``."""
        return {**dict(config.env_kwargs), **dict(self.env_kwargs)}


def file_digest(path: Path) -> str:
    """The first 16 hex digits of the SHA-256 of a file (a model's identity in results records:
    unlike its modification time, a fresh checkout keeps it)."""
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:16]


def ppo_model_path(run_dir: str | Path, which: str = "best") -> Path:
    """``best_model.zip`` (if ``which == "best"`` and it exists), ``bc_model.zip`` (``"bc"``: the
    behaviour-cloned start of a run with ``demos``) or ``model.zip`` of a run directory."""
    d = Path(run_dir)
    if which == "bc":
        return d / "bc_model.zip"
    best = d / "best_model.zip"
    if which == "best" and best.is_file():
        return best
    return d / "model.zip"


def ppo_env_kwargs(run_record: Mapping[str, Any]) -> dict[str, Any]:
    """The env settings a PPO run (its ``config.json``) was trained with, but those that change only
    the reward (:data:`REWARD_ONLY_KWARGS`): its control interval, envelope, step limit... A policy
    is scored in the env it learned to fly."""
    cfg = run_record.get("config", run_record)
    return {k: v for k, v in dict(cfg.get("env_kwargs", {})).items() if k not in REWARD_ONLY_KWARGS}


def agent_spec(name: str, config: EvalConfig) -> AgentSpec:
    """The :class:`AgentSpec` of agent ``name`` under ``config``; raises for unknown names."""
    check_agent_name(name)
    if name.startswith("sst-"):
        # "sst-primitives" / "sst-continuous": the paper's planner; "sst-soaring-*" / "sst-seeded-*":
        # the soaring configuration without / with the seeding reference search
        sampler = "primitive" if name.endswith("primitives") else "continuous"
        planner = next((p for p in ("soaring", "seeded") if name.startswith(f"sst-{p}-")), "paper")
        env_id = DISCRETE_ID if sampler == "primitive" else CONTINUOUS_ID
        settings: dict[str, Any] = {
            "sampler": sampler,
            "time_budget": config.sst_time_budget,
            "iterations": config.sst_iterations,
        }
        if planner != "paper":  # (the paper planner's records predate these keys)
            from baselines.sst.soaring import planner_record

            # a change of the configuration or of the steering rule redoes these episodes on resume
            settings.update(planner_record(planner, sampler))

        def make_sst() -> Any:
            from baselines.agents import SSTPlannerAgent

            return SSTPlannerAgent(
                time_limit=config.sst_time_budget, max_iterations=config.sst_iterations, name=name, planner=planner
            )

        return AgentSpec(name, env_id, make_sst, settings)
    if name in PPO_AGENTS:
        algo = PPO_AGENTS[name]
        run_dir = config.ppo_dirs.get(name)
        if run_dir is None:
            raise ConfigError(f"agent {name!r} needs a trained model: give its run directory (ppo_dirs / --ppo-dir)")
        path = ppo_model_path(run_dir, config.ppo_model)
        if not path.is_file():
            raise ConfigError(f"agent {name!r}: no trained model at {path}; train one with scripts/train_ppo.py")
        cfg = json.loads((Path(run_dir) / "config.json").read_text())
        if cfg.get("algo") != algo:
            raise ConfigError(f"agent {name!r} needs a {algo!r} model, but {run_dir} holds {cfg.get('algo')!r}")

        settings = {"model": str(path), "sha256": file_digest(path)}
        if name in ROLLOUT_AGENTS:
            if cfg.get("config", {}).get("policy") != "successor":
                raise ConfigError(
                    f"agent {name!r} needs a successor policy (--set 'policy=\"successor\"'), but {run_dir} holds "
                    f"policy={cfg.get('config', {}).get('policy')!r}"
                )
            settings["rollout_candidates"] = config.rollout_candidates

        def make_ppo() -> Any:
            from baselines.agents import PPOAgent, RolloutAgent

            if name in ROLLOUT_AGENTS:
                return RolloutAgent(path, candidates=config.rollout_candidates, name=name)
            return PPOAgent(path, name=name)

        own = ppo_env_kwargs(cfg)
        if own:
            settings["env_kwargs"] = own
        return AgentSpec(name, cfg["env_id"], make_ppo, settings, own)
    from baselines.agents import HeuristicAgent, RandomAgent, ThermallingAgent

    if name == "random":
        return AgentSpec(name, DISCRETE_ID, lambda: RandomAgent(use_masks=True, name=name), {"use_masks": True})
    env_id = CONTINUOUS_ID if name.endswith("-continuous") else DISCRETE_ID
    if name.startswith("thermalling"):
        return AgentSpec(name, env_id, lambda: ThermallingAgent(name=name), ThermallingAgent().settings())
    return AgentSpec(name, env_id, lambda: HeuristicAgent(name=name), HeuristicAgent().settings())


# --- running -------------------------------------------------------------------------------------------
def make_env(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> gym.Env:
    """A registered soaring env (imports :mod:`soaring_env` to register the ids)."""
    import soaring_env  # noqa: F401

    return gym.make(env_id, **dict(env_kwargs or {}))


def run_episode(env: gym.Env, agent: Any, scenario: Scenario, seed: int, keep_path: bool = True) -> dict[str, Any]:
    """One episode of ``agent`` on ``scenario`` through ``env.step``; returns the episode record."""
    base: Any = env.unwrapped
    obs, info = env.reset(seed=seed, options={"scenario": scenario})
    t0 = time.perf_counter()
    agent.reset(env, seed)
    plan_s = time.perf_counter() - t0
    predict_s = 0.0
    n = 0
    ret = 0.0
    terminated = truncated = False
    while not (terminated or truncated):
        t1 = time.perf_counter()
        action, _ = agent.predict(obs, deterministic=True)
        predict_s += time.perf_counter() - t1
        obs, reward, terminated, truncated, info = env.step(action)
        n += 1
        ret += float(reward)
    total = plan_s + predict_s
    end = np.asarray(base.state, dtype=np.float64)
    circling, in_lift = circling_fractions(base)
    path = None
    if keep_path:  # every flown output point (the env keeps them), [north, east, height] to 0.1 m
        path = np.round(np.asarray(base.path, dtype=np.float64)[:, [0, 1, 3]], 1).tolist()
    return {
        "success": bool(info.get("is_success", False)),
        "outcome": str(info.get("outcome", "success" if info.get("is_success") else "failure")),
        "terminated": bool(terminated),
        "truncated": bool(truncated),
        "energy_spent": float(info["energy_spent"]),
        "flight_time": float(base.time),
        "decisions": n,
        "return": ret,
        "final_height": float(end[3]),
        "compute_total_s": total,
        "compute_plan_s": plan_s,
        "compute_per_decision_s": total / max(n, 1),
        "circling_fraction": circling,
        "circling_in_lift_fraction": in_lift,
        "path": path,
    }


#: A flown interval counts as circling at a course rate of at least this [rad/s] (a full circle
#: per minute), and as in lift where the updraft at its end is at least ``LIFT_MIN`` [m/s].
CIRCLING_RATE = 2.0 * math.pi / 60.0
LIFT_MIN = 0.2


def circling_fractions(base: Any) -> tuple[float, float]:
    """(fraction of the flight time spent circling, fraction spent circling in lift) of the episode
    an env has just flown, from its flown points (``base.path``: N points per Ts, evenly spaced in
    time from the start) and the true field at them; (0, 0) before any step."""
    pts = np.asarray(base.path, dtype=np.float64)
    if len(pts) < 2:
        return 0.0, 0.0
    lib = base.model.library
    dt = float(lib.duration) / int(lib.n_points)
    t_end = float(base.time)
    times = t_end - dt * np.arange(len(pts) - 1, -1, -1, dtype=np.float64)
    dchi = np.abs((np.diff(pts[:, 2]) + math.pi) % (2.0 * math.pi) - math.pi)
    turning = dchi / dt >= CIRCLING_RATE
    lift = np.atleast_1d(base.scenario.field.updraft(pts[1:, 0], pts[1:, 1], pts[1:, 3], times[1:]))
    n = len(turning)
    return float(turning.sum() / n), float((turning & (lift >= LIFT_MIN)).sum() / n)


def action_set(env_id: str) -> str:
    """The reference action set of an env id: ``"primitive"`` (Discrete(174)) or ``"continuous"``."""
    return "primitive" if env_id == DISCRETE_ID else "continuous"


def episode_regret(ep: Mapping[str, Any], references: Mapping[str, ScenarioReference]) -> float | None:
    """Regret of a successful episode against its scenario's reference for its action set (None:
    a failure, no reference for the scenario, or a scenario where the thermals offer nothing)."""
    ref = references.get(ep["scenario"])
    if ref is None or not ep["success"]:
        return None
    r = ref.regret(float(ep["energy_spent"]), action_set(ep["env_id"]))
    return None if math.isnan(r) else r


def attach_regret(results: dict[str, Any], references: Mapping[str, ScenarioReference]) -> dict[str, Any]:
    """Set ``regret`` on every episode of ``results`` (in place) and record which reference was used.
    A reference whose scenario differs from the one the episodes ran on is not used."""
    scen = results["meta"].get("scenarios", {})
    references = {
        name: ref for name, ref in references.items() if name in scen and Scenario.from_dict(scen[name]) == ref.scenario
    }
    for ep in results["episodes"]:
        ep["regret"] = episode_regret(ep, references)
    results["meta"]["reference"] = {
        name: {s: {"best_cost": r.best_cost, "direct_cost": r.direct_cost} for s, r in ref.samplers.items()}
        for name, ref in references.items()
        if name in results["meta"].get("scenarios", {})
    }
    return results


def _key(agent: str, scenario: str, seed: int) -> str:
    return f"{agent}|{scenario}|{seed}"


def _load_results(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    data = read_json(path)
    if not isinstance(data, dict) or data.get("schema") != SCHEMA:
        schema = data.get("schema") if isinstance(data, dict) else type(data).__name__
        raise ConfigError(f"{path} has results schema {schema!r}, expected {SCHEMA}; use a new directory")
    return data


@holds_dir_lock(lambda a: a.arguments["out_dir"], "evaluation")
def run_evaluation(
    config: EvalConfig,
    out_dir: str | Path,
    *,
    resume: bool = True,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
    references: Mapping[str, ScenarioReference] | None = None,
    workers: int | None = 1,
    backend: str = "local",
    address: str | None = None,
) -> dict[str, Any]:
    """Run every (agent, scenario, seed) of ``config``; write ``results.json`` after each episode.

    Each episode is one job of :func:`baselines.backends.run_jobs`; the results file holds the
    episodes in the order of ``config`` (agents, then scenarios, then seeds) whichever job finished
    first, so that it is the same -- but for the timings and ``meta.created`` -- for any ``workers``
    and ``backend``. Agents with an SST wall-clock budget depend on the machine's load anyway.

    :param resume: reuse episodes already in ``out_dir/results.json`` whose agent settings match.
    :param references: the reference per scenario name (:func:`baselines.reference.load_references`);
        every episode record gets its ``regret`` against it (None where it has none).
    :param progress: show a tqdm progress bar.
    :param log: called with one line per episode (e.g. ``print``; through tqdm while ``progress``).
    :param workers: episodes at a time (1: one after another in this process; None: one per CPU).
    :param backend: ``"local"`` (worker processes) or ``"ray"``; see :mod:`baselines.backends`.
    :param address: with ``backend="ray"``: a running cluster's address (None: a local Ray instance).
    :returns: the results dict (also on disk).
    """
    check_backend(backend, workers, address)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    res_path = out / RESULTS_FILE
    specs = {a: agent_spec(a, config) for a in config.agents}
    random_kw = dict(config.env_kwargs.get("random_scenario", {}))
    scenarios = {s: resolve_scenario(s, random_kw) for s in config.scenarios}
    old = _load_results(res_path) if resume else None
    done: dict[str, dict[str, Any]] = {}
    if old is not None:
        if old["meta"].get("env_kwargs") != _jsonable(config.env_kwargs):
            was = old["meta"].get("env_kwargs")
            raise ConfigError(f"{res_path} was made with env_kwargs {was!r}; use a new directory")
        old_settings = old["meta"].get("agents", {})
        for ep in old["episodes"]:
            a = ep["agent"]
            if a in specs and old_settings.get(a) == _jsonable(specs[a].settings):
                done[_key(a, ep["scenario"], ep["seed"])] = ep
        if log is not None:
            log(f"resuming: {len(done)} finished episodes with the same settings loaded from {res_path}")
    meta = {
        "schema": SCHEMA,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "machine": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "env_kwargs": _jsonable(config.env_kwargs),
        "agents": {a: _jsonable(s.settings) for a, s in specs.items()},
        "agent_envs": {a: s.env_id for a, s in specs.items()},
        "scenarios": {s: sc.to_dict() for s, sc in scenarios.items()},
        "seeds": list(config.seeds),
        "config": {
            "sst_time_budget": config.sst_time_budget,
            "sst_iterations": config.sst_iterations,
            "ppo_model": config.ppo_model,
        },
    }
    others: list[dict[str, Any]] = []
    keys_wanted = [_key(a, s, seed) for a in config.agents for s in config.scenarios for seed in config.seeds]
    # Keep finished episodes of other agents/scenarios too (a results file can grow run by run).
    if old is not None:
        wanted = set(keys_wanted)
        for ep in old["episodes"]:
            k = _key(ep["agent"], ep["scenario"], ep["seed"])
            a = ep["agent"]
            same = a not in specs or old["meta"]["agents"].get(a) == _jsonable(specs[a].settings)
            if k not in wanted and same:
                others.append(ep)
                meta["agents"].setdefault(ep["agent"], old["meta"]["agents"].get(ep["agent"]))
                meta["agent_envs"].setdefault(ep["agent"], old["meta"].get("agent_envs", {}).get(ep["agent"]))
                meta["scenarios"].setdefault(ep["scenario"], old["meta"]["scenarios"].get(ep["scenario"]))
    finished = {k: done[k] for k in keys_wanted if k in done}  # key -> episode, reused or run now
    jobs = [
        EpisodeJob(a, s, scenarios[s], seed, config, _cache_key(specs[a], config))
        for a in config.agents
        for s in config.scenarios
        for seed in config.seeds
        if _key(a, s, seed) not in finished
    ]
    refs = references or {}

    def results() -> dict[str, Any]:
        episodes = others + [finished[k] for k in keys_wanted if k in finished]  # the serial order
        return attach_regret({"schema": SCHEMA, "meta": meta, "episodes": episodes}, refs)

    def save() -> None:
        atomic_write_text(res_path, json.dumps(results(), separators=(",", ":")))

    bar = progress_bar(len(keys_wanted), len(finished), progress, "episodes", "ep")
    try:
        for i, rec in run_jobs(run_episode_job, jobs, workers=workers, backend=backend, address=address):
            job = jobs[i]
            finished[_key(job.agent, job.scenario, job.seed)] = rec
            save()
            if log is not None:
                (bar.write if bar is not None else log)(
                    f"{job.agent:>16s} {job.scenario:>12s} seed {job.seed}: "
                    f"{'goal' if rec['success'] else rec['outcome']:>13s} "
                    f"E={rec['energy_spent'] / 1000:7.2f} kJ/kg t={rec['flight_time']:5.0f} s "
                    f"compute={rec['compute_total_s']:.2f} s"
                )
            if bar is not None:
                bar.update(1)
    finally:
        _close_cached()  # the agents and envs of episodes run in this process
        if bar is not None:
            bar.close()
    save()
    return results()


@dataclass(frozen=True)
class EpisodeJob:
    """One episode to run (a job of :func:`run_episode_job`): ``agent`` on ``scenario`` (its name and
    the scenario itself) with ``seed``; ``cache_key`` names the agent's settings and env."""

    agent: str
    scenario: str
    scenario_obj: Scenario
    seed: int
    config: EvalConfig
    cache_key: str


#: Per process: the agents (and their envs) built for earlier episodes, by :attr:`EpisodeJob.cache_key`.
_CACHE: dict[str, tuple[Any, gym.Env, str]] = {}


def _cache_key(spec: AgentSpec, config: EvalConfig) -> str:
    return json.dumps([spec.name, spec.env_id, _jsonable(spec.settings), _jsonable(spec.env_settings(config))])


def run_episode_job(job: EpisodeJob) -> dict[str, Any]:
    """Run one episode (in this process, a worker process or a Ray task) and return its record.

    The agent and its env are built once per process and reused for the process's later episodes,
    as in a serial run: every episode starts from ``env.reset(seed=...)`` and ``agent.reset(env,
    seed)``, so the record depends only on the job."""
    if job.cache_key not in _CACHE:
        spec = agent_spec(job.agent, job.config)
        _CACHE[job.cache_key] = (spec.factory(), make_env(spec.env_id, spec.env_settings(job.config)), spec.env_id)
    agent, env, env_id = _CACHE[job.cache_key]
    rec = run_episode(env, agent, job.scenario_obj, job.seed, job.config.keep_paths)
    return {"agent": job.agent, "scenario": job.scenario, "seed": job.seed, "env_id": env_id, **rec}


def _close_cached() -> None:
    """Close and forget the envs of :data:`_CACHE` (of this process)."""
    for _, env, _ in _CACHE.values():
        env.close()
    _CACHE.clear()


def _jsonable(x: Any) -> Any:
    return json.loads(json.dumps(x, default=str))


# --- summaries ---------------------------------------------------------------------------------------
def load_results(path: str | Path) -> dict[str, Any]:
    """Read a results file (or the ``results.json`` in a directory)."""
    p = Path(path)
    if p.is_dir():
        p = p / RESULTS_FILE
    data = _load_results(p)
    if data is None:
        raise FileNotFoundError(f"no results at {p}")
    return data


def _stats(values: Iterable[float]) -> tuple[float, float, int]:
    v = np.asarray(list(values), dtype=np.float64)
    if v.size == 0:
        return math.nan, math.nan, 0
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else 0.0, int(v.size)


def bootstrap_ci(
    values: Sequence[float], stat: Callable[[np.ndarray], float], n_boot: int = 2000, seed: int = 0
) -> tuple[float, float, float]:
    """``stat(values)`` and its percentile-bootstrap 95 % interval (seeded: deterministic); NaNs if empty."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return math.nan, math.nan, math.nan
    rng = np.random.default_rng(seed)
    boots = np.array([stat(v[rng.integers(0, v.size, v.size)]) for _ in range(n_boot)])
    if np.all(np.isfinite(boots)):
        lo, hi = np.percentile(boots, [2.5, 97.5])
    else:  # infinite values (failures counted as unbounded regret): order statistics, no inf - inf
        lo, hi = np.percentile(boots, [2.5, 97.5], method="nearest")
    return float(stat(v)), float(lo), float(hi)


def _regret_defined(results: Mapping[str, Any], ep: Mapping[str, Any]) -> bool:
    """Whether the episode's scenario has a reference for its action set with a defined regret
    (``results["meta"]["reference"]``, written by :func:`attach_regret`), success or not."""
    ref = results.get("meta", {}).get("reference", {}).get(ep["scenario"], {}).get(action_set(ep["env_id"]))
    if ref is None:
        return False
    return not math.isnan(regret(float(ref["best_cost"]), float(ref["best_cost"]), float(ref["direct_cost"])))


def summarize(results: Mapping[str, Any], reference: str = REFERENCE_AGENT) -> list[dict[str, Any]]:
    """Per agent: success rate, energy [J/kg] over its successes and over the (scenario, seed)
    pairs that it and ``reference`` both solve (with the ratio of those means), flight time [s]
    over successes, compute time per decision and per episode [s]."""
    eps = results["episodes"]
    agents = [a for a in AGENT_NAMES if any(e["agent"] == a for e in eps)]
    agents += sorted({e["agent"] for e in eps} - set(agents))
    ref_ok = {(e["scenario"], e["seed"]): e for e in eps if e["agent"] == reference and e["success"]}
    rows = []
    for a in agents:
        mine = [e for e in eps if e["agent"] == a]
        ok = [e for e in mine if e["success"]]
        common = [(e, ref_ok[(e["scenario"], e["seed"])]) for e in ok if (e["scenario"], e["seed"]) in ref_ok]
        e_mean, e_std, _ = _stats(e["energy_spent"] for e in ok)
        c_mine, _, n_common = _stats(e["energy_spent"] for e, _ in common)
        c_ref, _, _ = _stats(r["energy_spent"] for _, r in common)
        t_mean, t_std, _ = _stats(e["flight_time"] for e in ok)
        reg = [e["regret"] for e in ok if e.get("regret") is not None]
        # every scored episode, a failure as unbounded regret: the median over successes alone
        # flatters an agent that fails where soaring is hard
        reg_all = [e["regret"] if e["success"] else math.inf for e in mine if _regret_defined(results, e)]
        rows.append(
            {
                "agent": a,
                "episodes": len(mine),
                "successes": len(ok),
                "success_rate": len(ok) / len(mine) if mine else math.nan,
                "energy_mean": e_mean,
                "energy_std": e_std,
                "common": n_common,
                "energy_common": c_mine,
                "energy_common_ref": c_ref,
                "energy_ratio": c_mine / c_ref if n_common and c_ref > 0 else math.nan,
                "flight_time_mean": t_mean,
                "flight_time_std": t_std,
                "decisions_mean": _stats(e["decisions"] for e in mine)[0],
                "compute_per_decision_s": _stats(e["compute_per_decision_s"] for e in mine)[0],
                "compute_total_s": _stats(e["compute_total_s"] for e in mine)[0],
                "regret_n": len(reg),
                "regret_median": bootstrap_ci(reg, np.median),
                "regret_mean": bootstrap_ci(reg, np.mean),
                "regret_all_n": len(reg_all),
                "regret_all_median": bootstrap_ci(reg_all, np.median),
                "circling_in_lift": median_circling(mine),
            }
        )
    return rows


def median_circling(episodes: Iterable[Mapping[str, Any]]) -> float:
    """Median fraction of flight time spent circling in lift (:func:`circling_fractions`) over the
    episodes that record it (NaN if none: records made before it was measured)."""
    v = [e["circling_in_lift_fraction"] for e in episodes if e.get("circling_in_lift_fraction") is not None]
    return float(np.median(v)) if v else math.nan


def _f(x: float, fmt: str) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


def _pct(x: float) -> str:
    return "–" if math.isnan(x) else f"{round(100 * x) + 0} %"  # + 0: no "-0 %"


def _ci(t: tuple[float, float, float]) -> str:
    return "–" if math.isnan(t[0]) else f"{t[0]:.2f} [{t[1]:.2f}, {t[2]:.2f}]"


def markdown_table(results: Mapping[str, Any], reference: str = REFERENCE_AGENT) -> str:
    """The summary as a GitHub markdown table (energies in kJ/kg)."""
    rows = summarize(results, reference)
    head = (
        "| agent | success | energy, successes [kJ/kg] | energy on common successes [kJ/kg] "
        f"| × {reference} | regret, median [95 % CI] | regret, mean [95 % CI] "
        "| regret, median of all episodes (failure = inf) [95 % CI] | thermal benefit captured (median) "
        "| circling in lift (median) | flight time [s] | compute / decision [ms] | compute / episode [s] |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n"
    )
    lines = []
    for r in rows:
        lines.append(
            f"| {r['agent']} | {r['successes']}/{r['episodes']} ({_f(100 * r['success_rate'], '.0f')} %) "
            f"| {_f(r['energy_mean'] / 1000, '.2f')} ± {_f(r['energy_std'] / 1000, '.2f')} "
            f"| {_f(r['energy_common'] / 1000, '.2f')} vs {_f(r['energy_common_ref'] / 1000, '.2f')} (n={r['common']}) "
            f"| {_f(r['energy_ratio'], '.2f')} "
            f"| {_ci(r['regret_median'])} | {_ci(r['regret_mean'])} | {_ci(r['regret_all_median'])} "
            f"| {_pct(1 - r['regret_median'][0])} | {_pct(r['circling_in_lift'])} "
            f"| {_f(r['flight_time_mean'], '.0f')} ± {_f(r['flight_time_std'], '.0f')} "
            f"| {_f(1000 * r['compute_per_decision_s'], '.3g')} | {_f(r['compute_total_s'], '.3g')} |"
        )
    return head + "\n".join(lines) + "\n"


def write_report(
    results: Mapping[str, Any],
    out_dir: str | Path,
    reference: str = REFERENCE_AGENT,
    reference_dir: str | Path = "results/reference",
) -> list[Path]:
    """Write ``results.md`` (table + settings) and the plots; returns the files written.
    ``reference_dir``: where the regrets' reference files came from (named in the text)."""
    out = Path(out_dir)
    meta = results["meta"]
    cfg = meta.get("config", {})
    n_sc = len({e["scenario"] for e in results["episodes"]})
    n_seeds = len({e["seed"] for e in results["episodes"]})
    text = (
        markdown_table(results, reference) + f"\n{n_sc} scenarios x {n_seeds} seeds; SST budget per planning call: "
        f"{cfg.get('sst_time_budget')} s / {cfg.get('sst_iterations')} iterations; machine: {meta.get('machine')}.\n"
        "Energy = net specific energy spent (fuel + potential + kinetic) [kJ/kg], mean ± sd over successful "
        f"episodes; 'common' = (scenario, seed) pairs solved by both the agent and {reference}, "
        "× = ratio of those means. Regret r = (E - E_best) / (E_direct - E_best) per successful episode against "
        f"the reference search of its scenario and action set ({Path(reference_dir).as_posix()}/; 0 = best known plan, "
        "1 = no better than ignoring the thermals); thermal benefit captured = 1 - r; the median of all episodes "
        "counts a failed one as unbounded regret (inf). Circling in lift: the fraction "
        "of the flight time turning at >= 6 deg/s (a circle a minute) where the updraft is >= 0.2 m/s. SST knows the "
        "thermal field; compute time includes SST's planning.\n"
    )
    files = [out / TABLE_FILE]
    atomic_write_text(files[0], text)
    files.append(plot_boxes(results, out / "boxplots.png"))
    files.append(plot_trajectories(results, out / "trajectories.png"))
    return files


# --- plots ---------------------------------------------------------------------------------------------
def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _agent_order(results: Mapping[str, Any]) -> list[str]:
    present = {e["agent"] for e in results["episodes"]}
    return [a for a in AGENT_NAMES if a in present] + sorted(present - set(AGENT_NAMES))


def plot_boxes(results: Mapping[str, Any], png: str | Path) -> Path:
    """Box plots of regret (where a reference exists), energy spent [kJ/kg] and flight time [s] per
    agent (successful episodes)."""
    plt = _plt()
    agents = _agent_order(results)
    eps = results["episodes"]
    fig, axes = plt.subplots(1, 3, figsize=(17, 6.0), constrained_layout=True)
    for ax, key, scale, label in (
        (axes[0], "regret", 1.0, "regret (0 = best known, 1 = ignoring the thermals)"),
        (axes[1], "energy_spent", 1e-3, "energy spent [kJ/kg]"),
        (axes[2], "flight_time", 1.0, "flight time [s]"),
    ):
        data = [
            [scale * e[key] for e in eps if e["agent"] == a and e["success"] and e.get(key) is not None] for a in agents
        ]
        ticks = [f"{a} ({len(d)} ok)" for a, d in zip(agents, data, strict=True)]  # one line: many agents
        pos = [i for i, d in enumerate(data) if d]
        if pos:
            ax.boxplot([data[i] for i in pos], positions=pos, widths=0.6, showmeans=True)
        ax.set_xticks(range(len(agents)), ticks, rotation=60, ha="right", rotation_mode="anchor", fontsize=8)
        ax.set_xlim(-0.6, len(agents) - 0.4)
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    for y in (0.0, 1.0):
        axes[0].axhline(y, color="grey", lw=0.8, ls="--")
    axes[0].set_ylim(-0.5, 4.0)  # the random agent's few successes lie far above; see the table
    axes[0].set_title("regret vs the reference search (clipped at 4)")
    axes[1].set_title("energy spent, successful episodes")
    axes[2].set_title("flight time, successful episodes")
    out = Path(png)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def plot_trajectories(
    results: Mapping[str, Any], png: str | Path, scenarios: Sequence[str] | None = None, seed: int | None = None
) -> Path:
    """Top view of each agent's path over the updraft field, one panel per scenario (default: the
    first three scenarios of the results; seed: the first). Contours: updraft [m/s] at the mean of
    start and goal height; circle: goal region; dots: thermal centres."""
    plt = _plt()
    eps = [e for e in results["episodes"] if e.get("path")]
    if not eps:
        raise ValueError("the results hold no paths (keep_paths=False)")
    names = list(scenarios) if scenarios is not None else list(dict.fromkeys(e["scenario"] for e in eps))[:3]
    seed = seed if seed is not None else min(e["seed"] for e in eps)
    agents = _agent_order(results)
    colors = {a: plt.get_cmap("tab10")(i % 10) for i, a in enumerate(agents)}
    fig, axes = plt.subplots(1, len(names), figsize=(5.6 * len(names), 5.6), constrained_layout=True, squeeze=False)
    for ax, sc_name in zip(axes[0], names, strict=True):
        sc = Scenario.from_dict(results["meta"]["scenarios"][sc_name])
        runs = [e for e in eps if e["scenario"] == sc_name and e["seed"] == seed]
        pts = np.array(
            [p for e in runs for p in e["path"]]
            + [[sc.start[0], sc.start[1], sc.start[3]], list(sc.require_goal().centre)]
        )
        lo = pts[:, :2].min(axis=0) - 400.0
        hi = pts[:, :2].max(axis=0) + 400.0
        b = sc.bounds
        lo = np.maximum(lo, [b.north_min, b.east_min])
        hi = np.minimum(hi, [b.north_max, b.east_max])
        nn, ee = np.meshgrid(np.linspace(lo[0], hi[0], 160), np.linspace(lo[1], hi[1], 160), indexing="ij")
        h_ref = 0.5 * (sc.start[3] + sc.require_goal().height)
        w = sc.field.updraft(nn, ee, np.full_like(nn, h_ref))
        if np.ptp(w) > 0:
            cs = ax.contourf(ee, nn, w, levels=12, cmap="Greys", alpha=0.55)
            fig.colorbar(cs, ax=ax, shrink=0.7, label=f"updraft at {h_ref:.0f} m [m/s]")
        c = sc.field.centres()
        if len(c):
            ax.plot(c[:, 1], c[:, 0], "k+", ms=8)
        th = np.linspace(0, 2 * np.pi, 100)
        ax.plot(
            sc.require_goal().east + sc.require_goal().radius * np.sin(th),
            sc.require_goal().north + sc.require_goal().radius * np.cos(th),
            "g-",
            lw=2,
        )
        ax.plot(sc.start[1], sc.start[0], "go", ms=7)
        for e in sorted(runs, key=lambda r: agents.index(r["agent"])):
            p = np.asarray(e["path"])
            style = "-" if e["success"] else ":"
            ax.plot(p[:, 1], p[:, 0], style, color=colors[e["agent"]], lw=1.6, label=f"{e['agent']}")
            ax.plot(p[-1, 1], p[-1, 0], "x" if not e["success"] else ".", color=colors[e["agent"]], ms=7)
        ax.set_xlim(lo[1], hi[1])
        ax.set_ylim(lo[0], hi[0])
        ax.set_aspect("equal")
        ax.set_xlabel("east [m]")
        ax.set_ylabel("north [m]")
        ax.set_title(
            f"{sc_name} (seed {seed}); start height {sc.start[3]:.0f} m, goal {sc.require_goal().height:.0f} m",
            fontsize=9,
        )
        ax.legend(fontsize=7, loc="best")
    out = Path(png)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
