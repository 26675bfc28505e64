"""KPI tables of a run: one row per vehicle, one row per step, and the summary figures.

Everything a run reports is computed here from two tables:

* :func:`vehicle_table` -- one row per vehicle of the demand, built from the
  loop's :class:`bridge.cosim.VehicleRecord` accumulators (and SUMO's
  ``tripinfo.xml`` where it exists);
* :func:`step_table` -- one row per step, built from the loop's step rows;

and :func:`summarise` derives the figures of ``summary.json`` from these two
tables only (plus the loop's safety counters, which have no per-row source).

Definitions (all times in simulated seconds):

``admission_delay_s``
    admission time − requested departure (condition (12) may hold a vehicle back).
``travel_time_s``
    arrival − admission.
``free_flow_s``
    the route's time at ``min(v_max, lane limit under the front)`` (the record's
    ``free_flow_s``, :func:`controllers.speed_limits.free_flow_time`), else route length /
    the class's speed bound ``v_max`` (along the road for road-frame classes, per axis for the
    paper's world-frame classes -- a diagonal route can then be faster than "free flow" and its
    delay negative).
``delay_s``
    travel time − free-flow time.
``stop_episodes``, ``time_stopped_s``
    a vehicle is *stopped* in a step in which the traffic manager denied its request
    (it holds its waypoint); an episode is a maximal run of such steps.  Not defined for
    SUMO's own drivers (NaN in a baseline's table).
``halt_episodes``, ``time_halted_s``
    speed at most 0.1 m/s after a step, except at the last waypoint
    (:class:`analysis.halts.HaltCounter`); SUMO's ``waitingCount`` and ``waitingTime``
    for a baseline, so the two compare.  NaN when the run had no counter.
``speed_limit_excess_max``
    the largest ``speed - lane limit under the front bumper`` over the vehicle's run, at least
    0 (m/s; a traffic-rule KPI, not a safety counter).  On a gap between two waypoints that
    holds a lane change the lower of the two limits counts (the boundary lies somewhere in the
    gap, at most delta long).  NaN for a vehicle that never drove and in a baseline's table.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["VEHICLE_COLUMNS", "STEP_COLUMNS", "vehicle_table", "step_table", "per_second", "read_tripinfo",
           "baseline_vehicle_table", "summarise", "timing_means", "run_tables"]

#: Columns of the per-vehicle table, in order.
VEHICLE_COLUMNS = ("id", "vclass", "departure_s", "admitted_s", "admission_delay_s", "arrival_s",
                   "travel_time_s", "route_length_m", "free_flow_s", "delay_s", "sumo_time_loss_s", "denials",
                   "stop_episodes", "time_stopped_s", "halt_episodes", "time_halted_s", "mean_speed_mps",
                   "closest_m", "speed_limit_excess_max", "depart_speed_mps")

#: A vehicle counts in ``vehicles_over_limit`` when its speed exceeded its lane's limit by more than
#: this (m/s): the excess the controller cannot prevent, for the urban classes (d̄ = 0.005 in
#: position and velocity, ū = 3, a_c = 2.5, Ts = 0.1) at limits >= 3 m/s.  It bounds the NOMINAL
#: next speed (the disturbance adds d̄) at the front position predicted one step on (off by up to
#: d̄ + ū Ts^2 / 2, which the braking envelope turns into a_c (d̄ + ū Ts^2/2) / v_lim <= 0.017).
SPEED_LIMIT_KPI_TOL = 0.025

#: Columns of the per-step table every run has (others, e.g. ``min_separation_m``, are kept).
STEP_COLUMNS = ("t_s", "active", "requests", "grants", "denials", "edges", "admitted", "tm_ms", "tm_decide_ms",
                "request_ms", "gate_ms", "controller_ms", "world_ms", "logging_ms")


def read_tripinfo(path) -> pd.DataFrame:
    """SUMO's ``tripinfo.xml`` as a table (one row per finished trip).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    DataFrame
        Columns ``id, vtype, depart_s, requested_depart_s, depart_delay_s, arrival_s, duration_s,
        route_length_m, time_loss_s, waiting_time_s, waiting_count, depart_speed_mps``; empty when the
        file has no trip.
    """
    cols = ["id", "vtype", "depart_s", "requested_depart_s", "depart_delay_s", "arrival_s", "duration_s",
            "route_length_m", "time_loss_s", "waiting_time_s", "waiting_count", "depart_speed_mps"]
    rows = []
    for t in ET.parse(path).getroot().iter("tripinfo"):
        f = lambda k: float(t.get(k, "nan"))  # noqa: E731
        rows.append({"id": t.get("id"), "vtype": t.get("vType", ""), "depart_s": f("depart"),
                     "requested_depart_s": f("depart") - f("departDelay"), "depart_delay_s": f("departDelay"),
                     "arrival_s": f("arrival"), "duration_s": f("duration"), "route_length_m": f("routeLength"),
                     "time_loss_s": f("timeLoss"), "waiting_time_s": f("waitingTime"),
                     "waiting_count": int(t.get("waitingCount", 0)), "depart_speed_mps": f("departSpeed")})
    return pd.DataFrame(rows, columns=cols)


def vehicle_table(records, v_max: dict, Ts: float, tripinfo: pd.DataFrame | None = None,
                  halts=None) -> pd.DataFrame:
    """One row per vehicle from the loop's accumulators.

    Parameters
    ----------
    records : iterable of VehicleRecord
        ``Cosim.records.values()`` (or hand-made records).
    v_max : dict of str to float
        Speed bound (m/s) of every class named by a record.
    Ts : float
        Step length (s).
    tripinfo : DataFrame, optional
        :func:`read_tripinfo` of the run; fills ``sumo_time_loss_s`` for the trips it has.
    halts : HaltCounter, optional
        The run's :class:`analysis.halts.HaltCounter`; without it the halt columns are NaN.

    Returns
    -------
    DataFrame
        Columns :data:`VEHICLE_COLUMNS`; times of vehicles not admitted / not arrived are NaN.
    """
    rows = []
    for r in records:
        adm = np.nan if r.admitted_s is None else float(r.admitted_s)
        arr = np.nan if r.arrived_s is None else float(r.arrived_s)
        ff = getattr(r, "free_flow_s", None)
        free = float(ff) if ff is not None else float(r.route_length_m) / float(v_max[r.vclass])
        travel = arr - adm
        exc = float(getattr(r, "speed_limit_excess", -np.inf))
        rows.append({
            "id": r.id, "vclass": r.vclass, "departure_s": float(r.depart_s), "admitted_s": adm,
            "admission_delay_s": adm - float(r.depart_s), "arrival_s": arr, "travel_time_s": travel,
            "route_length_m": float(r.route_length_m), "free_flow_s": free, "delay_s": travel - free,
            "sumo_time_loss_s": np.nan, "denials": int(r.denials), "stop_episodes": int(r.stop_episodes),
            "time_stopped_s": int(r.stopped_steps) * Ts,
            "halt_episodes": np.nan if halts is None else halts.episodes.get(r.id, 0),
            "time_halted_s": np.nan if halts is None else halts.steps.get(r.id, 0) * Ts,
            "mean_speed_mps": float(r.speed_sum) / r.steps if r.steps else np.nan,
            "closest_m": float(r.closest_m),
            "speed_limit_excess_max": max(exc, 0.0) if np.isfinite(exc) else np.nan,
            "depart_speed_mps": np.nan if r.admitted_s is None else float(getattr(r, "depart_speed_mps", 0.0)),
        })
    df = pd.DataFrame(rows, columns=list(VEHICLE_COLUMNS))
    if tripinfo is not None and len(tripinfo) and len(df):
        loss = tripinfo.set_index("id")["time_loss_s"]
        df["sumo_time_loss_s"] = df["id"].map(loss).astype(float)
    return df


def baseline_vehicle_table(tripinfo: pd.DataFrame, v_max: dict, class_of=None) -> pd.DataFrame:
    """The per-vehicle table of a run by SUMO's own drivers, from its tripinfo.

    Parameters
    ----------
    tripinfo : DataFrame
        :func:`read_tripinfo`.
    v_max : dict of str to float
        Speed bound of each muvsim class (for ``free_flow_s``, as in :func:`vehicle_table`).
    class_of : callable, optional
        vType id -> muvsim class name; default: ``bus``/``truck`` if the id says so, else ``car``.

    Returns
    -------
    DataFrame
        Columns :data:`VEHICLE_COLUMNS` (``denials``, ``stop_episodes``, ``time_stopped_s`` and
        ``closest_m`` NaN, ``halt_episodes`` = waitingCount, ``time_halted_s`` = waitingTime,
        ``mean_speed_mps`` = route length / duration).  Only trips SUMO finished are in its tripinfo.
    """
    if class_of is None:
        def class_of(vt: str) -> str:
            vt = vt.lower()
            return "bus" if "bus" in vt else "truck" if "truck" in vt else "car"
    ti = tripinfo
    vcl = ti["vtype"].map(class_of) if len(ti) else pd.Series(dtype=str)
    free = ti["route_length_m"] / vcl.map(v_max).astype(float) if len(ti) else pd.Series(dtype=float)
    df = pd.DataFrame({
        "id": ti["id"], "vclass": vcl, "departure_s": ti["requested_depart_s"], "admitted_s": ti["depart_s"],
        "admission_delay_s": ti["depart_delay_s"], "arrival_s": ti["arrival_s"], "travel_time_s": ti["duration_s"],
        "route_length_m": ti["route_length_m"], "free_flow_s": free, "delay_s": ti["duration_s"] - free,
        "sumo_time_loss_s": ti["time_loss_s"], "denials": np.nan, "stop_episodes": np.nan,
        "time_stopped_s": np.nan, "halt_episodes": ti["waiting_count"], "time_halted_s": ti["waiting_time_s"],
        "mean_speed_mps": ti["route_length_m"] / ti["duration_s"].where(ti["duration_s"] > 0),
        "closest_m": np.nan, "speed_limit_excess_max": np.nan, "depart_speed_mps": ti["depart_speed_mps"],
    }, columns=list(VEHICLE_COLUMNS))
    return df


def step_table(step_rows) -> pd.DataFrame:
    """One row per step from the loop's step rows (``Cosim.step_rows``).

    Missing timing columns (e.g. ``logging_ms`` when nothing is logged) are 0; ``edges`` is
    0 on steps without vehicles.
    """
    df = pd.DataFrame(list(step_rows))
    for c in STEP_COLUMNS:
        if c not in df:
            df[c] = 0.0 if c.endswith("_ms") else 0
    df["edges"] = df["edges"].fillna(0).astype(int)
    first = [c for c in STEP_COLUMNS if c in df]
    return df[first + [c for c in df.columns if c not in first]]


def per_second(steps: pd.DataFrame, period_s: float = 1.0) -> pd.DataFrame:
    """The step table aggregated over periods of ``period_s`` (for long runs).

    Counts (requests, grants, denials, edges, admitted) are summed, ``active`` and the
    timings (``*_ms``) averaged (per step), ``min_separation_m`` minimised; ``t_s`` is
    the period's start.
    """
    if not len(steps):
        return steps.copy()
    key = (np.floor(steps["t_s"] / period_s + 1e-9) * period_s).round(6)
    agg = {}
    for c in steps.columns:
        if c == "t_s":
            continue
        if c in ("requests", "grants", "denials", "edges", "admitted", "footprint_overlaps", "claim_violations"):
            agg[c] = "sum"
        elif c == "min_separation_m":
            agg[c] = "min"
        else:
            agg[c] = "mean"
    out = steps.groupby(key).agg(agg)
    ms = [c for c in out.columns if c.endswith("_ms")]
    out[ms] = out[ms].round(4)
    out.index.name = "t_s"
    out.insert(0, "steps", steps.groupby(key).size())
    return out.reset_index()


def summarise(steps: pd.DataFrame, vehicles: pd.DataFrame, Ts: float) -> dict:
    """Summary figures computed from the two tables only.

    Returns
    -------
    dict
        ``steps, simulated_s, vehicles, vehicles_arrived, finished, collisions_geometric``
        (sum of per-step footprint overlaps), ``min_separation_m, stop_commands`` (denied
        requests), ``mean_travel_time_s, mean_delay_s, mean_admission_delay_s, stop_episodes,
        time_stopped_s, halt_episodes, time_halted_s`` (totals; halts None without a counter),
        ``throughput_vph`` (arrivals per simulated hour), ``speed_limit_excess_max`` (m/s, the
        largest over vehicles; None without one) and ``vehicles_over_limit`` (vehicles whose excess
        is above ``SPEED_LIMIT_KPI_TOL``; traffic-rule figures, not safety counters).  Wall times
        are not figures of the run (see :func:`timing_means`).
    """
    n = int(len(steps))
    arrived = vehicles["arrival_s"].notna() if len(vehicles) else pd.Series(dtype=bool)
    sim_s = round(n * Ts, 3)

    def mean(s):
        s = s.dropna()
        return float(s.mean()) if len(s) else None

    min_sep = float(steps["min_separation_m"].min()) if "min_separation_m" in steps and n else float("inf")
    if np.isnan(min_sep):  # no step had two vehicles
        min_sep = float("inf")
    out = {
        "steps": n, "simulated_s": sim_s, "vehicles": int(len(vehicles)),
        "vehicles_arrived": int(arrived.sum()), "finished": bool(len(vehicles)) and bool(arrived.all()),
        "collisions_geometric": int(steps["footprint_overlaps"].fillna(0).sum()) if "footprint_overlaps" in steps
        else 0,
        "min_separation_m": min_sep,
        "stop_commands": int(steps["denials"].sum()) if n else 0,
        "mean_travel_time_s": mean(vehicles["travel_time_s"]) if len(vehicles) else None,
        "mean_delay_s": mean(vehicles["delay_s"]) if len(vehicles) else None,
        "mean_admission_delay_s": mean(vehicles["admission_delay_s"]) if len(vehicles) else None,
        "stop_episodes": int(vehicles["stop_episodes"].sum()) if len(vehicles) else 0,
        "time_stopped_s": round(float(vehicles["time_stopped_s"].sum()), 6) if len(vehicles) else 0.0,
        "halt_episodes": int(vehicles["halt_episodes"].sum())
        if len(vehicles) and vehicles["halt_episodes"].notna().any() else None,
        "time_halted_s": round(float(vehicles["time_halted_s"].sum()), 6)
        if len(vehicles) and vehicles["time_halted_s"].notna().any() else None,
        "throughput_vph": round(float(arrived.sum()) * 3600.0 / sim_s, 3) if sim_s > 0 else None,
    }
    exc = vehicles["speed_limit_excess_max"].dropna() if "speed_limit_excess_max" in vehicles \
        else pd.Series(dtype=float)
    out["speed_limit_excess_max"] = round(float(exc.max()), 6) if len(exc) else None
    out["vehicles_over_limit"] = int((exc > SPEED_LIMIT_KPI_TOL).sum()) if len(exc) else None
    return out


def timing_means(steps: pd.DataFrame) -> dict:
    """Mean wall milliseconds per step of each part of the loop (``tm_ms, controller_ms, world_ms,
    logging_ms``).  Kept out of :func:`summarise`: wall times differ between identical runs."""
    return {c: round(float(steps[c].mean()), 4) if c in steps and len(steps) else 0.0
            for c in ("tm_ms", "controller_ms", "world_ms", "logging_ms")}


def run_tables(sim, tripinfo=None, waits=None) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """Summary figures, per-step table and per-vehicle table of a (possibly partial) :class:`Cosim` run.

    Parameters
    ----------
    sim : bridge.cosim.Cosim
    tripinfo : path-like, optional
        SUMO's tripinfo of the run, if it exists (read for ``sumo_time_loss_s``).
    waits : DataFrame, optional
        :func:`analysis.waits.waits_at_end` of ``sim``, if the caller has it already (else made here).

    Returns
    -------
    figures : dict
        :func:`summarise` of the tables plus the loop's safety counters
        (``collisions_world, invariant_violations, claim_violations, footprint_overlaps,
        constraint_violations``), :func:`analysis.safety.verdict` of them (``safe``,
        ``safety_violations``), and the junction layer's ``zones``, ``zones_ignored`` (zones it does
        not use), ``junction_tokens`` (tokens handed out), ``junction_given_back`` (at red lights)
        ``junction_withheld`` (requests withheld for want of one) and ``junction_chain_revoked``
        (tokens taken back in the hand-out because a chained zone's was not free,
        :meth:`tm.authority_gate.AuthorityGate._hand_out`) and ``junction_ordered`` (tokens taken after
        holders whose corridors the taker's meets: ordered entry, :meth:`tm.authority_gate.AuthorityGate._after`),
        and at the last step ``stopped_at_end``, ``gridlocked_at_end``, ``wait_cycles``
        (:func:`analysis.waits.wait_figures`).
    steps, vehicles : DataFrame
    """
    from controllers.classes import builtin_classes

    classes = dict(builtin_classes())
    classes.update(getattr(sim, "classes", {}))
    Ts = float(sim.settings.Ts)
    ti = None
    if tripinfo is not None and Path(tripinfo).exists():
        try:
            ti = read_tripinfo(tripinfo)
        except ET.ParseError:  # SUMO still writing or died: no time loss then
            ti = None
    from analysis.halts import HaltCounter

    halts = next((o for o in getattr(sim, "observers", []) if isinstance(o, HaltCounter)), None)
    if hasattr(sim, "flush_records"):  # accumulators of the vehicles still driving
        sim.flush_records()
    steps = step_table(sim.step_rows)
    vehicles = vehicle_table(sim.records.values(), {c: vc.v_max for c, vc in classes.items()}, Ts, ti, halts)
    figures = summarise(steps, vehicles, Ts)
    figures.update(
        collisions_world=len(sim.collisions_world),
        invariant_violations=int(sim.invariant_violations + sim.monitor.claim_violations),
        claim_violations=int(sim.monitor.claim_violations),
        footprint_overlaps=int(sim.monitor.footprint_overlaps),
        tube_escapes=int(getattr(sim.monitor, "tube_escapes", 0)),
        body_window_exits=int(getattr(sim, "body_window_exits", 0)),
        constraint_violations=int(sim.constraint_violations))
    from analysis.safety import verdict
    from analysis.waits import wait_figures, waits_at_end

    figures.update(verdict(figures))
    figures.update(wait_figures(waits_at_end(sim) if waits is None else waits))
    gate = getattr(sim, "junctions", None)  # the junction liveness layer (tm.junctions, tm.authority_gate)
    if gate is not None:
        figures.update(zones=len(gate.zones), zones_ignored=int(getattr(sim, "zones_ignored", 0)),
                       junction_tokens=int(gate.tokens_granted), junction_given_back=int(gate.tokens_given_back),
                       junction_withheld=int(gate.requests_withheld),
                       junction_chain_revoked=int(getattr(gate, "chain_revoked", 0)),
                       junction_ordered=int(getattr(gate, "ordered_granted", 0)))
    return figures, steps, vehicles
