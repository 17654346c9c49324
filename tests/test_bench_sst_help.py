"""``scripts/bench_sst.py --help`` states the batch sizes the benchmark actually runs with."""

from __future__ import annotations

import importlib.util

import pytest

from baselines.sst.soaring import SST_CONFIGS


def test_bench_sst_help_shows_the_true_batch_sizes(capsys: pytest.CaptureFixture[str]) -> None:
    mod = importlib.import_module("baselines.cli.bench_sst")
    with pytest.raises(SystemExit) as exc:
        mod.main(["--help"])
    assert exc.value.code == 0
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    for name, cfg in SST_CONFIGS.items():
        assert f"{name} K = {cfg.batch_size}" in out
    assert "K = 1024" not in (mod.__doc__ or "")  # no hard-coded copy that could drift
