"""A finished study's false alarms grouped by one sampled parameter: per value, runs, armed
fault-free hours (:func:`fdi_sim.study.stats.exposure_s`, the one exposure definition), the runs'
false-alarm episodes, the rate with its dispersion-scaled 95 % interval
(:func:`fdi_sim.study.stats.overdispersed_rate`: alarms cluster by run) and the members that
raised them (the records' false alarms: per-member episodes outside the faults).

    python tools/study_by_param.py STUDY_OUT_DIR [atmosphere.turbulence]

(Development tool: the envelope studies' rate per turbulence level, issue 24.)
"""
from __future__ import annotations

import sys
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.study.execute import load_records  # noqa: E402
from fdi_sim.study.stats import exposure_s, overdispersed_rate  # noqa: E402
from fdi_sim.units import S_PER_H  # noqa: E402


def _row(label: str, counts: list[int], hours: list[float], by: Counter) -> str:
    r, ci, phi = overdispersed_rate(counts, hours, 0.95)
    rate = "-" if r is None else f"{r:.3g} [{ci[0]:.3g}, {ci[1]:.3g}]"
    return (f"{label:>24} | {len(counts):4d} | {sum(hours):5.1f} | {sum(counts):6d} | {rate} | "
            f"{'-' if phi is None else f'{phi:.2g}'} | {dict(by)}")


def main(argv: list[str]) -> int:
    out = Path(argv[0])
    key = argv[1] if len(argv) > 1 else "atmosphere.turbulence"
    groups: dict[str, tuple[list[int], list[float], Counter]] = defaultdict(lambda: ([], [], Counter()))
    for r in load_records(out):
        counts, hours, by = groups[str(r.get("params", {}).get(key))]
        counts.append(len(r.get("false_alarms", [])))
        hours.append(exposure_s(r) / S_PER_H)
        by.update(a["detector"] for a in r.get("false_alarms", []))
    print(f"{key:>24} | runs | armed h | alarms | per h [95 %] | dispersion | by member")
    for v, (counts, hours, by) in sorted(groups.items()):
        print(_row(v, counts, hours, by))
    allc = [c for g in groups.values() for c in g[0]]
    allh = [h for g in groups.values() for h in g[1]]
    print(_row("all", allc, allh, sum((g[2] for g in groups.values()), Counter())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
