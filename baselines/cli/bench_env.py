"""Environment throughput: soaring envs against gymnasium's CartPole-v1, measured in one run.

Prints env steps per second for ``soaring/Soaring-v0``, ``soaring/SoaringContinuous-v0``,
``CartPole-v1`` (the reference), gymnasium's sync vector env, and the natively batched vector env
(``gym.make_vec`` through ``vector_entry_point``) at 1024 envs, then the targets with PASS/FAIL:

* a single-env step takes at most 3x CartPole's step time (both through ``gym.make``, wrappers
  included, random actions, reset when an episode ends);
* the native batched env makes at least 500,000 env-steps per second on one core;
* random scenarios at full speed: the native batched env with ``scenario="random"`` (a new random
  scenario at every reset, drawn in batches) makes at least 1,000,000 env-steps per second on one
  core; its ratio to the fixed-scenario row of the same run is printed with it.

Two more one-core rows without a target: the natively batched continuous thermal-climb and
cross-country ids, whose resets draw task scenarios (in batches since 2026-12-05).

The process is pinned to one core (``os.sched_setaffinity`` where available) and numba to one
thread, so the numbers above are single-core numbers. Then, where the process may use more than one
core, the two native 1024-env rows are measured again with ``num_threads`` = ``--threads`` (default:
every core the process may use; the affinity widened for these rows only) and printed with their
speed-up over the one-thread rows; they are not held to the one-core targets. Each measurement is
the best of ``--repeats``.
The load average (``os.getloadavg``) is printed before and after: other processes on the machine
make the numbers smaller, so read a run under load as a lower bound.

Usage: ``python scripts/bench_env.py [--seconds 1.0] [--repeats 3] [--num-envs 1024] [--threads N] [--strict]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable

os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # before numba is imported

import gymnasium as gym
import numpy as np

import soaring_env  # noqa: F401  (registers the ids)
from baselines._runs import check_cli_args
from soaring_env._threads import check_threads
from soaring_env._validation import ConfigError

SINGLE_TARGET_RATIO = 3.0
NATIVE_TARGET = 500_000.0
RANDOM_TARGET = 1_000_000.0


def usable_cores() -> set[int]:
    """The cores this process may run on (one pseudo-core where the OS does not say)."""
    return set(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else {0}


def pin_one_core() -> str:
    """Pin this process to one CPU core if the OS allows it; return a description."""
    if hasattr(os, "sched_setaffinity"):
        core = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {core})
        return f"pinned to core {core}"
    return "not pinned (os.sched_setaffinity unavailable)"


def best_rate(run: Callable[[float], tuple[int, float]], seconds: float, repeats: int) -> float:
    """Best of ``repeats`` runs of ``run(seconds) -> (steps, elapsed)``, in steps per second."""
    run(min(0.2, seconds))  # warm-up: numba cache loading, first-call checks
    return max(n / dt for n, dt in (run(seconds) for _ in range(repeats)))


def single_env_runner(env_id: str, seed: int = 0, **kwargs) -> Callable[[float], tuple[int, float]]:
    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(4096)]

    def run(seconds: float) -> tuple[int, float]:
        n = 0
        t0 = time.perf_counter()
        deadline = t0 + seconds
        step, reset = env.step, env.reset
        while True:
            for a in actions:
                _, _, terminated, truncated, _ = step(a)
                if terminated or truncated:
                    reset()
            n += len(actions)
            now = time.perf_counter()
            if now >= deadline:
                return n, now - t0

    return run


#: task ids measured natively batched (rows without a target: resets draw task scenarios)
TASK_ROWS = ("soaring/ThermalClimbContinuous-v0", "soaring/CrossCountryContinuous-v0")


def vector_env_runner(env_id: str, num_envs: int, mode: str | None, **kwargs) -> Callable[[float], tuple[int, float]]:
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode, **kwargs)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(64)]

    def run(seconds: float) -> tuple[int, float]:
        n = 0
        t0 = time.perf_counter()
        deadline = t0 + seconds
        while True:
            for a in actions:
                env.step(a)
            n += len(actions) * num_envs
            now = time.perf_counter()
            if now >= deadline:
                return n, now - t0

    return run


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=1.0, help="duration of one measurement [s]")
    p.add_argument("--repeats", type=int, default=3, help="measurements per row; the best is reported")
    p.add_argument("--num-envs", type=int, default=1024, help="envs of the native batched env")
    p.add_argument("--sync-envs", type=int, default=16, help="envs of gymnasium's sync vector env")
    p.add_argument(
        "--threads", type=int, default=None, help="threads of the multi-core rows (default: the usable cores)"
    )
    p.add_argument("--strict", action="store_true", help="exit with status 1 if a target fails")
    args = p.parse_args(argv)
    check_cli_args(p, args, counts=("repeats", "num_envs", "sync_envs"), positive=("seconds",))
    cores = usable_cores()
    threads = len(cores) if args.threads is None else args.threads
    try:
        check_threads(threads)
    except ConfigError as err:
        p.error(f"--threads: {err}")

    pinning = pin_one_core()
    print(f"soaring-env benchmark | {pinning} | NUMBA_NUM_THREADS={os.environ['NUMBA_NUM_THREADS']}")
    print(f"load average before: {_load()}")
    print(f"python {sys.version.split()[0]}, gymnasium {gym.__version__}, numpy {np.__version__}")
    print(f"best of {args.repeats} x {args.seconds:g} s, random actions, default 'paper' scenario unless noted\n")

    rows: list[tuple[str, float]] = []

    def measure(name: str, runner: Callable[[float], tuple[int, float]]) -> float:
        rate = best_rate(runner, args.seconds, args.repeats)
        rows.append((name, rate))
        print(f"  {name:<58s} {rate:>14,.0f} steps/s  {1e6 / rate:>9.3f} us/step", flush=True)
        return rate

    cart = measure("CartPole-v1 (gym.make, reference)", single_env_runner("CartPole-v1"))
    disc = measure("soaring/Soaring-v0 (gym.make)", single_env_runner("soaring/Soaring-v0"))
    cont = measure("soaring/SoaringContinuous-v0 (gym.make)", single_env_runner("soaring/SoaringContinuous-v0"))
    measure(
        "soaring/Soaring-v0 random scenarios (gym.make)",
        single_env_runner("soaring/Soaring-v0", scenario="random"),
    )
    measure(
        f"Soaring-v0 sync vector env, {args.sync_envs} envs",
        vector_env_runner("soaring/Soaring-v0", args.sync_envs, "sync"),
    )
    native = measure(
        f"Soaring-v0 native batched env, {args.num_envs} envs",
        vector_env_runner("soaring/Soaring-v0", args.num_envs, None),
    )
    measure(
        f"SoaringContinuous-v0 native batched env, {args.num_envs} envs",
        vector_env_runner("soaring/SoaringContinuous-v0", args.num_envs, None),
    )
    rand = measure(
        f"Soaring-v0 native batched env, {args.num_envs} envs, random scen.",
        vector_env_runner("soaring/Soaring-v0", args.num_envs, None, scenario="random"),
    )
    for task_id in TASK_ROWS:  # their default: a new random task scenario at every reset
        measure(
            f"{task_id.split('/')[1]} native, {args.num_envs} envs",
            vector_env_runner(task_id, args.num_envs, None),
        )

    multi: list[tuple[str, float, float]] = []
    if threads > 1 and len(cores) > 1 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, cores)
        print(f"\n{threads} threads (num_threads={threads}), {len(cores)} usable cores, not pinned:")
        for label, kwargs, one in (
            ("native", {}, native),
            ("native, random scen.", {"scenario": "random"}, rand),
        ):
            rate = measure(
                f"Soaring-v0 {label}, {args.num_envs} envs, {threads} threads",
                vector_env_runner("soaring/Soaring-v0", args.num_envs, None, num_threads=threads, **kwargs),
            )
            multi.append((label, rate, one))
        pin_one_core()

    print("\nratios (step time relative to CartPole-v1):")
    results = []
    for name, rate in (("Soaring-v0", disc), ("SoaringContinuous-v0", cont)):
        ratio = cart / rate
        ok = ratio <= SINGLE_TARGET_RATIO
        results.append(ok)
        print(f"  {name:<22s} {ratio:5.2f}x CartPole   target <= {SINGLE_TARGET_RATIO:g}x   {'PASS' if ok else 'FAIL'}")
    ok = native >= NATIVE_TARGET
    results.append(ok)
    verdict = "PASS" if ok else "FAIL"
    print(f"  native batched env     {native:,.0f} env-steps/s   target >= {NATIVE_TARGET:,.0f}   {verdict}")
    ok = rand >= RANDOM_TARGET
    results.append(ok)
    verdict = "PASS" if ok else "FAIL"
    print(
        f"  random scenarios at full speed  {rand:,.0f} env-steps/s   target >= {RANDOM_TARGET:,.0f}   {verdict}"
        f"   ({rand / native:.2f}x the fixed-scenario row)"
    )
    print(f"  native speed-up over the single Soaring-v0 env: {native / disc:.1f}x")
    for label, rate, one in multi:
        print(f"  {label} with {threads} threads: {rate:,.0f} env-steps/s, {rate / one:.2f}x one thread")
    print(f"\nload average after: {_load()}")
    return 0 if (all(results) or not args.strict) else 1


def _load() -> str:
    """The 1, 5 and 15 minute load averages, or why there are none."""
    try:
        return ", ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:  # pragma: no cover - platforms without getloadavg
        return "unavailable"
