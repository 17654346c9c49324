"""``scripts/bench_sst.py --help`` states the batch sizes the benchmark actually runs with."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from baselines.sst.soaring import SST_CONFIGS


def test_bench_sst_help_shows_the_true_batch_sizes(capsys: pytest.CaptureFixture[str]) -> None:
    path = Path(__file__).resolve().parents[1] / "scripts" / "bench_sst.py"
    spec = importlib.util.spec_from_file_location("bench_sst", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    with pytest.raises(SystemExit) as exc:
        mod.main(["--help"])
    assert exc.value.code == 0
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    for name, cfg in SST_CONFIGS.items():
        assert f"{name} K = {cfg.batch_size}" in out
    assert "K = 1024" not in (mod.__doc__ or "")  # no hard-coded copy that could drift
