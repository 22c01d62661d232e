"""Name the modes of an aircraft model: short period, phugoid, Dutch roll, roll, spiral, ...

The eigenvalues of ``A`` are grouped by their participation factors ``p_ki = |r_ki l_ik|``
(right eigenvector ``r_i``, left eigenvector ``l_i``), which, unlike mode shapes, do not depend
on the units of the states. A mode belongs to the longitudinal, lateral or engine group where
most of its participation lies, and within a group the names are given greedily by the states
that characterise each mode:

==================  ============================  ==========================================
name                group                         chosen as
==================  ============================  ==========================================
short period        longitudinal                  largest alpha + q participation (a pair,
                                                  or the two real roots when overdamped, as
                                                  in the FBW F-16)
phugoid             longitudinal                  largest Vt + theta participation of the rest
altitude            longitudinal                  h-dominated (density gradient) root
dutch roll          lateral                       complex pair with largest beta + r share
                                                  (two real roots if none is complex)
roll                lateral                       the fastest remaining real root
spiral              lateral                       the slowest remaining root (it can pair
                                                  with the height mode: DHC-6 105 KCAS)
heading             lateral                       psi-dominated (zero) root
engine              engine states                 ``n1_pct`` / ``prop_rpm``
==================  ============================  ==========================================

Roll and spiral are told apart by speed, not participation: in the FBW F-16 the yaw damper and
the roll-rate loop make roll and yaw rate one fast pair, and the participation of the real
"roll" root (-1.04 at 10 kft / 400 KTAS) sits on beta (0.91). Names follow the textbook
(and JSBSIM_NOTES 4.3) and the report shows the dominant states next to each name.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError

LONGITUDINAL: tuple[str, ...] = ("vt_fps", "alpha_rad", "q_radps", "theta_rad", "h_ft")
LATERAL: tuple[str, ...] = ("beta_rad", "p_radps", "r_radps", "phi_rad", "psi_rad")
ENGINE: tuple[str, ...] = ("n1_pct", "prop_rpm")
#: the names a full aircraft model is expected to show, in report order
MODE_ORDER: tuple[str, ...] = ("short period", "phugoid", "altitude", "dutch roll", "roll", "spiral", "heading", "engine", "other")


@dataclass(frozen=True)
class Mode:
    """One eigenvalue (or one conjugate pair) with its name.

    Attributes
    ----------
    name : str
        One of :data:`MODE_ORDER`.
    eigenvalue : complex
        The eigenvalue (imaginary part >= 0 for a pair) [1/s].
    is_pair : bool
        True for a complex-conjugate pair.
    wn_radps : float
        Natural frequency ``|lambda|`` [rad/s].
    zeta : float
        Damping ratio ``-Re(lambda) / |lambda|`` [-] (1 or -1 for real roots, nan for 0).
    tau_s : float
        Time constant ``-1 / lambda`` of a real root [s] (negative: time to grow by e); nan for pairs.
    period_s : float
        Damped period ``2 pi / Im(lambda)`` of a pair [s]; nan for real roots.
    dominant : tuple of str
        The states with the largest participation, largest first.
    group : str
        ``"longitudinal"``, ``"lateral"`` or ``"engine"``.
    """

    name: str
    eigenvalue: complex
    is_pair: bool
    wn_radps: float
    zeta: float
    tau_s: float
    period_s: float
    dominant: tuple[str, ...]
    group: str

    def describe(self) -> str:
        """A short human-readable line, e.g. ``-2.25+2.65j  wn 3.47 rad/s  zeta 0.65``."""
        lam = self.eigenvalue
        if self.is_pair:
            return f"{lam.real:.4g}{lam.imag:+.4g}j  wn {self.wn_radps:.3g} rad/s  zeta {self.zeta:.3g}  T {self.period_s:.3g} s"
        return f"{lam.real:.4g}  tau {self.tau_s:.3g} s"


@dataclass(frozen=True)
class ModeTable:
    """All modes of one model, named.

    Attributes
    ----------
    modes : tuple of Mode
        In :data:`MODE_ORDER` order (several ``engine``/``other`` entries possible; an
        overdamped short period appears as two ``short period`` entries).
    """

    modes: tuple[Mode, ...]

    def get(self, name: str) -> tuple[Mode, ...]:
        """All modes with this name (empty tuple if none)."""
        return tuple(m for m in self.modes if m.name == name)

    def eigenvalues(self) -> NDArray[np.complex128]:
        """Every eigenvalue, conjugates included [1/s]."""
        out: list[complex] = []
        for m in self.modes:
            out.append(m.eigenvalue)
            if m.is_pair:
                out.append(m.eigenvalue.conjugate())
        return np.array(out)

    def relative_errors(self, reference: NDArray[np.complex128]) -> NDArray[np.float64]:
        """Per mode, the relative distance of its eigenvalue(s) to their partners in ``reference``.

        The partners come from :func:`match_eigenvalues` over all eigenvalues; a pair scores
        the worse of its two roots.

        Returns
        -------
        NDArray
            Shape ``(len(modes),)``, in :attr:`modes` order [-].
        """
        return self.per_mode(match_eigenvalues(self.eigenvalues(), reference)[1])

    def per_mode(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per mode, the largest of ``values`` (one per eigenvalue, in :meth:`eigenvalues` order) over its root(s)."""
        starts = np.cumsum([0] + [2 if m.is_pair else 1 for m in self.modes[:-1]])
        return np.maximum.reduceat(values, starts) if self.modes else np.zeros(0)


def _is_pair(lam: complex) -> bool:
    return abs(lam.imag) > 1e-9 * max(1.0, abs(lam))


def _make_mode(name: str, lam: complex, part: NDArray[np.float64], states: Sequence[str], group: str) -> Mode:
    pair = _is_pair(lam)
    lam = complex(lam.real, abs(lam.imag)) if pair else complex(lam.real, 0.0)
    wn = abs(lam)
    zeta = -lam.real / wn if wn > 0 else math.nan
    tau = -1.0 / lam.real if (not pair and lam.real != 0) else math.nan
    period = 2 * math.pi / lam.imag if pair else math.nan
    order = np.argsort(-part)
    dominant = tuple(states[i] for i in order[:3] if part[i] > 0.05)
    return Mode(name=name, eigenvalue=lam, is_pair=pair, wn_radps=wn, zeta=zeta, tau_s=tau, period_s=period,
                dominant=dominant, group=group)


def participation(A: NDArray[np.float64]) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """Eigenvalues and participation factors of ``A``.

    Returns
    -------
    eigenvalues : NDArray
        Shape (n,) [1/s].
    P : NDArray
        Shape (n, n): ``P[k, i] = |R[k, i] L[i, k]|`` normalized so each column sums to 1
        (state ``k`` in mode ``i``).
    """
    A = np.asarray(A, dtype=float)
    lam, R = np.linalg.eig(A)
    if np.linalg.cond(R) > 1e12:
        raise DesignError("A is defective (repeated eigenvalues without independent eigenvectors); "
                          "mode identification needs a diagonalizable A")
    L = np.linalg.inv(R)
    P = np.abs(R * L.T)
    P /= P.sum(axis=0, keepdims=True)
    return lam, P


def identify_modes(A: NDArray[np.float64], state_names: Sequence[str]) -> ModeTable:
    """Name the modes of ``A`` whose states are called ``state_names``.

    Raises
    ------
    DesignError
        Shape mismatch, or a defective ``A``.
    """
    names = list(state_names)
    A = np.asarray(A, dtype=float)
    if A.shape != (len(names), len(names)):
        raise DesignError(f"A is {A.shape} but {len(names)} state names were given")
    lam, P = participation(A)
    idx = {s: i for i, s in enumerate(names)}

    def share(i: int, group: Sequence[str]) -> float:
        return float(sum(P[idx[s], i] for s in group if s in idx))

    # one representative per conjugate pair (the one with Im > 0) and every real root
    seen = [i for i in range(len(lam)) if lam[i].imag > 0 or not _is_pair(lam[i])]
    groups: dict[str, list[int]] = {"longitudinal": [], "lateral": [], "engine": []}
    for i in seen:
        shares = {"longitudinal": share(i, LONGITUDINAL), "lateral": share(i, LATERAL), "engine": share(i, ENGINE)}
        groups[max(shares, key=shares.get)].append(i)
    named: list[tuple[str, int, str]] = []

    def take(cands: list[int], score_states: Sequence[str], want_pair: bool | None, count: int = 1) -> list[int]:
        pool = [i for i in cands if want_pair is None or _is_pair(lam[i]) == want_pair]
        pool.sort(key=lambda i: -share(i, score_states))
        return pool[:count]

    def is_pair(i: int) -> bool:
        return _is_pair(lam[i])

    # ---- longitudinal
    lon = list(groups["longitudinal"])
    for i in [i for i in lon if share(i, ("h_ft",)) > 0.5]:
        named.append(("altitude", i, "longitudinal"))
        lon.remove(i)
    sp = take(lon, ("alpha_rad", "q_radps"), None)
    if sp and not is_pair(sp[0]):  # overdamped: the two real roots with most alpha + q
        sp = take(lon, ("alpha_rad", "q_radps"), False, 2)
    for i in sp:
        named.append(("short period", i, "longitudinal"))
        lon.remove(i)
    ph = take(lon, ("vt_fps", "theta_rad"), None)
    if ph and not is_pair(ph[0]):
        ph = take(lon, ("vt_fps", "theta_rad"), False, 2)
    for i in ph:
        named.append(("phugoid", i, "longitudinal"))
        lon.remove(i)
    named += [("other", i, "longitudinal") for i in lon]
    # ---- lateral
    lat = list(groups["lateral"])
    for i in [i for i in lat if share(i, ("psi_rad",)) > 0.5]:
        named.append(("heading", i, "lateral"))
        lat.remove(i)
    dr = take(lat, ("beta_rad", "r_radps"), True)
    if not dr:
        dr = take(lat, ("beta_rad", "r_radps"), False, 2)
    for i in dr:
        named.append(("dutch roll", i, "lateral"))
        lat.remove(i)
    reals = sorted((i for i in lat if not is_pair(i)), key=lambda i: -abs(lam[i]))
    if reals and (len(reals) >= 2 or share(reals[0], ("p_radps",)) >= share(reals[0], ("phi_rad",))):
        named.append(("roll", reals[0], "lateral"))  # textbook: roll subsidence is the fast real root
        lat.remove(reals[0])
    # spiral: the slowest remaining lateral root, real or (coupled with the height mode) a pair
    if lat:
        i = min(lat, key=lambda i: (abs(lam[i]), -share(i, ("phi_rad",))))
        named.append(("spiral", i, "lateral"))
        lat.remove(i)
    named += [("other", i, "lateral") for i in lat]
    named += [("engine", i, "engine") for i in groups["engine"]]
    modes = [_make_mode(nm, complex(lam[i]), P[:, i], names, grp) for nm, i, grp in named]
    modes.sort(key=lambda m: (MODE_ORDER.index(m.name), -abs(m.eigenvalue)))
    return ModeTable(modes=tuple(modes))


def match_eigenvalues(a: NDArray[np.complex128], b: NDArray[np.complex128]) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Pair each eigenvalue of ``a`` with one of ``b`` (optimal assignment on ``|a_i - b_j|``).

    Returns
    -------
    j : NDArray
        ``b[j[i]]`` is the partner of ``a[i]``.
    rel : NDArray
        ``|a_i - b_j| / max(|b_j|, 1e-3)`` [-], the relative distance.
    """
    from scipy.optimize import linear_sum_assignment

    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        raise DesignError(f"cannot match {a.size} eigenvalues with {b.size}")
    cost = np.abs(a[:, None] - b[None, :])
    ri, ci = linear_sum_assignment(cost)
    j = np.empty(a.size, dtype=np.intp)
    j[ri] = ci
    rel = np.abs(a - b[j]) / np.maximum(np.abs(b[j]), 1e-3)
    return j, rel
