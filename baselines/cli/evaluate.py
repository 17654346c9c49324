"""Evaluate agents on seeded scenarios through ``env.step``: results file, markdown table, plots.

Examples::

    # the README's table: all agents (PPO where trained), paper + 20 held-out scenarios, 3 seeds
    python scripts/evaluate.py --heldout 20 --seeds 0 1 2 --sst-budget 20 --out results/eval
    # a quick look (into results/eval-local, never the committed results)
    python scripts/evaluate.py --agents heuristic random --heldout 5
    # a discrete successor run as it is and improved online by one-step lookahead
    # (docs/learning-to-soar.md, round twenty-one)
    python scripts/evaluate.py --agents ppo-discrete ppo-discrete-rollout --ppo-model final \
        --ppo-dir ppo-discrete=results/ppo-score/a3-s0/discrete \
        --ppo-dir ppo-discrete-rollout=results/ppo-score/a3-s0/discrete
    # deterministic SST (iteration budget instead of wall clock)
    python scripts/evaluate.py --agents sst-primitives --sst-budget none --sst-iterations 2000
    # the episodes in parallel: 4 local worker processes, or every CPU of a running Ray cluster
    python scripts/evaluate.py --workers 4
    python scripts/evaluate.py --backend ray --address auto
    python scripts/evaluate.py --list

Writes ``<out>/results.json`` (atomically after every episode; a rerun resumes), ``results.md``,
``boxplots.png`` and ``trajectories.png``. The results file is the same (but for the timings) for
any ``--workers`` and ``--backend``; SST with a wall-clock budget depends on the machine's load.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from baselines._runs import add_backend_args, check_cli_args, cli_workers
from baselines.evaluation import (
    AGENT_NAMES,
    PPO_AGENTS,
    PPO_MODELS,
    ROLLOUT_AGENTS,
    EvalConfig,
    attach_regret,
    heldout_names,
    load_results,
    markdown_table,
    ppo_model_path,
    run_evaluation,
    write_report,
)
from baselines.reference import load_references
from soaring_env._validation import ConfigError
from soaring_env.scenario import SCENARIOS, atomic_write_text


def _budget(text: str) -> float | None:
    return None if text.lower() == "none" else float(text)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--agents", nargs="+", default=None, help="agent names (default: all; PPO ones where trained)")
    p.add_argument("--scenarios", nargs="+", default=None, help="scenario names (default: paper + --heldout)")
    p.add_argument("--heldout", type=int, default=20, help="add random-10000 ... random-(10000+N-1) (default 20)")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2], help="episode seeds (default 0 1 2)")
    p.add_argument("--sst-budget", type=_budget, default=20.0, help="SST seconds per planning call, or 'none'")
    p.add_argument("--sst-iterations", type=int, default=None, help="SST iteration budget per planning call")
    p.add_argument("--ppo-root", default="results/ppo", help="where <algo>/model.zip runs live (default results/ppo)")
    p.add_argument("--ppo-dir", action="append", default=[], metavar="AGENT=DIR", help="e.g. ppo-masked=runs/x")
    p.add_argument(
        "--ppo-model",
        choices=PPO_MODELS,
        default="best",
        help="which saved PPO model to use (bc: the behaviour-cloned start of a run with demos)",
    )
    p.add_argument(
        "--rollout-candidates",
        type=int,
        default=8,
        help="primitives ppo-discrete-rollout tries per decision (default 8; 1: the policy itself)",
    )
    p.add_argument(
        "--out",
        default="results/eval-local",
        help="output directory (default results/eval-local, not tracked; the README's committed results "
        "live in results/eval: pass --out results/eval to add to them)",
    )
    p.add_argument("--fresh", action="store_true", help="ignore existing results in --out (default: resume)")
    p.add_argument("--quiet", action="store_true", help="no per-episode lines, no progress bar")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (per-episode lines stay)")
    p.add_argument("--list", action="store_true", help="list known agents and scenarios and exit")
    add_backend_args(p, "1, one episode after another in this process")
    p.add_argument(
        "--reference-dir", default="results/reference", help="reference files for regret (scripts/reference.py)"
    )
    p.add_argument(
        "--rescore", action="store_true", help="run no episode: recompute the regrets of --out's results and report"
    )
    args = p.parse_args(argv)
    check_cli_args(p, args, counts=("heldout",), seeds=("seeds",), dirs=("out",))

    if args.list:
        print("agents:", ", ".join(AGENT_NAMES))
        print("scenarios:", ", ".join(sorted(SCENARIOS)), "and random-<seed> (held-out: random-10000, ...)")
        return 0
    ppo_dirs: dict[str, str] = {}
    root = Path(args.ppo_root)
    for agent, algo in PPO_AGENTS.items():
        if agent not in ROLLOUT_AGENTS and ppo_model_path(root / algo, args.ppo_model).is_file():
            ppo_dirs[agent] = str(root / algo)
    for item in args.ppo_dir:
        if "=" not in item:
            p.error(f"--ppo-dir expects AGENT=DIR, got {item!r}")
        k, v = item.split("=", 1)
        ppo_dirs[k] = v
    if args.agents is None:
        agents = [a for a in AGENT_NAMES if a not in PPO_AGENTS or a in ppo_dirs]
    else:
        agents = args.agents
    scenarios = args.scenarios if args.scenarios is not None else ["paper", *heldout_names(args.heldout)]
    try:
        references = load_references(args.reference_dir)
        if args.rescore:
            results = attach_regret(load_results(args.out), references)
            atomic_write_text(Path(args.out) / "results.json", json.dumps(results, separators=(",", ":")))
            files = write_report(results, args.out, reference_dir=args.reference_dir)
            print(markdown_table(results))
            print("rescored:", ", ".join(str(f) for f in [Path(args.out) / "results.json", *files]))
            return 0
        if not references:
            print(f"note: no reference files in {args.reference_dir}; regret stays empty (scripts/reference.py)")
        cfg = EvalConfig(
            agents=tuple(agents),
            scenarios=tuple(scenarios),
            seeds=tuple(args.seeds),
            sst_time_budget=args.sst_budget,
            sst_iterations=args.sst_iterations,
            ppo_dirs={k: v for k, v in ppo_dirs.items() if k in agents},
            ppo_model=args.ppo_model,
            rollout_candidates=args.rollout_candidates,
        )
        results = run_evaluation(
            cfg,
            args.out,
            resume=not args.fresh,
            progress=not (args.quiet or args.no_progress),
            log=None if args.quiet else lambda line: print(line, flush=True),
            references=references,
            workers=cli_workers(args, 1),
            backend=args.backend,
            address=args.address,
        )
    except (ConfigError, FileNotFoundError) as exc:
        p.print_usage(sys.stderr)  # argparse's usual usage + "error:" lines; status 2 as returned value
        print(f"{p.prog}: error: {exc}", file=sys.stderr)
        return 2
    files = write_report(results, args.out, reference_dir=args.reference_dir)
    print()
    print(markdown_table(results))
    print("written:", ", ".join(str(f) for f in [Path(args.out) / "results.json", *files]))
    return 0
