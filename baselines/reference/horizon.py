"""The thermal-climb reference: a deterministic beam search for the most energy gained in a fixed time.

The thermal-climb task (``soaring/ThermalClimb-v0``, ``soaring/ThermalClimbContinuous-v0``) has no
goal: its return is the net specific energy gained over ``time_limit``, ``E = -sum(edge costs)``
(g x height gained minus motor energy). This search answers "how much is possible here with this
action set", as :mod:`baselines.reference.beam` does for goal reaching:

1. expand every node of the beam with every control of the control set (one batched model call
   per chunk, the calls ``env.step`` makes, so plans replay bit for bit);
2. edges that crash or leave the domain end the episode early and are dropped (an episode that
   ends early forfeits the rest of the climb and pays the penalty);
3. children that fall into the same cell -- (north, east) on a grid of ``cell_size``, course in
   ``course_cells`` sectors, height in ``height_cell`` layers, last airspeed -- are merged: the one
   that has gained the most energy survives. All nodes of a depth share the flight time, so this
   is the only dominance (nodes of different depths are not comparable: time left matters);
4. the ``beam_width`` nodes with the most energy form the next beam (ties: lower index).

At the horizon the node with the most energy is the reference plan. Costs need no reweighting here:
every node of a depth is compared at the same time, and the objective is the raw energy itself.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from soaring_env._validation import ConfigError, check_choice, check_int, check_positive
from soaring_env.model import FLYING, SoaringModel
from soaring_env.physics.atmosphere import G

SAMPLERS = ("primitive", "continuous")
#: Airspeeds of the continuous control set as fractions of the envelope's range.
SPEED_FRACTIONS = (0.0, 0.15, 0.35, 0.7)
#: Bank angles of the continuous control set as fractions of the envelope's bank limit at that speed.
BANK_FRACTIONS = (-1.0, -0.7, -0.4, 0.0, 0.4, 0.7, 1.0)
_ROWS_PER_CALL = 1 << 16


@dataclass(frozen=True)
class HorizonConfig:
    """Settings of :func:`energy_search`.

    :param beam_width: nodes kept per depth -- the accuracy knob.
    :param cell_size: horizontal cell of the dominance grid [m].
    :param height_cell: height layer of the dominance grid [m].
    :param course_cells: course sectors of the dominance grid.
    """

    beam_width: int = 1000
    cell_size: float = 60.0
    height_cell: float = 15.0
    course_cells: int = 8

    def __post_init__(self) -> None:
        check_int("beam_width", self.beam_width, 1, 1_000_000)
        check_positive("cell_size", self.cell_size)
        check_positive("height_cell", self.height_cell)
        check_int("course_cells", self.course_cells, 1, 1024)


@dataclass(frozen=True)
class HorizonResult:
    """The best plan of :func:`energy_search`: ``energy`` [J/kg] gained (-inf if every plan ends
    early), ``actions`` the env actions (primitive indices (n,) or normalized (n, 3) float32),
    ``rollouts`` edges flown, ``seconds`` wall time, ``n_controls`` the control set's size."""

    energy: float
    actions: np.ndarray
    rollouts: int
    seconds: float
    n_controls: int


def continuous_controls(model: SoaringModel) -> np.ndarray:
    """(M, 3) float32-exact normalized actions: airspeeds x bank angles (:data:`SPEED_FRACTIONS`,
    :data:`BANK_FRACTIONS` of the envelope), each at its zero-thrust glide angle (rounded so that it
    needs no thrust) and level."""
    env = model.control_envelope
    if env.kind != "physical":
        raise ConfigError("the climb reference's continuous set needs the physical envelope (envelope='physical')")
    v_lo, v_hi = env.airspeed
    h_top = model.scenario.bounds.height_max
    rows = []
    for f in SPEED_FRACTIONS:
        v = v_lo + f * (v_hi - v_lo)
        for b in BANK_FRACTIONS:
            chi_dot = G * math.tan(b * float(env.bank_limit(v))) / v
            glide = float(model.aircraft.glide_angle(v, chi_dot, h_top))
            for gamma in (glide, 0.0):
                a = np.clip(model.control_to_action(np.array([v, chi_dot, gamma])), -1.0, 1.0).astype(np.float32)
                while float(model.action_to_control(a.astype(np.float64))[2]) > gamma and a[2] > -1.0:
                    a[2] = np.nextafter(a[2], np.float32(-1.0))  # stay at zero thrust after rounding
                rows.append(a)
    return np.unique(np.array(rows, dtype=np.float32), axis=0)


def energy_search(
    model: SoaringModel,
    sampler: str,
    horizon: float,
    config: HorizonConfig | None = None,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> HorizonResult:
    """The plan that gains the most energy in ``horizon`` [s] from the scenario's start (module docstring).

    :param model: the env's model (``env.unwrapped.model``: scenario, aircraft, library, envelope).
    :param sampler: ``"primitive"`` (the allowed primitives) or ``"continuous"`` (:func:`continuous_controls`).
    :param horizon: flight time [s]; ``round(horizon / Ts)`` edges.
    :param progress: called as ``progress(depth, depths)``.
    """
    if not isinstance(model, SoaringModel):
        raise ConfigError(f"model={model!r} must be a soaring_env.model.SoaringModel")
    check_choice("sampler", sampler, SAMPLERS)
    cfg = config if config is not None else HorizonConfig()
    ts = model.library.duration
    depths = int(round(check_positive("horizon", horizon) / ts))
    if depths < 1:
        raise ConfigError(f"horizon={horizon!r} s is shorter than one step (Ts = {ts:g} s)")
    t_start = time.perf_counter()
    if sampler == "primitive":
        ctrls = np.flatnonzero(model.allowed_primitives()).astype(np.float64)[:, None]
        speeds = model.library.table[ctrls[:, 0].astype(np.int64), 1]
    else:
        ctrls = continuous_controls(model).astype(np.float64)
        speeds = model.action_to_control(ctrls)[:, 0]
    speed_key = np.unique(speeds, return_inverse=True)[1].astype(np.int64)
    m = len(ctrls)
    x = model.scenario.start_state[None, :]
    vp = np.full(1, np.nan)
    energy = np.zeros(1)
    last_speed = np.zeros(1, dtype=np.int64)
    chosen: list[np.ndarray] = []  # per depth: (parent index, control index) of the kept nodes
    rollouts = 0
    for depth in range(depths):
        n = len(x)
        par = np.repeat(np.arange(n, dtype=np.int64), m)
        ctl = np.tile(np.arange(m, dtype=np.int64), n)
        end = np.empty((n * m, 4))
        cost = np.empty(n * m)
        ok = np.empty(n * m, dtype=bool)
        for s in range(0, n * m, _ROWS_PER_CALL):
            sl = slice(s, min(s + _ROWS_PER_CALL, n * m))
            r = _fly(model, sampler, x[par[sl]], ctrls[ctl[sl]], depth * ts, vp[par[sl]])
            code, _ = model.classify(r)
            end[sl], cost[sl], ok[sl] = r.final, r.cost, code == FLYING
        rollouts += n * m
        e = energy[par] - cost
        keep = np.flatnonzero(ok)
        if len(keep) == 0:
            return HorizonResult(-math.inf, _empty_actions(sampler), rollouts, time.perf_counter() - t_start, m)
        key = _cell_keys(end[keep], speed_key[ctl[keep]], cfg)
        order = np.lexsort((np.arange(len(keep)), -e[keep], key))  # per cell: most energy, then first
        first = np.ones(len(order), dtype=bool)
        first[1:] = key[order[1:]] != key[order[:-1]]
        uniq = order[first]
        if len(uniq) > cfg.beam_width:
            uniq = uniq[np.lexsort((uniq, -e[keep][uniq]))[: cfg.beam_width]]
        sel = keep[np.sort(uniq)]
        x, energy = end[sel], e[sel]
        vp = speeds[ctl[sel]]
        last_speed = speed_key[ctl[sel]]
        chosen.append(np.stack([par[sel], ctl[sel]], axis=1))
        if progress is not None:
            progress(depth + 1, depths)
    del last_speed
    best = int(np.argmax(energy))  # first of the ties
    path = []
    i = best
    for step in reversed(chosen):
        p, c = step[i]
        path.append(int(c))
        i = int(p)
    idx = np.array(path[::-1], dtype=np.int64)
    actions = idx_actions(ctrls, idx, sampler)
    return HorizonResult(float(energy[best]), actions, rollouts, time.perf_counter() - t_start, m)


def idx_actions(ctrls: np.ndarray, idx: np.ndarray, sampler: str) -> np.ndarray:
    """The env actions of control-set rows ``idx``."""
    if sampler == "primitive":
        return ctrls[idx, 0].astype(np.int64)
    return ctrls[idx].astype(np.float32)


def _empty_actions(sampler: str) -> np.ndarray:
    return np.zeros(0, dtype=np.int64) if sampler == "primitive" else np.zeros((0, 3), dtype=np.float32)


def _fly(model: SoaringModel, sampler: str, x: np.ndarray, ctrls: np.ndarray, t0: float, vp: np.ndarray):
    """One batched model call: the edges ``env.step`` flies for these actions."""
    if sampler == "primitive":
        return model.rollout_primitive(x, ctrls[:, 0].astype(np.int64), t0=t0, airspeed_prev=vp)
    return model.rollout_control(x, model.action_to_control(ctrls), t0=t0, airspeed_prev=vp)


def _cell_keys(s: np.ndarray, speed: np.ndarray, cfg: HorizonConfig) -> np.ndarray:
    """One int64 per state: its (north, east, height, course, airspeed) cell."""
    n = np.floor(s[:, 0] / cfg.cell_size).astype(np.int64) + (1 << 14)
    e = np.floor(s[:, 1] / cfg.cell_size).astype(np.int64) + (1 << 14)
    h = np.floor(s[:, 3] / cfg.height_cell).astype(np.int64)
    c = np.floor((s[:, 2] + math.pi) / (2 * math.pi) * cfg.course_cells).astype(np.int64) % cfg.course_cells
    return (((n * (1 << 15) + e) * (1 << 12) + h) * 1024 + c) * 16 + speed
