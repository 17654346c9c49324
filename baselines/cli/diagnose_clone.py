"""Diagnose a cloned primitive policy (docs/learning-to-soar.md, round ten): where does its regret come from?

Measurements for the successor policies of ``scripts/train_ppo.py --algo discrete --set
'policy="successor"'`` and their demonstrations, each written as JSON (``--out``) and printed:

* ``fit``: how well the policy fits demonstrations (``--demos`` folder, ``--match`` regular
  expression over scenario names): mean negative log-likelihood of the demonstrated primitive, the
  share of rows whose most likely primitive is the demonstrated one, and the share of the other
  rows whose successor is *near-equivalent* to the demonstrated one
  (:func:`baselines.scoring.near_equivalent`: end points within 50 m, heights within 10 m, edge
  costs within 20 J/kg -- e.g. a 360 against a 720 degree circle; before round twelve: the goal
  distance instead of the end point, docs/learning-to-soar.md) or *different* (everything
  else); separately for the rows a DAgger round labelled (a visited state: the first row of a
  ``-<tag>s<k>`` plan).
* ``decisions`` (round nineteen): the run's pick at every state of lookahead plans (``--match``;
  ``scripts/demos.py --self-imitate RUN --lookahead C``) against the cheapest of the primitives
  tried there, by the step's index in the plan: where in the flight the policy loses energy.
* ``demonstrator``: the regret of the demonstrator itself (the goal env's own search with the time
  weight and beam width of ``scripts/demos.py``) on scenarios outside its training set, its plans
  replayed through ``env.step`` and scored against ``--reference-dir``.
* ``consistency`` (docs/learning-to-soar.md, round eleven): how often the demonstrator labels a state of its own plans
  as it would from there: from states along the plans (``--match``, default the base plans;
  ``--samples`` of them, ``--seed``) the same search plans again; the share that picks the plan's
  next primitive, and whether the other picks are cheaper or dearer. Where the clones agree with
  the demonstrations far less often than that, their labels are not what holds them back.
* ``ensemble``: the regret of the runs' policies side by side, the mean of their logits deciding
  (one run: the policy itself, as ``scripts/evaluate.py`` flies it); ``--lead N --plans DIR``: the
  first N steps flown by the demonstrator's plans (a ``demonstrator`` run's ``plans`` folder), the
  policy taking over from there (docs/learning-to-soar.md, round eleven: where in the flight the clones lose);
  ``--repeat-bonus B``: the primitive flown last gets B added to its logit (round twelve).
* ``sampled`` (round thirteen): what lies within one run's reach: per scenario its mode's episode
  and ``--samples`` episodes drawn from its logits (``--temperature``,
  :func:`baselines.imitation.sampled_episodes`), the best of them by energy scored. Not an agent
  (it picks with the simulator): the headroom ``scripts/demos.py --self-imitate`` clones from.
* ``rollout`` (round fourteen): one run's mode improved by one-step lookahead
  (:func:`baselines.imitation.rollout_improved`): at each step (the first ``--steps``) each of the
  ``--candidates`` primitives of largest logit is tried, the mode flying on, and the cheapest kept.
  Also not an agent: the policy-improvement step that ``scripts/demos.py --self-imitate RUN
  --lookahead C`` clones from.

Scenario sets (``--on``): ``val`` = ``random-5000 ... 5019`` against ``results/reference-val``
(narrow primitive references, made for this round), ``h21`` = ``paper`` + ``random-10000 ...
10019`` against the yardstick (``results/reference``), ``h100`` = ``paper`` + ``random-10000 ...
10099`` against ``results/reference-heldout100``, ``val100`` = ``random-5000 ... 5099`` against
``results/reference-val100`` (made as ``h100``'s, round eighteen): where runs or seeds are chosen.

Usage::

    python scripts/diagnose_clone.py fit --runs results/ppo-score/s3 --match 'random-201[2-7]\\d-s3s\\d+'
    python scripts/diagnose_clone.py decisions --runs results/ppo-score/n2-s0 --match 'random-99\\d\\d\\d-n3s0'
    python scripts/diagnose_clone.py demonstrator --on val --out results/ppo-score/round10/demonstrator
    python scripts/diagnose_clone.py consistency --samples 60 --out results/ppo-score/round11/consistency
    python scripts/diagnose_clone.py ensemble --runs results/ppo-score/s2 results/ppo-score/s3 --on h100
    python scripts/diagnose_clone.py sampled --runs results/ppo-score/m3-s0 --samples 32 --on val
    python scripts/diagnose_clone.py rollout --runs results/ppo-score/m3-s0 --candidates 8 --on val
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from baselines._runs import check_cli_args
from soaring_env._validation import ConfigError
from soaring_env.scenario import atomic_write_text

#: The scenario sets of ``--on``: (names, reference folder).
SETS: dict[str, tuple[list[str], str]] = {
    "val": ([f"random-{5000 + i}" for i in range(20)], "results/reference-val"),
    # 100 validation scenarios against primitive references made as h100's: picking a run or a seed
    # by its score here leaves the held-out scenarios unseen.
    "val100": ([f"random-{5000 + i}" for i in range(100)], "results/reference-val100"),
    "h21": (["paper"] + [f"random-{10000 + i}" for i in range(20)], "results/reference"),
    "h100": (["paper"] + [f"random-{10000 + i}" for i in range(100)], "results/reference-heldout100"),
}

#: The env the demonstrations were planned and flown in.
DEMO_ENV_ID = "soaring/Soaring-v0"


def _run_dir(run: str | Path) -> Path:
    """``RUN`` or ``RUN/discrete``: the folder holding ``model.zip`` and ``config.json``."""
    d = Path(run)
    if not (d / "model.zip").is_file() and (d / "discrete" / "model.zip").is_file():
        d = d / "discrete"
    if not (d / "model.zip").is_file() or not (d / "config.json").is_file():
        raise ConfigError(f"run={str(run)!r}: no model.zip beside a config.json (a scripts/train_ppo.py run)")
    cfg = json.loads((d / "config.json").read_text())
    if cfg.get("algo") != "discrete" or cfg.get("config", {}).get("policy") != "successor":
        raise ConfigError(f"run={str(run)!r} is not a successor policy (--algo discrete, policy='successor')")
    return d


def _logits(policy: Any, obs: np.ndarray) -> np.ndarray:
    """The policy's logits (B, 174) for body-frame observations, in blocks."""
    import torch

    with torch.no_grad():
        out = [
            policy.get_distribution(torch.as_tensor(obs[i : i + 512])).distribution.logits.numpy()
            for i in range(0, len(obs), 512)
        ]
    return np.concatenate(out)


def _policy_and_plans(run: str | Path, demos_dir: str | Path, match: str | None) -> tuple[Path, Any, Any]:
    """One run's folder and model, and the demonstrations that ``match`` selects replayed in its env."""
    from baselines.imitation import demonstrations
    from baselines.ppo import load_model, make_eval_env

    d = _run_dir(run)
    c = json.loads((d / "config.json").read_text())["config"]
    model = load_model(d / "model.zip", "discrete")
    plans = demonstrations(
        str(demos_dir),
        lambda sc: make_eval_env(
            c["env_id"], [sc], c["env_kwargs"], True, c["turn_exponent"], False, bool(c["final_glide"])
        ),
        sampler="primitive",
        gamma=float(c["gamma"]),
        match=match,
    )
    return d, model, plans


def fit_report(run: str | Path, demos_dir: str | Path, match: str | None) -> dict[str, Any]:
    """The ``fit`` measurement of one run on the demonstrations that ``match`` selects."""
    from baselines.scoring import accepted_successors

    d, model, plans = _policy_and_plans(run, demos_dir, match)
    obs, act = plans.observations, plans.actions.astype(np.int64)
    lg = _logits(model.policy, obs)
    lp = lg - lg.max(axis=1, keepdims=True)
    lp = lp - np.log(np.exp(lp).sum(axis=1, keepdims=True))
    i = np.arange(len(act))
    best = lg.argmax(axis=1)
    near = accepted_successors(model.policy.mlp_extractor.policy_net.features, obs, act)[i, best]
    right = best == act
    visited = np.zeros(len(act), bool)
    starts = np.r_[True, plans.episode[1:] != plans.episode[:-1]]
    dagger = np.array([re.search(r"-[A-Za-z0-9]*s\d+$", s) is not None for s in plans.scenarios])  # <name>-<tag>s<k>
    visited[starts] = dagger[plans.episode[starts]]

    def shares(m: np.ndarray) -> dict[str, float]:
        n = max(int(m.sum()), 1)
        return {
            "rows": int(m.sum()),
            "nll": float(-lp[i[m], act[m]].mean()) if m.any() else float("nan"),
            "top1": float(right[m].sum() / n),
            "near_equivalent": float((~right & near)[m].sum() / n),
            "different": float((~right & ~near)[m].sum() / n),
        }

    return {
        "run": str(d),
        "match": match,
        "plans": len(plans.scenarios),
        "all": shares(np.ones(len(act), bool)),
        "visited": shares(visited),
    }


#: ``decisions``: the step groups reported, (label, first step, last step).
STEP_GROUPS = (("0", 0, 0), ("1", 1, 1), ("2", 2, 2), ("3", 3, 3), ("4-7", 4, 7), ("8+", 8, 10**9), ("all", 0, 10**9))


def decisions_report(run: str | Path, demos_dir: str | Path, match: str | None) -> dict[str, Any]:
    """The ``decisions`` measurement: one run's pick at every state of lookahead plans (the plans'
    ``candidate_costs``: each tried primitive's energy with the trying policy's mode flying on)
    against the cheapest primitive tried there, by the step's index in its plan.

    Per group of steps: ``rows`` (states where some tried primitive reached the goal), ``excess``
    (mean energy [J/kg] of the pick's episode above the cheapest, over the rows whose pick was
    tried and reached the goal), ``best`` (share of rows picking a cheapest), ``untried`` (share
    whose pick was not tried or missed the goal: no cost to compare)."""
    from baselines.reference.yardstick import load_references

    d, model, plans = _policy_and_plans(run, demos_dir, match)
    names = set(plans.scenarios)
    refs = load_references(demos_dir, select=lambda n: n in names)
    costs: list[dict[int, float]] = []
    for name in plans.scenarios:
        steps = refs[name].samplers["primitive"].candidate_costs
        if not steps:
            raise ConfigError(f"{name}: no candidate costs (not a lookahead plan: scripts/demos.py --lookahead)")
        costs += [{int(a): float(c) for a, c in step if c is not None} for step in steps]
    if len(costs) != len(plans):
        raise ConfigError(f"{len(costs)} steps of candidate costs for {len(plans)} replayed rows")
    pick = _logits(model.policy, plans.observations).argmax(axis=1)
    starts = np.flatnonzero(np.r_[True, plans.episode[1:] != plans.episode[:-1]])
    step = np.arange(len(plans)) - starts[np.searchsorted(starts, np.arange(len(plans)), side="right") - 1]
    labelled = np.array([bool(c) for c in costs])
    excess = np.array([c[a] - min(c.values()) if a in c else np.nan for c, a in zip(costs, pick.tolist(), strict=True)])
    groups = {}
    for label, lo, hi in STEP_GROUPS:
        m = labelled & (step >= lo) & (step <= hi)
        tried = m & np.isfinite(excess)
        n = max(int(m.sum()), 1)
        groups[label] = {
            "rows": int(m.sum()),
            "excess": float(excess[tried].mean()) if tried.any() else float("nan"),
            "best": float((tried & (excess <= 1e-9)).sum() / n),
            "untried": float((m & ~tried).sum() / n),
        }
    return {"run": str(d), "match": match, "plans": len(plans.scenarios), "steps": groups}


def _demo_search(
    scenarios: list[Any],
    out_dir: Path,
    prefixes: dict[str, list[Any]],
    beam_width: int,
    time_weight: float,
    workers: int,
    progress: bool,
) -> dict[str, Any]:
    """The demonstrations' own search (the goal env's, as ``scripts/demos.py`` runs it) on
    ``scenarios`` after the env actions ``prefixes`` (by name), its plans kept in ``out_dir`` (a
    rerun resumes): the references by scenario name."""
    import gymnasium as gym

    import soaring_env  # noqa: F401  (registers the ids)
    from baselines.reference import ReferenceConfig
    from baselines.reference.runner import run_references
    from baselines.reference.tasks import reference_config

    env = gym.make(DEMO_ENV_ID)
    cfg = reference_config(env, beam_width, time_weight, 0.0)
    env.close()
    assert isinstance(cfg, ReferenceConfig)  # the goal task's search (not the climb's horizon search)
    return run_references(
        scenarios,
        out_dir,
        samplers=("primitive",),
        config=cfg,
        workers=workers,
        progress=progress,
        env_id=DEMO_ENV_ID,
        prefixes=prefixes,
        env_kwargs=None,
    )


def demonstrator_report(
    on: str, out: Path, beam_width: int, time_weight: float, workers: int, progress: bool
) -> dict[str, Any]:
    """The ``demonstrator`` measurement: plans of the demos' search on ``on``'s scenarios (kept in
    ``out/plans``; a rerun resumes), replayed through ``env.step`` and scored."""
    import gymnasium as gym

    from baselines.reference import load_references
    from soaring_env.scenario import get_scenario

    names, ref_dir = SETS[on]
    plans = _demo_search(
        [get_scenario(n) for n in names], out / "plans", {}, beam_width, time_weight, workers, progress
    )
    refs = load_references(ref_dir)
    env = gym.make(DEMO_ENV_ID)
    rows = []
    for n in names:
        _, info = env.reset(seed=0, options={"scenario": get_scenario(n)})
        for a in plans[n].samplers["primitive"].actions:
            _, _, term, trunc, info = env.step(int(a))
            if term or trunc:
                break
        e = float(info["energy_spent"])
        r = refs[n].regret(e, "primitive") if n in refs and info.get("is_success") else float("nan")
        rows.append({"scenario": n, "success": bool(info.get("is_success")), "energy_spent": e, "regret": r})
    env.close()
    return {"on": on, "beam_width": beam_width, "time_weight": time_weight, "episodes": rows}


def consistency_report(
    demos_dir: str | Path,
    match: str,
    samples: int,
    seed: int,
    out: Path,
    beam_width: int,
    time_weight: float,
    workers: int,
    progress: bool,
) -> dict[str, Any]:
    """The ``consistency`` measurement: from ``samples`` states along the demonstrations' own plans
    (plans ``match`` selects, drawn with ``seed``; a state after 1 .. n - 2 of a plan's n steps), the
    same search plans again (kept in ``out/plans`` as ``<name>-conss<k>``; a rerun resumes). Where it
    picks the plan's next primitive, the demonstrations label that state as their own search
    would; the cost columns say whether the new plan is cheaper or dearer than the rest of the old."""
    import math

    from baselines.imitation import demo_plans
    from baselines.reference import load_references

    pool = [(sc, acts) for sc, acts in demo_plans(demos_dir, sampler="primitive", match=match) if len(acts) >= 3]
    if not pool:
        raise ConfigError(f"match={match!r}: no plan of 3 or more steps in {str(demos_dir)!r}")
    rng = np.random.default_rng(seed)
    starts: dict[str, tuple[Any, int, tuple[Any, ...]]] = {}
    while len(starts) < min(samples, sum(len(a) - 2 for _, a in pool)):
        sc, acts = pool[int(rng.integers(len(pool)))]
        k = int(rng.integers(1, len(acts) - 1))
        starts.setdefault(f"{sc.name}-conss{k}", (sc, k, acts))
    base = load_references(demos_dir, {sc.name for sc, _, _ in starts.values()}.__contains__)
    again = _demo_search(
        [sc.replace(name=name) for name, (sc, _, _) in starts.items()],
        out / "plans",
        {name: list(acts[:k]) for name, (_, k, acts) in starts.items()},
        beam_width,
        time_weight,
        workers,
        progress,
    )
    rows = []
    for name, (sc, k, acts) in starts.items():
        new = again[name].samplers["primitive"]
        old_cost = base[sc.name].samplers["primitive"].best_cost
        rows.append(
            {
                "state": name,
                "plan_primitive": int(acts[k]),
                "replanned_primitive": int(new.actions[k]) if len(new.actions) > k else None,
                "delta_cost": float(new.best_cost - old_cost) if math.isfinite(new.best_cost) else math.inf,
            }
        )
    agree = np.array([r["plan_primitive"] == r["replanned_primitive"] for r in rows])
    delta = np.array([r["delta_cost"] for r in rows])
    summary = {
        "states": len(rows),
        "agree": float(agree.mean()),
        "cheaper_by_more_than_5": int((delta < -5.0).sum()),
        "dearer_by_more_than_5": int((delta > 5.0).sum()),
        "other_primitive_within_5": int((~agree & (np.abs(delta) <= 5.0)).sum()),
        "median_delta_where_other": float(np.median(delta[~agree])) if (~agree).any() else 0.0,
    }
    return {"demos": str(demos_dir), "match": match, "seed": seed, "states": rows, "consistency": summary}


def ensemble_report(
    runs: list[str], on: str, lead: int = 0, plans_dir: str | Path | None = None, repeat_bonus: float = 0.0
) -> dict[str, Any]:
    """The ``ensemble`` measurement: one deterministic episode per scenario of ``on``; with ``lead``
    > 0 the first ``lead`` steps are those of the demonstrator's plan of the scenario (the plans of
    a ``demonstrator`` run, ``plans_dir``), the policy flying on from there; with ``repeat_bonus``
    > 0 the primitive flown last gets that much added to its mean logit (docs/learning-to-soar.md, round twelve:
    does keeping a manoeuvre help?)."""
    if not (isinstance(repeat_bonus, (int, float)) and 0.0 <= repeat_bonus < math.inf):
        raise ConfigError(f"--repeat-bonus={repeat_bonus!r} must be a finite number >= 0 (logit units)")
    from baselines.agents import PPOAgent
    from baselines.evaluation import episode_regret, make_env, ppo_env_kwargs, resolve_scenario, run_episode
    from baselines.reference import load_references

    names, ref_dir = SETS[on]
    refs = load_references(ref_dir)
    scenarios = [resolve_scenario(n, {}) for n in names]
    led: dict[str, list[Any]] = {}
    if lead > 0:
        if plans_dir is None:
            raise ConfigError("--lead needs --plans (the plans folder of a demonstrator run)")
        found = load_references(plans_dir)
        missing = [sc.name for sc in scenarios if sc.name not in found]
        if missing:
            raise ConfigError(
                f"--plans={str(plans_dir)!r} has no plan of {', '.join(missing[:3])} (run demonstrator --on {on})"
            )
        led = {sc.name: list(found[sc.name].samplers["primitive"].actions[:lead]) for sc in scenarios}
    agents = [PPOAgent(_run_dir(r) / "model.zip") for r in runs]
    env = make_env(agents[0].env_id, ppo_env_kwargs(agents[0].config))

    class MeanOfLogits:
        """The runs side by side: the primitive with the largest mean logit (after the lead)."""

        def __init__(self) -> None:
            self.lead: list[Any] = []  # this episode's first steps
            self.steps = 0
            self.last = -1  # the primitive flown last (-1: none yet)

        def reset(self, env: Any, seed: int | None = None) -> None:
            for a in agents:
                a.reset(env, seed)
            self.steps = 0
            self.last = -1

        def predict(self, observation: Any, deterministic: bool = True) -> tuple[Any, None]:
            k, self.steps = self.steps, self.steps + 1
            if k < len(self.lead):
                self.last = int(self.lead[k])
            else:
                mean = np.mean([a.logits(observation) for a in agents], axis=0)
                if self.last >= 0:
                    mean[self.last] += repeat_bonus
                self.last = int(np.argmax(mean))
            return np.int64(self.last), None

    agent = MeanOfLogits()
    rows = []
    for n, sc in zip(names, scenarios, strict=True):
        agent.lead = led.get(sc.name, [])
        ep = run_episode(env, agent, sc, 0, keep_path=False)
        ep.update(scenario=n, env_id=agents[0].env_id)
        r = episode_regret(ep, refs)
        rows.append({"scenario": n, "success": ep["success"], "energy_spent": ep["energy_spent"], "regret": r})
    env.close()
    return {
        "on": on,
        "runs": [str(_run_dir(r)) for r in runs],
        "lead": lead,
        "repeat_bonus": float(repeat_bonus),
        "episodes": rows,
    }


def sampled_report(
    run: str, on: str, samples: int, temperature: float, candidates: int = 0, steps: int | None = None
) -> dict[str, Any]:
    """The ``sampled`` measurement: per scenario of ``on`` the best (least energy, reaching the goal)
    of one run's mode and ``samples`` episodes drawn from its logits, seeded by the scenario's
    position in the set; ``episodes`` holds the best, ``greedy`` the mode's. With ``candidates`` > 0
    the ``rollout`` measurement instead: the mode improved by one-step lookahead over that many
    actions per step, the first ``steps`` steps (:func:`baselines.imitation.rollout_improved`)."""
    from baselines.agents import PPOAgent
    from baselines.evaluation import episode_regret, make_env, ppo_env_kwargs, resolve_scenario
    from baselines.imitation import best_reached, rollout_improved, sampled_episodes
    from baselines.reference import load_references

    names, ref_dir = SETS[on]
    refs = load_references(ref_dir)
    agent = PPOAgent(_run_dir(run) / "model.zip")
    env = make_env(agent.env_id, ppo_env_kwargs(agent.config))
    agent.reset(env)

    def row(name: str, ep: dict[str, Any] | None) -> dict[str, Any]:
        if ep is None:  # no episode reached the goal
            return {"scenario": name, "success": False, "energy_spent": None, "regret": None}
        rec = {"scenario": name, "success": ep["success"], "energy_spent": ep["energy_spent"], "env_id": agent.env_id}
        return {**rec, "regret": episode_regret(rec, refs)}

    best_rows, greedy_rows, tried = [], [], 0
    for k, name in enumerate(names):
        sc = resolve_scenario(name, {})
        best: dict[str, Any] | None
        if candidates > 0:
            greedy, best = rollout_improved(env, agent.logits, sc, candidates=candidates, steps=steps)
            tried += best["tried"]
        else:
            eps = sampled_episodes(env, agent.logits, sc, samples=samples, temperature=temperature, seed=k)
            greedy, best = eps[0], best_reached(eps)
        best_rows.append(row(name, best))
        greedy_rows.append(row(name, greedy))
    env.close()
    method = (
        {"candidates": candidates, "steps": steps, "episodes_flown": tried}
        if candidates > 0
        else {"samples": samples, "temperature": temperature}
    )
    return {"on": on, "run": str(_run_dir(run)), **method, "episodes": best_rows, "greedy": greedy_rows}


def regret_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Median and mean regret over the successful episodes with a regret, the count <= 0.6, failures."""
    r = np.array([x["regret"] for x in rows if x["success"] and x["regret"] is not None], float)
    r = r[~np.isnan(r)]
    return {
        "episodes": len(rows),
        "with_regret": len(r),
        "median": float(np.median(r)) if len(r) else float("nan"),
        "mean": float(np.mean(r)) if len(r) else float("nan"),
        "at_most_0.6": int((r <= 0.6).sum()),
        "failures": sum(not x["success"] for x in rows),
    }


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "mode", choices=("fit", "decisions", "demonstrator", "consistency", "ensemble", "sampled", "rollout")
    )
    p.add_argument("--runs", nargs="+", default=[], help="successor-policy runs (fit: each; ensemble: together)")
    p.add_argument("--demos", default="results/reference-train-prim-t1", help="fit: the demonstrations' folder")
    p.add_argument(
        "--match",
        default=None,
        help="fit, decisions, consistency: only the scenario names matching this regular expression "
        "(consistency: default the base plans, random-20\\d\\d\\d)",
    )
    p.add_argument("--samples", type=int, default=60, help="consistency: states to plan again from; sampled: episodes")
    p.add_argument("--temperature", type=float, default=1.0, help="sampled: of the logits (default 1)")
    p.add_argument("--candidates", type=int, default=8, help="rollout: actions tried per step (default 8)")
    p.add_argument("--steps", type=int, default=None, help="rollout: decide only the first N steps (default all)")
    p.add_argument("--lead", type=int, default=0, help="ensemble: the first N steps from the demonstrator's plans")
    p.add_argument("--plans", default=None, help="ensemble with --lead: a demonstrator run's plans folder")
    p.add_argument(
        "--repeat-bonus", type=float, default=0.0, help="ensemble: added to the logit of the primitive flown last"
    )
    p.add_argument("--seed", type=int, default=0, help="consistency: which states")
    p.add_argument("--on", choices=sorted(SETS), default="val", help="demonstrator / ensemble: scenario set")
    p.add_argument("--beam-width", type=int, default=250, help="demonstrator, consistency: the search's beam width")
    p.add_argument(
        "--time-weight", type=float, default=1.0, help="demonstrator, consistency: its time weight [J/kg per s]"
    )
    p.add_argument("--workers", type=int, default=2, help="demonstrator, consistency: searches at a time")
    p.add_argument(
        "--out", type=Path, default=None, help="write the result as JSON (demonstrator, consistency: a folder)"
    )
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)
    check_cli_args(p, args, counts=("beam_width", "workers", "samples", "candidates"))
    if args.lead < 0:
        p.error(f"--lead={args.lead!r} must be >= 0 (steps)")
    searches = args.mode in ("demonstrator", "consistency")
    if not searches and not args.runs:
        p.error(f"{args.mode} needs --runs")
    if searches and (args.out is None or not 0.0 <= args.time_weight < float("inf")):
        p.error(f"{args.mode} needs --out (a folder) and a --time-weight >= 0")
    if args.mode == "sampled" and (len(args.runs) != 1 or not 0.0 < args.temperature < float("inf")):
        p.error(f"sampled needs one run (got {len(args.runs)}) and a --temperature > 0 (got {args.temperature})")
    if args.mode == "rollout" and len(args.runs) != 1:
        p.error(f"rollout needs one run (got {len(args.runs)})")
    if args.steps is not None and args.steps < 0:
        p.error(f"--steps={args.steps!r} must be >= 0 (steps decided by lookahead)")
    if searches:
        check_cli_args(p, args, dirs=("out",))
    elif args.out is not None and args.out.is_dir():
        p.error(f"--out={str(args.out)!r} is a folder; {args.mode} writes one JSON file")
    import torch

    torch.set_num_threads(1)
    t0 = time.perf_counter()
    try:
        if args.mode == "fit":
            res: dict[str, Any] = {"fit": [fit_report(r, args.demos, args.match) for r in args.runs]}
            print("| run | plans | rows | nll | top-1 | near-equivalent | different | visited: top-1 | different |")
            print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
            for f in res["fit"]:
                a, v = f["all"], f["visited"]
                print(
                    f"| {f['run']} | {f['plans']} | {a['rows']} | {a['nll']:.3f} | {a['top1']:.3f} | "
                    f"{a['near_equivalent']:.3f} | {a['different']:.3f} | {v['top1']:.3f} | {v['different']:.3f} |"
                )
        elif args.mode == "decisions":
            res = {"decisions": [decisions_report(r, args.demos, args.match) for r in args.runs]}
            print("| run | steps | rows | excess [J/kg] | picks a cheapest | untried |")
            print("|---|---|---:|---:|---:|---:|")
            for f in res["decisions"]:
                for label, g in f["steps"].items():
                    print(
                        f"| {f['run']} | {label} | {g['rows']} | {g['excess']:.1f} | {g['best']:.3f} | "
                        f"{g['untried']:.3f} |"
                    )
        elif args.mode == "demonstrator":
            res = demonstrator_report(
                args.on, args.out, args.beam_width, args.time_weight, args.workers, not args.no_progress
            )
        elif args.mode == "consistency":
            res = consistency_report(
                args.demos,
                args.match if args.match is not None else r"random-20\d\d\d",
                args.samples,
                args.seed,
                args.out,
                args.beam_width,
                args.time_weight,
                args.workers,
                not args.no_progress,
            )
            c = res["consistency"]
            print(
                f"consistency of {c['states']} states: the search picks the plan's primitive again at "
                f"{c['agree']:.2f}; its new plan is cheaper than the old by > 5 J/kg at "
                f"{c['cheaper_by_more_than_5']}, dearer at {c['dearer_by_more_than_5']}; another primitive "
                f"within 5 J/kg at {c['other_primitive_within_5']}"
            )
        elif args.mode in ("sampled", "rollout"):
            res = sampled_report(
                args.runs[0],
                args.on,
                args.samples,
                args.temperature,
                args.candidates if args.mode == "rollout" else 0,
                args.steps,
            )
            g = regret_summary(res["greedy"])
            print(f"the mode alone on {args.on}: regret median {g['median']:.3f}, {g['at_most_0.6']} at most 0.6")
        else:
            res = ensemble_report(args.runs, args.on, args.lead, args.plans, args.repeat_bonus)
    except ConfigError as exc:
        p.error(str(exc))
    if "episodes" in res:
        res["summary"] = s = regret_summary(res["episodes"])
        print(
            f"{args.mode} on {args.on}: regret median {s['median']:.3f}, mean {s['mean']:.3f}, "
            f"{s['at_most_0.6']}/{s['with_regret']} at most 0.6, {s['failures']} failures"
        )
    res["seconds"] = round(time.perf_counter() - t0, 1)
    if args.out is not None:
        path = args.out / f"{args.mode}.json" if searches else args.out
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, json.dumps(res, indent=1, default=float) + "\n")
        print(f"written: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
