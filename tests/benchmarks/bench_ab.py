"""Benchmark (on demand): the study-mode loop of two source trees, interleaved, as ratios to bare JSBSim.

On a shared machine the absolute step times move with the load by a factor of two or more; the
ratio loop/bare measured in one process moves much less, and alternating the two trees trial by
trial lets the load hit both alike. ``base`` is a copy of another commit's tree::

    mkdir /tmp/base && git archive HEAD fdi_sim aircraft scenarios | tar -x -C /tmp/base
    python tests/benchmarks/bench_ab.py /tmp/base [trials] [duration_s]

Each trial is a fresh process on one tree: a 60 s warm-up flight (design cached, kernels loaded),
then bare JSBSim and the study-mode flight (``check_study_logs.study_text``) twice, interleaved,
in CPU time of the process (``time.process_time``: far steadier than wall time when other jobs
share the cores), the loop's per step from a long and a 60 s flight (the set-up cancels); it
reports the best of each as us/step. Printed: per tree and aircraft the median over the trials
of the ratio and of the loop's overhead over bare (us/step). Never a timed assertion in the suite.
"""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
NEW = HERE.parents[1]

TRIAL = r"""
import sys, tempfile, time
sys.path.insert(0, {here!r})
from fdi_sim.aircraft import Aircraft, Atmosphere, trim
from bench_split import _study_scenario
try:
    from fdi_sim.training import fly
except ImportError:  # a base tree from before fdi_sim.training (its loop designed its own bank)
    from fdi_sim.sim import run as fly
name, T = {name!r}, {T!r}
sc, short = _study_scenario(name, T), _study_scenario(name, 60.0)
bare, loop = [], []
def cpu_run(s, d):
    c0 = time.process_time()
    r = fly(s, d, progress=False).summary
    return time.process_time() - c0, r.steps
with tempfile.TemporaryDirectory() as d:
    fly(short, d, progress=False)
    for _ in range(2):
        ac = Aircraft(sc.aircraft, sc.dt_s)  # bench_loop.bare_rate in CPU time
        trim(ac, sc.operating_point())
        ac.set_atmosphere(Atmosphere("moderate"), 1)
        write, n = ac.command_writer(), int(min(T, 120.0) / sc.dt_s)
        c0 = time.process_time()
        for _ in range(n):
            write(0.0, 0.0, 0.0, 0.3)
            ac.step()
        bare.append(1e6 * (time.process_time() - c0) / n)
        (c_long, n_long), (c_short, n_short) = cpu_run(sc, d), cpu_run(short, d)
        loop.append(1e6 * (c_long - c_short) / (n_long - n_short))  # the set-up cancels
print(min(bare), min(loop))
"""


def trial(tree: Path, name: str, T: float) -> tuple[float, float]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    code = TRIAL.format(here=str(HERE), name=name, T=T)
    out = subprocess.run([sys.executable, "-c", code], cwd=tree, env=env, capture_output=True, text=True, check=True)
    import fdi_sim  # noqa: F401 (only to fail early outside the venv)
    b, lp = (float(v) for v in out.stdout.split()[-2:])
    return b, lp


def main(base: str, trials: int = 4, T: float = 300.0,
         names: tuple[str, ...] = ("f16_cruise_doublets", "dhc6_cruise_doublets")) -> None:
    trees = {"base": Path(base).resolve(), "new": NEW}
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} (2 cores)")
    for name in names:
        res: dict[str, list[tuple[float, float]]] = {k: [] for k in trees}
        for _ in range(trials):
            for label, tree in trees.items():
                res[label].append(trial(tree, name, T))
        for label, rows in res.items():
            ratio = statistics.median(b / lp for b, lp in rows)
            over = statistics.median(lp - b for b, lp in rows)
            print(f"{name:22} {label:5} ratio to bare {ratio:.3f} (trials {', '.join(f'{b / lp:.3f}' for b, lp in rows)})"
                  f"  overhead {over:.2f} us/step  bare {statistics.median(b for b, _ in rows):.2f} us/step")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main(sys.argv[1], *(int(sys.argv[2]),) if len(sys.argv) > 2 else (), *(float(sys.argv[3]),) if len(sys.argv) > 3 else (),
         *(tuple(sys.argv[4].split(",")),) if len(sys.argv) > 4 else ())
