"""Render the README's benchmark tables from the benchmarks' CSV files: one source per figure.

Usage::

    python benchmarks/render_readme.py          # rewrite the tables in README.md
    python benchmarks/render_readme.py --check  # exit 1 when README.md differs from the CSV files

Each table sits in README.md between ``<!-- table:NAME -->`` and ``<!-- /table:NAME -->``;
everything between the markers is generated (edit the CSV by re-running the benchmark, never
the README table).  Tables:

* ``traffic``: ``benchmarks/results/traffic.csv`` (``bench_traffic.py``), one row per driver, muvsim
  controller and variant (a CSV without a ``controller`` column is the paper controller's);
* ``scale``: ``benchmarks/results/scale.csv`` (``bench_scale.py``), wall seconds per simulated
  second by component;
* ``scenarios``: ``benchmarks/results/scenarios.csv`` (``bench_scenarios.py``), one row per SUMO demo
  scenario (and muvsim controller, when the CSV has authority rows), muvsim beside SUMO's drivers on
  the same demand;
* ``tm_reach``: ``benchmarks/results/tm_reach.csv`` (``bench_tm.py``), the traffic manager on
  time-indexed reach claims, per fleet size and variant.

Figures are rounded to their meaning (s to 0.1, counts whole, ratios to 0.01 or as measured).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _f(v, digits: int) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return f"{float(v):.{digits}f}"


def _count(v) -> str:
    """A count, or a mean of counts over seeds (one decimal when not whole)."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    v = float(v)
    return f"{v:.0f}" if v == round(v) else f"{v:.1f}"


def traffic_table(csv: Path = RESULTS / "traffic.csv") -> str:
    """One row per driver, muvsim controller and variant, means over seeds: arrivals of the demand, then
    delay and halts over the arrived vehicles, TM stops, collisions and the simulated length of the runs."""
    df = pd.read_csv(csv)
    if "controller" not in df:
        df["controller"] = df["driver"].map(lambda d: "paper" if d == "muvsim" else "-")
    g = lambda r, k: r[k] if k in r else None  # noqa: E731 - a column older CSVs lack: "-"
    head = ("| driver | controller | switching | check | policy | seeds | arrived / demand | delay mean / p95 (s) "
            "| halts per vehicle | time halted (s) | TM stops | collisions (SUMO / geometric) | simulated (s) |")
    lines = [head, "| " + " | ".join(["---"] * 13) + " |"]
    for _, r in df.iterrows():
        driver = "SUMO's drivers" if r["driver"] == "sumo" else r["driver"]
        lines.append(f"| {driver} | {r['controller']} | {r['switching']} | {r['check']} | {r['policy']} "
                     f"| {int(r['seeds'])} | {_count(r['arrived'])} / {_count(g(r, 'demand'))} "
                     f"| {_f(r['delay_mean_s'], 1)} / {_f(r['delay_p95_s'], 1)} "
                     f"| {_f(r['halts_per_vehicle'], 1)} | {_f(r['time_halted_s'], 1)} | {_count(r['tm_stops'])} "
                     f"| {_count(r['collisions_sumo'])} / {_count(r['collisions_geometric'])} "
                     f"| {_count(g(r, 'simulated_s'))} |")
    return "\n".join(lines)


def scale_table(csv: Path = RESULTS / "scale.csv") -> str:
    df = pd.read_csv(csv)
    head = ("| vehicles (target / mean active) | SUMO | controllers | TM | monitor | logging | other | rtf "
            "| wall vs SUMO | peak RSS |")
    lines = [head, "| " + " | ".join(["---"] * 10) + " |"]
    for _, r in df.iterrows():
        parts = [f"{int(r['target'])} / {r['active_mean']:.0f}"]
        parts += [f"{r[c + '_s_per_sim_s']:.3f}" for c in ("sumo", "controllers", "tm", "monitor", "logging",
                                                           "other")]
        parts += [f"{r['rtf_window']:.2f}", f"{r['wall_ratio']:.1f} ×", f"{r['peak_rss_mb']:.0f} MB"]
        lines.append("| " + " | ".join(parts) + " |")
    return "\n".join(lines)


def _pair(a, b, fmt) -> str:
    return f"{fmt(a)} / {fmt(b)}"


def _of(part, whole) -> str:
    """``part of whole`` (counts), ``-`` where either is missing (a run before the column existed)."""
    if any(v is None or (isinstance(v, float) and math.isnan(v)) for v in (part, whole)):
        return "-"
    return f"{int(part)} of {int(whole)}"


def scenarios_table(csv: Path = RESULTS / "scenarios.csv") -> str:
    """One row per scenario and muvsim controller: muvsim's figures beside SUMO's drivers' (the rows of
    ``driver`` muvsim, sumo).  ``controller`` paper (or no such column): the row is the scenario's name;
    another controller (``bench_scenarios.py --controller both``): ``NAME (authority)``, after it."""
    df = pd.read_csv(csv, keep_default_na=True)
    if "controller" not in df:
        df["controller"] = "paper"
    df["controller"] = df["controller"].where(df["driver"] == "muvsim", "-").fillna("paper")
    head = ("| scenario | window (s) | demand | arrived muvsim / SUMO | at rest at the end: gridlocked of all "
            "(muvsim) | mean delay muvsim / SUMO (s) "
            "| SUMO collisions muvsim / SUMO | geometric, invariant (muvsim) | undrivable (muvsim) "
            "| signals (muvsim), red crossings | rtf muvsim / SUMO | error |")
    lines = [head, "| " + " | ".join(["---"] * 12) + " |"]
    g = lambda r, k: r.get(k) if k in r else None  # noqa: E731 - a missing driver or column: "-"
    for name in dict.fromkeys(df["scenario"]):  # the CSV's order
        rows = df[df["scenario"] == name]
        b = rows[rows["driver"] == "sumo"]
        b = b.iloc[0] if len(b) else pd.Series(dtype=object)
        mus = rows[rows["driver"] == "muvsim"]
        ctrls = sorted(dict.fromkeys(mus["controller"]), key=lambda c: c != "paper") or ["paper"]
        for ctrl in ctrls:
            m = mus[mus["controller"] == ctrl]
            m = m.iloc[0] if len(m) else pd.Series(dtype=object)
            errors = "; ".join(f"{d}: {str(g(r, 'error'))[:120]}" for d, r in (("muvsim", m), ("sumo", b))
                               if isinstance(g(r, "error"), str) and g(r, "error").strip())
            signals = g(m, "signals")
            signals = signals if isinstance(signals, str) else "-"
            label = name if ctrl == "paper" else f"{name} ({ctrl})"
            lines.append(
                f"| {label} | {_count(g(m, 'duration_s') if g(m, 'duration_s') is not None else g(b, 'duration_s'))} "
                f"| {_count(g(m, 'demand'))} | {_pair(g(m, 'arrived'), g(b, 'arrived'), _count)} "
                f"| {_of(g(m, 'gridlocked_at_end'), g(m, 'stopped_at_end'))} "
                f"| {_pair(g(m, 'mean_delay_s'), g(b, 'mean_delay_s'), lambda v: _f(v, 1))} "
                f"| {_pair(g(m, 'collisions_sumo'), g(b, 'collisions_sumo'), _count)} "
                f"| {_count(g(m, 'collisions_geometric'))}, {_count(g(m, 'invariant_violations'))} "
                f"| {_count(g(m, 'undrivable'))} | {signals}, {_count(g(m, 'red_violations'))} "
                f"| {_pair(g(m, 'rtf'), g(b, 'rtf'), lambda v: _f(v, 2))} | {errors or '-'} |")
    return "\n".join(lines)


def tm_reach_table(csv: Path = RESULTS / "tm_reach.csv") -> str:
    """The time-indexed reach-claims TM case: medians over the measured steps per fleet and variant."""
    df = pd.read_csv(csv)
    head = ("| fleet (target / active) | requesting | policy | current claims | decision CPU (ms) "
            "| decision wall median / p90 (ms) | claims + boxes / broad / narrow / select (ms, wall) | reused "
            "| grants lost |")
    lines = [head, "| " + " | ".join(["---"] * 9) + " |"]
    for _, r in df.iterrows():
        lines.append(f"| {int(r['fleet'])} / {_count(r['vehicles'])} | {_count(r['requesting'])} | {r['policy']} "
                     f"| {r['claims']} | {_f(r['decide_cpu_ms'], 1)} "
                     f"| {_f(r['decide_ms'], 1)} / {_f(r['p90_decide_ms'], 1)} "
                     f"| {_f(r['claims_ms'], 1)} / {_f(r['broad_ms'], 2)} / {_f(r['narrow_ms'], 2)} / "
                     f"{_f(r['select_ms'], 2)} | {_count(r['reused'])} | {_count(r['grants_lost'])} |")
    return "\n".join(lines)


def admission_table(csv: Path = RESULTS / "admission.csv") -> str:
    """What a vehicle costs once, at admission: each part, the new method against the one it replaced."""
    df = pd.read_csv(csv)
    lines = ["| part | method | routes | waypoints (median) | ms per route (median) | ms (all routes) | × the new |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for _, r in df.iterrows():
        lines.append(f"| {r['part']} | {r['method']} | {int(r['routes'])} | {_count(r['waypoints_median'])} "
                     f"| {_f(r['ms_median'], 1)} | {_f(r['ms_total'], 0)} | {_f(r['ratio_to_new'], 2)} |")
    return "\n".join(lines)


TABLES = {"traffic": traffic_table, "scale": scale_table, "scenarios": scenarios_table, "tm_reach": tm_reach_table,
          "admission": admission_table}


def render(text: str) -> str:
    """``text`` (README.md) with every marked table regenerated."""
    for name, make in TABLES.items():
        pat = re.compile(rf"(<!-- table:{name} -->\n).*?(\n<!-- /table:{name} -->)", re.S)
        if not pat.search(text):
            raise SystemExit(f"README.md: no <!-- table:{name} --> ... <!-- /table:{name} --> markers")
        text = pat.sub(lambda m: m.group(1) + make() + m.group(2), text)
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check; exit 1 when README.md is out of date")
    ap.add_argument("--readme", default=str(ROOT / "README.md"))
    args = ap.parse_args(argv)
    path = Path(args.readme)
    old = path.read_text(encoding="utf-8")
    new = render(old)
    if args.check:
        if new != old:
            print(f"{path}: tables differ from benchmarks/results/*.csv; run python benchmarks/render_readme.py",
                  file=sys.stderr)
            return 1
        print(f"{path}: tables match benchmarks/results/*.csv")
        return 0
    path.write_text(new, encoding="utf-8")
    print(f"written: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
