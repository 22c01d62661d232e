"""The schedule report: pass counts, worst point and output, both validations of the DHC-6 throttle."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from fdi_sim.linear.report import BAR, ENGINE_LAG_KEY, bar_entry, bar_method, format_report, nonsmooth_causes, worst_validation
from fdi_sim.linear.schedule import ModelSchedule, SchedulePoint
from fdi_sim.operating_point import OperatingPoint

OUTS = ("q_radps", "nx_g", "h_ft")
RUNS = ("elevator_cmd_norm", "throttle_cmd_norm")


def _entry(pair: list[list[float]]) -> dict:
    """A validation entry as the grid driver stores it, from per-run, per-output errors (equal RMS)."""
    P = np.array(pair)
    agg = np.sqrt(np.mean(P**2, axis=0))  # equal run RMS: aggregate = RMS over runs
    k, k0 = int(np.argmax(agg)), int(np.argmax(P[0]))
    return {"nrmse": agg.tolist(), "worst_output": OUTS[k], "worst": float(agg[k]),
            "worst_without_throttle": float(P[0, k0]), "worst_output_without_throttle": OUTS[k0],
            "input_names": list(RUNS), "nrmse_pair": P.tolist(), "rms_nl": np.ones_like(P).tolist(),
            "passed": bool(np.all(agg < 0.05)), "duration_s": 10.0}


def _schedule() -> ModelSchedule:
    pts = []
    linear = ([[0.01, 0.02, 0.01], [0.60, 0.90, 0.80]], [[0.01, 0.03, 0.02], [0.50, 0.70, 0.90]])
    lagged = ([[0.01, 0.02, 0.01], [0.02, 0.03, 0.01]], [[0.01, 0.03, 0.02], [0.04, 0.09, 0.03]])
    for i, vc in enumerate((100.0, 120.0)):
        pts.append(SchedulePoint(
            op=OperatingPoint("DHC6", 5000.0, vc_kts=vc), status="ok", index=i,
            sched={"h_ft": 5000.0, "vc_kts": vc, "flaps_deg": 0.0, "icing_eta": 0.0},
            trim={"alpha_rad": 0.03, "throttle_cmd_norm": 0.7},
            info={"modes": [], "validation": {"zoh": _entry(linear[i])}, ENGINE_LAG_KEY: _entry(lagged[i])}))
    pts.append(SchedulePoint(op=OperatingPoint("DHC6", 5000.0, vc_kts=145.0), status="untrimmable",
                             reason="throttle_cmd_norm = 1.000 at its limit"))
    names = {"state_names": ("q_radps",), "input_names": RUNS, "input_kinds": ("control", "control"),
             "output_names": OUTS, "lagged_outputs": ()}
    meta = {"grid_source": "test", "validation": {"methods": ["zoh"], "amplitudes": {}, "width_s": 1.0,
                                                  "duration_s": 10.0}}
    return ModelSchedule("DHC6", pts, {}, names, meta)


def test_report_shows_both_validations_with_pass_counts() -> None:
    s = _schedule()
    assert worst_validation(s, "zoh") == ("DHC6 h=5000 ft VC=100 kt", "nx_g", np.sqrt((0.02**2 + 0.9**2) / 2))
    assert worst_validation(s, ENGINE_LAG_KEY)[1:] == ("nx_g", np.sqrt((0.03**2 + 0.09**2) / 2))
    text = format_report(s)
    assert ("- validation (zoh): 0/2 points below 5% on every output; "
            "worst nx_g 63.7% at DHC6 h=5000 ft VC=100 kt") in text
    assert "  - leaving out the throttle doublet: 2/2 points pass; worst nx_g 3.0% at DHC6 h=5000 ft VC=120 kt" in text
    assert ("- validation (zoh with the identified N1 lag): 1/2 points below 5% on every output; "
            "worst nx_g 6.7% at DHC6 h=5000 ft VC=120 kt") in text
    assert "### zoh\n" in text and "### zoh with the identified N1 lag\n" in text
    assert "| 5000 ft 120 KCAS | nx_g | 6.7% | throttle_cmd_norm |" in text  # the run the worst error comes from
    assert "throttle_cmd_norm = 1.000 at its limit" in text  # points without a model keep their reason


def test_table_rows_name_flaps_and_icing() -> None:
    """Iced and flapped grids repeat altitude and speed: the rows must tell their points apart."""
    s = _schedule()
    pts = list(s.points)
    pts[1] = replace(pts[1], op=OperatingPoint("DHC6", 5000.0, vc_kts=120.0, flaps_deg=10.0, icing_eta=0.05))
    text = format_report(ModelSchedule(s.aircraft, pts, {}, s.names, s.meta))
    assert "| 5000 ft 120 KCAS flaps 10 eta 0.05 | nx_g | 6.7% |" in text
    assert "| 5000 ft 100 KCAS | nx_g |" in text


def test_report_without_engine_lag_has_no_such_section() -> None:
    s = _schedule()
    for p in s.ok_points:
        del p.info[ENGINE_LAG_KEY]
    text = format_report(s)
    assert "N1 lag" not in text and "### zoh\n" in text


def test_bar_is_judged_on_the_step_model_and_names_the_causes() -> None:
    """With step validations the bar is judged on them; each point that misses it is listed with the
    slope jumps and the engine lag JSBSim has there (and whether it passes with the identified lag)."""
    s = _schedule()
    for i, p in enumerate(s.ok_points):
        p.info["validation"]["step"] = p.info["validation"]["zoh"]
        p.info[ENGINE_LAG_KEY]["method"] = "step"
        p.info["engine_lag"] = {"tau_up_s": 1.0, "tau_down_s": 2.4}
        p.info["nonsmooth"] = {"aileron_cmd_norm": {"excursion": 0.004, "jump": 0.12 if i else 0.01},
                               "alpha_rad": {"excursion": 0.002, "jump": 0.03}}
    s.meta["validation"]["methods"] = ["zoh", "step"]
    assert bar_method(s) == "step"
    text = format_report(s)
    # without linear-range entries (older schedules) the bar reads the step model with the N1 lag
    assert ("- **bar** (5% on every output; step with the identified N1 lag, doublets inside the smooth range of "
            "JSBSim's tables): **1/2 points pass**; worst nx_g 6.7% at DHC6 h=5000 ft VC=120 kt") in text
    assert "  - misses: DHC6 h=5000 ft VC=120 kt: nx_g 6.7%" in text
    assert "- 'step' as it is, configured doublets: 0/2 points pass" in text
    assert "- validation (step with the identified N1 lag): 1/2 points" in text
    line100 = next(ln for ln in text.splitlines() if ln.startswith("  - DHC6 h=5000 ft VC=100 kt:"))
    assert "with the identified N1 lag it passes" in line100 and "aileron" not in line100
    assert "throttle_cmd_norm: N1 lag 1 s up, 2.4 s down" in line100
    line120 = next(ln for ln in text.splitlines() if ln.startswith("  - DHC6 h=5000 ft VC=120 kt:"))
    assert "aileron_cmd_norm: slopes differ by 12% across +-0.004" in line120
    assert "with the identified N1 lag nx_g 6.7%" in line120
    p = s.ok_points[1]
    assert nonsmooth_causes(p, min_jump=0.2) == ["throttle_cmd_norm: N1 lag 1 s up, 2.4 s down (FGTurboProp ExpSeek, "
                                                 "non-smooth at the trim)"]
    del s.ok_points[0].info["validation"]["step"], s.ok_points[1].info["validation"]["step"]
    assert bar_method(s) == "zoh"


def test_bar_reads_the_linear_range_validation_and_lists_the_smaller_doublets() -> None:
    """A point whose aileron doublet was flown smaller (kink at zero left-aileron deflection) is
    judged on that validation, and the report says which doublet, by how much and why."""
    s = _schedule()
    for p in s.ok_points:
        p.info["validation"]["step"] = p.info["validation"]["zoh"]
        p.info[ENGINE_LAG_KEY]["method"] = "step"
    p = s.ok_points[1]
    p.info["linear_range"] = {
        "doublets": {"elevator_cmd_norm": 0.01, "throttle_cmd_norm": 0.001},
        "reduced": {"throttle_cmd_norm": {"factor": 0.25, "amplitude": 0.005, "by": "alpha_rad", "radius": 0.001,
                                          "jump": 0.12}},
        "no_smooth_range": {}, "nonsmooth": {},
        "validation": {"step": _entry([[0.01, 0.02, 0.01], [0.5, 0.5, 0.5]])},
        ENGINE_LAG_KEY: {**_entry([[0.01, 0.02, 0.01], [0.02, 0.03, 0.04]]), "method": "step"},
    }
    assert bar_entry(p)["worst"] == bar_entry(p, "step")["worst"] == np.sqrt((0.01**2 + 0.04**2) / 2)
    assert bar_entry(s.ok_points[0]) is s.ok_points[0].info[ENGINE_LAG_KEY]  # no linear range: as configured
    text = format_report(s)
    assert "**2/2 points pass**" in text
    assert ("    - DHC6 h=5000 ft VC=120 kt: throttle_cmd_norm x0.25 (alpha_rad: slopes differ by 12% across the "
            "configured doublets' excursion, by less than 5% within +-0.001)") in text
    assert "### bar: step with the identified N1 lag, doublets inside the smooth range" in text
    assert worst_validation(s, BAR) == ("DHC6 h=5000 ft VC=120 kt", "h_ft", np.sqrt((0.01**2 + 0.04**2) / 2))
