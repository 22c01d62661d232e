"""Every file in scenarios/ flies (shortened to 20 s) and leaves a complete, readable log."""
from __future__ import annotations

from pathlib import Path

import pytest

from fdi_sim.flightlog import read_log
from fdi_sim.scenario import load
from fdi_sim.training import fly

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_scenario_flies(tmp_path: Path, path: Path) -> None:
    sc = load(path)
    sc, _ = sc.shortened(min(sc.duration_s, 20.0))
    res = fly(sc, tmp_path, progress=False)
    assert res.status == "completed", res.summary.reason
    log = read_log(res.log_path)
    assert log.metadata["scenario"]["name"] == sc.name
    assert log.metadata["scenario"]["seed"] == str(sc.seed)
    n = round(sc.duration_s / sc.dt_s) + 1
    topics = ["/truth/state", "/commands/pilot", "/sensors/measurements", "/truth/operating_point"]
    if sc.faults:
        topics.append("/faults/active")
        active = log.topics["/faults/active"]
        for i in range(len(sc.faults)):  # every fault of the file acts during the shortened run
            col = active.fields[1 + 3 * i]  # <label>_active, _level, _error per fault, after t_s
            assert col.endswith("_active") and active[col].any(), col
    for topic in topics:
        assert log.message_counts[topic] == n, topic
