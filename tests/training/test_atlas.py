"""The shipped calibration atlas (fdi_sim.training.atlas): a new scenario inside the envelope flies
the default bank with no training flight, its log naming the node and the file; outside, the log
says why and the bank trains; the lookup tolerates another CPU's rounding and nothing more."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.errors import DesignError
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import loads
from fdi_sim.training import atlas as atlas_mod
from fdi_sim.training import fly
from fdi_sim.training.atlas import (
    DESIGN_RTOL, LEVELS, MANEUVERS, atlas_path, fingerprint, fingerprint_distance, load_atlas, read_atlas,
)
from fdi_sim.training.schedule import atlas_design, design_choice

HOLDOUT = Path(__file__).resolve().parents[1] / "data" / "holdout"
#: scenarios written for issue 24 (not shipped, never tuned on), inside the atlas envelopes
NEW_F16 = (HOLDOUT / "holdout_f16_roll_gyro_bias_7500ft.toml").read_text()
NEW_DHC6 = (HOLDOUT / "holdout_dhc6_calm_6900ft.toml").read_text()


@pytest.fixture
def no_training(monkeypatch, tmp_path):
    """An empty calibration cache, and a tripwire on every training flight."""
    monkeypatch.setenv("FDI_SIM_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("FDI_SIM_ATLAS", raising=False)

    def tripwire(*a, **k):
        raise AssertionError("a training flight was flown")

    import fdi_sim.training.flights as flights
    import fdi_sim.training.gust as gust

    monkeypatch.setattr(flights, "fly_training", tripwire)
    monkeypatch.setattr(gust, "fly_training", tripwire)


def test_fingerprint_tolerates_rounding_and_sees_a_design_change():
    rng = np.random.default_rng(3)
    a = [rng.standard_normal((12, 12)), rng.standard_normal((14, 3)), np.zeros(0)]
    ref = fingerprint(a)
    assert fingerprint_distance(fingerprint(a), ref) == 0.0
    rounded = [x * (1 + 1e-12 * rng.standard_normal(x.shape)) for x in a]  # another CPU's last bits
    assert fingerprint_distance(fingerprint(rounded), ref) < 1e-10
    changed = [a[0].copy(), a[1], a[2]]
    changed[0][3, 4] += 1e-2 * np.linalg.norm(a[0])  # one entry moved by 1 % of the matrix's norm
    assert fingerprint_distance(fingerprint(changed), ref) > DESIGN_RTOL
    assert fingerprint_distance(fingerprint(a[:2]), ref) == np.inf  # another structure
    assert fingerprint_distance(fingerprint([a[0], a[1][:, :2], a[2]]), ref) == np.inf


@pytest.mark.parametrize("aircraft", ["f16", "DHC6"])
def test_shipped_atlas_covers_its_envelope(aircraft):
    from fdi_sim.study.atlas import envelope_nodes

    at = load_atlas(aircraft)
    assert at is not None, f"no atlas at {atlas_path(aircraft)}: `python -m fdi_sim.study.atlas {aircraft}`"
    made = {(n.h_ft, n.vc_kts, n.turbulence, n.maneuvers) for n in at.nodes}
    # steady flights at every level; the reference's maneuvers at least at moderate (the studies' design)
    want = {(h, v, lv, "steady") for h, v in envelope_nodes(aircraft) for lv in LEVELS}
    want |= {(h, v, "moderate", "doublets") for h, v in envelope_nodes(aircraft)}
    assert want <= made, "the atlas was made for another envelope or other levels: regenerate it"
    assert {m for *_, m in made} <= set(MANEUVERS) and {lv for _, _, lv, _ in made} <= set(LEVELS)
    assert len({(lv, mv) for _, _, lv, mv in made}) * len(envelope_nodes(aircraft)) == len(made)
    ok = [n for n in at.nodes if n.status == "ok"]
    assert len(ok) >= 0.9 * len(at.nodes), [n.status for n in at.nodes if n.status != "ok"]
    # every calibrated node holds both entries: the gust filter's calibration and the thresholds
    kinds: dict[tuple, set] = {}
    for k, e in at.entries.items():
        h, v, _, lv, mv = e["node"]
        kinds.setdefault((h, v, lv, mv), set()).add(k.split(":")[0])
    assert all(kinds.get((n.h_ft, n.vc_kts, n.turbulence, n.maneuvers)) == {"gust", "bank"} for n in ok)


def test_new_scenario_flies_with_no_training_flight_and_its_log_names_the_calibration(tmp_path, no_training):
    sc = loads(NEW_F16, "holdout_f16.toml")
    des, note = design_choice(sc)
    assert "calibrated design of" in note and "node h 6000 ft" in note, note
    res = fly(sc, tmp_path / "runs", progress=False)
    log = read_log(res.log_path)
    cal = json.loads(log.metadata["fdi"]["calibration"])
    assert cal["source"] == "atlas", cal.get("source")
    assert cal["atlas"]["node"] == {"h_ft": 6000.0, "vc_kts": des.model.initial.vc_kts, "flaps_deg": 0.0,
                                    "turbulence": "light", "maneuvers": "steady"}
    # shown inside the package, never where it was checked out: the same seed, the same log on every machine
    assert cal["atlas"]["file"] == "fdi_sim/_aircraft/f16/fdi_atlas.json"
    assert "calibrated design of fdi_sim/_aircraft/f16/fdi_atlas.json at node" in cal["design"]
    from fdi_sim.data import AIRCRAFT_DATA

    assert str(AIRCRAFT_DATA.parent.parent) not in json.dumps(log.metadata["fdi"])
    notes = json.loads(log.metadata["fdi"]["notes"])
    assert notes[0].startswith("design: calibrated design of")
    assert res.summary.fdi_detections, "the roll-rate gyro bias of 3 deg/s went undetected"


def test_dhc6_new_scenario_takes_its_calibration_from_the_atlas(tmp_path, no_training):
    res = fly(loads(NEW_DHC6, "holdout_dhc6.toml"), tmp_path / "runs", progress=False)
    cal = json.loads(read_log(res.log_path).metadata["fdi"]["calibration"])
    assert cal["source"] == "atlas" and cal["atlas"]["node"]["h_ft"] == 6000.0
    assert cal["atlas"]["node"]["turbulence"] == "none" and cal["atlas"]["node"]["maneuvers"] == "steady"


def test_a_severe_flight_is_designed_at_moderate_and_says_so():
    sc = loads(NEW_F16.replace('turbulence = "light"', 'turbulence = "severe"'), "severe.toml")
    des, note = design_choice(sc)
    assert des.model.atmosphere.turbulence == "moderate"
    assert "severe: the atlas's nearest level below" in note


def test_outside_the_atlas_the_log_says_why():
    far = NEW_F16.replace("h_ft = 7500.0", "h_ft = 30000.0")
    des, why = atlas_design(loads(far, "far.toml"))
    assert des is None and "does not cover this flight" in why and "no such node" in why
    own = NEW_F16.replace('bank = "default"', 'bank = "default"\nfar_per_h = 0.05')
    des, why = atlas_design(loads(own, "own.toml"))
    assert des is None and "[fdi] settings differ" in why
    climb = NEW_F16 + """
[[maneuvers]]
type = "altitude-v1"
t_start_s = 5.0
h_ft = 14000.0
rate_fps = 50.0
"""
    sc = loads(climb, "climb.toml")
    des, why = design_choice(sc)
    assert des is sc and "schedule points" in why and why.startswith("designed at the flight's own point")
    # other maneuvers than none or the reference's: the gust filter's calm-air threshold depends on them
    dbl = NEW_F16.replace("[[faults]]", """[[maneuvers]]
type = "doublet-v1"
axis = "aileron"
t_start_s = 8.0
amplitude_norm = 0.08
pulse_s = 1.0

[[faults]]""")
    des, why = atlas_design(loads(dbl, "dbl.toml"))
    assert des is None and "maneuvers are neither none nor f16_cruise_doublets's" in why
    # the reference's own maneuvers, in light air: the doublets variant
    from fdi_sim.scenario.shipped import shipped_dir

    text = (shipped_dir() / "f16_cruise_doublets.toml").read_text()
    ref = loads(text.replace('turbulence = "moderate"', 'turbulence = "light"') + '\n[fdi]\nbank = "default"\n', "r.toml")
    des, note = design_choice(ref)
    assert "f16_cruise_doublets's maneuvers, as the flight's" in note and des.maneuvers
    # an explicit design is the user's: no atlas
    expl = NEW_F16.replace('bank = "default"', 'bank = "default"\ndesign = { point = "flight" }')
    sc = loads(expl, "expl.toml")
    assert design_choice(sc) == (sc, "")


def test_an_atlas_of_another_aircraft_is_refused(tmp_path, monkeypatch):
    src = atlas_path("DHC6")
    bad = tmp_path / "fdi_atlas.json"
    shutil.copy(src, bad)
    with pytest.raises(DesignError, match=r"key 'aircraft' is 'DHC6', this flight's aircraft is 'f16'"):
        read_atlas(bad, "f16")
    bad.write_text(json.dumps({"kind": "fdi-thresholds"}))
    with pytest.raises(DesignError, match="not an atlas file; regenerate"):
        read_atlas(bad)
    monkeypatch.setattr(atlas_mod, "atlas_path", lambda a: src)  # the DHC-6's file where the F-16's belongs
    with pytest.raises(DesignError, match="an atlas of another aircraft"):
        load_atlas("f16")


def test_a_changed_design_is_not_taken_from_the_atlas(tmp_path, no_training, monkeypatch):
    """The gust filter designed with another option (a 2 s window instead of 1 s) is not the atlas's:
    the lookup refuses it and the bank would train (the tripwire)."""
    sc = loads(NEW_DHC6, "x.toml")
    des, _ = design_choice(sc)
    from fdi_sim.training.cache import calibration_atlas_key
    from fdi_sim.training.models import model_for_scenario
    from fdi_sim.detectors.catalogue_observers import make_gust_kalman

    lm = model_for_scenario(des, 20.0)
    params = {"turbulence": "light"}  # a calm-air design carries small gust states (fdi_sim.training.gust)
    det = make_gust_kalman(lm.continuous(), rate_hz=20.0, sim_rate_hz=des.model.rate_hz, **params)
    n_samples = 24 * 295.0 * 20.0
    key, fp = calibration_atlas_key(des, det.design, params, 20.0, 24, 300.0, max(1e-4, 20.0 / n_samples))
    hit, why = atlas_mod.lookup("DHC6", "gust", key, fp)
    assert hit is not None, why
    moved = [[x[0]] + [y * (1 + 1e-3) for y in x[1:]] for x in fp]
    hit, why = atlas_mod.lookup("DHC6", "gust", key, moved)
    assert hit is None and "differs from this one" in why
