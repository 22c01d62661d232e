"""The engine-gauge check's torque limits (fdi_sim.detectors.engine_gauges.TORQUE_LIMITS_FTLB) are
what the JSBSim engine files say: a changed model must not leave them behind."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from fdi_sim.aircraft.overlays import jsbsim_root
from fdi_sim.detectors.engine_gauges import torque_limit_ftlb


@pytest.mark.parametrize("aircraft", ["DHC6", "DHC6_iced"])
def test_the_torque_limit_is_the_engine_file_s(aircraft: str) -> None:
    """Every engine of the model has an IELU limit ``<ielumaxtorque>`` [lbf ft] equal to the one
    the check is given."""
    folder = jsbsim_root() / "aircraft" / aircraft
    model = ET.parse(folder / f"{aircraft}.xml").getroot()
    files = [e.get("file") for e in model.iter("engine")]
    assert len(files) == 2
    for name in files:
        el = ET.parse(folder / "Engines" / f"{name}.xml").getroot().find("ielumaxtorque")
        assert el is not None and el.get("unit") == "FT*LB"
        assert float(el.text) == torque_limit_ftlb(aircraft)


def test_an_aircraft_without_a_limiter_file_has_none() -> None:
    """The F-16 (one jet engine) has no limit."""
    assert torque_limit_ftlb("f16") == float("inf")
