"""Render the detector card (``docs/detectors.md`` and its figures) from the study's JSON results.

The numbers come from :mod:`fdi_sim.study.card` (run by ``docs/make_detector_card.py``); this
module only reads them, so the card can be redrawn without flying again. Each table is a generated
block (:mod:`fdi_sim.stamp`) carrying the stamp of the JSON card its numbers come from (the stamp
made when they were computed, its id the block's); a card without a stamp gives its tables the
"unstamped" marker line instead.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from fdi_sim.decision.intervals import clopper_pearson
from fdi_sim.stamp import Stamp, generated_block

#: what a table of a card without a stamp (written before the stamps) says above it
UNSTAMPED = "<!-- table: result, unstamped; regenerate: python docs/make_detector_card.py -->"


def _fmt(x: float) -> str:
    return "0" if x == 0 else f"{x:.1e}"


def conditions_table(data: dict[str, Any]) -> list[str]:
    rows = data["rows"]
    ids = sorted({r["detector"] for r in rows})
    lines = ["| detector | aircraft | turbulence | held-out samples | calibrated: alarms, fraction [95 % CI] | "
             "own threshold: fraction | onsets /h | us/sample | target 1e-4 |",
             "|---|---|---|---|---|---|---|---|---|"]
    for ident in ids:
        for r in (x for x in rows if x["detector"] == ident):
            if r["error"]:
                lines.append(f"| {ident} | {r['aircraft']} | {r['turbulence']} | - | not designed: "
                             f"{r['error'][:110].replace('|', '/')} | - | - | - | unusable |")
                continue
            n, k = r["samples"], r["calibrated_alarms"]
            lo, hi = clopper_pearson(k, n)
            own = r["own_threshold_alarms"] / n if n else math.nan
            lines.append(f"| {ident} | {r['aircraft']} | {r['turbulence']} | {n} | {k}, {_fmt(k / n)} "
                         f"[{_fmt(lo)}, {_fmt(hi)}] | {own:.2e} | {r['onsets_per_h']:.1f} | "
                         f"{r['cost_us_per_sample']:.1f} | {'meets' if r['meets_target'] else '**misses**'} |")
    return lines


def faults_table(data: dict[str, Any]) -> list[str]:
    lines = ["| scenario | detector | fault | alarms before onset | first alarm [s] | delay [s] | isolated as |",
             "|---|---|---|---|---|---|---|"]
    for res in data["results"]:
        for r in res["rows"]:
            if r["error"]:
                continue
            if r["delay_s"] is None and r["alarms_before_onset"] == 0:
                continue  # silent detectors are summarised below
            iso = r["isolated_as"] or "rejected"
            mark = "" if r["isolation_correct"] is None else (" (right)" if r["isolation_correct"] else " (wrong)")
            delay = "-" if r["delay_s"] is None else f"{r['delay_s']:.2f}"
            first = "-" if r["first_alarm_s"] is None else f"{r['first_alarm_s']:.2f}"
            lines.append(f"| {r['scenario']} | {r['detector']} | {r['label']} | {r['alarms_before_onset']} | {first} | "
                         f"{delay} | {iso}{mark} |")
    return lines


def best_per_scenario(data: dict[str, Any]) -> list[str]:
    """Per scenario: the detectors that detect with no alarm before the onset, fastest first."""
    lines = ["| scenario | fault | clean detections (no alarm before onset), fastest first |", "|---|---|---|"]
    for res in data["results"]:
        rows = [r for r in res["rows"] if not r["error"] and r["delay_s"] is not None and r["alarms_before_onset"] == 0]
        rows.sort(key=lambda r: r["delay_s"])
        label = res["rows"][0]["label"] if res["rows"] else ""
        def iso(r: dict[str, Any]) -> str:
            mark = "" if r["isolation_correct"] is None else (", right" if r["isolation_correct"] else ", wrong")
            return f"{r['isolated_as'] or 'rejected'}{mark}"

        cells = "; ".join(f"{r['detector']} {r['delay_s']:.2f} s ({iso(r)})" for r in rows)
        lines.append(f"| {res['scenario']} | {label} | {cells or '**none**'} |")
    return lines


def fault_figure(data: dict[str, Any], path: Path) -> Path:
    """Test statistic against its calibrated threshold over the true fault interval, per scenario."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    res = data["results"]
    fig, axes = plt.subplots(len(res), 1, figsize=(9, 2.0 * len(res)), squeeze=False)
    for ax, r in zip(axes[:, 0], res):
        tr = r["traces"].get("kalman-gust-v1")
        faults = [x for x in r["rows"] if x["detector"] == "kalman-gust-v1"]
        if tr is None:
            ax.set_title(f"{r['scenario']}: kalman-gust-v1 not run")
            continue
        t = np.asarray(tr["t_s"])
        s = np.asarray([np.nan if v is None else v for v in tr["statistic"]], dtype=float)
        ax.semilogy(t, np.maximum(s, 1e-2), lw=0.7, color="k", label="T (kalman-gust-v1)")
        ax.axhline(tr["threshold"], color="r", lw=1.0, label="calibrated threshold")
        for f in faults:
            ax.axvspan(f["t_onset_s"], t[-1], color="orange", alpha=0.2, label="fault active (from onset)")
            if f["first_alarm_s"] is not None:
                ax.axvline(f["first_alarm_s"], color="b", ls="--", lw=0.8,
                           label=f"first alarm +{f['delay_s']:.2f} s, {f['isolated_as'] or 'rejected'}")
        ax.set_title(r["scenario"], fontsize=9, loc="left")
        ax.set_ylabel("T")
        ax.legend(fontsize=6, loc="upper left")
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _table(card: dict[str, Any], block_id: str, table: list[str]) -> list[str]:
    """``table`` as the generated block ``block_id`` with ``card``'s stamp (the marker line and the
    table when the card has none)."""
    d = card.get("stamp")
    if not isinstance(d, dict):
        return [UNSTAMPED] + table
    stamp = Stamp(**{**d, "inputs": tuple(d["inputs"]), "id": block_id})
    return generated_block(stamp, "\n".join(table)).splitlines()


def render(results_dir: Path, md_path: Path, figures_dir: Path) -> Path:
    """Write the markdown card from ``conditions.json`` and ``faults.json`` in ``results_dir``."""
    cond = json.loads((results_dir / "conditions.json").read_text()) if (results_dir / "conditions.json").exists() else None
    faults = json.loads((results_dir / "faults.json").read_text()) if (results_dir / "faults.json").exists() else None
    lines = ["# Detector card", "",
             "Made by `python docs/make_detector_card.py` (protocol: `fdi_sim/study/card.py`); every number below is",
             "read from `docs/card/*.json`. Detector rate 20 Hz; per-sample false-alarm target 1e-4.", ""]
    if cond:
        lines += ["## Fault-free flights not used for calibration",
                  "",
                  f"Training: {cond['n_train']} fault-free flights of {cond['duration_s']:g} s per condition (seeds "
                  "1e6 + i); test flights: 8 of the same length, seeds 101-108 (a development set of the seed registry: ",
                  "looked at while the tail method was chosen). 'calibrated' uses the empirical",
                  "quantile of the training flights; 'own threshold' is the detector's design (analytic) threshold, or the",
                  "shipped calibration of the kinematic checks. 'meets' = the held-out count is at most the upper end",
                  "of the binomial 95 % interval of the target (fewer false alarms than the target is not a failure).",
                  ""] + _table(cond, "detector-card-conditions", conditions_table(cond)) + [""]
    if faults:
        fig = fault_figure(faults, figures_dir / "detector_card_faults.png")
        lines += ["## Shipped fault scenarios", "",
                  f"Each detector designed at the scenario's point and calibrated on {faults['n_train']} fault-free "
                  f"flights of it ({faults['duration_s']:g} s, faults removed) at the same target; isolation is the most",
                  "frequent hypothesis in the first second of alarm ('rejected': no hypothesis within the angle bound).",
                  ""] + _table(faults, "detector-card-faults-clean", best_per_scenario(faults)) + [
                  "", "Every detector that alarmed:", ""] + _table(faults, "detector-card-faults-all",
                                                                     faults_table(faults)) + [
                  "", f"![kalman-gust-v1 statistic against its threshold over the fault interval](figures/{fig.name})", ""]
    md_path.write_text("\n".join(lines) + "\n")
    return md_path
