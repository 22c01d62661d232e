"""The loop's speed with the default bank against bare JSBSim in the same process: the generated
block ``bank-speed`` of docs/bank.md. The cases of ``tests/benchmarks/bench_bank.py`` (its
scenarios, its bare loop, its interleaving; 120 s flights in moderate turbulence, best of 3), the
bank of every detector left out (its training makes it a study of its own: run the benchmark).
Each row is measured with both loops (``FDI_SIM_CORE=python`` and ``compiled``: the compiled chunk
core of issue 26). The ratios depend on the machine and on its load: run it on an idle one.

    python docs/make_bank_speed_table.py
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

from bench_bank import CASES, loop_rate, scenario  # noqa: E402
from bench_loop import bare_rate  # noqa: E402

from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402
from fdi_sim.training import fly  # noqa: E402

MD = ROOT / "docs" / "bank.md"
T_S = 120.0
REPEATS = 3
#: (row label, bank, per-step log, block [s], residuals)
ROWS = (("full (`fdi-sim run`), no bank", "none", True, 0.5, True),
        ("full, default bank", "default", True, 0.5, True),
        ("FDI topics only, default bank (with residuals)", "default", False, 0.5, True),
        ("FDI topics only, default bank, 1 s blocks", "default", False, 1.0, True),
        ("as a study logs (FDI topics, no residuals), default bank", "default", False, 0.5, False))
INPUTS = ("fdi_sim/sim", "fdi_sim/bank", "fdi_sim/detectors", "fdi_sim/decision", "fdi_sim/sensors", "fdi_sim/flightlog",
          "fdi_sim/pilot", "fdi_sim/faults", "aircraft", "tests/benchmarks/bench_bank.py", "tests/benchmarks/bench_loop.py",
          "docs/make_bank_speed_table.py")


CORES = ("python", "compiled")


def main() -> int:
    cells: dict[tuple[str, str, str], str] = {}
    bare_all: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as d:
        for ac in CASES:
            for label, bank, per_step, block, resid in ROWS:
                sc = scenario(ac, T_S, bank, per_step, block, resid)
                for core in CORES:
                    os.environ["FDI_SIM_CORE"] = core
                    fly(scenario(ac, 2.0, bank, per_step, block, resid), d, progress=False, force=True)  # designs, compile
                bare: list[float] = []
                loop: dict[str, list[float]] = {c: [] for c in CORES}
                for _ in range(REPEATS):  # interleaved so that machine load hits all alike
                    bare.append(bare_rate(ac, sc, T_S))
                    for core in CORES:
                        os.environ["FDI_SIM_CORE"] = core
                        loop[core].append(loop_rate(sc, d))
                for core in CORES:
                    cells[(label, ac, core)] = f"{max(loop[core]) / max(bare):.2f}"
                    print(f"{ac} {label} {core}: {cells[(label, ac, core)]}", file=sys.stderr, flush=True)
                bare_all[ac] = max(bare_all.get(ac, 0.0), max(bare))
    os.environ.pop("FDI_SIM_CORE", None)
    acs = tuple(CASES)
    lines = ["| log | " + " | ".join(f"{ac} {core}" for ac in acs for core in CORES) + " |",
             "|---|" + "---|" * (len(acs) * len(CORES))]
    lines += [f"| {label} | " + " | ".join(cells[(label, ac, core)] for ac in acs for core in CORES) + " |"
              for label, *_ in ROWS]
    lines += ["", f"Ratio of steps per second to bare JSBSim (`bench_loop.bare_rate`: the trimmed aircraft in moderate "
              f"turbulence, the loop's four command writes and `run()` from Python), {T_S:g} s flights, best of "
              f"{REPEATS}, interleaved; `python`: the Python loop, `compiled`: the compiled chunk core "
              "(`fdi_sim/sim/_chunk.py`); bare JSBSim ran at " + ", ".join(f"{bare_all[a]:,.0f} ({a})" for a in acs)
              + f" steps per second on {platform.processor() or platform.machine()}, {os.cpu_count()} cores."]
    stamp = make_stamp("bank-speed", "python docs/make_bank_speed_table.py", INPUTS)
    MD.write_text(replace_block(MD.read_text(), stamp, "\n".join(lines)))
    print(f"wrote the bank-speed block of {MD}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
