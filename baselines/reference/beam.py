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
4. children that cannot beat the best plan found are pruned (below); of the rest, ``width`` form
   the next beam (selection below).

Costs. Raw edge costs c = fuel + kinetic - g (h_end - h_start) are negative in lift, so pruning or
ordering on the cost-to-come J alone would be wrong: a costly path may still climb. Reweighting
every edge by the potential g h gives c' = c + g (h_end - h_start) = fuel + kinetic >= 0 (thrust is
clipped at zero and slowing down earns nothing), and J = C' - g (h - h_0) with C' the summed c'.
Because the height terms telescope, every plan from a node at height h costs at least
J - g (h_cap - h) = C' - g (h_cap - h_0) in total, where h_cap bounds the height at the end of the
goal edge (:func:`~baselines.reference.bounds.height_cap`). That bound is admissible with
negative edges, so a child with C' - g (h_cap - h_0) >= the best plan's cost is pruned without
losing anything (step 4), and the search stops when the whole beam is pruned.

Ranking. Ordering on C' alone is exactly A* with that admissible bound, but C' is zero for every
zero-thrust glide and every climb in lift, so it cannot tell them apart. The beam is ranked by
``J + H`` instead, with H the cheapest way to the goal of two: straight in, ``eps d`` over the
horizontal distance d to the goal region at ``eps``, the action set's cheapest still-air cost per
metre (g / (L/D) of the best zero-thrust glide for the continuous set; level powered flight for the
primitives, whose fixed glides are steep); or through a thermal j, ``eps (d_j + d_j,goal)`` minus
what climbing there to the goal top is worth (``value_j`` per metre, measured with the action set
at the thermal's centre); and never less than ``g (h - h_goal_top)``, the height that must be given
up to get in. It is a heuristic, not a bound, which is why it only orders the beam and never prunes.
With ``descent_step``, a node above the goal's top is ranked by at least ``g max(h - h_top, D) +
eps d``, D being the least height one descending edge of the control set loses
(:func:`smallest_descent`): the goal is a sphere, narrow at its top, and a control set whose
descents come in steps (the primitives: 78 m per edge) cannot shed a few metres, so without it the
beam prefers climbs that overshoot the top over those that stop just below it.

Selection. A beam ordered by one heuristic crowds into one corridor, so the selection interleaves
two orders -- by ``J + H`` and by J alone (the nodes that have gained the most energy, wherever
they are) -- and takes the first ``region_quota`` nodes of every ``region_size`` square in that
order before the rest. Ties go to the lower cost-to-come (more height), then the lower index.

Iterative widening. One beam search is not monotone in its width (a wider beam admits children
that displace a good path's nodes later). :func:`search` therefore runs beams of ``start_width``,
twice that, ... up to ``beam_width``, each seeded with the best plan of the ones before (a seeded
path's nodes stay in the beam at every depth), so the best cost never gets worse as the knob grows.

Control sets. ``"primitive"``: the 174 primitives (those within the model's bank and stall limits,
``model.allowed_primitives()``), i.e. the
actions of ``soaring/Soaring-v0``. ``"continuous"``: a grid of normalized ``Box(float32)`` actions of
``soaring/SoaringContinuous-v0`` over airspeeds x course rates x path angles, where the path angles
are the primitives' fixed ones plus, for every (airspeed, course rate) pair, the zero-thrust glide
angle (the shallowest path angle that needs no thrust anywhere between the ground and the domain
ceiling; without it a grid of fixed angles either burns fuel or wastes height).

The search is exact up to the beam and the cells (a test checks it against exhaustive enumeration
with cells of 1 m x 0.2 m x 0.5 deg); ``beam_width`` is the one accuracy knob
(``scripts/reference.py --convergence`` shows the best cost as it is doubled).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from baselines.reference.bounds import height_cap, without_thermals
from baselines.sst.core import EDGE_GOAL, EDGE_INVALID, EDGE_VALID, Edges, SSTResult, SSTStats
from baselines.sst.plan import Plan, plan_from_result
from baselines.sst.soaring import S_CHI, S_E, S_H, S_N, S_V, SAMPLERS, SST_CONFIGS, SoaringProblem
from soaring_env._validation import ConfigError, check_bool, check_choice, check_int, check_positive, check_range
from soaring_env.model import SoaringModel
from soaring_env.physics.atmosphere import G
from soaring_env.primitives import COL_AIRSPEED, COL_CHI_DOT_1, COL_CHI_DOT_2

#: The continuous grid on the physical envelope (:func:`envelope_grid`; the cross-country reference's
#: for Ts = 10 s): airspeeds [m/s] x course changes per step [deg] (clipped to the bank and stall
#: limits), with the zero-thrust glide angle (cross-country: and level flight).
XC_SPEEDS = (12.5, 15.0, 18.0, 22.0)
XC_TURNS_DEG = (-300.0, -150.0, -60.0, 0.0, 60.0, 150.0, 300.0)
#: Fixed path angles [deg] of goal reaching's control set on the physical envelope (beside the
#: zero-thrust glide angle): level and a 10-degree powered climb -- without a battery, a goal above
#: the start and out of a thermal's reach is climbed to under power.
GOAL_PHYSICAL_GAMMAS_DEG = (0.0, 10.0)
#: Default grid of the continuous control set: airspeeds [m/s], course change per Ts [deg], and the
#: fixed path angles [deg] (the primitives'); the zero-thrust glide angle is added per pair.
CONTINUOUS_SPEEDS = (10.0, 12.5, 15.0, 17.5, 20.0)
CONTINUOUS_TURNS_DEG = (0.0, 60.0, -60.0, 180.0, -180.0, 360.0, -360.0, 540.0, -540.0, 720.0, -720.0,
                        900.0, -900.0, 1080.0, -1080.0)  # fmt: skip
CONTINUOUS_GAMMAS_DEG = (-45.0, -15.0, 0.0, 15.0, 45.0)

#: Largest beam width: the children of one depth (width x controls) are held in memory at once.
MAX_BEAM_WIDTH = 100_000
#: Most planner runs seeding the reference's second search (each one's plan is kept in its beam).
MAX_PLANNER_SEEDS = 64
#: Most controls a polishing move removes or inserts (:mod:`baselines.reference.polish`).
MAX_POLISH_DEPTH = 2
_ROWS_PER_CALL = 32768  # rollouts per model call: bounds the (B, N, 4) output to ~30 MB


@dataclass(frozen=True)
class ReferenceConfig:
    """Settings of the reference search.

    :param beam_width: nodes kept per depth in the last (widest) beam -- the accuracy knob (more is
        better and slower).
    :param start_width: width of the first beam of the iterative widening (each next one doubles).
    :param max_edges: most edges of a plan (the envs truncate at 40 steps).
    :param cell_size: horizontal cell of the dominance grid [m].
    :param height_cell: height layer of the dominance grid [m].
    :param course_cells: course sectors of the dominance grid.
    :param speeds: airspeeds of the continuous control set [m/s] (within the envelope).
    :param turns_deg: course changes per Ts of the continuous control set [deg].
    :param gammas_deg: fixed path angles of the continuous control set [deg] (the zero-thrust glide
        angle of each (airspeed, turn) pair is always added).
    :param primitives: restrict the primitive control set to these indices (None: all within the
        model's bank and stall limits); for tests and ablations.
    :param region_size: side of the squares of the beam's diversity quota [m].
    :param region_quota: nodes per square taken first into the beam (0: no quota).
    :param progress_weight: adds ``progress_weight x eps x d`` (d: distance to the goal region [m],
        eps: the cheapest still-air cost per metre) to the ranking, so that of nodes the ranking
        rates alike (circling high in lift vs gliding on: both keep J + H) the nearer goes first --
        needed over long distances (the cross-country task); 0 (default): the goal-reaching
        references as published. Ranking only, never pruning: the search stays admissible.
    :param time_weight: adds ``time_weight x t`` (t: flight time [s]) to the objective the search
        minimizes [J/kg per s]: among plans that reach the goal it keeps the one with the least
        energy cost plus this charge, and prunes against it, so that of plans alike in energy the
        earlier arrival wins (a plan that circles at the top of a thermal, where lift and sink cancel,
        is then no longer as good as one that glides on at once). The reported cost stays the plan's
        energy cost. 0 (default): least energy, as the yardstick's references are published.
    :param min_height: a floor [m]: an edge may end below it only if it does not descend (end
        height >= start height), so plans keep that much height in reserve and a start below it
        climbs first -- the engine-start height of motor-glider practice. A learner that copies the
        plans, with errors in judging its glide, then still has height to use the motor when its
        glide misses the lift. Goal edges are exempt (the goal region may reach lower). 0
        (default): down to the ground, as the yardstick's references are published.
    :param planner_iterations: (:func:`~baselines.reference.compute_reference`; :func:`search`
        takes its seeds as arguments): random expansions of each deterministic soaring-SST run
        (:func:`baselines.sst.plan_soaring`) whose plan seeds a second search beside the direct
        flight's -- kept in the beam at every depth, so that search is never worse than that plan;
        the reference is the cheaper of the two searches (a beam is not monotone in its seeds: a
        seed's nodes take slots and cells). 0: one search, no planner. Both action sets: a
        continuous plan's controls, which lie outside the continuous control set, join it there.
    :param planner_seeds: planner runs, with seeds 0 ... ``planner_seeds - 1``; every distinct plan
        seeds that second search. SST's result varies much with its seed (on ``random-10019``,
        primitive, seeds 0, 1, 2 end at 2,428, 2,346 and 2,287 J/kg) and the beam keeps each plan.
    :param planner_config: the name of the planner's configuration in
        :data:`baselines.sst.soaring.SST_CONFIGS` (pinned, so that a reference file's settings say
        which planner seeded it, whatever the planner's default).
    :param polish: (:func:`~baselines.reference.compute_reference`) the depth of the local search
        that ends the reference (:mod:`baselines.reference.polish`): the most consecutive controls
        one move replaces or inserts, 0 ... ``MAX_POLISH_DEPTH`` (0: none). The beam's cell merging
        leaves plans that are not locally optimal (on ``random-10005``, primitive, depth 2 lowers
        789 to 482 J/kg).
    :param descent_step: rank a node above the goal's top as one that must still fly at least one
        whole descending edge of the control set (:func:`smallest_descent`) besides the distance to
        the goal (module docstring, "Ranking"). Ranking only, never pruning. False (default): the
        goal-reaching references as first published and the planners' beams.
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
    start_width: int = 250
    region_size: float = 200.0
    region_quota: int = 8
    planner_iterations: int = 0
    planner_seeds: int = 1
    planner_config: str = "soaring"
    progress_weight: float = 0.0
    time_weight: float = 0.0
    min_height: float = 0.0
    polish: int = 0
    descent_step: bool = False

    def __post_init__(self) -> None:
        check_bool("descent_step", self.descent_step)
        object.__setattr__(self, "progress_weight", check_range("progress_weight", self.progress_weight, 0.0, 100.0))
        object.__setattr__(self, "time_weight", check_range("time_weight", self.time_weight, 0.0, 1000.0))
        object.__setattr__(self, "min_height", check_range("min_height", self.min_height, 0.0, 5000.0))
        check_positive("region_size", self.region_size)
        check_int("region_quota", self.region_quota, 0)
        check_int("planner_iterations", self.planner_iterations, 0)
        check_int("planner_seeds", self.planner_seeds, 1)
        if self.planner_seeds > MAX_PLANNER_SEEDS:
            raise ConfigError(f"planner_seeds={self.planner_seeds!r} is too large; allowed: 1..{MAX_PLANNER_SEEDS}")
        check_choice("planner_config", self.planner_config, tuple(SST_CONFIGS))
        check_int("polish", self.polish, 0, MAX_POLISH_DEPTH)
        check_int("beam_width", self.beam_width, 1)
        if self.beam_width > MAX_BEAM_WIDTH:
            raise ConfigError(f"beam_width={self.beam_width!r} is too large; allowed: 1..{MAX_BEAM_WIDTH}")
        check_int("start_width", self.start_width, 1)
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

    def to_dict(self) -> dict[str, Any]:
        """JSON form (sequences as lists); ``ReferenceConfig(**d)`` reads it back."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}


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
    :param stopped: whether the budget (``time_limit``, ``max_rollouts``) stopped a beam before its end.
    """

    plan: Plan
    cost: float
    rollouts: int
    seconds: float
    depth: int
    n_controls: int
    stopped: bool = False


def envelope_grid(model: SoaringModel) -> dict[str, Any]:
    """The continuous control grid of a goal search (the seeded SST's seeding beams, the tasks'
    references) for ``model``, as :class:`ReferenceConfig` keywords: none (the yardstick's grid)
    where the model's envelope holds it (the paper's), else the cross-country grid with a powered
    climb (:data:`XC_SPEEDS` x :data:`XC_TURNS_DEG` x :data:`GOAL_PHYSICAL_GAMMAS_DEG`; the physical
    envelope excludes the yardstick's 10 m/s and 1080-degree controls)."""
    lo, hi = model.control_low, model.control_high
    d = ReferenceConfig()
    turn_max = math.radians(max(abs(t) for t in d.turns_deg)) / model.library.duration
    if lo[0] <= min(d.speeds) and max(d.speeds) <= hi[0] and turn_max <= hi[1] + 1e-12:
        return {}
    return {"speeds": XC_SPEEDS, "turns_deg": XC_TURNS_DEG, "gammas_deg": GOAL_PHYSICAL_GAMMAS_DEG}


def control_set(model: SoaringModel, sampler: str, config: ReferenceConfig) -> np.ndarray:
    """The controls the search tries at every node, as rows of the SST core's control vectors:
    (M, 1) primitive indices or (M, 3) float32-exact normalized actions in [-1, 1]."""
    check_choice("sampler", sampler, SAMPLERS)
    if sampler == "primitive":
        ok = model.allowed_primitives()
        idx = np.flatnonzero(ok) if config.primitives is None else np.array(config.primitives, dtype=np.int64)
        if np.any(idx >= model.n_primitives) or not np.all(ok[idx]):
            raise ConfigError(
                f"primitives={config.primitives!r}: allowed: indices 0..{model.n_primitives - 1} "
                "within the bank and stall limits"
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
    ``chi_dot`` [rad/s] needs no thrust at any height in [0, ``height_max``] m
    (:meth:`~soaring_env.physics.aircraft.Aircraft.glide_angle`)."""
    return float(model.aircraft.glide_angle(airspeed, chi_dot, min(height_max, 10999.0)))


def _action_at_most(model: SoaringModel, v: float, chi_dot: float, gamma: float) -> np.ndarray:
    """The float32 action nearest to control (v, chi_dot, gamma) whose path angle does not exceed
    ``gamma`` (so a zero-thrust glide stays at zero thrust after rounding)."""
    a = model.control_to_action(np.array([v, chi_dot, gamma])).astype(np.float32)
    a = np.clip(a, -1.0, 1.0)
    while float(model.action_to_control(a.astype(np.float64))[2]) > gamma and a[2] > -1.0:
        a[2] = np.nextafter(a[2], np.float32(-1.0))
    return a.astype(np.float64)


def _still_air_edges(model: SoaringModel, controls: np.ndarray) -> tuple[np.ndarray, Edges]:
    """Every control flown once from the scenario's start in still air without thermals: the start
    rows (M, 6) and the edges (:meth:`~baselines.sst.soaring.SoaringProblem.propagate`)."""
    calm = without_thermals(model)
    sc = calm.scenario
    still_field = dataclasses.replace(sc.field, wind_north=0.0, wind_east=0.0)
    still = dataclasses.replace(calm, scenario=sc.replace(field=still_field))
    problem = SoaringProblem(still, "primitive" if controls.shape[1] == 1 else "continuous")
    x = np.repeat(problem.root_state()[None, :], len(controls), axis=0)
    return x, problem.propagate(x, controls)


def still_air_cost_per_metre(model: SoaringModel, controls: np.ndarray) -> float:
    """The cheapest cost per metre of straight flight [J/(kg m)] with ``controls`` in still air
    without thermals, from the scenario's start height: g / (L/D) of the best zero-thrust glide in
    the continuous set, the cheapest of level powered flight and the fixed glides for the primitives.
    """
    x, e = _still_air_edges(model, controls)
    dist = np.hypot(e.states[:, S_N] - x[:, S_N], e.states[:, S_E] - x[:, S_E])
    if controls.shape[1] == 1:
        rows = model.library.table[controls[:, 0].astype(np.int64)]
        turn = np.abs(rows[:, COL_CHI_DOT_1]) + np.abs(rows[:, COL_CHI_DOT_2])
    else:
        turn = np.abs(model.action_to_control(controls)[:, 1])
    straight = (e.outcome != EDGE_INVALID) & (turn == 0.0)
    ratio = np.where(straight & (e.cost > 0.0), e.cost / np.maximum(dist, 1e-9), np.inf)
    return float(ratio.min()) if np.isfinite(ratio.min()) else 0.0


def smallest_descent(model: SoaringModel, controls: np.ndarray) -> float:
    """The least height [m] that one descending edge of ``controls`` loses in still air without
    thermals, from the scenario's start (0 if none descends): what a node above the goal's top
    must give up at least once (``ReferenceConfig.descent_step``). The primitives' shallowest
    descent is the -15 degree path at 10 m/s, 78 m per 30 s edge."""
    x, e = _still_air_edges(model, controls)
    drop = x[:, S_H] - e.states[:, S_H]
    drop = drop[(e.outcome != EDGE_INVALID) & (drop > 1e-6)]
    return float(drop.min()) if len(drop) else 0.0


def widening(start: int, widest: int) -> list[int]:
    """The widths of iterative widening: ``start`` (at most ``widest``), twice that, ... and
    ``widest`` last."""
    out = []
    w = min(start, widest)
    while w < widest:
        out.append(w)
        w *= 2
    return [*out, widest]


def search(
    model: SoaringModel,
    sampler: str = "primitive",
    config: ReferenceConfig | None = None,
    *,
    seed_controls: Sequence[np.ndarray] = (),
    progress: Callable[[int, int], None] | None = None,
    battery: float = math.inf,
    start: np.ndarray | None = None,
    t0: float = 0.0,
    airspeed_prev: float | None = None,
    time_limit: float | None = None,
    max_rollouts: int | None = None,
) -> SearchResult:
    """Run the reference search from the scenario's start (see the module docstring).

    Iterative widening: beam searches of width ``start_width``, twice that, ... up to
    ``beam_width``, each seeded with the best plan of the ones before, so the best cost can only
    improve as ``beam_width`` grows (a single beam search is not monotone in its width).

    :param model: the flight model (scenario, aircraft, primitives).
    :param sampler: ``"primitive"`` or ``"continuous"`` -- the action set.
    :param config: search settings.
    :param seed_controls: control sequences (rows as in :func:`control_set`) whose nodes are kept in
        the beam at every depth, e.g. the best plan in the field without thermals: the search then
        never does worse than flying any of them. Their controls that are not in the control set
        (e.g. a continuous SST plan's) join it for this search.
    :param progress: called as ``progress(done, total)`` in units of depth x stage.
    :param battery: motor energy budget [J/kg] (the cross-country task's): a path whose summed
        fuel + kinetic charge C' reaches it before the goal ends there (as ``"battery_empty"`` in the
        env), so only children with C' below it are kept; the goal edge itself may cross it, as in
        the env.
    :param start: start state ``[Pn, Pe, chi, h]`` [m, m, rad, m] (None: the scenario's start).
    :param t0: time at the start [s] (a search from a state mid-episode).
    :param airspeed_prev: airspeed of the edge flown before the start [m/s] (None: the first edge
        pays no speed change, as after ``env.reset``).
    :param time_limit: wall-clock budget [s] (None: none): no wider beam is started that would
        need more than the time left (a doubled width takes about twice as long), and a beam stops
        (its best plan so far is kept) at the first depth past it, or as soon as it is not
        expected to finish within it: from its third depth on, the rest of the beam is projected
        as every remaining depth expanding as many edges as the next one, at the beam's rate so
        far (depths cost about the same once the beam is full; a beam usually runs to
        ``max_edges``). A search that cannot finish thus gives its time back after a few depths.
    :param max_rollouts: budget in edges flown (None: none), applied the same way but exactly: no
        depth is expanded that would take the search past it, nor one of a beam whose projected
        edges would, so a rollout budget gives the same plan on every machine.
    :returns: the best plan found (unsolved if none).
    """
    if not isinstance(model, SoaringModel):
        raise ConfigError(f"model={model!r} must be a soaring_env.model.SoaringModel")
    cfg = config if config is not None else ReferenceConfig()
    if not isinstance(cfg, ReferenceConfig):
        raise ConfigError(f"config={cfg!r} must be a ReferenceConfig")
    check_choice("sampler", sampler, SAMPLERS)
    t_start = time.perf_counter()
    t_lim = None if time_limit is None else check_positive("time_limit", time_limit)
    n_lim = None if max_rollouts is None else check_int("max_rollouts", max_rollouts, 1)
    problem = SoaringProblem(model, sampler, start=start, t0=t0, airspeed_prev=airspeed_prev)
    ctrls = control_set(model, sampler, cfg)
    cols = ctrls.shape[1]
    seeds = [_seed_rows(model, sampler, sq, cols, f"seed_controls[{i}]") for i, sq in enumerate(seed_controls)]
    if seeds:  # the seeds' controls outside the set join it (after it: the set's order is kept)
        extra = np.unique(np.concatenate(seeds), axis=0)
        extra = extra[~np.any(np.all(extra[:, None, :] == ctrls[None, :, :], axis=2), axis=1)]
        ctrls = np.concatenate([ctrls, extra]) if len(extra) else ctrls
    widths = widening(cfg.start_width, cfg.beam_width)
    if not (isinstance(battery, (int, float)) and battery > 0.0) or math.isnan(battery):
        raise ConfigError(f"battery={battery!r} must be a number > 0 J/kg (math.inf: no battery)")
    ctx = _Context.make(model, problem, sampler, ctrls, cfg, float(battery))
    best: tuple[float, float, np.ndarray, np.ndarray] | None = None
    rollouts = depth = 0
    last_s = last_n = 0.0  # time and rollouts of the last beam
    t_beam = t_start
    stopped = False

    def stop(done: int, n_end: int) -> bool:
        """Whether the budget forbids the beam to go on: it has flown ``done`` edges, and the next
        depth (or, projected, the whole beam) would take it to ``n_end``."""
        nonlocal stopped
        now = time.perf_counter()
        left = math.inf if t_lim is None else t_lim - (now - t_start)
        stopped = (
            left <= 0.0
            or (n_lim is not None and rollouts + n_end > n_lim)
            or (done > 0 and (now - t_beam) / done * (n_end - done) > left)
        )
        return stopped

    for k, width in enumerate(widths):
        if k > 0 and (
            (t_lim is not None and time.perf_counter() - t_start + 2.0 * last_s > t_lim)
            or (n_lim is not None and rollouts + 2.0 * last_n > n_lim)
        ):
            break  # a doubled beam would not fit into the budget

        def cb(d: int, n: int, k: int = k) -> None:
            if progress is not None:
                progress(k * n + d, n * len(widths))

        t_beam = time.perf_counter()
        found, n_roll, depth = _beam(ctx, width, [*seeds, *([best[3]] if best else [])], cb, stop)
        last_s, last_n = time.perf_counter() - t_beam, float(n_roll)
        rollouts += n_roll
        if found is not None and (best is None or found[0] < best[0]):
            best = found
        if stopped:
            break
    if best is None:
        res = SSTResult(False, math.inf, np.zeros((0, 6)), np.zeros((0, ctrls.shape[1])), np.zeros(0), np.zeros(0),
                        SSTStats())  # fmt: skip
        plan = plan_from_result(problem, res)
        cost = math.inf
    else:
        _, cost, st, cu = best
        plan = path_plan(problem, st, cu, cost)
    return SearchResult(
        plan=plan,
        cost=cost,
        rollouts=rollouts,
        seconds=time.perf_counter() - t_start,
        depth=depth,
        n_controls=len(ctrls),
        stopped=stopped,
    )


def path_plan(problem: SoaringProblem, states: np.ndarray, controls: np.ndarray, cost: float) -> Plan:
    """The :class:`Plan` of a path that reaches the goal: core ``states`` (n + 1, 6) from the root
    and ``controls`` (n, c), whose edges are re-flown (and checked against ``states``) for their
    costs and durations."""
    edge = problem.propagate(states[:-1], controls)
    if not np.array_equal(edge.states, states[1:]):
        raise RuntimeError("internal error: the reference plan does not re-fly to its nodes")
    return plan_from_result(problem, SSTResult(True, cost, states, controls, edge.cost, edge.duration, SSTStats()))


def edge_rules(ctx: _Context, h_start: np.ndarray, h_end: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Which non-goal edges the search's rules let a path go on from (a bool per edge): the
    ``min_height`` floor (below it only edges that do not descend) and the battery (the motor
    energy C' = J + g (h - h_0) so far below it). ``h_start``, ``h_end``: the edge's heights [m];
    ``j``: cost-to-come at its end [J/kg]. Goal edges are exempt from both, as in the env."""
    ok = np.ones(len(h_end), dtype=bool)
    if ctx.cfg.min_height:
        ok &= (h_end >= ctx.cfg.min_height) | (h_end >= h_start)
    if ctx.battery != math.inf:
        ok &= j + G * (h_end - ctx.root[S_H]) < ctx.battery
    return ok


def _seed_rows(model: SoaringModel, sampler: str, seq: np.ndarray, width: int, name: str) -> np.ndarray:
    """Control sequence ``name`` (for messages) as (n, width) control rows; raises unless every row
    is an action of the action set: an allowed primitive index, or a normalized action in [-1, 1]^3."""
    try:
        rows = np.asarray(seq, dtype=np.float64).reshape(-1, width)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name} must be a sequence of {width}-number control rows ({exc})") from None
    if sampler == "primitive":
        idx = rows[:, 0]
        ok = np.isfinite(idx) & (idx == np.round(idx)) & (idx >= 0) & (idx < model.n_primitives)
        ok[ok] = model.allowed_primitives()[idx[ok].astype(np.int64)]
        allowed = "indices of primitives within the bank and stall limits"
    else:
        ok = np.all(np.isfinite(rows) & (np.abs(rows) <= 1.0), axis=1)
        allowed = "normalized actions in [-1, 1]^3"
    if not np.all(ok):
        bad = rows[int(np.flatnonzero(~ok)[0])].tolist()
        raise ConfigError(f"{name} holds the control {bad!r}; allowed: {allowed}")
    return rows


@dataclass(frozen=True)
class _Context:
    """What every beam of one search shares."""

    problem: SoaringProblem
    ctrls: np.ndarray
    cfg: ReferenceConfig
    root: np.ndarray
    goal: tuple[float, float, float]  # north, east, radius [m]
    g_top: float
    h_cap: float
    per_metre: float
    descent: float  # [m]: 0 unless cfg.descent_step
    lift: np.ndarray
    speed_keys: np.ndarray
    battery: float

    @classmethod
    def make(
        cls,
        model: SoaringModel,
        problem: SoaringProblem,
        sampler: str,
        ctrls: np.ndarray,
        cfg: ReferenceConfig,
        battery: float = math.inf,
    ) -> _Context:
        g = model.scenario.require_goal()
        if sampler == "continuous":
            speeds = model.action_to_control(ctrls)[:, 0]
        else:
            speeds = model.library.table[:, COL_AIRSPEED]
        speed_keys = np.unique(np.round(speeds, 9))
        _check_cell_grid(model, cfg, len(speed_keys))
        return cls(
            problem=problem,
            ctrls=ctrls,
            cfg=cfg,
            root=problem.root_state(),
            goal=(g.north, g.east, g.radius),
            g_top=g.height + g.radius,
            h_cap=height_cap(model),
            per_metre=still_air_cost_per_metre(model, ctrls),
            descent=smallest_descent(model, ctrls) if cfg.descent_step else 0.0,
            lift=thermal_values(model, ctrls),
            speed_keys=speed_keys,
            battery=battery,
        )


def _beam(
    ctx: _Context,
    width: int,
    seeds: list[np.ndarray],
    progress: Callable[[int, int], None],
    stop: Callable[[int, int], bool] | None = None,
) -> tuple[tuple[float, float, np.ndarray, np.ndarray] | None, int, int]:
    """One beam search of ``width``: ((objective, cost, path states (n + 1, 6), controls (n, c)) of
    the best plan or None, rollouts, deepest depth); the objective is the cost plus
    ``time_weight`` x its flight time. ``stop(done, n_end)`` (the search's budget) is asked before
    each depth whether the beam, having flown ``done`` edges, may go on to ``n_end``: the end of the
    next depth, and from the third depth on the end of the whole beam projected as every remaining
    depth like the next; if not, the beam ends with its best plan so far."""
    problem, ctrls, cfg = ctx.problem, ctx.ctrls, ctx.cfg
    m = len(ctrls)
    gn, ge, gr = ctx.goal
    g_top, h_cap, per_metre, lift = ctx.g_top, ctx.h_cap, ctx.per_metre, ctx.lift
    root = ctx.root
    # per-depth node arrays; node i of depth d has parent parents[d][i] in depth d - 1
    states = [root[None, :]]
    costs = [np.zeros(1)]
    times = [np.zeros(1)]  # flight time since the root [s] (used with a time weight only)
    tw = cfg.time_weight
    parents: list[np.ndarray] = [np.full(1, -1, dtype=np.int64)]
    controls_of: list[np.ndarray] = [np.full(1, -1, dtype=np.int64)]
    cell_keys = np.zeros(0, dtype=np.int64)  # sorted keys of every kept node so far
    cell_best = np.zeros(0)
    best_cost = best_obj = math.inf
    best: tuple[int, int, int, np.ndarray] | None = None  # (depth of parent, parent index, control, end state)
    seed_idx = [0] * len(seeds)  # index of each seeded path's node in the current beam (-1: gone)
    rollouts = 0
    depth = 0
    for depth in range(1, cfg.max_edges + 1):
        x = states[-1]
        jc = costs[-1]
        n = len(x)
        # (depths 1 and 2 grow the beam from the root: no projection from them)
        if stop is not None and stop(rollouts, rollouts + n * m * (cfg.max_edges - depth + 1 if depth > 2 else 1)):
            break
        # children: node-major, control-minor
        par = np.repeat(np.arange(n, dtype=np.int64), m)
        ctl = np.tile(np.arange(m, dtype=np.int64), n)
        end = np.empty((n * m, 6))
        cost = np.empty(n * m)
        dur = np.empty(n * m)
        out = np.empty(n * m, dtype=np.int64)
        for s in range(0, n * m, _ROWS_PER_CALL):
            sl = slice(s, min(s + _ROWS_PER_CALL, n * m))
            e = problem.propagate(x[par[sl]], ctrls[ctl[sl]])
            end[sl], cost[sl], dur[sl], out[sl] = e.states, e.cost, e.duration, e.outcome
        rollouts += n * m
        j = jc[par] + cost
        tj = times[-1][par] + dur
        # the objective: J, plus the time charge (flight time only grows, so J + tw t bounds every
        # descendant's charge from below and the pruning below stays admissible)
        obj = j + tw * tj if tw else j
        # 2. goal edges: the cheapest complete plan (first in node-major order on ties)
        goal = np.flatnonzero(out == EDGE_GOAL)
        if len(goal):
            i = goal[int(np.argmin(obj[goal]))]
            if obj[i] < best_obj:
                best_obj, best_cost = float(obj[i]), float(j[i])
                best = (depth - 1, int(par[i]), int(ctl[i]), end[i].copy())
        # the seeded paths' children this depth (kept whatever their rank)
        seed_child = [-1] * len(seeds)
        for q, sq in enumerate(seeds):
            if seed_idx[q] >= 0 and depth <= len(sq):
                hit = np.flatnonzero(np.all(ctrls == sq[depth - 1], axis=1))
                if len(hit):
                    c = seed_idx[q] * m + int(hit[0])
                    seed_child[q] = c if out[c] == EDGE_VALID else -1
        forced = np.array(sorted({c for c in seed_child if c >= 0}), dtype=np.int64)
        # 3. valid children; admissible pruning (module docstring)
        ok = edge_rules(ctx, x[par, S_H], end[:, S_H], j)
        valid = (out == EDGE_VALID) & (obj - G * (h_cap - end[:, S_H]) < best_obj) & ok
        forced = forced[ok[forced]]
        keep = np.flatnonzero(valid)
        keep = np.union1d(keep, forced)
        if depth == cfg.max_edges or len(keep) == 0:
            break
        ce = end[keep]
        jk = j[keep]
        d_goal = np.maximum(np.hypot(ce[:, S_N] - gn, ce[:, S_E] - ge) - gr, 0.0)
        rank = jk + cost_to_go_estimate(ce, d_goal, per_metre, g_top, lift, (gn, ge), ctx.descent)
        if cfg.progress_weight:
            rank = rank + cfg.progress_weight * per_metre * d_goal
        key = _cell_keys(ce, cfg, ctx)
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
        if len(uniq) > width:
            uniq = _select(uniq, rank, jk, ce, width, cfg)
        if len(forced):
            sp = np.searchsorted(keep, forced)  # positions of the forced children in keep
            uniq = np.union1d(uniq, sp)
        for q, c in enumerate(seed_child):
            seed_idx[q] = int(np.searchsorted(uniq, np.searchsorted(keep, c))) if c >= 0 else -1
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
        times.append(tj[sel_children])
        parents.append(par[sel_children])
        controls_of.append(ctl[sel_children])
        progress(depth, cfg.max_edges)
    progress(cfg.max_edges, cfg.max_edges)
    if best is None:
        return None, rollouts, depth
    d, i, c, end_state = best
    path_states = [end_state]
    path_ctrls = [c]
    while d > 0:
        path_states.append(states[d][i])
        path_ctrls.append(int(controls_of[d][i]))
        i = int(parents[d][i])
        d -= 1
    path_states.append(states[0][0])
    return (best_obj, best_cost, np.array(path_states[::-1]), ctrls[np.array(path_ctrls[::-1])]), rollouts, depth


def thermal_values(
    model: SoaringModel, controls: np.ndarray, offsets: Sequence[float] = (0.0, 20.0), n_courses: int = 4
) -> np.ndarray:
    """Per thermal that the action set can climb in: (north [m], east [m], value [J/(kg m)]) rows,
    the value being what one metre of climb there is worth, ``-cost / dh`` of the cheapest (most
    negative) climbing edge from near the centre (g for a zero-thrust climb; less where the climb
    needs thrust). Starts: ``offsets`` [m] from the centre at t = 0 (the search's: 0 and 20 m),
    ``n_courses`` courses (its: four), at the start height (clipped to 50 m .. zi - 100 m). A
    thermal with a life cycle is valued when it is first mature after t = 0 (at max(0, birth +
    rise), its centre drifted there); one dead by then has none."""
    sc = model.scenario
    rows = []
    problem = SoaringProblem(model, "primitive" if controls.shape[1] == 1 else "continuous")
    h = float(np.clip(sc.start[3], 50.0, max(50.0, sc.field.zi - 100.0)))
    for j, t in enumerate(sc.field.thermals):
        tm = 0.0 if t.lifetime is None else max(0.0, t.birth + t.rise)
        if tm >= t.death:
            continue
        cn, ce = (t.north, t.east) if tm == 0.0 else (float(c) for c in sc.field.centres(tm)[j])
        starts = []
        for off in offsets:
            for chi in (0.0, 0.5 * math.pi, math.pi - 1e-9, -0.5 * math.pi)[:n_courses]:
                n, e = cn + off * math.cos(chi + 0.5 * math.pi), ce + off * math.sin(chi + 0.5 * math.pi)
                if bool(sc.bounds.contains(n, e, h)):
                    starts.append([n, e, chi, h, tm, math.nan])
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


def cost_to_go_estimate(s, d_goal, per_metre, g_top, lift, goal_ne, descent=0.0) -> np.ndarray:
    """The ranking heuristic of the module docstring, per state row of ``s``: the cheaper of flying
    straight in (``eps d``) and of a detour through a thermal j that climbs to the goal top there
    (``eps (d_j + d_j,goal) - value_j max(0, h_top - h)``), but at least ``g (h - h_top)``; with a
    ``descent`` step D [m] > 0, a node above the top at least ``g max(h - h_top, D) + eps d``."""
    h = s[:, S_H]
    est = per_metre * d_goal
    for tn, te, val in lift:
        d_j = np.hypot(s[:, S_N] - tn, s[:, S_E] - te)
        d_jg = math.hypot(goal_ne[0] - tn, goal_ne[1] - te)
        est = np.minimum(est, per_metre * (d_j + d_jg) - val * np.maximum(0.0, g_top - h))
    if descent > 0.0:  # above the top: a whole descending edge, then still the distance to go
        est = np.where(h > g_top, np.maximum(est, G * np.maximum(h - g_top, descent) + per_metre * d_goal), est)
    return np.maximum(est, G * (h - g_top))  # height above the goal top must be given up either way


def _select(
    cand: np.ndarray, rank: np.ndarray, jk: np.ndarray, s: np.ndarray, width: int, cfg: ReferenceConfig
) -> np.ndarray:
    """The beam: ``width`` of ``cand`` (sorted indices). Two orders are interleaved -- by rank
    (cost-to-come plus the cost-to-go estimate) and by cost-to-come alone (the nodes that have
    gained the most energy, wherever they are) -- and the first ``region_quota`` of each region
    (``region_size`` squares) in that order go first, so that no part of the domain is crowded out."""
    n = len(cand)
    pos_rank = np.empty(n, dtype=np.int64)
    pos_rank[np.lexsort((cand, jk[cand], rank[cand]))] = np.arange(n)
    pos_cost = np.empty(n, dtype=np.int64)
    pos_cost[np.lexsort((cand, rank[cand], jk[cand]))] = np.arange(n)
    order = np.lexsort((pos_rank, np.minimum(pos_rank, pos_cost)))
    if cfg.region_quota > 0:
        sn = s[cand[order]]
        rn = np.floor(sn[:, S_N] / cfg.region_size).astype(np.int64)
        re_ = np.floor(sn[:, S_E] / cfg.region_size).astype(np.int64)
        region = rn * (1 << 20) + re_
        by_region = np.lexsort((np.arange(n), region))  # stable: interleaved order within a region
        first = np.ones(n, dtype=bool)
        first[1:] = region[by_region[1:]] != region[by_region[:-1]]
        start = np.maximum.accumulate(np.where(first, np.arange(n), 0))
        place = np.empty(n, dtype=np.int64)
        place[by_region] = np.arange(n) - start
        quota = place < cfg.region_quota
        order = np.concatenate([order[quota], order[~quota]])
    return np.sort(cand[order[:width]])


def _check_cell_grid(model: SoaringModel, cfg: ReferenceConfig, n_speeds: int) -> None:
    """Check that the dominance grid over the domain can be numbered in 63 bits (north and east
    cells within +-2^15 of the origin, height layers below 2^13, courses x speeds below 2^18)."""
    b = model.scenario.bounds
    reach = max(abs(b.north_min), abs(b.north_max), abs(b.east_min), abs(b.east_max)) / cfg.cell_size
    if reach >= 2**15 - 1 or b.height_max / cfg.height_cell >= 2**13 - 1 or cfg.course_cells * (n_speeds + 1) >= 2**18:
        raise ConfigError(
            f"cell_size={cfg.cell_size!r}, height_cell={cfg.height_cell!r}, course_cells={cfg.course_cells!r} "
            "make more cells than can be numbered for this domain; allowed: at most 2^15 cells from the origin "
            "north and east, 2^13 height layers, course_cells x (airspeeds + 1) < 2^18"
        )


def _cell_keys(s: np.ndarray, cfg: ReferenceConfig, ctx: _Context) -> np.ndarray:
    """One int64 per state: its (north, east, height, course, last-airspeed) cell, packed (the
    ranges are checked by :func:`_check_cell_grid`)."""
    nc = cfg.course_cells
    ni = np.floor(s[:, S_N] / cfg.cell_size).astype(np.int64) + (1 << 15)
    ei = np.floor(s[:, S_E] / cfg.cell_size).astype(np.int64) + (1 << 15)
    ci = np.floor((s[:, S_CHI] + math.pi) / (2 * math.pi) * nc).astype(np.int64) % nc
    hi = np.floor(s[:, S_H] / cfg.height_cell).astype(np.int64)
    vi = np.searchsorted(ctx.speed_keys, np.round(s[:, S_V], 9))
    nv = len(ctx.speed_keys) + 1
    return (((ni * (1 << 16) + ei) * (1 << 13) + hi) * nc + ci) * nv + vi


__all__ = [
    "ReferenceConfig",
    "SearchResult",
    "control_set",
    "glide_angle",
    "search",
    "smallest_descent",
    "still_air_cost_per_metre",
    "thermal_values",
]
