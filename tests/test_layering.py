"""One adapter per engine (STYLE rule 2): jsbsim, MCAP and the plotting libraries (matplotlib, plotly)
each imported in one place."""
from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "fdi_sim"
ALLOWED = {"jsbsim": "aircraft", "mcap": "flightlog", "foxglove": "flightlog", "matplotlib": "review",
           "plotly": "review"}


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


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _fdi_imports(path: Path, *, module_level_only: bool = False) -> set[str]:
    """Absolute ``fdi_sim.*`` modules a file imports (``from a.b import c`` gives ``a.b`` and ``a.b.c``).

    With ``module_level_only`` the imports inside functions (deferred, run at call time) and
    under ``if TYPE_CHECKING:`` (never run) are left out: only those run when the module is imported.
    """
    tree = ast.parse(path.read_text(), str(path))
    out: set[str] = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if module_level_only and isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            if module_level_only and isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                visit_list(child.orelse)
                continue
            if isinstance(child, ast.Import):
                out.update(a.name for a in child.names if a.name.startswith("fdi_sim"))
            elif isinstance(child, ast.ImportFrom) and child.module and child.level == 0 and child.module.startswith("fdi_sim"):
                out.add(child.module)
                out.update(f"{child.module}.{a.name}" for a in child.names)
            visit(child)

    def visit_list(nodes: list[ast.stmt]) -> None:
        for n in nodes:
            wrapper = ast.Module(body=[n], type_ignores=[])
            visit(wrapper)

    visit(tree)
    return out


def _all_modules() -> dict[str, Path]:
    return {_module_name(p): p for p in PKG.rglob("*.py")}


def test_no_relative_imports() -> None:
    """The scans below read absolute imports only; a relative one would slip past them."""
    rel = [str(p.relative_to(PKG.parent)) for p in PKG.rglob("*.py")
           if any(isinstance(n, ast.ImportFrom) and n.level > 0 for n in ast.walk(ast.parse(p.read_text())))]
    assert not rel, rel


FORBIDDEN_FOR_LIBRARY = ("fdi_sim.sim", "fdi_sim.papers", "fdi_sim.study", "fdi_sim.aircraft", "fdi_sim.flightlog")


def _hits(imported: set[str], prefixes: tuple[str, ...]) -> list[str]:
    return sorted(m for m in imported if any(m == p or m.startswith(p + ".") for p in prefixes))


def test_detectors_and_decision_never_fly_a_simulation() -> None:
    """DESIGN.md: ``detectors/`` and ``decision/`` never fly a simulation, read a log or import papers
    (imports inside functions count too: they run at call time)."""
    breaches = []
    for sub in ("detectors", "decision"):
        for path in (PKG / sub).rglob("*.py"):
            for mod in _hits(_fdi_imports(path), FORBIDDEN_FOR_LIBRARY):
                breaches.append(f"{path.relative_to(PKG.parent)} imports {mod}")
    assert not breaches, breaches


def test_nothing_imports_papers() -> None:
    """DESIGN.md: papers/ composes the library; nothing outside it imports it back."""
    breaches = []
    for path in PKG.rglob("*.py"):
        if path.relative_to(PKG).parts[0] == "papers":
            continue
        for mod in _hits(_fdi_imports(path), ("fdi_sim.papers",)):
            breaches.append(f"{path.relative_to(PKG.parent)} imports {mod}")
    assert not breaches, breaches


def _module_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports at module level (the edge ``from a import b`` goes
    to ``a.b`` when that is a module, else to ``a``); imports inside functions and under
    ``TYPE_CHECKING`` are ignored, as they do not run at import time."""
    mods = _all_modules()
    graph: dict[str, set[str]] = {}
    for name, path in mods.items():
        graph[name] = {m for m in _fdi_imports(path, module_level_only=True) if m in mods and m != name}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_cycle_finder_finds_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_level_import_cycles() -> None:
    """No two modules of the package import each other at module level, directly or through others.

    A package's ``__init__`` importing its own submodules is an edge like any other, so
    ``fdi_sim.x`` -> ``fdi_sim.x.y`` -> ``fdi_sim.x`` counts as a cycle.
    """
    cycles = _cycles(_module_graph())
    assert not cycles, cycles


#: the data flow (DESIGN.md), lowest first: a module may import its own package and any package of
#: a lower rank, at module level or inside a function (that runs too, at call time)
RANKS: tuple[tuple[str, ...], ...] = (
    ("units", "errors", "signals", "threads", "data", "isa", "operating_point", "registry", "contracts", "seeds",
     "stamp"),
    ("flightlog", "aircraft", "sensors", "pilot", "decision", "scoring"),
    ("faults", "linear", "scenario"),
    ("detectors",),
    ("bank",),
    ("sim",),
    ("training",),
    ("offline",),
    ("study", "papers"),
    ("review",),
    ("bench",),
    ("cli",),
)
#: arrows against the flow that are known and not yet removed: (from package, to package) -> why
KNOWN_UPWARD: dict[tuple[str, str], str] = {
    ("linear", "review"): "linear/cli.py draws its pole map with review.linear_figures (the CLI belongs above)",
    ("study", "review"): "study/report.py renders with review.study_figures (the report belongs to review/)",
}


def _rank() -> dict[str, int]:
    return {pkg: i for i, layer in enumerate(RANKS) for pkg in layer}


def test_every_package_has_a_rank() -> None:
    pkgs = {p.name.removesuffix(".py") for p in PKG.iterdir()
            if (p.is_dir() and (p / "__init__.py").exists()) or (p.suffix == ".py" and p.name != "__init__.py")}
    assert not pkgs - set(_rank()), sorted(pkgs - set(_rank()))


def test_imports_follow_the_data_flow_including_those_inside_functions() -> None:
    """No import, at module level or inside a function, goes to a package of a higher rank, except
    the arrows listed in :data:`KNOWN_UPWARD` (each with its reason; the list only shrinks)."""
    rank, bad, seen = _rank(), [], set()
    for path in PKG.rglob("*.py"):
        src = path.relative_to(PKG).parts[0].removesuffix(".py")
        for mod in _fdi_imports(path):
            parts = mod.split(".")
            dst = parts[1] if len(parts) > 1 else ""
            if dst not in rank or src not in rank or dst == src:
                continue
            if rank[dst] > rank[src]:
                if (src, dst) in KNOWN_UPWARD:
                    seen.add((src, dst))
                else:
                    bad.append(f"{path.relative_to(PKG.parent)} imports {mod} ({src} -> {dst}: against the flow)")
    assert not bad, bad
    assert seen == set(KNOWN_UPWARD), f"no longer needed, remove from KNOWN_UPWARD: {set(KNOWN_UPWARD) - seen}"
