"""Benchmark the rollout kernel: rollouts per second against a naive numpy reference.

Setup (fixed seed 0):

* field: Allen model, zi = 1400 m, no wind, 5 thermals with centres uniform over the square
  [-1.2, 1.2] km x [-1.2, 1.2] km and w* uniform in [1.5, 3.5] m/s;
* "uniform" starts: north and east uniform over the 3 km x 3 km square [-1.5, 1.5] km^2 that contains
  the thermals, course uniform in [-pi, pi), height uniform in [100, 1000] m (most edges never come
  near a thermal: the kernel's fast path);
* "in core" starts (worst case): every start within 20 m of a thermal centre, so every output
  interval of every edge is integrated through the updraft;
* "primitive": a primitive index uniform in 0..173 per start; "control": a constant control uniform
  over the continuous envelope (v_a in [10, 20] m/s, chi_dot in +-1080 deg / Ts, gamma in +-45 deg).

Each cell times ``soaring_env.rollout`` (default Ts = 30 s, N = 30, default substeps) and, in the same
run, a naive reference: explicit Euler of all four states, vectorized over the batch, one numpy step
per substep (10 substeps per output interval, 300 per edge) with the updraft from
``WindField.updraft``. The reference computes the states only (no energy terms), so the speed ratio
favours it. The process is pinned to one core with one numba thread; everything is compiled before
timing, and each cell reports the best of three timed rounds of about ``--seconds`` / 3 each.

Usage::

    python scripts/bench_model.py [--quick] [--seconds 0.6]
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported

import argparse
import math
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from baselines._runs import check_cli_args
from soaring_env import Aircraft, PrimitiveLibrary, Thermal, WindField, rollout

BATCHES = (1, 64, 4096)
TARGET_BATCH_4096 = 1_000_000  # primitive rollouts/s at batch 4096
TARGET_BATCH_1 = 20_000  # primitive rollouts/s at batch 1
EULER_SUBSTEPS = 10  # per output interval
SEED = 0


@dataclass(frozen=True)
class Case:
    """One benchmark input: start states and either primitive indices or controls, for the largest batch."""

    states: np.ndarray  # (B, 4)
    primitives: np.ndarray | None  # (B,) int
    controls: np.ndarray | None  # (B, 3) [v_a, chi_dot, gamma]


def pin_to_one_core() -> str:
    try:
        os.sched_setaffinity(0, {0})
        return "pinned to CPU 0"
    except (AttributeError, OSError) as exc:  # not Linux, or not allowed
        return f"not pinned ({type(exc).__name__})"


def make_field(rng: np.random.Generator) -> WindField:
    centres = rng.uniform(-1200.0, 1200.0, (5, 2))
    strengths = rng.uniform(1.5, 3.5, 5)
    thermals = tuple(Thermal(float(n), float(e), float(s)) for (n, e), s in zip(centres, strengths, strict=True))
    return WindField(thermals=thermals, model="allen", zi=1400.0)


def make_states(rng: np.random.Generator, field: WindField, b: int, in_core: bool) -> np.ndarray:
    if in_core:
        which = rng.integers(0, len(field.thermals), b)
        rad = 20.0 * np.sqrt(rng.uniform(0.0, 1.0, b))
        ang = rng.uniform(-math.pi, math.pi, b)
        centres = field.centres()[which]
        n = centres[:, 0] + rad * np.cos(ang)
        e = centres[:, 1] + rad * np.sin(ang)
    else:
        n = rng.uniform(-1500.0, 1500.0, b)
        e = rng.uniform(-1500.0, 1500.0, b)
    chi = rng.uniform(-math.pi, math.pi, b)
    h = rng.uniform(100.0, 1000.0, b)
    return np.stack([n, e, chi, h], axis=1)


def make_case(rng: np.random.Generator, field: WindField, lib: PrimitiveLibrary, mode: str, in_core: bool) -> Case:
    b = max(BATCHES)
    states = make_states(rng, field, b, in_core)
    if mode == "primitive":
        return Case(states, rng.integers(0, len(lib), b), None)
    lo, hi = lib.control_bounds()
    return Case(states, None, rng.uniform(lo, hi, (b, 3)))


def naive_rollout(
    states: np.ndarray,
    v: np.ndarray,
    rate1: np.ndarray,
    rate2: np.ndarray,
    gamma: np.ndarray,
    field: WindField,
    ts: float,
    n_pts: int,
) -> np.ndarray:
    """Explicit Euler of [Pn, Pe, chi, h], one vectorized step per substep; returns (B, N, 4)."""
    n, e, chi, h = (states[:, i].copy() for i in range(4))
    out = np.empty((states.shape[0], n_pts, 4))
    dt = ts / n_pts / EULER_SUBSTEPS
    vh = v * np.cos(gamma)
    climb = v * np.sin(gamma)
    wn, we = field.wind_north, field.wind_east
    t = 0.0
    for k in range(n_pts):
        rate = rate1 if k < n_pts // 2 else rate2
        for _ in range(EULER_SUBSTEPS):
            w_up = field.updraft(n, e, h, t)
            n, e, chi, h = (
                n + (vh * np.cos(chi) + wn) * dt,
                e + (vh * np.sin(chi) + we) * dt,
                chi + rate * dt,
                h + (climb + w_up) * dt,
            )
            t += dt
        out[:, k, 0], out[:, k, 1], out[:, k, 2], out[:, k, 3] = n, e, chi, h
    return out


def time_rate(fn: Callable[[], object], batch: int, seconds: float) -> float:
    """Best-of-three rollouts per second, each round lasting about seconds / 3."""
    t0 = time.perf_counter()
    fn()
    once = max(time.perf_counter() - t0, 1e-7)
    reps = max(1, int(seconds / 3.0 / once))
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        best = min(best, (time.perf_counter() - t0) / reps)
    return batch / best


def fmt_rate(x: float) -> str:
    return f"{x:,.0f}"


def print_table(title: str, header: list[str], rows: list[list[str]]) -> None:
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:
        widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
        line = "  ".join("-" * w for w in widths)
        print(title)
        print(line)
        print(
            "  ".join(h.ljust(w) if i < 3 else h.rjust(w) for i, (h, w) in enumerate(zip(header, widths, strict=True)))
        )
        print(line)
        for r in rows:
            print(
                "  ".join(c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths, strict=True)))
            )
        print(line)
        return
    table = Table(title=title)
    for i, h in enumerate(header):
        table.add_column(h, justify="left" if i < 3 else "right")
    for r in rows:
        table.add_row(*r)
    Console(width=None if sys.stdout.isatty() else 120).print(table)  # no wrapping in logs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short run (about 0.15 s per timed cell)")
    parser.add_argument("--seconds", type=float, default=0.6, help="time per timed cell and implementation [s]")
    args = parser.parse_args(argv)
    check_cli_args(parser, args, positive=("seconds",))
    seconds = 0.15 if args.quick else args.seconds
    pinned = pin_to_one_core()

    import numba

    rng = np.random.default_rng(SEED)
    lib = PrimitiveLibrary()
    ac = Aircraft()
    field = make_field(rng)

    # warm up: compile every kernel path (primitive / control, near / far from thermals)
    warm = make_states(rng, field, 8, in_core=True)
    warm[4:] = make_states(rng, field, 4, in_core=False)
    rollout(warm, field, ac, primitive=np.arange(8))
    rollout(warm, field, ac, control=[15.0, 0.1, 0.1])
    field.updraft(warm[:, 0], warm[:, 1], warm[:, 3])

    print(
        f"soaring-env rollout benchmark: {platform.python_implementation()} {platform.python_version()}, "
        f"numpy {np.__version__}, numba {numba.__version__}, NUMBA_NUM_THREADS={os.environ['NUMBA_NUM_THREADS']}, "
        f"{pinned}, {platform.machine()} {platform.processor() or ''}".rstrip()
    )
    print(
        f"Allen field, 5 thermals, seed {SEED}; Ts = {lib.duration:g} s, N = {lib.n_points}; "
        f"naive reference: Euler, {EULER_SUBSTEPS} substeps per output interval, states only"
    )

    header = ["input", "starts", "batch", "rollout [1/s]", "naive numpy [1/s]", "speed-up"]
    rows: list[list[str]] = []
    results: dict[tuple[str, str, int], float] = {}
    for mode in ("primitive", "control"):
        for dist, in_core in (("uniform 3x3 km", False), ("in core (worst)", True)):
            case = make_case(np.random.default_rng(SEED + 1), field, lib, mode, in_core)
            for b in BATCHES:
                x = case.states[:b]
                if case.primitives is not None:
                    p = case.primitives[:b]
                    row = lib.table[p]
                    v, gam, r1, r2 = row[:, 1], row[:, 2], row[:, 3], row[:, 4]

                    def fast(x: np.ndarray = x, p: np.ndarray = p) -> object:
                        return rollout(x, field, ac, primitive=p)
                else:
                    u = case.controls[:b]  # type: ignore[index]
                    v, r1, gam = u[:, 0], u[:, 1], u[:, 2]
                    r2 = r1

                    def fast(x: np.ndarray = x, u: np.ndarray = u) -> object:  # type: ignore[misc]
                        return rollout(x, field, ac, control=u)

                def naive(
                    x: np.ndarray = x, v: np.ndarray = v, r1: np.ndarray = r1, r2: np.ndarray = r2, g: np.ndarray = gam
                ) -> object:
                    return naive_rollout(x, v, r1, r2, g, field, lib.duration, lib.n_points)

                rate_fast = time_rate(fast, b, seconds)
                rate_naive = time_rate(naive, b, seconds)
                results[(mode, dist, b)] = rate_fast
                rows.append(
                    [mode, dist, str(b), fmt_rate(rate_fast), fmt_rate(rate_naive), f"{rate_fast / rate_naive:,.0f}x"]
                )

    print_table("Rollouts per second (one core)", header, rows)

    # sanity: the reference flies the same problem (Euler error only)
    case = make_case(np.random.default_rng(SEED + 1), field, lib, "primitive", True)
    x, p = case.states[:64], case.primitives[:64]  # type: ignore[index]
    row = lib.table[p]
    ref = naive_rollout(x, row[:, 1], row[:, 3], row[:, 4], row[:, 2], field, lib.duration, lib.n_points)
    got = rollout(x, field, ac, primitive=p).states
    d_pos = np.abs(got[:, -1, :2] - ref[:, -1, :2]).max()
    d_h = np.abs(got[:, -1, 3] - ref[:, -1, 3]).max()
    print(
        f"sanity (64 in-core primitives): max |final position - naive| {d_pos:.2f} m, "
        f"max |final height - naive| {d_h:.2f} m (the reference's Euler error, 0.1 s steps)"
    )

    ok = True
    for b, target in ((4096, TARGET_BATCH_4096), (1, TARGET_BATCH_1)):
        rate = results[("primitive", "uniform 3x3 km", b)]
        passed = rate >= target
        ok &= passed
        print(
            f"target: >= {target:,} primitive rollouts/s at batch {b}: {fmt_rate(rate)}  {'PASS' if passed else 'FAIL'}"
        )
    return 0 if ok else 1
