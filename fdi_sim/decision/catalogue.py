"""Registered decision rules (kind ``"decision"``): each factory takes the rule's own parameters.

``fdi_sim.registry.load_builtin_plugins`` imports this module.
"""
from __future__ import annotations

from fdi_sim.decision.angle import AngleMagnitudeRule
from fdi_sim.decision.chi2 import Chi2Test
from fdi_sim.decision.cusum import Cusum
from fdi_sim.decision.glr import WindowGlr
from fdi_sim.decision.persistence import Persistence
from fdi_sim.decision.signature import SignatureIsolation
from fdi_sim.decision.sprt import Sprt
from fdi_sim.registry import register

register("decision", Chi2Test.id, "chi-square statistic > h, P(chi2(dof) > h) = per-sample target", Chi2Test)
register("decision", Persistence.id, "k of the last n chi-square tests fired; per-sample rate P(Bin(n,p) >= k)", Persistence)
register("decision", Cusum.id, "Page's CUSUM for a known mean change; h from a target ARL0 (Siegmund)", Cusum)
register("decision", WindowGlr.id, "window-limited GLR for a mean change of unknown size; h from a target ARL0", WindowGlr)
register("decision", Sprt.id, "repeated Wald SPRT, thresholds from alpha and beta", Sprt)
register("decision", AngleMagnitudeRule.id,
         "two-step rule (Miller & Ribbens): |e|^2 > h, then angle to C D_f below a bound, else reject",
         AngleMagnitudeRule)
register("decision", SignatureIsolation.id, "isolation by binary signature of structured residuals, reject option",
         SignatureIsolation)
