"""Why each vehicle at rest at the end of a run waits, and which waits run in a circle.

A run that ends with vehicles at rest may have ended mid-queue (they would move on) or in a
gridlock: vehicles each waiting for another that waits, around a circle, for the first.  The
traffic manager's conflict edges tell which: a requester it denies waits for the vehicles whose
claims its new claim meets (:attr:`tm.manager.Decision.edges`), and a request withheld before the
decision waits for a rule (a planned stop's dwell, a red, a junction token, a pedestrian:
:class:`bridge.request_filters.RequestFilters`) -- for a junction token, on the vehicles holding it
(:attr:`tm.junctions.JunctionGate.waiting_on`).  :func:`wait_table` follows each vehicle's chain of
waits, the other's current claim first (``new-old``, ``new-fixed``: the one standing in its way),
until it reaches a vehicle that is not waiting for a vehicle (the chain's end is that one's
reason, or ``moving``) or one it has met before (``cycle``: a gridlock, for good unless a rule
breaks it).  Written as ``waits.csv`` at the end of a run; the summary's ``stopped_at_end`` and
``gridlocked_at_end`` count its rows and those whose chain ends in a cycle.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.halts import SUMO_HALT_MPS

__all__ = ["wait_table", "wait_figures", "waits_at_end", "WAIT_COLUMNS"]

#: Columns of :func:`wait_table` (``waits.csv``).
WAIT_COLUMNS = ("vehicle", "x_m", "y_m", "speed_mps", "reason", "blockers", "chain_end", "cycle")
#: The traffic manager's reason, and the order its conflict kinds are followed in.
TM_REASON = "traffic manager"
_FIRST = ("new-old", "new-fixed")


def wait_table(ids: Sequence[str], xy: np.ndarray, speed: np.ndarray, requesting: np.ndarray, go: np.ndarray,
               withheld_by: Mapping[str, str], edges: np.ndarray, edge_kinds: Sequence[str],
               rule_blockers: Mapping[str, Sequence[str]] | None = None) -> pd.DataFrame:
    """Every vehicle at rest, why it waits, and where its chain of waits ends (module notes).

    Parameters
    ----------
    ids : sequence of str
        The decision's vehicles.
    xy : ndarray, shape (n, 2)
        Their positions (m); NaN for a vehicle no longer in the network (left out).
    speed : ndarray, shape (n,)
        Their speeds (m/s); NaN for a vehicle no longer in the network.  At rest: at most
        :data:`analysis.halts.SUMO_HALT_MPS` (SUMO's halting speed, as the halt counts).
    requesting, go : ndarray of bool, shape (n,)
        The requests the traffic manager saw (after the rules' withholding) and its grants.
    withheld_by : mapping of str to str
        Vehicle id -> the rule that withheld its request before the decision.
    edges : ndarray of int, shape (E, 2)
        The decision's conflicts ``(u, v)``: ``u``'s new claim meets ``v``'s claim.
    edge_kinds : sequence of str, shape (E,)
    rule_blockers : mapping of str to sequence of str, optional
        Vehicle id -> the vehicles a rule that withheld its request makes it wait for (a junction
        token's holders); without: a withheld request's chain ends at its rule.

    Returns
    -------
    DataFrame
        :data:`WAIT_COLUMNS`, one row per vehicle at rest, in decision order: ``reason`` (``no
        request``, a rule's name, ``traffic manager`` or ``granted``), ``blockers`` (ids its new
        claim meets, ``;``-joined, the other's current claims first; for a rule, the vehicles it
        waits for there), ``chain_end`` (``cycle``,
        ``moving`` or the reason of the last vehicle of the chain) and ``cycle`` (the ids of the
        cycle it ends in, ``;``-joined, in chain order).
    """
    ids = list(ids)
    n = len(ids)
    xy = np.asarray(xy, dtype=float).reshape(n, 2)
    speed = np.asarray(speed, dtype=float).reshape(n)
    requesting = np.asarray(requesting, dtype=bool).reshape(n)
    go = np.asarray(go, dtype=bool).reshape(n)
    edges = np.asarray(edges, dtype=np.intp).reshape(-1, 2)
    kinds = [str(k) for k in edge_kinds]
    if len(kinds) != len(edges):
        raise ValueError(f"wait_table: {len(edges)} edges and {len(kinds)} kinds")
    rest = np.isfinite(speed) & (speed <= SUMO_HALT_MPS)  # at rest: halted as SUMO counts it
    first: dict[int, list[int]] = {}
    later: dict[int, list[int]] = {}
    for (u, v), k in zip(edges.tolist(), kinds):
        (first if k in _FIRST else later).setdefault(u, []).append(v)
    reason, blockers = {}, {}
    row_of = {v: i for i, v in enumerate(ids)}
    rule_blockers = rule_blockers or {}
    for i in np.flatnonzero(rest).tolist():
        if ids[i] in withheld_by:
            reason[i] = withheld_by[ids[i]]
            blockers[i] = list(dict.fromkeys(row_of[v] for v in rule_blockers.get(ids[i], ()) if v in row_of))
        elif not requesting[i]:
            reason[i] = "no request"
        elif go[i]:
            reason[i] = "granted"
        else:
            reason[i] = TM_REASON
            blockers[i] = list(dict.fromkeys(first.get(i, []) + later.get(i, [])))
    rows = []
    ends = _chain_ends(reason, blockers)
    for i in sorted(reason):
        end, cycle = ends[i]
        rows.append((ids[i], round(float(xy[i, 0]), 2), round(float(xy[i, 1]), 2), round(float(speed[i]), 3),
                     reason[i], ";".join(ids[b] for b in blockers.get(i, [])), end,
                     ";".join(ids[c] for c in cycle)))
    return pd.DataFrame(rows, columns=list(WAIT_COLUMNS))


def _chain_ends(reason: dict, blockers: dict) -> dict:
    """Where the chain of waits from each vehicle of ``reason`` ends: ``{i: (end, cycle members)}``, the
    members of a cycle from where the chain enters it.  Each vehicle's answer is its first blocker's
    (or its own end), so every vehicle is walked once: linear in the vehicles at rest."""
    out: dict = {}
    for start in reason:
        path: list[int] = []
        at: dict[int, int] = {}
        cur = start
        while cur not in out:
            if cur in at:  # a new cycle: each member's chain runs around it from itself
                cyc = path[at[cur]:]
                for j, m in enumerate(cyc):
                    out[m] = ("cycle", cyc[j:] + cyc[:j])
                del path[at[cur]:]
                break
            if cur not in reason:
                out[cur] = ("moving", [])
                break
            if not blockers.get(cur):
                out[cur] = (reason[cur], [])
                break
            at[cur] = len(path)
            path.append(cur)
            cur = blockers[cur][0]
        for m in reversed(path):  # the tail leading here: each ends where its first blocker does
            out[m] = out[blockers[m][0]]
    return out


def wait_figures(waits: pd.DataFrame) -> dict:
    """``stopped_at_end`` (vehicles at rest), ``gridlocked_at_end`` (of them, those whose chain of waits
    ends in a cycle) and ``wait_cycles`` (how many distinct cycles)."""
    cyc = waits[waits["chain_end"] == "cycle"]["cycle"] if len(waits) else pd.Series([], dtype=str)
    distinct = {frozenset(c.split(";")) for c in cyc}
    return dict(stopped_at_end=int(len(waits)), gridlocked_at_end=int(len(cyc)), wait_cycles=len(distinct))


def waits_at_end(sim) -> pd.DataFrame:
    """:func:`wait_table` of a :class:`bridge.cosim.Cosim` run's last decision, with the positions and
    speeds of its vehicles now (an empty table before the first decision or without requests)."""
    dec = getattr(sim, "last_decision", None)
    if dec is None or not len(dec.ids):
        return pd.DataFrame([], columns=list(WAIT_COLUMNS))
    where = {}
    for g in sim.groups.values():
        if g.ids:
            S = sim.world_states(g)
            where.update(zip(g.ids, S[:, :4].tolist()))
    rows = np.array([where.get(v, [np.nan] * 4) for v in dec.ids], dtype=float).reshape(len(dec.ids), 4)
    filters = getattr(sim, "filters", None)
    gate = getattr(filters, "junctions", None)
    return wait_table(dec.ids, rows[:, :2], np.hypot(rows[:, 2], rows[:, 3]), dec.requesting, dec.go,
                      getattr(filters, "withheld_by", {}), dec.edges, dec.edge_kinds,
                      getattr(gate, "waiting_on", {}))
