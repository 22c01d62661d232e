"""Which linear model form fits the detector samples of a logged flight, as the generated block
``sample-pairing`` of docs/detection.md.

Flies the calm-air F-16 doublet flight of ``tests/detectors/test_samples.py`` with real JSBSim
(``scenarios/f16_cruise_doublets.toml`` with turbulence none, no sensor turn-on biases, 12 s, so
the elevator doublet at 5 s only; its own seed 1; no FDI bank, which does not act on a
fault-free flight), linearizes the F-16 at 10 000 ft / 400 kt, and at each detector rate drives
the linear model open loop with the logged commands of the samples (``log_samples``): the rms
of the q [rad/s] and nz [g] prediction errors over 4 s < t < 11 s, for the step model, the ZOH
model as it is, and the ZOH model in the paired form ``(A, B, C A, C B + D)`` (what
``paired_model`` makes of it for n >= 2 simulation steps; forced here at 120 Hz too, where
``paired_model`` leaves the model as it is). Runs in about 5 s.

    python docs/make_detection_table.py
"""
from __future__ import annotations

import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.detectors.samples import log_samples, paired_model  # noqa: E402
from fdi_sim.flightlog import read_log  # noqa: E402
from fdi_sim.linear.grid import parse_grid_spec  # noqa: E402
from fdi_sim.linear.linearize import linearize_grid  # noqa: E402
from fdi_sim.scenario import loads  # noqa: E402
from fdi_sim.sim.run import run  # noqa: E402
from fdi_sim.stamp import table_main  # noqa: E402

MD = ROOT / "docs" / "detection.md"
BLOCK = "sample-pairing"
RATES_HZ = (120, 60, 40, 20, 10)
SIM_RATE_HZ = 120.0
INPUTS = ("scenarios/f16_cruise_doublets.toml", "aircraft/f16", "fdi_sim/aircraft", "fdi_sim/sim", "fdi_sim/pilot",
          "fdi_sim/sensors", "fdi_sim/scenario", "fdi_sim/linear", "fdi_sim/detectors/samples.py",
          "fdi_sim/flightlog", "docs/make_detection_table.py")


def flight(tmp: Path):
    """The calm F-16 doublet flight's log, the 10 kft / 400 kt linearization and the operating point."""
    text = (ROOT / "scenarios" / "f16_cruise_doublets.toml").read_text()
    text = text.replace('turbulence = "moderate"', 'turbulence = "none"').replace(
        'suite = "default"', 'suite = "default"\nbiases = false') + '\n[fdi]\nbank = "none"\n'
    sc, _ = loads(text).shortened(12.0)
    res = run(sc, tmp, progress=False)
    sched = linearize_grid(parse_grid_spec("h_ft=10000;vt_kts=400", "f16"), validate=False)
    return read_log(res.log_path), sched, sc.operating_point()


def open_loop_rms(model, s, names=("q_radps", "nz_g")) -> np.ndarray:
    """rms of dy - (the linear model driven by du), 4 s < t < 11 s (the doublet)."""
    ci = [i for i, k in enumerate(model.input_kinds) if k == "control"]
    A, B, C, D = model.A, model.B[:, ci], model.C, model.D[:, ci]
    x = np.zeros(A.shape[0])
    yhat = np.empty_like(s.dy)
    for j in range(s.n):  # y_j = C x_j + D u_j, x_{j+1} = A x_j + B u_j
        yhat[j] = C @ x + D @ s.du[j]
        x = A @ x + B @ s.du[j]
    w = (s.t_s > 4.0) & (s.t_s < 11.0)
    cols = [s.output_names.index(n) for n in names]
    return np.sqrt(np.mean((s.dy - yhat)[w][:, cols] ** 2, axis=0))


def forced_pair(model):
    """``(A, B, C A, C B + D)`` at any rate (``paired_model`` does it only for n >= 2 steps)."""
    A, B, C, D = (np.asarray(a, dtype=float) for a in (model.A, model.B, model.C, model.D))
    return replace(model, C=C @ A, D=C @ B + D, meta={**dict(model.meta or {}), "paired": True})


def render() -> str:
    with tempfile.TemporaryDirectory() as tmp:
        log, sched, op = flight(Path(tmp))
        lines = ["| rate | step model | ZOH as is | ZOH paired (A, B, CA, CB+D) |", "|---|---|---|---|"]
        for rate in RATES_HZ:
            step = paired_model(sched.model_at(op, dt_s=1.0 / rate, method="step").model, SIM_RATE_HZ)
            zoh = sched.model_at(op, dt_s=1.0 / rate, method="zoh").model
            cells = []
            for i, m in enumerate((step, zoh, forced_pair(zoh))):
                q, nz = open_loop_rms(m, log_samples(log, m, rate))
                cells.append(f"{q:.4f} rad/s, {nz:.3f} g" if rate == RATES_HZ[0] and i == 0 else f"{q:.4f}, {nz:.3f}")
            lines.append(f"| {rate} Hz | " + " | ".join(cells) + " |")
    lines += ["", "rms of the open-loop q and nz prediction errors, 4 s < t < 11 s, calm-air F-16 elevator doublet "
              "(10 000 ft, 400 kt, seed 1, no turn-on biases); at 120 Hz `paired_model` keeps the model as it is, "
              "the last column is the paired form forced there for comparison."]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(table_main(MD, "python docs/make_detection_table.py", [(BLOCK, INPUTS, render)], sys.argv[1:]))
