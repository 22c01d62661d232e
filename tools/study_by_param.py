"""A finished study's false alarms grouped by one sampled parameter: per value, runs, flight hours,
false-alarm episodes (the runs' records), the rate with its exact 95 % Poisson interval, and the
members that raised them.

    python tools/study_by_param.py STUDY_OUT_DIR [atmosphere.turbulence]

(Development tool: the envelope studies' rate per turbulence level, issue 24.)
"""
from __future__ import annotations

import sys
from collections import Counter, defaultdict
from pathlib import Path

from scipy.stats import chi2

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.study.execute import load_records  # noqa: E402


def interval(k: int, h: float) -> tuple[float, float]:
    """Exact (Garwood) 95 % interval of a Poisson rate [1/h]."""
    lo = chi2.ppf(0.025, 2 * k) / 2 / h if k else 0.0
    return lo, chi2.ppf(0.975, 2 * k + 2) / 2 / h


def main(argv: list[str]) -> int:
    out = Path(argv[0])
    key = argv[1] if len(argv) > 1 else "atmosphere.turbulence"
    groups: dict[str, list] = defaultdict(lambda: [0, 0, 0.0, Counter()])
    for r in load_records(out):
        g = groups[str(r.get("params", {}).get(key))]
        g[0] += 1
        g[1] += len(r.get("false_alarms", []))
        g[2] += float(r.get("flight_h", 0.0))
        g[3].update(a["detector"] for a in r.get("false_alarms", []))
    print(f"{key:>24} | runs | hours | alarms | per h [95 %] | by member")
    for v, (n, k, h, by) in sorted(groups.items()):
        lo, hi = interval(k, h)
        print(f"{v:>24} | {n:4d} | {h:5.1f} | {k:6d} | {k / h:.3g} [{lo:.3g}, {hi:.3g}] | {dict(by)}")
    n, k, h = (sum(g[i] for g in groups.values()) for i in range(3))
    lo, hi = interval(k, h)
    print(f"{'all':>24} | {n:4d} | {h:5.1f} | {k:6d} | {k / h:.3g} [{lo:.3g}, {hi:.3g}] |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
