"""Plots of a run (``muvsim report --plots``, ``muvsim run --plots``), written into ``RUN_DIR/plots``.

* ``timespace.png``: time-space diagram of the busiest routes (distance along the route over
  time, one line per vehicle, coloured moving / halted / TM-stopped): the traffic engineer's view
  of stops, queues and waves;
* ``trajectories.png``: every vehicle's path in the plane coloured by its state, departures and
  arrivals marked, the waypoints used (the paper's Fig. 3);
* ``membership.png``: membership index ``l`` over time of the vehicles halted longest (Fig. 5),
  TM stops shaded;
* ``delay.png``: distribution (empirical CDF) of per-vehicle delay, against another run if given;
* ``stops.png``: distributions of halts (speed <= 0.1 m/s, comparable with SUMO's drivers) and
  of TM stops (denied requests) per vehicle, and of the time spent so, likewise.

Every figure's title names the scenario, the run directory and the seed.  The first three
need the run's ``run.mcap`` (``--log summary`` or ``full``); the last two its per-vehicle
table.  matplotlib's Agg backend is selected inside :func:`write_plots`, never at import.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from analysis.halts import SUMO_HALT_MPS

__all__ = ["write_plots", "PLOT_KINDS", "STATE_COLOURS", "vehicle_states_with_state", "busiest_routes",
           "read_denials"]

PLOT_KINDS = ("timespace", "trajectories", "membership", "delay", "stops")

#: Colour of each state of a vehicle in a step.
STATE_COLOURS = {"moving": "#2b7bba", "halted": "#f0a30a", "TM-stopped": "#d7301f"}

#: A vehicle at most this fast (m/s) is halted (SUMO's waiting definition, :mod:`analysis.halts`).
HALT_SPEED_MPS = SUMO_HALT_MPS

#: Time-space and trajectory plots draw every this many steps (0.5 s at Ts = 0.1 s).
PLOT_EVERY = 5


def read_denials(path) -> "set[tuple[float, str]]":
    """``(t_s, id)`` of every denied request in a ``run.mcap`` (channel ``/tm/decision``)."""
    from mcap.reader import make_reader

    out = set()
    with open(path, "rb") as fh:
        for _, _, msg in make_reader(fh).iter_messages(topics=["/tm/decision"]):
            m = json.loads(msg.data)
            t = round(float(m["t_s"]), 6)
            out.update((t, v) for v in m.get("denied", []))
    return out


def vehicle_states_with_state(states, denials) -> "pd.DataFrame":
    """``states`` (:func:`analysis.mcap_log.read_vehicle_states`) with ``state`` (moving / halted /
    TM-stopped, TM-stopped first) and ``s_m``, the distance each vehicle has travelled so far."""
    df = states.sort_values(["id", "t_s"]).reset_index(drop=True)
    speed = np.hypot(df["vx_mps"].to_numpy(float), df["vy_mps"].to_numpy(float))
    state = np.where(speed <= HALT_SPEED_MPS, "halted", "moving").astype(object)
    if denials:
        key = list(zip(df["t_s"].round(6), df["id"]))
        state[np.fromiter((k in denials for k in key), bool, len(key))] = "TM-stopped"
    df["state"] = state
    step = np.hypot(df.groupby("id")["x_m"].diff().fillna(0.0), df.groupby("id")["y_m"].diff().fillna(0.0))
    df["s_m"] = step.groupby(df["id"]).cumsum()
    return df


def busiest_routes(states, count: int = 3) -> list[tuple[str, list[str]]]:
    """The ``count`` routes most vehicles drove, as ``(label, vehicle ids)``.

    A route is the vehicles' first and last waypoint (rounded to 1 m) and their waypoint count:
    on a road network vehicles with the same origin, destination and waypoint count drove the
    same path.
    """
    g = states.sort_values("t_s").groupby("id")
    first, last = g.first(), g.last()
    key = (first["wx_m"].round().astype(int).astype(str) + "," + first["wy_m"].round().astype(int).astype(str)
           + " -> " + last["wx_m"].round().astype(int).astype(str) + "," + last["wy_m"].round().astype(int).astype(str)
           + " (" + first["waypoints"].astype(str) + " waypoints)")
    groups = key.groupby(key).groups
    ranked = sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0]))[:count]
    return [(label, sorted(ids)) for label, ids in ranked]


def _coloured_lines(ax, df, xcol, ycol):
    """One line per vehicle, each segment coloured by the state at its start."""
    from matplotlib.collections import LineCollection

    for state, colour in STATE_COLOURS.items():
        segs = []
        for _, g in df.groupby("id", sort=False):
            g = g.iloc[::PLOT_EVERY] if len(g) > 2 * PLOT_EVERY else g
            xy = g[[xcol, ycol]].to_numpy(float)
            if len(xy) < 2:
                continue
            m = (g["state"].to_numpy() == state)[:-1]
            if m.any():
                segs.append(np.stack([xy[:-1][m], xy[1:][m]], axis=1))
        if segs:
            ax.add_collection(LineCollection(np.concatenate(segs), colors=colour, linewidths=1.0, label=state))
    ax.autoscale()


def _title(run) -> str:
    s = run.summary
    seed = s.get("seed")
    return f"{s.get('scenario', '?')} - run {run.path.name}" + (f" (seed {seed})" if seed is not None else "") + \
        (" - SUMO's drivers" if run.baseline else "")


def _ecdf(ax, x, label):
    x = np.sort(np.asarray(x, dtype=float)[np.isfinite(np.asarray(x, dtype=float))])
    if len(x):
        ax.step(x, np.arange(1, len(x) + 1) / len(x), where="post", label=f"{label} (n={len(x)})")


def _legend(ax):
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no vehicle arrived", transform=ax.transAxes, ha="center", va="center")


def _timespace(fig, df, title):
    routes = busiest_routes(df)
    axes = fig.subplots(len(routes), 1, squeeze=False)[:, 0]
    for ax, (label, ids) in zip(axes, routes):
        _coloured_lines(ax, df[df["id"].isin(ids)], "t_s", "s_m")
        ax.set_ylabel("distance along route (m)")
        ax.set_title(f"route {label}: {len(ids)} vehicles", fontsize=9)
    axes[-1].set_xlabel("simulated time (s)")
    axes[0].legend(loc="upper left", fontsize=7)
    fig.suptitle(f"time-space diagram of the busiest routes\n{title}", fontsize=10)


def _trajectories(fig, df, vehicles, title):
    ax = fig.add_subplot(111)
    _coloured_lines(ax, df, "x_m", "y_m")
    w = df[["wx_m", "wy_m"]].drop_duplicates()
    ax.plot(w["wx_m"], w["wy_m"], ".", ms=1.5, color="0.6", label="waypoints used", zorder=0)
    g = df.groupby("id")
    first, last = g.first(), g.last()
    ax.plot(first["x_m"], first["y_m"], "^", ms=4, color="k", label="departure", ls="none")
    arrived = set(vehicles.loc[vehicles["arrival_s"].notna(), "id"]) if vehicles is not None else set()
    arr = last[last.index.isin(arrived)]
    out = last[~last.index.isin(arrived)]
    ax.plot(arr["x_m"], arr["y_m"], "o", ms=5, mfc="none", mec="#1a9850", mew=1.2, ls="none",
            label=f"arrival ({len(arr)})")
    if len(out):
        ax.plot(out["x_m"], out["y_m"], "x", ms=4, color="k", ls="none", label=f"not arrived, last position ({len(out)})")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7, loc="upper right", framealpha=0.8)
    ax.set_title(f"paths coloured by state, departures and arrivals\n{title}", fontsize=10)


def halted_longest(vehicles, present, count: int = 4) -> list[str]:
    """The ``count`` vehicles (of ``present``) halted longest (``time_halted_s``; TM stops break ties)."""
    if vehicles is None or not len(vehicles):
        return sorted(present)[:count]
    v = vehicles[vehicles["id"].isin(present)].copy()
    v["_h"] = v["time_halted_s"].fillna(-1.0)
    v["_s"] = v["time_stopped_s"].fillna(-1.0)
    return list(v.sort_values(["_h", "_s", "id"], ascending=[False, False, True])["id"][:count])


def _membership(fig, df, vehicles, title, count=4):
    chosen = halted_longest(vehicles, set(df["id"]), count)
    axes = fig.subplots(len(chosen), 1, sharex=True, squeeze=False)[:, 0]
    halted = dict(zip(vehicles["id"], vehicles["time_halted_s"])) if vehicles is not None else {}
    for ax, vid in zip(axes, chosen):
        g = df[df["id"] == vid]
        ax.step(g["t_s"], g["index"], where="post", lw=1.0, color="k")
        stopped = g["state"].to_numpy() == "TM-stopped"
        ax.fill_between(g["t_s"], 0, g["index"].max() or 1, where=stopped, step="post",
                        color=STATE_COLOURS["TM-stopped"], alpha=0.25, lw=0, label="TM-stopped")
        h = halted.get(vid)
        ax.set_ylabel(f"l, {vid}", fontsize=8)
        ax.set_title(f"{vid}: halted {h:.1f} s" if h == h and h is not None else vid, fontsize=8, loc="left")
    axes[0].legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("simulated time (s)")
    fig.suptitle(f"membership index l of the vehicles halted longest\n{title}", fontsize=10)


def _arrived_note(a, b=None) -> str:
    def one(r):
        v = r.vehicles
        total = r.summary.get("vehicles_total", r.summary.get("vehicles", len(v)))
        return f"{int(v['arrival_s'].notna().sum())} of {total} arrived"
    return one(a) + (f"; vs {one(b)}" if b is not None else "")


def write_plots(run_dir, vs_dir=None) -> dict:
    """Write every plot the run's files allow; return ``{kind: path}``.

    Parameters
    ----------
    run_dir : path-like
        A run directory (``muvsim run --out``).
    vs_dir : path-like, optional
        Another run of the same demand (e.g. ``--baseline sumo``) drawn in the distributions.
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    from analysis.mcap_log import read_vehicle_states
    from analysis.report import load_run

    run_dir = Path(run_dir)
    dest = run_dir / "plots"
    dest.mkdir(parents=True, exist_ok=True)
    written = {}
    a = load_run(run_dir)
    b = load_run(vs_dir) if vs_dir is not None else None

    def save(fig, kind):
        path = dest / f"{kind}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=120)
        plt.close(fig)
        written[kind] = path

    title = _title(a)
    mcap = run_dir / "run.mcap"
    if mcap.exists():
        states = read_vehicle_states(mcap)
        if len(states):
            df = vehicle_states_with_state(states, read_denials(mcap))
            fig = plt.figure(figsize=(9, 9))
            _timespace(fig, df, title)
            save(fig, "timespace")
            fig = plt.figure(figsize=(8, 8))
            _trajectories(fig, df, a.vehicles, title)
            save(fig, "trajectories")
            fig = plt.figure(figsize=(8, 6))
            _membership(fig, df, a.vehicles, title)
            save(fig, "membership")
    runs = [(a.label, a.vehicles)] + ([(b.label, b.vehicles)] if b is not None else [])
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, v in runs:
        _ecdf(ax, v.loc[v["arrival_s"].notna(), "delay_s"], label)
    ax.set_xlabel("delay = travel time - free-flow time (s)")
    ax.set_ylabel("fraction of arrived vehicles")
    ax.set_title(f"delay of the arrived vehicles ({_arrived_note(a, b)})\n{title}", fontsize=9)
    _legend(ax)
    save(fig, "delay")
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    cols = (("halt_episodes", "halts per vehicle (speed <= 0.1 m/s)"),
            ("time_halted_s", "time halted per vehicle (s)"),
            ("stop_episodes", "stops per vehicle (denied TM requests)"),
            ("time_stopped_s", "time stopped per vehicle (s)"))
    for ax, (col, xlabel) in zip(axes.ravel(), cols):
        for label, v in runs:
            _ecdf(ax, v.loc[v["arrival_s"].notna(), col], label)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("fraction of arrived vehicles")
        _legend(ax)
    fig.suptitle(f"halts and TM stops of the arrived vehicles ({_arrived_note(a, b)})\n{title}", fontsize=10)
    save(fig, "stops")
    return written
