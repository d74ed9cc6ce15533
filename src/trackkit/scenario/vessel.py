"""Vessel scenarios (Zolfagharnasab and Seif 2025): the manoeuvring model of the 19.6 m SAR boat
identified from simulated GPS/INS sea-trial data, a demonstrated sea trial and the Monte
Carlo runs, as a TOML file validated with pydantic. Run with ``trackkit identify NAME``.

    sc = load_vessel("vessel-zigzag-20")        # bundled by name, or a path to a .toml file
    sc.trial_kwargs()                           # SI keyword arguments of trackkit.sim.seatrials

The file (units in the field names; angles in degrees, the nozzle positive to starboard)::

    name = "vessel-zigzag-20"
    description = "..."
    notes = ["..."]

    [vessel]                   # the truth (the table that marks a vessel scenario)
    coefficients = "reference" # trackkit's stable reference set (models/vessel_data.toml)
    substeps = 10              # the truth's Euler sub-steps per sample (1: the identifier's
                               # own discrete model, paper eq. 4)

    [trial]                    # the demonstrated sea trial (optional)
    kind = "zigzag"            # "zigzag" or "turn"
    rpm = 2000.0
    speed_kn = 18.0            # approach speed (default: the straight-line speed at rpm)
    nozzle_deg = 20.0
    check_deg = 20.0           # zig-zag only: heading deviation that reverses the nozzle
    side = "starboard"         # the first command's side
    commands = 5               # zig-zag only
    # duration_s = 120.0       # default: until the trial is complete (540 deg for a turn)

    [sensors]                  # simulated GPS/INS (trackkit.sim.gnss)
    gps_rate_hz = 2.0
    gps_sigma_m = 1.5          # per horizontal axis
    gps_velocity_sigma_mps = 0.05
    ins_rate_hz = 10.0
    heading_sigma_deg = 0.2
    rate_sigma_deg_s = 0.05

    [identification]
    data = "programme"         # identify.DEFAULT_PROGRAMME, or "trial": the trial itself
    filters = ["ekf"]          # any of ekf, ukf, ckf, srckf, ls (batch least squares); the first
                               # that is not ls is the one the figures show
    period_s = 1.0             # the grid T of the pre-processed u, v, r
    substeps = 10              # the identifier's Euler sub-steps per sample
    theta0 = "zero"            # prior mean: "zero", or "guess" (reference set perturbed by
    guess_spread = 0.5         # up to +-guess_spread, per run: identify.initial_guess)
    theta_sd0 = 1.0            # prior standard deviation of every coefficient (prime units)
    q_body = [3e-4, 3e-4, 3e-6]  # body random walk (m^2/s^3, m^2/s^3, rad^2/s^3)
    q_theta = 0.0              # coefficient random walk (prime units^2 / s)
    settle_tol = 0.2           # "settled": within this fraction of the truth to the end

    [run]
    runs = 10
    seed = 2025

The identifier's measurement standard deviations follow from the sensors: rotating a GPS
velocity error of ``s_v`` per axis with a heading error of ``s_h`` gives surge and sway
errors ``hypot(s_v, |v| s_h)`` and ``hypot(s_v, U s_h)``, taken at the trial's (or the
design) speed U with ``|v| = 0``, and the yaw rate's is the gyro's (:meth:`VesselScenario.sigma_z`).
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, field_validator, model_validator

from trackkit.identify import METHODS
from trackkit.models.manoeuvring import KNOT, CoefficientSet, reference_vessel
from trackkit.scenario import (
    descriptions,
    holds_table,
    read_scenario,
    validated,
)
from trackkit.scenario.schema import (
    NonNegFloat,
    PositiveFloat,
    Strict,
    check_plain_name,
    raise_at,
    unit,
)

__all__ = [
    "FILTERS",
    "IdentificationSpec",
    "SensorsSpec",
    "TrialSpec",
    "VesselRunSpec",
    "VesselScenario",
    "VesselSpec",
    "bundled_vessel",
    "is_vessel",
    "load_vessel",
    "parse_vessel",
]

Array = NDArray[np.float64]

#: the identifiers a scenario (and ``trackkit identify --filter``) may name
FILTERS = METHODS
#: Naji 7's maximum speed (Zolfagharnasab and Seif 2025, Table 2)
MAX_SPEED_KN = 44.0


class VesselSpec(Strict):
    """The truth: the coefficient set and how finely the sea trials are simulated."""

    coefficients: Literal["reference"] = Field(
        "reference", description="the true coefficients: trackkit's stable reference set "
        "(the paper's Tables 3-5 are unstable in any units, models.manoeuvring)")
    substeps: Annotated[int, Field(ge=1, le=100)] = Field(
        10, description="the truth's forward-Euler sub-steps per sample (1: the identifier's "
        "own discrete model, paper eq. 4; 10: close to the continuous model)",
        json_schema_extra=unit("1"))

    def truth(self) -> CoefficientSet:
        return reference_vessel()


class TrialSpec(Strict):
    """The demonstrated sea trial of the reference vessel (SI conversion in
    :meth:`VesselScenario.trial_kwargs`)."""

    kind: Literal["zigzag", "turn"] = Field(description="a zig-zag or a turning circle")
    rpm: Annotated[float, Field(gt=0, le=5000, allow_inf_nan=False)] = Field(
        2000.0, description="engine speed (the reference set is calibrated at 2000 rpm, "
        "18 kn)", json_schema_extra=unit("rpm"))
    speed_kn: Annotated[float, Field(gt=0, le=MAX_SPEED_KN, allow_inf_nan=False)] | None = (
        Field(None, description="approach speed (default: the reference set's straight-line "
              "speed at rpm)"))
    nozzle_deg: Annotated[float, Field(gt=0, le=35, allow_inf_nan=False)] = Field(
        20.0, description="nozzle angle of the commands (the paper's trials: 20 deg)")
    check_deg: Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)] | None = Field(
        None, description="zig-zag only: the heading deviation that reverses the nozzle "
        "(default: nozzle_deg, a 20/20 zig-zag for 20 deg)")
    side: Literal["starboard", "port"] = Field("starboard", description="side of the first "
                                               "command")
    commands: Annotated[int, Field(ge=1, le=20)] | None = Field(
        None, description="zig-zag only: nozzle commands (default 5, the paper's)")
    duration_s: Annotated[float, Field(gt=0, le=3600, allow_inf_nan=False)] | None = Field(
        None, description="length of the record (default: until complete: 540 deg of "
        "heading for a turn, the heading due for the next command of a zig-zag)")

    @model_validator(mode="after")
    def _kind_fields(self) -> TrialSpec:
        if self.kind == "turn":
            for name in ("check_deg", "commands"):
                if getattr(self, name) is not None:
                    raise_at((name,), getattr(self, name), "a zig-zag field; expected no "
                             f"{name} with kind = 'turn'")
        return self


class SensorsSpec(Strict):
    """Simulated GPS and INS (``trackkit.sim.gnss``; the defaults are its own, explained
    there)."""

    gps_rate_hz: Annotated[float, Field(gt=0, le=100, allow_inf_nan=False)] = Field(
        2.0, description="GPS fix rate (IMO asks high-speed craft for 2 Hz)")
    gps_sigma_m: PositiveFloat = Field(1.5, description="GPS position noise per horizontal "
                                       "axis")
    gps_velocity_sigma_mps: PositiveFloat = Field(
        0.05, description="GPS velocity noise per horizontal axis (> 0: the identifier's "
        "measurement covariance must be positive definite)")
    ins_rate_hz: Annotated[float, Field(gt=0, le=1000, allow_inf_nan=False)] = Field(
        10.0, description="INS heading and yaw-rate rate")
    heading_sigma_deg: NonNegFloat = Field(0.2, description="INS heading noise")
    rate_sigma_deg_s: PositiveFloat = Field(0.05, description="INS yaw-rate noise (> 0, as "
                                            "gps_velocity_sigma_mps)")

    def gps(self):
        from trackkit.sim.gnss import GpsModel

        return GpsModel(rate=self.gps_rate_hz, sigma_position=self.gps_sigma_m,
                        sigma_velocity=self.gps_velocity_sigma_mps)

    def ins(self):
        from trackkit.sim.gnss import InsModel

        return InsModel(rate=self.ins_rate_hz, sigma_heading=math.radians(self.heading_sigma_deg),
                        sigma_rate=math.radians(self.rate_sigma_deg_s))


def _q_body(v: list[float]) -> list[float]:
    if len(v) != 3 or not all(math.isfinite(x) and x >= 0 for x in v):
        raise ValueError("expected 3 finite densities >= 0 (surge m^2/s^3, sway m^2/s^3, yaw "
                         "rad^2/s^3)")
    return v


class IdentificationSpec(Strict):
    """What is identified from which data, by which filters, with which prior and noise."""

    data: Literal["programme", "trial"] = Field(
        "programme", description="the identification data: identify.DEFAULT_PROGRAMME "
        "(seven trials, 657 s at 1 s) or the demonstrated trial itself")
    filters: list[Literal[METHODS]] = Field(  # type: ignore[valid-type]
        default_factory=lambda: ["ekf"], min_length=1, description="the identifiers "
        "compared: the augmented EKF, UKF, CKF or square-root CKF, or batch least squares "
        "(ls); the first "
        "that is not ls is the one the figures show")
    period_s: Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)] = Field(
        1.0, description="sample period T of the pre-processed u, v, r (the paper's "
        "'500 recursive steps' in 500 s suggest 1 s)")
    substeps: Annotated[int, Field(ge=1, le=100)] = Field(
        10, description="the identifier's Euler sub-steps per sample (1: paper eq. 4)",
        json_schema_extra=unit("1"))
    theta0: Literal["zero", "guess"] = Field(
        "zero", description="the coefficients' prior mean: zero, or the reference set "
        "perturbed per run by up to +-guess_spread (identify.initial_guess)")
    guess_spread: Annotated[float, Field(ge=0, le=2, allow_inf_nan=False)] = Field(
        0.5, description="relative perturbation of the guess", json_schema_extra=unit("1"))
    theta_sd0: PositiveFloat = Field(1.0, description="the coefficients' prior standard "
                                     "deviation", json_schema_extra=unit("prime units"))
    q_body: list[float] = Field(
        default_factory=lambda: [3e-4, 3e-4, 3e-6], description="random-walk densities of "
        "the body states (the programme's inputs are known at the samples only, and this Q "
        "covers their interpolation; identify.DEFAULT_Q_BODY is for measured inputs)",
        json_schema_extra=unit("m^2/s^3, m^2/s^3, rad^2/s^3"))
    q_theta: NonNegFloat = Field(0.0, description="random-walk density of every coefficient "
                                 "(0: constant)", json_schema_extra=unit("prime units^2/s"))
    settle_tol: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)] = Field(
        0.2, description="a coefficient has settled from the step after which it stays "
        "within this fraction of the truth", json_schema_extra=unit("1"))

    _q = field_validator("q_body")(classmethod(lambda cls, v: _q_body(v)))

    @field_validator("filters")
    @classmethod
    def _unique(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError("expected each filter at most once")
        return v

    @property
    def shown(self) -> str:
        """The filter the figures show: the first that is not ls (ls when it is alone)."""
        return next((f for f in self.filters if f != "ls"), self.filters[0])


class VesselRunSpec(Strict):
    """The Monte Carlo runs: every run its own sensor noise (and prior guess)."""

    runs: Annotated[int, Field(ge=1, le=100_000)] = Field(10, description="Monte Carlo runs")
    seed: Annotated[int, Field(ge=0)] = Field(0, description="master seed; run r draws from "
                                              "SeedSequence(seed, spawn_key=(r, ...))")


class VesselScenario(Strict):
    """A vessel identification scenario: truth, trial, sensors, identification and runs."""

    name: str = Field(max_length=255, description="the scenario's name; the report goes to "
                      "trackkit-out/NAME, so a plain file name: letters, digits, '.', '_', "
                      "'-', not starting with '.'")
    description: str = Field("", description="one line for `trackkit list` and the report")
    vessel: VesselSpec = Field(description="the truth (this table marks a vessel scenario: "
                               "write [vessel] even with its defaults)")
    trial: TrialSpec | None = Field(None, description="the demonstrated sea trial")
    sensors: SensorsSpec = Field(default_factory=SensorsSpec, description="simulated GPS/INS")
    identification: IdentificationSpec = Field(default_factory=IdentificationSpec,
                                               description="identifiers, prior and noise")
    run: VesselRunSpec = Field(default_factory=VesselRunSpec, description="the Monte Carlo "
                               "runs")
    notes: list[str] = Field(default_factory=list, description="notes printed with the "
                             "results (what is invented and why)")

    _plain_name = field_validator("name")(classmethod(lambda cls, v: check_plain_name(v)))

    @model_validator(mode="after")
    def _consistent(self) -> VesselScenario:
        if self.identification.data == "trial" and self.trial is None:
            raise_at(("identification", "data"), "trial", "expected a [trial] table to "
                     "identify from (or data = 'programme')")
        return self

    # -- SI for trackkit.sim.seatrials and trackkit.identify --------------------------------

    def speed(self) -> float:
        """The trial's approach speed (m/s): ``speed_kn``, else the truth's straight-line
        speed at the trial's (or the design) rpm."""
        from trackkit.models.manoeuvring import straight_line_speed

        truth = self.vessel.truth()
        if self.trial is not None and self.trial.speed_kn is not None:
            return self.trial.speed_kn * KNOT
        rpm = self.trial.rpm if self.trial is not None else truth.design["rpm"]
        return float(straight_line_speed(truth.theta, rpm, truth.norm))

    def rpm(self) -> float:
        """The trial's (or the design) engine speed, rpm."""
        return self.trial.rpm if self.trial is not None else self.vessel.truth().design["rpm"]

    def trial_kwargs(self) -> dict:
        """Keyword arguments (SI) of ``seatrials.zigzag`` or ``seatrials.turning_circle``
        for the trial, without theta, norm, T and substeps."""
        tr = self.trial
        if tr is None:
            raise ValueError(f"scenario {self.name!r} has no [trial]")
        kw: dict = {"delta": math.radians(tr.nozzle_deg), "rpm": tr.rpm, "speed": self.speed(),
                    "side": 1.0 if tr.side == "starboard" else -1.0,
                    "duration": tr.duration_s}
        if tr.kind == "zigzag":
            check = tr.nozzle_deg if tr.check_deg is None else tr.check_deg
            kw.update(alpha=math.radians(check), commands=tr.commands or 5)
        return kw

    def sigma_z(self) -> Array:
        """The identifier's measurement standard deviations of ``[u, v, r]`` (module
        docstring): ``[s_v, hypot(s_v, U s_h), s_r]`` at the trial's speed U."""
        s = self.sensors
        sv, sh = s.gps_velocity_sigma_mps, math.radians(s.heading_sigma_deg)
        return np.array([sv, math.hypot(sv, self.speed() * sh), math.radians(s.rate_sigma_deg_s)])


# ---------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------


def _bundled_dir():
    return resources.files("trackkit.scenario") / "vessels"


def bundled_vessel() -> dict[str, str]:
    """Bundled vessel scenario names and their one-line descriptions."""
    return descriptions(_bundled_dir())


def parse_vessel(data: dict, source: str = "<scenario>") -> VesselScenario:
    """Validate a vessel scenario given as a dict (e.g. parsed TOML); every problem is a
    ScenarioError naming ``source``, the field, the value and what is expected."""
    return validated(VesselScenario, data, source)


def is_vessel(name_or_path: str | Path) -> bool:
    """Whether ``name_or_path`` is a bundled vessel scenario's name, or a TOML file with a
    ``[vessel]`` table (no other kind of scenario has one). A file that cannot be read or
    parsed is not claimed (another loader then reports its problem)."""
    return holds_table(name_or_path, _bundled_dir(), "vessel", dict)


def load_vessel(name_or_path: str | Path) -> VesselScenario:
    """Load a bundled vessel scenario by name or a TOML file by path."""
    return parse_vessel(*read_scenario(name_or_path, _bundled_dir(), "vessel "))
