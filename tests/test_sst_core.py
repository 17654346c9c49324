"""The generic SST core on toy problems (no aircraft): pruning, sparsity, determinism, negative
costs, budgets, bad input, and agreement of the batched core (K = 1) with the plain reference."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from baselines.sst import SST, Edges, ReferenceSST, SSTError, SSTParams, StateSpace
from baselines.sst.core import EDGE_GOAL, EDGE_INVALID, EDGE_VALID, TreeView


@dataclass(frozen=True)
class ScriptedSpace(StateSpace):
    """A state space whose selection targets are scripted (pops ``points`` in order)."""

    points: list[float] = field(default_factory=list)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return np.array([[self.points.pop(0)] for _ in range(n)])


class ScriptedLine:
    """1-D problem with scripted selection targets and controls: control (x, c) moves to x at cost c."""

    control_dim = 2

    def __init__(self, script: list[tuple[float, float, float]]) -> None:
        self.space = ScriptedSpace(
            dim=1, dims=(0,), scales=(1.0,), periods=(0.0,), low=(-10.0,), high=(10.0,), points=[r[0] for r in script]
        )
        self.script = [r[1:] for r in script]
        self.i = 0

    def root_state(self) -> np.ndarray:
        return np.zeros(1)

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        rows = self.script[self.i : self.i + n]
        self.i += n
        return np.asarray(rows, dtype=np.float64)

    def propagate(self, states: np.ndarray, controls: np.ndarray) -> Edges:
        x = controls[:, :1].copy()
        outcome = np.where(x[:, 0] >= 9.0, EDGE_GOAL, np.where(x[:, 0] < 0, EDGE_INVALID, EDGE_VALID))
        return Edges(states=x, cost=controls[:, 1].copy(), duration=np.ones(len(x)), outcome=outcome)


class Car:
    """A unicycle in a 10 x 10 box: state [x, y, theta]; control [-1, 1]^2 -> speed, turn rate.

    Edge cost = length, times -1 inside a "thermal" disk (negative costs); goal: a disk at (8, 8).
    """

    control_dim = 2

    def __init__(self, goal: tuple[float, float, float] = (8.0, 8.0, 0.7)) -> None:
        self.space = StateSpace(
            dim=3,
            dims=(0, 1, 2),
            scales=(1.0, 1.0, 0.3),
            periods=(0.0, 0.0, 2 * math.pi),
            low=(0.0, 0.0, -math.pi),
            high=(10.0, 10.0, math.pi),
        )
        self.goal = goal

    def root_state(self) -> np.ndarray:
        return np.array([1.0, 1.0, 0.0])

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, size=(n, 2))

    def propagate(self, states: np.ndarray, controls: np.ndarray) -> Edges:
        v = 0.75 + 0.25 * controls[:, 0]
        w = controls[:, 1]
        th = states[:, 2] + w
        x = states[:, 0] + v * np.cos(th)
        y = states[:, 1] + v * np.sin(th)
        th = (th + math.pi) % (2 * math.pi) - math.pi
        lift = (x - 5.0) ** 2 + (y - 3.0) ** 2 < 1.5**2
        cost = np.where(lift, -v, v)
        gx, gy, gr = self.goal
        goal = (x - gx) ** 2 + (y - gy) ** 2 <= gr**2
        inside = (x >= 0) & (x <= 10) & (y >= 0) & (y <= 10)
        outcome = np.where(~inside, EDGE_INVALID, np.where(goal, EDGE_GOAL, EDGE_VALID))
        return Edges(states=np.stack([x, y, th], axis=1), cost=cost, duration=np.ones(len(x)), outcome=outcome)


def check_tree_invariants(tree: TreeView, problem: Any, params: SSTParams) -> None:
    """Everything the SST paper promises about the tree's structure, and that every node is what
    its parent's state and its control give (same state, cost-to-come = parent's + edge cost)."""
    space = problem.space
    pos = {int(i): k for k, i in enumerate(tree.ids)}
    kids = np.flatnonzero(tree.parent >= 0)
    par = np.array([pos[int(p)] for p in tree.parent[kids]], dtype=np.int64)
    e = problem.propagate(tree.states[par], tree.controls[kids])
    np.testing.assert_array_equal(e.states, tree.states[kids])
    np.testing.assert_array_equal(tree.cost[par] + e.cost, tree.cost[kids])
    assert np.all((e.outcome == EDGE_GOAL) == (tree.status[kids] == TreeView.SOLUTION))
    # every parent is in the tree and child counts are right
    counts = np.zeros(len(tree.ids), np.int64)
    for p in tree.parent:
        if p >= 0:
            assert int(p) in pos, "a node's parent was removed"
            counts[pos[int(p)]] += 1
    assert np.array_equal(counts, tree.nchild)
    # inactive leaves are removed
    inactive = tree.status == TreeView.INACTIVE
    assert np.all(tree.nchild[inactive] > 0), "an inactive leaf survived pruning"
    # every witness has exactly one representative, it is active, and active nodes are exactly the reps
    reps = tree.witness_rep
    assert np.all(reps >= 0)
    assert len(set(reps.tolist())) == len(reps)
    active_ids = set(tree.ids[tree.status == TreeView.ACTIVE].tolist())
    assert active_ids == set(reps.tolist())
    # representatives lie within delta_s of their witness; witnesses are more than delta_s apart
    for w, r in zip(tree.witnesses, reps, strict=True):
        x = tree.states[pos[int(r)]]
        full = np.zeros(space.dim)
        full[list(space.dims)] = w
        assert space.distance(x, full) <= params.pruning_radius + 1e-9
    wfull = np.zeros((len(tree.witnesses), space.dim))
    wfull[:, list(space.dims)] = tree.witnesses
    d = space.distance(wfull[:, None, :], wfull[None, :, :])
    np.fill_diagonal(d, np.inf)
    assert d.min() > params.pruning_radius


def test_scripted_pruning_displaces_and_removes_recursively() -> None:
    # (selection target, new x, edge cost); delta_BN = 0.3 selects the node at the target
    script = [
        (0.0, 1.0, 5.0),  # 1: root -> A (x=1, cost 5)
        (0.0, 2.0, -10.0),  # 2: root -> B (x=2, cost -10)
        (2.0, 3.0, -1.0),  # 3: B -> C (x=3, cost -11)
        (1.0, 2.1, -20.0),  # 4: A -> D (x=2.1, cost -15) displaces B, which has a child: inactive
        (0.0, 3.05, -12.0),  # 5: root -> E (x=3.05, cost -12) displaces C: removed, then B too
        (1.0, 1.05, -1.0),  # 6: A -> F (x=1.05, cost 4) displaces A, which has a child: inactive
        (2.1, 9.5, 100.0),  # 7: D -> goal, cost 85: the first solution
        (3.05, 9.6, 50.0),  # 8: E -> goal, cost 38: replaces it (the old goal node is removed)
        (1.05, 1.1, 0.0),  # 9: F -> x=1.1, cost 4: not cheaper than F at that witness: rejected
        (0.0, -1.0, 0.0),  # 10: invalid edge
    ]
    params = SSTParams(selection_radius=0.3, pruning_radius=0.5, batch_size=1)
    active, inactive = 1, 2
    for cls in (SST, ReferenceSST):
        prob = ScriptedLine(script)
        sst = cls(prob, params, seed=0)

        def nodes(sst: SST | ReferenceSST = sst) -> dict[float, int]:
            t = sst.tree()
            return {round(float(x[0]), 3): int(st) for x, st in zip(t.states, t.status, strict=True)}

        sst.run(max_iterations=4)
        assert nodes() == {0.0: active, 1.0: active, 2.0: inactive, 3.0: active, 2.1: active}, cls
        sst.run(max_iterations=1)
        assert nodes() == {0.0: active, 1.0: active, 2.1: active, 3.05: active}, cls  # C and B removed
        sst.run(max_iterations=1)
        assert nodes() == {0.0: active, 1.0: inactive, 2.1: active, 3.05: active, 1.05: active}, cls
        res = sst.run(max_iterations=4)
        assert res.solved and res.cost == 38.0
        np.testing.assert_array_equal(res.states[:, 0], [0.0, 3.05, 9.6])
        np.testing.assert_array_equal(res.edge_costs, [-12.0, 50.0])
        s = sst.stats
        assert (s.iterations, s.dominated, s.invalid, s.goal_edges, s.deactivated, s.removed) == (10, 1, 1, 2, 3, 3)
        assert s.active == s.witnesses == 4 and s.inactive == 1 and s.total == 6
        assert s.best_duration == res.duration == 2.0
        assert [c[1:] for c in s.cost_history] == [(7, 85.0), (8, 38.0)]
        check_tree_invariants(sst.tree(), prob, params)


@pytest.mark.parametrize("batch_size", [1, 64])
def test_tree_stays_sparse(batch_size: int) -> None:
    prob = Car()
    params = SSTParams(selection_radius=0.6, pruning_radius=0.3, batch_size=batch_size)
    sst = SST(prob, params, seed=3)
    sst.run(max_iterations=10_000)
    s = sst.stats
    w1 = s.witnesses
    # active nodes are exactly the witnesses' representatives; displaced nodes went inactive and
    # the inactive leaves were removed, so the tree holds far fewer nodes than were ever accepted
    assert s.active == s.witnesses
    assert s.deactivated > 100 and s.removed > 100 and s.inactive > 0
    assert s.total < 0.6 * s.accepted
    check_tree_invariants(sst.tree(), prob, params)
    # witnesses are > delta_s apart in a bounded space: their number saturates as the run goes on
    sst.run(max_iterations=10_000)
    s = sst.stats
    assert s.witnesses - w1 < 0.5 * w1
    assert s.total < 0.5 * s.accepted
    check_tree_invariants(sst.tree(), prob, params)


def test_batched_core_with_k1_equals_reference() -> None:
    params = SSTParams(selection_radius=0.6, pruning_radius=0.3, batch_size=1)
    a = SST(Car(), params, seed=11)
    b = ReferenceSST(Car(), params, seed=11)
    ra = a.run(max_iterations=3000)
    rb = b.run(max_iterations=3000)
    ta, tb = a.tree(), b.tree()
    assert np.array_equal(ta.ids, tb.ids)
    assert np.array_equal(ta.states, tb.states)
    assert np.array_equal(ta.cost, tb.cost)
    assert np.array_equal(ta.parent, tb.parent)
    assert np.array_equal(ta.status, tb.status)
    assert np.array_equal(ta.witnesses, tb.witnesses)
    assert ra.solved == rb.solved and ra.cost == rb.cost
    for f in ("iterations", "active", "inactive", "witnesses", "dominated", "invalid", "removed", "fallbacks"):
        assert getattr(a.stats, f) == getattr(b.stats, f), f


@pytest.mark.parametrize("batch_size", [1, 100])
def test_same_seed_same_tree(batch_size: int) -> None:
    params = SSTParams(selection_radius=0.6, pruning_radius=0.3, batch_size=batch_size)
    trees = []
    for seed in (5, 5, 6):
        sst = SST(Car(), params, seed=seed)
        sst.run(max_iterations=5000)
        trees.append(sst.tree().canonical())
    assert trees[0] == trees[1]
    assert trees[0] != trees[2]


def test_negative_costs_are_handled() -> None:
    prob = Car()
    sst = SST(prob, SSTParams(selection_radius=0.6, pruning_radius=0.3, batch_size=32), seed=0)
    res = sst.run(max_iterations=30_000)
    tree = sst.tree()
    assert (tree.cost < 0).any(), "the lift disk should give nodes a negative cost-to-come"
    assert res.solved
    # the path's cost is the sum of its edges (negative ones included), re-propagated from the root
    x = res.states[0:1]
    total = 0.0
    for u in res.controls:
        e = prob.propagate(x, u[None, :])
        total += float(e.cost[0])
        x = e.states
    np.testing.assert_array_equal(x[0], res.states[-1])
    assert total == pytest.approx(res.cost)
    assert np.sum(res.edge_costs < 0) > 0, "the best path should use the lift"
    # the anytime record only improves
    costs = [c for _, _, c in sst.stats.cost_history]
    assert costs == sorted(costs, reverse=True) and costs[-1] == res.cost


def test_budget_without_solution_is_a_result() -> None:
    prob = Car(goal=(9.9, 9.9, 0.01))
    sst = SST(prob, SSTParams(selection_radius=0.6, pruning_radius=0.3), seed=0)
    res = sst.run(max_iterations=300)
    assert not res.solved and math.isinf(res.cost) and len(res.controls) == 0
    assert res.stats.iterations == 300 and res.stats.time_to_first_solution is None
    assert res.stats.to_dict()["best_cost"] is None
    res = sst.run(time_limit=0.05)
    assert res.stats.iterations > 300 and res.stats.elapsed > 0.05


def test_iteration_budget_is_exact_and_time_budget_stops() -> None:
    sst = SST(Car(), SSTParams(selection_radius=0.6, pruning_radius=0.3, batch_size=64), seed=0)
    sst.run(max_iterations=1000)
    assert sst.stats.iterations == 1000
    sst.run(time_limit=0.2, max_iterations=10**9)
    assert 0.2 <= sst.stats.elapsed < 2.0


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"selection_radius": -1.0}, "selection_radius"),
        ({"pruning_radius": 0.0}, "pruning_radius"),
        ({"pruning_radius": math.nan}, "pruning_radius"),
        ({"batch_size": 0}, "batch_size"),
        ({"batch_size": 2.5}, "batch_size"),
    ],
)
def test_bad_params_name_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(SSTError, match=field):
        SSTParams(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"time_limit": -1.0}, "time_limit=-1.0 must be > 0"),
        ({"time_limit": 0.0}, "time_limit"),
        ({"max_iterations": 0}, "max_iterations=0 must be an integer >= 1"),
        ({"max_iterations": -5}, "max_iterations"),
        ({}, "time_limit=None and max_iterations=None"),
    ],
)
def test_bad_budget_names_the_field(kwargs: dict, match: str) -> None:
    sst = SST(Car(), SSTParams(), seed=0)
    with pytest.raises(SSTError, match=match):
        sst.run(**kwargs)


def test_bad_state_space() -> None:
    with pytest.raises(SSTError, match="scales"):
        StateSpace(dim=2, dims=(0, 1), scales=(1.0, -1.0), periods=(0.0, 0.0), low=(0, 0), high=(1, 1))
    with pytest.raises(SSTError, match="dims"):
        StateSpace(dim=2, dims=(0, 2), scales=(1.0, 1.0), periods=(0.0, 0.0), low=(0, 0), high=(1, 1))
    with pytest.raises(SSTError, match="high"):
        StateSpace(dim=1, dims=(0,), scales=(1.0,), periods=(0.0,), low=(1.0,), high=(0.0,))
    with pytest.raises(SSTError, match="Problem protocol"):
        SST(object(), SSTParams())  # type: ignore[arg-type]


def test_periodic_distance_wraps() -> None:
    sp = Car().space
    a = np.array([1.0, 1.0, math.pi - 0.1])
    b = np.array([1.0, 1.0, -math.pi + 0.1])
    assert sp.distance(a, b) == pytest.approx(0.3 * 0.2)


def test_depth_limit_matches_reference_and_bounds_paths() -> None:
    params = SSTParams(selection_radius=0.6, pruning_radius=0.3, batch_size=1, max_depth=16)
    a = SST(Car(), params, seed=4)
    b = ReferenceSST(Car(), params, seed=4)
    ra, rb = a.run(max_iterations=6000), b.run(max_iterations=6000)
    assert a.tree().canonical() == b.tree().canonical()
    assert a.stats.too_deep == b.stats.too_deep > 0
    assert ra.solved and len(ra.controls) <= 16 and ra.cost == rb.cost
    with pytest.raises(SSTError, match="max_depth=0"):
        SSTParams(max_depth=0)
