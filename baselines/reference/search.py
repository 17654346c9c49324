"""The reference search: a deterministic beam search over control sequences through the model.

It answers "what is possible in this scenario with this action set", the yardstick every planner
and agent is measured by (see :mod:`baselines.reference.yardstick` for bounds and regret). It
flies edges with exactly the calls ``env.step`` makes (the SST soaring adapter's
:meth:`~baselines.sst.soaring.SoaringProblem.propagate`), so its plans replay bit for bit.

The search, depth by depth (one depth = one env step of Ts):

1. expand every node of the beam with every control of the control set (one batched rollout);
2. an edge that reaches the goal is a complete plan: keep the cheapest;
3. valid edges are children. Children that fall into the same *cell* -- (north, east) on a grid of
   ``cell_size``, course in ``course_cells`` sectors, height in ``height_cell`` layers, and the
   index of the last airspeed (it sets the kinetic charge of the next edge) -- are merged: only the
   one with the lowest cost-to-come survives, and only if it beats every earlier node of that cell
   (of any depth). This dominance is what makes the search approximate; cells shrink to exact
   enumeration as the sizes go to zero;
4. children that cannot beat the best plan found are pruned (below); of the rest, the
   ``beam_width`` best by the ranking below form the next beam.

Costs. Raw edge costs c = fuel + kinetic - g (h_end - h_start) are negative in lift, so pruning or
ordering on the cost-to-come J alone would be wrong: a costly path may still climb. Reweighting
every edge by the potential g h gives c' = c + g (h_end - h_start) = fuel + kinetic >= 0 (thrust is
clipped at zero and slowing down earns nothing), and J = C' - g (h - h_0) with C' the summed c'.
Because the height terms telescope, every plan from a node at height h costs at least
J - g (h_cap - h) = C' - g (h_cap - h_0) in total, where h_cap bounds the height at the end of the
goal edge (:func:`~baselines.reference.yardstick.height_cap`). That bound is admissible with
negative edges, so a child with C' - g (h_cap - h_0) >= the best plan's cost is pruned without
losing anything (step 4), and the search stops when the whole beam is pruned.

Ranking. Ordering on C' alone is exactly A* with that admissible bound, but C' is zero for every
zero-thrust glide and every climb in lift, so it cannot tell them apart. The beam is ranked by
``J + max(eps d, g (h - h_goal_top))`` instead: the cost-to-come plus the cheapest way to the goal
if no further lift is found -- straight flight over the horizontal distance d to the goal region at
``eps``, the action set's cheapest still-air cost per metre (g / (L/D) of the best zero-thrust
glide for the continuous set; level powered flight for the primitives, whose fixed glides are
steep), or the height that must be given up to enter it. Written with the reweighted cost this is
``C' + max(0, eps d - g (h - h_goal_top)) + const``: fuel spent plus the energy still missing to
get in. It is a heuristic, not a bound (lift ahead makes it pessimistic), which is why it only
orders the beam and never prunes. Ties (common: zero-thrust glides and climbs in lift all have
C' = 0) go to the lower cost-to-come, i.e. the node that has more height.

Control sets. ``"primitive"``: the 174 primitives (those within the model's bank limit), i.e. the
actions of ``soaring/Soaring-v0``. ``"continuous"``: a grid of normalized ``Box(float32)`` actions of
``soaring/SoaringContinuous-v0`` over airspeeds x course rates x path angles, where the path angles
are the primitives' fixed ones plus, for every (airspeed, course rate) pair, the zero-thrust glide
angle (the shallowest path angle that needs no thrust anywhere between the ground and the domain
ceiling; without it a grid of fixed angles either burns fuel or wastes height).

The search is exact up to the beam width and the cells; ``beam_width`` is the one accuracy knob
(``scripts/reference.py --convergence`` shows the best cost as it is doubled).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from baselines.reference.bounds import height_cap
from baselines.sst.core import EDGE_GOAL, EDGE_INVALID, EDGE_VALID, SSTResult, SSTStats
from baselines.sst.plan import Plan, plan_from_result
from baselines.sst.soaring import S_CHI, S_E, S_H, S_N, S_T, S_V, SAMPLERS, SoaringProblem
from soaring_env._validation import ConfigError, check_choice, check_int, check_positive
from soaring_env.model import SoaringModel
from soaring_env.physics.atmosphere import G
from soaring_env.primitives import COL_AIRSPEED, COL_CHI_DOT_1, COL_CHI_DOT_2

#: Default grid of the continuous control set: airspeeds [m/s], course change per Ts [deg], and the
#: fixed path angles [deg] (the primitives'); the zero-thrust glide angle is added per pair.
CONTINUOUS_SPEEDS = (10.0, 12.5, 15.0, 17.5, 20.0)
CONTINUOUS_TURNS_DEG = (0.0, 60.0, -60.0, 180.0, -180.0, 360.0, -360.0, 540.0, -540.0, 720.0, -720.0,
                        900.0, -900.0, 1080.0, -1080.0)  # fmt: skip
CONTINUOUS_GAMMAS_DEG = (-45.0, -15.0, 0.0, 15.0, 45.0)

_ROWS_PER_CALL = 32768  # rollouts per model call: bounds the (B, N, 4) output to ~30 MB


@dataclass(frozen=True)
class ReferenceConfig:
    """Settings of the reference search.

    :param beam_width: nodes kept per depth -- the accuracy knob (more is better and slower).
    :param max_edges: most edges of a plan (the envs truncate at 40 steps).
    :param cell_size: horizontal cell of the dominance grid [m].
    :param height_cell: height layer of the dominance grid [m].
    :param course_cells: course sectors of the dominance grid.
    :param speeds: airspeeds of the continuous control set [m/s] (within the envelope).
    :param turns_deg: course changes per Ts of the continuous control set [deg].
    :param gammas_deg: fixed path angles of the continuous control set [deg] (the zero-thrust glide
        angle of each (airspeed, turn) pair is always added).
    :param primitives: restrict the primitive control set to these indices (None: all within the
        model's bank limit); for tests and ablations.
    """

    beam_width: int = 2000
    max_edges: int = 40
    cell_size: float = 40.0
    height_cell: float = 10.0
    course_cells: int = 16
    speeds: tuple[float, ...] = CONTINUOUS_SPEEDS
    turns_deg: tuple[float, ...] = CONTINUOUS_TURNS_DEG
    gammas_deg: tuple[float, ...] = CONTINUOUS_GAMMAS_DEG
    primitives: tuple[int, ...] | None = None
    region_size: float = 200.0
    region_quota: int = 8

    def __post_init__(self) -> None:
        check_positive("region_size", self.region_size)
        check_int("region_quota", self.region_quota, 0)
        check_int("beam_width", self.beam_width, 1)
        check_int("max_edges", self.max_edges, 1)
        check_positive("cell_size", self.cell_size)
        check_positive("height_cell", self.height_cell)
        check_int("course_cells", self.course_cells, 1)
        for name in ("speeds", "turns_deg", "gammas_deg"):
            vals = getattr(self, name)
            if isinstance(vals, (str, bytes)) or not isinstance(vals, Sequence) or len(vals) == 0:
                raise ConfigError(f"{name}={vals!r} must be a non-empty sequence of numbers")
            object.__setattr__(self, name, tuple(_num(f"{name}[{i}]", v) for i, v in enumerate(vals)))
        if self.primitives is not None:
            if isinstance(self.primitives, (str, bytes)) or len(self.primitives) == 0:
                raise ConfigError(f"primitives={self.primitives!r} must be None or a non-empty sequence of indices")
            object.__setattr__(
                self, "primitives", tuple(check_int(f"primitives[{i}]", p, 0) for i, p in enumerate(self.primitives))
            )

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _num(name: str, v: object) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(float(v)):
        raise ConfigError(f"{name}={v!r} must be a finite number")
    return float(v)


@dataclass(frozen=True)
class SearchResult:
    """The best plan the search found and what it took.

    :param plan: the best plan (``plan.solved`` False and no actions if none reached the goal).
    :param cost: its cost [J/kg] (inf if unsolved).
    :param rollouts: edges flown.
    :param seconds: wall-clock time of the search [s].
    :param depth: deepest depth expanded.
    :param n_controls: size of the control set.
    """

    plan: Plan
    cost: float
    rollouts: int
    seconds: float
    depth: int
    n_controls: int


def control_set(model: SoaringModel, sampler: str, config: ReferenceConfig) -> np.ndarray:
    """The controls the search tries at every node, as rows of the SST core's control vectors:
    (M, 1) primitive indices or (M, 3) float32-exact normalized actions in [-1, 1]."""
    check_choice("sampler", sampler, SAMPLERS)
    if sampler == "primitive":
        ok = model.bank_ok()
        idx = np.flatnonzero(ok) if config.primitives is None else np.array(config.primitives, dtype=np.int64)
        if np.any(idx >= model.n_primitives) or not np.all(ok[idx]):
            raise ConfigError(
                f"primitives={config.primitives!r}: allowed indices are 0..{model.n_primitives - 1} within the bank limit"
            )
        return np.unique(idx).astype(np.float64)[:, None]
    lo, hi = model.control_low, model.control_high
    ts = model.library.duration
    h_top = model.scenario.bounds.height_max
    rows = []
    for v in config.speeds:
        if not lo[0] <= v <= hi[0]:
            raise ConfigError(f"speeds contains {v!r} m/s; allowed: [{lo[0]:g}, {hi[0]:g}]")
        for turn in config.turns_deg:
            chi_dot = math.radians(turn) / ts
            if not lo[1] - 1e-12 <= chi_dot <= hi[1] + 1e-12:
                lim = math.degrees(hi[1]) * ts
                raise ConfigError(f"turns_deg contains {turn!r}; allowed: [{-lim:g}, {lim:g}] deg per Ts")
            gammas = [math.radians(g) for g in config.gammas_deg]
            gammas.append(glide_angle(model, v, chi_dot, h_top))
            for gam in gammas:
                if not lo[2] <= gam <= hi[2]:
                    raise ConfigError(f"gammas_deg contains {math.degrees(gam)!r}; allowed: [-45, 45] deg")
                rows.append(_action_at_most(model, v, chi_dot, gam))
    return np.unique(np.array(rows, dtype=np.float64), axis=0)


def glide_angle(model: SoaringModel, airspeed: float, chi_dot: float, height_max: float) -> float:
    """The shallowest path angle [rad] at which steady flight at ``airspeed`` [m/s] and course rate
    ``chi_dot`` [rad/s] needs no thrust at any height in [0, ``height_max``] m.

    Thrust is ``a rho + b / rho + c(gamma)``, convex in the density rho, so it is zero on the whole
    height range when it is zero at both ends; bisection on gamma.
    """
    ac = model.aircraft
    bank = math.atan(airspeed * chi_dot / G)
    heights = np.array([0.0, min(height_max, 10999.0)])

    def needs_thrust(gam: float) -> bool:
        return bool(np.any(ac.thrust(airspeed, gam, bank, heights) > 0.0))

    lo, hi = -math.pi / 4, 0.0
    if needs_thrust(lo):
        return lo  # no glide within the envelope; the steepest angle is the closest
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if needs_thrust(mid) else (mid, hi)
    return lo


def _action_at_most(model: SoaringModel, v: float, chi_dot: float, gamma: float) -> np.ndarray:
    """The float32 action nearest to control (v, chi_dot, gamma) whose path angle does not exceed
    ``gamma`` (so a zero-thrust glide stays at zero thrust after rounding)."""
    a = model.control_to_action(np.array([v, chi_dot, gamma])).astype(np.float32)
    a = np.clip(a, -1.0, 1.0)
    while float(model.action_to_control(a.astype(np.float64))[2]) > gamma and a[2] > -1.0:
        a[2] = np.nextafter(a[2], np.float32(-1.0))
    return a.astype(np.float64)


def still_air_cost_per_metre(model: SoaringModel, controls: np.ndarray) -> float:
    """The cheapest cost per metre of straight flight [J/(kg m)] with ``controls`` in still air
    without thermals, from the scenario's start height: g / (L/D) of the best zero-thrust glide in
    the continuous set, the cheapest of level powered flight and the fixed glides for the primitives.
    """
    sc = model.scenario
    still = dataclasses.replace(
        model, scenario=sc.replace(field=dataclasses.replace(sc.field, thermals=(), wind_north=0.0, wind_east=0.0))
    )
    problem = SoaringProblem(still, "primitive" if controls.shape[1] == 1 else "continuous")
    x = np.repeat(problem.root_state()[None, :], len(controls), axis=0)
    e = problem.propagate(x, controls)
    dist = np.hypot(e.states[:, S_N] - x[:, S_N], e.states[:, S_E] - x[:, S_E])
    if controls.shape[1] == 1:
        rows = model.library.table[controls[:, 0].astype(np.int64)]
        turn = np.abs(rows[:, COL_CHI_DOT_1]) + np.abs(rows[:, COL_CHI_DOT_2])
    else:
        turn = np.abs(model.action_to_control(controls)[:, 1])
    straight = (e.outcome != EDGE_INVALID) & (turn == 0.0)
    ratio = np.where(straight & (e.cost > 0.0), e.cost / np.maximum(dist, 1e-9), np.inf)
    return float(ratio.min()) if np.isfinite(ratio.min()) else 0.0


def search(
    model: SoaringModel,
    sampler: str = "primitive",
    config: ReferenceConfig | None = None,
    *,
    seed_controls: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SearchResult:
    """Run the reference search from the scenario's start (see the module docstring).

    :param model: the flight model (scenario, aircraft, primitives).
    :param sampler: ``"primitive"`` or ``"continuous"`` -- the action set.
    :param config: search settings.
    :param seed_controls: a control sequence (rows as in :func:`control_set`) whose nodes are kept in
        the beam at every depth, e.g. the best plan in the field without thermals: the search then
        never does worse than flying that plan.
    :param progress: called as ``progress(depth, max_edges)`` after every depth.
    :returns: the best plan found (unsolved if none).
    """
    if not isinstance(model, SoaringModel):
        raise ConfigError(f"model={model!r} must be a soaring_env.model.SoaringModel")
    cfg = config if config is not None else ReferenceConfig()
    if not isinstance(cfg, ReferenceConfig):
        raise ConfigError(f"config={cfg!r} must be a ReferenceConfig")
    check_choice("sampler", sampler, SAMPLERS)
    t_start = time.perf_counter()
    problem = SoaringProblem(model, sampler)
    ctrls = control_set(model, sampler, cfg)
    m = len(ctrls)
    if seed_controls is not None:
        seed_controls = np.asarray(seed_controls, dtype=np.float64).reshape(-1, ctrls.shape[1])
    sc = model.scenario
    g = sc.goal
    root = problem.root_state()
    h0 = root[S_H]
    h_cap = height_cap(model)
    g_top = g.height + g.radius
    per_metre = still_air_cost_per_metre(model, ctrls)
    lift = thermal_values(model, ctrls)
    speed_keys = np.unique(
        np.round(model.action_to_control(ctrls)[:, 0] if sampler == "continuous" else model.library.table[:, COL_AIRSPEED], 9)
    )

    # per-depth node arrays; node i of depth d has parent parents[d][i] in depth d - 1
    states = [root[None, :]]
    costs = [np.zeros(1)]
    parents: list[np.ndarray] = [np.full(1, -1, dtype=np.int64)]
    controls_of: list[np.ndarray] = [np.full(1, -1, dtype=np.int64)]
    cell_keys = np.zeros(0, dtype=np.int64)  # sorted keys of every kept node so far
    cell_best = np.zeros(0)
    best_cost = math.inf
    best: tuple[int, int, int, np.ndarray] | None = None  # (depth of parent, parent index, control, end state)
    seed_idx = 0  # index of the seeded path's node in the current beam (-1: gone)
    rollouts = 0
    depth = 0
    for depth in range(1, cfg.max_edges + 1):
        x = states[-1]
        jc = costs[-1]
        n = len(x)
        # children: node-major, control-minor
        par = np.repeat(np.arange(n, dtype=np.int64), m)
        ctl = np.tile(np.arange(m, dtype=np.int64), n)
        end = np.empty((n * m, 6))
        cost = np.empty(n * m)
        out = np.empty(n * m, dtype=np.int64)
        for s in range(0, n * m, _ROWS_PER_CALL):
            sl = slice(s, min(s + _ROWS_PER_CALL, n * m))
            e = problem.propagate(x[par[sl]], ctrls[ctl[sl]])
            end[sl], cost[sl], out[sl] = e.states, e.cost, e.outcome
        rollouts += n * m
        j = jc[par] + cost
        # 2. goal edges: the cheapest complete plan (first in node-major order on ties)
        goal = np.flatnonzero(out == EDGE_GOAL)
        if len(goal):
            i = goal[int(np.argmin(j[goal]))]
            if j[i] < best_cost:
                best_cost = float(j[i])
                best = (depth - 1, int(par[i]), int(ctl[i]), end[i].copy())
        # the seeded path's child this depth (kept whatever its rank)
        seed_child = -1
        if seed_controls is not None and seed_idx >= 0 and depth <= len(seed_controls):
            hit = np.flatnonzero(np.all(ctrls == seed_controls[depth - 1], axis=1))
            if len(hit):
                c = seed_idx * m + int(hit[0])
                seed_child = c if out[c] == EDGE_VALID else -1
        # 3. valid children; admissible pruning (module docstring)
        keep = np.flatnonzero((out == EDGE_VALID) & (j - G * (h_cap - end[:, S_H]) < best_cost))
        if seed_child >= 0 and not np.any(keep == seed_child):
            keep = np.sort(np.append(keep, seed_child))
        if depth == cfg.max_edges or len(keep) == 0:
            break
        ce = end[keep]
        jk = j[keep]
        d_goal = np.maximum(np.hypot(ce[:, S_N] - g.north, ce[:, S_E] - g.east) - g.radius, 0.0)
        rank = jk + _cost_to_go_estimate(ce, d_goal, per_metre, g_top, lift, (g.north, g.east))
        key = _cell_keys(ce, cfg, speed_keys)
        # merge children of one cell: the lowest J (then lowest rank, then first) survives
        order = np.lexsort((np.arange(len(keep)), rank, jk, key))
        first = np.ones(len(order), dtype=bool)
        first[1:] = key[order[1:]] != key[order[:-1]]
        uniq = order[first]
        # dominance by earlier depths: an older node of the cell at no higher cost wins
        pos = np.searchsorted(cell_keys, key[uniq])
        seen = pos < len(cell_keys)
        seen[seen] = cell_keys[pos[seen]] == key[uniq][seen]
        older = np.full(len(uniq), np.inf)
        older[seen] = cell_best[pos[seen]]
        uniq = uniq[jk[uniq] < older]
        # 4. the beam: best rank first, ties by index (deterministic)
        if len(uniq) > cfg.beam_width:
            uniq = _select(uniq, rank, jk, ce, cfg)
        if seed_child >= 0:
            sp = int(np.flatnonzero(keep == seed_child)[0])
            if not np.any(uniq == sp):
                uniq = np.sort(np.append(uniq, sp))
            seed_idx = int(np.flatnonzero(uniq == sp)[0])
        else:
            seed_idx = -1
        # record the beam's cells
        all_keys = np.concatenate([cell_keys, key[uniq]])
        all_best = np.concatenate([cell_best, jk[uniq]])
        o = np.lexsort((all_best, all_keys))
        all_keys, all_best = all_keys[o], all_best[o]
        f = np.ones(len(o), dtype=bool)
        f[1:] = all_keys[1:] != all_keys[:-1]
        cell_keys, cell_best = all_keys[f], all_best[f]
        sel_children = keep[uniq]
        states.append(end[sel_children])
        costs.append(j[sel_children])
        parents.append(par[sel_children])
        controls_of.append(ctl[sel_children])
        if progress is not None:
            progress(depth, cfg.max_edges)
    if progress is not None:
        progress(cfg.max_edges, cfg.max_edges)
    plan = _plan(problem, ctrls, states, parents, controls_of, best, best_cost)
    return SearchResult(
        plan=plan,
        cost=best_cost,
        rollouts=rollouts,
        seconds=time.perf_counter() - t_start,
        depth=depth,
        n_controls=m,
    )


def thermal_values(model: SoaringModel, controls: np.ndarray) -> np.ndarray:
    """Per thermal that the action set can climb in: (north [m], east [m], value [J/(kg m)]) rows,
    the value being what one metre of climb there is worth, ``-cost / dh`` of the cheapest (most
    negative) climbing edge from near the centre (g for a zero-thrust climb; less where the climb
    needs thrust). Starts: 0 and 20 m from the centre at t = 0, four courses, at the start
    height (clipped to 50 m .. zi - 100 m)."""
    sc = model.scenario
    rows = []
    problem = SoaringProblem(model, "primitive" if controls.shape[1] == 1 else "continuous")
    h = float(np.clip(sc.start[3], 50.0, max(50.0, sc.field.zi - 100.0)))
    for t in sc.field.thermals:
        starts = []
        for off in (0.0, 20.0):
            for chi in (0.0, 0.5 * math.pi, math.pi - 1e-9, -0.5 * math.pi):
                n, e = t.north + off * math.cos(chi + 0.5 * math.pi), t.east + off * math.sin(chi + 0.5 * math.pi)
                if bool(sc.bounds.contains(n, e, h)):
                    starts.append([n, e, chi, h, 0.0, math.nan])
        if not starts:
            continue
        x = np.repeat(np.array(starts), len(controls), axis=0)
        u = np.tile(controls, (len(starts), 1))
        ed = problem.propagate(x, u)
        dh = ed.states[:, S_H] - x[:, S_H]
        ok = (ed.outcome == EDGE_VALID) & (dh > 1.0) & (ed.cost < 0.0)
        if np.any(ok):
            i = np.flatnonzero(ok)[int(np.argmin(ed.cost[ok]))]
            rows.append((t.north, t.east, float(-ed.cost[i] / dh[i])))
    return np.array(rows, dtype=np.float64).reshape(-1, 3)


def _cost_to_go_estimate(s, d_goal, per_metre, g_top, lift, goal_ne) -> np.ndarray:
    """The ranking heuristic of the module docstring, per state row of ``s``: the cheaper of flying
    straight in (``max(eps d, g (h - h_top))``) and of a detour through a thermal j that climbs to
    the goal top there (``eps (d_j + d_j,goal) - value_j max(0, h_top - h)``)."""
    h = s[:, S_H]
    est = np.maximum(per_metre * d_goal, G * (h - g_top))
    for tn, te, val in lift:
        d_j = np.hypot(s[:, S_N] - tn, s[:, S_E] - te)
        d_jg = max(math.hypot(goal_ne[0] - tn, goal_ne[1] - te), 0.0)
        est = np.minimum(est, per_metre * (d_j + d_jg) - val * np.maximum(0.0, g_top - h))
    return est


def _select(cand: np.ndarray, rank: np.ndarray, jk: np.ndarray, s: np.ndarray, cfg: ReferenceConfig) -> np.ndarray:
    """The beam: ``beam_width`` of ``cand`` (sorted indices), at most ``region_quota`` per region
    (``region_size`` squares) first, then the best of the rest; each by rank, then cost, then index."""
    order = cand[np.lexsort((cand, jk[cand], rank[cand]))]
    if cfg.region_quota > 0:
        rn = np.floor(s[order, S_N] / cfg.region_size).astype(np.int64)
        re_ = np.floor(s[order, S_E] / cfg.region_size).astype(np.int64)
        region = rn * (1 << 20) + re_
        by_region = np.lexsort((np.arange(len(order)), region))  # stable: rank order within a region
        first = np.ones(len(order), dtype=bool)
        first[1:] = region[by_region[1:]] != region[by_region[:-1]]
        start = np.maximum.accumulate(np.where(first, np.arange(len(order)), 0))
        place = np.empty(len(order), dtype=np.int64)
        place[by_region] = np.arange(len(order)) - start
        quota = place < cfg.region_quota
        order = np.concatenate([order[quota], order[~quota]])
    return np.sort(order[: cfg.beam_width])


def _cell_keys(s: np.ndarray, cfg: ReferenceConfig, speed_keys: np.ndarray) -> np.ndarray:
    """One int64 per state: (north, east, course, height, last-airspeed) cell, packed."""
    ni = np.floor(s[:, S_N] / cfg.cell_size).astype(np.int64) + (1 << 15)
    ei = np.floor(s[:, S_E] / cfg.cell_size).astype(np.int64) + (1 << 15)
    ci = np.floor((s[:, S_CHI] + math.pi) / (2 * math.pi) * cfg.course_cells).astype(np.int64) % cfg.course_cells
    hi = np.floor(s[:, S_H] / cfg.height_cell).astype(np.int64)
    vi = np.searchsorted(speed_keys, np.round(s[:, S_V], 9))
    nv = len(speed_keys) + 1
    # north, east < 2^16 cells each, height < 2^13 layers: fits in 63 bits for any sane config
    return (((ni * (1 << 16) + ei) * (1 << 13) + hi) * cfg.course_cells + ci) * nv + vi


def _plan(problem, ctrls, states, parents, controls_of, best, best_cost) -> Plan:
    """Backtrack the best goal edge to the root and turn the path into a :class:`Plan`."""
    if best is None:
        res = SSTResult(False, math.inf, np.zeros((0, 6)), np.zeros((0, ctrls.shape[1])), np.zeros(0), np.zeros(0),
                        SSTStats())  # fmt: skip
        return plan_from_result(problem, res)
    d, i, c, end = best
    path_states = [end]
    path_ctrls = [c]
    while d > 0:
        path_states.append(states[d][i])
        path_ctrls.append(int(controls_of[d][i]))
        i = int(parents[d][i])
        d -= 1
    path_states.append(states[0][0])
    st = np.array(path_states[::-1])
    cu = ctrls[np.array(path_ctrls[::-1])]
    # the edge costs are re-flown from the path (the costs-to-come are differences of sums)
    edge = problem.propagate(st[:-1], cu)
    if not np.array_equal(edge.states, st[1:]):
        raise RuntimeError("internal error: the reference plan does not re-fly to its nodes")
    res = SSTResult(True, float(best_cost), st, cu, edge.cost, edge.duration, SSTStats())
    return plan_from_result(problem, res)


__all__ = ["ReferenceConfig", "SearchResult", "control_set", "glide_angle", "search", "still_air_cost_per_metre"]
