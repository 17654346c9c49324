"""The optimality yardstick: the reference search on the paper scenario and every held-out
evaluation scenario -- lower bound, direct-flight cost and best plan per action set.

    python scripts/reference.py                      # paper + 20 held-out scenarios, both action sets
    python scripts/reference.py --scenarios paper    # one scenario
    python scripts/reference.py --convergence        # paper: best cost as the beam width doubles
    python scripts/reference.py --backend ray --address auto   # the scenarios as tasks on a Ray cluster
    python scripts/reference.py --samplers primitive           # one action set (the file keeps the other)

For both action sets a second search is seeded with the plans of deterministic soaring-SST runs
(``--planner-iterations`` each, seeds 0 ... ``--planner-seeds`` - 1) besides the direct flight's,
and the cheaper of the two searches is kept, so the reference is never worse than those plans:
"best known" includes what the planner itself found. The best plan is then polished by local
search (``--polish``: every edit of up to that many consecutive controls, repeated while one
helps; depth 1 for the continuous action set); files computed without it are polished, not
recomputed.

Writes one JSON per scenario to ``results/reference/<name>.json`` (atomically, as soon as it is
done; a rerun resumes and recomputes only files whose settings differ), ``table.md`` and
``paper.png`` (the paper scenario's best and direct plans, replayed through ``env.step``);
``--convergence`` writes ``convergence/convergence.md`` and ``convergence.json``. Every regret the project
reports (``scripts/evaluate.py``, ``scripts/reproduce_paper.py``, ``scripts/bench_sst.py``) reads
these files.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path
from typing import Any

from baselines._runs import add_backend_args, check_cli_args, cli_workers
from baselines.evaluation import heldout_names, resolve_scenario
from baselines.reference import ReferenceConfig, compute_reference
from baselines.reference.runner import reference_table, run_references
from baselines.sst.soaring import SAMPLERS
from soaring_env._validation import ConfigError
from soaring_env.scenario import atomic_write_text

#: Expansions of each soaring-SST run whose plan seeds the reference's second search (the reference
#: is then never worse than those deterministic plans; see ReferenceConfig.planner_iterations).
PLANNER_ITERATIONS = 300_000
#: Planner runs (seeds 0 ... 3) whose plans all seed that search: SST's plan varies much with its
#: seed (primitive, ``random-10002``: 1,070 / 787 / 972 / 1,070 J/kg for seeds 0-3, the beam 943).
PLANNER_SEEDS = 4
#: Depth of the local search that ends the reference (ReferenceConfig.polish): the beam's cell
#: merging leaves plans that are not locally optimal.
POLISH = 2
#: Default beam width per action set. The primitives' search ranks nodes above the goal's top with
#: ReferenceConfig.descent_step and needs 8,000 to converge with it on ``paper`` (4,000: 1,399 J/kg,
#: 8,000 and 16,000: 1,218; README, "Optimality yardstick").
BEAM_WIDTHS = {"primitive": 8000, "continuous": ReferenceConfig.beam_width}


def sampler_settings(
    beam_width: int | None, planner_iterations: int, planner_seeds: int, polish: int
) -> dict[str, ReferenceConfig]:
    """The yardstick's settings per action set: ``beam_width`` for both (None: :data:`BEAM_WIDTHS`);
    the primitives rank with ``descent_step`` (their shallowest descent loses 78 m in one edge)."""
    return {
        s: ReferenceConfig(
            beam_width=beam_width or BEAM_WIDTHS[s],
            planner_iterations=planner_iterations,
            planner_seeds=planner_seeds,
            polish=polish,
            descent_step=s == "primitive",
        )
        for s in SAMPLERS
    }


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenarios", nargs="+", default=None, help="scenario names (default: paper + --heldout)")
    p.add_argument("--heldout", type=int, default=20, help="held-out scenarios random-10000 ... (default 20)")
    p.add_argument("--samplers", nargs="+", choices=SAMPLERS, default=list(SAMPLERS), help="action sets")
    p.add_argument(
        "--beam-width",
        type=int,
        default=None,
        help="the accuracy knob, for both action sets (default: "
        + ", ".join(f"{w:,} ({s})" for s, w in BEAM_WIDTHS.items())
        + ")",
    )
    p.add_argument(
        "--planner-iterations",
        type=int,
        default=PLANNER_ITERATIONS,
        help=f"seed a second search with the plans of soaring-SST runs of this many expansions each and "
        f"keep the cheaper (0: one search, no planner; default {PLANNER_ITERATIONS:,})",
    )
    p.add_argument(
        "--planner-seeds",
        type=int,
        default=PLANNER_SEEDS,
        help=f"planner runs (seeds 0, 1, ...) whose plans seed that second search (default {PLANNER_SEEDS})",
    )
    p.add_argument(
        "--polish",
        type=int,
        default=POLISH,
        help=f"polish the best plan by edits of up to this many consecutive controls (0: none; the "
        f"continuous action set at most 1; default {POLISH})",
    )
    add_backend_args(p, "one per CPU core")
    p.add_argument("--out", type=Path, default=Path("results/reference"), help="output directory")
    p.add_argument("--fresh", action="store_true", help="recompute finished scenarios too")
    p.add_argument("--convergence", action="store_true", help="paper scenario at 1/2, 1 and 2 x the beam width")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG of the paper scenario's plans")
    args = p.parse_args(argv)
    check_cli_args(p, args, counts=("heldout", "beam_width", "workers"), dirs=("out",))
    if args.planner_iterations < 0:
        p.error(f"--planner-iterations={args.planner_iterations} must be >= 0")
    try:
        cfg = sampler_settings(args.beam_width, args.planner_iterations, args.planner_seeds, args.polish)
        if args.convergence:
            return _convergence(cfg, args.samplers, args.out)
        names = args.scenarios if args.scenarios is not None else ["paper", *heldout_names(args.heldout)]
        scenarios = [resolve_scenario(n) for n in names]
        t0 = time.perf_counter()
        workers = cli_workers(args, os.cpu_count() or 1)
        print(
            f"reference search: {len(scenarios)} scenarios x {', '.join(args.samplers)}, beam width "
            f"{', '.join(f'{cfg[s].beam_width} ({s})' for s in args.samplers)}, "
            f"{'all the cluster' if workers is None else workers} workers ({args.backend}) "
            f"-> {args.out}",
            flush=True,
        )
        refs = run_references(
            scenarios,
            args.out,
            samplers=args.samplers,
            config=cfg,
            workers=workers,
            fresh=args.fresh,
            progress=not args.no_progress,
            backend=args.backend,
            address=args.address,
        )
    except ConfigError as exc:
        p.error(str(exc))
    # every action set the files hold: a run of one keeps the other's columns
    table = reference_table(refs, [s for s in SAMPLERS if any(s in r.samplers for r in refs.values())])
    atomic_write_text(args.out / "table.md", table + "\n")
    if not args.no_figures and "paper" in refs:
        from baselines.reference.plots import plot_reference

        print(f"figure: {plot_reference(refs['paper'], args.out / 'paper.png')}")
    print(table)
    print(f"\n{len(refs)} scenarios in {time.perf_counter() - t0:.0f} s; table: {args.out / 'table.md'}")
    return 0


def _convergence(cfg: dict[str, ReferenceConfig], samplers: list[str], out: Path) -> int:
    """The paper scenario at beam widths W/2, W, 2W: best cost, its change as a share of
    (direct - lower bound), and the time (one process, one core). The rows of action sets not run
    are kept from an existing ``convergence.json`` (each row records its planner settings)."""
    sc = resolve_scenario("paper")
    path = out / "convergence" / "convergence.json"
    try:
        kept = [r for r in json.loads(path.read_text()) if r["sampler"] not in samplers] if path.exists() else []
    except (OSError, ValueError, TypeError, KeyError) as exc:
        raise ConfigError(f"{str(path)!r} cannot be read ({exc!r}); move it away to start afresh") from None
    rows: list[dict[str, Any]] = []
    for k in (0.5, 1, 2):
        c = {s: dataclasses.replace(v, beam_width=max(1, int(v.beam_width * k))) for s, v in cfg.items()}
        print(f"beam width x {k} ...", flush=True)
        ref = compute_reference(sc, samplers, c)
        for s in samplers:
            sr = ref.samplers[s]
            rows.append(
                {
                    "sampler": s,
                    "beam_width": c[s].beam_width,
                    "best_cost": sr.best_cost,
                    "direct_cost": sr.direct_cost,
                    "lower_bound": ref.lower_bound,
                    "seconds": sr.seconds,
                    "rollouts": sr.rollouts,
                    "planner_iterations": c[s].planner_iterations,
                    "planner_seeds": c[s].planner_seeds,
                    "descent_step": c[s].descent_step,
                    "polish": sr.settings.get("polish", 0),
                }
            )
            print(f"  {s}: best {sr.best_cost:,.0f} J/kg, direct {sr.direct_cost:,.0f}, {sr.seconds:.0f} s", flush=True)
    rows = kept + rows
    lines = [
        "| action set | beam width | planner seeds, polish | best [J/kg] "
        "| change vs half the width [% of direct - bound] | direct [J/kg] | lower bound [J/kg] | rollouts | time [s] |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for s in SAMPLERS:
        prev = None
        for r in (x for x in rows if x["sampler"] == s):
            n_it = int(r.get("planner_iterations", 0))  # rows from before the field: the beam alone
            plan = f"{int(r.get('planner_seeds', 1))} x {n_it:,} it." if n_it else "none"
            if r.get("polish", 0):
                plan += f", polish {r['polish']}"
            if r.get("descent_step"):
                plan += ", descent step"
            span = r["direct_cost"] - r["lower_bound"]
            ch = "—" if prev is None else f"{100 * (r['best_cost'] - prev) / span:+.1f}"
            lines.append(
                f"| {s} | {r['beam_width']} | {plan} | {r['best_cost']:,.0f} | {ch} | {r['direct_cost']:,.0f} "
                f"| {r['lower_bound']:,.0f} | {r['rollouts']:,} | {r['seconds']:.0f} |"
            )
            prev = r["best_cost"]
    table = "\n".join(lines)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path.with_suffix(".md"), table + "\n")
    atomic_write_text(path, json.dumps(rows, indent=1))
    print(table)
    return 0
