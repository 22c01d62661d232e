"""Fault magnitudes in any unit of the target's dimension reach the injector in the target's native
unit (fdi_sim/faults/quantities.py), with the factors of fdi_sim/units.py."""
from __future__ import annotations

import math

import pytest

from fdi_sim.faults.quantities import allowed_units, native_unit, target_unit, to_native
from fdi_sim.units import FPS_PER_KT, FT_PER_M, G0_FPS2, RAD_PER_DEG


@pytest.mark.parametrize("value,unit,native,rate,expected", [
    (2.0, "deg", "rad", False, 2.0 * math.pi / 180.0),
    (0.5, "degps", "radps", False, 0.5 * math.pi / 180.0),
    (10.0, "kts", "fps", False, 10.0 * 1852.0 / 3600.0 / 0.3048),  # 1 kt = 1852 m/h
    (10.0, "fps", "kts", False, 10.0 * 0.3048 * 3600.0 / 1852.0),
    (100.0, "m", "ft", False, 100.0 / 0.3048),
    (1.0, "g", "fps2", False, 32.174049),  # standard gravity 9.80665 m/s^2
    (32.174049, "fps2", "g", False, 1.0),
    # rates: the target's unit per second
    (2.0, "degps2", "radps", True, 2.0 * math.pi / 180.0),
    (0.1, "ktps", "kts", True, 0.1),
    (1.0, "fps2", "kts", True, 3600.0 * 0.3048 / 1852.0),
    (1.0, "mps", "ft", True, 1.0 / 0.3048),
    (1.0, "gps", "g", True, 1.0),
    (0.5, "normps", "norm", True, 0.5),
])
def test_to_native(value: float, unit: str, native: str, rate: bool, expected: float) -> None:
    assert to_native(value, unit, native, rate) == pytest.approx(expected, rel=1e-12)


def test_factors_are_the_units_constants() -> None:
    assert (RAD_PER_DEG, FPS_PER_KT, FT_PER_M, G0_FPS2) == (
        to_native(1.0, "deg", "rad"), to_native(1.0, "kts", "fps"), to_native(1.0, "m", "ft"), to_native(1.0, "g", "fps2"))
    assert G0_FPS2 == pytest.approx(9.80665 / 0.3048, rel=2e-8)  # 32.174049: 9.80665 m/s^2 rounded to 1e-6 ft/s^2


def test_wrong_dimension_is_refused_with_the_allowed_units() -> None:
    with pytest.raises(ValueError, match="use one of deg, rad|use one of rad, deg"):
        to_native(1.0, "kts", "rad")
    with pytest.raises(ValueError, match="per second"):
        to_native(1.0, "deg", "rad", rate=True)  # a rate needs degps or radps
    assert set(allowed_units("kts", rate=True)) == {"fps2", "ktps", "mps2", "g"}


def test_native_units_of_targets() -> None:
    assert native_unit("q_radps") == "radps" and native_unit("mach") == "mach" and native_unit("nz_g") == "g"
    assert target_unit("actuator", "elevator") == "rad" and target_unit("actuator", "throttle") == "norm"
    assert target_unit("sensor", "vc_kts") == "kts" and target_unit("engine", "engine_0") is None
    with pytest.raises(KeyError):
        native_unit("thrust")
