"""Compiled loops of the traffic manager's hot paths (numba), float for float the numpy formulas.

The ``timed`` check of reach claims (:func:`tm.reach.claims_conflict`) compares, for each candidate
pair, slot ``k`` of one claim with slot ``k`` of the other: a world bounding-box pre-filter, then
the separating-axis test, stopping at the first slot that meets.  In numpy that is a gather of
``pairs x K`` boxes and a second pass over the slots the first test left open; here it is one loop
per pair that stops early (measured: ``benchmarks/bench_tm.py``, README).  The claims themselves
(:func:`tm.reach.reach_claims`) are a dozen formulas per vehicle and slot; :func:`reach_boxes`
evaluates them in one pass, with the slots' world bounding boxes, instead of a dozen passes over
``(n, K)`` arrays.

Every kernel (but :func:`sets_meet`, see there) performs the same floating-point operations, in the
same order, as the numpy code it replaces (``tests/tm/test_kernels.py`` compares them bit for bit
with those formulas): compiled without ``fastmath``, so no reassociation or fused multiply-add.
Trigonometry stays in numpy (the callers pass ``cos``/``sin`` of the headings): the library's and
numpy's ``cos`` need not agree in the last bit. ``max``/``min`` below are numpy's
``maximum``/``minimum`` for numbers (the first argument on ties, as numpy). Compiled on first use
and cached beside this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["timed_pairs_plain", "timed_pairs_tight", "reach_boxes", "grid_pairs", "union_bounds", "slot_bounds", "path_slots",
           "cover_boxes", "cover_frame_bounds", "best_assignments", "stop_closure", "min_labels",
           "greedy_tables", "greedy_stops", "merge_rows", "sets_meet", "any_boxes_meet",
           "rows_meet_any"]


@njit(cache=True, inline="always")
def _max(a, b):
    return a if a >= b else b


@njit(cache=True, inline="always")
def _min(a, b):
    return a if a <= b else b


@njit(cache=True, inline="always")
def _sat(acx, acy, ac, as_, alo0, alo1, ahi0, ahi1, bcx, bcy, bc, bs, blo0, blo1, bhi0, bhi1, tol):
    """:func:`tm.reach._boxes_overlap` of one pair of boxes ``c + R [lo, hi]`` (``ac, as_``: cos, sin
    of the first box's heading)."""
    if not (alo0 <= ahi0 and alo1 <= ahi1 and blo0 <= bhi0 and blo1 <= bhi1):
        return False
    mx = 0.5 * (alo0 + ahi0)
    my = 0.5 * (alo1 + ahi1)
    ax = acx + ac * mx - as_ * my
    ay = acy + as_ * mx + ac * my
    ahx = 0.5 * (ahi0 - alo0)
    ahy = 0.5 * (ahi1 - alo1)
    mx = 0.5 * (blo0 + bhi0)
    my = 0.5 * (blo1 + bhi1)
    bx = bcx + bc * mx - bs * my
    by = bcy + bs * mx + bc * my
    bhx = 0.5 * (bhi0 - blo0)
    bhy = 0.5 * (bhi1 - blo1)
    dx = bx - ax
    dy = by - ay
    cc = abs(ac * bc + as_ * bs)
    ss = abs(ac * bs - as_ * bc)
    if abs(dx * ac + dy * as_) - (ahx + bhx * cc + bhy * ss) > tol:
        return False
    if abs(-dx * as_ + dy * ac) - (ahy + bhx * ss + bhy * cc) > tol:
        return False
    if abs(dx * bc + dy * bs) - (bhx + ahx * cc + ahy * ss) > tol:
        return False
    if abs(-dx * bs + dy * bc) - (bhy + ahx * ss + ahy * cc) > tol:
        return False
    return True


@njit(cache=True, inline="always")
def _aabb_meet(A, p, ka, B, q, kb, pad):
    return (A[0, p, ka] <= B[1, q, kb] + pad and B[0, q, kb] <= A[1, p, ka] + pad and
            A[2, p, ka] <= B[3, q, kb] + pad and B[2, q, kb] <= A[3, p, ka] + pad)


@njit(cache=True)
def timed_pairs_plain(A, B, ca, cos_a, sin_a, lo_a, hi_a, cb, cos_b, sin_b, lo_b, hi_b, i, j, tol, pad):
    """Whether claims ``a[i[t]]`` and ``b[j[t]]`` meet at some slot (``timed`` check), one box per
    slot.  ``A``, ``B``: the slots' world bounding boxes ``(4, n, K)`` (the pre-filter, compared
    with ``pad``); ``ca``, ``cos_a``, ``sin_a``, ``lo_a``, ``hi_a``: centres, headings' cos and sin,
    segment-frame corners ``(n, K, 2)``; slots past a shorter horizon are its last one.  With as
    many slot boxes on both sides (``KA == KB``), the pre-filter of every slot of a pair is
    evaluated first in one branch-free pass (most pairs meet at no slot) and the separating-axis
    test then runs on the slots that passed, in order, up to the first that meets: the same answer."""
    n = len(i)
    out = np.zeros(n, dtype=np.bool_)
    KA, KB = A.shape[2], B.shape[2]
    La, Lb = lo_a.shape[1], lo_b.shape[1]
    K = max(KA, KB)
    same = KA == KB
    meet = np.zeros(K, dtype=np.bool_)
    for t in range(n):
        p, q = i[t], j[t]
        if same:
            a0, a1, a2, a3 = A[0, p], A[1, p], A[2, p], A[3, p]
            b0, b1, b2, b3 = B[0, q], B[1, q], B[2, q], B[3, q]
            some = False
            for k in range(K):
                m = (a0[k] <= b1[k] + pad) & (b0[k] <= a1[k] + pad) & (a2[k] <= b3[k] + pad) & (b2[k] <= a3[k] + pad)
                meet[k] = m
                some |= m
            if not some:
                continue
        for k in range(K):
            if same:
                if not meet[k]:
                    continue
            elif not _aabb_meet(A, p, min(k, KA - 1), B, q, min(k, KB - 1), pad):
                continue
            ka, kb = min(k, La - 1), min(k, Lb - 1)
            if _sat(ca[p, 0], ca[p, 1], cos_a[p], sin_a[p], lo_a[p, ka, 0], lo_a[p, ka, 1], hi_a[p, ka, 0],
                    hi_a[p, ka, 1], cb[q, 0], cb[q, 1], cos_b[q], sin_b[q], lo_b[q, kb, 0], lo_b[q, kb, 1],
                    hi_b[q, kb, 0], hi_b[q, kb, 1], tol):
                out[t] = True
                break
    return out


@njit(cache=True)
def timed_pairs_tight(A, B, La, ca, cos_a, sin_a, half_a, start_a, count_a, Lb, cb, cos_b, sin_b, half_b, start_b,
                      count_b, i, j, tol, pad):
    """:func:`timed_pairs_plain` for slots that are unions of boxes (:class:`tm.slot_boxes.SlotBoxes`:
    flat boxes ``c + R [-half, half]``, each row's slot ``k`` the boxes ``start .. start + count - 1``);
    two slots meet when some box of one meets some box of the other.  ``La``, ``Lb``: the claims'
    own slot counts (the index into ``start``/``count`` is clipped to them)."""
    n = len(i)
    out = np.zeros(n, dtype=np.bool_)
    KA, KB = A.shape[2], B.shape[2]
    K = max(KA, KB)
    for t in range(n):
        p, q = i[t], j[t]
        for k in range(K):
            if not _aabb_meet(A, p, min(k, KA - 1), B, q, min(k, KB - 1), pad):
                continue
            ka, kb = min(k, La - 1), min(k, Lb - 1)
            s0, n0, s1, n1 = start_a[p, ka], count_a[p, ka], start_b[q, kb], count_b[q, kb]
            hit = False
            for x in range(s0, s0 + n0):
                for y in range(s1, s1 + n1):
                    if _sat(ca[x, 0], ca[x, 1], cos_a[x], sin_a[x], -half_a[x, 0], -half_a[x, 1], half_a[x, 0],
                            half_a[x, 1], cb[y, 0], cb[y, 1], cos_b[y], sin_b[y], -half_b[y, 0], -half_b[y, 1],
                            half_b[y, 0], half_b[y, 1], tol):
                        hit = True
                        break
                if hit:
                    break
            if hit:
                out[t] = True
                break
    return out


@njit(cache=True)
def _table(T, m, w, w0, dw, up):
    """``T[m, j]`` at the grid point at or below (``up`` False: at or above) ``w``, clipped to the
    grid (:meth:`controllers.authority.AuthorityTables.g` / ``h``)."""
    x = (w - w0) / dw
    f = np.floor(x) if up else np.ceil(x)
    f = _min(_max(f, 0.0), T.shape[1] - 1.0)
    return T[m, int(f)]


@njit(cache=True)
def reach_boxes(E, index, ly, Aa, Ac, ra, ry, v_lo_t, v_hi_t, p_lo_t, p_hi_t, y_lo_t, y_hi_t, G, H, w0, dw,
                margin, fx_lo, fx_hi, fy_lo, fy_hi, K, centre, cos_h, sin_h, lo, hi, W, U, row0, with_boxes):
    """The claim boxes of :func:`tm.reach.reach_claims`, written to rows ``row0 ..`` of ``lo``, ``hi``
    (rows, K_out, 2) (along, across in the segment frame, footprint added, empty slots ``+inf,
    -inf``) and, with ``with_boxes``, of ``W`` (4, rows, K_out): their world bounding boxes
    (:func:`tm.reach.slot_aabb`), and of ``U`` (rows, 4): the bounds over each row's slots,
    ``x_lo, x_hi, y_lo, y_hi`` (:func:`union_bounds` of ``W``'s rows, the same floats).  Slots
    ``K - 1 ..`` are ``T^0`` whole (the last slot, repeated up to ``K_out``: it stands for every
    later step).

    ``E`` (n, 4): segment-frame errors; ``index`` (n,); ``ly`` (n,): the across factor's level plus
    one, at most ``index`` (or ``index`` itself without an across factor); ``Aa``, ``Ac`` (K-1, 2, 2),
    ``ra``, ``ry`` (K-1, 2): ``A^k`` and ``r_k`` for ``k = 1 .. K-1``; the tables of
    :class:`controllers.authority.AuthorityTables`; footprint half extents (n,) per side."""
    n = E.shape[0]
    K_out = lo.shape[1]
    inf = np.inf
    g_v = np.empty(K)
    h_v = np.empty(K)
    for v in range(n):
        r = row0 + v
        e0, e1, e2, e3 = E[v, 0], E[v, 1], E[v, 2], E[v, 3]
        iv, lyv = index[v], ly[v]
        # the tables first, in a loop of their own: its few operations per slot let many of these
        # scattered loads be in flight at once (within the slot loop below they were its main cost)
        for s in range(K - 1):
            mm = _max(iv - (s + 1), 0)
            cv = e0 * Aa[s, 1, 0] + e2 * Aa[s, 1, 1]
            vl = _max(cv - ra[s, 1], v_lo_t[mm])
            vh = _min(cv + ra[s, 1], v_hi_t[mm])
            h_v[s] = _table(H, mm, vh + margin, w0, dw, False)
            g_v[s] = _table(G, mm, vl - margin, w0, dw, True)
        fxl, fxh, fyl, fyh = fx_lo[v], fx_hi[v], fy_lo[v], fy_hi[v]
        c, sn = cos_h[v], sin_h[v]
        ac, as_ = abs(c), abs(sn)
        c0, c1 = centre[v, 0], centre[v, 1]
        u0, u1, u2, u3 = inf, -inf, inf, -inf
        for s in range(K_out):
            if s >= K:  # T^0 whole again: slot K - 1's boxes (the same floats)
                b0, b1, b2, b3 = lo[r, K - 1, 0], lo[r, K - 1, 1], hi[r, K - 1, 0], hi[r, K - 1, 1]
                lo[r, s, 0], lo[r, s, 1], hi[r, s, 0], hi[r, s, 1] = b0, b1, b2, b3
                if with_boxes:
                    w_0, w_1, w_2, w_3 = W[0, r, K - 1], W[1, r, K - 1], W[2, r, K - 1], W[3, r, K - 1]
                    W[0, r, s], W[1, r, s], W[2, r, s], W[3, r, s] = w_0, w_1, w_2, w_3
                    u0 = _min(u0, w_0)
                    u1 = _max(u1, w_1)
                    u2 = _min(u2, w_2)
                    u3 = _max(u3, w_3)
                continue
            if s < K - 1:
                k = s + 1
                mm = _max(iv - k, 0)
                my = _max(lyv - k, 0)
                cp = e0 * Aa[s, 0, 0] + e2 * Aa[s, 0, 1]
                cy = e1 * Ac[s, 0, 0] + e3 * Ac[s, 0, 1]
                a0 = _max(_max(cp - ra[s, 0], h_v[s]), p_lo_t[mm])
                a1 = _min(_min(cp + ra[s, 0], g_v[s]), p_hi_t[mm])
                a2 = _max(cy - ry[s, 0], y_lo_t[my])
                a3 = _min(cy + ry[s, 0], y_hi_t[my])
            else:  # the last slot: T^0 whole
                a0, a1, a2, a3 = p_lo_t[0], p_hi_t[0], y_lo_t[0], y_hi_t[0]
            empty = a0 > a1 or a2 > a3
            if empty:
                a0, a1, a2, a3 = inf, -inf, inf, -inf
            else:
                a0 = a0 - fxl
                a1 = a1 + fxh
                a2 = a2 - fyl
                a3 = a3 + fyh
            lo[r, s, 0], lo[r, s, 1], hi[r, s, 0], hi[r, s, 1] = a0, a2, a1, a3
            if not with_boxes:
                continue
            hx = (a1 - a0) * 0.5
            hy = (a3 - a2) * 0.5
            if empty or not (hx >= 0 and hy >= 0):
                w_0, w_1, w_2, w_3 = inf, -inf, inf, -inf
            else:
                mx = (a0 + a1) * 0.5
                my_ = (a2 + a3) * 0.5
                wx = c * mx - sn * my_ + c0
                wy = sn * mx + c * my_ + c1
                ex = ac * hx + as_ * hy
                ey = as_ * hx + ac * hy
                w_0, w_1, w_2, w_3 = wx - ex, wx + ex, wy - ey, wy + ey
            W[0, r, s], W[1, r, s], W[2, r, s], W[3, r, s] = w_0, w_1, w_2, w_3
            if s == 0:  # the bounds over the row's slots: _row_bounds' min / max, in its order
                u0, u1, u2, u3 = w_0, w_1, w_2, w_3
            else:
                u0 = _min(u0, w_0)
                u1 = _max(u1, w_1)
                u2 = _min(u2, w_2)
                u3 = _max(u3, w_3)
        if with_boxes:
            U[r, 0], U[r, 1], U[r, 2], U[r, 3] = u0, u1, u2, u3


@njit(cache=True)
def grid_pairs(x0, x1, y0, y1, mask, use_mask):
    """Pairs ``(i, j)``, ``i < j``, of boxes ``[x0, x1] x [y0, y1]`` that meet (closed boxes:
    ``min(x1) >= max(x0)`` on both axes), at least one of them in ``mask`` when ``use_mask``;
    as packed keys ``i n + j``, sorted.  A uniform grid: cell size the (upper) median box extent,
    doubled while the boxes would cover more than ``8 n`` cells; every box is entered in the cells
    it covers, pairs are formed within each cell (with a mask, only those with a masked box: those
    come first in a cell) and kept only in the cell holding the corner
    ``max(lo_i, lo_j)`` of their intersection, so each is reported once.  Boxes must not be
    inverted (``x1 >= x0``, ``y1 >= y0``).  The entries are ordered by cell with a counting sort
    when the grid has at most about twice as many cells as entries (else a sort), and copied in
    that order to contiguous arrays before the pairs of each cell are formed."""
    n = len(x0)
    ox, oy = x0.min(), y0.min()
    ext = np.maximum(x1 - x0, y1 - y0)
    h = max(np.partition(ext, n // 2)[n // 2], 1e-6)
    span = max(x1.max() - ox, y1.max() - oy)
    cx0 = np.empty(n, dtype=np.int64)
    cy0 = np.empty(n, dtype=np.int64)
    nx = np.empty(n, dtype=np.int64)
    ny = np.empty(n, dtype=np.int64)
    while True:
        inv = 1.0 / h
        total = 0
        for b in range(n):
            cx0[b] = np.int64(np.floor((x0[b] - ox) * inv))
            cy0[b] = np.int64(np.floor((y0[b] - oy) * inv))
            nx[b] = np.int64(np.floor((x1[b] - ox) * inv)) - cx0[b] + 1
            ny[b] = np.int64(np.floor((y1[b] - oy) * inv)) - cy0[b] + 1
            total += nx[b] * ny[b]
        if total <= 8 * n or h > span:
            break
        h *= 2.0
    width = 0
    for b in range(n):
        width = max(width, cy0[b] + ny[b])
    width += 1
    cell = np.empty(total, dtype=np.int64)
    box = np.empty(total, dtype=np.int64)
    e = 0
    for b in range(n):
        for u in range(nx[b]):
            for w in range(ny[b]):
                cell[e] = (cx0[b] + u) * width + cy0[b] + w
                box[e] = b
                e += 1
    # entries by cell, and within a cell (with use_mask) the masked boxes' first: a pair needs one,
    # so the pairs of a cell stop at its first unmasked entry
    late = np.zeros(total, dtype=np.int64)
    if use_mask:
        for e in range(total):
            late[e] = 0 if mask[box[e]] else 1
    sub = cell * 2 + late
    n_sub = sub.max() + 1
    if n_sub <= 4 * total + 64:  # counting sort by (cell, late), entries in order within one
        first = np.zeros(n_sub + 1, dtype=np.int64)
        for e in range(total):
            first[sub[e] + 1] += 1
        for u in range(n_sub):
            first[u + 1] += first[u]
        order = np.empty(total, dtype=np.int64)
        for e in range(total):
            order[first[sub[e]]] = e
            first[sub[e]] += 1
    elif n_sub <= (1 << 62) // total:  # sort packed (cell, late, entry): much faster than argsort
        order = np.sort(sub * total + np.arange(total)) % total
    else:
        order = np.argsort(sub, kind="mergesort")
    # the entries in that order, contiguous: a cell's pairs read its boxes' bounds side by side
    ex0 = np.empty(total)
    ex1 = np.empty(total)
    ey0 = np.empty(total)
    ey1 = np.empty(total)
    eb = np.empty(total, dtype=np.int64)
    ec = np.empty(total, dtype=np.int64)
    for g in range(total):
        b = box[order[g]]
        ex0[g], ex1[g], ey0[g], ey1[g], eb[g], ec[g] = x0[b], x1[b], y0[b], y1[b], b, cell[order[g]]
    cap = max(16, 4 * n)
    key = np.empty(cap, dtype=np.int64)
    m = 0
    g = 0
    while g < total:
        c = ec[g]
        end = g + 1
        while end < total and ec[end] == c:
            end += 1
        last = end  # pairs start at a masked entry: those before the cell's first unmasked one
        if use_mask:
            last = g
            while last < end and mask[eb[last]]:
                last += 1
        for a in range(g, last):
            ax0, ax1, ay0, ay1 = ex0[a], ex1[a], ey0[a], ey1[a]
            if m + (end - a) > cap:  # room for every pair of this entry: the loop below writes each
                while m + (end - a) > cap:
                    cap *= 2
                grown = np.empty(cap, dtype=np.int64)
                grown[:m] = key[:m]
                key = grown
            p = eb[a]
            for b in range(a + 1, end):  # branch-free: each key written, kept (m + 1) when it counts
                cx = max(ax0, ex0[b])
                cy = max(ay0, ey0[b])
                ok = (min(ax1, ex1[b]) >= cx) & (min(ay1, ey1[b]) >= cy)
                ok &= np.int64(np.floor((cx - ox) * inv)) * width + np.int64(np.floor((cy - oy) * inv)) == c
                q = eb[b]
                key[m] = min(p, q) * n + max(p, q)
                m += ok
        g = end
    return np.sort(key[:m])


@njit(cache=True, inline="always")
def _row_bounds(W, i, U):
    """``U[i]`` = the bounds over row ``i``'s slot boxes in ``W`` (4, n, K): ``x_lo, x_hi, y_lo, y_hi``,
    slot 0 first, then each later slot's in order (``K >= 1``)."""
    K = W.shape[2]
    x0, x1, y0, y1 = W[0, i, 0], W[1, i, 0], W[2, i, 0], W[3, i, 0]
    for k in range(1, K):
        x0 = _min(x0, W[0, i, k])
        x1 = _max(x1, W[1, i, k])
        y0 = _min(y0, W[2, i, k])
        y1 = _max(y1, W[3, i, k])
    U[i, 0], U[i, 1], U[i, 2], U[i, 3] = x0, x1, y0, y1


@njit(cache=True)
def union_bounds(W):
    """Per row of world slot boxes ``W`` (4, n, K) (``x_lo, x_hi, y_lo, y_hi``; empty slots
    ``+inf, -inf``; ``K >= 1``): the bounds over its slots, ``U`` (n, 4): ``x_lo, x_hi, y_lo, y_hi``
    (inverted when all are empty) -- :attr:`tm.reach.ReachClaims.union_bounds`."""
    n = W.shape[1]
    U = np.empty((n, 4))
    for i in range(n):
        _row_bounds(W, i, U)
    return U


@njit(cache=True)
def slot_bounds(x0, x1, y0, y1, start, count):
    """World bounding boxes ``(4, n, K)`` of slots that are unions of boxes (:meth:`tm.slot_boxes.
    SlotBoxes.aabb`): ``x0 .. y1`` (q,) the boxes' own bounds, each slot the boxes ``start ..
    start + count - 1``; empty slots inverted (``+inf, -inf``).  A slot with the same boxes as the one
    before it copies that one's bounds.  Also the bounds over each row's slots, ``U`` (n, 4)
    (:func:`union_bounds` of the result, the same floats; with ``K >= 1``)."""
    n, K = start.shape
    out = np.empty((4, n, K))
    U = np.empty((n, 4))
    inf = np.inf
    for i in range(n):
        for k in range(K):
            if k > 0 and start[i, k] == start[i, k - 1] and count[i, k] == count[i, k - 1]:
                for c in range(4):
                    out[c, i, k] = out[c, i, k - 1]
                continue
            a0, a1, a2, a3 = inf, -inf, inf, -inf
            for b in range(start[i, k], start[i, k] + count[i, k]):
                a0 = _min(a0, x0[b])
                a1 = _max(a1, x1[b])
                a2 = _min(a2, y0[b])
                a3 = _max(a3, y1[b])
            out[0, i, k], out[1, i, k], out[2, i, k], out[3, i, k] = a0, a1, a2, a3
        if K:
            _row_bounds(out, i, U)
    return out, U


# ---------------------------------------------------------------------- path-frame claims (tm.path_claims)
@njit(cache=True)
def path_slots(lo, hi, s_c):
    """The slots of path-frame claims as path intervals (:func:`tm.path_claims.path_reach_claims`):
    ``lo``, ``hi`` (n, K, 2) the bare claims in the frame of ``(s_c, 0)``.  Returns the intervals of
    the slots that start a run of equal slots, ``s_lo, s_hi, n_lo, n_hi`` (m,) (an empty slot: ``[1, 0]
    x [0, 0]``), their flat slot indices ``first`` (m,), and per slot (n K,) its run's interval."""
    n, K = lo.shape[0], lo.shape[1]
    s_lo = np.empty(n * K)
    s_hi = np.empty(n * K)
    n_lo = np.empty(n * K)
    n_hi = np.empty(n * K)
    first = np.empty(n * K, dtype=np.intp)
    run = np.empty(n * K, dtype=np.intp)
    m = 0
    for i in range(n):
        for k in range(K):
            if not (lo[i, k, 0] <= hi[i, k, 0] and lo[i, k, 1] <= hi[i, k, 1]):
                a, b, c, d = 1.0, 0.0, 0.0, 0.0
            else:
                a, b, c, d = lo[i, k, 0] + s_c[i], hi[i, k, 0] + s_c[i], lo[i, k, 1], hi[i, k, 1]
            if k == 0 or not (a == s_lo[m - 1] and b == s_hi[m - 1] and c == n_lo[m - 1] and d == n_hi[m - 1]):
                s_lo[m], s_hi[m], n_lo[m], n_hi[m] = a, b, c, d
                first[m] = i * K + k
                m += 1
            run[i * K + k] = m - 1
    return s_lo[:m], s_hi[:m], n_lo[:m], n_hi[:m], first[:m], run


@njit(cache=True)
def cover_boxes(seg, owner, frame, sl, sh, nl, nh, bk, fr, rt, lf, s_first, s_last, s_start, s_end, s_heading,
                s_body, s_tangent, s_normal, s_vertices, lean, cos_d, sin_d, cos_b, sin_b):
    """The boxes of :func:`tm.path_cover.stack_box_cover`, one per ``(interval owner[q], segment
    seg[q])``: ``centre`` (q, 2), ``heading`` (q,), ``half`` (q, 2).  ``frame[q]``: the interval's frame;
    ``s_*``: the stack's arrays; ``lean[q]``: the segment's body leans, with ``cos_d, sin_d`` of the
    heading less the body heading and ``cos_b, sin_b`` of the body heading (computed by the caller)."""
    q = len(seg)
    centre = np.empty((q, 2))
    heading = np.empty(q)
    half = np.empty((q, 2))
    inf = np.inf
    for x in range(q):
        o, g, f = owner[x], seg[x], frame[x]
        S0 = -inf if g == s_first[f] else s_start[g]
        S1 = inf if g == s_last[f] else s_end[g]
        a = _max(sl[o], S0) - s_start[g]
        b = _min(sh[o], S1) - s_start[g]
        nlo, nhi = nl[o], nh[o]
        hd, t0, t1, n0, n1 = s_heading[g], s_tangent[g, 0], s_tangent[g, 1], s_normal[g, 0], s_normal[g, 1]
        if lean[x]:  # the reference points' parallelogram bounded in the body's frame
            c, sn = cos_d[x], sin_d[x]
            u0, u1, u2, u3 = c * a - sn * nlo, c * a - sn * nhi, c * b - sn * nlo, c * b - sn * nhi
            v0, v1, v2, v3 = sn * a + c * nlo, sn * a + c * nhi, sn * b + c * nlo, sn * b + c * nhi
            a = _min(_min(_min(u0, u1), u2), u3)
            b = _max(_max(_max(u0, u1), u2), u3)
            nlo = _min(_min(_min(v0, v1), v2), v3)
            nhi = _max(_max(_max(v0, v1), v2), v3)
            hd, t0, t1 = s_body[g], cos_b[x], sin_b[x]
            n0, n1 = -t1, t0
        lo_x, hi_x = a - bk[o], b + fr[o]
        lo_y, hi_y = nlo - rt[o], nhi + lf[o]
        mx, my = 0.5 * (lo_x + hi_x), 0.5 * (lo_y + hi_y)
        centre[x, 0] = s_vertices[g, 0] + mx * t0 + my * n0
        centre[x, 1] = s_vertices[g, 1] + mx * t1 + my * n1
        heading[x] = hd
        half[x, 0] = 0.5 * (hi_x - lo_x)
        half[x, 1] = 0.5 * (hi_y - lo_y)
    return centre, heading, half


@njit(cache=True)
def cover_frame_bounds(centre, half, start, count, pc, cos_p, sin_p, cc, ss):
    """:func:`tm.path_cover.cover_bounds`: per interval ``i`` (its boxes ``start .. start + count - 1``)
    the bounding box of its boxes in the frame ``pc[i] + R(h_i)`` (``cos_p``, ``sin_p``: of ``h_i``;
    ``cc``, ``ss`` (q,): ``|cos|``, ``|sin|`` of each box's heading less its interval's ``h``):
    ``lo``, ``hi`` (m, 2), inverted without a box."""
    m = len(start)
    lo = np.empty((m, 2))
    hi = np.empty((m, 2))
    inf = np.inf
    for i in range(m):
        a0, a1, b0, b1 = inf, inf, -inf, -inf
        c, s = cos_p[i], sin_p[i]
        for x in range(start[i], start[i] + count[i]):
            d0 = centre[x, 0] - pc[i, 0]
            d1 = centre[x, 1] - pc[i, 1]
            u = c * d0 + s * d1
            v = -s * d0 + c * d1
            eu = cc[x] * half[x, 0] + ss[x] * half[x, 1]
            ev = ss[x] * half[x, 0] + cc[x] * half[x, 1]
            a0 = _min(a0, u - eu)
            a1 = _min(a1, v - ev)
            b0 = _max(b0, u + eu)
            b1 = _max(b1, v + ev)
        lo[i, 0], lo[i, 1], hi[i, 0], hi[i, 1] = a0, a1, b0, b1
    return lo, hi


@njit(cache=True)
def best_assignments(start, size, nodes, e_ptr, e_a, e_b, e_excl, w, go):
    """Exhaustive Go/Stop selection (:func:`tm.selection.select_optimal`) of components one by one:
    component ``c``'s requesters are ``nodes[start[c] : start[c] + size[c]]`` (bit ``j`` of an
    assignment is the ``j``-th of them); its constraints are rows ``e_ptr[c] : e_ptr[c + 1]`` of
    ``e_a``, ``e_b`` (positions within the component) and ``e_excl`` (False: ``g_a <= g_b``,
    True: ``g_a + g_b <= 1``).  Assignments are tried in order ``0 .. 2^size - 1``; the first of
    the highest score ``Σ_j w[node_j] g_j`` (summed over ``j`` ascending) among the feasible ones
    is written to ``go[nodes]``.  All-Stop (assignment 0, score 0) is always feasible."""
    for c in range(len(start)):
        s0, s = start[c], size[c]
        best, best_a = -np.inf, 0
        for a in range(1 << s):
            ok = True
            for e in range(e_ptr[c], e_ptr[c + 1]):
                ga = (a >> e_a[e]) & 1
                gb = (a >> e_b[e]) & 1
                if ga == 1 and (gb == 1 if e_excl[e] else gb == 0):
                    ok = False
                    break
            if not ok:
                continue
            score = 0.0
            for j in range(s):
                if (a >> j) & 1:
                    score += w[nodes[s0 + j]]
            if score > best:
                best, best_a = score, a
        for j in range(s):
            go[nodes[s0 + j]] = ((best_a >> j) & 1) == 1


@njit(cache=True)
def stop_closure(stopped, a, b):
    """:func:`tm.selection.propagate_stops`: the least superset of the stop mask ``stopped`` (n,) closed
    under ``g_a <= g_b`` for every edge (``a[e]`` stops when ``b[e]`` does), by a search from the
    stopped requesters along the edges reversed (the closure is unique: any order gives it)."""
    n = len(stopped)
    out = stopped.copy()
    first, waits = _incident(n, a, b)  # edges grouped by b: the a's that wait on each b
    todo = np.empty(n, dtype=np.int64)
    top = 0
    for v in range(n):
        if out[v]:
            todo[top] = v
            top += 1
    while top:
        top -= 1
        v = todo[top]
        for x in range(first[v], first[v + 1]):
            u = waits[x]
            if not out[u]:
                out[u] = True
                todo[top] = u
                top += 1
    return out


@njit(cache=True)
def min_labels(n, a, b):
    """:func:`tm.selection.components`: per node the smallest node of its connected component (edges
    ``(a[e], b[e])``), by union-find whose root is always its set's smallest node."""
    parent = np.arange(n)
    for e in range(len(a)):
        x, y = a[e], b[e]
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        while parent[y] != y:
            parent[y] = parent[parent[y]]
            y = parent[y]
        if x < y:
            parent[y] = x
        elif y < x:
            parent[x] = y
    for v in range(n):
        parent[v] = parent[parent[v]]  # roots come first in node order: every chain is now flat
    return parent


@njit(cache=True)
def _incident(n, a, b):
    """Rows ``(a[e], b[e])`` grouped by ``b``: ``first`` (n + 1,), ``other`` the ``a`` of each."""
    first = np.zeros(n + 1, dtype=np.int64)
    for e in range(len(a)):
        first[b[e] + 1] += 1
    for v in range(n):
        first[v + 1] += first[v]
    fill = first[:n].copy()
    other = np.empty(len(a), dtype=np.int64)
    for e in range(len(a)):
        other[fill[b[e]]] = a[e]
        fill[b[e]] += 1
    return first, other


@njit(cache=True)
def greedy_tables(n, ex_a, ex_b, lq_a, lq_b):
    """The edges of :func:`greedy_stops` grouped by requester: exclusions ``(x, p)`` by ``p`` and
    ``(p, x)`` by ``p``, and rows ``g_i <= g_p`` by ``p`` (``first`` (n + 1,), ``other`` pairs)."""
    f1, o1 = _incident(n, ex_a, ex_b)
    f2, o2 = _incident(n, ex_b, ex_a)
    f3, o3 = _incident(n, lq_a, lq_b)
    return f1, o1, f2, o2, f3, o3


@njit(cache=True)
def greedy_stops(deg, stopped, ex_f1, ex_o1, ex_f2, ex_o2, lq_f, lq_o, pick):
    """The stop loop of :func:`tm.selection.select_greedy` with the active degrees ``deg`` (n,) kept
    up to date instead of recounted: stopping ``p`` takes one from the other end of each of ``p``'s
    exclusions still active, adds one to each requester ``i`` outside the stop set with a row
    ``g_i <= g_p``, and zeroes ``p``'s (the same integers as the recount).  Stops ``pick`` first
    (-1: none), then the requester of highest degree while it is alone; returns the tied
    requesters, ascending, when there are several (the caller draws the next ``pick`` among them),
    an empty array when the highest degree is 0.  Edges: :func:`greedy_tables`."""
    n = len(deg)
    while True:
        if pick >= 0:
            p = pick
            stopped[p] = True
            for x in range(ex_f1[p], ex_f1[p + 1]):  # rows (x, p)
                if not stopped[ex_o1[x]]:
                    deg[ex_o1[x]] -= 1
            for x in range(ex_f2[p], ex_f2[p + 1]):  # rows (p, x)
                if not stopped[ex_o2[x]]:
                    deg[ex_o2[x]] -= 1
            for x in range(lq_f[p], lq_f[p + 1]):    # rows g_i <= g_p
                if not stopped[lq_o[x]]:
                    deg[lq_o[x]] += 1
            deg[p] = 0
        best = deg.max() if n else 0
        if best == 0:
            return np.empty(0, dtype=np.int64)
        ties = np.flatnonzero(deg == best)
        if len(ties) > 1:
            return ties
        pick = ties[0]


@njit(cache=True)
def merge_rows(cur_lo, cur_hi, new_lo, new_hi, src):
    """The claim corners after a decision (:func:`tm.manager._result_claims`): row ``v`` of ``lo``,
    ``hi`` (V, K, 2) is row ``src[v]`` of ``new_lo``, ``new_hi`` where ``src[v] >= 0`` (a granted
    request), else row ``v`` of ``cur_lo``, ``cur_hi``: one pass, each row read once (a copy of
    the current rows and a gather and scatter of the granted ones read the granted rows three
    times).  Copies: the same floats."""
    V, K = cur_lo.shape[0], cur_lo.shape[1]
    lo = np.empty((V, K, 2))
    hi = np.empty((V, K, 2))
    for v in range(V):
        r = src[v]
        if r >= 0:
            for k in range(K):
                lo[v, k, 0], lo[v, k, 1] = new_lo[r, k, 0], new_lo[r, k, 1]
                hi[v, k, 0], hi[v, k, 1] = new_hi[r, k, 0], new_hi[r, k, 1]
        else:
            for k in range(K):
                lo[v, k, 0], lo[v, k, 1] = cur_lo[v, k, 0], cur_lo[v, k, 1]
                hi[v, k, 0], hi[v, k, 1] = cur_hi[v, k, 0], cur_hi[v, k, 1]
    return lo, hi


@njit(cache=True, inline="always")
def _apart(A, a, B, b, tol):
    """Whether some edge of polygon ``A[a]`` has polygon ``B[b]`` beyond its support by more than
    ``tol`` (:func:`tm.geometry._separated`, one direction: unit outward edge normals of a CCW
    polygon, zero for a zero-length edge)."""
    k, m = A.shape[1], B.shape[1]
    for e in range(k):
        f = e + 1 if e + 1 < k else 0
        ex, ey = A[a, f, 0] - A[a, e, 0], A[a, f, 1] - A[a, e, 1]
        norm = np.hypot(ex, ey)
        inv = 1.0 / norm if norm > 0 else 0.0
        nx, ny = ey * inv, -ex * inv
        h = -np.inf
        for v in range(k):
            h = max(h, nx * A[a, v, 0] + ny * A[a, v, 1])
        g = np.inf
        for v in range(m):
            g = min(g, nx * B[b, v, 0] + ny * B[b, v, 1])
        if g - h > tol:
            return True
    return False


@njit(cache=True)
def sets_meet(P, p_start, p_count, Q, q_start, q_count, tol):
    """Per pair ``t``: whether some polygon of ``P[p_start[t]:+p_count[t]]`` meets some of
    ``Q[q_start[t]:+q_count[t]]`` (:func:`tm.boxes.polygon_sets_meet`): bounding boxes first,
    then the separating-axis test both ways, stopping at the first pair of polygons that meets.

    Not float for float the numpy test: its projections are ``N @ Q.T`` (a BLAS product, which
    may fuse a multiply and an add), here ``n_x q_x + n_y q_y``; the two differ only where a gap
    lies within a rounding of ``tol``, and the gate that asks decides liveness, not safety (the
    traffic manager checks every request).  ``tests/tm/test_boxes.py`` compares them."""
    n = len(p_start)
    out = np.zeros(n, dtype=np.bool_)
    for t in range(n):
        for i in range(p_start[t], p_start[t] + p_count[t]):
            plx, ply = P[i, :, 0].min(), P[i, :, 1].min()
            phx, phy = P[i, :, 0].max(), P[i, :, 1].max()
            for j in range(q_start[t], q_start[t] + q_count[t]):
                if not (plx <= Q[j, :, 0].max() and phx >= Q[j, :, 0].min() and
                        ply <= Q[j, :, 1].max() and phy >= Q[j, :, 1].min()):
                    continue
                if not _apart(P, i, Q, j, tol) and not _apart(Q, j, P, i, tol):
                    out[t] = True
                    break
            if out[t]:
                break
    return out


@njit(cache=True, inline="always")
def _pair_meets(lo1, hi1, i, lo2, hi2, j):
    """Whether box ``i`` of ``(lo1, hi1)`` meets box ``j`` of ``(lo2, hi2)`` on every axis (touching
    counts; a NaN bound meets nothing)."""
    for a in range(lo1.shape[1]):
        if not (lo1[i, a] <= hi2[j, a] and hi1[i, a] >= lo2[j, a]):
            return False
    return True


@njit(cache=True)
def any_boxes_meet(lo1, hi1, lo2, hi2):
    """Whether some box ``(lo1[i], hi1[i])`` meets some ``(lo2[j], hi2[j])`` on every axis (touching
    counts; a NaN bound meets nothing), all (n, d) / (m, d): :func:`tm.boxes.boxes_meet`, the same
    comparisons one pair at a time, stopping at the first pair that meets (numpy compares every
    pair: the junction gate asks tens of thousands of times a step, of corridors of a few boxes)."""
    for i in range(lo1.shape[0]):
        for j in range(lo2.shape[0]):
            if _pair_meets(lo1, hi1, i, lo2, hi2, j):
                return True
    return False


@njit(cache=True)
def rows_meet_any(lo1, hi1, lo2, hi2):
    """Per box ``i`` of ``(lo1, hi1)`` (n, d): whether it meets some box of ``(lo2, hi2)`` (m, d),
    touching counting, NaN meeting nothing (:func:`tm.boxes.meets_any`): :func:`any_boxes_meet`
    row by row."""
    out = np.zeros(lo1.shape[0], dtype=np.bool_)
    for i in range(lo1.shape[0]):
        for j in range(lo2.shape[0]):
            if _pair_meets(lo1, hi1, i, lo2, hi2, j):
                out[i] = True
                break
    return out
