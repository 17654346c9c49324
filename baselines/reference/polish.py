"""Local search around a plan ("polish"): the last step of the reference.

The beam search (:mod:`baselines.reference.beam`) merges paths per dominance cell and keeps a
bounded beam, so its best plan need not be locally optimal: two paths that fall into one cell are
merged on their cost so far, although the one dropped may have led on to a cheaper end. Polishing
tries every plan within a small edit distance of the best one and keeps the cheapest, until none is
cheaper:

* a *move* replaces ``w`` consecutive controls of the plan (``w`` = 0 ... ``depth``: 0 inserts)
  by ``k`` = 0 ... ``depth`` controls of the action set (0 deletes), then flies the rest of the
  plan unchanged from wherever that leaves the aircraft. The edited plan ends at its first goal
  edge (so a move may also shorten it); it is dropped if an edge before that is invalid (ground,
  domain), breaks the search's rules (``min_height``) or it needs more than ``max_edges`` edges;
* each round flies every move at every position (batched through
  :meth:`~baselines.sst.soaring.SoaringProblem.propagate`, the call ``env.step`` makes, so plans
  replay bit for bit) and applies the best one (the lowest objective ``J + time_weight x t``; ties
  to the first position, then the first move in the order above); rounds repeat while the objective
  falls by more than ``MIN_GAIN``, at most ``max_rounds``.

Each round never makes the plan worse, so the polished reference is never worse than the beam's.
A move's children are pruned with the search's admissible bound (``J + time_weight x t - g
(h_cap - h)`` cannot end below the plan's objective). With ``depth`` = 2 and the 174 primitives a
round flies up to ~3 x 174^2 edited plans per position; the continuous grid (~400 controls) is
polished with ``depth`` = 1 (:func:`~baselines.reference.yardstick.sampler_config`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from baselines.reference.beam import (
    _ROWS_PER_CALL,
    MAX_POLISH_DEPTH,
    ReferenceConfig,
    SearchResult,
    _Context,
    _seed_rows,
    control_set,
    edge_rules,
    path_plan,
)
from baselines.sst.core import EDGE_GOAL, EDGE_VALID
from baselines.sst.soaring import S_CHI, S_E, S_H, S_N, S_T, S_V, SAMPLERS, SoaringProblem
from soaring_env._validation import ConfigError, check_choice, check_int, check_positive
from soaring_env.model import SoaringModel
from soaring_env.physics.atmosphere import G

#: Smallest fall of the objective [J/kg] for which another round is run.
MIN_GAIN = 1e-6
#: Most controls a move removes or inserts at one position.
MAX_DEPTH = MAX_POLISH_DEPTH
#: Default bound on the rounds (each applies one move).
MAX_ROUNDS = 200


def polish(
    model: SoaringModel,
    sampler: str,
    controls: np.ndarray,
    config: ReferenceConfig | None = None,
    *,
    depth: int | None = None,
    max_rounds: int = MAX_ROUNDS,
    progress: Callable[[int, float], None] | None = None,
    start: np.ndarray | None = None,
    t0: float = 0.0,
    airspeed_prev: float | None = None,
    time_limit: float | None = None,
    max_rollouts: int | None = None,
) -> SearchResult:
    """Polish a plan that reaches the goal (see the module docstring).

    :param model: the flight model.
    :param sampler: ``"primitive"`` or ``"continuous"`` -- the action set of the moves.
    :param controls: the plan's controls (n, c) as :meth:`~baselines.sst.plan.Plan.controls` gives
        them; its controls outside the control set join it (as in :func:`~baselines.reference.search`).
    :param config: the search settings (control set, ``max_edges``, ``time_weight``, ``min_height``);
        ``config.polish`` is the move depth unless ``depth`` is given.
    :param depth: the most controls a move removes or inserts, 1 or 2 (None: ``config.polish``).
    :param max_rounds: most moves applied.
    :param progress: called as ``progress(round, objective)`` after each round.
    :param start: start state ``[Pn, Pe, chi, h]`` [m, m, rad, m] of the plan (None: the scenario's).
    :param t0: time at the start [s].
    :param airspeed_prev: airspeed of the edge flown before the start [m/s] (None: none, as after
        ``env.reset``).
    :param time_limit: wall-clock budget [s] (None: none), checked before each batch of moves.
    :param max_rollouts: budget in edges flown (None: none): no batch of moves is flown that could
        take the polish past it (counted at its most: every edited plan flown to its end), so the
        result does not depend on the machine.
    :returns: the polished plan (never worse than ``controls``; a round cut short by a budget
        applies the best move it found); ``rollouts`` counts edges flown, ``stopped`` says that
        ``max_rounds`` or a budget ended it while moves may still help.
    """
    if not isinstance(model, SoaringModel):
        raise ConfigError(f"model={model!r} must be a soaring_env.model.SoaringModel")
    check_choice("sampler", sampler, SAMPLERS)
    cfg = config if config is not None else ReferenceConfig()
    if not isinstance(cfg, ReferenceConfig):
        raise ConfigError(f"config={cfg!r} must be a ReferenceConfig")
    k_max = check_int("depth", cfg.polish if depth is None else depth, 1, MAX_DEPTH)
    check_int("max_rounds", max_rounds, 0)
    t_lim = None if time_limit is None else check_positive("time_limit", time_limit)
    n_lim = None if max_rollouts is None else check_int("max_rollouts", max_rollouts, 1)
    t_start = time.perf_counter()
    problem = SoaringProblem(model, sampler, start=start, t0=t0, airspeed_prev=airspeed_prev)
    ctrls = control_set(model, sampler, cfg)
    plan_rows = _seed_rows(model, sampler, controls, ctrls.shape[1], "controls")
    extra = plan_rows[~np.any(np.all(plan_rows[:, None, :] == ctrls[None, :, :], axis=2), axis=1)]
    if len(extra):
        ctrls = np.concatenate([ctrls, np.unique(extra, axis=0)])
    ctx = _Context.make(model, problem, sampler, ctrls, cfg)
    seq = np.array([int(np.flatnonzero(np.all(ctrls == r, axis=1))[0]) for r in plan_rows], dtype=np.int64)
    path = _fly_path(ctx, seq)
    if path is None:
        raise ConfigError("controls: the plan does not reach the goal at its last edge (within the search's rules)")
    rollouts = len(seq)
    rounds = 0
    stopped = False

    def over(n_more: int) -> bool:
        """Whether the budget forbids flying up to ``n_more`` more edges."""
        return (t_lim is not None and time.perf_counter() - t_start >= t_lim) or (
            n_lim is not None and rollouts + n_more > n_lim
        )

    while True:
        states, j, t = path
        obj = float(j[-1] + cfg.time_weight * t[-1])
        if rounds == max_rounds:
            stopped = True
            break
        found, n_roll, cut = _best_move(ctx, seq, states, j, t, obj, k_max, over)
        rollouts += n_roll
        stopped = cut
        if found is None or found[0] > obj - MIN_GAIN:
            break
        seq = found[1]
        path = _fly_path(ctx, seq)
        if path is None:
            raise RuntimeError("internal error: a polished plan does not re-fly to the goal")
        rollouts += len(seq)
        rounds += 1
        if progress is not None:
            progress(rounds, found[0])
        if cut:
            break
    states, j, t = path
    cost = float(j[-1])
    return SearchResult(
        plan=path_plan(problem, states, ctrls[seq], cost),
        cost=cost,
        rollouts=rollouts,
        seconds=time.perf_counter() - t_start,
        depth=len(seq),
        n_controls=len(ctrls),
        stopped=stopped,
    )


def _fly_path(ctx: _Context, seq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Core states (n + 1, 6), cost-to-come and flight time (n + 1) of the control indices ``seq``
    from the root, or None unless the last edge alone reaches the goal within the rules."""
    n = len(seq)
    if n == 0 or n > ctx.cfg.max_edges:
        return None
    states = np.empty((n + 1, 6))
    j = np.zeros(n + 1)
    t = np.zeros(n + 1)
    states[0] = ctx.root
    for i in range(n):
        e = ctx.problem.propagate(states[i : i + 1], ctx.ctrls[seq[i : i + 1]])
        states[i + 1], j[i + 1], t[i + 1] = e.states[0], j[i] + e.cost[0], t[i] + e.duration[0]
        last = i == n - 1
        if last and e.outcome[0] != EDGE_GOAL:
            return None
        ok = edge_rules(ctx, states[i, S_H : S_H + 1], e.states[:, S_H], j[i + 1 : i + 2])
        if not last and not (e.outcome[0] == EDGE_VALID and ok[0]):
            return None
    return states, j, t


def _moves(k_max: int) -> list[tuple[int, int]]:
    """(removed, inserted) pairs in the order moves are tried: w = 0 ... k_max, k = 0 ... k_max, not both 0."""
    return [(w, k) for w in range(k_max + 1) for k in range(k_max + 1) if w or k]


def _windows(m: int, k: int) -> np.ndarray:
    """Every k-tuple of control indices 0 ... m - 1, in lexicographic order, as (m^k, k) rows."""
    if k == 0:
        return np.zeros((1, 0), dtype=np.int64)
    return np.stack(np.meshgrid(*([np.arange(m, dtype=np.int64)] * k), indexing="ij"), axis=-1).reshape(-1, k)


def _best_move(
    ctx: _Context,
    seq: np.ndarray,
    states: np.ndarray,
    j: np.ndarray,
    t: np.ndarray,
    obj: float,
    k_max: int,
    over: Callable[[int], bool],
) -> tuple[tuple[float, np.ndarray] | None, int, bool]:
    """The best move of one round: ((objective, new control indices) or None, edges flown, whether
    the budget cut the round short). ``over(n)`` says whether flying ``n`` more edges would break
    the budget; it is asked before each batch of moves."""
    m = len(ctx.ctrls)
    n = len(seq)
    best: tuple[float, np.ndarray] | None = None
    bound = obj
    rollouts = 0
    reach = _Reach.of_plan(ctx, seq, states)
    for i in range(n + 1):
        for w, k in _moves(k_max):
            if i + w > n or n - w + k > ctx.cfg.max_edges or n - w + k == 0:
                continue
            win = _windows(m, k)
            tail = seq[i + w :]
            if over(rollouts + len(win) * (k + len(tail))):
                return best, rollouts, True
            got, n_roll = _fly_moves(ctx, states[i], j[i], t[i], i, win, tail, bound, reach.from_node(i + w))
            rollouts += n_roll
            if got is not None and got[0] < bound:
                row, steps = got[1], got[2]
                new = np.concatenate([seq[:i], win[row], tail])[: i + steps]
                best = (got[0], new)
                bound = got[0]
    return best, rollouts, False


def _fly_moves(
    ctx: _Context,
    x0: np.ndarray,
    j0: float,
    t0: float,
    i: int,
    win: np.ndarray,
    tail: np.ndarray,
    bound: float,
    may_reach: Callable[[np.ndarray], np.ndarray] | None,
) -> tuple[tuple[float, int, int] | None, int]:
    """Fly every window of ``win`` (B, k) from state ``x0`` (edge ``i`` of the plan), then ``tail``:
    ((objective, window row, edges after the prefix) of the cheapest that reaches the goal below
    ``bound``, or None; edges flown). ``may_reach(states)`` (None: no tail) tells which window ends
    the tail can take to the goal at all; only those fly it."""
    cfg, problem, ctrls = ctx.cfg, ctx.problem, ctx.ctrls
    b, k = win.shape
    tw = cfg.time_weight
    alive = np.arange(b)
    x = np.repeat(x0[None, :], b, axis=0)
    j = np.full(b, j0)
    t = np.full(b, t0)
    best: tuple[float, int, int] | None = None
    rollouts = 0
    for q in range(k + len(tail)):
        if q == k and may_reach is not None:
            alive = alive[may_reach(x[alive])]
        if i + q + 1 > cfg.max_edges or len(alive) == 0:
            break
        xa = x[alive]
        # the first window edge starts at x0 for every row: fly each distinct control once
        rows, inv = (np.unique(win[alive, 0], return_inverse=True)) if q == 0 < k else (None, None)
        if rows is not None:
            end, cost, dur, out = _propagate(problem, xa[: len(rows)], ctrls[rows])
            end, cost, dur, out = end[inv], cost[inv], dur[inv], out[inv]
            rollouts += len(rows)
        else:
            u = ctrls[win[alive, q]] if q < k else np.repeat(ctrls[tail[q - k]][None, :], len(alive), axis=0)
            end, cost, dur, out = _propagate(problem, xa, u)
            rollouts += len(alive)
        ja = j[alive] + cost
        ta = t[alive] + dur
        oa = ja + tw * ta if tw else ja
        goal = np.flatnonzero(out == EDGE_GOAL)
        if len(goal):
            g = goal[int(np.argmin(oa[goal]))]  # first of the cheapest
            if oa[g] < bound:
                bound = float(oa[g])
                best = (bound, int(alive[g]), q + 1)
        go = (
            (out == EDGE_VALID)
            & edge_rules(ctx, xa[:, S_H], end[:, S_H], ja)
            & (oa - G * (ctx.h_cap - end[:, S_H]) < bound)  # admissible: see the beam module
        )
        x[alive], j[alive], t[alive] = end, ja, ta
        alive = alive[go]
    return best, rollouts


def _propagate(
    problem: SoaringProblem, x: np.ndarray, u: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """End states, costs, durations and outcomes of the edges ``u`` from ``x``, in bounded batches."""
    n = len(x)
    end, cost, dur, out = np.empty((n, 6)), np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    for s in range(0, n, _ROWS_PER_CALL):
        sl = slice(s, min(s + _ROWS_PER_CALL, n))
        e = problem.propagate(x[sl], u[sl])
        end[sl], cost[sl], dur[sl], out[sl] = e.states, e.cost, e.duration, e.outcome
    return end, cost, dur, out


@dataclass(frozen=True)
class _Reach:
    """Where the rest of a plan can take the aircraft: a necessary test for reaching the goal.

    The model's horizontal motion (dPn/dt = v_a cos(chi) cos(gamma) + w_n, and likewise east, with
    a constant wind and the course rate, airspeed and path angle set by the control) does not depend
    on position, height or time, and turns with the start course. So the tail of the plan from node
    a, flown from a state x instead, runs through its points turned by chi - chi_a about x, plus the
    same wind drift: edge e of the tail starts at ``P_x + R(chi - chi_a) rel_e + drift_e`` and its
    points stay within ``radius_e`` of that start. If no edge comes within the goal radius (+1 m
    for rounding) of the goal centre, the tail cannot reach the goal from x and is not flown. The
    test only drops candidates that cannot reach the goal, so the polished plan is the same without
    it, only slower (a test checks that).

    :param starts: per plan edge, its start's horizontal position (north, east) [m], (n, 2).
    :param times: per plan edge, its start time [s], (n,).
    :param course: per plan edge, the course at its start [rad], (n,).
    :param radius: per plan edge, how far its output points (flown in full) get from its start [m].
    :param wind: the ambient wind (north, east) [m/s].
    :param goal: the goal region's centre (north, east) and radius [m].
    """

    starts: np.ndarray
    times: np.ndarray
    course: np.ndarray
    radius: np.ndarray
    wind: np.ndarray
    goal: tuple[float, float, float]

    @classmethod
    def of_plan(cls, ctx: _Context, seq: np.ndarray, states: np.ndarray) -> _Reach:
        model = ctx.problem.model
        n = len(seq)
        radius = np.empty(n)
        for e in range(n):
            s, u = states[e], ctx.ctrls[seq[e]]
            if ctx.problem.kind == "primitive":
                r = model.rollout_primitive(s[:4], int(u[0]), t0=s[S_T], airspeed_prev=s[S_V])
            else:
                r = model.rollout_control(s[:4], model.action_to_control(u), t0=s[S_T], airspeed_prev=s[S_V])
            radius[e] = float(np.max(np.hypot(r.states[0, :, 0] - s[S_N], r.states[0, :, 1] - s[S_E])))
        return cls(
            starts=states[:n, [S_N, S_E]].copy(),
            times=states[:n, S_T].copy(),
            course=states[:n, S_CHI].copy(),
            radius=radius,
            wind=model.scenario.field.wind,
            goal=ctx.goal,
        )

    def from_node(self, a: int) -> Callable[[np.ndarray], np.ndarray] | None:
        """The test for tails from plan node ``a`` (None if the tail is empty)."""
        if a >= len(self.starts):
            return None
        drift = (self.times[a:] - self.times[a])[:, None] * self.wind[None, :]  # (E, 2)
        rel = self.starts[a:] - self.starts[a] - drift
        reach = self.radius[a:] + self.goal[2] + 1.0
        gn, ge = self.goal[0], self.goal[1]

        def test(x: np.ndarray) -> np.ndarray:
            d = x[:, S_CHI] - self.course[a]
            c, s = np.cos(d)[:, None], np.sin(d)[:, None]
            sn = x[:, S_N : S_N + 1] + c * rel[None, :, 0] - s * rel[None, :, 1] + drift[None, :, 0] - gn
            se = x[:, S_E : S_E + 1] + s * rel[None, :, 0] + c * rel[None, :, 1] + drift[None, :, 1] - ge
            return np.any(np.hypot(sn, se) <= reach[None, :], axis=1)

        return test


__all__ = ["MAX_DEPTH", "MAX_ROUNDS", "MIN_GAIN", "polish"]
