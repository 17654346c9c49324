"""The SST ablation script (``scripts/ablation_sst.py``): it writes its results, resumes, and runs a
row again when the row's planner settings change (the row names stay while their settings move)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

import baselines.cli.ablation_sst as abl

ROOT = Path(__file__).resolve().parents[1]
ARGS = ["--heldout", "--n-heldout", "1", "--heldout-rows", "soaring", "--samplers", "primitive", "--time", "1"]


def _runs(out: Path) -> list[dict]:
    return json.loads((out / "runs.json").read_text())["runs"]


def test_ablation_writes_resumes_and_redoes_changed_rows(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    argv = [*ARGS, "--reference-dir", str(ROOT / "results" / "reference"), "--out", str(tmp_path), "--no-progress"]
    assert abl.main(argv) == 0
    first = _runs(tmp_path)
    assert len(first) == 1 and first[0]["cost"] is not None and first[0]["scenario"] == "random-10000"
    assert {p.name for p in tmp_path.iterdir()} >= {"runs.json", "ablation.md", "summary.json", "anytime.png"}
    assert abl.main(argv) == 0  # resumed: nothing runs again
    assert _runs(tmp_path) == first
    # the same row name with other settings: a new run, and the old one is kept on disk
    rows = abl.rows()
    changed = {**rows, "soaring": dataclasses.replace(rows["soaring"], refinements=2)}
    monkeypatch.setattr(abl, "rows", lambda: changed)
    assert abl.main(argv) == 0
    again = _runs(tmp_path)
    assert len(again) == 2 and first[0] in again
    assert len({r["settings"] for r in again}) == 2
