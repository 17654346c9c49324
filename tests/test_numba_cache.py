"""numba's on-disk cache must not serve a kernel compiled against an older version of a file it
depends on (``soaring_env._jit`` adds a hash of the package's kernel sources to the cache key).

Each case runs in a subprocess on a copy of the package in a temporary directory, so that the
edits and the caches they leave touch neither the checkout nor the other tests.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import soaring_env

PROBE = """
import json
import soaring_env
from soaring_env import Aircraft, Thermal, WindField, rollout
assert soaring_env.__file__.startswith({root!r}), soaring_env.__file__
f = WindField(thermals=(Thermal(north=0.0, east=0.0, strength=2.56),))
r = rollout([0.0, 0.0, 0.0, 300.0], f, Aircraft(), primitive=107)
print(json.dumps({{"thrust": float(Aircraft().thrust(15.0, 0.0, 0.0, 300.0)), "h": float(r.final[0, 3])}}))
"""


def _copy_package(tmp: Path) -> Path:
    src = Path(soaring_env.__file__).parent
    dst = tmp / "soaring_env"
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__"))
    return dst


def _probe(tmp: Path) -> dict[str, float]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["PYTHONPATH"] = str(tmp)
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(root=str(tmp))],
        cwd=tmp,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) == 1, f"{old!r} not found once in {path}"
    path.write_text(text.replace(old, new))


def test_edited_dependency_is_recompiled(tmp_path: Path) -> None:
    pkg = _copy_package(tmp_path)
    first = _probe(tmp_path)
    caches = sorted(p.name for p in (pkg / "__pycache__").glob("primitives._rollout_kernel*.nbi"))
    assert caches, "the rollout kernel was not cached on disk"
    assert _probe(tmp_path) == first  # unchanged sources: same results from the cache
    # Dependencies in other files than the kernels that call them: the density (aircraft's thrust
    # kernel and the rollout kernel) and the updraft (the rollout kernel only).
    _edit(pkg / "physics" / "atmosphere.py", "RHO0 = 1.225", "RHO0 = 2.45")
    second = _probe(tmp_path)
    assert second["thrust"] != first["thrust"]
    _edit(pkg / "physics" / "thermals.py", "return ws * w_peak + wd * wbar", "return 2.0 * (ws * w_peak + wd * wbar)")
    third = _probe(tmp_path)
    assert third["thrust"] == second["thrust"]
    assert third["h"] > second["h"] + 10.0  # twice the updraft in the thermal core: a much higher climb


NOTICE_PROBE = """
import soaring_env
from soaring_env import air_density
from soaring_env.scenario import paper_scenario
print(float(paper_scenario().field.updraft(1500.0, 250.0, 300.0)), float(air_density(300.0)))
"""


def test_cold_cache_says_it_compiles_once(tmp_path: Path) -> None:
    """A cold on-disk cache prints the compile notice once (two kernels compile), a warm one never."""
    from soaring_env._jit import COMPILE_NOTICE

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}

    def run() -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-c", NOTICE_PROBE], env=env, capture_output=True, text=True, timeout=300, check=True
        )

    cold = run()
    assert cold.stderr.count(COMPILE_NOTICE) == 1, cold.stderr
    assert COMPILE_NOTICE not in cold.stdout
    assert any(tmp_path.rglob("*.nbi")), "nothing was cached in NUMBA_CACHE_DIR"
    warm = run()
    assert COMPILE_NOTICE not in warm.stderr, warm.stderr
    assert warm.stdout == cold.stdout
