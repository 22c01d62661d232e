"""Strict scenario files: every kind of bad input is one ScenarioError naming file, key and fix."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fdi_sim.errors import ScenarioError
from fdi_sim.scenario import from_dict, load, loads

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_validate(path: Path) -> None:
    sc = load(path)
    assert sc.name == path.stem
    assert sc.text == path.read_text()


@pytest.mark.parametrize("old,new,key,fix", [
    ("h_ft = 10000.0", "h = 10000.0", "initial.h", "h_ft"),
    ("vt_kts = 400.0", "vt_kts = -400.0", "initial.vt_kts", "> 50"),
    ('"doublet-v1"', '"doublet-v2"', "maneuvers[0].type", "doublet-v1"),
    ('aircraft = "f16"', 'aircraft = "f15"', "aircraft", "'f16'"),
    ("duration_s = 10.0", "duration_s = -1.0", "duration_s", "> 0"),
    ('axis = "elevator"', 'axis = "elevatr"', "maneuvers[0].axis", "'elevator'"),
    ("[atmosphere]", "[atmospheer]", "atmospheer", "atmosphere"),
    ("vt_kts = 400.0", "", "initial", "vt_kts"),
    ("t_start_s = 2.0", "t_start_s = 20.0", "maneuvers[0].t_start_s", "duration_s"),
    # wrong types are refused, not coerced (lax pydantic read "yes" as true and true as 1.0 s)
    ('turbulence = "moderate"', 'turbulence = "moderate"\n[autopilot]\naltitude = "yes"', "autopilot.altitude", "true or false"),
    ("h_ft = 10000.0", 'h_ft = "10000"', "initial.h_ft", "give a number"),
    ("duration_s = 10.0", "duration_s = true", "duration_s", "give a number"),
    ("seed = 7", "seed = 7.5", "seed", "whole number"),
    ("pulse_s = 1.0", "pulse_s = true", "maneuvers[0].pulse_s", "give a number"),
    ("h_ft = 10000.0", "h_ft = nan", "initial.h_ft", "finite"),
    ("pulse_s = 1.0", "pulse_s = inf", "maneuvers[0].pulse_s", "finite"),
    ('turbulence = "moderate"', 'turbulence = "moderate"\n[sensors.overrides.alpha_rad]\nbias = -inf', "sensors.overrides.alpha_rad.bias", "finite"),
    # the sensor suite and its overrides are checked when the file is loaded, not mid-run
    ('turbulence = "moderate"', 'turbulence = "moderate"\n[sensors]\nsuite = "defualt"', "sensors.suite", "'default'"),
    ('turbulence = "moderate"', 'turbulence = "moderate"\n[sensors.overrides.alpah_rad]\nnoise_std = 0.1', "sensors.overrides.alpah_rad", "alpha_rad"),
    ('turbulence = "moderate"', 'turbulence = "moderate"\n[sensors.overrides.alpha_rad]\nnoise = 0.1', "sensors.overrides.alpha_rad.noise", "noise_std"),
    ("[initial]\nh_ft = 10000.0\nvt_kts = 400.0\n", "", "initial", "[initial] table with h_ft"),
    ('aircraft = "f16"\n', "", "aircraft", "'f16', 'DHC6'"),
    ("[[maneuvers]]", "[maneuvers]", "maneuvers", "[[maneuvers]] table"),
    ('name = "t_f16"', 'name = "t f16"', "name", "regular expression"),
])
def test_bad_keys_name_file_key_and_fix(f16_text: str, old: str, new: str, key: str, fix: str) -> None:
    assert old in f16_text
    with pytest.raises(ScenarioError) as ei:
        loads(f16_text.replace(old, new), "bad.toml")
    e = ei.value
    assert e.source == "bad.toml"
    assert e.key == key, str(e)
    assert fix in e.fix, str(e)
    assert str(e).startswith("bad.toml: ")


def test_missing_file_and_wrong_suffix(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="no such file"):
        load(tmp_path / "nope.toml")
    p = tmp_path / "x.yaml"
    p.write_text("a: 1")
    with pytest.raises(ScenarioError, match="TOML"):
        load(p)


def test_replace_revalidates(f16_text: str) -> None:
    sc = loads(f16_text)
    assert sc.replace(seed=3).seed == 3
    with pytest.raises(ScenarioError):
        sc.replace(duration_s=-5.0)


# ---------------------------------------------------------------- property-based: only ScenarioError
_BASE: dict[str, Any] = tomllib.loads((Path(__file__).resolve().parents[2] / "scenarios" / "f16_cruise_doublets.toml").read_text())
_values = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12), st.lists(st.integers(), max_size=3), st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)


def _paths(d: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix] if prefix else []
    if isinstance(d, dict):
        for k, v in d.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            out += _paths(v, prefix + (i,))
    return out


_ALL_PATHS = _paths(_BASE)


@st.composite
def mutated(draw: st.DrawFn) -> dict[str, Any]:
    import copy

    d = copy.deepcopy(_BASE)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(_ALL_PATHS))
        parent: Any = d
        try:
            for p in path[:-1]:
                parent = parent[p]
            action = draw(st.sampled_from(["set", "delete", "add_key", "rename"]))
            last = path[-1]
            if action == "set":
                parent[last] = draw(_values)
            elif action == "delete":
                del parent[last]
            elif action == "add_key" and isinstance(parent, dict):
                parent[draw(st.text(min_size=1, max_size=10))] = draw(_values)
            elif action == "rename" and isinstance(parent, dict):
                parent[str(last) + draw(st.text(min_size=1, max_size=3))] = parent.pop(last)
        except (KeyError, IndexError, TypeError):
            continue
    return d


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_scenarios_raise_only_scenario_error(data: dict[str, Any]) -> None:
    try:
        from_dict(data, "mutated.toml")
    except ScenarioError as e:
        assert e.source == "mutated.toml"


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=200))
def test_arbitrary_text_raises_only_scenario_error(text: str) -> None:
    try:
        loads(text, "garbage.toml")
    except ScenarioError:
        pass


# ---------------------------------------------------------------- files that are not plain small UTF-8 TOML
_ICING = Path(__file__).resolve().parents[2] / "scenarios" / "dhc6_tail_icing.toml"


def test_utf8_bom_is_accepted(tmp_path: Path) -> None:
    """A BOM (Windows editors) is dropped; tomllib alone says "Invalid statement (at line 1)"."""
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf" + _ICING.read_bytes())
    with pytest.raises(tomllib.TOMLDecodeError):
        tomllib.loads(p.read_text(encoding="utf-8"))  # the failure this guards against
    sc = load(p)
    assert sc.model == load(_ICING).model
    assert not sc.text.startswith("\ufeff")


@pytest.mark.parametrize("data,problem", [
    (_ICING.read_text().encode("utf-16"), "UTF-16"),
    (_ICING.read_bytes().replace(b"tailplane", b"tail\xffplane"), "byte 0xff at line 2"),
    (_ICING.read_bytes() + b"#" * (1 << 20), "larger than 1048576 bytes"),
], ids=["utf16", "bad-utf8", "too-big"])
def test_unreadable_contents_name_the_problem(tmp_path: Path, data: bytes, problem: str) -> None:
    p = tmp_path / "bad.toml"
    p.write_bytes(data)
    with pytest.raises(ScenarioError) as ei:
        load(p)
    assert ei.value.source == str(p) and problem in ei.value.problem, str(ei.value)
    assert ei.value.fix


def test_directory_is_refused(tmp_path: Path) -> None:
    d = tmp_path / "dir.toml"
    d.mkdir()
    with pytest.raises(ScenarioError, match="is a directory, not a regular file"):
        load(d)


def test_array_nested_5000_deep_is_a_scenario_error() -> None:
    """tomllib recurses once per level: RecursionError without the guard."""
    text = "x = " + "[" * 5000 + "]" * 5000 + "\n"
    with pytest.raises(ScenarioError) as ei:
        loads(text, "deep.toml")
    assert ei.value.source == "deep.toml" and "nests too deeply" in ei.value.problem


def test_moderate_nesting_names_the_key(f16_text: str) -> None:
    """40 levels parse fine but nest deeper than any scenario key: the depth check names where."""
    text = f16_text.replace("[atmosphere]", "junk = " + "[" * 40 + "]" * 40 + "\n[atmosphere]")
    with pytest.raises(ScenarioError) as ei:
        loads(text, "deep.toml")
    assert ei.value.key.startswith("initial.junk[0][0]"), str(ei.value)
    # pydantic and _check_finite would recurse as deep as the data; a deep dict is refused the same way
    deep: dict[str, Any] = {}
    cur = deep
    for _ in range(3000):
        cur["a"] = {}
        cur = cur["a"]
    with pytest.raises(ScenarioError, match="nest more than"):
        from_dict({"name": "x", "sensors": deep}, "deep.toml")


# ---------------------------------------------------------------- misspelt keys: "did you mean" everywhere
_ICING_TEXT = _ICING.read_text()


@pytest.mark.parametrize("old,new,key,meant", [
    ("t_start_s = 10.0", "t_strat_s = 10.0", "faults[0].t_strat_s", "t_start_s"),  # a required key: reported as missing before
    ("ramp_s = 60.0", "rmp_s = 60.0", "faults[0].rmp_s", "ramp_s"),
    ('target = "airframe"', 'targt = "airframe"', "faults[0].targt", "target"),
    ("t_start_s = 5.0", "t_strat_s = 5.0", "maneuvers[0].t_strat_s", "t_start_s"),
    ("vc_kts = 100.0", "vc_kts = 100.0\nphi_degs = 3.0", "initial.phi_degs", "phi_deg"),
    ("[initial]", "[atmosphere]\nturbulance = 'none'\n[initial]", "atmosphere.turbulance", "turbulence"),
    ("[initial]", "[autopilot]\naltitud = true\n[initial]", "autopilot.altitud", "altitude"),
    ("[initial]", "[sensors]\nnoise_scal = 1.0\n[initial]", "sensors.noise_scal", "noise_scale"),
    ("[initial]", "[limits]\nalpha_mx_deg = 1.0\n[initial]", "limits.alpha_mx_deg", "alpha_max_deg"),
])
def test_misspelt_keys_get_did_you_mean(old: str, new: str, key: str, meant: str) -> None:
    assert old in _ICING_TEXT
    with pytest.raises(ScenarioError) as ei:
        loads(_ICING_TEXT.replace(old, new, 1), "typo.toml")
    e = ei.value
    assert e.key == key, str(e)
    typo = key.rsplit(".", 1)[-1]
    assert f"unknown key {typo!r} (did you mean {meant!r}?)" in e.problem, str(e)
    assert meant in e.fix


def test_detector_entry_keys_are_checked_against_the_factory() -> None:
    """[[detectors]] keys are the detector's options: a typo names the entry, the key and the fix."""
    from fdi_sim.errors import ScenarioError
    from fdi_sim.scenario import loads

    base = 'name = "d"\naircraft = "f16"\nduration_s = 5.0\n[initial]\nh_ft = 10000.0\nvt_kts = 400.0\n'
    sc = loads(base + '[[detectors]]\ntype = "kalman-gust-v1"\nturbulence = "light"\ntarget = 1e-4\n')
    assert sc.detectors[0][0] == "kalman-gust-v1"
    with pytest.raises(ScenarioError) as err:
        loads(base + '[[detectors]]\ntype = "kalman-gust-v1"\nturbulnce = "light"\n')
    msg = str(err.value)
    assert "detectors[0].turbulnce" in msg and "did you mean 'turbulence'" in msg and "Fix:" in msg
