"""The steady-state Kalman predictor whose one-step prediction error the CUSUM watches.

Noise model, in the standard form of the detector samples (``fdi_sim.detectors.samples``)::

    x_{j+1} = A x_j + B_c du_j + B_w w_j              process
    dy_j    = C x_j + D_c du_j + D_w w_j + v_j         measurement

with ``B_c``, ``D_c`` the columns of the command inputs (``*_cmd_norm``, input kind
``"control"``) and ``B_w``, ``D_w`` those of the gust inputs (``*_gust_body_fps``) plus, with a
small std, the command columns again (unmodelled command activity). ``w_j ~ N(0, Q_w)``,
``Q_w = diag(sigma_gust^2 [ft^2/s^2], sigma_cmd^2 [-])``; ``v_j ~ N(0, R_v)``, ``R_v = diag(sigma_i^2)``
in the units of each output. The gusts are not logged: they enter the predictor only as noise
(their deviation is 0 in the prediction).

The gusts reach both the state and the measurement (air data reads the air-mass velocity), so
the process and measurement noises are correlated::

    Q = B_w Q_w B_w'      R = D_w Q_w D_w' + R_v      S = B_w Q_w D_w'

The predictor's covariance ``P`` (of ``x_j - xhat_{j|j-1}``) solves the filtering DARE with a
cross term (the control DARE of ``scipy.linalg.solve_discrete_are`` for ``(A', C')``)::

    P = A P A' + Q - (A P C' + S) (C P C' + R)^-1 (A P C' + S)'

    Sigma = C P C' + R                        innovation covariance
    K     = (A P C' + S) Sigma^-1             predictor gain
    xhat_{j+1|j} = A xhat_{j|j-1} + B_c du_j + K nu_j,   nu_j = dy_j - C xhat_{j|j-1} - D_c du_j

and the innovations ``nu_j`` of the exact model are white with covariance ``Sigma``; the residual
of the chosen signal ``i`` is ``e_j = nu_j[i] / sqrt(Sigma_ii)`` ~ N(0, 1) [-].

Why the command noise: on the F-16 at 10 kft / 400 KTAS the model has a mode at ``z = 1`` (the
flight path's course: a body-axis gust changes the sideslip, not the inertial velocity) that
the gusts alone do not excite, and the DARE then has no stabilizing solution. A small command
noise (default 0.002, a fifth of a percent of the stick) reaches it.
"""
from __future__ import annotations

import difflib
import hashlib
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["DEFAULT_NOISE_STD", "KERNEL_VERSION", "CusumDesign", "default_noise_std", "design_cusum", "is_wrapped"]

#: bumped whenever the kernel computes different numbers from the same design (goes into design_key)
KERNEL_VERSION = "cusum-residual-kernel-1"

#: measurement-noise std per output [output units]: gyros, accelerometers, attitude and flow
#: angles, calibrated airspeed, altitude, climb rate
DEFAULT_NOISE_STD: dict[str, float] = {
    "p_radps": 0.002, "q_radps": 0.002, "r_radps": 0.002,
    "nx_g": 0.005, "ny_g": 0.005, "nz_g": 0.005,
    "phi_rad": 0.003, "theta_rad": 0.003, "psi_rad": 0.003, "alpha_rad": 0.003, "beta_rad": 0.003,
    "vc_kts": 0.5, "h_ft": 3.0, "hdot_fps": 1.0,
}

#: the same by unit suffix, for outputs not named above (checked in this order)
_SUFFIX_NOISE_STD: tuple[tuple[str, float], ...] = (
    ("_radps", 0.002), ("_g", 0.005), ("_rad", 0.003), ("_kts", 0.5), ("_fps", 1.0), ("_ft", 3.0),
)

#: suffix of the gust input columns (``u_gust_body_fps``, ...)
GUST_SUFFIX = "_gust_body_fps"


def is_wrapped(name: str) -> bool:
    """An output on a circle (a heading ``psi*_rad``): its deviation is wrapped to [-pi, pi)."""
    return name.startswith("psi") and name.endswith("_rad")


def default_noise_std(name: str) -> float | None:
    """Default measurement-noise std of an output [its units], by name then unit suffix; None if unknown."""
    if name in DEFAULT_NOISE_STD:
        return DEFAULT_NOISE_STD[name]
    for suffix, std in _SUFFIX_NOISE_STD:
        if name.endswith(suffix):
            return std
    return None


def _did_you_mean(name: str, names: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, list(names), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _positive(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return v


@dataclass(frozen=True, eq=False)
class CusumDesign:
    """The numbers the kernel runs on (module docstring for the equations).

    Attributes
    ----------
    signal : str
        The watched output.
    input_names : tuple of str
        The command columns (``u`` of ``process_block``).
    output_names : tuple of str
        The outputs the predictor uses (``y`` of ``process_block``).
    A : NDArray
        (n, n) state transition [-].
    B : NDArray
        (n, m_c) command input matrix [state units per command unit].
    C : NDArray
        (p, n) output matrix.
    D : NDArray
        (p, m_c) command feedthrough.
    K : NDArray
        (n, p) steady-state predictor gain.
    P : NDArray
        (n, n) steady-state prediction error covariance of the state.
    Sigma : NDArray
        (p, p) innovation covariance [output units squared].
    u0 : NDArray
        (m_c,) trim commands [-].
    y0 : NDArray
        (p,) trim outputs [output units].
    wrap : NDArray of bool
        (p,) the output's deviation is wrapped to [-pi, pi) (headings).
    signal_index : int
        Column of ``signal`` in ``output_names``.
    signal_std : float
        ``sqrt(Sigma_ii)``, the predicted std of the signal's prediction error [signal units].
    noise_std : NDArray
        (p,) measurement-noise std used [output units].
    gust_std_fps : NDArray
        (3,) gust noise std per gust column [ft/s].
    command_std : float
        Command noise std [-].
    drift : float
        CUSUM drift (reference value) ``k`` [-], in units of ``signal_std``.
    settle_n : int
        Samples after a reset or a gap that update the filter but not the CUSUM.
    rate_hz : float
        Detector rate ``1 / model.dt_s`` [Hz].
    spectral_radius : float
        Largest ``|z|`` of the predictor's error dynamics ``A - K C`` [-] (< 1).
    key : bytes
        sha256 of the design inputs and options (:meth:`CusumResidualDetector.design_key`).
    """

    signal: str
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    D: NDArray[np.float64]
    K: NDArray[np.float64]
    P: NDArray[np.float64]
    Sigma: NDArray[np.float64]
    u0: NDArray[np.float64]
    y0: NDArray[np.float64]
    wrap: NDArray[np.bool_]
    signal_index: int
    signal_std: float
    noise_std: NDArray[np.float64]
    gust_std_fps: NDArray[np.float64]
    command_std: float
    drift: float
    settle_n: int
    rate_hz: float
    spectral_radius: float
    key: bytes


def _select_outputs(model: Any, signal: str, outputs: Sequence[str] | None) -> list[int]:
    names = list(model.output_names)
    if not isinstance(signal, str) or signal not in names:
        raise ValueError(f"signal {signal!r} is not an output of the model{_did_you_mean(str(signal), names)}; "
                         f"the model's outputs are {', '.join(names)}")
    if outputs is None:
        return list(range(len(names)))
    if isinstance(outputs, str):
        outputs = [outputs]
    wanted = list(outputs)
    for o in wanted:
        if o not in names:
            raise ValueError(f"outputs: {o!r} is not an output of the model{_did_you_mean(str(o), names)}; "
                             f"the model's outputs are {', '.join(names)}")
    if signal not in wanted:
        raise ValueError(f"outputs must include the watched signal {signal!r}, got {', '.join(wanted)}")
    return [i for i, nm in enumerate(names) if nm in wanted]  # the model's order, duplicates dropped


def _noise_vector(out_names: Sequence[str], all_names: Sequence[str], noise_std: Mapping[str, float] | None
                  ) -> NDArray[np.float64]:
    given = dict(noise_std or {})
    for k in given:
        if k not in all_names:
            raise ValueError(f"noise_std: {k!r} is not an output of the model{_did_you_mean(str(k), all_names)}; "
                             f"the model's outputs are {', '.join(all_names)}")
    out = []
    for nm in out_names:
        if nm in given:
            out.append(_positive(f"noise_std[{nm!r}]", given[nm]))
            continue
        d = default_noise_std(nm)
        if d is None:
            raise ValueError(f"no default measurement noise for output {nm!r}; give it as noise_std = {{{nm} = ...}} "
                             "in its units, or leave it out with the outputs option")
        out.append(d)
    return np.array(out, dtype=float)


def _gust_vector(gust_std_fps: Any, n_gust: int) -> NDArray[np.float64]:
    if np.ndim(gust_std_fps) == 0:
        return np.full(n_gust, _positive("gust_std_fps", gust_std_fps))
    vals = list(gust_std_fps)
    if len(vals) != n_gust:
        raise ValueError(f"gust_std_fps: give one std or {n_gust} (one per gust input), got {len(vals)}")
    return np.array([_positive(f"gust_std_fps[{i}]", v) for i, v in enumerate(vals)], dtype=float)


def _design_key(parts: Sequence[Any]) -> bytes:
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p, dtype="<f8") if p.dtype != np.bool_ else np.ascontiguousarray(p, dtype="u1")
            h.update(f"{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(repr(p).encode())
        h.update(b"\x00")
    return h.digest()


def design_cusum(model: Any, *, signal: str = "q_radps", drift: float = 0.5, gust_std_fps: Any = 10.0,
                 command_std: float = 0.002, noise_std: Mapping[str, float] | None = None,
                 outputs: Sequence[str] | None = None, settle_s: float = 1.0) -> CusumDesign:
    """Design the steady-state Kalman predictor and the CUSUM constants (module docstring).

    Parameters
    ----------
    model : LinearModel
        Discrete (``dt_s > 0``, the detector rate), in the standard form of the detector samples
        (``fdi_sim.detectors.samples.paired_model``), with ``*_gust_body_fps`` disturbance columns.
    signal : str
        The output whose prediction error is tested.
    drift : float
        CUSUM drift ``k`` [-] (in units of the residual's std; half the smallest shift to detect
        quickly).
    gust_std_fps : float or sequence of 3 floats
        Std of the white gust noise per sample on each gust input [ft/s].
    command_std : float
        Std of the white noise on each command input per sample [-] (unmodelled command
        activity; keeps the DARE solvable).
    noise_std : mapping, optional
        Measurement-noise std per output name [output units]; the rest from
        :data:`DEFAULT_NOISE_STD`.
    outputs : sequence of str, optional
        The outputs the predictor uses (default: all of the model's); must contain ``signal``.
    settle_s : float
        Time after a reset or a gap in the measurements during which the filter updates but the
        CUSUM does not accumulate [s] (>= 0).

    Returns
    -------
    CusumDesign

    Raises
    ------
    ValueError
        Unknown signal or output (with a "did you mean"), a non-positive option, a continuous
        model, a model without gust inputs, or a noise model with no stabilizing predictor.
    """
    import scipy.linalg as sla
    from threadpoolctl import threadpool_limits

    dt = float(getattr(model, "dt_s", 0.0) or 0.0)
    if not dt > 0:
        raise ValueError("cusum-residual-v1 needs a discrete model (dt_s > 0, the detector rate); got a continuous one")
    yi = _select_outputs(model, signal, outputs)
    names_all = tuple(model.output_names)
    out_names = tuple(names_all[i] for i in yi)
    in_all = tuple(model.input_names)
    kinds = tuple(getattr(model, "input_kinds", ()) or ("control",) * len(in_all))
    ci = [i for i, k in enumerate(kinds) if k == "control"]
    gi = [i for i, nm in enumerate(in_all) if nm.endswith(GUST_SUFFIX) and kinds[i] != "control"]
    if not gi:
        raise ValueError(f"the model has no gust inputs (*{GUST_SUFFIX}) to carry the process noise; its inputs are "
                         f"{', '.join(in_all)}")
    drift = float(drift)
    if not (math.isfinite(drift) and drift >= 0):
        raise ValueError(f"drift must be a finite number >= 0, got {drift!r}")
    settle_s = float(settle_s)
    if not (math.isfinite(settle_s) and settle_s >= 0):
        raise ValueError(f"settle_s must be a finite number >= 0 [s], got {settle_s!r}")
    g_std = _gust_vector(gust_std_fps, len(gi))
    c_std = _positive("command_std", command_std)
    v_std = _noise_vector(out_names, names_all, noise_std)

    A = np.array(model.A, dtype=float)
    Bf = np.asarray(model.B, dtype=float)
    C = np.array(np.asarray(model.C, dtype=float)[yi])
    Df = np.asarray(model.D, dtype=float)[yi]
    B = np.array(Bf[:, ci])
    D = np.array(Df[:, ci])
    u0 = np.asarray(model.u0, dtype=float)[ci].copy()
    y0 = np.asarray(model.y0, dtype=float)[yi].copy()
    # noise inputs: the gusts, then the commands again (small)
    Bw = np.hstack([Bf[:, gi], B])
    Dw = np.hstack([Df[:, gi], D])
    Qw = np.diag(np.concatenate([g_std ** 2, np.full(len(ci), c_std ** 2)]))
    Q = Bw @ Qw @ Bw.T                      # Q = B_w Q_w B_w'
    R = Dw @ Qw @ Dw.T + np.diag(v_std ** 2)  # R = D_w Q_w D_w' + R_v
    S = Bw @ Qw @ Dw.T                      # S = B_w Q_w D_w'
    Q, R = 0.5 * (Q + Q.T), 0.5 * (R + R.T)
    with threadpool_limits(limits=1, user_api="blas"):  # the same bits whatever the machine's thread count
        try:
            # P = A P A' + Q - (A P C' + S)(C P C' + R)^-1 (A P C' + S)'  (dual of the control DARE)
            P = sla.solve_discrete_are(A.T, C.T, Q, R, s=S)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise ValueError(f"no stabilizing Kalman predictor for {', '.join(out_names)} with this noise model "
                             f"({exc}); use more outputs or a larger command_std") from exc
        P = 0.5 * (P + P.T)
        Sigma = C @ P @ C.T + R                            # Sigma = C P C' + R
        Sigma = 0.5 * (Sigma + Sigma.T)
        K = np.linalg.solve(Sigma, (A @ P @ C.T + S).T).T  # K = (A P C' + S) Sigma^-1
        rho = float(np.max(np.abs(np.linalg.eigvals(A - K @ C))))
    if not (np.all(np.isfinite(K)) and rho < 1.0):
        raise ValueError(f"the Kalman predictor is not stable (spectral radius {rho:.6f}); use more outputs or a "
                         "larger command_std")
    i_sig = out_names.index(signal)
    sd = float(math.sqrt(Sigma[i_sig, i_sig]))
    rate_hz = 1.0 / dt
    settle_n = int(math.ceil(settle_s * rate_hz - 1e-9))
    wrap = np.array([is_wrapped(nm) for nm in out_names], dtype=np.bool_)
    key = _design_key([
        KERNEL_VERSION, "signal", signal, "inputs", tuple(in_all[i] for i in ci), "outputs", out_names,
        np.asarray(model.A, dtype=float), Bf, np.asarray(model.C, dtype=float), np.asarray(model.D, dtype=float),
        np.asarray(model.u0, dtype=float), np.asarray(model.y0, dtype=float), dt,
        "gust", tuple(in_all[i] for i in gi), g_std, "command_std", c_std, "noise", v_std,
        "drift", drift, "settle_n", settle_n,
    ])
    arrays = [A, B, C, D, K, P, Sigma, u0, y0, wrap, v_std, g_std]
    for a in arrays:
        a.setflags(write=False)
    return CusumDesign(signal, tuple(in_all[i] for i in ci), out_names, A, B, C, D, K, P, Sigma, u0, y0, wrap, i_sig,
                       sd, v_std, g_std, c_std, drift, settle_n, rate_hz, rho, key)
