"""Run folders: one writer at a time, corrupt results files named, no worker outlives its parent,
and the scripts' command lines answer bad values with argparse's ``error:`` line (exit status 2)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from baselines._runs import DirLock, read_json
from baselines.evaluation import EvalConfig, load_results, run_evaluation
from soaring_env import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_second_writer_refuses_with_the_pid(tmp_path: Path) -> None:
    with DirLock(tmp_path, "evaluation"):
        with pytest.raises(ConfigError, match=rf"in use by another evaluation \(PID {os.getpid()}"):
            run_evaluation(EvalConfig(agents=("random",), scenarios=("paper",), seeds=(0,)), tmp_path)
    res = run_evaluation(EvalConfig(agents=("random",), scenarios=("paper",), seeds=(0,)), tmp_path)
    assert len(res["episodes"]) == 1  # the lock is released after use


def test_lock_of_a_killed_process_is_free(tmp_path: Path) -> None:
    code = f"from baselines._runs import DirLock; import time; lock = DirLock({str(tmp_path)!r})\n"
    code += "print('held', flush=True); time.sleep(60)"
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    assert p.stdout is not None and p.stdout.readline().strip() == "held"
    with pytest.raises(ConfigError, match=rf"PID {p.pid}"):
        DirLock(tmp_path)
    p.kill()
    p.wait()
    DirLock(tmp_path).release()  # the kernel dropped the lock with its holder


def test_corrupt_results_file_is_named(tmp_path: Path) -> None:
    (tmp_path / "results.json").write_text('{"schema": 1, "episodes": [')
    with pytest.raises(ConfigError, match=r"results\.json.*cannot be read"):
        load_results(tmp_path)
    with pytest.raises(ConfigError, match=r"results\.json.*cannot be read"):
        run_evaluation(EvalConfig(agents=("random",), scenarios=("paper",), seeds=(0,)), tmp_path)
    (tmp_path / "results.json").write_text("[1, 2]")
    with pytest.raises(ConfigError, match=r"results\.json has results schema 'list'"):
        load_results(tmp_path)
    with pytest.raises(ConfigError, match=r"x\.json"):
        read_json(tmp_path / "x.json")


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killing_the_experiment_leaves_no_worker(tmp_path: Path, sig: signal.Signals) -> None:
    cmd = [sys.executable, "scripts/reproduce_paper.py", "--runs", "2", "--time", "60", "--workers", "2"]
    cmd += ["--out", str(tmp_path), "--no-figures", "--no-progress"]
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        workers: list[int] = []
        while time.monotonic() < deadline and len(workers) < 2:
            time.sleep(0.2)
            workers = [c for c in _children(p.pid) if "spawn_main" in (Path("/proc") / str(c) / "cmdline").read_text()]
        assert len(workers) >= 2, "the workers did not start"
        p.send_signal(sig)
        p.wait(timeout=10)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.1)
        assert not any(_alive(w) for w in workers), "a worker outlived the main process"
    finally:
        if p.poll() is None:
            p.kill()
    assert not list((tmp_path / "runs").glob("*.json"))  # nothing finished: redone on resume


@pytest.mark.parametrize(
    ("script", "args", "message"),
    [
        ("evaluate.py", ["--seeds", "0", "-1"], "seed -1 must be >= 0"),
        ("evaluate.py", ["--heldout", "-2"], "--heldout=-2 must be >= 0"),
        ("evaluate.py", ["--agents", "nobody", "--heldout", "0"], "agent 'nobody' is unknown"),
        ("evaluate.py", ["--out", "FILE"], "is a file"),
        ("reproduce_paper.py", ["--runs", "-3"], "--runs=-3 must be >= 1"),
        ("reproduce_paper.py", ["--seed", "-1"], "seed -1 must be >= 0"),
        ("reproduce_paper.py", ["--time", "0"], "--time=0.0 must be"),
        ("reproduce_paper.py", ["--workers", "0"], "--workers=0 must be >= 1"),
        ("reproduce_paper.py", ["--out", "FILE"], "is a file"),
    ],
)
def test_script_command_lines(tmp_path: Path, script: str, args: list[str], message: str) -> None:
    f = tmp_path / "file.txt"
    f.write_text("")
    argv = [str(f) if a == "FILE" else a for a in args]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "out")]
    r = subprocess.run(
        [sys.executable, f"scripts/{script}", *argv], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 2, r.stderr
    assert f"{script}: error:" in r.stderr and message in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
