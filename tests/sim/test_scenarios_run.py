"""Every file in scenarios/ flies (shortened to 20 s) and leaves a complete, readable log."""
from __future__ import annotations

from pathlib import Path

import pytest

from fdi_sim.flightlog import read_log
from fdi_sim.scenario import load
from fdi_sim.sim import run

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_scenario_flies(tmp_path: Path, path: Path) -> None:
    sc = load(path)
    sc = sc.replace(duration_s=min(sc.duration_s, 20.0),
                    maneuvers=[m for m in sc.model.maneuvers if m.get("t_start_s", 0.0) < 20.0])
    res = run(sc, tmp_path, progress=False)
    assert res.status == "completed", res.summary.reason
    log = read_log(res.log_path)
    assert log.metadata["scenario"]["name"] == sc.name
    assert log.metadata["scenario"]["seed"] == str(sc.seed)
    n = round(sc.duration_s / sc.dt_s) + 1
    for topic in ("/truth/state", "/commands/pilot", "/sensors/measurements", "/truth/operating_point"):
        assert log.message_counts[topic] == n, topic
