"""The flown gusts against the detectors' shaping filter, as the generated block ``flown-gusts`` of
docs/disturbance.md.

The numbers of ``tests/detectors/test_disturbance.py::test_flown_gusts_match_the_shaping_filter``,
computed the same way (the test's flight, recursion check and 1/e time are repeated here, not
imported from tests/): real JSBSim, each aircraft trimmed at its point (F-16 10 kft / 400 KTAS,
DHC-6 5 kft / 120 KIAS), turbulence light and moderate with seed 11, stepped 200 s at 120 Hz with
the integrators off (the aircraft held at its trim state while FGWinds runs every step). Per gust
axis: the rms and the 1/e time of the autocorrelation as flown, against the stationary rms and
1/e time of ``dryden_shaping_filter(dryden_parameters(mean h, mean Vt, level, span))``; under the
table, the one-step residual check of JSBSim's recursion with our parameters. Four 200 s
flights: about 25 s niced on a busy 2-core machine.

    python docs/make_disturbance_table.py
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fdi_sim.aircraft import Aircraft, Atmosphere, trim  # noqa: E402
from fdi_sim.detectors.disturbance import (  # noqa: E402
    TURBULENCE_SETTINGS, dryden_parameters, dryden_shaping_filter, euler_to_body,
)
from fdi_sim.operating_point import OperatingPoint  # noqa: E402
from fdi_sim.stamp import make_stamp, replace_block  # noqa: E402

MD = ROOT / "docs" / "disturbance.md"
BLOCK = "flown-gusts"
COMMAND = "python docs/make_disturbance_table.py"
INPUTS = ("aircraft", "fdi_sim/_aircraft", "fdi_sim/aircraft", "fdi_sim/data.py", "fdi_sim/detectors/disturbance.py",
          "fdi_sim/operating_point.py", "fdi_sim/linear/model.py", "fdi_sim/units.py", "fdi_sim/errors.py",
          "docs/make_disturbance_table.py")
DT_S = 1.0 / 120.0
T_S = 200.0
#: the flight's seed is the test's own (tests/detectors/test_disturbance.py flies 11), so the table is
#: the test's numbers: a gust-model check, not a detector's evaluation; tests are outside the seed
#: registry (fdi_sim/seeds.py), and this copy of their flight stays with them
TEST_FLIGHT = {"seed": 11}
LEVELS = ("light", "moderate")
POINTS = {"f16": OperatingPoint("f16", 10000.0, vt_kts=400.0), "DHC6": OperatingPoint("DHC6", 5000.0, vc_kts=120.0)}
PROPS = ("atmosphere/total-wind-north-fps", "atmosphere/total-wind-east-fps", "atmosphere/total-wind-down-fps",
         "atmosphere/p-turb-rad_sec", "atmosphere/q-turb-rad_sec", "atmosphere/r-turb-rad_sec",
         "attitude/phi-rad", "attitude/theta-rad", "attitude/psi-rad", "velocities/vt-fps", "position/h-sl-ft")


def fly(op: OperatingPoint, level: str, t_s: float, seed: int) -> tuple[np.ndarray, float]:
    """Gusts in local axes ``xi`` (N, 6), Vt and h (N, 2) flown, and the wing span [ft] (the test's flight)."""
    ac = Aircraft(op.aircraft, DT_S)
    trim(ac, op)
    ac.set_atmosphere(Atmosphere(level), seed)
    for kind in ("rate/rotational", "rate/translational", "position/rotational", "position/translational"):
        ac[f"simulation/integrator/{kind}"] = 0
    if not (ac["atmosphere/turb-type"] == 3
            and ac["atmosphere/turbulence/milspec/severity"] == TURBULENCE_SETTINGS[level][0]):
        raise RuntimeError(f"JSBSim's turbulence is not the milspec model at level {level}")
    get = [ac.node(p).get_double_value for p in PROPS]
    n = int(round(t_s / DT_S))
    rec = np.empty((n + 1, len(PROPS)))
    rec[0] = [g() for g in get]
    for k in range(n):
        if not ac.step():
            raise RuntimeError(f"JSBSim stopped at step {k}")
        rec[k + 1] = [g() for g in get]
    xi = rec[:, :6].copy()
    for k in range(n + 1):  # vTurbPQR = Tl2b [xi_p, xi_q, xi_r]: back to local axes
        xi[k, 3:] = euler_to_body(*rec[k, 6:9]).T @ rec[k, 3:6]
    return np.hstack([xi, rec[:, 9:11]]), ac["metrics/bw-ft"]


def check_recursion(x: np.ndarray, span_ft: float, level: str) -> dict[str, float]:
    """Variance of the normalized one-step residuals of JSBSim's recursion with our parameters (u, v,
    w, p), and the rms of q, r left over by the high-pass of w, v relative to their rms."""
    V, h = x[:-1, 6], x[1:, 7]
    pars = [dryden_parameters(hk, vk, level, span_ft) for hk, vk in zip(h, V)]
    out = {}
    for i, name, sig, tau, two in ((0, "u", "sigma_u_fps", "tau_u_s", 1), (1, "v", "sigma_v_fps", "tau_u_s", 2),
                                   (2, "w", "sigma_w_fps", "tau_w_s", 2), (3, "p", "sigma_p_radps", "tau_p_s", 1)):
        a = np.array([1 - two * DT_S / getattr(p, tau) for p in pars])
        b = np.array([getattr(p, sig) * math.sqrt(2 * two * DT_S / getattr(p, tau)) for p in pars])
        out[name] = float(np.var((x[1:, i] - a * x[:-1, i]) / b))
    for i, j, c, tau in ((4, 2, math.pi / 4 / span_ft, "tau_q_s"), (5, 1, math.pi / 3 / span_ft, "tau_r_s")):
        a = np.array([1 - DT_S / getattr(p, tau) for p in pars])
        err = x[1:, i] - a * x[:-1, i] - c * (x[1:, j] - x[:-1, j])
        out["qr"[i - 4]] = float(np.std(err) / np.std(x[:, i]))
    return out


def acf_1e(x: np.ndarray, max_lag: int) -> float:
    """First lag [s] where the sample autocorrelation falls below 1/e (linear interpolation)."""
    x = x - x.mean()
    r = np.array([np.dot(x[: len(x) - k], x[k:]) for k in range(max_lag)]) / np.dot(x, x)
    k = int(np.argmax(r < 1 / math.e))
    return (k - 1 + (r[k - 1] - 1 / math.e) / (r[k - 1] - r[k])) * DT_S


def _g(x: float) -> str:
    """Three significant digits, trailing zeros kept."""
    return f"{x:#.3g}".rstrip(".")


def render() -> str:
    rows, checks, names = [], [], None
    for ac_name, op in POINTS.items():
        for level in LEVELS:
            x, span = fly(op, level, T_S, TEST_FLIGHT["seed"])
            res = check_recursion(x, span, level)
            p = dryden_parameters(float(np.mean(x[:, 7])), float(np.mean(x[:, 6])), level, span)
            st = dryden_shaping_filter(p).statistics()
            names = st.names
            cells = []
            for i, name in enumerate(st.names):
                rms_pred, t_pred = st.of(name)
                rms = float(np.sqrt(np.mean(x[:, i] ** 2)))
                t_meas = acf_1e(x[:, i], int(4 * t_pred / DT_S) + 10)
                cells += [f"{_g(rms)}/{_g(rms_pred)}", f"{_g(t_meas)}/{_g(t_pred)}"]
            rows.append(f"| {ac_name} {level} | " + " | ".join(cells) + " |")
            checks.append((f"{ac_name} {level}", res, len(x) - 1))
    head = "| case | " + " | ".join(f"{n[0]} | " for n in names) + " |"
    lines = [head, "|---|" + "---|" * (2 * len(names))] + rows
    var = [r[a] for _, r, _ in checks for a in "uvwp"]
    qr = [r[a] for _, r, _ in checks for a in "qr"]
    tol = 5 * math.sqrt(2 / min(n for _, _, n in checks))
    lines += ["", f"Measured/predicted rms [ft/s, rad/s], then 1/e time [s], per gust axis; {T_S:g} s at 120 Hz, "
              f"seed {TEST_FLIGHT['seed']} in both levels. One-step residuals of JSBSim's recursion with our parameters: variance "
              f"{min(var):.3f} to {max(var):.3f} over u, v, w, p of the four flights (tolerance 1 +- {tol:.3f}, "
              f"5 sqrt(2/N)); q and r off the high-pass of w and v by {100 * min(qr):.2f} to {100 * max(qr):.2f} % rms."]
    return "\n".join(lines)


def main() -> int:
    t0 = time.perf_counter()
    stamp = make_stamp(BLOCK, COMMAND, INPUTS)
    body = render()
    MD.write_text(replace_block(MD.read_text(), stamp, body))
    print(body)
    print(f"wrote the {BLOCK} block of {MD} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
