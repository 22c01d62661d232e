"""The detector card renders from the shipped study results (docs/card/*.json) without flying."""
from __future__ import annotations

import json
from pathlib import Path

from fdi_sim.review.detector_card import render

DOCS = Path(__file__).resolve().parents[2] / "docs"


def test_card_renders_every_detector_and_scenario(tmp_path: Path) -> None:
    md = render(DOCS / "card", tmp_path / "detectors.md", tmp_path)
    text = md.read_text()
    cond = json.loads((DOCS / "card" / "conditions.json").read_text())
    faults = json.loads((DOCS / "card" / "faults.json").read_text())
    for r in cond["rows"]:  # one table row per detector and condition, with its verdict
        assert f"| {r['detector']} | {r['aircraft']} | {r['turbulence']} |" in text
    for res in faults["results"]:
        assert f"| {res['scenario']} |" in text
    assert (tmp_path / "detector_card_faults.png").stat().st_size > 10_000
    # the shipped card says what the closing note and docs/detection.md say
    assert "| kalman-gust-v1 | f16 | moderate | 47680 | 4, 8.4e-05" in text
    assert "| kalman-gust-v1 | DHC6 | moderate | 47680 | 65, 1.4e-03" in text and "**misses**" in text
    assert (DOCS / "detectors.md").read_text() == text  # the committed card is the rendering of the JSON
