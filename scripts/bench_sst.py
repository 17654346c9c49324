"""Benchmark the SST planner on the paper scenario, one core, serially.

For both samplers (primitive, continuous) and three implementations -- the batched planner
(default, K = 256 expansions per round), the same planner one expansion at a time (K = 1: the
published algorithm, grid nearest neighbours) and the plain reference (brute-force nearest
neighbours, one rollout per iteration) -- it prints, as medians over the seeds: iterations per
second (wall clock and CPU time), time to the first solution, and the solution cost after 1, 5 and
T seconds, plus how many runs found a solution.

    python scripts/bench_sst.py                    # 3 seeds x 20 s per row (about 6 minutes)
    python scripts/bench_sst.py --time 5 --seeds 2 # a quick look

Targets (issue 4): >= 40,000 iterations/s with the primitive sampler on one core; a solution in
every run within 20 s for both samplers. Wall-clock rates suffer when other processes share the
cores; the CPU-time rate is the steadier figure on a busy machine.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from baselines.reference import load_reference
from baselines.sst.plan import make_planner
from baselines.sst.soaring import SAMPLERS, SoaringSSTConfig
from soaring_env.model import SoaringModel
from soaring_env.scenario import atomic_write_text, get_scenario

VARIANTS = ("batched", "one-at-a-time", "reference")


def bench_one(
    model: SoaringModel, sampler: str, variant: str, seed: int, t_lim: float, base: SoaringSSTConfig
) -> dict[str, Any]:
    cfg = base if variant == "batched" else SoaringSSTConfig(**{**base.__dict__, "batch_size": 1})
    _, warm = make_planner(model, sampler, config=cfg, seed=seed, reference=variant == "reference")
    warm.run(max_iterations=300)  # compile / load kernels outside the timing
    _, planner = make_planner(model, sampler, config=cfg, seed=seed, reference=variant == "reference")
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3, help="seeds per row (medians are reported)")
    ap.add_argument("--time", type=float, default=20.0, help="planning time per run [s]")
    ap.add_argument("--samplers", nargs="+", default=list(SAMPLERS), choices=SAMPLERS)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    ap.add_argument("--out", type=Path, default=Path("results/bench_sst.json"), help="JSON output file")
    ap.add_argument(
        "--reference", type=Path, default=Path("results/reference/paper.json"), help="reference file (regret)"
    )
    args = ap.parse_args(argv)
    if args.seeds < 1 or not args.time > 0:
        ap.error(f"--seeds={args.seeds} must be >= 1 and --time={args.time} > 0")

    model = SoaringModel(scenario=get_scenario("paper"))
    reference = load_reference(args.reference) if args.reference.is_file() else None
    if reference is None:
        print(f"note: no reference at {args.reference}; regret columns stay empty (scripts/reference.py)")

    def regret(cost: float | None, sampler: str) -> float | None:
        if reference is None or cost is None or not math.isfinite(cost):
            return None
        r = reference.regret(cost, sampler)
        return None if math.isnan(r) else r

    base = SoaringSSTConfig()
    print(
        f"SST benchmark, paper scenario, {args.seeds} seeds x {args.time:g} s per row, one core "
        f"(delta_BN={base.selection_radius:g} m, delta_s={base.pruning_radius:g} m, batch={base.batch_size}); "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}",
        flush=True,
    )
    rows: list[dict[str, Any]] = []
    for sampler in args.samplers:
        for variant in args.variants:
            for seed in range(args.seeds):
                r = bench_one(model, sampler, variant, seed, args.time, base)
                for k in ("1", "5", "T"):
                    r[f"regret_{k}"] = regret(r[f"cost_{k}"], sampler)
                rows.append(r)
                print(
                    f"  {sampler:10s} {variant:13s} seed {seed}: {r['it_per_s']:,.0f} it/s "
                    f"({r['it_per_cpu_s']:,.0f} per CPU s), first solution {_fmt(_med([r['ttfs']]), '{:.3f}')} s, "
                    f"cost {_fmt(r['cost_T'])} J/kg",
                    flush=True,
                )
    t = args.time
    lines = [
        f"| sampler | implementation | it/s (wall) | it/s (CPU) | first solution [s] | cost @1 s | cost @5 s "
        f"| cost @{t:g} s [J/kg] | regret @1 s | @5 s | @{t:g} s | solved |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for sampler in args.samplers:
        for variant in args.variants:
            rs = [r for r in rows if r["sampler"] == sampler and r["variant"] == variant]
            lines.append(
                f"| {sampler} | {variant} | {_fmt(_med([r['it_per_s'] for r in rs]))} "
                f"| {_fmt(_med([r['it_per_cpu_s'] for r in rs]))} "
                f"| {_fmt(_med([r['ttfs'] for r in rs]), '{:.3f}')} "
                f"| {_fmt(_med([r['cost_1'] for r in rs]))} | {_fmt(_med([r['cost_5'] for r in rs]))} "
                f"| {_fmt(_med([r['cost_T'] for r in rs]))} "
                + "".join(f"| {_fmt(_med([r[f'regret_{k}'] for r in rs]), '{:.2f}')} " for k in ("1", "5", "T"))
                + f"| {sum(r['solved'] for r in rs)}/{len(rs)} |"
            )
    table = "\n".join(lines)
    if reference is not None:
        table += "\n\n" + " ".join(
            f"{k}: best {v.best_cost:,.0f}, direct {v.direct_cost:,.0f} J/kg;" for k, v in reference.samplers.items()
        ) + " regret = (cost - best) / (direct - best), median over the seeds."
    print()
    print(table)
    prim = [r for r in rows if r["sampler"] == "primitive" and r["variant"] == "batched"]
    if prim:
        rate = _med([r["it_per_s"] for r in prim])
        verdict = "PASS" if rate >= 40_000 else "FAIL"
        print(f"\ntarget >= 40,000 it/s (primitive, batched, one core): {verdict} ({rate:,.0f})")
    for sampler in args.samplers:
        rs = [r for r in rows if r["sampler"] == sampler and r["variant"] == "batched"]
        if rs:
            ok = all(r["solved"] for r in rs)
            print(f"target: a solution in every run ({sampler}, batched): {'PASS' if ok else 'FAIL'}")
    atomic_write_text(
        args.out,
        json.dumps({"time": t, "seeds": args.seeds, "config": base.__dict__, "rows": rows, "table": table}, indent=1),
    )
    print(f"\nresults: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
