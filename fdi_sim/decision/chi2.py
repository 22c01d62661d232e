"""Chi-square test thresholds shared by every detector that normalizes its residual."""
from __future__ import annotations

from scipy.stats import chi2

from fdi_sim.errors import DesignError


def chi2_threshold(dof: int, p_false_alarm: float) -> float:
    """Threshold h with ``P(chi2(dof) > h) = p_false_alarm`` (Hagenblad et al. eq. 13).

    Parameters
    ----------
    dof : int
        Degrees of freedom (residual dimension), at least 1.
    p_false_alarm : float
        False-alarm probability per test, in (0, 1).
    """
    if not 0.0 < p_false_alarm < 1.0:
        raise DesignError(f"p_false_alarm must be in (0, 1), got {p_false_alarm}")
    if dof < 1:
        raise DesignError(f"a chi-square test needs at least 1 degree of freedom, got {dof}")
    return float(chi2.isf(p_false_alarm, dof))
