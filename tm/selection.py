"""Go/Stop selection among requesters, given their conflicts (design 3b, 3c).

Requesters are numbered ``0 .. n-1``; ``g_i = 1`` is Go.  Conflicts arrive
as three arrays:

* ``fixed_hits[i]``: how many non-requesters' claims ``new_i`` meets
  (``> 0`` forces ``g_i = 0``);
* ``leq`` rows ``(i, j)``: ``new_i`` meets ``old_j``, so ``g_i <= g_j``
  (``i`` may not go into the hold region of a stopped ``j``);
* ``excl`` rows ``(i, j)``: ``new_i`` meets ``new_j``, so ``g_i + g_j <= 1``.

All-Stop satisfies every constraint, so every policy returns a feasible
answer.  Ties are broken by the ``numpy.random.Generator`` passed in, so a
seeded generator makes the decisions reproducible.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import coo_matrix

from tm.kernels import best_assignments, greedy_stops, greedy_tables, min_labels, stop_closure

__all__ = ["feasible", "select_greedy", "select_optimal", "propagate_stops", "components"]


def _edges(e) -> np.ndarray:
    return np.asarray(e, dtype=np.intp).reshape(-1, 2)


def feasible(go, fixed_hits, leq, excl) -> bool:
    """Whether the Go mask ``go`` (n,) satisfies every constraint."""
    go = np.asarray(go, dtype=bool)
    leq, excl = _edges(leq), _edges(excl)
    return bool(not np.any(go & (np.asarray(fixed_hits) > 0))
                and not np.any(go[leq[:, 0]] & ~go[leq[:, 1]])
                and not np.any(go[excl[:, 0]] & go[excl[:, 1]]))


def select_greedy(n: int, fixed_hits, leq, excl, rng: np.random.Generator) -> np.ndarray:
    """The paper's (P1)-(P3) extended to hold regions (design 3b).

    With stop set ``S`` (initially empty), the active edges are the
    conflicts of ``new_i`` (``i ∉ S``) with fixed claims, with ``new_j``
    (``j ∉ S``) and with ``old_j`` (``j ∈ S``).  While an active edge exists,
    the requester outside ``S`` with the highest active degree is stopped
    (ties: uniformly at random from ``rng``).  Pass ``leq`` empty for the
    paper's graph as written (hold regions ignored).

    Returns
    -------
    ndarray of bool, shape (n,)
        Go mask.
    """
    fixed_hits = np.asarray(fixed_hits, dtype=np.intp)
    leq, excl = _edges(leq), _edges(excl)
    stopped = np.zeros(n, dtype=bool)
    # the active degrees with nobody stopped; then kept up to date as requesters stop (compiled,
    # tm.kernels.greedy_stops), the random draws here: one per tie, as the recount per stop did
    deg = (fixed_hits + np.bincount(excl.ravel(), minlength=n)).astype(np.int64)
    col = lambda a, k: np.ascontiguousarray(a[:, k], dtype=np.int64)  # noqa: E731
    tables = greedy_tables(n, col(excl, 0), col(excl, 1), col(leq, 0), col(leq, 1))
    pick = -1
    while True:
        ties = greedy_stops(deg, stopped, *tables, pick)
        if not len(ties):
            return ~stopped
        pick = ties[rng.integers(len(ties))]


def propagate_stops(stopped, leq) -> np.ndarray:
    """Close a stop mask under ``g_i <= g_j``: if ``j`` stops, ``i`` must stop (compiled,
    :func:`tm.kernels.stop_closure`)."""
    stopped = np.array(stopped, dtype=bool)
    leq = _edges(leq)
    return stop_closure(stopped, np.ascontiguousarray(leq[:, 0]), np.ascontiguousarray(leq[:, 1]))


def components(n: int, edges) -> np.ndarray:
    """Connected-component labels of an undirected graph on ``n`` nodes: each label is the
    smallest node of its component (compiled union-find, :func:`tm.kernels.min_labels`; scipy's
    ``connected_components`` costs ~0.3 ms of overhead per call here).
    """
    edges = _edges(edges)
    return min_labels(n, np.ascontiguousarray(edges[:, 0]), np.ascontiguousarray(edges[:, 1]))


def _milp(n: int, leq: np.ndarray, excl: np.ndarray, w: np.ndarray, time_limit: float):
    rows = np.arange(len(leq) + len(excl))
    r = np.concatenate([rows, rows])
    c = np.concatenate([leq[:, 0], excl[:, 0], leq[:, 1], excl[:, 1]])
    v = np.concatenate([np.ones(len(leq) + len(excl)), -np.ones(len(leq)), np.ones(len(excl))])
    A = coo_matrix((v, (r, c)), shape=(len(rows), n)).tocsr()
    ub = np.concatenate([np.zeros(len(leq)), np.ones(len(excl))])
    res = milp(-w, integrality=np.ones(n), bounds=Bounds(0, 1),
               constraints=LinearConstraint(A, -np.inf, ub),
               options={"time_limit": float(time_limit), "mip_rel_gap": 0.0})
    return None if res.x is None else res.x > 0.5


def select_optimal(n: int, fixed_hits, leq, excl, weights, rng: np.random.Generator,
                   exhaustive_max: int = 14, milp_time_limit: float = 1.0) -> np.ndarray:
    """Exact maximum-weight Go set.

    Maximises ``Σ weights_i g_i`` subject to the constraints.  Forced stops
    (``fixed_hits > 0``, closed under ``leq``) are fixed first; the rest
    splits into connected components of the constraint graph, each solved
    alone: exhaustive enumeration (compiled,
    :func:`tm.kernels.best_assignments`: the first best assignment in
    counting order, as an argmax over all of them) up to ``exhaustive_max``
    requesters, ``scipy.optimize.milp`` (HiGHS, zero gap) above.

    Parameters
    ----------
    weights : array_like of int, shape (n,)
        Positive integer weights (the manager passes ``H + waited_i``).
        Ties between optimal sets are broken at random by adding
        ``u_i / (2 n)``, ``u_i ~ U[0, 1)``, which sums to less than 1 and so
        never changes an integer optimum.
    rng : numpy.random.Generator
        Draws ``n`` numbers per call (plus the greedy tie-breaks of a MILP
        fallback), so a seeded generator gives reproducible decisions.

    Returns
    -------
    ndarray of bool, shape (n,)
        Go mask.  If a MILP finds no feasible point within its time limit,
        that component falls back to :func:`select_greedy` (still feasible).
    """
    fixed_hits = np.asarray(fixed_hits, dtype=np.intp)
    leq, excl = _edges(leq), _edges(excl)
    w = np.asarray(weights, dtype=float) + rng.random(n) / (2 * max(n, 1))
    stopped = propagate_stops(fixed_hits > 0, leq)
    go = ~stopped
    leq = leq[go[leq[:, 0]] & go[leq[:, 1]]]
    excl = excl[go[excl[:, 0]] & go[excl[:, 1]]]
    edges = np.vstack([leq, excl])
    if len(edges) == 0:
        return go
    label = components(n, edges)                                 # component id = its smallest node
    sizes = np.bincount(label, minlength=n)
    by_comp = np.argsort(label, kind="stable")                   # requesters grouped by component
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    local = np.empty(n, dtype=np.intp)
    local[by_comp] = np.arange(n) - np.repeat(first, sizes)       # position within its component
    comp_of = label[edges[:, 0]]                                 # each edge's component
    small = (sizes > 1) & (sizes <= exhaustive_max)               # indexed by component id
    if small.any():                                               # exhaustive: one compiled loop
        ids = np.flatnonzero(small)
        sel = np.flatnonzero(small[comp_of])
        sel = sel[np.argsort(comp_of[sel], kind="stable")]        # edges grouped by component
        e_ptr = np.searchsorted(comp_of[sel], ids, side="left")
        e_ptr = np.r_[e_ptr, len(sel)].astype(np.intp)
        best_assignments(first[ids].astype(np.intp), sizes[ids].astype(np.intp), by_comp.astype(np.intp), e_ptr,
                         np.ascontiguousarray(local[edges[sel, 0]]), np.ascontiguousarray(local[edges[sel, 1]]),
                         sel >= len(leq), w, go)
    for size in np.unique(sizes[sizes > exhaustive_max]):        # large components: one MILP each
        comps = np.flatnonzero(sizes == size)
        nodes = by_comp[first[comps][:, None] + np.arange(size)]   # (C, size)
        in_size = sizes[comp_of] == size
        n_leq = len(leq)
        cl, ce = edges[:n_leq][in_size[:n_leq]], edges[n_leq:][in_size[n_leq:]]
        for row in nodes:
            inside = np.zeros(n, dtype=bool)
            inside[row] = True
            ml, me = local[cl[inside[cl[:, 0]]]], local[ce[inside[ce[:, 0]]]]
            sol = _milp(int(size), ml, me, w[row], milp_time_limit)
            if sol is None or not feasible(sol, np.zeros(int(size)), ml, me):
                sol = select_greedy(int(size), np.zeros(int(size), dtype=np.intp), ml, me, rng)
            go[row] = sol
    return go
