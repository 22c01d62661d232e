"""The scenario schema: TOML sections validated by pydantic v2 into frozen objects.

Every key carries its unit in its name. Plugin sections (``[[maneuvers]]``, ``[[faults]]``,
``[[detectors]]``) name a registered ``type`` id and are validated against that plugin's
parameter model, so new faults and detectors slot in without touching this file.
"""
from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, SerializerFunctionWrapHandler, model_serializer, model_validator


class _Section(BaseModel):
    # strict: TOML values are typed, so a string or a boolean where a number belongs is a mistake
    # (lax pydantic read ``altitude = "yes"`` as True and ``duration_s = true`` as 1.0 s); an
    # integer still fills a float key
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class InitialSection(_Section):
    """Initial operating point (the trim point)."""

    h_ft: float = Field(ge=500.0, le=50000.0, description="altitude above sea level [ft]")
    vt_kts: float | None = Field(default=None, gt=50.0, le=900.0, description="true airspeed [kt]")
    vc_kts: float | None = Field(default=None, gt=40.0, le=800.0, description="calibrated airspeed [kt]")
    gamma_deg: float = Field(default=0.0, ge=-15.0, le=15.0, description="flight-path angle [deg]")
    phi_deg: float = Field(default=0.0, ge=-60.0, le=60.0, description="bank angle of a steady turn [deg]")
    psi_deg: float = Field(default=0.0, ge=0.0, lt=360.0, description="true heading [deg]")
    flaps_deg: float = Field(default=0.0, ge=0.0, le=40.0, description="flap deflection [deg] (DHC-6)")

    @model_validator(mode="after")
    def _one_speed(self) -> "InitialSection":
        if (self.vt_kts is None) == (self.vc_kts is None):
            raise ValueError("give exactly one of vt_kts (true airspeed) and vc_kts (calibrated airspeed)")
        return self


class AtmosphereSection(_Section):
    turbulence: Literal["none", "light", "moderate", "severe"] = "none"
    wind_from_deg: float = Field(default=0.0, ge=0.0, le=360.0, description="steady wind direction (from) [deg]")
    wind_speed_kts: float = Field(default=0.0, ge=0.0, le=100.0, description="steady wind speed [kt]")


class AutopilotSection(_Section):
    altitude: bool = True
    airspeed: bool = True
    lateral: bool = True


class SensorOverride(_Section):
    noise_std: float | None = Field(default=None, ge=0.0)
    bias: float | None = None
    bias_std: float | None = Field(default=None, ge=0.0)
    rate_hz: float | None = Field(default=None, gt=0.0, le=1000.0)
    quantum: float | None = Field(default=None, ge=0.0)


class SensorsSection(_Section):
    suite: str = "default"
    noise_scale: float = Field(default=1.0, ge=0.0, le=100.0, description="multiplies every sensor's noise")
    biases: bool = True
    overrides: dict[str, SensorOverride] = Field(default_factory=dict)


class LimitsSection(_Section):
    """Where a run counts as diverged (departure)."""

    alpha_min_deg: float = Field(default=-20.0, ge=-90.0, le=0.0)
    alpha_max_deg: float = Field(default=30.0, ge=0.0, le=90.0)
    phi_max_deg: float = Field(default=120.0, gt=0.0, le=180.0)
    rate_max_radps: float = Field(default=4.0, gt=0.0, le=20.0)
    vc_min_kts: float = Field(default=50.0, ge=0.0, le=500.0)


class FdiDesignSection(_Section):
    """The conditions the bank is designed and calibrated for, when not the flight's own
    (``fdi_sim.training.schedule.design_scenario``): a Monte Carlo study designs its bank once per
    schedule-grid node at nominal conditions and flies it in the sampled ones."""

    point: Literal["auto", "flight", "grid"] = Field(
        default="auto", description="design at the flight's initial point, at the nearest node of the "
        "aircraft's schedule grid (fdi_sim.training.schedule.DEFAULT_SPACING), or \"auto\": the calibrated design "
        "of the aircraft's shipped atlas (fdi_sim.training.atlas: no training flight) where it covers the flight "
        "and no other design field is given, else the flight's initial point")
    turbulence: Literal["none", "light", "moderate", "severe"] | None = Field(
        default=None, description="turbulence of the training flights (default: the flight's)")
    wind_speed_kts: float | None = Field(default=None, ge=0.0, le=100.0,
                                         description="steady wind of the training flights [kt] (default: the flight's)")
    wind_from_deg: float | None = Field(default=None, ge=0.0, le=360.0,
                                        description="its direction (from) [deg] (default: the flight's; 0 without wind)")
    noise_scale: float | None = Field(default=None, ge=0.0, le=100.0,
                                      description="sensor noise scale of the training flights (default: the flight's)")
    # TOML arrays give lists: not strict; each entry is validated by its plugin when the design is built
    maneuvers: tuple[dict[str, Any], ...] | None = Field(
        default=None, strict=False, description="the training flights' maneuvers (default: the flight's). A "
        "benchmark case sets its phase's whole list: a case shorter than the training flights has lost the "
        "maneuvers that start after its end, and its design would differ from a longer case's of the same phase")

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        # maneuvers is left out while unset: a scenario's JSON (in every log, in every cache key) is the
        # same bytes as before the key existed
        d = handler(self)
        if self.maneuvers is None and isinstance(d, dict):
            d.pop("maneuvers", None)
        return d


class FdiSection(_Section):
    """The FDI bank flown in the loop (``fdi_sim.bank``)."""

    bank: Literal["none", "default"] = Field(default="none", description="named bank (per aircraft) or none")
    rate_hz: float = Field(default=20.0, gt=0.0, le=240.0, description="detector rate [Hz]; divides rate_hz")
    block_s: float = Field(default=0.5, gt=0.0, le=5.0, description="the bank runs every block_s [s]")
    far_per_h: float = Field(default=0.1, gt=0.0, lt=1.0,
                             description="design false-alarm rate of the whole bank [1/flight hour], in (0, 1)")
    decision: Literal["persistence", "angle-magnitude"] = Field(
        default="persistence", description="k-of-n on the exceedances, or the patent's two-step rule (magnitude, "
        "then the angle to a fault direction: only for detectors that give fault directions)")
    persistence_k: int = Field(default=3, ge=1, le=100, description="alarm when k of the last n samples exceed")
    persistence_n: int = Field(default=5, ge=1, le=100)
    arm_s: float = Field(default=5.0, ge=0.0, le=600.0, description="the bank decides from this time on [s]")
    confirm_s: float = Field(default=0.5, gt=0.0, le=60.0, description="isolation votes before reconfiguring [s]")
    reconfigure: bool = True
    schedule: Literal["auto", "off"] = Field(default="auto", description="gain-schedule the model-based detectors")
    on_design_failure: Literal["refuse", "skip"] = "refuse"
    log_residuals: bool = True
    calibration_flights: int = Field(default=24, ge=2, le=1000)
    calibration_duration_s: float = Field(default=300.0, ge=10.0, le=36000.0)
    design: FdiDesignSection = FdiDesignSection()
    thresholds: str = Field(
        default="default", min_length=1, description="where the members' thresholds come from: \"trained\" (the "
        "bank's own training flights), \"shipped\" (the aircraft's calibration-study file, "
        "fdi_sim.bank.thresholds_file.shipped_thresholds_path), a path to such a TOML file (relative to the scenario "
        "file), or \"default\" (per aircraft: fdi_sim.bank.thresholds_file.DEFAULT_THRESHOLDS)")

    @model_validator(mode="after")
    def _kn(self) -> "FdiSection":
        if self.persistence_k > self.persistence_n:
            raise ValueError(f"persistence_k = {self.persistence_k} exceeds persistence_n = {self.persistence_n}")
        if self.thresholds not in ("default", "trained", "shipped") and not self.thresholds.endswith(".toml"):
            raise ValueError(f"thresholds = {self.thresholds!r}: give \"default\", \"trained\", \"shipped\" or the "
                             "path of a thresholds file ending in .toml (`fdi-sim study STUDY --calibrate OUT.toml` "
                             "writes one)")
        return self

    @model_serializer(mode="wrap")
    def _dump(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        # thresholds is left out while it holds its default: a scenario's JSON (in every log, in a
        # study's identity) is the same bytes as before the key existed
        d = handler(self)
        if self.thresholds == "default" and isinstance(d, dict):
            d.pop("thresholds", None)
        return d


class LogSection(_Section):
    """What the log holds."""

    per_step: bool = Field(default=True, description="the 120 Hz topics (truth, sensors, commands...); "
                           "false keeps only the FDI topics, as a Monte Carlo run would (flushed every 10 s)")


class ScenarioModel(_Section):
    """The whole scenario file."""

    name: str = Field(min_length=1, max_length=120, pattern=r"^[A-Za-z0-9_.\-]+$")
    description: str = ""
    aircraft: Literal["f16", "DHC6"]
    duration_s: float = Field(gt=0.0, le=360000.0, description="simulated time [s]")
    seed: int = Field(default=0, ge=0, lt=2**63)
    rate_hz: Literal[60, 120, 240] = 120
    initial: InitialSection
    atmosphere: AtmosphereSection = AtmosphereSection()
    autopilot: AutopilotSection = AutopilotSection()
    sensors: SensorsSection = SensorsSection()
    limits: LimitsSection = LimitsSection()
    fdi: FdiSection = FdiSection()
    log: LogSection = LogSection()
    # TOML arrays (and JSON) give lists: not strict; the entries are validated by their plugin
    maneuvers: tuple[dict[str, Any], ...] = Field(default=(), strict=False)
    faults: tuple[dict[str, Any], ...] = Field(default=(), strict=False)
    detectors: tuple[dict[str, Any], ...] = Field(default=(), strict=False)
