"""Ablation of the soaring SST configuration, and its targets on the paper and held-out scenarios.

Rows: the paper's planner (``SST_CONFIGS["paper"]``: uniform samplers, no bound), the paper's
planner with the glide mixture (the first step of the cumulative path paper -> + glide mixture ->
+ cost bound = "soaring without goal completions" -> + completions = "soaring without local
refinement" -> + refinements = soaring), the soaring
configuration (``SST_CONFIGS["soaring"]``), the soaring configuration with each of its measures
switched back to the paper's setting (leave one out: a measure earns its place when its row is
worse than the soaring row), the soaring configuration plus the seeding reference search (row
"soaring + reference seed") and plus the polish of its plan too (``SST_CONFIGS["seeded"]``, the
default planner, row "soaring + reference seed + polish"). Every run plans from the
scenario's start for ``--time`` seconds of wall clock on one core (one worker process per core
with ``--workers``); the anytime record gives the cost after 1, 5 and ``--time`` seconds. Regret
is measured against the reference table (``scripts/reference.py``) of the same scenario.

    python scripts/ablation_sst.py --workers 2           # paper scenario: 10 seeds per row, 30 for the
                                                         # soaring and seeded rows, 20 s per run, both samplers
    python scripts/ablation_sst.py --heldout --workers 2 # the 20 held-out scenarios (soaring row)
    python scripts/ablation_sst.py --time 2 --seeds 2 --out /tmp/abl   # a quick look

Writes ``<out>/runs.json`` (every run, resumable: finished runs are kept and skipped, written
atomically; one writer per folder; a run is keyed by its row, scenario, sampler, seed, time and a
digest of the row's planner settings and steering rule, so a row whose settings changed runs
again, and the older runs stay in the file), ``<out>/ablation.md`` (the table) and ``<out>/anytime.png``
(median regret against planning time, paper vs soaring). Wall-clock budgets: run it on a quiet
machine, one worker per core at most; the table reports the CPU share each run got.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from baselines._runs import DirLock, check_cli_args, progress_bar, read_json
from baselines.backends import run_jobs
from baselines.evaluation import heldout_names, resolve_scenario
from baselines.reference import load_reference, reference_path, regret
from baselines.sst.planner import make_planner
from baselines.sst.soaring import SAMPLERS, SST_CONFIGS, STEERING_VERSION, SoaringSSTConfig
from soaring_env.model import SoaringModel
from soaring_env.scenario import atomic_write_text

#: The measures of the soaring configuration, each with the fields that switch it off.
MEASURES: dict[str, dict[str, Any]] = {
    "glide mixture": {"glide_share": 0.0},
    "cost bound": {"cost_bound": False},
    "goal completions": {"completions": 0, "refinements": 0},
    "local refinement": {"refinements": 0},
}
#: The soaring configuration plus the seeding reference search (``SST_CONFIGS["seeded"]`` without
#: the polish: the default until 2026-12-05).
SEEDED_ROW = "soaring + reference seed"
#: The row of ``SST_CONFIGS["seeded"]``, the default: the seeding search and the polish of its plan.
POLISHED_ROW = "soaring + reference seed + polish"
CHECKPOINTS = (1.0, 5.0)
#: Regret at which a plan counts as near-best for the time-to-target column.
NEAR_BEST = 0.1


def rows() -> dict[str, SoaringSSTConfig]:
    """The ablation rows: label -> planner configuration."""
    soar = SST_CONFIGS["soaring"]
    paper = SST_CONFIGS["paper"]
    # the cumulative path paper -> + glide mixture -> + cost bound (= soaring without completions)
    # -> + completions (= soaring without local refinement) -> + refinements (= soaring), and
    # leave-one-out rows
    out = {"paper": paper, "paper + glide mixture": dataclasses.replace(paper, glide_share=soar.glide_share)}
    out["soaring"] = soar
    for name, off in MEASURES.items():
        out[f"soaring without {name}"] = dataclasses.replace(soar, **off)
    out[SEEDED_ROW] = dataclasses.replace(SST_CONFIGS["seeded"], seed_polish=0)  # + the seeding search
    out[POLISHED_ROW] = SST_CONFIGS["seeded"]  # the last step: + the polish of its plan
    return out


def _run(job: dict[str, Any]) -> dict[str, Any]:
    """One planning run (in a worker process)."""
    cfg = SoaringSSTConfig(**{**job["config"], "circle_radius": tuple(job["config"]["circle_radius"])})
    model = SoaringModel(resolve_scenario(job["scenario"]))
    warm = make_planner(model, job["sampler"], config=cfg, seed=job["seed"] + 1_000_000)[1]
    warm.run(max_iterations=2 * cfg.batch_size)  # load the compiled kernels outside the timing
    _, planner = make_planner(model, job["sampler"], config=cfg, seed=job["seed"])
    c0 = time.process_time()
    res = planner.run(time_limit=job["time"])
    cpu = time.process_time() - c0
    st = res.stats
    return {
        **{k: job[k] for k in ("row", "scenario", "sampler", "seed", "time", "settings")},
        "cost": st.best_cost if res.solved else None,
        "history": [[t, c] for t, _, c in st.cost_history],
        "iterations": st.iterations,
        "elapsed": st.elapsed,
        "cpu_share": cpu / st.elapsed if st.elapsed > 0 else math.nan,
        "ttfs": st.time_to_first_solution,
    }


def settings_digest(config: SoaringSSTConfig, sampler: str | None = None) -> str:
    """A digest of a row's planner settings (those that act with ``sampler``) and the steering
    rule's version: a run recorded with other settings is stale and runs again (the row names stay
    while their settings change)."""
    blob = json.dumps({"config": config.acting_settings(sampler), "steering": STEERING_VERSION}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _key(r: dict[str, Any]) -> str:
    return f"{r['row']}|{r['scenario']}|{r['sampler']}|{r['seed']}|{r['time']:g}|{r.get('settings', '')}"


def cost_at(run: dict[str, Any], t: float) -> float:
    """Best cost of a run after ``t`` seconds (inf if none yet)."""
    c = math.inf
    for tt, cc in run["history"]:
        if tt <= t:
            c = cc
    return c


def run_all(jobs: list[dict[str, Any]], out: Path, workers: int, progress: bool) -> list[dict[str, Any]]:
    """Run (or load) every job; ``out/runs.json`` holds all finished runs and is rewritten
    atomically after each one, so a killed run loses at most the runs in flight."""
    path = out / "runs.json"
    with DirLock(out, "ablation run"):
        done: dict[str, dict[str, Any]] = {}
        if path.exists():
            done = {_key(r): r for r in read_json(path, "ablation results")["runs"]}
        todo = [j for j in jobs if _key(j) not in done]
        if progress and len(jobs) > len(todo):
            print(f"resuming: {len(jobs) - len(todo)} of {len(jobs)} runs already done in {out}", flush=True)
        if todo:
            bar = progress_bar(len(jobs), len(jobs) - len(todo), progress, "SST runs", "run")
            for _, r in run_jobs(_run, todo, workers=workers):
                done[_key(r)] = r
                atomic_write_text(path, json.dumps({"schema": 1, "runs": sorted(done.values(), key=_key)}))
                if bar is not None:
                    bar.update(1)
            if bar is not None:
                bar.close()
    return [done[_key(j)] for j in jobs]


def _median(xs: list[float]) -> float:
    """Median over the defined values (regret is NaN where the thermals offer < MIN_GAP)."""
    a = np.asarray(xs, np.float64)
    a = a[~np.isnan(a)]
    return float(np.median(a)) if a.size else math.nan


def summarize(runs: list[dict[str, Any]], time_limit: float, refs: dict[str, Any]) -> list[dict[str, Any]]:
    """Per (row, sampler): median cost and regret at the checkpoints, the share of runs with regret
    <= 1, the median time to regret <= NEAR_BEST, and the median CPU share."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in runs:
        groups.setdefault((r["row"], r["sampler"]), []).append(r)
    out = []
    for (row, sampler), rs in groups.items():
        ts = (*CHECKPOINTS, time_limit)
        reg: dict[float, list[float]] = {t: [] for t in ts}
        cost: dict[float, list[float]] = {t: [] for t in ts}
        t_near = []
        for r in rs:
            sr = refs[r["scenario"]].samplers[sampler]
            for t in ts:
                c = cost_at(r, t)
                cost[t].append(c)
                reg[t].append(regret(c, sr.best_cost, sr.direct_cost) if math.isfinite(c) else math.inf)
            thr = sr.best_cost + NEAR_BEST * (sr.direct_cost - sr.best_cost)
            t_near.append(next((t for t, c in r["history"] if c <= thr), math.inf))
        final = np.asarray(reg[time_limit])
        final = final[~np.isnan(final)]
        out.append(
            {
                "row": row,
                "sampler": sampler,
                "runs": len(rs),
                "cost": {f"{t:g}": _median(cost[t]) for t in ts},
                "cost_p10_p90": [float(x) for x in np.percentile(np.asarray(cost[time_limit]), [10, 90])],
                "regret": {f"{t:g}": _median(reg[t]) for t in ts},
                "share_regret_le_1": float(np.mean(final <= 1.0)) if final.size else math.nan,
                "regret_defined": int(final.size),
                "time_to_near_best": _median(t_near),
                "cpu_share": _median([r["cpu_share"] for r in rs]),
            }
        )
    return out


def _f(x: float, spec: str, inf: str = "none") -> str:
    if math.isinf(x):
        return inf
    return "-" if math.isnan(x) else spec.format(x)


def table(summary: list[dict[str, Any]], time_limit: float) -> str:
    """Markdown table of :func:`summarize`."""
    ts = [f"{t:g}" for t in (*CHECKPOINTS, time_limit)]
    head = ["configuration", "sampler", "runs", *[f"regret @{t} s" for t in ts], f"cost @{ts[-1]} s [J/kg]"]
    head += ["10–90 % of it"]
    head += [f"time to regret <= {NEAR_BEST:g}", "regret <= 1 (runs with a regret)", "CPU share"]
    lines = ["| " + " | ".join(head) + " |", "|---|---|" + "---:|" * (len(head) - 2)]
    for s in summary:
        cells = [s["row"], s["sampler"], str(s["runs"])]
        cells += [_f(s["regret"][t], "{:.2f}") for t in ts]
        lo, hi = s["cost_p10_p90"]
        cells += [_f(s["cost"][ts[-1]], "{:,.0f}"), f"{_f(lo, '{:,.0f}')} … {_f(hi, '{:,.0f}')}"]
        cells += [_f(s["time_to_near_best"], "{:.2f} s", "never")]
        cells += [f"{100 * s['share_regret_le_1']:.0f} % of {s['regret_defined']}", f"{100 * s['cpu_share']:.0f} %"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_anytime(runs: list[dict[str, Any]], refs: dict[str, Any], time_limit: float, path: Path) -> None:
    """Median regret against planning time, one line per (row, sampler), log time axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = np.geomspace(0.01, time_limit, 80)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for ax, sampler in zip(axes, SAMPLERS, strict=True):
        labels = sorted({r["row"] for r in runs if r["sampler"] == sampler}, key=list(rows()).index)
        for label in labels:
            rs = [r for r in runs if r["sampler"] == sampler and r["row"] == label]
            curves = []
            for r in rs:
                sr = refs[r["scenario"]].samplers[sampler]
                curves.append(
                    [
                        regret(c, sr.best_cost, sr.direct_cost) if math.isfinite(c := cost_at(r, t)) else np.inf
                        for t in grid
                    ]
                )
            arr = np.asarray(curves, np.float64)
            arr = arr[~np.any(np.isnan(arr), axis=1)]  # runs whose regret is undefined (NaN once solved)
            med = np.median(arr, axis=0) if len(arr) else np.full(len(grid), np.nan)
            style = {
                "paper": {"color": "tab:blue", "lw": 2.0},
                "soaring": {"color": "black", "lw": 3.0, "zorder": 5},
                SEEDED_ROW: {"color": "tab:red", "lw": 2.5, "zorder": 6},
                POLISHED_ROW: {"color": "tab:purple", "lw": 2.0, "zorder": 7},
            }
            kw = style.get(label, {"ls": "--", "lw": 1.5})
            ax.plot(grid, np.where(np.isfinite(med), med, np.nan), label=f"{label} ({len(rs)} runs)", **kw)
        ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("planning time [s] (one core)")
        ax.set_title(f"{sampler} sampler")
        ax.set_ylim(-0.1, 1.6)
        if labels:
            ax.legend(fontsize=7, loc="upper right", framealpha=0.9)
        else:  # a run restricted to the other sampler
            ax.text(0.5, 0.5, "not run", transform=ax.transAxes, ha="center", color="0.5")
    axes[0].set_ylabel("median regret (0 = reference, 1 = ignoring the thermals)")
    fig.suptitle("SST anytime regret: paper configuration vs soaring configuration and its ablations")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--time", type=float, default=20.0, help="planning time per run [s] (default 20)")
    ap.add_argument("--seeds", type=int, default=10, help="seeds per ablation row (default 10)")
    ap.add_argument("--soaring-seeds", type=int, default=30, help="seeds of the soaring and seeded rows (default 30)")
    ap.add_argument("--samplers", nargs="+", default=list(SAMPLERS), choices=SAMPLERS)
    ap.add_argument("--heldout", action="store_true", help="the held-out scenarios (one seed each), paper vs soaring")
    ap.add_argument("--n-heldout", type=int, default=20, help="held-out scenarios with --heldout (default 20)")
    ap.add_argument("--heldout-rows", nargs="+", default=["soaring"], choices=list(rows()), help="rows with --heldout")
    ap.add_argument("--workers", type=int, default=1, help="worker processes, at most one per core (default 1)")
    ap.add_argument("--reference-dir", type=Path, default=Path("results/reference"), help="reference table folder")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default results/sst_ablation[/heldout])")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    check_cli_args(
        ap, args, counts=("seeds", "soaring_seeds", "n_heldout", "workers"), positive=("time",), dirs=("out",)
    )
    out = args.out or Path("results/sst_ablation") / ("heldout" if args.heldout else "paper")
    jobs: list[dict[str, Any]] = []
    cfgs = rows()
    if args.heldout:
        scen = heldout_names(args.n_heldout)
        plan = [(row, name, 0) for row in args.heldout_rows for name in scen]
    else:
        scen = ["paper"]
        plan = [
            (row, "paper", seed)
            for row in cfgs
            for seed in range(args.soaring_seeds if row in ("soaring", SEEDED_ROW, POLISHED_ROW) else args.seeds)
        ]
    try:
        refs = {name: load_reference(reference_path(args.reference_dir, name)) for name in scen}
    except Exception as exc:  # a missing reference is a usage error: say how to make it
        ap.error(f"{exc}; run scripts/reference.py first (or pass --reference-dir)")
    for sampler in args.samplers:
        for row, name, seed in plan:
            if sampler == "primitive" and row in ("soaring without glide mixture", "paper + glide mixture"):
                continue  # the glide mixture acts on the continuous sampler only: rows equal to others
            if sampler == "continuous" and row == POLISHED_ROW:
                continue  # the polish acts on the primitive sampler only: the row equals the seeded one
            cfg = dataclasses.asdict(cfgs[row])  # (every field: the worker rebuilds the configuration)
            jobs.append(
                {
                    "row": row,
                    "scenario": name,
                    "sampler": sampler,
                    "seed": seed,
                    "time": args.time,
                    "config": cfg,
                    "settings": settings_digest(cfgs[row], sampler),
                }
            )
    runs = run_all(jobs, out, args.workers, not args.no_progress)
    summary = summarize(runs, args.time, refs)
    md = table(summary, args.time)
    where = f"{len(scen)} held-out scenarios, one seed each" if args.heldout else "the paper scenario"
    atomic_write_text(out / "ablation.md", f"SST on {where}, {args.time:g} s per run:\n\n" + md)
    atomic_write_text(out / "summary.json", json.dumps({"schema": 1, "time": args.time, "summary": summary}, indent=1))
    plot_anytime(runs, refs, args.time, out / "anytime.png")
    print(md)
    print(f"wrote {out / 'ablation.md'}, {out / 'summary.json'}, {out / 'anytime.png'} and {out / 'runs.json'}")
    return 0
