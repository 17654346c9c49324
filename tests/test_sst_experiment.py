"""The paper experiment's machinery: parallel runs, atomic per-run files, resuming, table, figures."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from baselines.experiment import ExperimentConfig, format_table, make_figures, run_experiment, summarize, write_report
from baselines.sst import SSTError


def test_tiny_experiment_writes_resumes_and_reports(tmp_path: Path) -> None:
    cfg = ExperimentConfig(runs=2, time_limit=0.3, workers=2, out_dir=tmp_path)
    records = run_experiment(cfg, progress=False)
    assert [(r["planner"], r["run"]) for r in records] == [
        ("primitive", 0),
        ("primitive", 1),
        ("continuous", 0),
        ("continuous", 1),
    ]
    files = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert files == ["continuous-000.json", "continuous-001.json", "primitive-000.json", "primitive-001.json"]
    for r in records:
        assert r["iterations"] > 0 and r["active"] >= 1 and r["witnesses"] >= r["active"]
        if r["solved"]:
            assert r["cost"] is not None and r["flight_time"] > 0 and r["plan"]["actions"]
    # resume: nothing is run again (the files are untouched) ...
    mtimes = {p: p.stat().st_mtime_ns for p in (tmp_path / "runs").iterdir()}
    again = run_experiment(cfg, progress=False)
    assert again == records
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "runs").iterdir()} == mtimes
    # ... unless the settings changed (a different time budget is a different run)
    cfg2 = ExperimentConfig(runs=1, time_limit=0.2, workers=1, out_dir=tmp_path, planners=("primitive",))
    rec2 = run_experiment(cfg2, progress=False)
    assert rec2[0]["time_limit"] == 0.2
    json.loads((tmp_path / "runs" / "primitive-000.json").read_text())

    table, path = write_report(cfg, records)
    assert path.exists() and "failures" in table and "3/30" in table and "flight time" in table
    summary = summarize(records)
    assert summary["primitive"]["runs"] == 2


@pytest.mark.slow
def test_figures_are_written(tmp_path: Path) -> None:
    cfg = ExperimentConfig(runs=1, time_limit=0.5, workers=1, out_dir=tmp_path)
    records = run_experiment(cfg, progress=False)
    paths = make_figures(records, cfg.scenario, tmp_path, cfg.time_limit)
    assert [p.name for p in paths] == [
        "fig2_trajectories.png",
        "fig3_iterations.png",
        "fig4_cost.png",
        "fig5_flight_time.png",
    ]
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_table_with_failures_only() -> None:
    recs = [
        {
            "planner": "primitive",
            "solved": False,
            "cost": None,
            "flight_time": None,
            "iterations": 10,
            "active": 1,
            "total": 1,
            "witnesses": 1,
            "cpu_time": 1.0,
            "time_to_first_solution": None,
        }
    ]
    table = format_table(summarize(recs, ("primitive",)), 1.0)
    assert "1/1" in table


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"runs": 0}, "runs=0"),
        ({"time_limit": -3.0}, "time_limit=-3.0"),
        ({"workers": 0}, "workers=0"),
        ({"planners": ("grid",)}, "planner 'grid' is unknown"),
    ],
)
def test_bad_experiment_config(kwargs: dict, match: str) -> None:
    with pytest.raises(SSTError, match=match):
        ExperimentConfig(**kwargs)


def test_cpu_share_is_reported_and_a_busy_machine_is_flagged(tmp_path: Path) -> None:
    from baselines.experiment import BUSY_CPU_SHARE, busy_warning

    def rec(planner: str, cpu: float) -> dict:
        return {"planner": planner, "solved": False, "cost": None, "flight_time": None, "iterations": 10,
                "active": 1, "total": 1, "witnesses": 1, "cpu_time": cpu, "wall_time": 1.0, "elapsed": 1.0,
                "time_to_first_solution": None}  # fmt: skip

    quiet = [rec("primitive", 0.99), rec("continuous", 0.97), rec("continuous", 0.5)]
    assert busy_warning(quiet) is None
    table = format_table(summarize(quiet), 1.0)
    assert "| CPU share of the planning" in table and "median 0.99 (min 0.99)" in table
    assert "median 0.73 (min 0.50)" in table
    busy = [rec("primitive", 0.6), rec("continuous", 0.5), rec("continuous", 0.95)]
    warning = busy_warning(busy)
    assert warning is not None and "machine was busy" in warning and "not comparable" in warning
    assert f"{BUSY_CPU_SHARE:g}" in warning and "median CPU share of the planning was 0.60" in warning
    cfg = ExperimentConfig(runs=1, out_dir=tmp_path)
    table, path = write_report(cfg, busy)
    assert warning in table and warning in path.read_text()
    assert json.loads((tmp_path / "summary.json").read_text())["busy_warning"] == warning
