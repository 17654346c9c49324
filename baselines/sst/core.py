"""Stable Sparse RRT (SST), Li, Littlefield and Bekris, IJRR 35(5), 2016 -- the generic core.

The core knows nothing about aircraft. It sees a :class:`Problem`:

* a :class:`StateSpace` -- state vectors of ``dim`` floats, a weighted distance over some of the
  components (any of them may wrap, e.g. a course angle) and a box to sample selection targets in;
* ``sample_controls(rng, n)`` -- n random controls (rows of ``control_dim`` floats);
* ``propagate(states, controls)`` -- the edges from n states under n controls: end states, edge
  cost (any real number, negative costs included), duration and outcome (valid, reached the goal,
  invalid). The goal region lives in the propagator because an edge may pass through it.

The algorithm (the paper's Algorithm 6 with its subroutines, ``Best_First_Selection_SST``,
``MonteCarlo-Prop``, ``Is_Node_Locally_the_Best_SST`` and ``Prune_Dominated_Nodes_SST``):

1. draw a random point of the state space (uniform over its box, or from the problem's own
   ``sample_targets(rng, n)`` where it has one); among the *active* nodes within the selection radius
   delta_BN pick the one with the lowest cost-to-come (none within delta_BN: the nearest active
   node);
2. propagate it with one randomly sampled control (Monte-Carlo propagation);
3. invalid edges are dropped. An edge that reaches the goal is a solution candidate: it is kept
   (as a terminal node that is never expanded and has no witness) only if it beats the best
   solution so far, which it then replaces. With a depth limit (``max_depth``, e.g. an episode's
   step limit), a non-goal child at the limit is dropped as well;
4. otherwise find the new node's witness: the nearest witness within the pruning radius delta_s,
   or the new node itself becomes a new witness. The new node is kept only if its witness has no
   representative or a costlier one (strictly: ``cost_new < cost_rep``);
5. a kept node becomes its witness's representative; the displaced representative is made
   *inactive* (never selected again) and, if it is a leaf, removed, then its parent if that is now
   an inactive leaf, and so on up the tree.

So every active node represents exactly one witness (active nodes == witnesses), inactive nodes
stay only as long as they have descendants, and the tree stays sparse. OMPL's current ``SST`` never
deactivates nodes in its pruning loop; this implementation follows the paper.

Costs. Edge costs may be negative (a thermal can return more energy than the motor spends).
Nothing here assumes otherwise: selection and dominance compare costs-to-come. A problem may give,
with every edge, an admissible lower bound on the cost still to go from its end state
(``Edges.togo``; it may be negative); then a child whose cost-to-come plus that bound cannot beat
the best solution is dropped before it is inserted (branch and bound: no solution better than the
best one is lost, so this keeps every property of SST). The best solution is the lowest-cost goal
edge found so far; it can only improve.

Batching. :class:`SST` expands ``batch_size`` (K) nodes per round: it draws K targets, selects K
nodes against the tree as it stands at the start of the round, propagates the K edges in one call
and then inserts the K children one after another exactly as in steps 3-5. With K = 1 this is the
published one-at-a-time algorithm. With K > 1 it differs in two ways only: (a) selection within a
round does not see the nodes added earlier in that round, and (b) a child whose parent was made
inactive by an earlier child of the same round is discarded (counted as ``stale``) -- the
one-at-a-time algorithm would never have expanded an inactive node. So the first round expands
the root K times, and a node that is the cheapest near many of a round's targets is expanded by
all of them, even if an earlier child of that round would have taken over its neighbourhood. Random
draws are made per round (K targets, then K controls), so the random stream differs from K = 1,
but a given seed and K always give the same tree. The wall-clock budget is checked after every
round (one round takes milliseconds). :class:`~baselines.sst.reference.ReferenceSST` is a plain,
unbatched implementation (brute-force nearest neighbours, one propagation per iteration) that gives
the same tree as ``SST`` with K = 1 for the same seed.

Nearest neighbours use two uniform grids over up to three non-periodic weighted dimensions (cells
delta_BN wide for the active nodes, delta_s wide for the witnesses): a radius query scans the 27
cells around the query. When no active node lies within delta_BN, the nearest one is found by an
exact search over growing shells of cells.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from baselines.sst import _kernels as K
from baselines.sst._kernels import EDGE_GOAL, EDGE_INVALID, EDGE_VALID
from soaring_env._validation import ConfigError, check_finite, check_int, check_positive, check_seed

__all__ = [
    "EDGE_GOAL",
    "EDGE_INVALID",
    "EDGE_VALID",
    "SST",
    "Edges",
    "Problem",
    "SSTError",
    "SSTParams",
    "SSTResult",
    "SSTStats",
    "StateSpace",
    "check_budget",
]

#: Upper limit on the number of cells of one grid; coarser cells are used beyond it.
MAX_GRID_CELLS = 1 << 22


#: Invalid planner input; the message names the field, the value and what is allowed. The same
#: class as the model's configuration errors, so one ``except ConfigError`` catches both.
SSTError = ConfigError
_finite = check_finite
_positive = check_positive
_int = check_int


def check_budget(time_limit: float | None, max_iterations: int | None) -> tuple[float | None, int | None]:
    """Validate a planning budget: wall-clock seconds (> 0) and/or iterations (>= 1), at least one."""
    t = None if time_limit is None else _positive("time_limit", time_limit)
    n = None if max_iterations is None else _int("max_iterations", max_iterations, 1)
    if t is None and n is None:
        raise SSTError("time_limit=None and max_iterations=None: give a wall-clock budget [s] or an iteration budget")
    return t, n


@dataclass(frozen=True)
class StateSpace:
    """States are rows of ``dim`` floats; the distance uses the *metric dimensions* only.

    ``distance(a, b)^2 = sum_k (scales[k] * delta_k)^2`` with ``delta_k = a[dims[k]] - b[dims[k]]``
    wrapped into [-periods[k]/2, periods[k]/2] when ``periods[k] > 0``. Components that are not
    metric dimensions (e.g. time, the previous control) travel with the state but do not count.

    :param dim: length of a state vector.
    :param dims: the metric dimensions (column indices).
    :param scales: weight of each metric dimension [distance unit per state unit], > 0.
    :param periods: period of each metric dimension (0 = not periodic), >= 0.
    :param low: lower corner of the box the selection targets are drawn from (one per metric dim).
    :param high: upper corner of that box.
    """

    dim: int
    dims: tuple[int, ...]
    scales: tuple[float, ...]
    periods: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]

    def __post_init__(self) -> None:
        _int("dim", self.dim, 1)
        m = len(self.dims)
        if m == 0:
            raise SSTError("dims=() is empty; at least one metric dimension is required")
        for name in ("scales", "periods", "low", "high"):
            if len(getattr(self, name)) != m:
                raise SSTError(f"{name} has {len(getattr(self, name))} entries; expected one per metric dim ({m})")
        for k, d in enumerate(self.dims):
            if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or not 0 <= d < self.dim:
                raise SSTError(f"dims[{k}]={d!r} is not a column index in 0..{self.dim - 1}")
            _positive(f"scales[{k}]", self.scales[k])
            if _finite(f"periods[{k}]", self.periods[k]) < 0:
                raise SSTError(f"periods[{k}]={self.periods[k]!r} must be >= 0 (0 = not periodic)")
            if _finite(f"high[{k}]", self.high[k]) < _finite(f"low[{k}]", self.low[k]):
                raise SSTError(f"high[{k}]={self.high[k]!r} must be >= low[{k}]={self.low[k]!r}")

    @property
    def grid_axes(self) -> tuple[int, ...]:
        """Indices (into ``dims``) of the up to three non-periodic metric dims the grids use."""
        return tuple(k for k in range(len(self.dims)) if self.periods[k] == 0)[:3]

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n uniform points of the sampling box, in metric coordinates (n, len(dims))."""
        return rng.uniform(np.asarray(self.low), np.asarray(self.high), size=(n, len(self.dims)))

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Distance between states a and b (broadcasting over leading axes)."""
        s = np.zeros(np.broadcast_shapes(np.shape(a)[:-1], np.shape(b)[:-1]))
        for k, d in enumerate(self.dims):
            x = np.abs(np.asarray(a)[..., d] - np.asarray(b)[..., d])
            p = self.periods[k]
            if p > 0:
                x = x % p
                x = np.minimum(x, p - x)
            x = x * self.scales[k]
            s = s + x * x
        return np.sqrt(s)


@dataclass(frozen=True)
class Edges:
    """What a propagator returns for n edges.

    :param states: end states (n, dim); for goal edges, the first state inside the goal region.
    :param cost: edge cost (n,), any real number (negative allowed).
    :param duration: edge duration (n,) (e.g. flight time [s]); summed along a solution path.
    :param outcome: (n,) ints: ``EDGE_VALID``, ``EDGE_GOAL`` or ``EDGE_INVALID``.
    :param togo: optional (n,) admissible lower bound on the cost still to go from each end state to
        the goal (``-inf``: none). A child with cost-to-come + ``togo`` >= the best solution's cost
        can lead to no better solution and is dropped (counted as ``bounded``); None: no bound.
    """

    states: np.ndarray
    cost: np.ndarray
    duration: np.ndarray
    outcome: np.ndarray
    togo: np.ndarray | None = None


@runtime_checkable
class Problem(Protocol):
    """What SST needs to know about a planning problem (see the module docstring)."""

    space: StateSpace
    control_dim: int

    def root_state(self) -> np.ndarray:
        """The start state (dim,)."""
        ...

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n random controls (n, control_dim) drawn only from ``rng``."""
        ...

    def propagate(self, states: np.ndarray, controls: np.ndarray) -> Edges:
        """Edges from ``states`` (n, dim) under ``controls`` (n, control_dim)."""
        ...


@dataclass(frozen=True)
class SSTParams:
    """SST parameters.

    :param selection_radius: delta_BN, radius of best-near selection [distance units], > 0.
    :param pruning_radius: delta_s, witness (sparsity) radius [distance units], > 0.
    :param batch_size: K, expansions per round (1 = the published one-at-a-time algorithm).
    :param max_depth: most edges a solution may have (None: unlimited); a non-goal child at this
        depth is dropped (counted as ``too_deep``), since it could only lead to longer solutions.
    :param initial_capacity: initial node/witness array size (grows by doubling).
    :param completions: greedy goal completions per round (0: none, the published algorithm): the
        ``completions`` cheapest children accepted in a round are each continued with the problem's
        ``goal_controls`` (a steering rule towards the goal) for up to ``completion_depth`` edges.
    :param completion_depth: most edges of one completion.
    :param refinements: extra completions per round around the best solution (0: none): each starts
        at a distinct active node of the best solution's path (uniform), flies one random control
        (``sample_controls``), then the steering rule -- a local search that perturbs the incumbent
        one edge at a time.
    """

    selection_radius: float = 1.0
    pruning_radius: float = 0.5
    batch_size: int = 256
    max_depth: int | None = None
    initial_capacity: int = 4096
    completions: int = 0
    completion_depth: int = 10
    refinements: int = 0

    def __post_init__(self) -> None:
        _positive("selection_radius", self.selection_radius)
        _positive("pruning_radius", self.pruning_radius)
        _int("batch_size", self.batch_size, 1)
        if self.max_depth is not None:
            _int("max_depth", self.max_depth, 1)
        _int("initial_capacity", self.initial_capacity, 16)
        _int("completions", self.completions, 0, 1 << 20)
        _int("completion_depth", self.completion_depth, 1, 1 << 20)
        _int("refinements", self.refinements, 0, 1 << 20)

    @property
    def depth_limit(self) -> int:
        """``max_depth`` as an int (a huge number when unlimited)."""
        return (1 << 62) if self.max_depth is None else int(self.max_depth)


@dataclass
class SSTStats:
    """Planner statistics (times are wall-clock seconds of planning, cumulative over ``run`` calls).

    ``cost_history`` is the anytime record: one ``(time [s], iteration, best cost)`` per improvement
    of the best solution; with batching, times are those of the end of the round that found it.
    ``seed_edges`` counts the edges flown by searches outside SST whose solutions were offered to
    the tree (:meth:`SST.insert_path`; included in ``iterations``, their time in ``elapsed``).
    ``best_duration`` is the summed edge duration of the best solution (for the soaring problem:
    its flight time [s]); ``total`` counts the nodes in the tree (active + inactive + solution).
    """

    iterations: int = 0
    elapsed: float = 0.0
    active: int = 0
    inactive: int = 0
    witnesses: int = 0
    accepted: int = 0
    dominated: int = 0
    invalid: int = 0
    stale: int = 0
    goal_edges: int = 0
    removed: int = 0
    deactivated: int = 0
    fallbacks: int = 0
    too_deep: int = 0
    bounded: int = 0
    completion_edges: int = 0
    seed_edges: int = 0
    best_cost: float = math.inf
    best_duration: float = math.nan
    time_to_first_solution: float | None = None
    iterations_to_first_solution: int | None = None
    cost_history: list[tuple[float, int, float]] = field(default_factory=list)
    batch_size: int = 1

    @property
    def total(self) -> int:
        """Nodes in the tree: active + inactive (+ the solution node, if any)."""
        return self.active + self.inactive + (1 if math.isfinite(self.best_cost) else 0)

    @property
    def iterations_per_second(self) -> float:
        return self.iterations / self.elapsed if self.elapsed > 0 else 0.0

    def cost_at(self, t: float) -> float:
        """Best cost known after ``t`` seconds of planning (inf if none yet)."""
        c = math.inf
        for tt, _, cc in self.cost_history:
            if tt <= t:
                c = cc
        return c

    def to_dict(self) -> dict[str, Any]:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["total"] = self.total
        d["iterations_per_second"] = self.iterations_per_second
        d["cost_history"] = [list(x) for x in self.cost_history]
        if not math.isfinite(self.best_cost):
            d["best_cost"] = None
            d["best_duration"] = None
        return d


@dataclass(frozen=True)
class SSTResult:
    """The outcome of a planning run: the best solution (if any) and the statistics.

    :param solved: whether a goal edge was found.
    :param cost: cost of the best solution (inf if none).
    :param states: states along the solution, root first (n + 1, dim); empty if none.
    :param controls: the controls of its n edges (n, control_dim).
    :param edge_costs: the cost of each edge (n,).
    :param durations: the duration of each edge (n,).
    :param stats: statistics at the end of the run.
    """

    solved: bool
    cost: float
    states: np.ndarray
    controls: np.ndarray
    edge_costs: np.ndarray
    durations: np.ndarray
    stats: SSTStats

    @property
    def duration(self) -> float:
        """Total duration of the solution (sum of edge durations; NaN if unsolved)."""
        return float(self.durations.sum()) if self.solved else math.nan


class SST:
    """Batched Stable Sparse RRT over flat arrays with numba kernels (see the module docstring).

    :param problem: the planning problem.
    :param params: radii and batch size.
    :param seed: seed of the planner's own ``np.random.Generator`` (same seed -> same tree).
    """

    def __init__(self, problem: Problem, params: SSTParams | None = None, seed: int | None = 0) -> None:
        if not isinstance(problem, Problem):
            raise SSTError(f"problem={problem!r} does not implement the Problem protocol")
        self.problem = problem
        self.params = params or SSTParams()
        self.seed = check_seed("seed", seed)
        self.rng = np.random.default_rng(seed)
        sp = problem.space
        self.space = sp
        self._dim = sp.dim
        self._cdim = _int("problem.control_dim", problem.control_dim, 1)
        self._xdims = np.asarray(sp.dims, np.int64)
        self._wdims = np.arange(len(sp.dims), dtype=np.int64)
        self._scale = np.asarray(sp.scales, np.float64)
        self._period = np.asarray(sp.periods, np.float64)
        gax = list(sp.grid_axes)
        self._gax = np.asarray(gax + [-1] * (3 - len(gax)), np.int64)
        self._a_grid = self._make_grid(self.params.selection_radius)
        self._w_grid = self._make_grid(self.params.pruning_radius)
        self._r2 = self.params.selection_radius**2
        self._ws2 = self.params.pruning_radius**2
        self._cnt = np.zeros(K.N_COUNTERS, np.int64)
        self._best_cost = np.array([np.inf])
        self._a: dict[str, np.ndarray] = {}
        self._w: dict[str, np.ndarray] = {}
        self._alloc_nodes(self.params.initial_capacity)
        self._alloc_witnesses(self.params.initial_capacity)
        self._a["head"] = np.full(int(np.prod(self._a_grid[2])), -1, np.int64)
        self._w["head"] = np.full(int(np.prod(self._w_grid[2])), -1, np.int64)
        self.stats = SSTStats(batch_size=self.params.batch_size)
        self._accepted = np.full(self.params.batch_size, -1, np.int64)  # node ids of the last insert
        self._init_root()

    # --- set-up -----------------------------------------------------------------------------
    def _make_grid(self, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        g0 = np.zeros(3)
        span = np.zeros(3)
        for t, k in enumerate(self._gax):
            if k >= 0:
                lo, hi = self.space.low[k] * self._scale[k], self.space.high[k] * self._scale[k]
                g0[t] = min(lo, hi)
                span[t] = abs(hi - lo)
        cs = np.full(3, radius * (1.0 + 1e-9))
        while True:
            gn = np.maximum(1, np.ceil(span / cs).astype(np.int64))
            gn[self._gax < 0] = 1
            if np.prod(gn.astype(np.float64)) <= MAX_GRID_CELLS:
                return g0, cs, gn
            cs = cs * 1.25

    def _alloc_nodes(self, cap: int) -> None:
        old = self._a
        n = len(old["cost"]) if old else 0
        new = {
            "X": np.zeros((cap, self._dim)),
            "U": np.zeros((cap, self._cdim)),
            "cost": np.full(cap, np.inf),
            "tcome": np.zeros(cap),
            "ecost": np.zeros(cap),
            "parent": np.full(cap, -1, np.int64),
            "nchild": np.zeros(cap, np.int64),
            "status": np.zeros(cap, np.int8),
            "depth": np.zeros(cap, np.int64),
            "nxt": np.full(cap, -1, np.int64),
            "prv": np.full(cap, -1, np.int64),
            "cell": np.full(cap, -1, np.int64),
            "free": np.zeros(cap, np.int64),
            "pend": np.zeros(cap, np.int64),
        }
        for key, arr in new.items():
            if n:
                arr[:n] = old[key][:n]
            old[key] = arr

    def _alloc_witnesses(self, cap: int) -> None:
        old = self._w
        n = len(old["rep"]) if old else 0
        new = {
            "W": np.zeros((cap, len(self.space.dims))),
            "rep": np.full(cap, -1, np.int64),
            "wnext": np.full(cap, -1, np.int64),
        }
        for key, arr in new.items():
            if n:
                arr[:n] = old[key][:n]
            old[key] = arr

    def _init_root(self) -> None:
        root = np.asarray(self.problem.root_state(), np.float64)
        if root.shape != (self._dim,) or not np.all(np.isfinite(root[self._xdims])):
            raise SSTError(f"root_state() returned {root!r}; expected {self._dim} floats, finite in the metric dims")
        a, w = self._a, self._w
        a["X"][0] = root
        a["cost"][0] = 0.0
        a["status"][0] = K.ACTIVE
        g0, cs, gn = self._a_grid
        K.grid_add(
            0,
            a["X"],
            a["cost"],
            self._xdims,
            self._gax,
            self._scale,
            g0,
            cs,
            gn,
            a["head"],
            a["nxt"],
            a["prv"],
            a["cell"],
        )
        w["W"][0] = root[self._xdims]
        w["rep"][0] = 0
        g0, cs, gn = self._w_grid
        w["head"][K.cell_of(w["W"], 0, self._wdims, self._gax, self._scale, g0, cs, gn)] = 0
        self._cnt[K.C_USED] = 1
        self._cnt[K.C_ACT] = 1
        self._cnt[K.C_WIT] = 1
        self._cnt[K.C_BEST] = -1
        self._sync_stats()

    # --- the main loop ------------------------------------------------------------------------
    def run(
        self,
        time_limit: float | None = None,
        max_iterations: int | None = None,
        *,
        callback: Callable[[SSTStats], None] | None = None,
    ) -> SSTResult:
        """Grow the tree until the wall-clock budget [s] or the iteration budget is spent (whichever
        comes first; calling ``run`` again continues). Never raises for "no solution found".

        :param time_limit: wall-clock budget of this call [s] (checked after every round).
        :param max_iterations: iteration budget of this call (exact).
        :param callback: called with the statistics after every round.
        """
        t_lim, n_lim = check_budget(time_limit, max_iterations)
        kk = self.params.batch_size
        t_start = time.perf_counter()
        base_elapsed = self.stats.elapsed
        done = 0
        imp_k = np.zeros(kk, np.int64)
        a = self._a  # (the dict is grown in place)
        if self.stats.iterations == 0 and self.params.completions:
            self._accepted[:] = -1
            self._accepted[0] = 0  # the first completion starts at the root
            n_imp = self._complete()
            self.stats.elapsed = base_elapsed + (time.perf_counter() - t_start)
            if n_imp:
                self._record_improvement()
            self._sync_stats()
        while True:
            n = kk if n_lim is None else min(kk, n_lim - done)
            if n <= 0:
                break
            self._grow(n)
            q = self._targets(n)
            sel = np.empty(n, np.int64)
            g0, cs, gn = self._a_grid
            self._cnt[K.C_FALLBACK] += K.select_batch(
                q,
                a["X"],
                a["cost"],
                self._xdims,
                self._wdims,
                self._scale,
                self._period,
                self._gax,
                g0,
                cs,
                gn,
                a["head"],
                a["nxt"],
                self._r2,
                sel,
            )
            u = np.asarray(self.problem.sample_controls(self.rng, n), np.float64).reshape(n, self._cdim)
            e = self.problem.propagate(a["X"][sel], u)
            n_imp = self._insert(sel, e, u, imp_k)
            done += n
            self.stats.iterations += n
            if self.params.completions or self.params.refinements:
                n_imp += self._complete()
            now = time.perf_counter()
            self.stats.elapsed = base_elapsed + (now - t_start)
            if n_imp:
                self._record_improvement()
            self._sync_stats()
            if callback is not None:
                callback(self.stats)
            if t_lim is not None and now - t_start >= t_lim:
                break
        return self.result()

    def insert_path(self, controls: np.ndarray, *, seconds: float = 0.0, edges: int = 0) -> bool:
        """Insert a solution found elsewhere (e.g. by another search): the path that flies
        ``controls`` (n, control_dim) from the root.

        It is re-flown with the problem's ``propagate`` and inserted like a goal completion (the
        ``chain`` mode of ``insert_batch``: edges its witnesses dominate become inactive ancestors)
        if it reaches the goal within the depth limit, every edge valid, at a cost below the best
        solution's; otherwise the tree is left as it is. Only nodes are added, so SST's guarantees
        are kept. ``seconds`` and ``edges`` -- what finding the path took -- are added to the
        statistics (``elapsed``, ``iterations``, ``seed_edges``) so that the anytime record counts
        them, and an improvement is recorded at the new elapsed time.

        :returns: whether the path became the best solution.
        """
        try:
            u = np.asarray(controls, np.float64).reshape(-1, self._cdim)
        except (TypeError, ValueError) as exc:
            raise SSTError(f"controls must be rows of {self._cdim} numbers ({exc})") from None
        if not np.all(np.isfinite(u)):
            raise SSTError(f"controls={controls!r} must be finite numbers")
        self.stats.elapsed += _positive("seconds", seconds) if seconds else 0.0
        self.stats.iterations += _int("edges", edges, 0)
        self.stats.seed_edges += edges
        n = len(u)
        if n == 0 or n > self.params.depth_limit:
            return False
        a = self._a
        root = 0  # the root's slot never changes: it always has descendants or is active
        x = a["X"][root][None, :].copy()
        rows: list[Edges] = []
        cost = 0.0
        for k in range(n):
            e = self.problem.propagate(x, u[k : k + 1])
            want = K.EDGE_GOAL if k == n - 1 else K.EDGE_VALID
            if int(e.outcome[0]) != want:
                return False
            rows.append(e)
            cost = cost + float(e.cost[0])  # summed as the kernel sums costs to come
            x = np.asarray(e.states, np.float64)
        if not cost < self._best_cost[0] or a["status"][root] not in (K.ACTIVE, K.INACTIVE):
            return False
        self._grow(n)
        e = Edges(
            states=np.concatenate([r.states for r in rows]),
            cost=np.concatenate([r.cost for r in rows]),
            duration=np.concatenate([r.duration for r in rows]),
            outcome=np.concatenate([r.outcome for r in rows]),
        )
        n_imp = self._insert(np.zeros(n, np.int64), e, u, np.zeros(n, np.int64), chain=True)
        if n_imp:
            self._record_improvement()
        self._sync_stats()
        return bool(n_imp)

    def _targets(self, n: int) -> np.ndarray:
        """n selection targets: the problem's own ``sample_targets`` if it has one, else uniform."""
        f = getattr(self.problem, "sample_targets", None)
        if f is None:
            return self.space.sample(self.rng, n)
        q = np.asarray(f(self.rng, n), np.float64)
        if q.shape != (n, len(self.space.dims)) or not np.all(np.isfinite(q)):
            raise SSTError(
                f"sample_targets returned shape {q.shape} or non-finite values; expected ({n}, {len(self.space.dims)})"
            )
        return q

    def _complete(self) -> int:
        """Greedy goal completions from the cheapest children accepted in the last round.

        Each is flown on with ``problem.goal_controls`` (a steering rule) for up to
        ``completion_depth`` edges, all completions in lockstep, until it reaches the goal, turns
        invalid or hits the depth limit. Its edges are then inserted under the usual rules (witness
        dominance, the depth limit, the cost bound) until one is rejected -- so the random
        expansions can build on them. If the cheapest completion that reached the goal beats the
        best solution but was cut off by a dominated edge, its remaining edges are inserted as a
        path to the new solution, the dominated ones as inactive nodes (``chain`` mode of
        ``insert_batch``). Extra nodes only: the random expansions go on unchanged, so SST's
        guarantees are kept. Returns how many insertions improved the best solution.
        """
        steer = getattr(self.problem, "goal_controls", None)
        if steer is None:
            return 0
        a = self._a
        ids = self._accepted[self._accepted >= 0]
        if len(ids) == 0:
            return 0
        ids = ids[np.argsort(a["cost"][ids], kind="stable")[: self.params.completions]]
        ids = ids[a["status"][ids] == K.ACTIVE]
        n_ref = 0
        if self.params.refinements and self.best_node >= 0:
            # distinct start nodes: two chains from one parent could collide in one insert call
            path = np.asarray(self.path_to(self.best_node)[:-1], np.int64)
            path = path[(a["status"][path] == K.ACTIVE) & ~np.isin(path, ids)]
            if len(path):
                n_ref = min(self.params.refinements, len(path))
                ids = np.concatenate([ids, self.rng.choice(path, size=n_ref, replace=False)])
        m, depth = len(ids), self.params.completion_depth
        if m == 0:
            return 0
        # 1. fly the completions (no tree changes)
        xs = np.zeros((m, depth, self._dim))
        us = np.zeros((m, depth, self._cdim))
        ec = np.zeros((m, depth))
        du = np.zeros((m, depth))
        oc = np.full((m, depth), K.EDGE_INVALID, np.int64)
        tg = np.full((m, depth), -np.inf)
        length = np.zeros(m, np.int64)
        x = a["X"][ids].copy()
        x0 = x.copy()
        live = np.arange(m)
        d0 = a["depth"][ids]
        for d in range(depth):
            u = np.asarray(steer(x), np.float64).reshape(len(live), self._cdim)
            if d == 0 and n_ref:  # the refinements leave the incumbent's path on a random control
                u[m - n_ref :] = np.asarray(self.problem.sample_controls(self.rng, n_ref), np.float64).reshape(
                    n_ref, self._cdim
                )
            e = self.problem.propagate(x, u)
            self.stats.iterations += len(live)
            self.stats.completion_edges += len(live)
            xs[live, d], us[live, d], ec[live, d] = e.states, u, e.cost
            du[live, d], oc[live, d], tg[live, d] = e.duration, e.outcome, _togo(e)
            length[live] = d + 1
            go = (e.outcome == K.EDGE_VALID) & (d0[live] + d + 1 < self.params.depth_limit)
            live, x = live[go], np.asarray(e.states)[go]
            if len(live) == 0:
                break
        # 2. insert them under the usual rules, in lockstep, each until its first rejected edge
        n_imp = 0
        nodes = np.full((m, depth), -1, np.int64)
        cur = ids.copy()
        alive = np.ones(m, bool)
        for d in range(depth):
            # a parent freed by the previous call is no longer a node (its slot may be reused in
            # this call): only chains whose parent is still active go on
            alive &= a["status"][cur] == K.ACTIVE
            rows = np.flatnonzero(alive & (length > d))
            if len(rows) == 0:
                break
            self._grow(len(rows))
            e = Edges(xs[rows, d], ec[rows, d], du[rows, d], oc[rows, d], tg[rows, d])
            n_imp += self._insert(cur[rows], e, us[rows, d], np.zeros(len(rows), np.int64))
            got = self._accepted[: len(rows)].copy()
            nodes[rows, d] = got
            cur[rows] = got
            alive[rows] = got >= 0
        # 3. the cheapest completion that reached the goal, if it beats the best solution still
        last = length - 1
        reached = oc[np.arange(m), last] == K.EDGE_GOAL
        if reached.any():
            # costs to come summed edge by edge, in the kernel's order: a completion that re-flies
            # the incumbent (a refinement whose random control is the incumbent's) must not look
            # cheaper by rounding -- its chain would end in a rejected goal edge
            edge = np.where(np.arange(depth)[None, :] < length[:, None], ec, 0.0)
            seq = np.cumsum(np.concatenate([a["cost"][ids][:, None], edge], axis=1), axis=1)
            total = seq[:, -1]
            c = int(np.flatnonzero(reached)[np.argmin(total[reached])])
            if total[c] < self._best_cost[0]:
                # start after the deepest edge of it that is still in the tree
                # (still the same node: a freed slot may hold another one by now)
                come = seq[c, 1:]
                start, parent = 0, int(ids[c])
                if a["status"][parent] not in (K.ACTIVE, K.INACTIVE) or not np.array_equal(
                    a["X"][parent], x0[c], equal_nan=True
                ):
                    return n_imp
                for d in range(int(length[c]) - 1, -1, -1):
                    q = int(nodes[c, d])
                    if (
                        q >= 0
                        and a["status"][q] in (K.ACTIVE, K.INACTIVE)
                        and a["cost"][q] == come[d]
                        and np.array_equal(a["X"][q], xs[c, d], equal_nan=True)
                    ):
                        start, parent = d + 1, q
                        break
                k = slice(start, int(length[c]))
                n = int(length[c]) - start
                self._grow(n)
                e = Edges(states=xs[c, k], cost=ec[c, k], duration=du[c, k], outcome=oc[c, k])
                sel = np.full(n, parent, np.int64)
                n_imp += self._insert(sel, e, us[c, k], np.zeros(n, np.int64), chain=True)
        return n_imp

    def _grow(self, n: int) -> None:
        """Make room for n more nodes and witnesses."""
        if self._cnt[K.C_USED] + n + 1 > len(self._a["cost"]):
            self._alloc_nodes(2 * len(self._a["cost"]) + n)
        if self._cnt[K.C_WIT] + n + 1 > len(self._w["rep"]):
            self._alloc_witnesses(2 * len(self._w["rep"]) + n)

    def _insert(self, sel: np.ndarray, e: Edges, u: np.ndarray, imp_k: np.ndarray, chain: bool = False) -> int:
        a, w = self._a, self._w
        if len(self._accepted) < len(sel):
            self._accepted = np.empty(max(len(sel), self.params.batch_size), np.int64)
        self._accepted[len(sel) :] = -1
        ag0, acs, agn = self._a_grid
        wg0, wcs, wgn = self._w_grid
        return int(
            K.insert_batch(
                sel,
                np.ascontiguousarray(e.states, dtype=np.float64),
                u,
                np.ascontiguousarray(e.cost, dtype=np.float64),
                np.ascontiguousarray(e.duration, dtype=np.float64),
                np.ascontiguousarray(e.outcome, dtype=np.int64),
                _togo(e),
                a["X"],
                a["U"],
                a["cost"],
                a["tcome"],
                a["ecost"],
                a["parent"],
                a["nchild"],
                a["status"],
                a["depth"],
                a["head"],
                a["nxt"],
                a["prv"],
                a["cell"],
                w["W"],
                w["rep"],
                w["head"],
                w["wnext"],
                self._xdims,
                self._wdims,
                self._scale,
                self._period,
                self._gax,
                ag0,
                acs,
                agn,
                wg0,
                wcs,
                wgn,
                self._ws2,
                self.params.depth_limit,
                self._cnt,
                a["free"],
                a["pend"],
                self._best_cost,
                imp_k,
                self._accepted,
                chain,
            )
        )

    def _record_improvement(self) -> None:
        s = self.stats
        c = float(self._best_cost[0])
        if s.time_to_first_solution is None:
            s.time_to_first_solution = s.elapsed
            s.iterations_to_first_solution = s.iterations
        s.cost_history.append((s.elapsed, s.iterations, c))

    def _sync_stats(self) -> None:
        c, s = self._cnt, self.stats
        s.active = int(c[K.C_ACT])
        s.inactive = int(c[K.C_INACT])
        s.witnesses = int(c[K.C_WIT])
        s.accepted = int(c[K.C_ACCEPT])
        s.dominated = int(c[K.C_DOMINATED])
        s.invalid = int(c[K.C_INVALID])
        s.stale = int(c[K.C_STALE])
        s.goal_edges = int(c[K.C_GOAL_EDGES])
        s.removed = int(c[K.C_REMOVED])
        s.deactivated = int(c[K.C_DEACT])
        s.fallbacks = int(c[K.C_FALLBACK])
        s.too_deep = int(c[K.C_TOO_DEEP])
        s.bounded = int(c[K.C_BOUNDED])
        s.best_cost = float(self._best_cost[0])
        best = int(c[K.C_BEST])
        s.best_duration = float(self._a["tcome"][best]) if best >= 0 else math.nan

    # --- results and inspection ----------------------------------------------------------------
    @property
    def best_node(self) -> int:
        """Id of the best solution node (-1 if none)."""
        return int(self._cnt[K.C_BEST])

    def path_to(self, node: int) -> list[int]:
        """Node ids from the root to ``node``."""
        a = self._a
        if not 0 <= node < self._cnt[K.C_USED] or a["status"][node] == K.FREE:
            raise SSTError(f"node={node!r} is not in the tree")
        path = [node]
        while a["parent"][path[-1]] >= 0:
            path.append(int(a["parent"][path[-1]]))
        return path[::-1]

    def result_for(self, node: int) -> SSTResult:
        """An :class:`SSTResult` for the path to any tree node (``solved`` only for the best
        solution node)."""
        ids = np.asarray(self.path_to(node), np.int64)
        a = self._a
        solved = node == self.best_node
        return SSTResult(
            solved=solved,
            cost=float(a["cost"][node]),
            states=a["X"][ids].copy(),
            controls=a["U"][ids[1:]].copy(),
            edge_costs=a["ecost"][ids[1:]].copy(),
            durations=a["tcome"][ids[1:]] - a["tcome"][ids[:-1]],
            stats=self.stats,
        )

    def result(self) -> SSTResult:
        """The best solution so far (``solved=False`` with empty arrays if there is none)."""
        if self.best_node >= 0:
            return self.result_for(self.best_node)
        return SSTResult(
            solved=False,
            cost=math.inf,
            states=np.zeros((0, self._dim)),
            controls=np.zeros((0, self._cdim)),
            edge_costs=np.zeros(0),
            durations=np.zeros(0),
            stats=self.stats,
        )

    def tree(self) -> TreeView:
        """A copy of the live tree (every node not yet removed) for inspection and plots."""
        a = self._a
        used = int(self._cnt[K.C_USED])
        st = a["status"][:used]
        ids = np.flatnonzero(st != K.FREE)
        nw = int(self._cnt[K.C_WIT])
        return TreeView(
            ids=ids,
            states=a["X"][ids].copy(),
            cost=a["cost"][ids].copy(),
            parent=a["parent"][ids].copy(),
            status=st[ids].copy(),
            nchild=a["nchild"][ids].copy(),
            controls=a["U"][ids].copy(),
            tcome=a["tcome"][ids].copy(),
            witnesses=self._w["W"][:nw].copy(),
            witness_rep=self._w["rep"][:nw].copy(),
        )


def _togo(e: Edges) -> np.ndarray:
    """The edges' cost-to-go bounds as a float64 array (``-inf`` where the problem gives none)."""
    n = len(e.cost)
    if e.togo is None:
        return np.full(n, -np.inf)
    t = np.ascontiguousarray(e.togo, dtype=np.float64)
    if t.shape != (n,) or np.any(np.isnan(t)):
        raise SSTError(f"Edges.togo has shape {t.shape} or NaN; expected ({n},) numbers (-inf: no bound)")
    return t


@dataclass(frozen=True)
class TreeView:
    """Snapshot of an SST tree. ``status``: 1 active, 2 inactive, 3 solution (terminal);
    ``tcome``: summed edge durations from the root; ``controls``: of the edge into each node."""

    ids: np.ndarray
    states: np.ndarray
    cost: np.ndarray
    parent: np.ndarray
    status: np.ndarray
    nchild: np.ndarray
    controls: np.ndarray
    tcome: np.ndarray
    witnesses: np.ndarray
    witness_rep: np.ndarray

    ACTIVE = K.ACTIVE
    INACTIVE = K.INACTIVE
    SOLUTION = K.SOLUTION

    def canonical(self) -> tuple[Sequence[Any], ...]:
        """A representation independent of slot ids, for comparing two trees: the sorted list
        of (state, cost, status, parent state) tuples and the sorted witnesses."""
        pos = {int(i): k for k, i in enumerate(self.ids)}
        rows = []
        for k in range(len(self.ids)):
            p = int(self.parent[k])
            ps = tuple(self.states[pos[p]].tolist()) if p >= 0 else ()
            rows.append((tuple(self.states[k].tolist()), float(self.cost[k]), int(self.status[k]), ps))
        wit = sorted(tuple(r) for r in self.witnesses.tolist())
        return sorted(rows, key=repr), wit
