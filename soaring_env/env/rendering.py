"""Pictures of an episode: top view over the updraft field, 3-D view, height and energy traces.

matplotlib is imported only here, and only when an env renders. ``rgb_array`` frames are drawn
off-screen with the Agg canvas (no display needed); ``human`` opens a pyplot window when the
backend is interactive and silently draws off-screen otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from soaring_env.scenario import Scenario

_NON_INTERACTIVE = {"agg", "pdf", "ps", "svg", "pgf", "cairo", "template"}
_OUTCOME_COLOURS = {"flying": "#1f3b73", "goal": "#1a8f3a", "crash": "#c0392b", "out_of_bounds": "#d35400"}


class EpisodeView(Protocol):
    """What the renderer reads of an env (:class:`~soaring_env.env.core.SoaringBaseEnv` has it):
    a protocol, so that rendering does not import the env module that imports it."""

    @property
    def continuous(self) -> bool: ...
    @property
    def scenario(self) -> Scenario: ...
    @property
    def state(self) -> np.ndarray: ...  # [Pn, Pe, chi, h] [m, m, rad, m]
    @property
    def time(self) -> float: ...  # [s]
    @property
    def steps(self) -> int: ...
    @property
    def energy_spent(self) -> float: ...  # [J/kg]
    @property
    def outcome(self) -> str: ...
    @property
    def path(self) -> np.ndarray: ...  # every flown point (M, 4)
    @property
    def history(self) -> Mapping[str, Sequence[float]]: ...  # per-step traces


class Renderer:
    """Draws :class:`EpisodeView` states (the envs') into one matplotlib figure.

    :param size: (width, height) of the frame [px].
    :param human: show the figure in a window (pyplot) instead of drawing off-screen only.
    :param grid: resolution of the updraft heat map (cells per side).
    """

    def __init__(self, size: tuple[int, int] = (960, 640), human: bool = False, grid: int = 240) -> None:
        import matplotlib

        self.size = size
        self.grid = grid
        self.dpi = 100
        figsize = (size[0] / self.dpi, size[1] / self.dpi)
        self.human = human and matplotlib.get_backend().lower() not in _NON_INTERACTIVE
        if self.human:
            import matplotlib.pyplot as plt

            plt.ion()
            self.fig = plt.figure(figsize=figsize, dpi=self.dpi)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.fig = Figure(figsize=figsize, dpi=self.dpi)
            FigureCanvasAgg(self.fig)
        self._heat_key: tuple[Any, ...] | None = None
        self._heat: np.ndarray | None = None

    def close(self) -> None:
        if self.human:
            import matplotlib.pyplot as plt

            plt.close(self.fig)
        self.fig.clf()

    # --- the updraft field at the aircraft's height ---------------------------------------------------
    def _heatmap(self, env: EpisodeView, height: float, t: float) -> tuple[np.ndarray, list[float]]:
        sc = env.scenario
        b = sc.bounds
        # the map changes with time where thermals drift, live and die, or fluctuate
        key = (id(sc), round(height / 10.0), round(t) if sc.field.drift or not sc.field.steady else 0)
        extent = [b.east_min / 1e3, b.east_max / 1e3, b.north_min / 1e3, b.north_max / 1e3]
        if key != self._heat_key or self._heat is None:
            g = self.grid
            ee, nn = np.meshgrid(np.linspace(b.east_min, b.east_max, g), np.linspace(b.north_min, b.north_max, g))
            self._heat = sc.field.updraft(nn, ee, np.full_like(nn, max(height, 1.0)), t)
            self._heat_key = key
        return self._heat, extent

    # --- drawing --------------------------------------------------------------------------------------
    def draw(self, env: EpisodeView) -> np.ndarray:
        """Draw the current episode and return the frame (uint8, H x W x 3)."""
        fig = self.fig
        fig.clf()
        sc = env.scenario
        path = env.path
        hist = env.history
        state = np.asarray(env.state, dtype=np.float64)
        h_now = float(state[3])
        outcome = env.outcome
        colour = _OUTCOME_COLOURS.get(outcome, "#1f3b73")
        gs = fig.add_gridspec(2, 1, height_ratios=[1.75, 1.0], left=0.06, right=0.985, bottom=0.075, top=0.895)
        gs.update(hspace=0.28)
        top = gs[0].subgridspec(1, 2, width_ratios=[1.0, 1.1], wspace=0.12)
        bottom = gs[1].subgridspec(1, 3, wspace=0.32)
        self._top_view(fig.add_subplot(top[0]), env, path, state, colour)
        self._view_3d(fig.add_subplot(top[1], projection="3d"), env, path, colour)
        self._height_trace(fig.add_subplot(bottom[0]), env, hist)
        self._updraft_trace(fig.add_subplot(bottom[1]), hist)
        self._energy_trace(fig.add_subplot(bottom[2]), hist)
        kind = "continuous" if env.continuous else "primitives"
        fig.suptitle(
            f"Soaring ({kind}) | scenario '{sc.name}' | t = {env.time:.0f} s, step {env.steps} | "
            f"h = {h_now:.0f} m | energy spent {env.energy_spent / 1e3:.2f} kJ/kg | {outcome.replace('_', ' ')}",
            fontsize=10,
            color=colour if outcome != "flying" else "black",
            fontweight="bold" if outcome != "flying" else "normal",
        )
        fig.canvas.draw()
        if self.human:
            import matplotlib.pyplot as plt

            fig.canvas.flush_events()
            plt.pause(0.001)
        canvas: Any = fig.canvas
        buf = np.asarray(canvas.buffer_rgba())
        return np.ascontiguousarray(buf[..., :3])

    def _top_view(self, ax: Any, env: EpisodeView, path: np.ndarray, state: np.ndarray, colour: str) -> None:
        from matplotlib.patches import Circle, FancyArrow, Rectangle

        sc = env.scenario
        b = sc.bounds
        g = sc.goal
        heat, extent = self._heatmap(env, float(state[3]), env.time)
        vmax = max(1.0, float(np.abs(heat).max()))
        im = ax.imshow(
            heat, origin="lower", extent=extent, cmap="RdBu_r", vmin=-vmax, vmax=vmax, interpolation="bilinear"
        )
        cb = ax.figure.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
        cb.set_label(f"updraft at h = {state[3]:.0f} m [m/s]", fontsize=8)
        cb.ax.tick_params(labelsize=7)
        ax.add_patch(
            Rectangle(
                (b.east_min / 1e3, b.north_min / 1e3),
                (b.east_max - b.east_min) / 1e3,
                (b.north_max - b.north_min) / 1e3,
                fill=False,
                lw=1.5,
                ec="0.3",
            )
        )
        centres = sc.field.centres(env.time)
        f = sc.field
        alive = f.alive(env.time)
        for j, (cn, ce) in enumerate(centres):
            if not alive[j]:  # not yet born or already dead: a faint marker only
                ax.plot(ce / 1e3, cn / 1e3, marker="+", ms=7, mew=1.0, color="0.55", alpha=0.6)
                continue
            if f.model == "allen":
                r_core = f.allen_profile(min(max(float(state[3]), 1.0), f.zi))["r2"]
            else:
                r_core = f.thermals[j].radius
            ax.add_patch(Circle((ce / 1e3, cn / 1e3), r_core / 1e3, fill=False, ec="#7b1010", lw=0.8, ls="--"))
            ax.plot(ce / 1e3, cn / 1e3, marker="+", ms=9, mew=1.5, color="#7b1010")
            ax.annotate(f"T{j}", (ce / 1e3, cn / 1e3), xytext=(4, 4), textcoords="offset points", fontsize=7)
        if g is not None:
            ax.add_patch(Circle((g.east / 1e3, g.north / 1e3), g.radius / 1e3, fc="#2ecc71", ec="#145a32", alpha=0.6))
            ax.annotate("goal", (g.east / 1e3, g.north / 1e3), xytext=(0, -14), textcoords="offset points",
                        ha="center", fontsize=8, color="#145a32", fontweight="bold")  # fmt: skip
        s0 = sc.start
        ax.plot(s0[1] / 1e3, s0[0] / 1e3, marker="o", ms=6, color="black")
        ax.annotate("start", (s0[1] / 1e3, s0[0] / 1e3), xytext=(0, -13), textcoords="offset points",
                    ha="center", fontsize=8)  # fmt: skip
        ax.plot(path[:, 1] / 1e3, path[:, 0] / 1e3, color=colour, lw=1.8)
        span = max(b.east_max - b.east_min, b.north_max - b.north_min) / 1e3
        arrow = 0.05 * span
        chi = float(state[2])
        ax.add_patch(
            FancyArrow(
                state[1] / 1e3,
                state[0] / 1e3,
                arrow * math.sin(chi),
                arrow * math.cos(chi),
                width=0.008 * span,
                head_width=0.03 * span,
                head_length=0.03 * span,
                length_includes_head=True,
                color=colour,
            )
        )
        wn, we = sc.field.wind_north, sc.field.wind_east
        ws = math.hypot(wn, we)
        if ws > 0.05:
            x0 = b.east_min / 1e3 + 0.1 * span
            y0 = b.north_max / 1e3 - 0.1 * span
            k = 0.07 * span / ws
            ax.annotate("", xy=(x0 + k * we, y0 + k * wn), xytext=(x0, y0),
                        arrowprops={"arrowstyle": "->", "color": "black", "lw": 1.5})  # fmt: skip
            ax.text(x0, y0 - 0.05 * span, f"wind {ws:.1f} m/s", fontsize=7, ha="center")
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.set_aspect("equal")
        self._zoom_inset(ax, env, path, state, colour, extent)
        ax.set_xlabel("east [km]", fontsize=8)
        ax.set_ylabel("north [km]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_title("top view", fontsize=9)

    def _zoom_inset(
        self, ax: Any, env: EpisodeView, path: np.ndarray, state: np.ndarray, colour: str, extent: list[float]
    ) -> None:
        """A 700 m x 700 m close-up of the updraft around the aircraft, in the emptiest corner."""
        from matplotlib.patches import Rectangle

        half = 350.0
        n0, e0, h0 = float(state[0]), float(state[1]), float(state[3])
        f = env.scenario.field
        cells = 90
        ee, nn = np.meshgrid(np.linspace(e0 - half, e0 + half, cells), np.linspace(n0 - half, n0 + half, cells))
        w = f.updraft(nn, ee, np.full_like(nn, max(h0, 1.0)), env.time)
        # the corner of the map holding the fewest path points
        px = (path[:, 1] / 1e3 - extent[0]) / (extent[1] - extent[0])
        py = (path[:, 0] / 1e3 - extent[2]) / (extent[3] - extent[2])
        corners = [(0.6, 0.6), (0.02, 0.6), (0.6, 0.02), (0.02, 0.02)]
        counts = [np.count_nonzero((px > cx) & (px < cx + 0.38) & (py > cy) & (py < cy + 0.38)) for cx, cy in corners]
        cx, cy = corners[int(np.argmin(counts))]
        ins = ax.inset_axes([cx, cy, 0.38, 0.38])
        vmax = max(1.0, float(np.abs(w).max()))
        ins.imshow(
            w,
            origin="lower",
            extent=[-half, half, -half, half],
            cmap="RdBu_r",
            vmin=-vmax,
            vmax=vmax,
            interpolation="bilinear",
        )
        from matplotlib.patches import Circle

        g = env.scenario.goal
        if g is not None:
            ins.add_patch(Circle((g.east - e0, g.north - n0), g.radius, fc="#2ecc71", ec="#145a32", alpha=0.5))
        for (tn, te), live in zip(f.centres(env.time), f.alive(env.time), strict=True):
            ins.plot(te - e0, tn - n0, marker="+", ms=7, mew=1.2, color="#7b1010" if live else "0.55")
        ins.plot(path[:, 1] - e0, path[:, 0] - n0, color=colour, lw=1.0)
        ins.plot(0.0, 0.0, marker=(3, 0, -math.degrees(float(state[2]))), ms=8, color=colour)
        ins.set_xlim(-half, half)
        ins.set_ylim(-half, half)
        ins.set_xticks([])
        ins.set_yticks([])
        ins.text(0.03, 0.04, "zoom: 700 m", transform=ins.transAxes, fontsize=6.5, color="0.15")
        ax.add_patch(
            Rectangle(
                ((e0 - half) / 1e3, (n0 - half) / 1e3), 2 * half / 1e3, 2 * half / 1e3, fill=False, lw=0.8, ec="0.2"
            )
        )

    def _view_3d(self, ax: Any, env: EpisodeView, path: np.ndarray, colour: str) -> None:
        sc = env.scenario
        b = sc.bounds
        g = sc.goal
        f = sc.field
        centres = f.centres(env.time)
        # Zoom on what matters: the path, the goal and the thermals, with a margin [km].
        goal_e, goal_n = ([], []) if g is None else ([g.east], [g.north])
        pts_e = np.concatenate([path[:, 1], goal_e, centres[:, 1]]) / 1e3
        pts_n = np.concatenate([path[:, 0], goal_n, centres[:, 0]]) / 1e3
        half = 0.5 * max(np.ptp(pts_e), np.ptp(pts_n)) + 0.4
        ce, cn = 0.5 * (pts_e.min() + pts_e.max()), 0.5 * (pts_n.min() + pts_n.max())
        xlim = (max(ce - half, b.east_min / 1e3), min(ce + half, b.east_max / 1e3))
        ylim = (max(cn - half, b.north_min / 1e3), min(cn + half, b.north_max / 1e3))
        zmax = max(float(path[:, 3].max()), 0.0 if g is None else g.height + g.radius, 100.0) * 1.1
        top = min(f.zi, zmax)
        theta = np.linspace(0.0, 2.0 * math.pi, 32)
        alive = f.alive(env.time)
        for j, (tn, te) in enumerate(centres):
            if not alive[j]:  # no column for a thermal that does not exist now
                continue
            r = (0.0765 * f.zi if f.model == "allen" else f.thermals[j].radius) / 1e3
            xs, ys = te / 1e3 + r * np.cos(theta), tn / 1e3 + r * np.sin(theta)
            ax.plot(xs, ys, np.zeros_like(theta), color="#c0392b", lw=0.8)
            ax.plot(xs, ys, np.full_like(theta, top), color="#c0392b", lw=0.8, alpha=0.6)
            ax.plot([te / 1e3] * 2, [tn / 1e3] * 2, [0.0, top], color="#c0392b", lw=2.5, alpha=0.5)
        u, v = np.meshgrid(np.linspace(0, 2 * math.pi, 16), np.linspace(0, math.pi, 9))
        if g is not None:
            rk = g.radius / 1e3
            ax.plot_surface(
                g.east / 1e3 + rk * np.cos(u) * np.sin(v),
                g.north / 1e3 + rk * np.sin(u) * np.sin(v),
                g.height + g.radius * np.cos(v),
                color="#2ecc71",
                alpha=0.45,
                linewidth=0,
            )
        pe, pn, ph = path[:, 1] / 1e3, path[:, 0] / 1e3, path[:, 3]
        ax.plot(pe, pn, np.zeros(len(path)), color="0.35", lw=1.0, ls="--")
        ax.plot(pe, pn, ph, color=colour, lw=1.8)
        ax.plot([pe[-1]] * 2, [pn[-1]] * 2, [0.0, ph[-1]], color=colour, lw=0.8, ls=":")
        ax.scatter([pe[-1]], [pn[-1]], [ph[-1]], color=colour, s=22, depthshade=False)
        ax.scatter([pe[0]], [pn[0]], [ph[0]], color="black", s=14, depthshade=False)
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        ax.set_zlim(0.0, zmax)
        span = max(xlim[1] - xlim[0], ylim[1] - ylim[0])
        ax.set_box_aspect((xlim[1] - xlim[0], ylim[1] - ylim[0], 0.55 * span))
        exaggeration = 0.55 * span * 1e3 / zmax
        ax.set_xlabel("east [km]", fontsize=7, labelpad=-3)
        ax.set_ylabel("north [km]", fontsize=7, labelpad=-3)
        ax.set_zlabel("height [m]", fontsize=7, labelpad=-1)
        ax.tick_params(labelsize=6, pad=-2)
        ax.view_init(elev=22, azim=-125)
        ax.set_title(f"3-D view (height x{exaggeration:.0f}; shadow dashed)", fontsize=9)

    def _height_trace(self, ax: Any, env: EpisodeView, hist: Mapping[str, Sequence[float]]) -> None:
        t = np.asarray(hist["time"]) / 60.0
        ax.plot(t, hist["height"], marker="o", ms=3, color="#1f3b73", label="height")
        g = env.scenario.goal
        if g is not None:
            ax.axhspan(g.height - g.radius, g.height + g.radius, color="#2ecc71", alpha=0.25, label="goal band")
        ax.axhline(0.0, color="#7f4f24", lw=2)
        ax.set_xlabel("time [min]", fontsize=8)
        ax.set_ylabel("height [m]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_ylim(bottom=min(-20.0, min(hist["height"]) - 20.0))
        ax.legend(fontsize=7, loc="best")
        ax.grid(alpha=0.3)
        ax.set_title("height", fontsize=9)

    def _updraft_trace(self, ax: Any, hist: Mapping[str, Sequence[float]]) -> None:
        t = np.asarray(hist["time"]) / 60.0
        w = np.asarray(hist["updraft"])
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.fill_between(t, 0.0, w, where=w >= 0, interpolate=True, color="#e74c3c", alpha=0.5, lw=0)
        ax.fill_between(t, 0.0, w, where=w < 0, interpolate=True, color="#3498db", alpha=0.5, lw=0)
        ax.plot(t, w, marker="o", ms=3, color="#c0392b")
        ax.set_xlabel("time [min]", fontsize=8)
        ax.set_ylabel("updraft [m/s]", fontsize=8)
        ax.set_ylim(min(-0.5, float(w.min()) - 0.2), max(1.0, float(w.max()) + 0.2))
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.set_title("updraft at the aircraft", fontsize=9)

    def _energy_trace(self, ax: Any, hist: Mapping[str, Sequence[float]]) -> None:
        t = np.asarray(hist["time"]) / 60.0
        e = np.asarray(hist["energy_spent"]) / 1e3
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.plot(t, e, marker="o", ms=3, color="#8e44ad")
        ax.set_xlabel("time [min]", fontsize=8)
        ax.set_ylabel("energy spent [kJ/kg]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.set_title("energy spent (net, J/kg / 1000)", fontsize=9)
