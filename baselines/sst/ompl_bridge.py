"""OMPL's ``control::SST`` and ``control::RRT`` on the soaring problem, for comparison.

The same problem as our planner's: OMPL flies every edge through
:meth:`baselines.sst.soaring.SoaringProblem.propagate` (the calls ``env.step`` makes), with the
paper's uniform control spaces (a ``RealVectorControlSpace`` over [-1, 1]^3, rounded to float32 as
the continuous env stores actions, or a ``DiscreteControlSpace`` over the 174 primitives, those
beyond the bank limit invalid), the same goal region, the same depth limit, the same radii
(delta_BN, delta_s) and the raw edge costs as OMPL's motion costs (negative in lift). One control
is held for one Ts per edge (``setMinMaxControlDuration(1, 1)``).

What differs, and why: OMPL's compound state space combines subspace distances as a *weighted sum*
(north/east/height Euclidean, plus ``heading_scale`` times the wrapped course difference), not the
Euclidean combination of :mod:`baselines.sst.soaring`; the state carries a payload (time, previous
airspeed, the edge's cost, its outcome, the depth) in a subspace of weight 0. The propagator is a
Python callback, so OMPL runs at a fraction of our batched planner's iteration rate: that is part
of what the comparison shows. OMPL's control RRT does not optimize: it keeps its first solution.

The Python bindings may crash at interpreter exit, so every run happens in a spawned subprocess
that sends its result back and ends with ``os._exit``. Install with ``pip install -e ".[ompl]"``
(``ompl==1.7.0``: its wheels accept Python propagators).
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import time
from typing import Any

import numpy as np

from baselines.sst.core import EDGE_GOAL, EDGE_INVALID
from baselines.sst.soaring import S_CHI, S_E, S_H, S_N, S_T, S_V, SAMPLERS, SST_CONFIGS, SoaringProblem
from soaring_env._validation import ConfigError, check_choice, check_int, check_positive
from soaring_env.model import SoaringModel
from soaring_env.scenario import Scenario

OMPL_PLANNERS = ("sst", "rrt")
#: Payload columns: time [s], previous airspeed [m/s] (-1: none), edge cost [J/kg], outcome, depth.
_P_T, _P_V, _P_COST, _P_OUT, _P_DEPTH = range(5)


def ompl_available() -> bool:
    """Whether the ``ompl`` Python bindings can be imported (checked in a subprocess)."""
    ctx = mp.get_context("spawn")
    p = ctx.Process(target=_probe)
    p.start()
    p.join(120)
    return p.exitcode == 0


def _probe() -> None:
    try:
        import ompl.control  # noqa: F401
    except Exception:
        os._exit(3)
    os._exit(0)


def run_ompl(
    scenario: Scenario,
    sampler: str,
    planner: str,
    *,
    time_limit: float,
    seed: int = 0,
    max_edges: int = 40,
    slice_s: float = 0.05,
) -> dict[str, Any]:
    """Plan with OMPL's ``planner`` for ``time_limit`` seconds of wall clock (in slices of
    ``slice_s``, recording the best cost after each) in a subprocess.

    :returns: ``{"history": [[t, cost], ...], "best_cost": float (inf: none), "solved": bool,
        "iterations": propagations, "elapsed": s, "actions": the best plan's env actions}``.
    """
    check_choice("sampler", sampler, SAMPLERS)
    check_choice("planner", planner, OMPL_PLANNERS)
    check_positive("time_limit", time_limit)
    check_int("seed", seed, 0, 2**31 - 2)
    check_int("max_edges", max_edges, 1)
    if not isinstance(scenario, Scenario):
        raise ConfigError(f"scenario={scenario!r} must be a soaring_env.scenario.Scenario")
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    args = (scenario.to_dict(), sampler, planner, float(time_limit), int(seed), int(max_edges), float(slice_s))
    proc = ctx.Process(target=_worker, args=(child, args))
    proc.start()
    child.close()
    out: dict[str, Any] | None = None
    if parent.poll(time_limit + 120.0):
        try:
            out = parent.recv()
        except EOFError:
            out = None
    proc.join(30.0)
    if proc.is_alive():
        proc.kill()
    if out is None:
        raise RuntimeError(f"the OMPL subprocess ended without a result (exit code {proc.exitcode})")
    if "error" in out:
        raise RuntimeError(f"OMPL run failed: {out['error']}")
    return out


def _worker(conn: Any, args: tuple[Any, ...]) -> None:
    try:
        conn.send(_plan(*args))
    except Exception as exc:  # reported to the parent, which raises
        conn.send({"error": f"{type(exc).__name__}: {exc}"})
    conn.close()
    os._exit(0)  # the bindings may crash at interpreter exit


def _plan(
    scenario_dict: dict[str, Any],
    sampler: str,
    planner: str,
    time_limit: float,
    seed: int,
    max_edges: int,
    slice_s: float,
) -> dict[str, Any]:
    from ompl import base as ob
    from ompl import control as oc
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(seed + 1)  # OMPL's seeds must be positive
    model = SoaringModel(Scenario.from_dict(scenario_dict))
    cfg = SST_CONFIGS["paper"]
    prob = SoaringProblem(model, sampler, cfg)
    b = model.scenario.bounds
    allowed = model.allowed_primitives()

    space = ob.CompoundStateSpace()
    geo = ob.RealVectorStateSpace(3)
    gb = ob.RealVectorBounds(3)
    for i, (lo, hi) in enumerate(
        [(b.north_min, b.north_max), (b.east_min, b.east_max), (0.0, b.height_max * cfg.height_scale)]
    ):
        gb.setLow(i, lo)
        gb.setHigh(i, hi)
    geo.setBounds(gb)
    pay = ob.RealVectorStateSpace(5)
    pb = ob.RealVectorBounds(5)
    pb.setLow(-1e12)
    pb.setHigh(1e12)
    pay.setBounds(pb)
    space.addSubspace(geo, 1.0)
    space.addSubspace(ob.SO2StateSpace(), cfg.heading_scale)
    space.addSubspace(pay, 0.0)
    space.lock()
    if sampler == "primitive":
        cspace: Any = oc.DiscreteControlSpace(space, 0, model.n_primitives - 1)
    else:
        cspace = oc.RealVectorControlSpace(space, 3)
        cbnd = ob.RealVectorBounds(3)
        cbnd.setLow(-1.0)
        cbnd.setHigh(1.0)
        cspace.setBounds(cbnd)
    si = oc.SpaceInformation(space, cspace)
    n_prop = [0]

    def core_state(s: Any) -> np.ndarray:
        v = s[2][_P_V]
        return np.array(
            [s[0][0], s[0][1], s[1].value, s[0][2] / cfg.height_scale, s[2][_P_T], math.nan if v < 0 else v]
        )

    def control_row(u: Any) -> np.ndarray:
        if sampler == "primitive":
            return np.array([float(u.value)])
        return np.array([u[0], u[1], u[2]], dtype=np.float32).astype(np.float64)

    def propagate(start: Any, control: Any, duration: float, result: Any) -> None:
        n_prop[0] += 1
        u = control_row(control)
        depth = start[2][_P_DEPTH] + 1
        if (sampler == "primitive" and not allowed[int(u[0])]) or depth > max_edges:
            outcome, x, cost = EDGE_INVALID, core_state(start), 0.0
        else:
            e = prob.propagate(core_state(start)[None, :], u[None, :])
            outcome, x, cost = int(e.outcome[0]), e.states[0], float(e.cost[0])
        result[0][0] = x[S_N]
        result[0][1] = x[S_E]
        result[0][2] = min(max(x[S_H], 0.0), b.height_max) * cfg.height_scale
        result[1].value = (x[S_CHI] + math.pi) % (2.0 * math.pi) - math.pi
        result[2][_P_T] = x[S_T]
        result[2][_P_V] = -1.0 if math.isnan(x[S_V]) else x[S_V]
        result[2][_P_COST] = cost
        result[2][_P_OUT] = float(outcome)
        result[2][_P_DEPTH] = depth

    si.setStatePropagator(oc.StatePropagatorFn(propagate))
    si.setStateValidityChecker(ob.StateValidityCheckerFn(lambda s: s[2][_P_OUT] != EDGE_INVALID))
    si.setPropagationStepSize(1.0)
    si.setMinMaxControlDuration(1, 1)
    si.setup()
    goal_region = model.scenario.require_goal()

    class Goal(ob.GoalRegion):  # the goal edge ends at its first point inside the region
        def __init__(self, s: Any) -> None:
            super().__init__(s)
            self.setThreshold(1e-6)

        def distanceGoal(self, s: Any) -> float:
            if s[2][_P_OUT] == EDGE_GOAL:
                return 0.0
            return max(1.0, float(goal_region.distance(s[0][0], s[0][1], s[0][2] / cfg.height_scale)))

    class EdgeCost(ob.OptimizationObjective):  # the raw edge cost carried by the edge's end state
        def __init__(self, s: Any) -> None:
            super().__init__(s)

        def stateCost(self, s: Any) -> Any:
            return ob.Cost(0.0)

        def motionCost(self, s1: Any, s2: Any) -> Any:
            return ob.Cost(s2[2][_P_COST])

    pdef = ob.ProblemDefinition(si)
    start = ob.State(space)
    x0 = prob.root_state()
    st = start()
    st[0][0], st[0][1], st[0][2] = x0[S_N], x0[S_E], x0[S_H] * cfg.height_scale
    st[1].value = x0[S_CHI]
    for k, val in ((_P_T, x0[S_T]), (_P_V, -1.0), (_P_COST, 0.0), (_P_OUT, 0.0), (_P_DEPTH, 0.0)):
        st[2][k] = val
    pdef.addStartState(start)
    goal = Goal(si)
    pdef.setGoal(goal)
    objective = EdgeCost(si)
    pdef.setOptimizationObjective(objective)
    if planner == "sst":
        pl: Any = oc.SST(si)
        pl.setSelectionRadius(cfg.selection_radius)
        pl.setPruningRadius(cfg.pruning_radius)
    else:
        pl = oc.RRT(si)
    pl.setProblemDefinition(pdef)
    pl.setup()
    history: list[list[float]] = []
    best = math.inf
    actions: list[Any] = []
    t0 = time.perf_counter()
    while (now := time.perf_counter() - t0) < time_limit:
        pl.solve(min(slice_s, time_limit - now))
        if pdef.hasExactSolution():
            path = pdef.getSolutionPath()
            n = path.getStateCount()
            cost = sum(path.getState(i)[2][_P_COST] for i in range(1, n))
            if cost < best:
                best = cost
                history.append([time.perf_counter() - t0, cost])
                actions = [control_row(path.getControl(i)).tolist() for i in range(path.getControlCount())]
    return {
        "history": history,
        "best_cost": best,
        "solved": math.isfinite(best),
        "iterations": n_prop[0],
        "elapsed": time.perf_counter() - t0,
        "actions": actions,
    }


__all__ = ["OMPL_PLANNERS", "ompl_available", "run_ompl"]
