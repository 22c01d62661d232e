"""The thresholds file a calibration study writes and a bank reads (``aircraft/<ac>/fdi_thresholds.toml``).

Per member: the threshold, how it was set, and how it held on the study's held-out half
(:class:`StudyThresholds`); read strictly (an unknown key or a wrong type names the file, the key
and the fix).
"""
from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any


# --- thresholds from a calibration study (the file `fdi-sim study STUDY --calibrate OUT.toml` writes) ---
#: the ``kind`` of a thresholds file
THRESHOLDS_KIND = "fdi-thresholds"


#: the shipped file's name in ``aircraft/<aircraft>/`` (package data)
THRESHOLDS_FILE = "fdi_thresholds.toml"


@dataclass(frozen=True)
class HeldRate:
    """False alarms of one member (or of the bank) on one half of a study's runs.

    Attributes
    ----------
    runs : int
    false_alarms : int
    exposure_h : float
        Armed fault-free flight hours [h].
    far_per_h : float
        ``false_alarms / exposure_h`` [1/h].
    ci_per_h : tuple of float
        Exact Poisson interval at the file's confidence [1/h].
    verdict : str
        The interval against the target: ``"contains"``, ``"below"``, ``"above"`` or
        ``"undetermined"`` (no exposure) (:func:`fdi_sim.decision.intervals.rate_verdict`).
    detectable_ratio : float
        The smallest ratio of a true rate to the target these hours would show as ``"above"``
        half the time [-] (:func:`fdi_sim.decision.intervals.detectable_ratio`): what a
        ``"contains"`` with few alarms is worth.
    """

    runs: int
    false_alarms: int
    exposure_h: float
    far_per_h: float
    ci_per_h: tuple[float, float]
    verdict: str
    detectable_ratio: float

    @property
    def target_inside(self) -> bool:
        """The target lies in ``ci_per_h``."""
        return self.verdict == "contains"


@dataclass(frozen=True)
class MemberRate:
    """One member's false alarms on a validation study."""

    id: str
    target_per_h: float
    rate: HeldRate


@dataclass(frozen=True)
class Validation:
    """A thresholds file checked on a fresh fault-free study (a seed no calibration used).

    Attributes
    ----------
    study, study_identity : str
    seed : int
        The study's master seed (the seed registry's validation set).
    runs : int
    flight_h : float
        Completed flight hours [h].
    bank : HeldRate
        The bank against ``far_per_h``.
    members : tuple of MemberRate
        Each member against its share.
    version : str
        fdi-sim version that checked it.
    """

    study: str
    study_identity: str
    seed: int
    runs: int
    flight_h: float
    bank: HeldRate
    members: tuple[MemberRate, ...]
    version: str


@dataclass(frozen=True)
class StudyMemberThreshold:
    """One member's threshold calibrated on a study.

    Attributes
    ----------
    id : str
    threshold : float
        The calibrated threshold on the member's statistic [-].
    trained_threshold : float
        The threshold the study's runs flew (the bank's training flights) [-].
    scale : float
        ``threshold / trained_threshold`` [-].
    target_per_h : float
        The member's share of the bank's rate [1/h].
    calibration, held_out : HeldRate
        On the calibration half at ``threshold``, and on the held-out half.
    method : str
        How the threshold was set on the calibration half (the tail fit's description).
    rate_ratio : float
        Held-out rate over the calibration half's at ``threshold`` [-] (inf when that half has none).
    rate_ratio_ci : tuple of float
        Its exact conditional interval, scaled by the runs' dispersion [-].
    ratio_check : str
        ``"consistent"`` (1 lies in ``rate_ratio_ci``: the two halves agree, allowing for both
        counts' sampling error), ``"inconsistent"``, or ``"undetermined"`` (no alarm in either
        half: a ratio of 0 to 0 can say nothing).
    """

    id: str
    threshold: float
    trained_threshold: float
    scale: float
    target_per_h: float
    calibration: HeldRate
    held_out: HeldRate
    method: str
    rate_ratio: float
    rate_ratio_ci: tuple[float, float]
    ratio_check: str


@dataclass(frozen=True)
class StudyThresholds:
    """A thresholds file: a default bank's thresholds from a calibration study, with provenance.

    Attributes
    ----------
    aircraft : str
    study, study_identity : str
        The study's name and identity hash (``study.json`` of its results folder).
    runs : int
        Completed runs used (both halves).
    flight_h : float
        Their flight hours [h].
    version : str
        fdi-sim version that wrote the file.
    design_h_ft, design_vc_kts : float
        The bank's design node [ft], [kt].
    design_turbulence : str
    design_wind_speed_kts, design_noise_scale : float
        [kt], [-].
    design_hash : str
        :func:`fdi_sim.bank.members.design_hash` of the bank the study flew.
    rate_hz : float
        Detector rate [Hz].
    persistence_k, persistence_n : int
        The decision rule the thresholds were calibrated with.
    far_per_h : float
        The bank's target rate [1/h]; each member's is ``far_per_h / members``.
    split : str
        ``even``: calibrated on the even run indices, held out the odd ones.
    confidence : float
    members : tuple of StudyMemberThreshold
    bank_calibration, bank_held_out : HeldRate
        The bank (OR of its members at their thresholds) against ``far_per_h``.
    method : str
    validation : Validation or None
        The check on a fresh study (another seed), once flown: ``fdi-sim study STUDY --validate``.
    """

    aircraft: str
    study: str
    study_identity: str
    runs: int
    flight_h: float
    version: str
    design_h_ft: float
    design_vc_kts: float
    design_turbulence: str
    design_wind_speed_kts: float
    design_noise_scale: float
    design_hash: str
    rate_hz: float
    persistence_k: int
    persistence_n: int
    far_per_h: float
    split: str
    confidence: float
    members: tuple[StudyMemberThreshold, ...]
    bank_calibration: HeldRate
    bank_held_out: HeldRate
    method: str
    validation: "Validation | None" = None

    def member_method(self, member_id: str) -> str:
        """The method string a bank records for a member that uses this file's threshold."""
        m = next(x for x in self.members if x.id == member_id)
        h = m.held_out
        return (f"calibration study {self.study} ({self.runs} runs, {self.flight_h:.1f} h), held-out rate "
                f"{h.far_per_h:.3g} per h [{h.ci_per_h[0]:.3g}, {h.ci_per_h[1]:.3g}] ({h.false_alarms} in "
                f"{h.exposure_h:.1f} h, target {m.target_per_h:.3g}; calibrated on the {self.split} runs: "
                f"{m.calibration.false_alarms} in {m.calibration.exposure_h:.1f} h, rate ratio "
                f"[{m.rate_ratio_ci[0]:.3g}, {m.rate_ratio_ci[1]:.3g}]; study {self.study_identity}; {m.method})")


def _strict(cls: type, d: Any, source: str, where: str) -> dict[str, Any]:
    """``d``'s keys must be exactly ``cls``'s fields (the file is strict data)."""

    from fdi_sim.errors import ScenarioError

    if not isinstance(d, dict):
        raise ScenarioError(source, where, f"expected a table, got {type(d).__name__}",
                            "write the file with `fdi-sim study STUDY --calibrate OUT.toml`")
    names = [f.name for f in fields(cls)]
    extra = sorted(set(d) - set(names))
    optional = {f.name for f in fields(cls) if f.default is None}  # absent until made (validation)
    missing = [n for n in names if n not in d and n not in optional]
    if extra or missing:
        key = f"{where}.{(extra or missing)[0]}" if where else (extra or missing)[0]
        raise ScenarioError(source, key, ("unknown key" + "s" * (len(extra) > 1) + f" {', '.join(extra)}" if extra
                                          else f"missing key{'s' * (len(missing) > 1)} {', '.join(missing)}"),
                            f"a thresholds file has exactly the keys {', '.join(names)}; write it again with "
                            "`fdi-sim study STUDY --calibrate OUT.toml`")
    return d


#: what a rate's interval says of its target (:func:`fdi_sim.decision.intervals.rate_verdict`)
VERDICTS = ("contains", "below", "above", "undetermined")
#: what two halves' rate ratio says (:class:`StudyMemberThreshold`)
RATIO_CHECKS = ("consistent", "inconsistent", "undetermined")


def _ratio_check(m: dict[str, Any], source: str, i: int) -> str:
    from fdi_sim.errors import ScenarioError

    r = str(m["ratio_check"])
    if r not in RATIO_CHECKS:
        raise ScenarioError(source, f"members[{i}].ratio_check", f"{r!r} is not one of {', '.join(RATIO_CHECKS)}",
                            "write the file again with `fdi-sim study STUDY --calibrate OUT.toml`")
    return r


def _held(d: Any, source: str, where: str) -> HeldRate:
    d = _strict(HeldRate, d, source, where)
    try:
        verdict = str(d["verdict"])
        if verdict not in VERDICTS:
            raise ValueError(f"verdict {verdict!r} is not one of {', '.join(VERDICTS)}")
        return HeldRate(int(d["runs"]), int(d["false_alarms"]), float(d["exposure_h"]), float(d["far_per_h"]),
                        (float(d["ci_per_h"][0]), float(d["ci_per_h"][1])), verdict, float(d["detectable_ratio"]))
    except (TypeError, ValueError, IndexError) as exc:
        from fdi_sim.errors import ScenarioError

        raise ScenarioError(source, where, f"a value of the wrong type ({exc})",
                            "write the file again with `fdi-sim study STUDY --calibrate OUT.toml`") from None


def thresholds_to_dict(t: StudyThresholds) -> dict[str, Any]:
    """The TOML tables of a thresholds file."""
    from dataclasses import asdict

    d = asdict(t)
    d = {"kind": THRESHOLDS_KIND, **d}
    for h in [d["bank_calibration"], d["bank_held_out"]] + [x for m in d["members"] for x in (m["calibration"], m["held_out"])]:
        h["ci_per_h"] = list(h["ci_per_h"])
    for m in d["members"]:
        m["rate_ratio_ci"] = list(m["rate_ratio_ci"])
    d["members"] = list(d["members"])
    if d["validation"] is None:
        del d["validation"]
    else:
        v = d["validation"]
        for h in [v["bank"]] + [m["rate"] for m in v["members"]]:
            h["ci_per_h"] = list(h["ci_per_h"])
        v["members"] = list(v["members"])
    return d


def write_thresholds(t: StudyThresholds, path: str | Path) -> Path:
    """Write a thresholds file (TOML, committed by rename)."""
    import tomli_w

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    head = (f"# fdi-sim thresholds file: written by `fdi-sim study {t.study} --calibrate`, do not edit by hand\n"
            f"# {t.method}\n")
    b = t.bank_held_out
    head += (f"# held-out half: the bank {b.false_alarms} false alarms in {b.exposure_h:.1f} h = {b.far_per_h:.3g} per h "
             f"[{b.ci_per_h[0]:.3g}, {b.ci_per_h[1]:.3g}], target {t.far_per_h:g} "
             f"{'inside' if b.target_inside else 'OUTSIDE'}; members outside: "
             f"{', '.join(m.id for m in t.members if not m.held_out.target_inside) or 'none'}\n")
    v = t.validation
    head += ("# validation: none yet (`fdi-sim study STUDY --validate`)\n" if v is None else
             f"# validation on {v.study} (seed {v.seed}, {v.flight_h:.1f} h): the bank {v.bank.false_alarms} in "
             f"{v.bank.exposure_h:.1f} h = {v.bank.far_per_h:.3g} per h [{v.bank.ci_per_h[0]:.3g}, "
             f"{v.bank.ci_per_h[1]:.3g}], target {t.far_per_h:g}: {v.bank.verdict} (a rate {v.bank.detectable_ratio:.2g} x "
             f"the target would show as above half the time)\n")
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(head + tomli_w.dumps(thresholds_to_dict(t)))
    os.replace(tmp, path)
    return path


def read_thresholds(path: str | Path) -> StudyThresholds:
    """Read a thresholds file (strict: every key, no other).

    Raises
    ------
    ScenarioError
        A missing or unreadable file, another kind, an unknown or missing key; naming the file and key.
    """

    from fdi_sim.errors import ScenarioError

    src = str(path)
    try:
        d = tomllib.loads(Path(path).read_text())
    except OSError as exc:
        raise ScenarioError(src, "", f"cannot read the thresholds file ({exc.strerror or exc})",
                            "give the path of a file written by `fdi-sim study STUDY --calibrate OUT.toml`, "
                            "or thresholds = \"trained\"") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(src, "", f"not valid TOML ({exc})", "write it again with `fdi-sim study STUDY "
                            "--calibrate OUT.toml`") from None
    if d.pop("kind", None) != THRESHOLDS_KIND:
        raise ScenarioError(src, "kind", f"not a thresholds file (kind must be {THRESHOLDS_KIND!r})",
                            "give a file written by `fdi-sim study STUDY --calibrate OUT.toml`")
    d = _strict(StudyThresholds, d, src, "")
    members = []
    for i, m in enumerate(d["members"] if isinstance(d["members"], list) else [None]):
        m = _strict(StudyMemberThreshold, m, src, f"members[{i}]")
        members.append(StudyMemberThreshold(
            str(m["id"]), float(m["threshold"]), float(m["trained_threshold"]), float(m["scale"]),
            float(m["target_per_h"]), _held(m["calibration"], src, f"members[{i}].calibration"),
            _held(m["held_out"], src, f"members[{i}].held_out"), str(m["method"]), float(m["rate_ratio"]),
            (float(m["rate_ratio_ci"][0]), float(m["rate_ratio_ci"][1])), _ratio_check(m, src, i)))
    validation = None
    if "validation" in d:
        v = _strict(Validation, d["validation"], src, "validation")
        try:
            validation = Validation(
                str(v["study"]), str(v["study_identity"]), int(v["seed"]), int(v["runs"]), float(v["flight_h"]),
                _held(v["bank"], src, "validation.bank"),
                tuple(MemberRate(str(_strict(MemberRate, m, src, f"validation.members[{i}]")["id"]),
                                 float(m["target_per_h"]), _held(m["rate"], src, f"validation.members[{i}].rate"))
                      for i, m in enumerate(v["members"])), str(v["version"]))
        except (TypeError, ValueError) as exc:
            raise ScenarioError(src, "validation", f"a value of the wrong type ({exc})",
                                "validate the file again with `fdi-sim study STUDY --validate`") from None
    try:
        return StudyThresholds(
            str(d["aircraft"]), str(d["study"]), str(d["study_identity"]), int(d["runs"]), float(d["flight_h"]),
            str(d["version"]), float(d["design_h_ft"]), float(d["design_vc_kts"]), str(d["design_turbulence"]),
            float(d["design_wind_speed_kts"]), float(d["design_noise_scale"]), str(d["design_hash"]),
            float(d["rate_hz"]), int(d["persistence_k"]), int(d["persistence_n"]), float(d["far_per_h"]),
            str(d["split"]), float(d["confidence"]), tuple(members),
            _held(d["bank_calibration"], src, "bank_calibration"), _held(d["bank_held_out"], src, "bank_held_out"),
            str(d["method"]), validation)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(src, "", f"a value of the wrong type ({exc})",
                            "write the file again with `fdi-sim study STUDY --calibrate OUT.toml`") from None



# --- thresholds from a calibration study ------------------------------------------------------------
#: ``[fdi] thresholds = "default"`` per aircraft: "trained" (the bank's own training flights) or
#: "shipped" (:func:`shipped_thresholds_path`, where it covers the bank's design; trained elsewhere)
DEFAULT_THRESHOLDS: dict[str, str] = {"f16": "shipped", "DHC6": "shipped"}


def shipped_thresholds_path(aircraft: str) -> Path:
    """``aircraft/<aircraft>/fdi_thresholds.toml``: the thresholds the aircraft's calibration study gave."""
    from fdi_sim.data import aircraft_file


    return aircraft_file(aircraft, THRESHOLDS_FILE)

