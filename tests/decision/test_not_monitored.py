"""Issue 25's bad input: a fault whose class no member covers is listed as "not monitored" in the
run summary, not silently missed."""
from __future__ import annotations

from fdi_sim.decision.outcome import not_monitored
from fdi_sim.detectors.engine_gauges import HYPOTHESES as GAUGE_HYPOTHESES

GUST = ("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm", "q_radps", "nx_g")


def _f(label: str, target: str, windows=((10.0, 90.0),)) -> dict:
    return {"label": label, "target": target, "windows_s": [list(w) for w in windows]}


def test_faults_without_a_hypothesis_are_listed() -> None:
    faults = [_f("icing", "airframe"), _f("elev", "elevator"), _f("ng", "n1_0_pct"), _f("eng", "engine_1"),
              _f("later", "n1_1_pct", windows=())]
    assert not_monitored(GUST, faults) == (("icing", "airframe"), ("ng", "n1_0_pct"))
    # the engine-gauge check names the gauges and the engines; icing stays unmonitored
    assert not_monitored(GUST + GAUGE_HYPOTHESES, faults) == (("icing", "airframe"),)
    assert not_monitored((), [_f("elev", "elevator")]) == (("elev", "elevator"),)


def test_the_run_summary_says_so() -> None:
    import dataclasses

    from fdi_sim.sim.run import RunSummary

    fields = {f.name: 0 for f in dataclasses.fields(RunSummary) if f.default is dataclasses.MISSING}
    fields.update(scenario="s", aircraft="DHC6", status="completed", reason="")
    s = RunSummary(**fields, fdi_detectors=("kalman-gust-v1",), fdi_not_monitored=(("icing", "airframe"),))
    assert "icing                  not monitored: no member of this bank has a hypothesis for 'airframe'" in s.format()
