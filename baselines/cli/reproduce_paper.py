"""Reproduce the paper's experiment: both SST planners (motion primitives vs continuous controls),
R runs of T seconds each on the paper scenario, in parallel; prints the paper's table beside ours
and saves figures 2-5.

    python scripts/reproduce_paper.py --quick          # 3 runs x 5 s per planner (about a minute)
    python scripts/reproduce_paper.py                  # the paper's 30 runs x 20 s per planner
    python scripts/reproduce_paper.py --backend ray --address auto   # on a running Ray cluster

Results go to ``results/paper`` (``results/paper-quick`` with ``--quick``): one JSON file per run,
written as soon as the run finishes, so an interrupted experiment resumes where it stopped.

The budget is wall clock: the table reports the CPU share each run got (process CPU time / wall
time of the planning), and a median share below 0.9 is reported as a busy machine (on stderr and
in the table): its time-budgeted numbers are not comparable with the paper's (on a busy machine
even the paper's cost ranking can come out reversed).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

from baselines._runs import add_backend_args, check_cli_args, cli_workers
from baselines.experiment import ExperimentConfig, busy_warning, make_figures, run_experiment, write_report
from baselines.reference import load_reference, reference_path
from baselines.sst.core import SSTError
from baselines.sst.soaring import SST_CONFIGS, SoaringSSTConfig


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=None, help="runs per planner (paper: 30)")
    ap.add_argument("--time", type=float, default=None, help="planning time per run [s] (paper: 20)")
    ap.add_argument("--quick", action="store_true", help="shortened mode: 3 runs x 5 s per planner")
    add_backend_args(ap, "one per CPU core")
    ap.add_argument("--seed", type=int, default=0, help="seed of run 0 (run r uses seed + r)")
    ap.add_argument("--out", type=Path, default=None, help="output directory")
    ap.add_argument("--fresh", action="store_true", help="ignore existing results and run everything again")
    ap.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    ap.add_argument("--reference-dir", type=Path, default=Path("results/reference"), help="reference files (regret)")
    ap.add_argument("--selection-radius", type=float, default=SoaringSSTConfig.selection_radius, help="delta_BN [m]")
    ap.add_argument("--pruning-radius", type=float, default=SoaringSSTConfig.pruning_radius, help="delta_s [m]")
    ap.add_argument("--batch-size", type=int, default=SoaringSSTConfig.batch_size, help="expansions per round")
    args = ap.parse_args(argv)
    check_cli_args(
        ap, args, counts=("runs", "workers", "batch_size"), seeds=("seed",), positive=("time",), dirs=("out",)
    )

    runs = args.runs if args.runs is not None else (3 if args.quick else 30)
    t_lim = args.time if args.time is not None else (5.0 if args.quick else 20.0)
    out = args.out if args.out is not None else Path("results/paper-quick" if args.quick else "results/paper")
    workers = cli_workers(args, os.cpu_count() or 1)
    try:
        planner = dataclasses.replace(  # the paper's planner: uniform samplers, no bound, no completions
            SST_CONFIGS["paper"],
            selection_radius=args.selection_radius,
            pruning_radius=args.pruning_radius,
            batch_size=args.batch_size,
        )
        cfg = ExperimentConfig(
            runs=runs,
            time_limit=t_lim,
            workers=workers,
            seed=args.seed,
            out_dir=out,
            planner=planner,
            backend=args.backend,
            address=args.address,
        )
    except SSTError as exc:
        ap.error(str(exc))
    t0 = time.perf_counter()
    print(
        f"SST on the '{cfg.scenario.name}' scenario: {runs} runs x {t_lim:g} s per planner, "
        f"{'all the cluster' if workers is None else workers} workers ({args.backend}), "
        f"delta_BN={planner.selection_radius:g} m, delta_s={planner.pruning_radius:g} m, batch={planner.batch_size}",
        flush=True,
    )
    try:
        records = run_experiment(cfg, progress=not args.no_progress, fresh=args.fresh)
    except SSTError as exc:  # e.g. the output folder is in use by another run
        ap.error(str(exc))
    ref_file = reference_path(args.reference_dir, cfg.scenario.name)
    reference = load_reference(ref_file) if ref_file.is_file() else None
    if reference is None:
        print(f"note: no reference at {ref_file}; the table has no regret row (scripts/reference.py)")
    elif reference.scenario != cfg.scenario:
        print(f"note: {ref_file} is for another scenario; the table has no regret row")
        reference = None
    table, path = write_report(cfg, records, reference)
    print()
    print(table)
    print(f"\ntable: {path}")
    warning = busy_warning(records)
    if warning is not None:
        print(warning, file=sys.stderr)
    if not args.no_figures:
        for p in make_figures(records, cfg.scenario, cfg.out_dir, cfg.time_limit):
            print(f"figure: {p}")
    print(f"done in {time.perf_counter() - t0:.1f} s")
    return 0
