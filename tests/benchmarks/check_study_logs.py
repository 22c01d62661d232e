"""Bit-identity check of the study mode: scenarios flown as a Monte Carlo study flies them.

The companion of ``check_identical_logs.py`` (which flies the scenarios as written, full logs):
here each scenario gets the default bank, no residual logging and no per-step topics (what
``fdi_sim.study.spec`` gives a study's runs), so the loop's statistics-only fast path is the one
checked. Run on demand (a few minutes)::

    python tests/benchmarks/check_study_logs.py --write /tmp/ref_study.json
    python tests/benchmarks/check_study_logs.py --compare /tmp/ref_study.json

Exit status 1 on any difference, naming the scenario and the topic.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from check_identical_logs import SCENARIOS, compare, fingerprint

from fdi_sim import scenario
try:
    from fdi_sim.training import fly as fly_scenario
except ImportError:  # a tree from before fdi_sim.training (bench_ab.py times an older commit's tree)
    from fdi_sim.sim import run as fly_scenario

#: fault-free and faulty, both aircraft, with and without dropouts (the loop's two paths)
DEFAULT = ("f16_cruise_doublets", "dhc6_cruise_doublets", "f16_pitch_gyro_bias", "dhc6_intermittent_aoa",
           "f16_stuck_elevator", "dhc6_tail_icing")


def study_text(path: Path) -> str:
    """The scenario's TOML with the study's [fdi] and [log] settings (appended or merged)."""
    text = path.read_text()
    lines = text.rstrip("\n").splitlines()
    sections = [ln.strip() for ln in lines if ln.strip().startswith("[")]
    if "[fdi]" in sections:
        if sections[-1] != "[fdi]":
            raise ValueError(f"{path.name}: [fdi] is not the last section; cannot append to it")
        extra = "log_residuals = false\n"
    else:
        extra = '\n[fdi]\nbank = "default"\nlog_residuals = false\n'
    return text.rstrip("\n") + "\n" + extra + "\n[log]\nper_step = false\n"


def fly(names: tuple[str, ...]) -> dict[str, dict]:
    out = {}
    with tempfile.TemporaryDirectory() as d:
        for name in names:
            path = SCENARIOS / f"{name}.toml"
            sc = scenario.loads(study_text(path), source=str(path))
            t0 = time.perf_counter()
            res = fly_scenario(sc, d, progress=False)
            out[name] = {"status": res.status, "steps": res.summary.steps, **fingerprint(res.log_path)}
            print(f"{name:30} {res.status:10} {res.summary.steps:6d} steps  loop {res.summary.wall_s:5.2f} s  "
                  f"all {time.perf_counter() - t0:5.1f} s", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", type=Path)
    ap.add_argument("--compare", type=Path)
    ap.add_argument("names", nargs="*", default=list(DEFAULT))
    args = ap.parse_args(argv)
    new = fly(tuple(args.names))
    if args.write:
        args.write.write_text(json.dumps(new, indent=1, sort_keys=True))
    if args.compare:
        ref = {k: v for k, v in json.loads(args.compare.read_text()).items() if k in new}
        bad = compare(ref, new)
        print(f"{len(ref)} compared: {len(ref) - len({b.split(':')[0] for b in bad})} with identical topics")
        for b in bad:
            print("DIFFERENT", b)
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
