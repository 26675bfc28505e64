"""Writing a ``.sumocfg`` and running ``muvsim run`` on it, for the tests about SUMO scenarios
(``tests/bridge``): one place for the configuration a test writes and the run's summary it reads."""

from __future__ import annotations

import json
from pathlib import Path

from bridge.cli import main


def write_cfg(path: Path, net, *, routes=(), additional=(), begin=None, end=None, step=None, extra="") -> Path:
    """A ``.sumocfg`` at ``path``: its net, route and additional files (paths as given: relative ones
    are SUMO's, from the configuration's directory), the ``<time>`` values given, and ``extra`` XML;
    returns ``path``."""
    def files(tag, fs):
        return f'<{tag} value="{",".join(str(f) for f in fs)}"/>' if fs else ""

    time = "".join(f'<{k} value="{v}"/>' for k, v in (("begin", begin), ("end", end), ("step-length", step))
                   if v is not None)
    path.write_text(f'<configuration><input><net-file value="{net}"/>{files("route-files", routes)}'
                    f'{files("additional-files", additional)}</input>{"<time>" + time + "</time>" if time else ""}{extra}'
                    f'</configuration>')
    return path


def run_cfg(cfg, out: Path, *extra) -> tuple[int, dict]:
    """``muvsim run CFG --out OUT --quiet --log none EXTRA...``: its exit code and ``summary.json``."""
    rc = main(["run", str(cfg), "--out", str(out), "--quiet", "--log", "none", *extra])
    return rc, json.loads((Path(out) / "summary.json").read_text())
