"""Plots of a run (``muvsim report --plots``, ``muvsim run --plots``), written into ``RUN_DIR/plots``.

* ``trajectories.png``: every vehicle's path with the waypoints it used (the paper's Fig. 3);
* ``membership.png``: membership index ``l`` of chosen vehicles over time (Fig. 5);
* ``delay.png``: distribution (empirical CDF) of per-vehicle delay, against another run if given;
* ``stops.png``: distributions of halts (speed <= 0.1 m/s, comparable with SUMO's drivers) and
  of TM stops (denied requests) per vehicle, and of the time spent so, likewise.

The first two need the run's ``run.mcap`` (``--log summary`` or ``full``); the
last two its per-vehicle table.  matplotlib's Agg backend is selected inside
:func:`write_plots`, never at import.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["write_plots", "PLOT_KINDS"]

PLOT_KINDS = ("trajectories", "membership", "delay", "stops")


def _ecdf(ax, x, label):
    x = np.sort(np.asarray(x, dtype=float)[np.isfinite(np.asarray(x, dtype=float))])
    if len(x):
        ax.step(x, np.arange(1, len(x) + 1) / len(x), where="post", label=f"{label} (n={len(x)})")


def _legend(ax):
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no vehicle arrived", transform=ax.transAxes, ha="center", va="center")


def _trajectories(fig, states):
    ax = fig.add_subplot(111)
    for vid, g in states.groupby("id", sort=True):
        line, = ax.plot(g["x_m"], g["y_m"], lw=1.2)
        w = g[["wx_m", "wy_m"]].drop_duplicates()
        ax.plot(w["wx_m"], w["wy_m"], "o", ms=2.5, color=line.get_color(), alpha=0.6)
        ax.annotate(str(vid), (g["x_m"].iloc[0], g["y_m"].iloc[0]), fontsize=6)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("trajectories (lines) and waypoints used (dots)")


def _membership(fig, states, vehicles, count=4):
    chosen = []
    if vehicles is not None and len(vehicles):
        present = set(states["id"])
        chosen = [v for v in vehicles.sort_values(["stop_episodes", "id"], ascending=[False, True])["id"]
                  if v in present][:count]
    if not chosen:
        chosen = sorted(states["id"].unique())[:count]
    axes = fig.subplots(len(chosen), 1, sharex=True, squeeze=False)[:, 0]
    for ax, vid in zip(axes, chosen):
        g = states[states["id"] == vid]
        ax.step(g["t_s"], g["index"], where="post", lw=1.0)
        ax.set_ylabel(f"l ({vid})", fontsize=8)
    axes[0].set_title("membership index of the vehicles stopped most")
    axes[-1].set_xlabel("t (s)")


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

    mcap = run_dir / "run.mcap"
    if mcap.exists():
        states = read_vehicle_states(mcap)
        if len(states):
            fig = plt.figure(figsize=(7, 7))
            _trajectories(fig, states)
            save(fig, "trajectories")
            fig = plt.figure(figsize=(8, 6))
            _membership(fig, states, a.vehicles)
            save(fig, "membership")
    runs = [(a.label, a.vehicles)] + ([(b.label, b.vehicles)] if b is not None else [])
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, v in runs:
        _ecdf(ax, v.loc[v["arrival_s"].notna(), "delay_s"], label)
    ax.set_xlabel("delay = travel time - free-flow time (s)")
    ax.set_ylabel("fraction of arrived vehicles")
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
    save(fig, "stops")
    return written
