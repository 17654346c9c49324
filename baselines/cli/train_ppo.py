"""Train PPO baselines on the soaring envs (stable-baselines3; sb3-contrib for action masks).

Examples::

    # the README's run: all three variants, one after another, 30 minutes in total
    python scripts/train_ppo.py --algo all --minutes 30
    # one variant, with TensorBoard logs (tensorboard --logdir results/ppo/masked/tb)
    python scripts/train_ppo.py --algo masked --timesteps 2000000 --tensorboard
    # any other TrainConfig field
    python scripts/train_ppo.py --algo continuous --set ent_coef=0.0 --set net_arch=[256,256]
    # three seeds at once (one job each: local worker processes, or Ray tasks with --backend ray)
    python scripts/train_ppo.py --algo masked --minutes 30 --seeds 0 1 2 --out results/ppo-seeds

Each variant writes ``<out>/<algo>/``: ``model.zip``, ``best_model.zip``, ``config.json`` (the
exact configuration, versions and timings), ``eval_log.json``, ``evaluations.npz``,
``learning_curve.png`` and ``checkpoints/``; ``<out>/learning_curve.png`` overlays all variants
(those trained into ``<out>`` by earlier runs too).
With several ``--seeds`` each seed is a job of its own, training its variants one after another
into ``<out>/seed-<seed>/<algo>/`` (the same layout below ``<out>/seed-<seed>``: pass that folder
to ``scripts/evaluate.py --ppo-root``); torch uses one thread per job; ``--minutes`` caps each seed
alone. A run of one seed is the same whichever way it is run, but for the wall-clock cap. With a
multi-node Ray cluster ``--out`` must be a folder every node can write (the jobs write it).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

from baselines._runs import add_backend_args, check_cli_args, cli_workers
from baselines.backends import run_jobs
from baselines.ppo import ALGOS, TASKS, VEC_ENVS, TrainConfig, plot_learning_curve, train
from soaring_env._validation import ConfigError

#: The variants of ``--algo all`` and their wall-clock shares of ``--minutes`` (masked PPO steps ~4x
#: slower: the masks cost a batched rollout of all 174 primitives per step). ``grid`` is trained on
#: its own, from reference plans (``--set demos=...``).
SHARES = {"masked": 0.4, "discrete": 0.3, "continuous": 0.3}


def _parse_set(items: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise SystemExit(f"--set expects key=value, got {item!r}")
        k, v = item.split("=", 1)
        try:
            out[k] = json.loads(v)
        except json.JSONDecodeError:
            out[k] = v
    return out


def train_seed(job: dict[str, Any]) -> list[dict[str, Any]]:
    """Train the variants ``job["algos"]`` of one seed, one after another, into
    ``job["root"]/<algo>`` (a job of :func:`baselines.backends.run_jobs`); returns per variant the
    run folder and the summary of its ``config.json``."""
    out = []
    for algo in job["algos"]:
        overrides = dict(job["overrides"])
        minutes = job["minutes"]
        if minutes is not None and job["split"]:
            minutes = minutes * SHARES[algo] / sum(SHARES[a] for a in job["algos"])
        if minutes is not None:
            overrides["max_minutes"] = minutes
            overrides.setdefault("total_timesteps", 100_000_000)  # the clock decides
        cfg = TrainConfig(algo=algo, **overrides)
        if job["announce"]:
            print(f"[train_ppo] {algo} on {cfg.env_id}: {cfg.total_timesteps} steps, cap {minutes} min -> "
                  f"{Path(job['root']) / algo}", flush=True)  # fmt: skip
        run = train(cfg, Path(job["root"]) / algo)
        rec = json.loads((run / "config.json").read_text())
        keys = ("timesteps_done", "train_wall_s", "steps_per_s", "final_eval")
        out.append({"algo": algo, "seed": cfg.seed, "dir": str(run), **{k: rec.get(k) for k in keys}})
    return out


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--algo", default="all", choices=[*ALGOS, "all"], help="variant(s) to train (default: all)")
    p.add_argument(
        "--task",
        default="goal",
        choices=list(TASKS),
        help="goal reaching (default), climb (ThermalClimb*-v0) or xc (CrossCountry*-v0)",
    )
    p.add_argument("--timesteps", type=int, default=None, help="env steps per variant (default: TrainConfig's)")
    p.add_argument(
        "--minutes",
        type=float,
        default=None,
        help="wall-clock cap [min]: per variant, or in total for --algo all (split masked 40 %%, others 30 %%)",
    )
    p.add_argument("--n-envs", type=int, default=None, help="parallel envs (default 8)")
    p.add_argument(
        "--vec-env", choices=list(VEC_ENVS), default=None, help="vectorization (default native: one batched env)"
    )
    p.add_argument("--seed", type=int, default=None, help="the seed (default 0); results in <out>/<algo>/")
    p.add_argument(
        "--seeds", nargs="+", type=int, default=None, help="several seeds, trained in parallel: <out>/seed-<s>/<algo>/"
    )
    p.add_argument("--out", default="results/ppo", help="output root (default results/ppo)")
    p.add_argument("--tensorboard", action="store_true", help="write TensorBoard logs to <out>/<algo>/tb")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--eval-freq", type=int, default=None, help="evaluate every this many timesteps")
    p.add_argument("--eval-scenarios", type=int, default=None, help="validation scenarios per evaluation")
    p.add_argument("--checkpoint-freq", type=int, default=None, help="checkpoint every this many timesteps")
    p.add_argument(
        "--init-from", default=None, metavar="RUN", help="start from an earlier run's weights (a curriculum stage)"
    )
    p.add_argument("--set", action="append", default=[], metavar="FIELD=JSON", help="any other TrainConfig field")
    add_backend_args(p, "one per seed, at most one per CPU core")
    args = p.parse_args(argv)
    check_cli_args(
        p,
        args,
        counts=("timesteps", "n_envs", "eval_freq", "eval_scenarios", "checkpoint_freq", "workers"),
        seeds=("seed", "seeds"),
        positive=("minutes",),
        dirs=("out",),
    )
    if args.seed is not None and args.seeds is not None:
        p.error("give --seed or --seeds, not both")
    seeds = args.seeds if args.seeds is not None else [0 if args.seed is None else args.seed]
    if len(set(seeds)) != len(seeds):
        p.error(f"--seeds {' '.join(map(str, seeds))}: a seed is repeated")
    multi = len(seeds) > 1
    workers = cli_workers(args, min(len(seeds), os.cpu_count() or 1))

    algos = list(SHARES) if args.algo == "all" else [args.algo]
    # several seeds at a time: their progress bars would fight over the terminal
    overrides: dict[str, Any] = {"progress_bar": not args.no_progress and (not multi or workers == 1)}
    if args.task != "goal":
        overrides["task"] = args.task
    for name, val in (
        ("total_timesteps", args.timesteps),
        ("n_envs", args.n_envs),
        ("vec_env", args.vec_env),
        ("eval_freq", args.eval_freq),
        ("n_eval_scenarios", args.eval_scenarios),
        ("checkpoint_freq", args.checkpoint_freq),
        ("init_from", args.init_from),
    ):
        if val is not None:
            overrides[name] = val
    if args.tensorboard:
        overrides["tensorboard"] = True
    settings = _parse_set(args.set)
    for key, flag in (("seed", "--seed/--seeds"), ("algo", "--algo"), ("max_minutes", "--minutes")):
        if key in settings:  # the flag's value would replace it without a word
            p.error(f"--set {key}=...: set it with {flag}")
    overrides.update(settings)
    try:  # check the settings here, before any job starts
        for algo in algos:
            TrainConfig(algo=algo, **overrides)
    except (ConfigError, TypeError, ValueError) as exc:
        p.error(str(exc))
    root = Path(args.out)
    jobs = [
        {
            "algos": algos,
            "overrides": {**overrides, "seed": seed},
            "minutes": args.minutes,
            "split": args.algo == "all",
            "root": str(root / f"seed-{seed}" if multi else root),
            "announce": not multi,
        }
        for seed in seeds
    ]
    if multi:
        where = "all the cluster" if workers is None else workers
        print(f"[train_ppo] seeds {' '.join(map(str, seeds))} ({', '.join(algos)}), {where} workers ({args.backend}) "
              f"-> {root}/seed-<seed>/<algo>", flush=True)  # fmt: skip
    logs, labels = [], []
    t0 = time.perf_counter()
    try:
        for _, runs in run_jobs(train_seed, jobs, workers=workers, backend=args.backend, address=args.address):
            for r in runs:
                fin = r["final_eval"] or {}
                name = f"{r['algo']} seed {r['seed']}" if multi else r["algo"]
                print(
                    f"[train_ppo] {name}: {r['timesteps_done']} steps in {r['train_wall_s']:.0f} s "
                    f"({r['steps_per_s']:.0f}/s); validation success "
                    f"{100 * fin.get('success_rate', float('nan')):.0f} % -> {r['dir']}",
                    flush=True,
                )
                if (Path(r["dir"]) / "eval_log.json").is_file():
                    logs.append(Path(r["dir"]) / "eval_log.json")
                    labels.append(name)
    except ConfigError as exc:  # e.g. ray not installed, or no Ray cluster at --address
        p.error(str(exc))
    total = time.perf_counter() - t0
    # the other variants trained into this root before keep their curves in the overlay
    for algo in ALGOS:
        earlier = root / algo / "eval_log.json"
        if earlier.is_file() and earlier not in logs:
            logs.append(earlier)
            labels.append(algo)
    if logs:
        try:
            png = plot_learning_curve(
                logs,
                root / "learning_curve.png",
                title=f"PPO on the soaring envs: validation curves (this run: {total / 60:.1f} min of training)",
                labels=labels,
            )
            print(f"[train_ppo] learning curve: {png}")
        except ImportError:
            print("[train_ppo] matplotlib is not installed: no learning curve (pip install '.[plot]')")
    print(f"[train_ppo] total wall-clock: {total / 60:.1f} min")
    return 0
