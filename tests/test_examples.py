"""Every ``examples/*.py`` runs to completion (quick mode, in a subprocess, from a scratch directory)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.py"))
#: Modules an example needs beyond the core install, by file name.
NEEDS = {"04_train_ppo.py": ("torch", "sb3_contrib"), "07_rollout_agent.py": ("torch",)}
#: A line each example must print (a sign that it did its job, not only that it exited 0).
EXPECT = {
    "01_quickstart.py": "heuristic",
    "02_plan_sst.py": "replayed through env.step: goal",
    "03_vector_env.py": "env steps in",
    "04_train_ppo.py": "trained",
    "05_scenarios.py": "is unknown; known: paper",
    "06_tasks.py": "reference search:",
    "07_rollout_agent.py": "with the rollout goal",
}


def test_every_example_is_checked() -> None:
    assert [p.name for p in EXAMPLES] == sorted(EXPECT)


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(path: Path, tmp_path: Path) -> None:
    missing = [m for m in NEEDS.get(path.name, ()) if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"needs {', '.join(missing)}")
    env = {**os.environ, "SOARING_EXAMPLES_QUICK": "1", "MPLBACKEND": "Agg"}
    out = subprocess.run(
        [sys.executable, str(path)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, f"{path.name} failed:\n{out.stdout}\n{out.stderr}"
    assert EXPECT[path.name] in out.stdout, out.stdout
    assert not list(tmp_path.iterdir()), "an example left files in its working directory"
