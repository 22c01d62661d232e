"""The seed registry (fdi_sim/seeds.py): disjoint sets, every shipped study and every seed
constant drawn from it, and a hold-out seed flown by one consumer only."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from fdi_sim.scenario.shipped import list_studies
from fdi_sim.seeds import REGISTRY, ROLES, SeedSet, role_of, seed_set
from fdi_sim.study.spec import load_study

ROOT = Path(__file__).resolve().parents[1]


def test_sets_are_disjoint_and_named_once():
    names = [s.name for s in REGISTRY]
    assert len(names) == len(set(names))
    seen: dict[int, str] = {}
    for s in REGISTRY:
        assert s.seeds and s.used_by and s.history, s.name
        for x in s.seeds:
            assert x not in seen, f"seed {x} is in both {seen[x]} and {s.name}"
            seen[x] = s.name


def test_every_shipped_study_draws_its_seed_from_the_registry():
    for f in list_studies():
        study = load_study(f.path)
        s = role_of(study.model.seed)
        assert s is not None, f"{f.path.name}: seed {study.model.seed} is not in fdi_sim/seeds.py"
        assert f"studies/{study.model.name}" in s.used_by, (f.path.name, s.name, s.used_by)


def test_every_registered_study_exists_with_its_seed():
    studies = {load_study(f.path).model.name: load_study(f.path).model.seed for f in list_studies()}
    for s in REGISTRY:
        for i, user in enumerate(s.used_by):
            if user.startswith("studies/"):
                name = user.split("/", 1)[1]
                assert name in studies, f"{s.name}: no shipped study {name}"
                assert studies[name] in s.seeds, (s.name, name, studies[name])
                if s.role == "hold-out":  # paired in order: one seed, one study
                    assert studies[name] == s.seeds[i], (s.name, name)


def test_a_hold_out_set_has_one_consumer_per_seed():
    for s in REGISTRY:
        if s.role == "hold-out":
            assert len(s.used_by) in (1, len(s.seeds)), s


def test_a_bad_role_is_refused():
    with pytest.raises(ValueError, match="role"):
        SeedSet("x", "held out", (1,), ("a",), "b")
    assert set(ROLES) >= {s.role for s in REGISTRY}
    with pytest.raises(KeyError, match="registered"):
        seed_set("no-such-set")


_SEED_NAME = re.compile(r"(^|_)SEEDS?$")


def _seed_constants(path: Path) -> list[str]:
    """Module- or function-level assignments to a ``*SEED``/``*SEEDS`` name (or ``*_seeds`` locals)
    whose value holds an integer literal or a ``range``: seeds typed by hand, not drawn from the
    registry."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, (ast.Assign, ast.AnnAssign)):
            continue
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        names = [t.id for t in targets if isinstance(t, ast.Name)]
        if not any(_SEED_NAME.search(n.upper()) and (n.isupper() or n.endswith("_seeds")) for n in names):
            continue
        value = node.value
        if value is None:
            continue
        typed = any(isinstance(v, ast.Constant) and isinstance(v.value, int) and not isinstance(v.value, bool)
                    and v.value > 2 for v in ast.walk(value))
        typed |= any(isinstance(v, ast.Call) and isinstance(v.func, ast.Name) and v.func.id == "range"
                     for v in ast.walk(value))
        if typed:
            out.append(f"{path.relative_to(ROOT)}:{node.lineno} {ast.unparse(node)[:100]}")
    return out


def test_no_seed_constant_is_typed_outside_the_registry():
    files = [p for p in (ROOT / "fdi_sim").rglob("*.py") if p.name != "seeds.py"] + list((ROOT / "docs").glob("*.py"))
    typed = [x for p in files for x in _seed_constants(p)]
    assert not typed, typed


def test_the_scan_sees_a_typed_seed(tmp_path):
    p = ROOT / "tests" / "_seed_scan_probe.py"
    p.write_text("HELD_OUT_SEEDS = tuple(range(101, 109))\ncal_seeds = (1, 2, 3)\n")
    try:
        assert len(_seed_constants(p)) == 2
    finally:
        p.unlink()


def test_every_shipped_suite_draws_its_seed_from_the_registry():
    from fdi_sim.bench.suite import SUITES_DIR, suite_names
    import tomllib

    for name in suite_names():
        seed = tomllib.loads((SUITES_DIR / f"{name}.toml").read_text())["seed"]
        s = role_of(seed)
        assert s is not None and s.role == "benchmark" and f"bench/{name}" in s.used_by, (name, seed, s)
