"""Package data is shown by where it sits in the package, not where the package was checked out."""
from __future__ import annotations

from pathlib import Path

from fdi_sim.data import AIRCRAFT_DATA, aircraft_file, shown_path


def test_package_data_is_shown_inside_the_package_and_a_users_file_as_given(tmp_path):
    assert shown_path(aircraft_file("DHC6", "fdi_atlas.json")) == "fdi_sim/_aircraft/DHC6/fdi_atlas.json"
    assert shown_path(aircraft_file("DHC6-iced", "fdi_thresholds.toml")) == "fdi_sim/_aircraft/DHC6/fdi_thresholds.toml"
    assert shown_path(str(AIRCRAFT_DATA / "f16" / "x.toml")) == "fdi_sim/_aircraft/f16/x.toml"
    own = tmp_path / "my_atlas.json"
    assert shown_path(own) == str(own)
    assert not Path(shown_path(aircraft_file("f16", "fdi_atlas.json"))).is_absolute()
