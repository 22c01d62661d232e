"""The shipped thresholds files as tables in docs/study.md: how each was made and validated.

Reads ``aircraft/<aircraft>/fdi_thresholds.toml`` (written by ``fdi-sim study *_calibration
--calibrate`` and ``fdi-sim study *_validation --validate``) and writes the generated block
``thresholds-files`` of docs/study.md, stamped with the digest of the files and this script
(:mod:`fdi_sim.stamp`): a file made or validated again makes the block stale until this runs.

    python docs/make_thresholds_table.py
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.bank.thresholds_file import HeldRate, read_thresholds  # noqa: E402
from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402

AIRCRAFT = ("DHC6", "f16")
FILES = tuple(f"aircraft/{ac}/fdi_thresholds.toml" for ac in AIRCRAFT)
INPUTS = FILES + ("fdi_sim/bank/thresholds_file.py", "docs/make_thresholds_table.py")
MD = ROOT / "docs" / "study.md"


def _rate(h: HeldRate) -> str:
    return (f"{h.false_alarms} in {h.exposure_h:.1f} h = {h.far_per_h:.3g} [{h.ci_per_h[0]:.3g}, "
            f"{h.ci_per_h[1]:.3g}] {h.verdict}, sees {h.detectable_ratio:.2g} x")


def render() -> str:
    lines = []
    for ac, path in zip(AIRCRAFT, FILES):
        t = read_thresholds(ROOT / path)
        v = t.validation
        lines += [f"**{path}**: calibration study `{t.study}` ({t.runs} runs, {t.flight_h:.1f} h, identity "
                  f"{t.study_identity}), node {t.design_h_ft:g} ft / {t.design_vc_kts:g} kt, {t.design_turbulence} "
                  f"turbulence; target {t.far_per_h:g} per h for the bank, calibrated on the {t.split} runs; "
                  + ("no validation yet." if v is None else
                     f"validated on `{v.study}` (seed {v.seed}, {v.runs} runs, {v.flight_h:.1f} h, fdi-sim {v.version})."),
                  "",
                  "| member | trained | file | calibration half | held-out half | halves' ratio | fresh validation |",
                  "|---|---|---|---|---|---|---|"]
        vm = {m.id: m.rate for m in v.members} if v is not None else {}
        for m in t.members:
            lines.append(f"| {m.id} | {m.trained_threshold:.4g} | {m.threshold:.4g} | {_rate(m.calibration)} | "
                         f"{_rate(m.held_out)} | [{m.rate_ratio_ci[0]:.3g}, {m.rate_ratio_ci[1]:.3g}] "
                         f"{m.ratio_check} | {_rate(vm[m.id]) if m.id in vm else '-'} |")
        lines.append(f"| bank | | | {_rate(t.bank_calibration)} | {_rate(t.bank_held_out)} | | "
                     f"{_rate(v.bank) if v is not None else '-'} |")
        lines.append("")
    lines.append("Rates per armed fault-free flight hour with their 95 % intervals (dispersion-scaled where alarms "
                 "cluster by run); `sees`: the smallest ratio of a true rate to the target those hours would show "
                 "as above half the time.")
    return "\n".join(lines)


def main() -> int:
    stamp = make_stamp("thresholds-files", "python docs/make_thresholds_table.py", INPUTS)
    MD.write_text(replace_block(MD.read_text(), stamp, render()))
    print(f"wrote the thresholds-files block of {MD}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
