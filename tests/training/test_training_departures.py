"""Issue 25: a training flight that departs is replaced by the next training seed and counted; a
calibration is refused only when more than a quarter depart, saying how many and which.

The case is the one the issue found: a DHC-6 approach at 85 KIAS with 10 deg flaps in moderate
turbulence, whose training flight seed 1000002 departs (alpha -20.1 deg at 88 s) while the others fly."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from fdi_sim.errors import DesignError
from fdi_sim.scenario.loader import from_dict, load
from fdi_sim.training.flights import MAX_DEPARTED_FRACTION, fly_training, training_seeds

ROOT = Path(__file__).resolve().parents[2]


def _approach():
    d = json.loads(load(ROOT / "scenarios" / "dhc6_approach_flaps.toml").to_json())
    d["initial"].update(vc_kts=85.0)
    return from_dict(d, source="dhc6_approach_flaps at 85 KIAS")


def test_a_departed_training_flight_is_replaced_and_counted() -> None:
    seeds = training_seeds(4)
    assert seeds[2] == 1_000_002 and MAX_DEPARTED_FRACTION * 4 >= 1
    logs = fly_training(_approach(), seeds, 100.0, progress=False)
    assert len(logs) == 4
    assert [s for s, _ in logs.departed] == [1_000_002]
    assert "alpha" in logs.departed[0][1]
    # the spare is the next training seed: its flight is the fourth log (the fault-free flight of seed 1000004)
    spare = fly_training(_approach(), (1_000_004,), 100.0, progress=False)
    assert (logs[3].topics["/sensors/measurements"].data == spare[0].topics["/sensors/measurements"].data).all()


def test_more_departures_than_allowed_refuse_with_the_count() -> None:
    # three flights: none may be replaced (a quarter of 3 is 0)
    with pytest.raises(DesignError, match=r"1 of 3 fault-free training flights departed \(at most 0 of 3 may be "
                                          r"replaced\): seed 1000002: alpha"):
        fly_training(_approach(), training_seeds(3), 100.0, progress=False)


def test_seeds_of_another_role_get_no_spare() -> None:
    """Seeds outside the training set (a card's held-out flights) are not replaced from it."""
    with pytest.raises(DesignError, match="no spare seed is left"):
        fly_training(_approach(), (1_000_002, 5, 6, 7, 8), 100.0, progress=False)
