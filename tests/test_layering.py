"""Only bridge/sumo_adapter.py talks to SUMO; controllers/ and tm/ do not know SUMO exists."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SUMO_MODULES = {"libsumo", "traci", "sumolib", "sumo"}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out


def test_only_the_adapter_imports_libsumo_or_traci():
    users = sorted(str(p.relative_to(ROOT)) for pkg in ("bridge", "controllers", "tm", "analysis", "sumo_nets")
                   for p in (ROOT / pkg).rglob("*.py") if _imports(p) & {"libsumo", "traci"})
    assert users == ["bridge/sumo_adapter.py"]


def test_controllers_and_tm_know_nothing_of_sumo_or_the_bridge():
    for pkg in ("controllers", "tm"):
        for p in (ROOT / pkg).rglob("*.py"):
            bad = _imports(p) & (SUMO_MODULES | {"bridge", "sumo_nets"})
            assert not bad, f"{p.relative_to(ROOT)} imports {bad}"
