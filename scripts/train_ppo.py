#!/usr/bin/env python
"""Train PPO baselines on the soaring envs (stable-baselines3; sb3-contrib for action masks).

Examples::

    # the README's run: all three variants, one after another, 30 minutes in total
    python scripts/train_ppo.py --algo all --minutes 30
    # one variant, with TensorBoard logs (tensorboard --logdir results/ppo/masked/tb)
    python scripts/train_ppo.py --algo masked --timesteps 2000000 --tensorboard
    # any other TrainConfig field
    python scripts/train_ppo.py --algo continuous --set ent_coef=0.0 --set net_arch=[256,256]

Each variant writes ``<out>/<algo>/``: ``model.zip``, ``best_model.zip``, ``config.json`` (the
exact configuration, versions and timings), ``eval_log.json``, ``evaluations.npz``,
``learning_curve.png`` and ``checkpoints/``; ``<out>/learning_curve.png`` overlays all variants.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from baselines._runs import check_cli_args
from baselines.ppo import ALGOS, TrainConfig, plot_learning_curve, train

#: Wall-clock shares of ``--minutes`` for ``--algo all`` (masked PPO steps ~4x slower: the masks
#: cost a batched rollout of all 174 primitives per step).
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


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--algo", default="all", choices=[*ALGOS, "all"], help="variant(s) to train (default: all)")
    p.add_argument("--timesteps", type=int, default=None, help="env steps per variant (default: TrainConfig's)")
    p.add_argument(
        "--minutes",
        type=float,
        default=None,
        help="wall-clock cap [min]: per variant, or in total for --algo all (split masked 40 %%, others 30 %%)",
    )
    p.add_argument("--n-envs", type=int, default=None, help="parallel envs (default 8)")
    p.add_argument("--vec-env", choices=["dummy", "subproc"], default=None, help="vectorization (default dummy)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="results/ppo", help="output root (default results/ppo)")
    p.add_argument("--tensorboard", action="store_true", help="write TensorBoard logs to <out>/<algo>/tb")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--eval-freq", type=int, default=None, help="evaluate every this many timesteps")
    p.add_argument("--eval-scenarios", type=int, default=None, help="validation scenarios per evaluation")
    p.add_argument("--checkpoint-freq", type=int, default=None, help="checkpoint every this many timesteps")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=JSON", help="any other TrainConfig field")
    args = p.parse_args(argv)
    check_cli_args(
        p,
        args,
        counts=("timesteps", "n_envs", "eval_freq", "eval_scenarios", "checkpoint_freq"),
        seeds=("seed",),
        positive=("minutes",),
        dirs=("out",),
    )

    algos = list(ALGOS) if args.algo == "all" else [args.algo]
    overrides: dict[str, Any] = {"seed": args.seed, "progress_bar": not args.no_progress}
    for name, val in (
        ("total_timesteps", args.timesteps),
        ("n_envs", args.n_envs),
        ("vec_env", args.vec_env),
        ("eval_freq", args.eval_freq),
        ("n_eval_scenarios", args.eval_scenarios),
        ("checkpoint_freq", args.checkpoint_freq),
    ):
        if val is not None:
            overrides[name] = val
    if args.tensorboard:
        overrides["tensorboard"] = True
    overrides.update(_parse_set(args.set))
    root = Path(args.out)
    logs = []
    t0 = time.perf_counter()
    for algo in algos:
        minutes = args.minutes
        if minutes is not None and args.algo == "all":
            minutes = args.minutes * SHARES[algo] / sum(SHARES[a] for a in algos)
        if minutes is not None:
            overrides["max_minutes"] = minutes
            overrides.setdefault("total_timesteps", 100_000_000)  # the clock decides
        cfg = TrainConfig(algo=algo, **overrides)
        print(f"[train_ppo] {algo} on {cfg.env_id}: {cfg.total_timesteps} steps, cap {minutes} min -> {root / algo}")
        out = train(cfg, root / algo)
        rec = json.loads((out / "config.json").read_text())
        fin = rec.get("final_eval") or {}
        print(
            f"[train_ppo] {algo}: {rec['timesteps_done']} steps in {rec['train_wall_s']:.0f} s "
            f"({rec['steps_per_s']:.0f}/s); validation success {100 * fin.get('success_rate', float('nan')):.0f} %"
        )
        if (out / "eval_log.json").is_file():
            logs.append(out / "eval_log.json")
    total = time.perf_counter() - t0
    if logs:
        try:
            png = plot_learning_curve(
                logs,
                root / "learning_curve.png",
                title=f"PPO on the soaring envs: validation curves ({total / 60:.1f} min of training in total)",
                labels=[p.parent.name for p in logs],
            )
            print(f"[train_ppo] learning curve: {png}")
        except ImportError:
            print("[train_ppo] matplotlib is not installed: no learning curve (pip install '.[plot]')")
    print(f"[train_ppo] total wall-clock: {total / 60:.1f} min")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
