"""The README's Python example runs as written (in a temporary folder, from the repository root's files)."""
from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_readme_python_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert blocks, "the README has a Python example"
    (tmp_path / "scenarios").symlink_to(ROOT / "scenarios")
    monkeypatch.chdir(tmp_path)
    for code in blocks:
        exec(compile(code, "README.md", "exec"), {})  # noqa: S102 - the documented example itself
    out = capsys.readouterr().out
    assert "completed" in out and os.path.exists(tmp_path / "runs")


def test_readme_scenario_example_loads_and_its_plugin_lists_are_the_registry() -> None:
    """The scenario file shown in the README validates as written (a fault starting at
    duration_s was refused), and its comments name every maneuver and count every fault."""
    from fdi_sim import registry
    from fdi_sim.scenario import loads

    text = (ROOT / "README.md").read_text()
    (toml,) = [b for b in re.findall(r"```toml\n(.*?)```", text, flags=re.S) if "[[maneuvers]]" in b]  # the scenario
    sc = loads(toml, "README.md")
    assert [tid for tid, _ in sc.faults] == ["actuator-stuck-v1", "sensor-bias-v1"]
    listed = re.search(r"\[\[maneuvers\]\]\s+# (.*)", toml).group(1).split(", ")
    assert sorted(listed) == registry.ids("maneuver")
    n_faults = int(re.search(r"# (\d+) registered faults", toml).group(1))
    assert n_faults == len(registry.ids("fault"))
