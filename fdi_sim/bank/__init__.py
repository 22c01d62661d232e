"""The FDI bank at run time: its members, one decision, isolation, failure log and reconfiguration.

It never flies: ``fdi_sim.training`` designs a scenario's bank (flying training flights where a
member needs them) and ``fdi_sim.sim.run`` flies it.

- :mod:`fdi_sim.bank.runtime`: :class:`FdiBank`, :class:`DecisionConfig`, the run summary's
  :func:`fdi_outcomes`;
- :mod:`fdi_sim.bank.members`: which detectors a scenario's bank runs (:func:`bank_members`);
- :mod:`fdi_sim.bank.thresholds_file`: the calibration study's thresholds file;
- :mod:`fdi_sim.bank.topics`: the bank's log layout.
"""
from __future__ import annotations

from fdi_sim.bank.members import DEFAULT_BANKS, MemberSpec, bank_members, design_hash, per_sample_target
from fdi_sim.bank.runtime import BankAlarm, DecisionConfig, FaultDetection, FdiBank, fdi_outcomes
from fdi_sim.bank.thresholds_file import StudyThresholds, read_thresholds, write_thresholds

__all__ = ["BankAlarm", "DEFAULT_BANKS", "DecisionConfig", "FaultDetection", "FdiBank", "MemberSpec",
           "StudyThresholds", "bank_members", "design_hash", "fdi_outcomes", "per_sample_target",
           "read_thresholds", "write_thresholds"]
