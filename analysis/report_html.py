"""``RUN_DIR/report.html``: one static page with a run's KPI tables and its plots.

Written by ``muvsim report --plots`` and ``muvsim run --plots`` after the plots.  The page is
plain HTML and CSS (no script, nothing fetched from the network): it opens from the file
system in any browser, and the plots are the PNG files next to it (``plots/*.png``, relative
links), so the run directory can be copied or served as it is.
"""

from __future__ import annotations

import html
from pathlib import Path

__all__ = ["write_html_report"]

_CSS = """body{font-family:system-ui,sans-serif;margin:2em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;padding:2px 8px}
td.num{text-align:right;font-variant-numeric:tabular-nums}th{background:#f3f3f3}
img{max-width:100%;border:1px solid #ddd;margin:0.5em 0 1.5em}p.warn{color:#a40000;font-weight:bold}"""

_PLOT_TEXT = {
    "timespace": "Time-space diagram of the busiest routes: distance along the route over time, one line per "
                 "vehicle; flat stretches are halts, red ones TM stops.",
    "trajectories": "Paths coloured by state, departures (triangles) and arrivals (circles).",
    "membership": "Membership index l of the vehicles halted longest; shaded: the TM denied its request.",
    "delay": "Distribution of the arrived vehicles' delay.",
    "stops": "Distributions of halts and TM stops per arrived vehicle.",
}


def _table(header, rows, numeric_from: int) -> str:
    out = ["<table><tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr>"]
    for r in rows:
        cells = []
        for i, c in enumerate(r):
            cls = ' class="num"' if i >= numeric_from else ""
            cells.append(f"<td{cls}>{html.escape(str(c))}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    return "\n".join(out + ["</table>"])


def write_html_report(run_dir, vs_dir=None, plots: dict | None = None) -> Path:
    """Write ``RUN_DIR/report.html`` (summary, KPI table, plots); return its path.

    Parameters
    ----------
    run_dir : path-like
        A run directory.
    vs_dir : path-like, optional
        Another run of the same demand: the KPI table is then the comparison
        (:func:`analysis.report.comparison_table`).
    plots : dict, optional
        ``{kind: path}`` of the plots written (:func:`analysis.plots.write_plots`).
    """
    from analysis.report import (SUMMARY_ROWS, arrived_sets_warning, format_summary, frame_cells, load_run,
                                 report_table)

    run_dir = Path(run_dir)
    a = load_run(run_dir)
    b = load_run(vs_dir) if vs_dir is not None else None
    title = f"muvsim report: {a.summary.get('scenario', '?')}, run {run_dir.name}"
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
             f"<style>{_CSS}</style></head><body>", f"<h1>{html.escape(title)}</h1>"]
    summary_rows = [ln.split(None, 1) for ln in format_summary(a.summary).splitlines()]
    parts.append("<h2>Summary</h2>")
    parts.append(_table(["figure (as in summary.json)", "value"],
                        [(k, v) for k, v in summary_rows if k in SUMMARY_ROWS], 2))
    df = report_table(a, b)
    parts.append("<h2>KPIs" + (f" against {html.escape(str(b.path))}" if b is not None else "") + "</h2>")
    if b is not None:
        warn = arrived_sets_warning(a, b)
        if warn:
            parts.append(f'<p class="warn">{html.escape(warn)}</p>')
        parts.append("<p>paired: the vehicles both runs landed; demand (censored): every vehicle, one not arrived "
                     "counted with its time so far; difference = run − vs, ratio = run / vs per vehicle.</p>")
    else:
        parts.append("<p>Statistics over the run's arrived vehicles (as report.csv).</p>")
    cols = list(df.columns)
    first_num = cols.index("run") if "run" in cols else len(cols)
    if "n" in cols:
        first_num = min(first_num, cols.index("n"))
    parts.append(_table(cols, frame_cells(df), first_num))
    if plots:
        parts.append("<h2>Plots</h2>")
        for kind, path in plots.items():
            rel = Path(path).resolve().relative_to(run_dir.resolve()).as_posix()
            text = _PLOT_TEXT.get(kind, kind)
            parts.append(f"<h3>{html.escape(kind)}</h3><p>{html.escape(text)}</p>"
                         f'<img src="{html.escape(rel)}" alt="{html.escape(kind)} plot">')
    parts.append("</body></html>")
    dest = run_dir / "report.html"
    dest.write_text("\n".join(parts), encoding="utf-8")
    return dest
