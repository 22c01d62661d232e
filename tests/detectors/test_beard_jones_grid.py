"""beard-jones-v1 at the initial point of every shipped scenario (Miller & Ribbens, US 6,643,569 B2, App. A).

The model is the one the in-loop bank and ``fdi-sim detect`` design from:
``model_for_scenario(load(path), 20.0).model`` (JSBSim trim and linearization at the scenario's
initial point, ZOH at 20 Hz with the accelerometers one sample late, in the paired form
``(A, B, C A, C B + D)`` of :mod:`fdi_sim.detectors.samples`). Until the observable realization
(:func:`~fdi_sim.detectors.beard_jones_filter.observable_realization`) the design refused every one
of them: "(A, C) is not observable: 3 of 13 modes fail the scaled PBH test" (15 on the DHC-6),
the three accelerometer lag states at ``z = 0``, which the paired ``C A`` no longer sees.

Checked per scenario: the design (default fault set) is one stable filter on the 10 (F-16) or 12
(DHC-6) observable states, with max ``|z|`` = ``exp(-6 rad/s * 0.05 s)`` = 0.741; every hypothesis's
output direction is a unit vector, the directions are separable, the design's own direction
check is exact, and a full-scale bias of each actuator gives a first-sample residual above the
chi-square threshold (detectable); a bias on one actuator input, simulated on the full paired
model (lag states included), gives a residual whose smallest whitened angle is to that
actuator's hypothesis at every sample, and the filter's own decision isolates it.

The 16 linearizations take about 4 s together (F-16 0.45 s, DHC-6 0.05 s each; the project does
not cache them), built once per module; a design takes 25-110 ms; the file about 15 s.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdi_sim.detectors.beard_jones import angle_rad
from fdi_sim.detectors.beard_jones_filter import (
    MIN_FEEDTHROUGH_SNR,
    BeardJonesBank,
    BeardJonesFilter,
    default_faults,
    observable_realization,
)
from fdi_sim.detectors.noise import suite_sensor_std
from fdi_sim.linear.model import LinearModel
from fdi_sim.scenario.loader import load
from fdi_sim.detectors.spec import build_detector, DetectorSpec
from fdi_sim.training.models import model_for_scenario

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))
RATE_HZ = 20.0
ACTUATORS = ("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm")
#: the default fault set per aircraft (default_faults: the DHC-6 throttle is below the noise in its sample)
DEFAULT_FAULTS = {"f16": ACTUATORS, "DHC6": ACTUATORS[:3]}
LAG_STATES = ("nx_lag_g", "ny_lag_g", "nz_lag_g")
#: slowest pole of the default design: the completion pole -6 rad/s at 20 Hz (no detection pole: order 0)
MAX_POLE = float(np.exp(-6.0 / RATE_HZ))
N_STEPS = 60  # 3 s of the synthetic bias


@pytest.fixture(scope="module")
def models() -> dict[str, LinearModel]:
    """Scenario file name -> its paired 20 Hz model at the initial point (built once)."""
    return {p.name: model_for_scenario(load(p), RATE_HZ).model for p in SCENARIOS}


def _filters(det: BeardJonesFilter | BeardJonesBank) -> list[BeardJonesFilter]:
    return list(det.filters) if isinstance(det, BeardJonesBank) else [det]


def _bias_run(m: LinearModel, det: BeardJonesFilter | BeardJonesBank, actuator: str, bias: float) -> list:
    """Fly the full paired model with ``bias`` added to one input; the filter gets the commanded (trim) input."""
    du = np.zeros(m.n_inputs)
    du[m.input_names.index(actuator)] = bias
    x = np.zeros(m.n_states)
    det.reset(np.random.default_rng(0))
    out = []
    for k in range(N_STEPS):
        out.append(det.step(k / RATE_HZ, m.u0, m.y0 + m.C @ x + m.D @ du))
        x = m.A @ x + m.B @ du
    return out


def test_the_shipped_scenarios() -> None:
    names = [p.name for p in SCENARIOS]
    assert len(names) == 16
    assert sum(n.startswith("f16_") for n in names) == 7 and sum(n.startswith("dhc6_") for n in names) == 9


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_designs_stable_with_detectable_directions(path: Path, models: dict[str, LinearModel]) -> None:
    m = models[path.name]
    aircraft = m.meta["aircraft"]
    # the cause: exactly the three lag states are unobservable, at z = 0 (stable: removing them is exact)
    real = observable_realization(m)
    assert real.removed_states == LAG_STATES and np.allclose(real.removed_poles, 0.0, atol=1e-12)
    det = build_detector(DetectorSpec("beard-jones-v1", {}), m)
    assert isinstance(det, BeardJonesFilter)  # one filter: the default faults share one gain
    assert det.hypotheses == DEFAULT_FAULTS[aircraft]
    design = det.design
    n = design.model.n_states
    assert n == m.n_states - 3 == {"f16": 10, "DHC6": 12}[aircraft]
    assert design.model.state_names == tuple(s for s in m.state_names if s not in LAG_STATES)
    # a stable filter: the observer matrix Phi = A - L C the runtime steps with
    Phi = det.observer._F[:, :n]
    assert np.allclose(Phi, design.model.A - design.gain.L @ design.model.C, atol=1e-9 * max(1.0, np.abs(Phi).max()))
    assert np.abs(np.linalg.eigvals(Phi)).max() < MAX_POLE + 1e-6
    # directions well defined: unit, finite, separable, exact by the design's own check
    CF = design.gain.output_directions
    assert np.all(np.isfinite(CF)) and np.allclose(np.linalg.norm(CF, axis=0), 1.0)
    assert np.linalg.svd(CF, compute_uv=False).min() > 1e-2
    assert design.gain.max_direction_error_rad < 1e-6
    assert np.all(np.isfinite(det._dirs)) and np.allclose(np.linalg.norm(det._dirs, axis=0), 1.0)
    # detectable: a full-scale bias of each actuator is over the threshold on its first sample
    md = design.model
    for h in det.hypotheses:
        d = md.D[:, md.input_names.index(h)]  # order 0: the residual is d n from the first sample on
        assert d @ np.linalg.solve(design.S, d) > det.threshold, h


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_a_bias_on_one_actuator_is_isolated_by_its_direction(path: Path, models: dict[str, LinearModel]) -> None:
    m = models[path.name]
    det = build_detector(DetectorSpec("beard-jones-v1", {}), m)
    for i, h in enumerate(det.hypotheses):
        small = _bias_run(m, det, h, 0.01)  # noise-free: the direction holds at every sample
        for r in small:
            assert int(np.nanargmin(r.scores)) == i, (h, r.t_s, r.scores)
            assert r.scores[i] < 1e-6 and np.nanmin(np.delete(r.scores, i)) > 0.05
        large = _bias_run(m, det, h, 0.5)  # over the threshold: the detector's own decision names it
        assert all(r.alarm and r.isolation == h for r in large), h


def test_default_fault_set_leaves_out_the_dhc6_throttle(models: dict[str, LinearModel]) -> None:
    # the DHC-6 throttle moves the outputs of its own sample by less than the noise at full scale;
    # every other actuator of both aircraft by far more (MIN_FEEDTHROUGH_SNR)
    for name, m in models.items():
        W = 1.0 / suite_sensor_std(m)
        snr = {a: float(np.linalg.norm(W * m.D[:, m.input_names.index(a)])) for a in ACTUATORS}
        if m.meta["aircraft"] == "DHC6":
            assert snr["throttle_cmd_norm"] < 0.5 * MIN_FEEDTHROUGH_SNR, (name, snr)
            snr.pop("throttle_cmd_norm")
        assert min(snr.values()) > 20 * MIN_FEEDTHROUGH_SNR, (name, snr)
        assert tuple(default_faults(m, np.diag(suite_sensor_std(m) ** 2))) == DEFAULT_FAULTS[m.meta["aircraft"]]


@pytest.mark.parametrize("name", ["dhc6_elevator_loss.toml", "dhc6_approach_flaps.toml"])
def test_dhc6_throttle_on_request(name: str, models: dict[str, LinearModel]) -> None:
    # named explicitly, the throttle designs too (its own filter when it cannot share the surfaces'
    # gain) and its bias is still isolated by direction; its residual is tiny (the reason it is not default)
    m = models[name]
    det = build_detector(DetectorSpec("beard-jones-v1", {"faults": list(ACTUATORS)}), m)
    assert det.hypotheses == ACTUATORS
    for f in _filters(det):
        n = f.design.model.n_states
        assert np.abs(np.linalg.eigvals(f.observer._F[:, :n])).max() < MAX_POLE + 1e-6
    i = ACTUATORS.index("throttle_cmd_norm")
    for r in _bias_run(m, det, "throttle_cmd_norm", 0.01):
        assert int(np.nanargmin(r.scores)) == i and r.scores[i] < 1e-6
    thr = next(f for f in _filters(det) if "throttle_cmd_norm" in f.hypotheses)
    d = thr.design.model.D[:, m.input_names.index("throttle_cmd_norm")]
    assert d @ np.linalg.solve(thr.design.S, d) < 1.0  # below the noise even at full throttle
    assert angle_rad(d, thr.design.gain.output_directions[:, thr.hypotheses.index("throttle_cmd_norm")]) < 1e-12
