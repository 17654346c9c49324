"""Benchmark the SST planner on the paper scenario, one core, serially.

For both samplers (primitive, continuous) and seven variants -- the soaring configuration with the
seeding reference search (the default planner, ``SST_CONFIGS["seeded"]``), the soaring
configuration (``SST_CONFIGS["soaring"]``), the paper's planner (``SST_CONFIGS["paper"]``,
batched: K expansions per round, K at the end of --help), the paper's planner one expansion at a
time (K = 1: the published algorithm, grid nearest neighbours) and the plain reference implementation (brute-force
nearest neighbours, one rollout per iteration), OMPL's SST and RRT -- it prints, as medians over the seeds: iterations
per second (wall clock and CPU time), time to the first solution, the solution cost and its regret
after 1, 5 and T seconds, the time to regret <= 0.1 and how many runs found a solution; and it
plots the anytime regret curves (median over the seeds) to ``--figure``.

    python scripts/bench_sst.py                    # 3 seeds x 20 s per row (about 15 minutes)
    python scripts/bench_sst.py --time 5 --seeds 2 # a quick look
    python scripts/bench_sst.py --update --variants seeded    # rerun one variant, keep the other rows
    python scripts/bench_sst.py --rescore          # new reference: regrets, table and figure, no runs

Targets: >= 40,000 iterations/s with the primitive sampler on one core (the paper's planner,
batched); a solution in every run within 20 s for both samplers; a first solution within 50 ms.
Wall-clock rates suffer when other processes share the cores; the CPU-time rate is the steadier
figure on a busy machine. With the ``ompl`` extra installed, OMPL's ``control::SST`` and
``control::RRT`` run beside them on the same problem through the same propagator and budget
(:mod:`baselines.sst.ompl_bridge`; their CPU time, in a subprocess, is not measured).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from baselines.reference import load_reference
from baselines.sst.planner import make_planner
from baselines.sst.soaring import SAMPLERS, SST_CONFIGS, SoaringSSTConfig
from soaring_env.model import SoaringModel
from soaring_env.scenario import atomic_write_text, get_scenario

#: variant -> (configuration, implementation)
VARIANTS: dict[str, tuple[str, str]] = {
    "seeded": ("seeded", "batched"),
    "soaring": ("soaring", "batched"),
    "paper": ("paper", "batched"),
    "paper one-at-a-time": ("paper", "one-at-a-time"),
    "paper reference": ("paper", "reference"),
    "OMPL SST": ("paper", "ompl-sst"),
    "OMPL RRT": ("paper", "ompl-rrt"),
}
NEAR_BEST = 0.1


def bench_ompl(model: SoaringModel, sampler: str, variant: str, seed: int, t_lim: float) -> dict[str, Any]:
    """One OMPL run (in its own subprocess; its CPU time is not measured)."""
    from baselines.sst.ompl_bridge import run_ompl

    r = run_ompl(model.scenario, sampler, VARIANTS[variant][1].split("-")[1], time_limit=t_lim, seed=seed)
    hist = r["history"]

    def at(t: float) -> float:
        return min([c for tt, c in hist if tt <= t], default=math.inf)

    return {
        "sampler": sampler,
        "variant": variant,
        "seed": seed,
        "iterations": r["iterations"],
        "elapsed": r["elapsed"],
        "cpu": math.nan,
        "it_per_s": r["iterations"] / r["elapsed"],
        "it_per_cpu_s": math.nan,
        "ttfs": hist[0][0] if hist else None,
        "cost_1": at(1.0),
        "cost_5": at(5.0),
        "cost_T": r["best_cost"],
        "history": hist,
        "solved": r["solved"],
        "active": None,
        "witnesses": None,
    }


def bench_one(model: SoaringModel, sampler: str, variant: str, seed: int, t_lim: float) -> dict[str, Any]:
    conf, impl = VARIANTS[variant]
    if impl.startswith("ompl"):
        return bench_ompl(model, sampler, variant, seed, t_lim)
    cfg: SoaringSSTConfig = SST_CONFIGS[conf]
    if impl != "batched":
        cfg = dataclasses.replace(cfg, batch_size=1)
    ref = impl == "reference"
    _, warm = make_planner(model, sampler, config=cfg, seed=seed, reference=ref)
    warm.run(max_iterations=300)  # compile / load kernels outside the timing
    _, planner = make_planner(model, sampler, config=cfg, seed=seed, reference=ref)
    c0 = time.process_time()
    res = planner.run(time_limit=t_lim)
    cpu = time.process_time() - c0
    st = res.stats
    return {
        "sampler": sampler,
        "variant": variant,
        "seed": seed,
        "iterations": st.iterations,
        "elapsed": st.elapsed,
        "cpu": cpu,
        "it_per_s": st.iterations / st.elapsed,
        "it_per_cpu_s": st.iterations / cpu if cpu > 0 else math.nan,
        "ttfs": st.time_to_first_solution,
        "cost_1": st.cost_at(1.0),
        "cost_5": st.cost_at(5.0),
        "cost_T": st.best_cost,
        "history": [[t, c] for t, _, c in st.cost_history],
        "solved": res.solved,
        "active": st.active,
        "witnesses": st.witnesses,
    }


def _med(xs: list[float | None]) -> float:
    a = np.array([math.inf if x is None else x for x in xs], dtype=np.float64)
    return float(np.median(a)) if a.size else math.nan


def _fmt(x: float, spec: str = "{:,.0f}") -> str:
    if math.isinf(x):
        return "none"
    if math.isnan(x):
        return "-"
    return spec.format(x)


def plot_anytime(rows: list[dict[str, Any]], regret_of: Any, t_lim: float, path: Path) -> None:
    """Median regret over the seeds against planning time, per variant and sampler."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = np.geomspace(0.005, t_lim, 100)
    samplers = [s for s in SAMPLERS if any(r["sampler"] == s for r in rows)]
    fig, axes = plt.subplots(1, len(samplers), figsize=(5.5 * len(samplers), 4.2), sharey=True, squeeze=False)
    for ax, sampler in zip(axes[0], samplers, strict=True):
        for variant in VARIANTS:
            rs = [r for r in rows if r["sampler"] == sampler and r["variant"] == variant]
            if not rs:
                continue
            curves = []
            for r in rs:
                c = [min([cc for tt, cc in r["history"] if tt <= t], default=math.inf) for t in grid]
                reg = [regret_of(x, sampler) if math.isfinite(x) else math.inf for x in c]
                curves.append([math.nan if x is None else x for x in reg])
            med = np.median(np.asarray(curves, np.float64), axis=0)
            ax.plot(grid, np.where(np.isfinite(med), med, np.nan), label=f"{variant} ({len(rs)} seeds)")
        ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_xscale("log")
        ax.set_ylim(-0.1, 3.0)
        ax.set_xlabel("planning time [s] (one core)")
        ax.set_title(f"paper scenario, {sampler} sampler")
        ax.legend(fontsize=8)
    axes[0][0].set_ylabel("median regret (0 = reference, 1 = ignoring thermals)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    batch = ", ".join(f"{name} K = {cfg.batch_size}" for name, cfg in SST_CONFIGS.items())
    ap = argparse.ArgumentParser(
        description=__doc__,
        epilog=f"Batch sizes of the batched variants (SST_CONFIGS[...].batch_size): {batch}.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--seeds", type=int, default=3, help="seeds per row (medians are reported)")
    ap.add_argument("--time", type=float, default=20.0, help="planning time per run [s]")
    ap.add_argument("--samplers", nargs="+", default=list(SAMPLERS), choices=SAMPLERS)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--out", type=Path, default=Path("results/bench_sst.json"), help="JSON output file")
    ap.add_argument("--figure", type=Path, default=Path("results/figures/bench_sst_anytime.png"), help="PNG output")
    ap.add_argument(
        "--reference", type=Path, default=Path("results/reference/paper.json"), help="reference file (regret)"
    )
    ap.add_argument("--no-ompl", action="store_true", help="leave out OMPL's planners")
    ap.add_argument("--replot", action="store_true", help="only redraw --figure from the rows in --out")
    ap.add_argument(
        "--rescore",
        action="store_true",
        help="run nothing: recompute the regrets, the table and the figure of --out against --reference",
    )
    ap.add_argument(
        "--update",
        action="store_true",
        help="rerun only the given --samplers x --variants and keep the other rows of --out (same --time, --seeds)",
    )
    args = ap.parse_args(argv)
    if args.seeds < 1 or not args.time > 0:
        ap.error(f"--seeds={args.seeds} must be >= 1 and --time={args.time} > 0")
    if any(v.startswith("OMPL") for v in args.variants):
        from baselines.sst.ompl_bridge import ompl_available

        if args.no_ompl or not ompl_available():
            if not args.no_ompl:
                print('note: OMPL is not installed (pip install -e ".[ompl]"); its rows are left out')
            args.variants = [v for v in args.variants if not v.startswith("OMPL")]

    model = SoaringModel(scenario=get_scenario("paper"))
    reference = load_reference(args.reference) if args.reference.is_file() else None
    if reference is None:
        print(f"note: no reference at {args.reference}; regret columns stay empty (scripts/reference.py)")

    def regret(cost: float | None, sampler: str) -> float | None:
        if reference is None or cost is None or not math.isfinite(cost):
            return None
        r = reference.regret(cost, sampler)
        return None if math.isnan(r) else r

    def near_best_time(r: dict[str, Any]) -> float:
        if reference is None:
            return math.nan
        sr = reference.samplers[r["sampler"]]
        thr = sr.best_cost + NEAR_BEST * (sr.direct_cost - sr.best_cost)
        return next((t for t, c in r["history"] if c <= thr), math.inf)

    if args.replot:
        if reference is None:
            ap.error(f"--replot needs the reference file {args.reference}")
        saved = json.loads(args.out.read_text())
        plot_anytime(saved["rows"], regret, saved["time"], args.figure)
        print(f"figure: {args.figure}")
        return 0
    print(
        f"SST benchmark, paper scenario, {args.seeds} seeds x {args.time:g} s per row, one core; "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}",
        flush=True,
    )
    rows: list[dict[str, Any]] = []
    kept: list[dict[str, Any]] = []
    if args.update or args.rescore:
        if not args.out.is_file():
            ap.error(f"--update / --rescore need the results file {args.out}")
        saved = json.loads(args.out.read_text())
        if args.rescore:  # nothing to run: every saved row is kept
            args.time, args.seeds, args.samplers, args.variants = saved["time"], saved["seeds"], [], []
        elif saved["time"] != args.time or saved["seeds"] != args.seeds:
            ap.error(f"--update: {args.out} was run with --time {saved['time']:g} --seeds {saved['seeds']}")
        kept = [r for r in saved["rows"] if not (r["sampler"] in args.samplers and r["variant"] in args.variants)]
        for r in kept:  # against the reference of this run
            for k in ("1", "5", "T"):
                r[f"regret_{k}"] = regret(r[f"cost_{k}"], r["sampler"])
            r["time_to_near_best"] = near_best_time(r)
    for sampler in args.samplers:
        for variant in args.variants:
            for seed in range(args.seeds):
                r = bench_one(model, sampler, variant, seed, args.time)
                for k in ("1", "5", "T"):
                    r[f"regret_{k}"] = regret(r[f"cost_{k}"], sampler)
                r["time_to_near_best"] = near_best_time(r)
                rows.append(r)
                print(
                    f"  {sampler:10s} {variant:20s} seed {seed}: {r['it_per_s']:,.0f} it/s "
                    f"({r['it_per_cpu_s']:,.0f} per CPU s), first solution {_fmt(_med([r['ttfs']]), '{:.3f}')} s, "
                    f"cost {_fmt(r['cost_T'])} J/kg",
                    flush=True,
                )
    if kept:  # the table and figure cover every row, in the default order
        rows = [
            r
            for smp in SAMPLERS
            for var in VARIANTS
            for r in (*kept, *rows)
            if r["sampler"] == smp and r["variant"] == var
        ]
        args.samplers = [smp for smp in SAMPLERS if any(r["sampler"] == smp for r in rows)]
        args.variants = [var for var in VARIANTS if any(r["variant"] == var for r in rows)]
    t = args.time
    lines = [
        f"| sampler | planner | it/s (wall) | it/s (CPU) | first solution [s] | cost @1 s | cost @5 s "
        f"| cost @{t:g} s [J/kg] | regret @1 s | @5 s | @{t:g} s | time to regret <= {NEAR_BEST:g} [s] | solved |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for sampler in args.samplers:
        for variant in args.variants:
            rs = [r for r in rows if r["sampler"] == sampler and r["variant"] == variant]
            tn = _med([r["time_to_near_best"] for r in rs])
            lines.append(
                f"| {sampler} | {variant} | {_fmt(_med([r['it_per_s'] for r in rs]))} "
                f"| {_fmt(_med([r['it_per_cpu_s'] for r in rs]))} "
                f"| {_fmt(_med([r['ttfs'] for r in rs]), '{:.3f}')} "
                f"| {_fmt(_med([r['cost_1'] for r in rs]))} | {_fmt(_med([r['cost_5'] for r in rs]))} "
                f"| {_fmt(_med([r['cost_T'] for r in rs]))} "
                + "".join(f"| {_fmt(_med([r[f'regret_{k}'] for r in rs]), '{:.2f}')} " for k in ("1", "5", "T"))
                + f"| {'never' if math.isinf(tn) else _fmt(tn, '{:.3f}')} "
                + f"| {sum(r['solved'] for r in rs)}/{len(rs)} |"
            )
    table = "\n".join(lines)
    if reference is not None:
        table += (
            "\n\n"
            + " ".join(
                f"{k}: best {v.best_cost:,.0f}, direct {v.direct_cost:,.0f} J/kg;"
                for k, v in reference.samplers.items()
            )
            + " regret = (cost - best) / (direct - best), median over the seeds."
        )
    print()
    print(table)
    prim = [r for r in rows if r["sampler"] == "primitive" and r["variant"] == "paper"]
    if prim:
        rate = _med([r["it_per_s"] for r in prim])
        verdict = "PASS" if rate >= 40_000 else "FAIL"
        print(f"\ntarget >= 40,000 it/s (primitive, paper planner, batched, one core): {verdict} ({rate:,.0f})")
    for sampler in args.samplers:
        for variant in ("seeded", "soaring", "paper"):
            rs = [r for r in rows if r["sampler"] == sampler and r["variant"] == variant]
            if rs:
                ok = all(r["solved"] for r in rs)
                fast = all(r["ttfs"] is not None and r["ttfs"] <= 0.05 for r in rs)
                print(
                    f"targets ({sampler}, {variant}): a solution in every run {'PASS' if ok else 'FAIL'}; "
                    f"first solution within 50 ms {'PASS' if fast else 'FAIL'}"
                )
    if reference is not None:
        plot_anytime(rows, regret, t, args.figure)
        print(f"figure: {args.figure}")
    configs = {k: dataclasses.asdict(v) for k, v in SST_CONFIGS.items()}
    atomic_write_text(
        args.out,
        json.dumps({"time": t, "seeds": args.seeds, "configs": configs, "rows": rows, "table": table}, indent=1),
    )
    print(f"\nresults: {args.out}")
    return 0
