"""The backends (:mod:`baselines.backends`): bad values are refused naming the field, and the same
jobs give the same results in this process, on local worker processes and on Ray.

The Ray tests share one local Ray instance (``num_cpus=2``, one module-scoped fixture: starting it
costs a few seconds); they are skipped only where ray is not installed (CI installs it).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import logging
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from test_reference import TINY  # the reference tests' small scenario (tests/ is on sys.path)

from baselines.backends import check_backend, run_jobs
from baselines.evaluation import EvalConfig, load_results, run_evaluation
from baselines.experiment import ExperimentConfig, run_experiment
from baselines.reference import ReferenceConfig
from baselines.reference.runner import run_references
from soaring_env._validation import ConfigError

ROOT = Path(__file__).resolve().parents[1]
TIMING = {"compute_total_s", "compute_plan_s", "compute_per_decision_s"}
#: Deterministic agents (SST with an iteration budget only), 2 scenarios x 2 seeds.
CONFIG = EvalConfig(
    agents=("sst-primitives", "heuristic", "random"),
    scenarios=("paper", "random-10000"),
    seeds=(0, 1),
    sst_time_budget=None,
    sst_iterations=300,
)
TINY_REF = ReferenceConfig(beam_width=5, start_width=5, max_edges=2)


def _script(name: str) -> ModuleType:
    """The command-line module behind ``scripts/<name>.py``."""
    return importlib.import_module(f"baselines.cli.{name}")


def _file_without_timings(out: Path) -> dict[str, Any]:
    """The results file of ``out`` without what depends on the clock (timings, creation time)."""
    data = json.loads((out / "results.json").read_text())
    data["meta"].pop("created")
    for e in data["episodes"]:
        for k in TIMING:
            e.pop(k)
    return data


# --- bad values -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"backend": "dask"}, r"backend='dask' is unknown; allowed: local, ray"),
        ({"backend": None}, r"backend=None is unknown; allowed: local, ray"),
        ({"workers": 0}, r"workers=0 must be an integer >= 1"),
        ({"workers": 2.5}, r"workers=2\.5 must be an integer >= 1"),
        ({"workers": True}, r"workers=True must be an integer >= 1"),
        ({"address": "auto"}, r"address='auto' is a Ray cluster address; it needs backend='ray' \(not 'local'\)"),
        ({"backend": "ray", "address": " "}, r"address=' ' must be a Ray cluster address"),
    ],
)
def test_bad_backend_values_name_the_field(kwargs: dict[str, Any], match: str, tmp_path: Path) -> None:
    args = {"backend": "local", "workers": None, "address": None, **kwargs}
    with pytest.raises(ConfigError, match=match):
        check_backend(**args)
    with pytest.raises(ConfigError, match=match):
        run_jobs(math.factorial, [1], **args)  # checked at once, before any job starts
    with pytest.raises(ConfigError, match=match):
        run_evaluation(CONFIG, tmp_path, **args)
    with pytest.raises(ConfigError, match=match):
        run_references([TINY], tmp_path, **args)
    with pytest.raises(ConfigError, match=match):
        ExperimentConfig(out_dir=tmp_path, **args)


def test_missing_ray_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # "import ray" raises ImportError
    with pytest.raises(ConfigError, match=r'backend=.ray. needs the ray package: pip install -e "\.\[ray\]"'):
        run_jobs(math.factorial, [1], backend="ray")


@pytest.mark.parametrize("script", ["evaluate", "reproduce_paper", "reference", "train_ppo"])
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--backend", "dask"], "argument --backend: invalid choice: 'dask'"),
        (["--workers", "0"], "--workers=0 must be >= 1"),
        (["--address", "auto"], "address='auto' is a Ray cluster address; it needs backend='ray'"),
    ],
)
def test_script_backend_options(
    script: str, args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        _script(script).main([*args, "--out", str(tmp_path)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"error: {message}" in err, err


@pytest.mark.parametrize(
    ("key", "flag"), [("seed", "--seed/--seeds"), ("algo", "--algo"), ("max_minutes", "--minutes")]
)
def test_train_ppo_refuses_set_of_a_field_with_its_own_flag(
    key: str, flag: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--set seed=1`` would be replaced by ``--seed``'s default without a word: it is refused."""
    with pytest.raises(SystemExit) as exc:
        _script("train_ppo").main(["--set", f"{key}=1", "--out", str(tmp_path)])
    assert exc.value.code == 2
    assert f"--set {key}=...: set it with {flag}" in capsys.readouterr().err


def test_run_jobs_in_process_and_on_local_workers() -> None:
    jobs = [5, 3, 7, 1]
    serial = list(run_jobs(math.factorial, jobs, workers=1))
    assert serial == [(0, 120), (1, 6), (2, 5040), (3, 1)]  # in this process, in order
    assert sorted(run_jobs(math.factorial, jobs, workers=2)) == serial
    with pytest.raises(ValueError, match="not defined for negative values"):
        list(run_jobs(math.factorial, [1, -1], workers=2))  # a job's exception reaches the caller


# --- the evaluation: serial, local workers, ray ------------------------------------------------------
@pytest.fixture(scope="module")
def serial(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The evaluation of :data:`CONFIG`, one episode after another in this process."""
    out = tmp_path_factory.mktemp("serial")
    run_evaluation(CONFIG, out, resume=False)
    return out


def test_local_workers_give_the_serial_results_file(serial: Path, tmp_path: Path) -> None:
    """Two workers, resuming a partial run: the same file as the serial run, written after every
    episode in the serial order."""
    first = run_evaluation(dataclasses.replace(CONFIG, seeds=(0,)), tmp_path, workers=2)
    order = [(e["agent"], e["scenario"], e["seed"]) for e in load_results(serial)["episodes"]]
    written = []

    def check_file(_: str) -> None:  # called after each finished episode, once the file is written
        eps = load_results(tmp_path)["episodes"]
        keys = [(e["agent"], e["scenario"], e["seed"]) for e in eps]
        assert keys == [k for k in order if k in set(keys)]  # a subsequence of the serial order
        written.append(len(eps))

    res = run_evaluation(CONFIG, tmp_path, workers=2, log=check_file)
    assert written[1:] == list(range(len(first["episodes"]) + 1, len(order) + 1))  # [0]: the resume line
    reused = {(e["agent"], e["scenario"], e["seed"]): e for e in first["episodes"]}
    for e in res["episodes"]:
        if (e["agent"], e["scenario"], e["seed"]) in reused:  # never run again: even the timings stay
            assert e == reused[(e["agent"], e["scenario"], e["seed"])]
    assert _file_without_timings(tmp_path) == _file_without_timings(serial)


@pytest.fixture(scope="module")
def ray_session() -> Iterator[Any]:
    """One local Ray instance with 2 CPUs for the module's Ray tests."""
    ray = pytest.importorskip("ray")
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level=logging.ERROR)
    yield ray
    ray.shutdown()


def test_ray_gives_the_serial_results_file(ray_session: Any, serial: Path, tmp_path: Path) -> None:
    run_evaluation(CONFIG, tmp_path, workers=2, backend="ray")
    assert _file_without_timings(tmp_path) == _file_without_timings(serial)
    assert ray_session.is_initialized()  # a session it did not start is left running


def test_ray_references_match_local_ones(ray_session: Any, tmp_path: Path) -> None:
    scenarios = [TINY, TINY.replace(name="tiny-2", goal=dataclasses.replace(TINY.goal, east=-100.0))]
    local = run_references(scenarios, tmp_path / "local", config=TINY_REF, workers=1, progress=False)
    ray = run_references(scenarios, tmp_path / "ray", config=TINY_REF, backend="ray", progress=False)

    def content(refs: dict[str, Any]) -> dict[str, Any]:
        out = {name: r.to_dict() for name, r in refs.items()}
        for d in out.values():
            for s in d["samplers"].values():
                s.pop("seconds")
        return out

    assert list(ray) == ["tiny", "tiny-2"] and content(ray) == content(local)
    assert sorted(p.name for p in (tmp_path / "ray").glob("*.json")) == ["tiny-2.json", "tiny.json"]


def test_ray_experiment_records_the_cpu_share(ray_session: Any, tmp_path: Path) -> None:
    cfg = ExperimentConfig(runs=1, time_limit=0.2, workers=2, out_dir=tmp_path, backend="ray")
    records = run_experiment(cfg, progress=False)
    assert [(r["planner"], r["run"]) for r in records] == [("primitive", 0), ("continuous", 0)]
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["continuous-000.json", "primitive-000.json"]
    for r in records:
        assert r["iterations"] > 0 and 0.0 < r["cpu_time"] <= 1.05 * r["wall_time"]
