"""Compiled per-step work of the envs: the edge, its outcome, new state, sensed lift, observation.

The edge itself comes from the model's rollout kernel (the packed fast path of ``rollout`` behind
:class:`~soaring_env.primitives.Propagator`) and the outcome from
:func:`soaring_env.model.classify_row`, so ``env.step`` runs exactly the code of
:meth:`SoaringModel.rollout_primitive` / ``classify``. :func:`step_rows` runs both in one compiled
call per step (per thread block), skipping the rows whose result the env throws away.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from soaring_env._jit import ERROR_MODEL as _EM
from soaring_env.env.observation import goal_distance, observe_row
from soaring_env.model import CRASH, FLYING, GOAL, OUT_OF_BOUNDS, classify_batch, classify_row
from soaring_env.primitives import _rollout_kernel


@njit(cache=True, nogil=True, error_model=_EM)
def post_step(
    out: np.ndarray,
    x0: np.ndarray,
    ctrl: np.ndarray,
    dt: float,
    t_new: np.ndarray,
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
    codes: np.ndarray,
    ks: np.ndarray,
    new_states: np.ndarray,
    upd: np.ndarray,
    lift: np.ndarray,
    dist: np.ndarray,
    obs: np.ndarray,
) -> None:
    """After the rollout: outcome, new state (the event point), lift, goal distance, observation.

    ``lift[b]`` is the mean updraft [m/s] along the flown part of the edge,
    ``(h_k - h_0) / t_k - v_a sin(gamma)``; the new airspeed (for the observation) is ``ctrl[b, 0]``.
    """
    for b in range(out.shape[0]):
        code, k = classify_row(out, b, prm[b])
        codes[b] = code
        ks[b] = k
        n = out[b, k, 0]
        e = out[b, k, 1]
        chi = out[b, k, 2]
        h = out[b, k, 3]
        new_states[b, 0] = n
        new_states[b, 1] = e
        new_states[b, 2] = chi
        new_states[b, 3] = h
        lift_b = (h - x0[b, 3]) / ((k + 1) * dt) - ctrl[b, 0] * math.sin(ctrl[b, 1])
        lift[b] = lift_b
        dist[b] = goal_distance(n, e, h, prm[b])
        upd[b] = observe_row(
            n,
            e,
            chi,
            h,
            t_new[b],
            ctrl[b, 0],
            lift_b,
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


@njit(cache=True, nogil=True, error_model=_EM)
def step_rows(
    skip: np.ndarray,
    x0: np.ndarray,
    t0: np.ndarray,
    ctrl: np.ndarray,
    v_prev: np.ndarray,
    fidx: np.ndarray,
    dur: float,
    n_pts: int,
    k_switch: int,
    max_substep: float,
    th_all: np.ndarray,
    nth_all: np.ndarray,
    fpar: np.ndarray,
    ac: np.ndarray,
    out: np.ndarray,
    terms: np.ndarray,
    dt: float,
    t_new: np.ndarray,
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
    codes: np.ndarray,
    ks: np.ndarray,
    new_states: np.ndarray,
    upd: np.ndarray,
    lift: np.ndarray,
    dist: np.ndarray,
    obs: np.ndarray,
) -> None:
    """One env step of rows ``b`` with ``skip[b]`` False: the rollout kernel (arguments as in
    :meth:`Propagator.run_fields <soaring_env.primitives.Propagator.run_fields>`, ``fidx`` empty =
    field 0 for all; ``dur`` .. ``max_substep`` and ``ac`` from ``Propagator.kernel_constants``),
    then :func:`post_step`, on each run of consecutive rows (one compiled call instead of two).

    A skipped row (an env that autoresets after this step, so its edge would be thrown away) gets
    zero ``terms``, ``FLYING`` at the last point, its start as the new state, zero lift and updraft;
    its ``out``, ``dist`` and ``obs`` rows are left as they were (the reset writes them).
    """
    b_all = x0.shape[0]
    per_row = fidx.size > 0
    lo = 0
    while lo < b_all:
        if skip[lo]:
            for c in range(terms.shape[1]):
                terms[lo, c] = 0.0
            codes[lo] = FLYING
            ks[lo] = n_pts - 1
            for c in range(4):
                new_states[lo, c] = x0[lo, c]
            upd[lo] = 0.0
            lift[lo] = 0.0
            lo += 1
            continue
        hi = lo + 1
        while hi < b_all and not skip[hi]:
            hi += 1
        _rollout_kernel(
            x0[lo:hi], t0[lo:hi], ctrl[lo:hi], v_prev[lo:hi], fidx[lo:hi] if per_row else fidx, dur, n_pts,
            k_switch, max_substep, th_all, nth_all, fpar, ac, out[lo:hi], terms[lo:hi],
        )  # fmt: skip
        post_step(
            out[lo:hi], x0[lo:hi], ctrl[lo:hi], dt, t_new[lo:hi], prm[lo:hi], th[lo:hi], nth[lo:hi], scales, k_obs,
            low, high, goal_on, th_base, noise[lo:hi], codes[lo:hi], ks[lo:hi], new_states[lo:hi], upd[lo:hi],
            lift[lo:hi], dist[lo:hi], obs[lo:hi],
        )  # fmt: skip
        lo = hi


__all__ = ["CRASH", "FLYING", "GOAL", "OUT_OF_BOUNDS", "classify_batch", "post_step", "step_rows"]
