"""Compiled per-step bookkeeping of the envs: outcome, new state, sensed lift, observation.

The edge itself comes from the model's :class:`~soaring_env.primitives.Propagator` (the packed fast
path of ``rollout``) and the outcome from :func:`soaring_env.model.classify_row`, so ``env.step``
runs exactly the code of :meth:`SoaringModel.rollout_primitive` / ``classify``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from soaring_env.env.observation import goal_distance, observe_row
from soaring_env.model import CRASH, FLYING, GOAL, OUT_OF_BOUNDS, classify_batch, classify_row


@njit(cache=True, nogil=True)
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


__all__ = ["CRASH", "FLYING", "GOAL", "OUT_OF_BOUNDS", "classify_batch", "post_step"]
