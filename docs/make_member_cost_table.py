"""What each detector costs in the loop: the generated block ``bench-member-cost`` of docs/bench.md
(issue 27's "cost per detector", which the benchmark's wall time cannot separate: a bank's members
run in one loop).

Each registered detector alone in a bank, then each aircraft's default bank and the bank of every
detector, flown as a study or ``fdi-sim bench run`` logs (FDI topics without residuals), 120 s in
moderate turbulence on the cases of ``tests/benchmarks/bench_bank.py`` (their scenarios, their bare
loop), interleaved with bare JSBSim in the same process, best of 3. A detector's thresholds are
trained on four 60 s flights (only the cost is measured here; the designs and training come from
the cache after a 2 s warm-up flight and are not timed). Per cell:

- ``ratio``: the loop's steps per second over bare JSBSim's (1.00: free);
- ``us/step``: the loop's extra wall time per 120 Hz step over bare, ``1e6 / loop - 1e6 / bare``
  [us], of which the loop without any bank is the first row: a member's own cost is its row minus
  that one.

    python docs/make_member_cost_table.py

Needs an idle machine (the ratios move with load); about 15 minutes on 2 cores with a warm cache.
"""
from __future__ import annotations

import os
import platform
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "benchmarks"))

from bench_bank import CASES, best_rates, scenario  # noqa: E402

from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402
from fdi_sim.training import fly  # noqa: E402

MD = ROOT / "docs" / "bench.md"
T_S = 120.0
REPEATS = 3
INPUTS = ("fdi_sim/sim", "fdi_sim/bank", "fdi_sim/detectors", "fdi_sim/decision", "fdi_sim/sensors", "fdi_sim/flightlog",
          "fdi_sim/pilot", "fdi_sim/faults", "fdi_sim/training", "aircraft", "tests/benchmarks/bench_bank.py",
          "tests/benchmarks/bench_loop.py", "docs/make_member_cost_table.py")


def measure(ac: str, bank: str, detector: str | None) -> tuple[float, float, str]:
    """(ratio to bare, extra us per step, why it cannot be designed or "") of ``bank`` (``none``,
    ``default``, ``every``) or of ``detector`` alone (the every-detector set-up) on aircraft ``ac``."""
    from fdi_sim.errors import DesignError

    only = None if detector is None else (detector,)

    def make(T: float):
        return scenario(ac, T, "every" if only else bank, False, 0.5, False, detectors=only)

    with tempfile.TemporaryDirectory() as d:
        try:
            fly(make(2.0), d, progress=False, force=True)  # designs, training, compilation (cached)
        except DesignError as exc:  # no member designable on this aircraft (engine gauges on a single engine)
            return float("nan"), float("nan"), str(exc).rsplit("skipped, ", 1)[-1]
        b, lp = best_rates(ac, make(T_S), d, T_S, REPEATS)
    return lp / b, 1e6 / lp - 1e6 / b, ""


def main() -> int:
    from fdi_sim import registry

    registry.load_builtin_plugins()
    ids = registry.ids("detector")
    rows: list[tuple[str, str | None]] = [("none", None), ("default", None)] + [("one", i) for i in ids] + [
        ("every", None)]
    stamp = make_stamp("bench-member-cost", "python docs/make_member_cost_table.py", INPUTS)
    cells: dict[tuple[int, str], str] = {}
    why_not: list[str] = []
    for ac in CASES:
        for k, (bank, det) in enumerate(rows):
            ratio, us, note = measure(ac, bank, det)
            cells[(k, ac)] = ("cannot be designed here" if note else f"{ratio:.2f} / {us:.1f}")
            why = f" ({note})" if note else ""
            if note:
                why_not.append(f"{det} on the {ac}: {note}")
            print(f"{ac} {det or bank}: {cells[(k, ac)]}{why}", file=sys.stderr, flush=True)
    label = {"none": "the loop, no bank", "default": "the aircraft's default bank", "every": "every detector together"}
    lines = ["| bank | " + " | ".join(f"{ac}: ratio to bare / us per step" for ac in CASES) + " |",
             "|---|" + "---|" * len(CASES)]
    for k, (bank, det) in enumerate(rows):
        lines.append(f"| {label.get(bank, f'`{det}` alone')} | " + " | ".join(cells[(k, ac)] for ac in CASES) + " |")
    lines += ["", f"{T_S:g} s flights in moderate turbulence as a study logs them (FDI topics, no residuals), best of "
              f"{REPEATS}, interleaved with bare JSBSim in the same process; a member's own cost is its extra time per "
              "step minus the first row's; on " + f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores."]
    lines += ["", "Not designable here (the design's own words):"] + [f"- {w}" for w in why_not] if why_not else []
    MD.write_text(replace_block(MD.read_text(), stamp, "\n".join(lines)))
    print(f"wrote the bench-member-cost block of {MD}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
