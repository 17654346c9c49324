"""The one-call soaring planner: :func:`plan_soaring` and :func:`make_planner` build the SST over
a :class:`SoaringModel` (:class:`~baselines.sst.soaring.SoaringProblem`) for a named or given
configuration, including :class:`SeededSST`, the SST that starts from a reference search's plan.

(This module sits above :mod:`baselines.reference`, whose search flies edges with the SST's
soaring adapter and returns :class:`~baselines.sst.plan.Plan` s; nothing below imports it.)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import fields
from typing import Any

import numpy as np

from baselines.sst.core import SST, SSTParams, SSTResult, SSTStats, check_budget
from baselines.sst.plan import PlanningResult, plan_from_result
from baselines.sst.reference import ReferenceSST
from baselines.sst.soaring import S_CHI, S_E, S_H, S_N, S_T, S_V, SST_CONFIGS, SoaringProblem, SoaringSSTConfig
from soaring_env._validation import ConfigError, check_bool, check_seed
from soaring_env.model import SoaringModel

#: Most of a :class:`SeededSST` budget spent looking for a first solution before the seeding search.
FIRST_SHARE = 0.1


class SeededSST(SST):
    """SST that starts from the plan of a short reference beam search (``seed_width > 0``).

    The first call of :meth:`run` (a) runs SST rounds until the first solution (at most
    ``FIRST_SHARE`` of the budget) -- the goal completions usually give it within milliseconds, as
    without a seed; (b) runs the reference search (:func:`baselines.reference.search`: the
    deterministic beam over the same action set, with cell dominance and the admissible potential
    bound) with widths ``seed_scout_width`` (a narrow first beam, for an early plan), then
    ``seed_start_width``, twice that, ... up to ``seed_width`` (:func:`seed_widths`), as long as the
    next one is expected to fit into ``seed_share`` of the budget (a beam's time grows about as its
    width; a beam that is not expected to finish, projected from its first depths, stops
    at once and the search ends: with budgets too short for any beam the planner is plain SST
    after a few depths' detour); each beam is seeded with the tree's best plan (its controls join the
    continuous control grid), so it keeps that plan's nodes at every depth and can only improve on
    it, and (c) its plan is inserted into the tree at once (:meth:`SST.insert_path`); with
    ``seed_polish`` and the primitive sampler, the beams get ``seed_share - seed_polish_share``
    of the budget and then the tree's best plan is polished by local search
    (:func:`baselines.reference.polish.polish`, as the reference is) in what is left of
    ``seed_share``, and inserted likewise; (d) the rest
    of the budget goes to SST as usual: the refinements perturb the inserted plan edge by edge, and the
    random expansions go on, so SST's probabilistic completeness and asymptotic near-optimality are
    kept (the seed only adds nodes). The search's time and edges count in ``stats`` (``elapsed``,
    ``iterations``, ``seed_edges``). An iteration budget counts SST's random expansions and the
    search's edges (``seed_share`` of it for the search, in edges: the plan is deterministic); with
    a wall-clock budget the search runs as wide a beam as fits.
    Later calls of :meth:`run` continue plain SST.
    """

    def __init__(self, problem: SoaringProblem, params: SSTParams | None = None, seed: int | None = 0) -> None:
        super().__init__(problem, params, seed)
        self.soaring_problem = problem
        self.seeded = False
        #: the seeding searches run: (beam width (0: the polish), cost found [J/kg] (inf: none),
        #: edges flown, seconds)
        self.seed_searches: list[tuple[int, float, int, float]] = []

    def run(
        self,
        time_limit: float | None = None,
        max_iterations: int | None = None,
        *,
        callback: Callable[[SSTStats], None] | None = None,
    ) -> SSTResult:
        """As :meth:`SST.run`; the first call seeds the tree (see the class docstring)."""
        if self.seeded:
            return super().run(time_limit, max_iterations, callback=callback)
        from baselines.reference.beam import ReferenceConfig, envelope_grid, search  # (the layer above: see the module)
        from baselines.reference.polish import polish

        t_lim, n_lim = check_budget(time_limit, max_iterations)
        self.seeded = True
        t_start = time.perf_counter()
        # (a) SST rounds until its first solution, for at most FIRST_SHARE of the budget; an
        # iteration budget counts random expansions (as SST's does) and the search's edges
        used_n = 0
        while True:
            first = self.params.batch_size if n_lim is None else min(self.params.batch_size, n_lim - used_n)
            res = super().run(max_iterations=first, callback=callback)
            used_n += first
            if (
                res.solved
                or (t_lim is not None and time.perf_counter() - t_start >= FIRST_SHARE * t_lim)
                or (n_lim is not None and used_n >= FIRST_SHARE * n_lim)
            ):
                break
        # (b) the reference search, one width at a time (8, then 32, 64, ...), each seeded with the
        # best plan so far and inserted at once: iterative widening as in `search`, with an anytime
        # record
        p, cfg = self.soaring_problem, self.soaring_problem.config
        root = p.root_state()
        vp = float(root[S_V])
        max_edges = self.params.max_depth or ReferenceConfig().max_edges
        # the planner's start, as the searches take it
        here: dict[str, Any] = {
            "start": root[[S_N, S_E, S_CHI, S_H]],
            "t0": float(root[S_T]),
            "airspeed_prev": None if math.isnan(vp) else vp,
        }
        seed_n = 0
        last_s = last_n = 0.0
        last_w = 1
        # the polish is for the primitive sampler only (see SoaringSSTConfig.seed_polish)
        polish_depth = cfg.seed_polish if p.kind == "primitive" else 0
        # a continuous grid inside the model's envelope (the physical one excludes the paper's)
        grid = envelope_grid(p.model) if p.kind == "continuous" else {}
        beam_share = cfg.seed_share - (cfg.seed_polish_share if polish_depth else 0.0)
        for width in seed_widths(cfg):
            share_t = None if t_lim is None else beam_share * t_lim - (time.perf_counter() - t_start)
            share_n = None if n_lim is None else int(beam_share * n_lim) - used_n - seed_n
            grow = width / last_w  # (a beam's time and edges grow about as its width)
            if (share_t is not None and share_t <= grow * last_s) or (share_n is not None and share_n <= grow * last_n):
                break
            best = self.result()
            found = search(
                p.model,
                p.kind,
                ReferenceConfig(
                    beam_width=width,
                    start_width=width,
                    max_edges=max_edges,
                    progress_weight=cfg.seed_progress_weight,
                    **grid,
                ),
                seed_controls=[best.controls] if best.solved else [],
                battery=math.inf if p.battery is None else p.battery,
                **here,
                time_limit=share_t,
                max_rollouts=share_n,
            )
            seed_n += found.rollouts
            last_s, last_n, last_w = found.seconds, float(found.rollouts), width
            self._record(width, found, callback)
            if found.stopped:
                break  # (a beam the budget stopped gave its time back: SST has it)
        # (c) the polish of the tree's best plan, in what is left of the seeding share
        best = self.result()
        share_t = None if t_lim is None else cfg.seed_share * t_lim - (time.perf_counter() - t_start)
        share_n = None if n_lim is None else int(cfg.seed_share * n_lim) - used_n - seed_n
        if polish_depth and best.solved and (share_t is None or share_t > 0.0) and (share_n is None or share_n > 0):
            pol = polish(
                p.model,
                p.kind,
                best.controls,
                ReferenceConfig(max_edges=max_edges),
                depth=polish_depth,
                **here,
                time_limit=share_t,
                max_rollouts=share_n,
            )
            seed_n += pol.rollouts
            self._record(0, pol, callback)
        rest_t = None if t_lim is None else t_lim - (time.perf_counter() - t_start)
        rest_n = None if n_lim is None else n_lim - used_n - seed_n
        if (rest_t is not None and rest_t <= 0.0) or (rest_n is not None and rest_n <= 0):
            return self.result()
        return super().run(rest_t, rest_n, callback=callback)

    def _record(self, width: int, found: Any, callback: Callable[[SSTStats], None] | None) -> None:
        """Insert a seeding search's plan into the tree (if cheaper: :meth:`SST.insert_path`) and
        record the search (``width`` 0: the polish)."""
        self.insert_path(found.plan.controls(), seconds=found.seconds, edges=found.rollouts)
        self.seed_searches.append((width, found.cost, found.rollouts, found.seconds))
        if callback is not None:
            callback(self.stats)


def seed_widths(config: SoaringSSTConfig) -> list[int]:
    """The beam widths the seeded planner tries, in order (while they fit into its budget): the
    scout width if narrower than the start width, then the start width doubled up to
    ``seed_width`` (none if ``seed_width`` is 0)."""
    from baselines.reference.beam import widening  # (the layer above: see the module)

    if not config.seed_width:
        return []
    out = widening(config.seed_start_width, config.seed_width)
    return [config.seed_scout_width, *out] if 0 < config.seed_scout_width < out[0] else out


def make_planner(
    model: SoaringModel,
    sampler: str = "primitive",
    *,
    config: SoaringSSTConfig | Mapping[str, Any] | str | None = None,
    seed: int | None = 0,
    start: np.ndarray | None = None,
    t0: float = 0.0,
    airspeed_prev: float | None = None,
    reference: bool = False,
    battery: float | None = None,
) -> tuple[SoaringProblem, SST | ReferenceSST]:
    """Build the soaring problem and an SST planner over it (``reference=True``: the plain
    :class:`ReferenceSST`; ``config.seed_width > 0``: :class:`SeededSST`). Arguments as in
    :func:`plan_soaring`."""
    cfg = as_sst_config(config)
    check_seed("seed", seed)
    check_bool("reference", reference)
    if reference and cfg.seed_width:
        raise ConfigError(f"reference=True plans without a seeding search; set seed_width=0 (got {cfg.seed_width!r})")
    problem = SoaringProblem(model, sampler, cfg, start=start, t0=t0, airspeed_prev=airspeed_prev, battery=battery)
    params = SSTParams(
        selection_radius=cfg.selection_radius,
        pruning_radius=cfg.pruning_radius,
        batch_size=cfg.batch_size,
        max_depth=cfg.max_edges,
        completions=cfg.completions,
        completion_depth=cfg.completion_depth,
        refinements=cfg.refinements,
    )
    if reference:
        return problem, ReferenceSST(problem, params, seed=seed)
    return problem, (SeededSST if cfg.seed_width else SST)(problem, params, seed=seed)


def as_sst_config(config: SoaringSSTConfig | Mapping[str, Any] | str | None) -> SoaringSSTConfig:
    """A :class:`SoaringSSTConfig` from itself, a dict of its fields, a name of ``SST_CONFIGS`` or
    None (the defaults); unknown names, keys and other types raise a :class:`ConfigError` with
    what is allowed."""
    if config is None:
        return SoaringSSTConfig()
    if isinstance(config, str):
        if config not in SST_CONFIGS:
            raise ConfigError(
                f"config={config!r} is not a named configuration; allowed: {', '.join(map(repr, SST_CONFIGS))}"
            )
        return SST_CONFIGS[config]
    if isinstance(config, SoaringSSTConfig):
        return config
    names = [f.name for f in fields(SoaringSSTConfig)]
    if isinstance(config, Mapping):
        unknown = sorted(str(k) for k in config if k not in names)
        if unknown:
            raise ConfigError(f"config has unknown key(s) {unknown!r}; allowed: {', '.join(names)}")
        return SoaringSSTConfig(**config)
    raise ConfigError(
        f"config={config!r} has type {type(config).__name__}; a SoaringSSTConfig, a dict of its fields "
        f"({', '.join(names)}), a name of SST_CONFIGS or None is required"
    )


def plan_soaring(
    model: SoaringModel,
    sampler: str = "primitive",
    *,
    time_limit: float | None = None,
    max_iterations: int | None = None,
    seed: int | None = 0,
    config: SoaringSSTConfig | Mapping[str, Any] | str | None = None,
    start: np.ndarray | None = None,
    t0: float = 0.0,
    airspeed_prev: float | None = None,
    partial: bool = False,
    reference: bool = False,
    battery: float | None = None,
) -> PlanningResult:
    """Plan from the scenario's start (or ``start``) to its goal region with SST.

    :param model: the flight model (scenario, aircraft, primitives) -- SST knows the thermal field.
    :param sampler: ``"primitive"`` (174 primitives) or ``"continuous"`` (the continuous envelope).
    :param time_limit: wall-clock budget [s].
    :param max_iterations: iteration budget (at least one budget is required).
    :param seed: planner seed (same seed, same budget in iterations -> same plan).
    :param config: radii, distance weights, batch size, the seeding search (a
        :class:`SoaringSSTConfig`, a dict of its fields, or the name of one of ``SST_CONFIGS``).
    :param start: start state ``[Pn, Pe, chi, h]``; default the scenario's start.
    :param t0: start time [s].
    :param airspeed_prev: airspeed before the start [m/s] (None: the first edge pays no kinetic term).
    :param partial: if no solution is found, return the path to the tree node nearest the goal
        centre (for receding-horizon use) instead of an empty plan.
    :param reference: use the plain unbatched :class:`ReferenceSST` (slow; for comparisons).
    :param battery: the motor energy left at the start [J/kg] (the cross-country task's
        ``battery_left``; None: no battery): edges that empty it are invalid
        (:class:`~baselines.sst.soaring.SoaringProblem`); the seeding beams search within it, and a
        seed or polished plan that would empty it is not inserted (``insert_path`` flies it again).
    :returns: the plan (``plan.solved`` tells whether it reaches the goal) and the statistics;
        no solution within the budget is a normal result.
    """
    problem, planner = make_planner(
        model,
        sampler,
        config=config,
        seed=seed,
        start=start,
        t0=t0,
        airspeed_prev=airspeed_prev,
        reference=reference,
        battery=battery,
    )
    check_bool("partial", partial)
    res = planner.run(time_limit=time_limit, max_iterations=max_iterations)
    if not res.solved and partial:
        tree = planner.tree()
        g = model.scenario.require_goal()
        d = g.distance(tree.states[:, 0], tree.states[:, 1], tree.states[:, 3])
        res = planner.result_for(int(tree.ids[int(np.argmin(d))]))
    return PlanningResult(plan=plan_from_result(problem, res), stats=res.stats)
