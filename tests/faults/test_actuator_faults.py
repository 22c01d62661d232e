"""Issue 3 bar: every actuator fault on the elevator and the rudder of both aircraft, flown in real
JSBSim through a doublet, shows its physical effect in the truth signals.

Method: each case flies four 8 s runs from the same trim and seed, autopilot off: healthy and
faulty, each with and without a doublet (onset 2 s, doublet 3-5 s). The *doublet response* is the
body rate with the doublet minus the body rate without it (same noise, same fault), so a surface
that no longer follows its command shows exactly zero response. Surfaces are read from
``/truth/surfaces`` (what the aero model flew), the healthy position as surface minus the logged
fault error (``/faults/active``).
"""
from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from conftest import doublet, fly

T_ON_S, T_DOUBLET_S = 2.0, 3.0
RATE = {"elevator": "q_radps", "rudder": "r_radps"}
LAWS = {
    "stuck": {"type": "actuator-stuck-v1"},
    "loss": {"type": "actuator-loss-v1", "effectiveness": 0.5},
    "hard-over": {"type": "actuator-hard-over-v1", "direction": "max"},
    "runaway": {"type": "actuator-runaway-v1", "rate_degps": 2.0},
    "bias": {"type": "actuator-bias-v1", "bias_deg": 1.0},
    "rate-limit": {"type": "actuator-rate-limit-v1", "rate_degps": 5.0},
    "oscillation": {"type": "actuator-oscillation-v1", "amplitude_deg": 1.0, "frequency_hz": 2.0},
    "float": {"type": "actuator-float-v1"},
}
DT_S = 1.0 / 120.0


@lru_cache(maxsize=None)
def _runs(aircraft: str, surface: str, law: str | None, tmp: str) -> tuple[dict, dict]:
    faults = [] if law is None else [dict(LAWS[law], target=surface, t_start_s=T_ON_S)]
    kw = {"faults": faults, "may_diverge": True}
    with_d = fly(Path(tmp), aircraft, maneuvers=[doublet(surface, T_DOUBLET_S)], **kw)
    without = fly(Path(tmp), aircraft, **kw)
    return with_d, without


@pytest.fixture(scope="module")
def tmpdir_str(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp("actuator"))


def _response(pair: tuple[dict, dict], rate: str) -> np.ndarray:
    a, b = pair[0]["/truth/state"][rate], pair[1]["/truth/state"][rate]
    n = min(len(a), len(b))
    return a[:n] - b[:n]


def _peak(resp: np.ndarray, t0: float = T_DOUBLET_S, t1: float = T_DOUBLET_S + 3.0) -> float:
    t = np.arange(len(resp)) * DT_S
    w = (t >= t0) & (t < t1)
    assert w.any(), "the run ended before the doublet"
    return float(np.abs(resp[w]).max())


def _surface(run: dict, surface: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, flown position, healthy position) [s, rad, rad] after the onset."""
    s = run["/truth/surfaces"]
    f = run["/faults/active"]
    n = min(len(s["t_s"]), len(f["t_s"]))
    t = s["t_s"][:n]
    pos = s[f"{surface}_pos_rad"][:n]
    err_col = next(c for c in f.fields if c.endswith("_error"))
    healthy = pos - f[err_col][:n]
    on = t >= T_ON_S
    return t[on], pos[on], healthy[on]


CASES = [(ac, surf, law) for ac in ("f16", "DHC6") for surf in ("elevator", "rudder") for law in LAWS]


@pytest.mark.parametrize("aircraft,surface,law", CASES, ids=[f"{a}-{s}-{l}" for a, s, l in CASES])
def test_actuator_fault_effect(aircraft: str, surface: str, law: str, tmpdir_str: str) -> None:
    from fdi_sim.aircraft.properties import surfaces

    spec = surfaces(aircraft)[surface]
    rate = RATE[surface]
    healthy_resp = _peak(_response(_runs(aircraft, surface, None, tmpdir_str), rate))
    assert healthy_resp > 1e-3, "the healthy doublet must move the aircraft"
    pair = _runs(aircraft, surface, law, tmpdir_str)
    faulty, quiet = pair
    t, pos, healthy = _surface(faulty, surface)
    slew_radps = np.abs(np.diff(pos)) / DT_S

    if law == "stuck":
        # jammed at the onset position: the surface never moves, the doublet does nothing
        assert np.ptp(pos) == 0.0
        assert _peak(_response(pair, rate)) == 0.0
    elif law == "loss":
        # half the healthy deflection, exactly (the healthy value of the last frame)
        np.testing.assert_allclose(pos, 0.5 * healthy, atol=1e-12)
        ratio = _peak(_response(pair, rate)) / healthy_resp
        if aircraft == "DHC6":  # direct cable controls: about half the body-rate response
            assert 0.4 < ratio < 0.6, ratio
        else:  # the F-16's FBW loops deflect further and win part of it back
            assert 0.5 < ratio < 0.995, ratio
    elif law == "hard-over":
        stop = math.radians(spec.max_deg)
        rate_max = math.radians(spec.rate_degps)
        assert slew_radps.max() <= rate_max * (1 + 1e-9)
        at_stop = np.flatnonzero(np.isclose(pos, stop, atol=1e-12))
        assert at_stop.size, "the surface must reach its stop"
        t_reach = t[at_stop[0]] - T_ON_S
        assert t_reach <= abs(stop - pos[0]) / rate_max + 2 * DT_S, t_reach  # within the stated rate
        assert np.all(np.isclose(pos[at_stop[0]:], stop, atol=1e-12))  # and stays there
        x = faulty["/truth/state"]
        assert np.abs(x[rate][x["t_s"] > T_ON_S]).max() > 0.05  # a hard-over upsets the aircraft
    elif law == "runaway":
        expected = np.minimum(pos[0] + math.radians(2.0) * (t - t[0]), math.radians(spec.max_deg))
        np.testing.assert_allclose(pos, expected, atol=1e-9)
        assert _peak(_response(pair, rate)) == 0.0  # disconnected from the command
    elif law == "bias":
        np.testing.assert_allclose(pos - healthy, math.radians(1.0), atol=1e-12)
        # still a working surface: the doublet response is the healthy one, about
        assert abs(_peak(_response(pair, rate)) / healthy_resp - 1.0) < 0.1
    elif law == "rate-limit":
        assert slew_radps.max() <= math.radians(5.0) * (1 + 1e-9)
        assert np.abs(pos - healthy).max() > math.radians(0.5)  # it lags the healthy actuator
    elif law == "oscillation":
        np.testing.assert_allclose(pos - healthy, math.radians(1.0) * np.sin(2 * np.pi * 2.0 * (t - T_ON_S)), atol=1e-9)
        # the body rate (fault run without doublet) oscillates at 2 Hz: spectral peak there
        x = quiet["/truth/state"]
        sel = x["t_s"] >= T_ON_S + 1.0
        sig = x[rate][sel] - np.polyval(np.polyfit(x["t_s"][sel], x[rate][sel], 2), x["t_s"][sel])
        spec_ = np.abs(np.fft.rfft(sig * np.hanning(sig.size)))
        f = np.fft.rfftfreq(sig.size, DT_S)
        assert abs(f[1 + np.argmax(spec_[1:])] - 2.0) < 0.3
    elif law == "float":
        assert _peak(_response(pair, rate)) == 0.0  # released: the command no longer reaches it
        x = quiet["/truth/state"]
        n = min(len(x["t_s"]), len(pos) + int(T_ON_S / DT_S))
        flow = x["alpha_rad"] if surface == "elevator" else x["beta_rad"]
        sign = -1.0 if surface == "elevator" else 1.0
        _, qpos, _ = _surface(quiet, surface)
        # first-order lag toward delta_float = sign * 0.6 * local flow angle (tau 0.3 s)
        target = sign * 0.6 * flow[int(round(T_ON_S / DT_S)):n][: len(qpos)]
        k = np.arange(len(qpos) - 1)
        np.testing.assert_allclose(qpos[1:], qpos[:-1] + DT_S / 0.3 * (target[k + 1] - qpos[:-1]), atol=1e-9)
