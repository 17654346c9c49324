"""Results of the soaring tasks: the reference search, the heuristic, a direct flyer, a random agent
and, where a goal exists, the SST planner, on the held-out scenarios of every task id (``climb-10000
...``, ``xc-10000 ...``).

Every agent flies through ``env.step``; the reference's plan too (replayed action by action: its
predicted energy and the env's agree bit for bit, which :func:`run_task_job` checks). Scores:

* thermal climb -- the energy gained ``-energy_spent`` [J/kg] over the time limit, and its fraction
  of the reference search's (:func:`baselines.reference.horizon.energy_search`) in that scenario;
* cross-country -- success (the goal reached before the battery is empty), the battery left
  [fraction of the budget] and the energy spent [J/kg]; the reference is the goal-reaching beam
  search with the battery as a budget (:func:`baselines.reference.beam.search`).
"""

from __future__ import annotations

import json
import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from baselines._runs import read_json
from baselines.agents import (
    HeuristicAgent,
    PPOAgent,
    RandomAgent,
    ReplayAgent,
    SSTPlannerAgent,
    ThermallingAgent,
)
from baselines.evaluation import bootstrap_ci, file_digest, median_circling, ppo_env_kwargs, run_episode
from baselines.reference.tasks import DEFAULT_BEAM_WIDTH, REFERENCE_VERSION, reference_plan
from soaring_env._validation import ConfigError, check_choice
from soaring_env.scenario import HELDOUT_SEED0, get_scenario, heldout_names

#: The task ids and their scenario families.
TASK_FAMILIES = {
    "soaring/ThermalClimb-v0": "climb",
    "soaring/ThermalClimbContinuous-v0": "climb",
    "soaring/CrossCountry-v0": "xc",
    "soaring/CrossCountryContinuous-v0": "xc",
}
AGENTS = ("reference", "heuristic", "thermalling", "direct", "random", "sst")
#: The agents of a run that names none: SST (minutes per episode) only when asked for.
DEFAULT_AGENTS = AGENTS[:-1]
#: SST's iteration budget per planning call (random expansions plus the seeding search's edges,
#: :class:`~baselines.sst.planner.SeededSST`): an iteration budget makes its episodes deterministic
#: and independent of the machine's load.
SST_ITERATIONS = 2_000_000
#: Task ids the ``"sst"`` agent does not fly, and why (the table says so).
SST_SKIPPED = {
    "soaring/CrossCountry-v0": "no primitive plan within the battery exists: the reference search finds none on "
    "any of the 100 held-out scenarios, and a battery-aware SST replans until the battery is empty (about 3 min "
    "an episode)",
}
#: The label of a trained PPO run's rows (``task_jobs(ppo_runs=...)``): ``"ppo"`` for PPO-continuous,
#: ``"ppo-<algo>"`` for the others (:func:`ppo_label`).
PPO = "ppo"
#: Every label a PPO run's rows can carry, in table order.
PPO_LABELS = (PPO, f"{PPO}-grid", f"{PPO}-discrete", f"{PPO}-masked")
#: The scenario whose flown paths the results keep (the trajectories figure's), per family.
FIGURE_SCENARIO = {"climb": "climb-10000", "xc": "xc-10000"}
#: Bumped when the agents' episode records gain fields (2: circling fractions) or an agent's rule
#: changes: their records of another version are redone (the reference's cost minutes; they are not).
RECORD_VERSION = 2


@dataclass(frozen=True)
class TaskJob:
    """One episode: ``agent`` on held-out ``scenario`` of ``env_id`` (seed: the env's and the agent's)."""

    env_id: str
    scenario: str
    agent: str
    seed: int
    beam_width: int = DEFAULT_BEAM_WIDTH
    #: the PPO run directory (agents of :data:`PPO_LABELS`; its ``model.zip`` and ``config.json``)
    run: str = ""
    #: SST's iteration budget per planning call (agent ``"sst"``)
    sst_iterations: int = SST_ITERATIONS

    def key(self) -> str:
        return f"{self.env_id}|{self.scenario}|{self.agent}|{self.seed}"

    def settings(self) -> dict[str, Any]:
        """What makes a finished record current (a rerun redoes records made otherwise)."""
        if self.agent == "reference":
            return {"beam_width": self.beam_width, "reference_version": REFERENCE_VERSION}
        if self.agent in PPO_LABELS:
            model = Path(self.run) / "model.zip"
            digest = file_digest(model) if model.exists() else None
            return {"run": self.run, "sha256": digest, "record_version": RECORD_VERSION}
        if self.agent == "sst":
            from baselines.sst.soaring import DEFAULT_SST_CONFIG, planner_record

            sampler = "continuous" if self.env_id.endswith("Continuous-v0") else "primitive"
            settings = {
                "iterations": self.sst_iterations,
                **planner_record(DEFAULT_SST_CONFIG, sampler),
                "battery_aware": True,  # its plans keep within the battery (records made before are redone)
                "record_version": RECORD_VERSION,
            }
            return json.loads(json.dumps(settings))  # as a results file holds it (tuples as lists)
        if self.agent == "thermalling":  # the rule's version and settings: a changed rule flies again
            return {"record_version": RECORD_VERSION, **ThermallingAgent().settings()}
        if self.agent in ("heuristic", "direct"):  # the rule's version: a changed rule flies again
            return {"record_version": RECORD_VERSION, **HeuristicAgent().settings()}
        return {"record_version": RECORD_VERSION}


def task_jobs(
    env_ids: Sequence[str],
    n_scenarios: int,
    agents: Sequence[str],
    beam_width: int = DEFAULT_BEAM_WIDTH,
    ppo_runs: Sequence[str] = (),
    first_seed: int = HELDOUT_SEED0,
    sst_iterations: int = SST_ITERATIONS,
) -> list[TaskJob]:
    """Every (task id, held-out scenario, agent) job, seed 0; each PPO run directory adds an agent
    (:func:`ppo_label`) on the task id it was trained on (its ``config.json``). ``first_seed``:
    the scenarios' first seed (:data:`~soaring_env.scenario.VALIDATION_SEED0`: the validation
    scenarios, to choose a policy without looking at the test set). ``"direct"`` and ``"sst"``
    fly only where there is a goal (cross-country), ``"sst"`` not on the ids of :data:`SST_SKIPPED`."""
    for e in env_ids:
        check_choice("env_id", e, tuple(TASK_FAMILIES))
    for a in agents:
        check_choice("agent", a, AGENTS)
    runs: dict[str, dict[str, str]] = {}  # env id -> label -> run
    for r in ppo_runs:
        cfg = Path(r) / "config.json"
        if not cfg.is_file():
            raise ConfigError(f"ppo run {r!r} has no config.json; give a directory written by scripts/train_ppo.py")
        record = read_json(cfg, "PPO run configuration")
        env_id = str(record.get("env_id"))
        check_choice(f"the env id of ppo run {r!r}", env_id, tuple(TASK_FAMILIES))
        label = ppo_label(record)
        if label in runs.get(env_id, {}):
            raise ConfigError(
                f"two {label} runs for {env_id}: {runs[env_id][label]!r} and {r!r}; give one per task id and algo"
            )
        runs.setdefault(env_id, {})[label] = str(r)
    jobs = []
    for env_id in env_ids:
        fam = TASK_FAMILIES[env_id]
        for sc in heldout_names(n_scenarios, start=first_seed, family=fam):
            for agent in agents:
                if agent in ("direct", "sst") and fam != "xc":
                    continue  # no goal to fly to
                if agent == "sst" and env_id in SST_SKIPPED:
                    continue
                jobs.append(TaskJob(env_id, sc, agent, 0, beam_width, sst_iterations=sst_iterations))
            for label, run in runs.get(env_id, {}).items():
                jobs.append(TaskJob(env_id, sc, label, 0, beam_width, run))
    return jobs


def ppo_label(run_record: Mapping[str, Any]) -> str:
    """The rows' label of a PPO run (its ``config.json``): ``"ppo"`` (continuous) or ``"ppo-<algo>"``."""
    algo = str(run_record.get("algo", run_record.get("config", {}).get("algo", "continuous")))
    label = PPO if algo == "continuous" else f"{PPO}-{algo}"
    check_choice("the algo of a ppo run", label, PPO_LABELS)
    return label


def run_task_job(job: TaskJob) -> dict[str, Any]:
    """One episode record (see the module docstring); module level, so it runs in worker processes."""
    is_ppo = job.agent in PPO_LABELS
    own = ppo_env_kwargs(read_json(Path(job.run) / "config.json", "PPO run configuration")) if is_ppo else {}
    env = gym.make(job.env_id, **own)
    sc = get_scenario(job.scenario)
    base: Any = env.unwrapped
    ref_stats: dict[str, Any] | None = None
    agent: Any
    if job.agent == "reference":
        env.reset(seed=job.seed, options={"scenario": sc})
        actions, ref_stats = reference_plan(env, job.beam_width)
        if not ref_stats["found"]:
            env.close()
            return {**_ids(job), "job_settings": job.settings(), "found": False, "reference": ref_stats}
        agent = ReplayAgent(actions, name="reference")
    elif job.agent == "heuristic":
        agent = HeuristicAgent()
    elif job.agent == "thermalling":
        agent = ThermallingAgent()
    elif job.agent == "direct":
        agent = HeuristicAgent(lift_threshold=math.inf, name="direct")  # never circles
    elif job.agent == "sst":  # the default (seeded) configuration; the sampler follows the action space
        agent = SSTPlannerAgent(time_limit=None, max_iterations=job.sst_iterations, name="sst")
    elif is_ppo:
        agent = PPOAgent(job.run, name=job.agent)
    else:
        agent = RandomAgent()
    # flown points only for the first held-out scenario of each id (the figure's): files stay small
    rec = run_episode(env, agent, sc, job.seed, keep_path=job.scenario == FIGURE_SCENARIO[TASK_FAMILIES[job.env_id]])
    rec.update(_ids(job))
    rec["job_settings"] = job.settings()
    rec["found"] = True
    rec["energy_gained"] = -rec["energy_spent"]
    if base.has_battery:
        rec["battery_left"] = max(float(base.battery_left), 0.0) / float(base.battery)  # the last edge may overdraw
    if ref_stats is not None:
        rec["reference"] = ref_stats
        # the plan itself (a later rescoring replays it instead of searching again)
        rec["actions"] = [a.tolist() if isinstance(a, np.ndarray) else int(a) for a in actions]
        if ref_stats["predicted_energy"] != rec["energy_gained"]:
            raise RuntimeError(
                f"{job.key()}: the reference plan predicted {ref_stats['predicted_energy']!r} J/kg, "
                f"env.step gave {rec['energy_gained']!r}"
            )
    env.close()
    return rec


def _ids(job: TaskJob) -> dict[str, Any]:
    return {"env_id": job.env_id, "scenario": job.scenario, "agent": job.agent, "seed": job.seed}


def summarize(episodes: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One row per (task id, agent): episodes, successes, median energy gained, median fraction of
    the reference's energy (climb; per scenario, where the reference gained energy), each with a
    seeded percentile-bootstrap 95 % interval, and the battery left."""
    ref = {
        (e["env_id"], e["scenario"]): e["energy_gained"]
        for e in episodes
        if e["agent"] == "reference" and e.get("found")
    }
    rows = []
    for env_id in TASK_FAMILIES:
        for agent in (*AGENTS, *PPO_LABELS):
            eps = [e for e in episodes if e["env_id"] == env_id and e["agent"] == agent]
            if not eps:
                continue
            flown = [e for e in eps if e.get("found", True)]
            gained = [e["energy_gained"] for e in flown]
            frac = [
                e["energy_gained"] / ref[(env_id, e["scenario"])]
                for e in flown
                if ref.get((env_id, e["scenario"]), 0.0) > 0.0
            ]
            battery = [e["battery_left"] for e in flown if "battery_left" in e]
            outcomes: dict[str, int] = {}
            for e in flown:
                outcomes[e["outcome"]] = outcomes.get(e["outcome"], 0) + 1
            rows.append(
                {
                    "env_id": env_id,
                    "agent": agent,
                    "episodes": len(eps),
                    "no_plan": len(eps) - len(flown),
                    "success": sum(bool(e["success"]) for e in flown),
                    "energy_gained_median": bootstrap_ci(gained, np.median),
                    "fraction_of_reference_median": bootstrap_ci(frac, np.median),
                    "battery_left_median": statistics.median(battery) if battery else math.nan,
                    "circling_in_lift": median_circling(flown),
                    "outcomes": outcomes,
                }
            )
    return rows


def markdown_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """The summary as a markdown table (energies in kJ/kg)."""

    def num(v: Any, fmt: str, unit: str = "", scale: float = 1.0) -> str:
        """A number, or (value, low, high) as "value [low, high]" (a 95 % interval over > 1 episode)."""
        if isinstance(v, tuple):
            if math.isnan(v[0]):
                return "—"
            ci = f" [{v[1] * scale:{fmt}}, {v[2] * scale:{fmt}}]" if v[1] != v[2] else ""
            return format(v[0] * scale, fmt) + unit + ci
        return "—" if v is None or math.isnan(v) else format(v * scale, fmt) + unit

    lines = [
        "| task id | agent | episodes | success | energy gained, median [95 % CI] [kJ/kg] "
        "| of the reference's (median [95 % CI]) | battery left (median) | circling in lift (median) | outcomes |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        xc = TASK_FAMILIES[r["env_id"]] == "xc"
        flown = r["episodes"] - r["no_plan"]
        succ = f"{r['success']}/{flown}" if xc else "—"
        if r["no_plan"]:
            succ += f" ({r['no_plan']} without a plan)" if xc else f"{r['no_plan']} without a plan"
        outcomes = ", ".join(f"{k} {v}" for k, v in sorted(r["outcomes"].items()))
        lines.append(
            f"| `{r['env_id'].split('/')[1]}` | {r['agent']} | {r['episodes']} | {succ} | "
            f"{num(r['energy_gained_median'], '.2f', scale=1e-3)} | "
            f"{'—' if xc else num(r['fraction_of_reference_median'], '.0f', ' %', 100.0)} | "
            f"{num(r['battery_left_median'], '.0f', ' %', 100.0) if xc else '—'} | "
            f"{num(r['circling_in_lift'], '.0f', ' %', 100.0)} | {outcomes} |"
        )
    if any(r["agent"] == "sst" for r in rows):
        lines += ["", *(f"SST does not fly `{e.split('/')[1]}`: {why}." for e, why in SST_SKIPPED.items())]
    return "\n".join(lines) + "\n"


def check_episodes(data: Any, where: str) -> list[dict[str, Any]]:
    """The episode list of a results file, or a ConfigError naming it."""
    if not isinstance(data, dict) or not isinstance(data.get("episodes"), list):
        raise ConfigError(f"{where} is not a task results file (no 'episodes' list); move it away and run again")
    return list(data["episodes"])


def path_array(ep: Mapping[str, Any]) -> np.ndarray:
    """The flown points (M, 3) [north, east, height] of an episode record."""
    return np.asarray(ep.get("path") or [], dtype=np.float64).reshape(-1, 3)
