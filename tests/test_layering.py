"""One adapter per engine (STYLE rule 2): jsbsim, MCAP and matplotlib each imported in one place."""
from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "fdi_sim"
ALLOWED = {"jsbsim": "aircraft", "mcap": "flightlog", "foxglove": "flightlog", "matplotlib": "review"}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out


def test_engines_imported_only_in_their_adapter() -> None:
    breaches = []
    for path in PKG.rglob("*.py"):
        sub = path.relative_to(PKG).parts[0]
        for mod in _imports(path) & set(ALLOWED):
            if sub != ALLOWED[mod]:
                breaches.append(f"{path.relative_to(PKG.parent)} imports {mod}")
    assert not breaches, breaches
