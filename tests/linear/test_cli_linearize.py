"""`fdi-sim linearize`: exit 2 with one paragraph on bad input, files written on success."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdi_sim.cli import main
from fdi_sim.linear.schedule import ModelSchedule


@pytest.mark.parametrize("argv, match", [
    (["linearize", "b747"], "unknown aircraft 'b747'"),
    (["linearize", "f16", "--grid", "h_ft=10000;vt_kts=600"], "outside the linearization envelope"),
    (["linearize", "f16", "--grid", "h_ft=10000;vt_kts=fast"], "cannot read vt_kts"),
    (["linearize", "DHC6", "--grid", "/no/such/grid.toml"], "not found"),
    (["linearize", "f16", "--duration", "-1"], "must be positive"),
])
def test_bad_input_exits_2_without_traceback(argv: list[str], match: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_one_point_writes_schedule_report_and_figure(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["linearize", "f16", "--grid", "h_ft=10000;vt_kts=400", "--out", str(tmp_path), "--no-fglin",
               "--duration", "3", "--quiet"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "1/1 points linearized" in out and "validation (zoh, configured doublets)" in out
    assert "bar (step, doublets inside the smooth range of JSBSim's tables): 1/1 points below 5 %" in out
    s = ModelSchedule.load(tmp_path / "f16_schedule.npz", aircraft="f16")
    assert len(s.ok_points) == 1 and s.arrays["A"].shape == (1, 10, 10)
    report = (tmp_path / "f16_linearize.md").read_text()
    assert "## Modes per point" in report and "| 10000 ft 400 KTAS |" in report
    assert "| short period | phugoid | dutch roll | roll | spiral |" in report
    assert "f16_poles.png" in report and (tmp_path / "f16_poles.png").stat().st_size > 10_000
    r = s.model_at(s.points[0].op)
    assert r.model.dt_s == pytest.approx(1 / 120) and np.all(np.abs(np.linalg.eigvals(r.model.A)) <= 1 + 1e-9)


def test_named_grid_and_a_name_that_is_neither(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--grid iced`` is aircraft/DHC6/grid_iced.toml; a word that is no file, spec or shipped grid
    is refused with the choices."""
    from fdi_sim.linear.grid import named_grids, resolve_grid

    g = resolve_grid("iced", "DHC6")
    assert g.source.endswith("grid_iced.toml") and sorted({p.icing_eta for p in g.points}) == [0.0, 0.05, 0.1]
    assert set(named_grids("DHC6")) == {"default", "iced"}
    assert main(["linearize", "DHC6", "--grid", "frozen", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "'frozen' is not a file" in err and "default, iced" in err
