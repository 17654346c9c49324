"""A plain reference SST: one iteration at a time, brute-force nearest neighbours (numpy over all
nodes), one propagation call per iteration.

It is the yardstick of ``scripts/bench_sst.py`` and the oracle of the tests: for the same problem,
parameters and seed it builds the same tree as :class:`baselines.sst.core.SST` with
``batch_size=1`` (same random draws, same slot ids, same tie-breaks: lowest id first).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from baselines.sst import _kernels as K
from baselines.sst.core import Problem, SSTError, SSTParams, SSTResult, SSTStats, TreeView, check_budget
from soaring_env._validation import check_seed


class ReferenceSST:
    """Unbatched SST, written for clarity rather than speed (see :mod:`baselines.sst.core`).

    :param problem: the planning problem.
    :param params: radii (``batch_size`` is ignored: always 1).
    :param seed: seed of the planner's ``np.random.Generator``.
    """

    def __init__(self, problem: Problem, params: SSTParams | None = None, seed: int | None = 0) -> None:
        if not isinstance(problem, Problem):
            raise SSTError(f"problem={problem!r} does not implement the Problem protocol")
        self.problem = problem
        self.params = params or SSTParams()
        for name in ("completions", "refinements"):
            if getattr(self.params, name):
                raise SSTError(
                    f"{name}={getattr(self.params, name)!r}: ReferenceSST is the published algorithm; the goal "
                    "completions and refinements are an extension of the batched SST only; allowed: 0"
                )
        self.rng = np.random.default_rng(check_seed("seed", seed))
        sp = problem.space
        self.space = sp
        self._dims = list(sp.dims)
        cap = 1024
        dim, cdim = sp.dim, problem.control_dim
        self.X = np.zeros((cap, dim))
        self.U = np.zeros((cap, cdim))
        self.cost = np.full(cap, np.inf)
        self.ecost = np.zeros(cap)
        self.tcome = np.zeros(cap)
        self.parent = np.full(cap, -1, np.int64)
        self.depth = np.zeros(cap, np.int64)
        self.nchild = np.zeros(cap, np.int64)
        self.status = np.zeros(cap, np.int8)
        self.W = np.zeros((cap, len(sp.dims)))
        self.rep = np.full(cap, -1, np.int64)
        self.used = 1
        self.n_w = 1
        self.free: list[int] = []
        root = np.asarray(problem.root_state(), np.float64)
        self.X[0] = root
        self.cost[0] = 0.0
        self.status[0] = K.ACTIVE
        self.W[0] = root[self._dims]
        self.rep[0] = 0
        self.best = -1
        self.stats = SSTStats(batch_size=1, active=1, witnesses=1)

    # --- helpers ----------------------------------------------------------------------------
    def _d2(self, pts: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Squared distances between rows of ``pts`` and ``q`` (both in metric coordinates), with
        exactly the arithmetic of the numba kernels."""
        s = np.zeros(len(pts))
        for k in range(len(self._dims)):
            d = np.abs(pts[:, k] - q[k])
            p = self.space.periods[k]
            if p > 0:
                d = d % p
                d = np.where(p - d < d, p - d, d)
            d = d * self.space.scales[k]
            s = s + d * d
        return s

    def _grow(self) -> None:
        for name in ("X", "U", "cost", "ecost", "tcome", "parent", "depth", "nchild", "status", "W", "rep"):
            arr = getattr(self, name)
            fill = np.inf if name == "cost" else (-1 if name in ("parent", "rep") else 0)
            new = np.full((2 * len(arr), *arr.shape[1:]), fill, dtype=arr.dtype)
            new[: len(arr)] = arr
            setattr(self, name, new)

    def _alloc(self) -> int:
        if self.free:
            return self.free.pop()
        self.used += 1
        return self.used - 1

    def _release(self, node: int) -> None:
        self.status[node] = K.FREE
        self.free.append(node)
        self.stats.removed += 1

    def _prune_up(self, x: int) -> None:
        while x >= 0 and self.status[x] == K.INACTIVE and self.nchild[x] == 0:
            p = int(self.parent[x])
            self._release(x)
            self.stats.inactive -= 1
            if p >= 0:
                self.nchild[p] -= 1
            x = p

    def _new_node(self, p: int, x: np.ndarray, u: np.ndarray, c: float, ec: float, dur: float) -> int:
        node = self._alloc()
        self.X[node] = x
        self.U[node] = u
        self.cost[node] = c
        self.ecost[node] = ec
        self.tcome[node] = self.tcome[p] + dur
        self.parent[node] = p
        self.depth[node] = self.depth[p] + 1
        self.nchild[node] = 0
        self.nchild[p] += 1
        return node

    # --- one iteration ------------------------------------------------------------------------
    def step(self) -> bool:
        """One SST iteration; returns True if the best solution improved."""
        if max(self.used, self.n_w) + 2 > len(self.cost):
            self._grow()
        s = self.stats
        # Best_First_Selection_SST
        f = getattr(self.problem, "sample_targets", None)
        q = (self.space.sample(self.rng, 1) if f is None else np.asarray(f(self.rng, 1), np.float64))[0]
        act = np.flatnonzero(self.status[: self.used] == K.ACTIVE)
        d2 = self._d2(self.X[act][:, self._dims], q)
        near = act[d2 <= self.params.selection_radius**2]
        if len(near):
            cmin = self.cost[near].min()
            sel = int(near[self.cost[near] == cmin].min())
        else:
            sel = int(act[d2 == d2.min()].min())
            s.fallbacks += 1
        # MonteCarlo-Prop
        u = np.asarray(self.problem.sample_controls(self.rng, 1), np.float64).reshape(1, -1)
        e = self.problem.propagate(self.X[sel : sel + 1], u)
        s.iterations += 1
        oc = int(e.outcome[0])
        if oc == K.EDGE_INVALID:
            s.invalid += 1
            return False
        x_new = np.asarray(e.states[0], np.float64)
        c_new = self.cost[sel] + float(e.cost[0])
        if oc == K.EDGE_GOAL:
            s.goal_edges += 1
            if c_new < s.best_cost:
                node = self._new_node(sel, x_new, u[0], c_new, float(e.cost[0]), float(e.duration[0]))
                self.status[node] = K.SOLUTION
                old, self.best = self.best, node
                s.best_cost = c_new
                s.best_duration = float(self.tcome[node])
                if old >= 0:
                    op = int(self.parent[old])
                    self._release(old)
                    self.nchild[op] -= 1
                    self._prune_up(op)
                return True
            return False
        if self.depth[sel] + 1 >= self.params.depth_limit:
            s.too_deep += 1
            return False
        if e.togo is not None and c_new + float(e.togo[0]) >= s.best_cost:
            s.bounded += 1
            return False
        # Is_Node_Locally_the_Best_SST
        dw = self._d2(self.W[: self.n_w], x_new[self._dims])
        inside = np.flatnonzero(dw <= self.params.pruning_radius**2)
        if len(inside):
            w = int(inside[dw[inside] == dw[inside].min()].min())
        else:
            w = self.n_w
            self.n_w += 1
            self.W[w] = x_new[self._dims]
            self.rep[w] = -1
            s.witnesses += 1
        peer = int(self.rep[w])
        if peer >= 0 and not c_new < self.cost[peer]:
            s.dominated += 1
            return False
        # Prune_Dominated_Nodes_SST
        node = self._new_node(sel, x_new, u[0], c_new, float(e.cost[0]), float(e.duration[0]))
        self.status[node] = K.ACTIVE
        s.active += 1
        s.accepted += 1
        self.rep[w] = node
        if peer >= 0:
            self.status[peer] = K.INACTIVE
            s.active -= 1
            s.inactive += 1
            s.deactivated += 1
            self._prune_up(peer)
        return False

    def run(
        self,
        time_limit: float | None = None,
        max_iterations: int | None = None,
        *,
        callback: Callable[[SSTStats], None] | None = None,
    ) -> SSTResult:
        """Iterate until the wall-clock [s] or iteration budget is spent (see ``SST.run``)."""
        t_lim, n_lim = check_budget(time_limit, max_iterations)
        t0 = time.perf_counter()
        base = self.stats.elapsed
        n = 0
        while n_lim is None or n < n_lim:
            improved = self.step()
            n += 1
            now = time.perf_counter()
            self.stats.elapsed = base + now - t0
            if improved:
                s = self.stats
                if s.time_to_first_solution is None:
                    s.time_to_first_solution = s.elapsed
                    s.iterations_to_first_solution = s.iterations
                s.cost_history.append((s.elapsed, s.iterations, s.best_cost))
            if callback is not None:
                callback(self.stats)
            if t_lim is not None and now - t0 >= t_lim:
                break
        return self.result()

    # --- results --------------------------------------------------------------------------------
    @property
    def best_node(self) -> int:
        return self.best

    def path_to(self, node: int) -> list[int]:
        path = [node]
        while self.parent[path[-1]] >= 0:
            path.append(int(self.parent[path[-1]]))
        return path[::-1]

    def result_for(self, node: int) -> SSTResult:
        ids = np.asarray(self.path_to(node), np.int64)
        return SSTResult(
            solved=node == self.best,
            cost=float(self.cost[node]),
            states=self.X[ids].copy(),
            controls=self.U[ids[1:]].copy(),
            edge_costs=self.ecost[ids[1:]].copy(),
            durations=self.tcome[ids[1:]] - self.tcome[ids[:-1]],
            stats=self.stats,
        )

    def result(self) -> SSTResult:
        if self.best >= 0:
            return self.result_for(self.best)
        return SSTResult(
            solved=False,
            cost=math.inf,
            states=np.zeros((0, self.space.dim)),
            controls=np.zeros((0, self.problem.control_dim)),
            edge_costs=np.zeros(0),
            durations=np.zeros(0),
            stats=self.stats,
        )

    def tree(self) -> TreeView:
        st = self.status[: self.used]
        ids = np.flatnonzero(st != K.FREE)
        return TreeView(
            ids=ids,
            states=self.X[ids].copy(),
            cost=self.cost[ids].copy(),
            parent=self.parent[ids].copy(),
            status=st[ids].copy(),
            nchild=self.nchild[ids].copy(),
            controls=self.U[ids].copy(),
            tcome=self.tcome[ids].copy(),
            witnesses=self.W[: self.n_w].copy(),
            witness_rep=self.rep[: self.n_w].copy(),
        )
