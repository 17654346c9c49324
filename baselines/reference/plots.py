"""Figures from reference files: the best and the direct plans of each action set, replayed through
``env.step`` (top view over the thermals, and height over time)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from baselines.reference.yardstick import ScenarioReference

_ENV_IDS = {"primitive": "soaring/Soaring-v0", "continuous": "soaring/SoaringContinuous-v0"}


def replay(ref: ScenarioReference, sampler: str, which: str = "best") -> tuple[np.ndarray, np.ndarray, float]:
    """Fly the ``which`` (``"best"`` or ``"direct"``) plan of ``sampler`` through ``env.step`` in the
    reference's scenario: (every flown point [Pn, Pe, chi, h] (M, 4), times [s] (M,), energy [J/kg])."""
    import gymnasium as gym

    import soaring_env  # noqa: F401  (registers the ids)

    r = ref.samplers[sampler]
    actions = r.actions if which == "best" else r.direct_actions
    env = gym.make(_ENV_IDS[sampler])
    env.reset(seed=0, options={"scenario": ref.scenario})
    base: Any = env.unwrapped
    info: dict[str, Any] = {"energy_spent": 0.0}
    for a in actions:
        act = int(a) if sampler == "primitive" else np.asarray(a, dtype=np.float32)
        _, _, term, trunc, info = env.step(act)
        if term or trunc:
            break
    path = np.asarray(base.path, dtype=np.float64)
    lib = base.library
    dt = lib.duration / lib.n_points
    times = np.arange(len(path)) * dt  # output points are dt apart along every edge
    env.close()
    return path, times, float(info["energy_spent"])


def plot_reference(ref: ScenarioReference, png: str | Path) -> Path:
    """Top view and height over time of the best and direct plans of every action set in ``ref``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sc = ref.scenario
    fig, (ax, axh) = plt.subplots(1, 2, figsize=(13, 5.5), constrained_layout=True, width_ratios=(1, 1.6))
    colours = {"primitive": "tab:blue", "continuous": "tab:red"}
    for t in sc.field.thermals:
        r2 = sc.field.allen_profile(sc.start[3])["r2"] if sc.field.model == "allen" else t.radius
        ax.add_patch(plt.Circle((t.east, t.north), r2, color="gold", alpha=0.5, lw=0))
    g = sc.require_goal()
    ax.add_patch(plt.Circle((g.east, g.north), g.radius, fill=False, color="green", lw=1.5))
    ax.plot(sc.start[1], sc.start[0], "k^", ms=9, label="start")
    for sampler, r in ref.samplers.items():
        for which, style in (("best", "-"), ("direct", ":")):
            if not (r.actions if which == "best" else r.direct_actions):
                continue
            path, times, energy = replay(ref, sampler, which)
            cost = r.best_cost if which == "best" else r.direct_cost
            label = f"{sampler}, {'best' if which == 'best' else 'direct (no thermals)'}: {cost:,.0f} J/kg"
            if which == "direct":
                label += f", flown with thermals: {energy:,.0f}"
            ax.plot(path[:, 1], path[:, 0], style, color=colours.get(sampler, "k"), lw=1.3)
            axh.plot(times, path[:, 3], style, color=colours.get(sampler, "k"), lw=1.3, label=label)
    axh.axhspan(g.height - g.radius, g.height + g.radius, color="green", alpha=0.08, label="goal heights")
    axh.axhline(sc.field.zi, color="grey", lw=0.8, ls="--", label="zi (no lift above)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title(f"{sc.name}: reference plans (gold: thermal core r2, green: goal region)")
    ax.legend(fontsize=7, loc="best")
    axh.set_xlabel("time [s]")
    axh.set_ylabel("height [m]")
    axh.set_title(f"height; lower bound {ref.lower_bound:,.0f} J/kg")
    axh.legend(fontsize=7, loc="best")
    axh.grid(alpha=0.3)
    out = Path(png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


__all__ = ["plot_reference", "replay"]
