"""The paper's experiment (Ryu et al., section IV): both SST planners, R runs of T seconds each on
the paper scenario; the table of failures, iterations, active nodes, solution cost and flight time
beside the paper's numbers; and the paper's figures 2-5.

Runs execute in parallel jobs (:func:`baselines.backends.run_jobs`: local worker processes or a
Ray cluster; one planner run per core at a time, so that the wall-clock budget means the same thing
as in a serial run). Each finished run is written at once, atomically, to
``<out>/runs/<planner>-<run>.json``; an interrupted experiment resumes and skips the runs whose file
exists with the same settings. The table and the figures are made from the result files only.

Every run records the CPU share it got: process CPU time / wall time of its planning. The budget
is wall clock, so a run that shares its core does fewer iterations than on a quiet machine; when
the median share is below :data:`BUSY_CPU_SHARE` the report says that the machine was busy and
that its time-budgeted numbers are not comparable (the paper's and other machines' alike).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baselines._runs import holds_dir_lock, progress_bar
from baselines.backends import check_backend, run_jobs
from baselines.reference.yardstick import ScenarioReference
from baselines.sst.core import SSTError
from baselines.sst.soaring import SAMPLERS, SST_CONFIGS, SoaringSSTConfig
from soaring_env.scenario import Scenario, atomic_write_text, get_scenario

#: The planners of the paper, in its order of discussion.
PLANNERS = SAMPLERS

#: What the paper reports (section IV; 30 runs of 20 s each). Cost units are the paper's own
#: (its cost integrates -de/dt / v_g with a stray 1/g and unstated scaling), not J/kg.
PAPER: dict[str, dict[str, Any]] = {
    "primitive": {"runs": 30, "failures": 3, "cost_mean": 7.32e5, "cost_std": 1.39e5},
    "continuous": {"runs": 30, "failures": 2, "cost_mean": 3.51e5, "cost_std": 2.97e4},
}
PAPER_CLAIMS = {
    "iterations": "primitive ran 11.0% more iterations than continuous (figure 3)",
    "active_nodes": "the same number of active nodes for both",
    "flight_time": "primitive paths took about half the flight time of continuous ones (figure 5)",
}
#: Median CPU share (process CPU time / wall time of the planning) below which the machine counts as
#: busy: the runs shared their cores, and their time-budgeted results are not comparable.
BUSY_CPU_SHARE = 0.9


@dataclass(frozen=True)
class ExperimentConfig:
    """Settings of one experiment.

    :param runs: runs per planner (R; paper: 30).
    :param time_limit: wall-clock planning budget per run [s] (T; paper: 20 s).
    :param workers: runs at a time (default: the number of CPU cores; None: every CPU of the
        backend -- with ``backend="ray"`` the whole cluster).
    :param seed: seed of run 0; run r uses ``seed + r`` (for both planners).
    :param out_dir: where the per-run result files, the table and the figures go.
    :param scenario: the scenario (default: the paper scenario).
    :param planner: planner settings (default: the paper's planner, ``SST_CONFIGS["paper"]``).
    :param planners: which planners to run.
    :param backend: ``"local"`` (worker processes) or ``"ray"`` (see :mod:`baselines.backends`).
    :param address: with ``backend="ray"``: a running cluster's address (None: a local Ray instance).
    """

    runs: int = 30
    time_limit: float = 20.0
    workers: int | None = field(default_factory=lambda: os.cpu_count() or 1)
    seed: int = 0
    out_dir: Path = Path("results/paper")
    scenario: Scenario = field(default_factory=lambda: get_scenario("paper"))
    planner: SoaringSSTConfig = field(default_factory=lambda: SST_CONFIGS["paper"])
    planners: tuple[str, ...] = PLANNERS
    backend: str = "local"
    address: str | None = None

    def __post_init__(self) -> None:
        if isinstance(self.runs, bool) or not isinstance(self.runs, int) or self.runs < 1:
            raise SSTError(f"runs={self.runs!r} must be an integer >= 1")
        if not (isinstance(self.time_limit, (int, float)) and math.isfinite(self.time_limit) and self.time_limit > 0):
            raise SSTError(f"time_limit={self.time_limit!r} must be a finite number of seconds > 0")
        if self.workers is not None and (
            isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1
        ):
            raise SSTError(f"workers={self.workers!r} must be an integer >= 1")
        check_backend(self.backend, self.workers, self.address)
        for p in self.planners:
            if p not in PLANNERS:
                raise SSTError(f"planner {p!r} is unknown; allowed: {', '.join(PLANNERS)}")
        object.__setattr__(self, "out_dir", Path(self.out_dir))

    def settings_key(self, planner: str, run: int) -> str:
        """A digest of everything that determines run ``run`` of ``planner`` (for resuming)."""
        blob = json.dumps(
            {
                "planner": planner,
                "run": run,
                "seed": self.seed + run,
                "time_limit": self.time_limit,
                "scenario": self.scenario.to_dict(),
                "config": asdict(self.planner),
            },
            sort_keys=True,
        )
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def run_path(self, planner: str, run: int) -> Path:
        return self.out_dir / "runs" / f"{planner}-{run:03d}.json"


# --- one run (in a worker process) ------------------------------------------------------------
_WARM: set[str] = set()


def run_one(job: dict[str, Any]) -> dict[str, Any]:
    """Plan once and return the JSON-able record of the run (executed in a worker process)."""
    from baselines.sst.planner import plan_soaring
    from soaring_env.model import SoaringModel

    scenario = Scenario.from_dict(job["scenario"])
    cfg = SoaringSSTConfig(**job["config"])
    model = SoaringModel(scenario=scenario)
    planner = job["planner"]
    if planner not in _WARM:  # compile / load the numba kernels outside the timed run
        plan_soaring(model, planner, max_iterations=2 * cfg.batch_size, seed=0, config=cfg)
        _WARM.add(planner)
    t0, w0 = time.process_time(), time.perf_counter()
    res = plan_soaring(model, planner, time_limit=job["time_limit"], seed=job["seed"], config=cfg)
    cpu, wall = time.process_time() - t0, time.perf_counter() - w0
    st = res.stats
    plan = res.plan
    return {
        "key": job["key"],
        "planner": planner,
        "run": job["run"],
        "seed": job["seed"],
        "time_limit": job["time_limit"],
        "solved": plan.solved,
        "cost": plan.cost if plan.solved else None,
        "flight_time": plan.flight_time if plan.solved else None,
        "n_edges": len(plan),
        "iterations": st.iterations,
        "elapsed": st.elapsed,
        "cpu_time": cpu,
        "wall_time": wall,
        "active": st.active,
        "inactive": st.inactive,
        "total": st.total,
        "witnesses": st.witnesses,
        "time_to_first_solution": st.time_to_first_solution,
        "stats": st.to_dict(),
        "plan": plan.to_dict() if plan.solved else None,
    }


# --- the experiment ---------------------------------------------------------------------------
def load_results(cfg: ExperimentConfig) -> dict[tuple[str, int], dict[str, Any]]:
    """The finished runs of ``cfg`` found on disk (files with other settings are ignored)."""
    out: dict[tuple[str, int], dict[str, Any]] = {}
    for planner in cfg.planners:
        for run in range(cfg.runs):
            p = cfg.run_path(planner, run)
            if not p.exists():
                continue
            try:
                rec = json.loads(p.read_text())
            except (OSError, json.JSONDecodeError):
                continue
            if rec.get("key") == cfg.settings_key(planner, run):
                out[(planner, run)] = rec
    return out


@holds_dir_lock(lambda a: a.arguments["cfg"].out_dir, "experiment")
def run_experiment(cfg: ExperimentConfig, *, progress: bool = True, fresh: bool = False) -> list[dict[str, Any]]:
    """Run every (planner, run) that has no result yet, ``cfg.workers`` at a time.

    :param cfg: the experiment settings.
    :param progress: show a tqdm progress bar.
    :param fresh: ignore (and overwrite) existing results.
    :returns: all run records, ordered by planner and run.
    """
    done = {} if fresh else load_results(cfg)
    if done and progress:
        print(f"resuming: {len(done)} finished runs loaded from {cfg.out_dir / 'runs'}", flush=True)
    jobs = [
        {
            "planner": planner,
            "run": run,
            "seed": cfg.seed + run,
            "time_limit": cfg.time_limit,
            "scenario": cfg.scenario.to_dict(),
            "config": asdict(cfg.planner),
            "key": cfg.settings_key(planner, run),
        }
        for run in range(cfg.runs)
        for planner in cfg.planners
        if (planner, run) not in done
    ]
    (cfg.out_dir / "runs").mkdir(parents=True, exist_ok=True)
    if jobs:
        bar = progress_bar(len(jobs) + len(done), len(done), progress, "SST runs", "run")
        for _, rec in run_jobs(run_one, jobs, workers=cfg.workers, backend=cfg.backend, address=cfg.address):
            atomic_write_text(cfg.run_path(rec["planner"], rec["run"]), json.dumps(rec))
            done[(rec["planner"], rec["run"])] = rec
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
    return [done[k] for k in sorted(done, key=lambda k: (cfg.planners.index(k[0]), k[1]))]


# --- summary and table ------------------------------------------------------------------------
def cpu_share(rec: dict[str, Any]) -> float:
    """Process CPU time / wall time of a run's planning (1: it had a core to itself; NaN: no time).
    Records written before ``wall_time`` was kept use the planner's own clock (``elapsed``)."""
    wall = rec.get("wall_time", rec.get("elapsed", 0.0))
    return rec["cpu_time"] / wall if wall > 0 else math.nan


def busy_warning(records: list[dict[str, Any]]) -> str | None:
    """A warning if the median CPU share of ``records`` is below :data:`BUSY_CPU_SHARE`, else None."""
    shares = [x for x in map(cpu_share, records) if not math.isnan(x)]
    if not shares or float(np.median(shares)) >= BUSY_CPU_SHARE:
        return None
    return (
        f"warning: machine was busy: the median CPU share of the planning was {float(np.median(shares)):.2f} "
        f"(< {BUSY_CPU_SHARE:g}; min {min(shares):.2f}): time-budgeted results are not comparable; "
        "rerun on a quiet machine, one worker per free core"
    )


def _mean_std(xs: Iterable[float]) -> tuple[float, float]:
    a = np.asarray([x for x in xs if x is not None], dtype=np.float64)
    if a.size == 0:
        return math.nan, math.nan
    return float(a.mean()), float(a.std(ddof=1)) if a.size > 1 else 0.0


def summarize(
    records: list[dict[str, Any]], planners: Iterable[str] = PLANNERS, reference: ScenarioReference | None = None
) -> dict[str, dict[str, Any]]:
    """Per planner: runs, failures, and mean/std of iterations, active nodes, cost, flight time;
    with a ``reference`` (of the experiment's scenario) also the median and mean regret of the
    solved runs and the reference's best and direct cost for the planner's action set."""
    out: dict[str, dict[str, Any]] = {}
    for p in planners:
        recs = [r for r in records if r["planner"] == p]
        solved = [r for r in recs if r["solved"]]
        s: dict[str, Any] = {"runs": len(recs), "failures": len(recs) - len(solved)}
        for name in ("iterations", "active", "total", "witnesses"):
            s[name] = _mean_std(r[name] for r in recs)
        s["iterations_per_cpu_s"] = _mean_std(r["iterations"] / r["cpu_time"] for r in recs if r["cpu_time"] > 0)
        shares = [x for x in map(cpu_share, recs) if not math.isnan(x)]
        s["cpu_share_median"] = float(np.median(shares)) if shares else math.nan
        s["cpu_share_min"] = min(shares) if shares else math.nan
        s["cost"] = _mean_std(r["cost"] for r in solved)
        s["flight_time"] = _mean_std(r["flight_time"] for r in solved)
        s["time_to_first_solution"] = _mean_std(r["time_to_first_solution"] for r in solved)
        s["cost_median"] = float(np.median([r["cost"] for r in solved])) if solved else math.nan
        ref = reference.samplers.get(p) if reference is not None else None
        if ref is not None:
            reg = [ref.regret(r["cost"]) for r in solved]
            s["regret_median"] = float(np.median(reg)) if reg else math.nan
            s["regret"] = _mean_std(reg)
            s["reference"] = {"best_cost": ref.best_cost, "direct_cost": ref.direct_cost}
        out[p] = s
    return out


def _pm(ms: tuple[float, float]) -> str:
    """``mean ± std`` with sensible digits (thousands separators for large numbers)."""
    m, s = ms
    if math.isnan(m):
        return "-"
    if abs(m) >= 100:
        return f"{m:,.0f} ± {s:,.0f}"
    return f"{m:.3g} ± {s:.2g}"


def format_table(summary: dict[str, dict[str, Any]], time_limit: float) -> str:
    """The paper's results table beside ours (Markdown)."""
    prim, cont = summary.get("primitive"), summary.get("continuous")
    pp, pc = PAPER["primitive"], PAPER["continuous"]
    rows = [
        ("| quantity | paper: primitive | paper: continuous | ours: primitive | ours: continuous |"),
        ("|---|---|---|---|---|"),
    ]

    def ours(s: dict[str, Any] | None, key: str) -> str:
        if s is None:
            return "-"
        if key == "failures":
            return f"{s['failures']}/{s['runs']}"
        return _pm(s[key])

    rows.append(
        f"| failures (no solution in {time_limit:g} s) | {pp['failures']}/{pp['runs']} | {pc['failures']}/{pc['runs']} "
        f"| {ours(prim, 'failures')} | {ours(cont, 'failures')} |"
    )

    def ratio(key: str) -> str:
        if prim and cont and cont[key][0] > 0:
            return f" (primitive/continuous = {prim[key][0] / cont[key][0]:.2f})"
        return ""

    it_ratio = ratio("iterations")
    rows.append(
        f"| iterations per {time_limit:g} s | fig. 3; primitive 11% more | fig. 3 "
        f"| {ours(prim, 'iterations')} | {ours(cont, 'iterations')}{it_ratio} |"
    )
    rows.append(
        f"| active nodes at the end | same for both | same for both | {ours(prim, 'active')} | {ours(cont, 'active')} |"
    )
    rows.append(
        f"| solution cost (paper: its units; ours: J/kg) | {pp['cost_mean']:.3g} ± {pp['cost_std']:.3g} "
        f"| {pc['cost_mean']:.3g} ± {pc['cost_std']:.3g} | {ours(prim, 'cost')} "
        f"| {ours(cont, 'cost')} |"
    )
    ft_ratio = ratio("flight_time")
    rows.append(
        f"| flight time [s] | fig. 5; about half of continuous | fig. 5 | {ours(prim, 'flight_time')} "
        f"| {ours(cont, 'flight_time')}{ft_ratio} |"
    )
    rows.append(
        f"| time to first solution [s] | - | - | {ours(prim, 'time_to_first_solution')} "
        f"| {ours(cont, 'time_to_first_solution')} |"
    )

    def share(s: dict[str, Any] | None) -> str:
        if s is None or math.isnan(s.get("cpu_share_median", math.nan)):
            return "-"
        return f"median {s['cpu_share_median']:.2f} (min {s['cpu_share_min']:.2f})"

    rows.append(f"| CPU share of the planning (CPU / wall time; 1 = a core to itself) | - | - | {share(prim)} "
                f"| {share(cont)} |")  # fmt: skip
    if any(s is not None and "regret" in s for s in (prim, cont)):

        def reg(s: dict[str, Any] | None) -> str:
            if s is None or "regret" not in s:
                return "-"
            ref = s["reference"]
            return (
                f"median {s['regret_median']:.2f}, mean {_pm(s['regret'])} (best {ref['best_cost']:,.0f}, "
                f"direct {ref['direct_cost']:,.0f} J/kg)"
            )

        rows.append(f"| regret vs the reference search (0 = best known, 1 = ignoring the thermals) | - | - "
                    f"| {reg(prim)} | {reg(cont)} |")  # fmt: skip
    return "\n".join(rows)


# --- figures --------------------------------------------------------------------------------
def _thermal_surface(ax: Any, scenario: Scenario, z_top: float) -> None:
    f = scenario.field
    top = min(f.zi, z_top) if f.model == "allen" else z_top
    hs = np.linspace(1.0, top, 30)
    ang = np.linspace(0.0, 2.0 * math.pi, 40)
    for t in f.thermals:
        if f.model == "allen":
            r = np.array([f.allen_profile(h)["r2"] for h in hs])
        else:
            r = np.full_like(hs, t.radius)
        rr, aa = np.meshgrid(r, ang, indexing="ij")
        ax.plot_surface(
            t.east + rr * np.sin(aa),
            t.north + rr * np.cos(aa),
            np.broadcast_to(hs[:, None], rr.shape),
            color="yellow",
            alpha=0.35,
            linewidth=0,
            shade=False,
        )


def _goal_sphere(ax: Any, scenario: Scenario) -> None:
    g = scenario.require_goal()
    u, v = np.meshgrid(np.linspace(0, 2 * math.pi, 30), np.linspace(0, math.pi, 15))
    ax.plot_surface(
        g.east + g.radius * np.cos(u) * np.sin(v),
        g.north + g.radius * np.sin(u) * np.sin(v),
        g.height + g.radius * np.cos(v),
        color="red",
        alpha=0.4,
        linewidth=0,
        shade=False,
    )


def make_figures(
    records: list[dict[str, Any]], scenario: Scenario, out_dir: Path, time_limit: float, n_examples: int = 5
) -> list[Path]:
    """The paper's figures 2-5 as PNG files in ``out_dir``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    planners = [p for p in PLANNERS if any(r["planner"] == p for r in records)]
    paths = []

    # Figure 2: five example solution trajectories per planner, 3D
    examples = {p: [r for r in records if r["planner"] == p and r["solved"]][:n_examples] for p in planners}
    s = scenario.start
    g = scenario.require_goal()
    pts = [np.asarray(r["plan"]["trajectory"])[:, [0, 1, 3]] for rs in examples.values() for r in rs]
    pts.append(np.array([[s[0], s[1], s[3]], [g.north, g.east, g.height + g.radius]]))
    pts.append(np.array([[t.north, t.east, 0.0] for t in scenario.field.thermals]).reshape(-1, 3))
    allp = np.concatenate(pts)
    lo, hi = allp.min(axis=0) - 200.0, allp.max(axis=0) + 200.0
    span = max(hi[0] - lo[0], hi[1] - lo[1])
    cn, ce = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
    z_top = float(hi[2])
    exaggeration = 3.0
    fig = plt.figure(figsize=(6.5 * len(planners), 6.0))
    colours = [plt.get_cmap("tab10")(i) for i in range(10)]
    for i, p in enumerate(planners):
        ax = fig.add_subplot(1, len(planners), i + 1, projection="3d")
        _thermal_surface(ax, scenario, z_top)
        _goal_sphere(ax, scenario)
        for j, r in enumerate(examples[p]):
            tr = np.asarray(r["plan"]["trajectory"])
            ax.plot(tr[:, 1], tr[:, 0], tr[:, 3], color=colours[j % 10], lw=1.4, label=f"run {r['run']}")
        ax.scatter([s[1]], [s[0]], [s[3]], color="lime", s=60, edgecolor="k", depthshade=False, label="start")
        ax.set_xlim(ce - span / 2, ce + span / 2)
        ax.set_ylim(cn - span / 2, cn + span / 2)
        ax.set_zlim(0.0, z_top)
        ax.set_box_aspect((1.0, 1.0, min(1.0, exaggeration * z_top / span)))
        ax.set_xlabel("east [m]")
        ax.set_ylabel("north [m]")
        ax.set_zlabel(f"height [m] (x{exaggeration:g})")
        ax.set_title(f"{p} planner: {len(examples[p])} example solution(s)")
        ax.legend(loc="upper left", fontsize=7)
        ax.view_init(elev=22, azim=-120)
    fig.suptitle("Fig. 2: solution trajectories from the start (lime) to the goal region (red); thermal in yellow")
    fig.tight_layout()
    paths.append(out_dir / "fig2_trajectories.png")
    fig.savefig(paths[-1], dpi=120)
    plt.close(fig)

    # Figures 3-5: box plots
    specs = [
        ("fig3_iterations.png", "iterations", f"Fig. 3: iterations per {time_limit:g} s", "iterations", False),
        ("fig4_cost.png", "cost", "Fig. 4: solution path cost (net specific energy)", "cost [J/kg]", True),
        ("fig5_flight_time.png", "flight_time", "Fig. 5: flight time of the solution paths", "flight time [s]", True),
    ]
    for name, key, title, ylabel, solved_only in specs:
        fig, ax = plt.subplots(figsize=(5.5, 4.5))
        data = [
            [r[key] for r in records if r["planner"] == p and (r["solved"] or not solved_only) and r[key] is not None]
            for p in planners
        ]
        ax.boxplot(data, tick_labels=[f"{p}\n(n={len(d)})" for p, d in zip(planners, data, strict=True)])
        for k, d in enumerate(data):
            jitter = np.random.default_rng(k).uniform(-0.08, 0.08, len(d))
            ax.scatter(np.full(len(d), k + 1.0) + jitter, d, s=10, alpha=0.6, color="tab:blue", zorder=3)
        ax.set_title(title)
        ax.set_ylabel(ylabel)
        ax.grid(axis="y", alpha=0.3)
        fig.tight_layout()
        paths.append(out_dir / name)
        fig.savefig(paths[-1], dpi=120)
        plt.close(fig)
    return paths


def write_report(
    cfg: ExperimentConfig, records: list[dict[str, Any]], reference: ScenarioReference | None = None
) -> tuple[str, Path]:
    """Write ``summary.json`` and ``table.md`` to ``cfg.out_dir``; returns the table text and its path.
    ``reference``: the reference of the experiment's scenario, for the regret row."""
    summary = summarize(records, cfg.planners, reference)
    table = format_table(summary, cfg.time_limit)
    warning = busy_warning(records)
    if warning is not None:
        table += f"\n\n**{warning}**"
    summary_file = {**summary, "busy_warning": warning}
    atomic_write_text(cfg.out_dir / "summary.json", json.dumps(summary_file, indent=2, default=str))
    path = cfg.out_dir / "table.md"
    atomic_write_text(path, table + "\n")
    return table, path
