"""The F-16 study of Hagenblad, Gustafsson & Klein (seed 003, sec. 4): model, readings, simulation.

The model is the sampled (0.1 s) vertical dynamics of an F-16 (eq. 23-27, Table 1): 5 states,
3 known inputs (spoiler, forward acceleration, elevator), 3 outputs (relative altitude,
forward speed, pitch angle), six additive faults (three actuators, three sensors).

Table 1 leaves the noise model open. Its "Size" column gives variances for the inputs (1),
the measurement noise (1e-4, 1e-6, 1e-6), "the states" (1e-4) and magnitudes for the faults
(0.5, 0.1, 1, 1, 1, 1); it does not say how the state noise enters, and eq. 28 does not say
which fault magnitude m it uses. :func:`f16_reading` builds each reading:

- ``process="none"``: no process noise (``S = I_L ⊗ R``);
- ``process="all-states"``: ``B_v = I_5``, ``Q = 1e-4 I_5``;
- ``process="speed-disturbance"``: ``B_v = B_d`` (eq. 25), ``Q = 1e-4``;
- ``fault_sizes="unit"`` (m = 1 for every fault) or ``"table"`` (Table 1 magnitudes).

The reading that reproduces the published numbers is ``process="none", fault_sizes="unit"``
(:data:`PAPER_READING`); docs/parity.md shows the others. Simulations here are time-domain runs
of eq. 1 with white Gaussian inputs of variance 1; residual samples are taken from
non-overlapping windows, so they are independent (the parity residual does not depend on the
state at the start of the window).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.parity import AdditiveFaults
from fdi_sim.detectors.pca import PcaModel, estimate_fault_signatures, pca_train, stack_data_windows
from fdi_sim.detectors.stochastic_parity import (
    DiagnosisMatrix,
    StochasticParity,
    ThresholdEstimate,
    incorrect_diagnosis_matrix,
    isolation_rates,
    stochastic_parity,
    threshold_by_simulation,
)
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "F16Reading",
    "F16Windows",
    "F16StudyResult",
    "PAPER_ISOLATION_PARITY",
    "PAPER_ISOLATION_PCA",
    "PAPER_P_EQ28",
    "PAPER_READING",
    "PAPER_THRESHOLD_PARITY",
    "PAPER_THRESHOLD_PCA",
    "f16_faults",
    "f16_model",
    "f16_reading",
    "f16_design",
    "f16_parity_study",
    "f16_pca_model",
    "f16_pca_study",
    "simulate_f16",
]

DT_S = 0.1  # sampling time of the model [s] (Hagenblad et al. sec. 4; Gustafsson 2000)

# eq. 23
A_EQ23 = np.array([
    [1, 0.0014, 0.1133, 0.0004, -0.0997],
    [0, 0.9945, -0.0171, -0.0005, 0.0070],
    [0, 0.0003, 1.0000, 0.0957, -0.0049],
    [0, 0.0061, -0.0000, 0.9130, -0.0966],
    [0, -0.0286, 0.0002, 0.1004, 0.9879],
])
# eq. 24
BU_EQ24 = np.array([
    [-0.0078, 0.0000, 0.0003],
    [-0.0115, 0.0997, 0.0000],
    [0.0212, 0.0000, -0.0081],
    [0.4150, 0.0003, -0.1589],
    [0.1794, -0.0014, -0.0158],
])
BD_EQ25 = np.array([[0.0], [1.0], [0.0], [0.0], [0.0]])
C_EQ27 = np.eye(3, 5)
DF_EQ27 = np.hstack([np.zeros((3, 3)), np.eye(3)])

# Continuous AIRC model (Maciejowski 1989, App. A.1) as in Gustafsson's toolbox (a55 = -0.06859);
# its zero-order hold at 0.1 s equals eq. 23-24 to 4 decimals except A[0,2] (0.11319 vs 0.1133).
AC_AIRC = np.array([
    [0, 0, 1.132, 0, -1],
    [0, -0.0538, -0.1712, 0, 0.0705],
    [0, 0, 0, 1, 0],
    [0, 0.0485, 0, -0.8556, -1.013],
    [0, -0.2909, 0, 1.0532, -0.06859],
])
BC_AIRC = np.array([[0, 0, 0], [-0.12, 1, 0], [0, 0, 0], [4.419, 0, -1.665], [1.575, 0, -0.0732]])

R_TABLE1 = np.diag([1e-4, 1e-6, 1e-6])  # measurement noise variances (Table 1)
Q_TABLE1 = 1e-4  # state noise variance (Table 1)
INPUT_VAR_TABLE1 = 1.0  # input variance (Table 1)
FAULT_SIZES_TABLE1 = np.array([0.5, 0.1, 1.0, 1.0, 1.0, 1.0])  # constant fault magnitudes (Table 1)

#: published results (sec. 4): eq. 28, P[i, j] = prob(diagnosis i | fault j)
PAPER_P_EQ28 = np.array([
    [1.0000, 0.0000, 0.0000, 0, 0.0000, 0.0000],
    [0.0000, 0.5980, 0.0000, 0, 0.4020, 0.0001],
    [0.0000, 0.0000, 0.9999, 0, 0.0001, 0.0000],
    [0, 0, 0, 0, 0, 0],
    [0.0000, 0.4020, 0.0001, 0, 0.5415, 0.0564],
    [0.0000, 0.0001, 0.0000, 0, 0.0564, 0.9436],
])
PAPER_THRESHOLD_PARITY = 9.3  # h for a 0.05 false-alarm rate, parity space (sec. 4)
PAPER_THRESHOLD_PCA = 9.7  # h for a 0.05 false-alarm rate, PCA (sec. 4)
PAPER_ISOLATION_PARITY = np.array([1, 1, 0.96, 0.05, 0.72, 1])  # probability of correct isolation
PAPER_ISOLATION_PCA = np.array([1, 1, 0.96, 0.05, 0.67, 1])


def f16_model(exact: bool = False) -> LinearModel:
    """The F-16 vertical-dynamics model of eq. 23-24 and 27 as a discrete LinearModel (dt 0.1 s).

    Parameters
    ----------
    exact : bool
        False: the matrices as printed in the paper. True: the zero-order hold at 0.1 s of the
        continuous AIRC model they were rounded from (for sensitivity checks).
    """
    if exact:
        from scipy.signal import cont2discrete

        A, B, *_ = cont2discrete((AC_AIRC, BC_AIRC, C_EQ27, np.zeros((3, 3))), DT_S, method="zoh")
    else:
        A, B = A_EQ23, BU_EQ24
    return LinearModel(
        A=A, B=B, C=C_EQ27, D=np.zeros((3, 3)), dt_s=DT_S,
        state_names=("alt_m", "u_fwd_mps", "theta_deg", "q_degps", "vz_mps"),
        input_names=("spoiler_0p1deg", "fwd_accel_mps2", "elevator_deg"),
        output_names=("alt_rel_m", "u_fwd_mps", "theta_deg"),
        meta={"source": "Hagenblad, Gustafsson & Klein, eq. 23-27", "exact_zoh": exact},
    )


def f16_faults(model: LinearModel | None = None) -> AdditiveFaults:
    """Faults f1..f6 of Table 1: ``B_f`` of eq. 26 (actuators = B_u) and ``D_f`` of eq. 27."""
    model = f16_model() if model is None else model
    Bf = np.hstack([model.B, np.zeros((5, 3))])
    return AdditiveFaults(Bf=Bf, Df=DF_EQ27, names=(
        "spoiler_actuator", "fwd_accel_actuator", "elevator_actuator",
        "alt_sensor", "speed_sensor", "pitch_sensor"))


@dataclass(frozen=True, eq=False)
class F16Reading:
    """One reading of Table 1's noise model.

    Attributes
    ----------
    process : str
        "none", "all-states" or "speed-disturbance".
    fault_sizes : str
        "unit" or "table".
    Bv : NDArray
        (5, n_v) process-noise entry.
    Q : NDArray
        (n_v, n_v) process-noise covariance.
    R : NDArray
        (3, 3) measurement-noise covariance.
    magnitudes : NDArray
        Constant magnitude m of each fault (6,).
    input_var : float
        Variance of the white Gaussian known inputs.
    """

    process: str
    fault_sizes: str
    Bv: NDArray[np.float64]
    Q: NDArray[np.float64]
    R: NDArray[np.float64]
    magnitudes: NDArray[np.float64]
    input_var: float = INPUT_VAR_TABLE1


def f16_reading(process: str = "none", fault_sizes: str = "unit") -> F16Reading:
    """Build a reading of Table 1 (see the module docstring)."""
    if process == "none":
        Bv, Q = np.zeros((5, 0)), np.zeros((0, 0))
    elif process == "all-states":
        Bv, Q = np.eye(5), Q_TABLE1 * np.eye(5)
    elif process == "speed-disturbance":
        Bv, Q = BD_EQ25, Q_TABLE1 * np.eye(1)
    else:
        raise DesignError(f"process must be 'none', 'all-states' or 'speed-disturbance', got {process!r}")
    if fault_sizes not in ("unit", "table"):
        raise DesignError(f"fault_sizes must be 'unit' or 'table', got {fault_sizes!r}")
    m = np.ones(6) if fault_sizes == "unit" else FAULT_SIZES_TABLE1.copy()
    return F16Reading(process=process, fault_sizes=fault_sizes, Bv=Bv, Q=Q, R=R_TABLE1.copy(), magnitudes=m)


#: the reading that reproduces eq. 28 and the threshold (see docs/parity.md for the evidence)
PAPER_READING = ("none", "unit")


def f16_design(reading: F16Reading, window_L: int = 3, exact: bool = False) -> StochasticParity:
    """Stochastic parity design of the F-16 study (eq. 5-11) for window ``L`` (order s = L - 1)."""
    model = f16_model(exact)
    return stochastic_parity(model, window_L - 1, f16_faults(model), reading.R, Bv=reading.Bv, Q=reading.Q)


@dataclass(frozen=True, eq=False)
class F16Windows:
    """Stacked simulated windows, oldest sample first: Y (n, L*3), U (n, L*3)."""

    Y: NDArray[np.float64]
    U: NDArray[np.float64]

    @property
    def Z(self) -> NDArray[np.float64]:
        """PCA data vectors ``Z_t = (Y_t; U_t)`` (eq. 15), rows = windows."""
        return stack_data_windows(self.Y, self.U)


def simulate_f16(
    reading: F16Reading,
    fault: int | None,
    n_windows: int,
    rng: np.random.Generator,
    window_L: int = 3,
    windows_per_run: int = 100,
    exact: bool = False,
) -> F16Windows:
    """Time-domain simulation of eq. 1 with the F-16 matrices; non-overlapping windows.

    ``n_windows // windows_per_run`` runs (vectorized) start at x = 0 and last
    ``windows_per_run * L`` steps. Inputs u ~ N(0, input_var), e ~ N(0, R), v ~ N(0, Q); a fault
    ``f = m_i e_i`` (``fault = i``, 0-based) is present from the first step.

    Parameters
    ----------
    reading : F16Reading
    fault : int or None
        0-based fault index, or None for fault-free flight.
    n_windows : int
        Windows wanted (rounded up to whole runs).
    rng : numpy.random.Generator
    """
    model = f16_model(exact)
    faults = f16_faults(model)
    A, Bu, C = model.A, model.B, model.C
    n_runs = -(-int(n_windows) // windows_per_run)
    n_steps = windows_per_run * window_L
    f = np.zeros(6)
    if fault is not None:
        f[int(fault)] = reading.magnitudes[int(fault)]
    bf, df = faults.Bf @ f, faults.Df @ f
    x = np.zeros((n_runs, 5))
    Rs = np.linalg.cholesky(reading.R)
    nv = reading.Bv.shape[1]
    Gv = np.linalg.cholesky(reading.Q).T @ reading.Bv.T if nv else None  # v' B_v' = z' Q^(1/2)' B_v'
    ys = np.empty((n_steps, n_runs, 3))
    us = np.sqrt(reading.input_var) * rng.standard_normal((n_steps, n_runs, 3))
    for k in range(n_steps):
        ys[k] = x @ C.T + df + rng.standard_normal((n_runs, 3)) @ Rs.T  # y = C x + D_f f + e
        x = x @ A.T + us[k] @ Bu.T + bf  # x+ = A x + B_u u + B_f f + B_v v
        if nv:
            x = x + rng.standard_normal((n_runs, nv)) @ Gv
    # (steps, runs, 3) -> (runs, windows, L, 3) -> (runs*windows, L*3), oldest first
    Y = ys.transpose(1, 0, 2).reshape(n_runs * windows_per_run, window_L * 3)
    U = us.transpose(1, 0, 2).reshape(n_runs * windows_per_run, window_L * 3)
    return F16Windows(Y=Y[:n_windows], U=U[:n_windows])


@dataclass(frozen=True, eq=False)
class F16StudyResult:
    """Threshold and isolation probabilities of one F-16 Monte Carlo study.

    Attributes
    ----------
    threshold : ThresholdEstimate
        h for a 0.05 false-alarm rate by simulation, with its 95 % interval.
    p_correct : NDArray
        (6,) probability that fault j alarms and is isolated as j; for an undetectable fault
        (no fault vector) the alarm probability instead, which is what the paper's 0.05 is.
    rates : NDArray
        (6, 7) fraction of windows of fault j isolated as i (last column: rejected).
    detectable : NDArray of bool
    P_eq14 : DiagnosisMatrix or None
        Algorithm 2 prediction (parity study only).
    singular_values : NDArray or None
        Eigenvalues of the PCA data covariance, descending (PCA study only).
    n_windows : int
        Samples per case.
    """

    threshold: ThresholdEstimate
    p_correct: NDArray[np.float64]
    rates: NDArray[np.float64]
    detectable: NDArray[np.bool_]
    P_eq14: DiagnosisMatrix | None
    singular_values: NDArray[np.float64] | None
    n_windows: int


def _monte_carlo(
    residual: Callable[[F16Windows], NDArray], signatures: NDArray, detectable: NDArray, reading: F16Reading,
    n_windows: int, rng: np.random.Generator, window_L: int, p_false_alarm: float, exact: bool = False,
) -> tuple[ThresholdEstimate, NDArray[np.float64], NDArray[np.float64]]:
    """Threshold by simulation on fault-free windows, then Algorithm 1 on ``n_windows`` of each fault.

    Returns the threshold, the (6, 7) isolation rates and ``p_correct``: the rate of isolating
    fault j as j, or for an undetectable fault its alarm rate.
    """
    r0 = residual(simulate_f16(reading, None, n_windows, rng, window_L, exact=exact))
    th = threshold_by_simulation(np.einsum("ij,ij->i", r0, r0), p_false_alarm)
    rates = np.zeros((6, 7))
    p_correct = np.zeros(6)
    for j in range(6):
        rj = residual(simulate_f16(reading, j, n_windows, rng, window_L, exact=exact))
        rates[j] = isolation_rates(rj, signatures, detectable, th.h)
        p_correct[j] = rates[j, j] if detectable[j] else np.mean(np.einsum("ij,ij->i", rj, rj) > th.h)
    return th, rates, p_correct


def f16_parity_study(
    reading: F16Reading, n_windows: int, rng: np.random.Generator, window_L: int = 3,
    p_false_alarm: float = 0.05, exact: bool = False,
) -> F16StudyResult:
    """Reproduce the parity-space part of sec. 4: threshold by simulation and isolation probabilities.

    The threshold is calibrated on fault-free simulated windows; each fault case is simulated with
    its own ``n_windows`` and run through Algorithm 1 (detection + angle isolation).
    """
    design = f16_design(reading, window_L, exact)
    th, rates, p_correct = _monte_carlo(lambda w: design.residual(w.Y, w.U), design.mu_bar, design.detectable,
                                        reading, n_windows, rng, window_L, p_false_alarm, exact)
    return F16StudyResult(threshold=th, p_correct=p_correct, rates=rates, detectable=design.detectable,
                          P_eq14=incorrect_diagnosis_matrix(design, reading.magnitudes), singular_values=None,
                          n_windows=n_windows)


def f16_pca_model(
    reading: F16Reading, n_train: int, rng: np.random.Generator, window_L: int = 3, n_residuals: int = 4,
) -> tuple[PcaModel, NDArray[np.float64]]:
    """Train PCA (eq. 16-17) on fault-free simulated F-16 windows and estimate the six fault
    signatures from faulty windows (eq. 22). Returns the model and the (6, n_r) signatures.

    Training runs last 100 windows (30 s at L = 3): in shorter runs the slow modes (altitude,
    pitch) are barely excited and the smallest model-space eigenvalue approaches the altitude
    noise (1e-4), which tilts the estimated residual space (docs/parity.md).
    """
    pca = pca_train(simulate_f16(reading, None, n_train, rng, window_L).Z, n_residuals)
    sig = estimate_fault_signatures(pca, [simulate_f16(reading, j, n_train, rng, window_L).Z for j in range(6)])
    return pca, sig


def f16_pca_study(
    reading: F16Reading, n_train: int, n_windows: int, rng: np.random.Generator, window_L: int = 3,
    p_false_alarm: float = 0.05, n_residuals: int = 4,
) -> F16StudyResult:
    """Reproduce the PCA part of sec. 4: train on fault-free data, estimate fault signatures
    from fault data (eq. 22), calibrate h by simulation, then isolation by angle on fresh data.

    A fault whose estimated signature is not significantly different from zero (its mean is
    below 4 standard errors of the mean of a unit-covariance residual) is treated as undetectable.
    """
    pca, sig = f16_pca_model(reading, n_train, rng, window_L, n_residuals)
    detectable = np.linalg.norm(sig, axis=1) > 4.0 * np.sqrt(n_residuals / n_train)
    th, rates, p_correct = _monte_carlo(lambda w: pca.normalized_residual(w.Z), sig, detectable, reading,
                                        n_windows, rng, window_L, p_false_alarm)
    return F16StudyResult(threshold=th, p_correct=p_correct, rates=rates, detectable=detectable, P_eq14=None,
                          singular_values=pca.eigenvalues, n_windows=n_windows)
