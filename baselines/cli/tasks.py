"""The tasks' results table: reference search, heuristic, direct flyer and random agent on the held-out
scenarios of every task id (thermal climb, cross-country; primitives and continuous); the SST planner
on the continuous cross-country id when asked for (``--agents ... sst``; not on the ids of
``baselines.tasks.SST_SKIPPED``).

    python scripts/tasks.py                       # 10 held-out scenarios per task id, all agents
    python scripts/tasks.py --scenarios 3 --envs soaring/ThermalClimbContinuous-v0
    python scripts/tasks.py --beam-width 1000     # the reference's accuracy knob
    python scripts/tasks.py --convergence         # climb-10000, xc-10000: reference at 1/2, 1, 2 x the width
    python scripts/tasks.py --ppo results/ppo-climb/continuous   # adds a trained PPO run's rows
    python scripts/tasks.py --agents sst --envs soaring/CrossCountryContinuous-v0   # SST's rows
    python scripts/tasks.py --split validation --ppo RUN --out DIR   # validation scenarios (xc-5000, ...)

Writes ``results/tasks/results.json`` (every episode, atomically after each; a rerun resumes and
redoes only missing or changed jobs; one run per folder at a time), ``table.md`` and
``trajectories.png`` (each task id's first held-out scenario: the agents' paths over the thermals;
not for ``--split validation``, whose scenarios choose a policy without looking at the test set).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from baselines._runs import DirLock, add_backend_args, check_cli_args, cli_workers, progress_bar, read_json
from baselines.backends import run_jobs
from baselines.tasks import (
    AGENTS,
    DEFAULT_AGENTS,
    DEFAULT_BEAM_WIDTH,
    FIGURE_SCENARIO,
    SST_ITERATIONS,
    TASK_FAMILIES,
    TaskJob,
    check_episodes,
    markdown_table,
    path_array,
    run_task_job,
    summarize,
    task_jobs,
)
from soaring_env._validation import ConfigError
from soaring_env.scenario import HELDOUT_SEED0, VALIDATION_SEED0, atomic_write_text, get_scenario

SCHEMA = 1
#: ``--split``: the first seed of its scenarios.
SPLITS = {"heldout": HELDOUT_SEED0, "validation": VALIDATION_SEED0}


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", nargs="+", choices=tuple(TASK_FAMILIES), default=list(TASK_FAMILIES), help="task ids")
    p.add_argument("--scenarios", type=int, default=10, help="held-out scenarios per task id (default 10)")
    p.add_argument(
        "--split",
        choices=SPLITS,
        default="heldout",
        help="held-out test scenarios <family>-10000 ... (default) or validation ones <family>-5000 ...",
    )
    p.add_argument(
        "--agents",
        nargs="+",
        choices=AGENTS,
        default=list(DEFAULT_AGENTS),
        help=f"agents (default: {' '.join(DEFAULT_AGENTS)}; 'sst' flies the continuous cross-country id only)",
    )
    p.add_argument(
        "--sst-iterations",
        type=int,
        default=SST_ITERATIONS,
        help=f"SST's iteration budget per planning call (default {SST_ITERATIONS:,}: deterministic)",
    )
    p.add_argument("--beam-width", type=int, default=DEFAULT_BEAM_WIDTH, help="the reference search's accuracy knob")
    p.add_argument(
        "--ppo", nargs="+", default=[], metavar="RUN", help="PPO run directories (scripts/train_ppo.py --task ...)"
    )
    add_backend_args(p, "2")
    p.add_argument("--out", type=Path, default=Path("results/tasks"), help="output directory")
    p.add_argument("--convergence", action="store_true", help="the reference at 1/2, 1 and 2 x the beam width")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true", help="skip trajectories.png")
    args = p.parse_args(argv)
    check_cli_args(p, args, counts=("scenarios", "beam_width", "sst_iterations"), dirs=("out",))
    try:
        if args.convergence:
            return _convergence(args)
        jobs = task_jobs(
            args.envs, args.scenarios, args.agents, args.beam_width, args.ppo, SPLITS[args.split], args.sst_iterations
        )
        return _run(jobs, args)
    except ConfigError as exc:
        p.error(str(exc))
    return 2


def _run(jobs: list[TaskJob], args: Any) -> int:
    out: Path = args.out
    path = out / "results.json"
    t0 = time.perf_counter()
    with DirLock(out, "task run"):
        done: dict[str, dict[str, Any]] = {}
        if path.exists():
            for e in check_episodes(read_json(path, "task results"), str(path)):
                done[_key(e)] = e
        todo = [j for j in jobs if not _current(done.get(j.key()), j)]
        print(f"task results: {len(jobs)} episodes ({len(jobs) - len(todo)} done) -> {out}", flush=True)
        bar = progress_bar(len(jobs), len(jobs) - len(todo), not args.no_progress, "episodes", "ep")
        workers = cli_workers(args, 2)
        for _, rec in run_jobs(run_task_job, todo, workers=workers, backend=args.backend, address=args.address):
            done[_key(rec)] = rec
            atomic_write_text(path, json.dumps({"schema": SCHEMA, "episodes": sorted(done.values(), key=_key)}))
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        episodes = [done[j.key()] for j in jobs]
        table = markdown_table(summarize(episodes))
        atomic_write_text(out / "table.md", table)
        print(table)
        if not args.no_figures and args.split == "heldout":  # the figure's scenarios are held-out ones
            _figure(episodes, out / "trajectories.png")
    print(f"done in {time.perf_counter() - t0:.0f} s", flush=True)
    return 0


def _key(e: dict[str, Any]) -> str:
    return f"{e['env_id']}|{e['scenario']}|{e['agent']}|{e['seed']}"


def _current(rec: dict[str, Any] | None, job: TaskJob) -> bool:
    """A finished record made with the job's settings (the reference's beam width and version)."""
    return rec is not None and rec.get("job_settings", {}) == job.settings()


def _convergence(args: Any) -> int:
    """The reference's result as the beam width doubles, on each task id's first held-out scenario."""
    rows = [
        "| task id | scenario | beam width | energy [kJ/kg] | found | rollouts | seconds |",
        "|---|---|---|---|---|---|---|",
    ]
    for env_id in args.envs:
        sc = f"{TASK_FAMILIES[env_id]}-10000"
        for w in (args.beam_width // 2, args.beam_width, 2 * args.beam_width):
            rec = run_task_job(TaskJob(env_id, sc, "reference", 0, max(w, 1)))
            ref = rec["reference"]
            e = ref["predicted_energy"] / 1000.0
            rows.append(
                f"| `{env_id.split('/')[1]}` | {sc} | {w} | {e:.2f} | {ref['found']} | {ref['rollouts']:,} "
                f"| {ref['seconds']:.1f} |"
                if math.isfinite(e)
                else f"| `{env_id.split('/')[1]}` | {sc} | {w} | — | {ref['found']} | {ref['rollouts']:,} "
                f"| {ref['seconds']:.1f} |"
            )
            print(rows[-1], flush=True)
    text = "\n".join(rows) + "\n"
    atomic_write_text(args.out / "convergence.md", text)
    print(text)
    return 0


def _figure(episodes: list[dict[str, Any]], path: Path) -> None:
    """Each task id's first held-out scenario (:data:`FIGURE_SCENARIO`): thermals (at t = 0), goal,
    and every agent's path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ids = [e for e in TASK_FAMILIES if any(ep["env_id"] == e for ep in episodes)]
    cols = min(2, len(ids))
    rows = (len(ids) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 5.6 * rows), squeeze=False)
    for ax in axes.ravel()[len(ids) :]:
        ax.set_visible(False)
    colours = {
        "reference": "#1a8f3a",
        "heuristic": "#1f3b73",
        "thermalling": "#17a2b8",
        "direct": "#d35400",
        "random": "0.5",
        "ppo": "#8e44ad",
        "ppo-grid": "#e6007e",
        "ppo-discrete": "#b8860b",
        "ppo-masked": "#6b8e23",
        "sst": "#000000",
    }
    for ax, env_id in zip(axes.ravel(), ids, strict=False):
        first = FIGURE_SCENARIO[TASK_FAMILIES[env_id]]
        sc = get_scenario(first)
        for t in sc.field.thermals:
            alpha = min(0.25 + 0.1 * t.strength, 0.9)  # 100 m discs: about the cores' radius at 500 m
            ax.add_patch(plt.Circle((t.east / 1e3, t.north / 1e3), 0.1, color="#c0392b", alpha=alpha))
        if sc.goal is not None:
            g = sc.goal
            ax.add_patch(plt.Circle((g.east / 1e3, g.north / 1e3), g.radius / 1e3, fc="#2ecc71", alpha=0.5))
        for ep in episodes:
            if ep["env_id"] != env_id or ep["scenario"] != first or not ep.get("found", True):
                continue
            pts = path_array(ep)
            label = f"{ep['agent']}: {ep['energy_gained'] / 1e3:+.1f} kJ/kg, {ep['outcome']}"
            ax.plot(pts[:, 1] / 1e3, pts[:, 0] / 1e3, color=colours.get(ep["agent"], "k"), lw=1.2, label=label)
        ax.plot(sc.start[1] / 1e3, sc.start[0] / 1e3, "ko", ms=5)
        ax.set_aspect("equal")
        ax.set_title(f"{env_id.split('/')[1]}: {first}", fontsize=9)
        ax.set_xlabel("east [km]", fontsize=8)
        ax.set_ylabel("north [km]", fontsize=8)
        ax.legend(fontsize=6.5, loc="best")
        ax.tick_params(labelsize=7)
    fig.suptitle("Task agents on each task's first held-out scenario (red: thermals, darker = stronger)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
