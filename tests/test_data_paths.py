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


def test_a_bench_case_names_its_suite_inside_the_package():
    """A bench case's scenario source is in every note of its log (a member skipped, a design): it
    held the checkout's path (``/work/.../fdi_sim/_bench/fdi-bench-v1.toml case ...``), so the same
    case gave different log bytes from two checkouts."""
    from fdi_sim.bench.run import bench_bank, suite_study
    from fdi_sim.bench.suite import SUITES_DIR, load_suite
    from fdi_sim.data import PACKAGE

    assert shown_path(SUITES_DIR / "fdi-bench-v1.toml") == "fdi_sim/_bench/fdi-bench-v1.toml"
    assert shown_path(PACKAGE / "_scenarios" / "f16_cruise_doublets.toml") == "fdi_sim/_scenarios/f16_cruise_doublets.toml"
    suite = load_suite()
    case = suite.cases[0]
    st = suite_study(suite, bench_bank(True), [case])
    sc, _ = st.run_scenario(case.index)
    assert sc.source == f"fdi_sim/_bench/{suite.name}.toml case {case.case}"
    assert str(PACKAGE) not in sc.source
