"""Decision layer: from a detector's statistic (or residual) to alarms, isolation and the failure log.

Every rule has ``reset(rng=None)`` / ``step(t_s, x) -> Decision`` and a vectorised
``run(x) -> DecisionTrace`` (same numbers); docs/decision.md gives each rule's false-alarm rate or
average run length, the value measured on white noise, and when to use it.

=====================  ==========================================================================
``chi2``               :class:`Chi2Test`, :func:`chi2_threshold`: threshold from a per-sample target
``persistence``        :class:`Persistence`: k of n, ``P_FA = P(Bin(n, p) >= k)``
``cusum``              :class:`Cusum`: Page, known change; Siegmund's ARL and the exact integral equation
``glr``                :class:`WindowGlr`: window-limited GLR, unknown change; Siegmund-Venkatraman ARL
``sprt``               :class:`Sprt`: Wald's repeated SPRT, overshoot-corrected errors and ASN
``angle``              :class:`AngleMagnitudeRule`: the patent's magnitude-then-angle rule, reject option
``signature``          :class:`SignatureIsolation`: structured-residual signatures, reject option
``failure_log``        :func:`failure_log`, :class:`FailureLogger`, :class:`FailureEvent` (patent FIG. 4)
``base``               :class:`Decision`, :class:`DecisionTrace`, :class:`DecisionRule`
=====================  ==========================================================================
"""
from __future__ import annotations

from fdi_sim.decision.angle import AngleMagnitudeRule, angle_false_signature_probability
from fdi_sim.decision.base import Decision, DecisionRule, DecisionTrace
from fdi_sim.decision.chi2 import Chi2Test, chi2_threshold
from fdi_sim.decision.cusum import Cusum, cusum_arl_exact, cusum_threshold, siegmund_arl
from fdi_sim.decision.failure_log import FailureEvent, FailureLogger, failure_log
from fdi_sim.decision.glr import WindowGlr, glr_arl0, glr_threshold
from fdi_sim.decision.persistence import Persistence, persistence_false_alarm, persistence_sample_probability
from fdi_sim.decision.signature import SignatureIsolation
from fdi_sim.decision.sprt import Sprt, SprtOperatingCharacteristic, sprt_operating_characteristic, wald_thresholds

__all__ = [
    "AngleMagnitudeRule", "Chi2Test", "Cusum", "Decision", "DecisionRule", "DecisionTrace", "FailureEvent",
    "FailureLogger", "Persistence", "SignatureIsolation", "Sprt", "SprtOperatingCharacteristic", "WindowGlr",
    "angle_false_signature_probability", "chi2_threshold", "cusum_arl_exact", "cusum_threshold", "failure_log",
    "glr_arl0", "glr_threshold", "persistence_false_alarm", "persistence_sample_probability", "siegmund_arl",
    "sprt_operating_characteristic", "wald_thresholds",
]
