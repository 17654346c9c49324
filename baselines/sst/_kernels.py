"""Numba kernels of the fast SST core: uniform-grid nearest neighbours, batched best-near
selection and sequential insertion with witness dominance and recursive pruning.

Everything here works on flat arrays; :mod:`baselines.sst.core` owns them and documents the
algorithm. Node ids are slots in the node arrays; freed slots are reused last-in-first-out, so the
id sequence (and with it every tie-break "lowest id first") is a deterministic function of the seed.

The metric is a weighted Euclidean distance over the *metric dimensions* ``mdims`` of the state,
``d^2 = sum_j (scale_j * delta_j)^2``, where ``delta_j`` wraps on ``period_j`` when it is > 0
(e.g. a course angle). The grids index up to three non-periodic metric dimensions (``gax``, indices
into ``mdims``; -1 = unused axis): a point within distance r of a query differs from it by at most
r in every such scaled coordinate, so with cells at least r wide it lies in one of the 27 cells
around the query's cell. Coordinates outside the grid box are clipped into the border cells;
clipping is 1-Lipschitz, so that argument still holds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

import soaring_env._jit  # noqa: F401  (before any kernel: the package-wide numba cache key)

# Node status codes.
FREE, ACTIVE, INACTIVE, SOLUTION = 0, 1, 2, 3
# Edge outcomes reported by a propagator.
EDGE_VALID, EDGE_GOAL, EDGE_INVALID = 0, 1, 2

# Slots of the int64 counter array ``cnt``.
C_USED = 0  # high-water mark of node slots
C_FREE = 1  # size of the free-slot stack
C_ACT = 2  # active nodes
C_WIT = 3  # witnesses
C_BEST = 4  # id of the best solution node, -1 if none
C_INACT = 5  # inactive nodes still in the tree
C_ACCEPT = 6  # accepted (new active) nodes, cumulative
C_DOMINATED = 7  # children rejected because their witness holds a cheaper node
C_INVALID = 8  # invalid edges (crash, out of bounds)
C_STALE = 9  # children discarded because their parent went inactive earlier in the same batch
C_GOAL_EDGES = 10  # edges that reached the goal
C_REMOVED = 11  # nodes removed by pruning (inactive leaves and superseded solutions)
C_DEACT = 12  # nodes made inactive by a cheaper node at their witness
C_FALLBACK = 13  # selections with no active node within delta_BN (nearest node taken)
C_TOO_DEEP = 14  # non-goal children at the depth limit (they could never reach the goal in time)
C_PEND = 15  # slots freed in the current round (reusable only from the next round on)
C_BOUNDED = 16  # children whose lower bound on a solution through them cannot beat the best one
N_COUNTERS = 17


#: The 27 cell offsets around a cell, nearest first (the cell itself, faces, edges, corners).
_OFFSETS = np.array(
    sorted(((a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)), key=lambda o: sum(map(abs, o))),
    dtype=np.int64,
)


@njit(cache=True, inline="always")
def _wrap_abs(d: float, p: float) -> float:
    d = abs(d)
    if p > 0.0:
        d = d % p
        if p - d < d:
            d = p - d
    return d


@njit(cache=True)
def dist2_rows(a, i, b, j, adims, bdims, mscale, mperiod) -> float:
    """Squared metric distance between row i of ``a`` and row j of ``b``; ``adims``/``bdims`` map
    metric dimension k to the column of ``a``/``b`` (so states and metric-space points mix)."""
    s = 0.0
    for k in range(mscale.shape[0]):
        d = _wrap_abs(a[i, adims[k]] - b[j, bdims[k]], mperiod[k]) * mscale[k]
        s += d * d
    return s


@njit(cache=True, inline="always")
def _axis_cell(a, i, col, scale, g0, cs, gn) -> int:
    if col < 0:
        return 0
    c = int(math.floor((a[i, col] * scale - g0) / cs))
    if c < 0:
        return 0
    if c >= gn:
        return gn - 1
    return c


@njit(cache=True, inline="always")
def cell3(a, i, adims, gax, mscale, g0, cs, gn):
    """Grid cell (c0, c1, c2) of row i of ``a`` (columns via ``adims``)."""
    c0 = 0
    c1 = 0
    c2 = 0
    if gax[0] >= 0:
        c0 = _axis_cell(a, i, adims[gax[0]], mscale[gax[0]], g0[0], cs[0], gn[0])
    if gax[1] >= 0:
        c1 = _axis_cell(a, i, adims[gax[1]], mscale[gax[1]], g0[1], cs[1], gn[1])
    if gax[2] >= 0:
        c2 = _axis_cell(a, i, adims[gax[2]], mscale[gax[2]], g0[2], cs[2], gn[2])
    return c0, c1, c2


@njit(cache=True)
def cell_of(a, i, adims, gax, mscale, g0, cs, gn) -> int:
    """Flat grid cell index of row i of ``a``."""
    c0, c1, c2 = cell3(a, i, adims, gax, mscale, g0, cs, gn)
    return _flat(c0, c1, c2, gn)


@njit(cache=True, inline="always")
def _flat(c0, c1, c2, gn) -> int:
    return (c0 * gn[1] + c1) * gn[2] + c2


# --- active-node grid (doubly linked lists, O(1) removal) -------------------------------------
@njit(cache=True)
def grid_add(node, X, cost, xdims, gax, mscale, g0, cs, gn, head, nxt, prv, cell):
    """Insert ``node`` into its cell's list, which is kept sorted by (cost, id) ascending."""
    f = cell_of(X, node, xdims, gax, mscale, g0, cs, gn)
    c = cost[node]
    before = -1
    after = head[f]
    while after >= 0 and (cost[after] < c or (cost[after] == c and after < node)):
        before = after
        after = nxt[after]
    nxt[node] = after
    prv[node] = before
    if after >= 0:
        prv[after] = node
    if before >= 0:
        nxt[before] = node
    else:
        head[f] = node
    cell[node] = f


@njit(cache=True)
def grid_remove(node, head, nxt, prv, cell):
    p = prv[node]
    n = nxt[node]
    if p >= 0:
        nxt[p] = n
    else:
        head[cell[node]] = n
    if n >= 0:
        prv[n] = p
    nxt[node] = -1
    prv[node] = -1
    cell[node] = -1


@njit(cache=True)
def _scan_cell(node, q, Q, X, xdims, qdims, mscale, mperiod, nxt, best, best_d):
    """Nearest node of one cell's list (ties: lowest id) against the current best."""
    while node >= 0:
        d = dist2_rows(X, node, Q, q, xdims, qdims, mscale, mperiod)
        if d < best_d or (d == best_d and node < best):
            best = node
            best_d = d
        node = nxt[node]
    return best, best_d


@njit(cache=True)
def nearest_ring(Q, q, X, xdims, qdims, mscale, mperiod, gax, g0, cs, gn, head, nxt) -> int:
    """Exact nearest node in the grid (ties: lowest id) by a search over growing shells of cells
    around the query's cell; stops once no unscanned cell can hold a nearer node."""
    c0, c1, c2 = cell3(Q, q, qdims, gax, mscale, g0, cs, gn)
    best = -1
    best_d = np.inf
    cmin = np.inf
    for t in range(3):
        if gax[t] >= 0 and cs[t] < cmin:
            cmin = cs[t]
    rmax = max(gn[0], max(gn[1], gn[2]))
    for r in range(rmax + 1):
        for i0 in range(max(c0 - r, 0), min(c0 + r, gn[0] - 1) + 1):
            e0 = abs(i0 - c0) == r
            for i1 in range(max(c1 - r, 0), min(c1 + r, gn[1] - 1) + 1):
                if e0 or abs(i1 - c1) == r:
                    for i2 in range(max(c2 - r, 0), min(c2 + r, gn[2] - 1) + 1):
                        best, best_d = _scan_cell(
                            head[_flat(i0, i1, i2, gn)], q, Q, X, xdims, qdims, mscale, mperiod, nxt, best, best_d
                        )
                else:
                    if c2 - r >= 0:
                        best, best_d = _scan_cell(
                            head[_flat(i0, i1, c2 - r, gn)], q, Q, X, xdims, qdims, mscale, mperiod, nxt, best, best_d
                        )
                    if r > 0 and c2 + r < gn[2]:
                        best, best_d = _scan_cell(
                            head[_flat(i0, i1, c2 + r, gn)], q, Q, X, xdims, qdims, mscale, mperiod, nxt, best, best_d
                        )
        # every node in shells > r is more than r * cmin away along some grid axis
        if best >= 0 and best_d < (r * cmin) * (r * cmin):
            break
    return best


@njit(cache=True)
def select_batch(Q, X, cost, xdims, qdims, mscale, mperiod, gax, g0, cs, gn, head, nxt, r2, out) -> int:
    """Best-near selection for every query row of Q (metric coordinates): among active nodes within
    sqrt(r2) the cheapest (ties: lowest id); if there is none, the nearest active node (ties: lowest
    id). Returns how many queries needed the nearest-node fallback."""
    n_fallback = 0
    for q in range(Q.shape[0]):
        c0, c1, c2 = cell3(Q, q, qdims, gax, mscale, g0, cs, gn)
        best = -1
        best_c = np.inf
        for t in range(27):  # the query's own cell first: a cheap hit there cuts the other scans
            i0 = c0 + _OFFSETS[t, 0]
            i1 = c1 + _OFFSETS[t, 1]
            i2 = c2 + _OFFSETS[t, 2]
            if i0 < 0 or i1 < 0 or i2 < 0 or i0 >= gn[0] or i1 >= gn[1] or i2 >= gn[2]:
                continue
            node = head[_flat(i0, i1, i2, gn)]
            while node >= 0:  # cell lists are sorted by (cost, id): stop at the first hit
                cn = cost[node]
                if cn > best_c or (cn == best_c and node > best):
                    break
                if dist2_rows(X, node, Q, q, xdims, qdims, mscale, mperiod) <= r2:
                    best = node
                    best_c = cn
                    break
                node = nxt[node]
        if best < 0:
            n_fallback += 1
            best = nearest_ring(Q, q, X, xdims, qdims, mscale, mperiod, gax, g0, cs, gn, head, nxt)
        out[q] = best
    return n_fallback


@njit(cache=True)
def nearest_witness(NX, k, W, xdims, wdims, mscale, mperiod, gax, g0, cs, gn, whead, wnext, r2) -> int:
    """Nearest witness within sqrt(r2) of row k of NX (ties: lowest id), or -1."""
    c0, c1, c2 = cell3(NX, k, xdims, gax, mscale, g0, cs, gn)
    best = -1
    best_d = np.inf
    for i0 in range(max(c0 - 1, 0), min(c0 + 1, gn[0] - 1) + 1):
        for i1 in range(max(c1 - 1, 0), min(c1 + 1, gn[1] - 1) + 1):
            for i2 in range(max(c2 - 1, 0), min(c2 + 1, gn[2] - 1) + 1):
                w = whead[_flat(i0, i1, i2, gn)]
                while w >= 0:
                    d = dist2_rows(NX, k, W, w, xdims, wdims, mscale, mperiod)
                    if d <= r2 and (d < best_d or (d == best_d and w < best)):
                        best = w
                        best_d = d
                    w = wnext[w]
    return best


@njit(cache=True)
def _alloc(cnt, free) -> int:
    if cnt[C_FREE] > 0:
        cnt[C_FREE] -= 1
        return free[cnt[C_FREE]]
    node = cnt[C_USED]
    cnt[C_USED] += 1
    return node


@njit(cache=True)
def _release(node, status, cnt, pend):
    """Free a slot. It joins the free stack only at the end of the round (see ``insert_batch``)."""
    status[node] = FREE
    pend[cnt[C_PEND]] = node
    cnt[C_PEND] += 1
    cnt[C_REMOVED] += 1


@njit(cache=True)
def _prune_up(x, parent, nchild, status, cnt, pend):
    """Remove x and then its ancestors while each is an inactive leaf (SST's recursive pruning)."""
    while x >= 0 and status[x] == INACTIVE and nchild[x] == 0:
        p = parent[x]
        _release(x, status, cnt, pend)
        cnt[C_INACT] -= 1
        if p >= 0:
            nchild[p] -= 1
        x = p


@njit(cache=True)
def insert_batch(
    sel,
    NX,
    NU,
    ecost,
    edur,
    outcome,
    togo,
    X,
    U,
    cost,
    tcome,
    ecost_arr,
    parent,
    nchild,
    status,
    depth,
    head,
    nxt,
    prv,
    cell,
    W,
    wrep,
    whead,
    wnext,
    xdims,
    wdims,
    mscale,
    mperiod,
    gax,
    a_g0,
    a_cs,
    a_gn,
    w_g0,
    w_cs,
    w_gn,
    ws2,
    max_depth,
    cnt,
    free,
    pend,
    best_cost,
    imp_k,
    out_ids,
    chain,
) -> int:
    """Insert the children of one batch in order; returns how many improved the best solution
    (their batch positions are written to ``imp_k``). ``out_ids[k]`` receives the node id of child
    k if it was accepted as an active node, else -1. See :class:`baselines.sst.core.SST`.

    ``chain=True`` inserts a path that ends in a better solution (a goal completion): row k > 0 is
    the child of row k - 1 (``sel[0]`` is the first parent, active or inactive), no cost bound
    applies, and a row its witness dominates becomes an *inactive* node (kept as an ancestor of
    the solution, as SST keeps inactive nodes with descendants) instead of being rejected.

    Slots freed during the round are reused only from the next round on: a child whose selected
    parent was removed earlier in the round must find the slot FREE (stale), never reoccupied.
    """
    n_imp = 0
    m = mscale.shape[0]
    for k in range(sel.shape[0]):
        out_ids[k] = -1
        oc = outcome[k]
        if oc == EDGE_INVALID:
            cnt[C_INVALID] += 1
            continue
        p = out_ids[k - 1] if chain and k > 0 else sel[k]
        if p < 0 or not (status[p] == ACTIVE or (chain and status[p] == INACTIVE)):
            cnt[C_STALE] += 1
            continue
        c_new = cost[p] + ecost[k]
        if oc == EDGE_GOAL:
            cnt[C_GOAL_EDGES] += 1
            if c_new < best_cost[0]:
                node = _alloc(cnt, free)
                _write_node(node, p, k, c_new, NX, NU, ecost, edur, X, U, cost, tcome, ecost_arr, parent, depth)
                nchild[node] = 0
                nchild[p] += 1
                status[node] = SOLUTION
                old = cnt[C_BEST]
                cnt[C_BEST] = node
                best_cost[0] = c_new
                if old >= 0:
                    op = parent[old]
                    _release(old, status, cnt, pend)
                    nchild[op] -= 1
                    _prune_up(op, parent, nchild, status, cnt, pend)
                imp_k[n_imp] = k
                n_imp += 1
            continue
        if depth[p] + 1 >= max_depth:
            cnt[C_TOO_DEEP] += 1
            continue
        if not chain and c_new + togo[k] >= best_cost[0]:
            cnt[C_BOUNDED] += 1
            continue
        w = nearest_witness(NX, k, W, xdims, wdims, mscale, mperiod, gax, w_g0, w_cs, w_gn, whead, wnext, ws2)
        if w < 0:
            w = cnt[C_WIT]
            cnt[C_WIT] += 1
            for j in range(m):
                W[w, j] = NX[k, xdims[j]]
            wrep[w] = -1
            f = cell_of(W, w, wdims, gax, mscale, w_g0, w_cs, w_gn)
            wnext[w] = whead[f]
            whead[f] = w
        peer = wrep[w]
        if peer >= 0 and not c_new < cost[peer]:
            cnt[C_DOMINATED] += 1
            if chain:  # an inactive ancestor of the completion's solution
                node = _alloc(cnt, free)
                _write_node(node, p, k, c_new, NX, NU, ecost, edur, X, U, cost, tcome, ecost_arr, parent, depth)
                nchild[node] = 0
                nchild[p] += 1
                status[node] = INACTIVE
                cnt[C_INACT] += 1
                out_ids[k] = node
            continue
        node = _alloc(cnt, free)
        _write_node(node, p, k, c_new, NX, NU, ecost, edur, X, U, cost, tcome, ecost_arr, parent, depth)
        nchild[node] = 0
        nchild[p] += 1
        status[node] = ACTIVE
        grid_add(node, X, cost, xdims, gax, mscale, a_g0, a_cs, a_gn, head, nxt, prv, cell)
        cnt[C_ACT] += 1
        cnt[C_ACCEPT] += 1
        wrep[w] = node
        out_ids[k] = node
        if peer >= 0:
            # the displaced representative becomes inactive ...
            grid_remove(peer, head, nxt, prv, cell)
            cnt[C_ACT] -= 1
            status[peer] = INACTIVE
            cnt[C_INACT] += 1
            cnt[C_DEACT] += 1
            # ... and inactive leaves are removed recursively
            _prune_up(peer, parent, nchild, status, cnt, pend)
    for t in range(cnt[C_PEND]):
        free[cnt[C_FREE]] = pend[t]
        cnt[C_FREE] += 1
    cnt[C_PEND] = 0
    return n_imp


@njit(cache=True, inline="always")
def _write_node(node, p, k, c_new, NX, NU, ecost, edur, X, U, cost, tcome, ecost_arr, parent, depth):
    for j in range(X.shape[1]):
        X[node, j] = NX[k, j]
    for j in range(U.shape[1]):
        U[node, j] = NU[k, j]
    cost[node] = c_new
    ecost_arr[node] = ecost[k]
    tcome[node] = tcome[p] + edur[k]
    parent[node] = p
    depth[node] = depth[p] + 1
