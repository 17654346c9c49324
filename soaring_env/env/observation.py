"""The observation vector: layout, units, bounds, and the compiled function that fills it.

Layout (``observe_thermals=True``, K = ``n_obs_thermals`` slots; with ``observe_thermals=False``
only the first 11 entries). Default scales: 1 km for distances and heights, 5 m/s for vertical
winds, 20 m/s for airspeed, 10 m/s for horizontal wind. Every entry is clipped to its bounds.

====  ======================  =====================================================  ==========
idx   name                    meaning [unit before scaling]                          bounds
====  ======================  =====================================================  ==========
0     goal_north              (goal north - Pn) / position_scale [m]                 [-10, 10]
1     goal_east               (goal east - Pe) / position_scale [m]                  [-10, 10]
2     goal_up                 (goal height - h) / height_scale [m]                   [-3, 3]
3     sin_course              sin(chi) [-]                                           [-1, 1]
4     cos_course              cos(chi) [-]                                           [-1, 1]
5     height                  h / height_scale [m]                                   [-1, 3]
6     updraft                 w_up at the aircraft / updraft_scale [m/s]             [-4, 4]
7     edge_lift               mean updraft along the last edge / updraft_scale       [-4, 4]
                              [m/s] (what a variometer sensed; 0 at reset)
8     airspeed                airspeed of the last edge / speed_scale [m/s]          [0, 2]
                              (0 at reset: no previous edge)
9     wind_north              ambient wind towards north / wind_scale [m/s]          [-4, 4]
10    wind_east               ambient wind towards east / wind_scale [m/s]           [-4, 4]
11+5j thermal_j_present       1 if slot j holds a thermal, else 0 (all slot zeros)   [0, 1]
12+5j thermal_j_north         (centre north - Pn) / position_scale [m]               [-10, 10]
13+5j thermal_j_east          (centre east - Pe) / position_scale [m]                [-10, 10]
14+5j thermal_j_peak          peak updraft at the aircraft's height / updraft_scale  [0, 4]
                              [m/s] (Allen: w_peak(h); Gaussian: W), of the current
                              strength (life cycle and fluctuation at time t)
15+5j thermal_j_radius        updraft radius at that height / position_scale [m]     [0, 4]
                              (Allen: r2(h); Gaussian: R)
====  ======================  =====================================================  ==========

Slots hold the K living thermals nearest to the aircraft (horizontal distance, centres at the
current time), nearest first; ties keep scenario order. A thermal with a life cycle that is not yet
born or already dead at the current time is absent: it holds no slot (as in the updraft model, where
Allen's nearest-thermal rule skips it); with fewer living thermals than K the last slots are zeros.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from soaring_env._jit import ERROR_MODEL as _EM
from soaring_env.model import N_CLASSIFY_PARAMS, classify_params
from soaring_env.physics.thermals import _GAUSSIAN, COL_DYNAMIC, _r1_over_r2, row_absent, row_factor, updraft_at
from soaring_env.primitives import FP_DRIFT_EAST, FP_WIND_NORTH, field_params
from soaring_env.scenario import Scenario

BASE_FEATURES = (
    ("goal_north", -10.0, 10.0),
    ("goal_east", -10.0, 10.0),
    ("goal_up", -3.0, 3.0),
    ("sin_course", -1.0, 1.0),
    ("cos_course", -1.0, 1.0),
    ("height", -1.0, 3.0),
    ("updraft", -4.0, 4.0),
    ("edge_lift", -4.0, 4.0),
    ("airspeed", 0.0, 2.0),
    ("wind_north", -4.0, 4.0),
    ("wind_east", -4.0, 4.0),
)
THERMAL_FEATURES = (
    ("present", 0.0, 1.0),
    ("north", -10.0, 10.0),
    ("east", -10.0, 10.0),
    ("peak", 0.0, 4.0),
    ("radius", 0.0, 4.0),
)
N_BASE = len(BASE_FEATURES)
N_THERMAL_FEATURES = len(THERMAL_FEATURES)

# Columns of the per-env scenario parameter rows (see :func:`scenario_params`).
(P_GN, P_GE, P_GH, P_GR, P_NMIN, P_NMAX, P_EMIN, P_EMAX, P_HMAX, P_WN, P_WE, P_ZI, P_MODEL, P_DVX, P_DVY) = range(15)
N_PARAMS = 15
assert (P_WN, P_DVY) == (N_CLASSIFY_PARAMS + FP_WIND_NORTH, N_CLASSIFY_PARAMS + FP_DRIFT_EAST)  # field_params


#: Entries a task may add between the base entries and the thermal slots (name, low, high).
TASK_FEATURES = {
    "battery": ("battery", 0.0, 1.0),  # battery left / budget
    "time_left": ("time_left", 0.0, 1.0),  # flight time left / time limit
    "start_north": ("start_north", -10.0, 10.0),  # (start north - Pn) / position_scale [m]
    "start_east": ("start_east", -10.0, 10.0),  # (start east - Pe) / position_scale [m]
}
HISTORY_FEATURES = (("lift", -4.0, 4.0), ("climb", -4.0, 4.0), ("turn", -1.0, 1.0))
#: with ``history_positions``: where a past edge's lift was sensed (its time midpoint) relative to
#: the aircraft now, north and east / position_scale [m]
HISTORY_POSITION_FEATURES = (("north", -10.0, 10.0), ("east", -10.0, 10.0))
N_GOAL = 3  # the goal entries lead the base entries


def observation_layout(
    observe_thermals: bool,
    n_thermals: int,
    *,
    goal: bool = True,
    extras: tuple[str, ...] = (),
    history: int = 0,
    history_positions: bool = False,
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Names, lower and upper bounds (float32) of the observation vector: the base entries (without
    the three goal entries for tasks without a goal), the task's ``extras`` (keys of
    :data:`TASK_FEATURES`), ``history`` x (lift, climb, turn and, with ``history_positions``, north,
    east) of the last edges (newest first), then the thermal slots."""
    feats = list(BASE_FEATURES if goal else BASE_FEATURES[N_GOAL:])
    feats += [TASK_FEATURES[k] for k in extras]
    per_edge = HISTORY_FEATURES + (HISTORY_POSITION_FEATURES if history_positions else ())
    for j in range(history):
        feats += [(f"history_{j}_{name}", lo, hi) for name, lo, hi in per_edge]
    if observe_thermals:
        for j in range(n_thermals):
            feats += [(f"thermal_{j}_{name}", lo, hi) for name, lo, hi in THERMAL_FEATURES]
    names = [f[0] for f in feats]
    low = np.array([f[1] for f in feats], dtype=np.float32)
    high = np.array([f[2] for f in feats], dtype=np.float32)
    return names, low, high


def scenario_params(sc: Scenario) -> np.ndarray:
    """The scenario as the (N_PARAMS,) float64 row read by the compiled env kernels; it starts
    with :func:`soaring_env.model.classify_params` (goal and domain)."""
    return np.concatenate([classify_params(sc), field_params(sc.field)])


@njit(cache=True, inline="always", error_model=_EM)
def _clip(v: float, lo: float, hi: float) -> float:
    return min(max(v, lo), hi)


@njit(cache=True, inline="always", error_model=_EM)
def _allen_profile(h: float, zi: float) -> tuple[float, float, float]:
    """Allen's profile at height h for w* = 1: (w_peak [m/s], r2 [m]) and 0 < h < zi as 1.0/0.0."""
    zz = min(max(h / zi, 0.0), 1.0)
    cb = zz ** (1.0 / 3.0)
    r2 = max(10.0, 0.102 * cb * (1.0 - 0.25 * zz) * zi)
    if h <= 0.0 or h >= zi:
        return 0.0, r2, 0.0
    r1 = _r1_over_r2(r2) * r2
    wbar = cb * (1.0 - 1.1 * zz)
    w_peak = 3.0 * wbar * (r2 * r2 * r2 - r2 * r2 * r1) / (r2 * r2 * r2 - r1 * r1 * r1)
    return max(w_peak, 0.0), r2, 1.0


@njit(cache=True, inline="always", error_model=_EM)
def observe_row(
    n: float,
    e: float,
    chi: float,
    h: float,
    t: float,
    v_prev: float,
    lift: float,
    prm: np.ndarray,
    th: np.ndarray,
    scales: np.ndarray,
    k_obs: int,
    low: np.ndarray,
    high: np.ndarray,
    goal_on: int,
    th_base: int,
    noise: np.ndarray,
    out: np.ndarray,
) -> float:
    """Fill one observation row ``out`` (float32) and return the updraft w_up [m/s] at the aircraft.

    ``th`` holds this scenario's thermals (WindField.packed rows), ``scales`` = (position, height,
    updraft, speed, wind) scales, ``k_obs`` the number of thermal slots (0: thermals hidden),
    ``goal_on`` 0 leaves out the goal entries, ``th_base`` is the index of the first thermal slot
    and ``noise`` (2,) [m/s] is added to the sensed updraft and edge lift (not to the returned w).
    The task's extra and history entries in between are the env's to fill.
    """
    ps = scales[0]
    hs = scales[1]
    us = scales[2]
    ss = scales[3]
    wsc = scales[4]
    model = int(prm[P_MODEL])
    zi = prm[P_ZI]
    dvx = prm[P_DVX]
    dvy = prm[P_DVY]
    w = updraft_at(n, e, h, t, th, model, zi, dvx, dvy)
    vals = (
        (prm[P_GN] - n) / ps,
        (prm[P_GE] - e) / ps,
        (prm[P_GH] - h) / hs,
        math.sin(chi),
        math.cos(chi),
        h / hs,
        w / us,
        lift / us,
        (v_prev / ss) if v_prev == v_prev else 0.0,
        prm[P_WN] / wsc,
        prm[P_WE] / wsc,
    )
    i = 0
    skip = 0 if goal_on else N_GOAL
    for v in vals:
        if skip > 0:
            skip -= 1
            continue
        out[i] = _clip(v, low[i], high[i])
        i += 1
    if noise[0] != 0.0:
        out[i - 5] = _clip((w + noise[0]) / us, low[i - 5], high[i - 5])
    if noise[1] != 0.0:
        out[i - 4] = _clip((lift + noise[1]) / us, low[i - 4], high[i - 4])
    if k_obs == 0:
        return w
    nth = th.shape[0]
    ox = dvx * t
    oy = dvy * t
    unit_peak = 0.0
    allen_r2 = 0.0
    if model != _GAUSSIAN:
        unit_peak, allen_r2, _ = _allen_profile(h, zi)
    prev_d2 = -1.0
    prev_j = -1
    for slot in range(k_obs):
        base = th_base + N_THERMAL_FEATURES * slot
        # The next nearest thermal in the order (d2, index) after the previous slot's one.
        best = -1
        best_d2 = 0.0
        for j in range(nth):
            if row_absent(th, j, t):  # unborn or dead: no slot
                continue
            dx = th[j, 0] + ox - n
            dy = th[j, 1] + oy - e
            dj = dx * dx + dy * dy
            if (dj > prev_d2 or (dj == prev_d2 and j > prev_j)) and (best < 0 or dj < best_d2):
                best = j
                best_d2 = dj
        if best < 0:
            for c in range(N_THERMAL_FEATURES):
                out[base + c] = 0.0
            continue
        prev_d2 = best_d2
        prev_j = best
        w_now = th[best, 2]
        if th[best, COL_DYNAMIC] != 0.0:  # the current strength (steady rows: the old numbers)
            w_now *= row_factor(th, best, t)
        if model == _GAUSSIAN:
            peak = w_now
            radius = th[best, 3]
        else:  # w_peak scales linearly with w*
            peak = w_now * unit_peak
            radius = allen_r2
        out[base] = 1.0
        out[base + 1] = _clip((th[best, 0] + ox - n) / ps, low[base + 1], high[base + 1])
        out[base + 2] = _clip((th[best, 1] + oy - e) / ps, low[base + 2], high[base + 2])
        out[base + 3] = _clip(peak / us, low[base + 3], high[base + 3])
        out[base + 4] = _clip(radius / ps, low[base + 4], high[base + 4])
    return w


@njit(cache=True, error_model=_EM)
def goal_distance(n: float, e: float, h: float, prm: np.ndarray) -> float:
    """3-D distance [m] to the goal centre, evaluated like ``GoalRegion.distance``."""
    dn = n - prm[P_GN]
    de = e - prm[P_GE]
    dh = h - prm[P_GH]
    return math.sqrt(dn * dn + de * de + dh * dh)


@njit(cache=True, error_model=_EM)
def observe_batch(
    states: np.ndarray,
    times: np.ndarray,
    v_prev: np.ndarray,
    lift: np.ndarray,
    prm: np.ndarray,
    th: np.ndarray,
    nth: np.ndarray,
    scales: np.ndarray,
    k_obs: int,
    low: np.ndarray,
    high: np.ndarray,
    goal_on: int,
    th_base: int,
    noise: np.ndarray,
    rows: np.ndarray,
    upd: np.ndarray,
    dist: np.ndarray,
    obs: np.ndarray,
) -> None:
    """Observe envs ``rows``: fill ``obs[b]``, ``upd[b]`` [m/s] and ``dist[b]`` [m] for b in rows
    (``noise`` (B, 2): see :func:`observe_row`)."""
    for b in rows:
        upd[b] = observe_row(
            states[b, 0],
            states[b, 1],
            states[b, 2],
            states[b, 3],
            times[b],
            v_prev[b],
            lift[b],
            prm[b],
            th[b, : nth[b]],
            scales,
            k_obs,
            low,
            high,
            goal_on,
            th_base,
            noise[b],
            obs[b],
        )
        dist[b] = goal_distance(states[b, 0], states[b, 1], states[b, 3], prm[b])


_U64 = np.uint64
_MASK53 = 2.0**-53


def _splitmix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finalizer (Steele, Lea, Flood 2014) on uint64 arrays (wrapping arithmetic)."""
    x = x + _U64(0x9E3779B97F4A7C15)
    x = (x ^ (x >> _U64(30))) * _U64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> _U64(27))) * _U64(0x94D049BB133111EB)
    return x ^ (x >> _U64(31))


def sensor_noise(keys: np.ndarray, steps: np.ndarray, sigma: float) -> np.ndarray:
    """(B, 2) Gaussian sensor noise [m/s] of standard deviation ``sigma`` for the updraft and the
    edge-lift readings of step ``steps[b]`` of the episode with key ``keys[b]`` (uint64 arrays).

    A counter-based generator (a hash of key and step, then Box-Muller): the noise of a step does
    not depend on what else was drawn, so single and batched envs give the same numbers and an
    episode replays bit for bit from its seed.
    """
    with np.errstate(over="ignore"):
        x = _splitmix64(keys ^ _splitmix64(steps.astype(np.uint64)))
        y = _splitmix64(x)
    u1 = ((x >> _U64(11)).astype(np.float64) + 1.0) * _MASK53  # (0, 1]: the log is finite
    u2 = (y >> _U64(11)).astype(np.float64) * _MASK53
    r = sigma * np.sqrt(-2.0 * np.log(u1))
    return np.stack([r * np.cos(2.0 * np.pi * u2), r * np.sin(2.0 * np.pi * u2)], axis=1)
