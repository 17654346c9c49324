"""Reproduce the paper's figure 1: every motion primitive expanded from the origin.

All 174 primitives are flown from ``[Pn, Pe, chi, h] = [0, 0, 0, h0]`` (heading north) in still air
through :func:`soaring_env.rollout`, and drawn in a 3D view and a top (bird's-eye) view side by side,
coloured by family as in the paper: straight green, curve blue, spiral black, spline red.

Usage::

    python scripts/plot_primitives.py [--out results/figures/primitives.png] [--ts 30] [--n 30]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from baselines._runs import check_cli_args
from soaring_env import Aircraft, PrimitiveLibrary, WindField, rollout
from soaring_env.primitives import FAMILIES

#: The paper's colours per family (figure 1 caption), in FAMILIES order.
COLOURS = {"straight": "tab:green", "curve": "tab:blue", "spiral": "black", "spline": "tab:red"}
#: Drawing order: spirals first so that the sparser families stay visible on top.
DRAW_ORDER = ("spiral", "curve", "straight", "spline")


def expand(ts: float, n: int, h0: float) -> tuple[PrimitiveLibrary, np.ndarray]:
    """Fly every primitive from the origin; returns the library and paths (174, n + 1, 4) with the
    start point prepended."""
    lib = PrimitiveLibrary(ts, n)
    start = np.array([0.0, 0.0, 0.0, h0])
    r = rollout(start, WindField(), Aircraft(), primitive=np.arange(len(lib)), library=lib)
    paths = np.concatenate([np.broadcast_to(start, (len(lib), 1, 4)), r.states], axis=1)
    return lib, paths


def plot(
    lib: PrimitiveLibrary, paths: np.ndarray, h0: float, out: Path, *, elev: float = 20.0, azim: float = -60.0
) -> Path:
    """Draw the 3D view and the top view and save a PNG at ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    fam = lib.family
    fig = plt.figure(figsize=(15, 6.8), layout="constrained")
    ax3: Any = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    for name in DRAW_ORDER:
        code = FAMILIES.index(name)
        lw = 0.7 if name == "spiral" else 1.1
        for i in np.flatnonzero(fam == code):
            north, east, height = paths[i, :, 0], paths[i, :, 1], paths[i, :, 3] - h0
            # x = east, y = north: a map with north up
            ax3.plot(east, north, height, color=COLOURS[name], lw=lw, alpha=0.8)
            ax2.plot(east, north, color=COLOURS[name], lw=lw, alpha=0.8)
    for ax in (ax3, ax2):
        ax.plot([0.0], [0.0], marker="o", color="gold", markeredgecolor="k", ms=7, zorder=5)
    for axis in (ax3.xaxis, ax3.yaxis, ax3.zaxis):
        axis.set_major_locator(MaxNLocator(5))
    ax3.set_xlabel("east Pe [m]", labelpad=8)
    ax3.set_ylabel("north Pn [m]", labelpad=8)
    ax3.set_zlabel("height change h - h0 [m]", labelpad=12)
    ax3.set_title("3D view")
    ax3.view_init(elev=elev, azim=azim)
    span = np.ptp(paths[:, :, [1, 0, 3]].reshape(-1, 3), axis=0)
    ax3.set_box_aspect(tuple(span / span.max()))  # true horizontal scale, height on the same scale
    ax2.set_xlabel("east Pe [m]")
    ax2.set_ylabel("north Pn [m]")
    ax2.set_title("top view (start at the origin, heading north)")
    ax2.set_aspect("equal", adjustable="datalim")
    ax2.grid(True, lw=0.4, alpha=0.5)
    counts = np.bincount(fam, minlength=4)
    handles = [
        Line2D([], [], color=COLOURS[name], lw=2, label=f"{name} ({counts[FAMILIES.index(name)]})") for name in FAMILIES
    ]
    handles.append(Line2D([], [], marker="o", ls="", color="gold", markeredgecolor="k", label="start"))
    ax2.legend(handles=handles, loc="upper left", fontsize=9, framealpha=0.9)
    fig.suptitle(
        f"The {len(lib)} motion primitives expanded from the origin "
        f"(Ts = {lib.duration:g} s, N = {lib.n_points}, still air, h0 = {h0:g} m)",
        fontsize=13,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=130)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/figures/primitives.png"), help="PNG to write")
    parser.add_argument("--ts", type=float, default=30.0, help="primitive duration Ts [s]")
    parser.add_argument("--n", type=int, default=30, help="output points N per primitive")
    parser.add_argument("--h0", type=float, default=1000.0, help="start height [m] (only offsets are drawn)")
    args = parser.parse_args(argv)
    check_cli_args(parser, args, counts=("n",), positive=("ts",))
    lib, paths = expand(args.ts, args.n, args.h0)
    out = plot(lib, paths, args.h0, args.out)
    print(out)
    return 0
