"""The scenario file schema (TOML), validated with pydantic.

Units are declared in field names at the edge (``_m``, ``_s``, ``_kn``, ``_deg``, ``_deg_s``,
``_mps``, ``_hz``) and converted to SI once, by the ``si`` helpers here; lists of state values
(``state``, prior ``mean`` and ``std``) are SI in trackkit's state ordering.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

KNOT = 1852.0 / 3600.0  # m/s
KMH = 1000.0 / 3600.0  # m/s

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class TimeSpec(_Strict):
    """Scenario time: ``duration_s`` and ``step_s``; measurements at every step after 0."""

    duration_s: PositiveFloat
    step_s: PositiveFloat

    @model_validator(mode="after")
    def _whole_steps(self) -> TimeSpec:
        n = self.duration_s / self.step_s
        if abs(n - round(n)) > 1e-9 * max(n, 1):
            raise ValueError(
                f"duration_s = {self.duration_s} is not a whole number of steps of "
                f"step_s = {self.step_s}"
            )
        return self

    @property
    def steps(self) -> int:
        return int(round(self.duration_s / self.step_s))


class Kinematics(_Strict):
    """Initial position and velocity: position in metres, velocity as course and speed
    (nautical course, clockwise from north) or as components; ``z_m`` and ``vz_mps`` for 3-D.
    """

    x_m: Finite = 0.0
    y_m: Finite = 0.0
    z_m: Finite | None = None
    course_deg: Finite | None = None
    speed_kn: NonNegFloat | None = None
    vx_mps: Finite | None = None
    vy_mps: Finite | None = None
    vz_mps: Finite | None = None

    @model_validator(mode="after")
    def _one_velocity(self) -> Kinematics:
        polar = self.course_deg is not None or self.speed_kn is not None
        cart = self.vx_mps is not None or self.vy_mps is not None
        if polar and cart:
            raise ValueError("give the velocity as course_deg/speed_kn or as vx_mps/vy_mps, "
                             "not both")
        if polar and (self.course_deg is None) != (self.speed_kn is None) and self.speed_kn:
            raise ValueError("course_deg and speed_kn go together")
        return self

    def velocity(self) -> tuple[float, float]:
        if self.speed_kn is not None:
            c = math.radians(self.course_deg or 0.0)
            v = self.speed_kn * KNOT
            return v * math.sin(c), v * math.cos(c)
        return self.vx_mps or 0.0, self.vy_mps or 0.0


class Leg(_Strict):
    """A manoeuvre from ``start_s``: a new course and/or speed at once; a constant turn at
    ``turn_rate_deg_s`` (positive to starboard, i.e. clockwise) until ``end_s``; or a
    tangential ``acceleration_mps2`` until ``end_s``."""

    start_s: NonNegFloat
    end_s: NonNegFloat | None = None
    course_deg: Finite | None = None
    speed_kn: NonNegFloat | None = None
    turn_rate_deg_s: Finite | None = None
    acceleration_mps2: Finite | None = None
    #: a new velocity by components from ``start_s`` (a piecewise velocity schedule; 3-D)
    velocity_mps: list[Finite] | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> Leg:
        change = self.course_deg is not None or self.speed_kn is not None
        kinds = [change, self.turn_rate_deg_s is not None, self.acceleration_mps2 is not None,
                 self.velocity_mps is not None]
        if sum(kinds) != 1:
            raise ValueError("a leg is exactly one of: course_deg/speed_kn change, "
                             "turn_rate_deg_s, acceleration_mps2, velocity_mps")
        if self.velocity_mps is not None and len(self.velocity_mps) not in (2, 3):
            raise ValueError(f"velocity_mps has {len(self.velocity_mps)} components; "
                             "expected 2 or 3 (the scenario's dim)")
        if (self.turn_rate_deg_s is not None or self.acceleration_mps2 is not None) and (
            self.end_s is None or self.end_s <= self.start_s
        ):
            raise ValueError(f"a turn or acceleration leg needs end_s > start_s = "
                             f"{self.start_s}; got end_s = {self.end_s}")
        return self


class MotionSpec(_Strict):
    """A motion model by name with its parameters (SI)."""

    model: Literal["ConstantVelocity", "ConstantAcceleration", "Singer", "CoordinatedTurn",
                   "Linear"]
    q: NonNegFloat = 0.0
    #: Q given per step as a diagonal (SI, state order) instead of from the spectral
    #: density q: the additive "Q = q I" of seed 000 (ConstantVelocity and Linear)
    q_diag: list[NonNegFloat] | None = None
    #: the transition matrix of a ``Linear`` model (any state, e.g. seed 000's chapter 3)
    F: list[list[Finite]] | None = None
    q_omega: NonNegFloat = 1e-6
    #: random-walk density of the constant extras (e.g. f0), for filters' models
    q_extra: NonNegFloat = 0.0
    tau: PositiveFloat = 20.0
    sigma: NonNegFloat = 1.0

    @model_validator(mode="after")
    def _linear(self) -> MotionSpec:
        if self.model == "Linear":
            if self.F is None or self.q_diag is None:
                raise ValueError("motion model Linear needs F (a square matrix) and q_diag")
            n = len(self.F)
            if any(len(row) != n for row in self.F):
                raise ValueError(f"F has rows of lengths {[len(r) for r in self.F]}; "
                                 "expected a square matrix")
            if len(self.q_diag) != n:
                raise ValueError(f"q_diag has {len(self.q_diag)} values; expected {n} "
                                 "(the size of F)")
        elif self.F is not None:
            raise ValueError(f"F is only for motion model Linear, not {self.model}")
        elif self.q_diag is not None and self.model != "ConstantVelocity":
            raise ValueError(f"q_diag is for ConstantVelocity and Linear, not {self.model}")
        return self


class Target(_Strict):
    initial: Kinematics = Field(default_factory=Kinematics)
    state: list[Finite] | None = None
    motion: MotionSpec = Field(default_factory=lambda: MotionSpec(model="ConstantVelocity"))
    legs: list[Leg] = Field(default_factory=list)
    #: constant extra state components appended after the kinematics (e.g. f0 for DBT)
    extras: list[Finite] = Field(default_factory=list)


class SensorSpec(_Strict):
    """A sensor model by name. Noise as a standard deviation with units in the field name,
    or as ``snr_db`` (noise variance per channel = mean square of the noise-free measurement
    over the nominal truth / 10^(snr/10))."""

    model: Literal["Bearing", "RangeBearing", "Position", "AzimuthElevation",
                   "BearingFrequency", "MultipathDelay"]
    sigma_deg: PositiveFloat | None = None
    sigma_m: PositiveFloat | None = None
    sigma_hz: PositiveFloat | None = None
    sigma_s: PositiveFloat | None = None
    #: the noise covariance's diagonal per channel in SI units squared (m^2, rad^2, s^2);
    #: for Position it also sets the dimension (H = [I 0], e.g. seed 000's chapter 3)
    r_diag_si: list[PositiveFloat] | None = None
    snr_db: Finite | None = None
    convention: Literal["nautical", "math"] = "nautical"
    c_mps: PositiveFloat = 1500.0
    h_surface_m: PositiveFloat | None = None
    h_bottom_m: PositiveFloat | None = None
    #: probability that a scan has a measurement (1 = always); missing ones are nan
    p_detect: Annotated[float, Field(gt=0, le=1)] = 1.0

    @model_validator(mode="after")
    def _noise_given(self) -> SensorSpec:
        need = {
            "Bearing": ["sigma_deg"],
            "RangeBearing": ["sigma_m", "sigma_deg"],
            "Position": ["sigma_m"],
            "AzimuthElevation": ["sigma_deg"],
            "BearingFrequency": ["sigma_deg", "sigma_hz"],
            "MultipathDelay": ["sigma_s"],
        }[self.model]
        if self.snr_db is None and self.r_diag_si is None:
            missing = [f for f in need if getattr(self, f) is None]
            if missing:
                raise ValueError(f"sensor {self.model} needs {', '.join(missing)} (or snr_db "
                                 "or r_diag_si)")
        if self.model == "MultipathDelay" and (self.h_surface_m is None
                                               or self.h_bottom_m is None):
            raise ValueError("sensor MultipathDelay needs h_surface_m and h_bottom_m")
        return self


class Observer(_Strict):
    initial: Kinematics = Field(default_factory=Kinematics)
    legs: list[Leg] = Field(default_factory=list)
    sensor: SensorSpec


class PriorSpec(_Strict):
    """Filter prior: ``std`` (SI, state order) gives P0 = diag(std^2), or ``cov`` gives P0 in
    full (symmetric positive definite). Without ``mean`` the prior mean of each run is the
    truth plus a draw from N(0, P0) (a consistent prior); with ``mean``, every run starts
    from that mean."""

    std: list[PositiveFloat] | None = None
    cov: list[list[Finite]] | None = None
    mean: list[Finite] | None = None

    @model_validator(mode="after")
    def _one_cov(self) -> PriorSpec:
        if (self.std is None) == (self.cov is None):
            raise ValueError("give exactly one of std (standard deviations) or cov (matrix)")
        if self.cov is not None:
            import numpy as np

            P = np.asarray(self.cov, dtype=float)
            if P.ndim != 2 or P.shape[0] != P.shape[1]:
                raise ValueError(f"cov has shape {P.shape}; expected a square matrix")
            if not np.allclose(P, P.T, rtol=1e-12, atol=0):
                raise ValueError("cov is not symmetric")
            eig = np.linalg.eigvalsh(P)
            if eig[0] <= 0:
                raise ValueError(f"cov is not positive definite (smallest eigenvalue "
                                 f"{eig[0]:.3g}); expected a positive definite matrix")
        return self

    @property
    def size(self) -> int:
        return len(self.std) if self.std is not None else len(self.cov)


class TuneSpec(_Strict):
    """Off-line tuning of a fuzzy-adaptive filter's membership functions (seed 000, 3-2):
    ``runs`` independent optimiser runs on the DOM cost of ``realisations`` simulated runs of
    the scenario drawn from ``seed``, which is kept apart from the Monte Carlo seed so the
    filter is never scored on the data it was tuned on; the best run's parameters are used.
    ``on``: reuse the tuning of the same-named filter of that bundled scenario instead."""

    optimizer: Literal["GA", "PSO", "ICA"] = "ICA"
    population: Annotated[int, Field(ge=2)] = 50
    iterations: Annotated[int, Field(ge=1)] = 30
    runs: Annotated[int, Field(ge=1)] = 15
    seed: Annotated[int, Field(ge=0)] = 1
    realisations: Annotated[int, Field(ge=1)] = 1
    on: str | None = None


FUZZY_TYPES = {"OFKF": "KF", "OFEKF": "EKF", "OFUKF": "UKF"}


class FilterSpec(_Strict):
    name: str = Field(min_length=1)
    type: Literal["KF", "EKF", "EKF2", "IEKF", "UKF", "CKF", "MCEKF", "AMCEKF", "AEKF",
                  "OFKF", "OFEKF", "OFUKF"]
    options: dict[str, float | int | bool | str | list[float] | None] = Field(
        default_factory=dict)
    motion: MotionSpec | None = None  # default: the target's motion model
    prior: PriorSpec | None = None  # default: the scenario's prior
    #: the R the filter believes (diagonal, SI units squared) instead of the true R
    r0_diag_si: list[PositiveFloat] | None = None
    #: tune the fuzzy system (OF* filters without a ``params`` option)
    tune: TuneSpec | None = None

    @model_validator(mode="after")
    def _known_options(self) -> FilterSpec:
        import inspect

        from trackkit import filters

        fuzzy = self.type in FUZZY_TYPES
        if fuzzy and (self.tune is None) == ("params" not in self.options):
            raise ValueError(f"filter {self.name!r} ({self.type}) needs exactly one of tune "
                             "(tune the fuzzy system) or options.params (15 values)")
        if self.tune is not None and not fuzzy:
            raise ValueError(f"filter {self.name!r} ({self.type}): tune is only for the "
                             f"fuzzy-adaptive filters {sorted(FUZZY_TYPES)}")
        cls = filters.FuzzyAdaptive if fuzzy else getattr(
            filters, "EKF" if self.type == "EKF2" else self.type)
        allowed = [p for p in inspect.signature(cls).parameters if p not in ("self", "base")]
        unknown = sorted(set(self.options) - set(allowed))
        if unknown:
            raise ValueError(f"filter {self.name!r} ({self.type}) has no option "
                             f"{', '.join(unknown)}; allowed: {allowed or 'none'}")
        return self


class RunSpec(_Strict):
    runs: Annotated[int, Field(ge=1)] = 100
    seed: Annotated[int, Field(ge=0)] = 0
    #: runs per simulation block: the unit of work that makes results independent of
    #: how runs are split over executors
    block: Annotated[int, Field(ge=1)] = 250


class ReportSpec(_Strict):
    groups: list[Literal["position", "velocity", "speed", "course", "x", "y", "z", "vx",
                         "vy", "vz", "x1", "x2", "x3", "frequency", "bearing"]] = Field(
        default_factory=lambda: ["position", "velocity"])
    average_from_s: NonNegFloat = 0.0
    #: report seed 000's J1-J4 and the per-step R, S, C, DOM of run 0 (trackkit.eval.matching)
    matching: bool = False
    #: the alpha of J4 = alpha sum_i RMS(DOM(i,i)) (seed 000: 1000 in chapter 3, 5000 after)
    dom_alpha: PositiveFloat = 1000.0


class Scenario(_Strict):
    name: str = Field(min_length=1)
    description: str = ""
    dim: Literal[2, 3] = 2
    time: TimeSpec
    target: Target
    observers: list[Observer] = Field(min_length=1)
    prior: PriorSpec
    filters: list[FilterSpec] = Field(min_length=1)
    run: RunSpec = Field(default_factory=RunSpec)
    report: ReportSpec = Field(default_factory=ReportSpec)
    notes: list[str] = Field(default_factory=list)

    @model_validator(mode="after")
    def _consistent(self) -> Scenario:
        n = self.state_dim
        if self.target.state is not None and len(self.target.state) != n:
            raise ValueError(f"target.state has {len(self.target.state)} values; the state "
                             f"[pos, vel, extras] has {n}")
        for where, prior in [("prior", self.prior)] + [
            (f"filters[{i}].prior", f.prior) for i, f in enumerate(self.filters) if f.prior
        ]:
            if prior.size != n:
                what = "std" if prior.std is not None else "cov"
                raise ValueError(f"{where}.{what} has {prior.size} rows; expected {n} "
                                 "(the state length)")
            if prior.mean is not None and len(prior.mean) != n:
                raise ValueError(f"{where}.mean has {len(prior.mean)} values; expected {n}")
        names = [f.name for f in self.filters]
        if len(set(names)) != len(names):
            raise ValueError(f"filter names must be unique; got {names}")
        if self.report.average_from_s >= self.time.duration_s:
            raise ValueError(f"report.average_from_s = {self.report.average_from_s} is not "
                             f"before the end of the scenario ({self.time.duration_s} s)")
        if self.dim == 2 and (self.target.initial.z_m is not None):
            raise ValueError("target.initial.z_m is set but dim = 2")
        if self.linear_system and (self.target.state is None or self.target.legs):
            raise ValueError("a target with motion model Linear needs target.state and "
                             "takes no legs")
        for i, f in enumerate(self.filters):
            if f.motion is not None and f.motion.model == "Linear" and (
                    len(f.motion.F) != n):
                raise ValueError(f"filters[{i}].motion.F is {len(f.motion.F)} x "
                                 f"{len(f.motion.F)}; expected {n} x {n}")
        platforms = [("target", self.target.legs)] + [
            (f"observers[{i}]", o.legs) for i, o in enumerate(self.observers)]
        for where, legs in platforms:
            for j, leg in enumerate(legs):
                if leg.velocity_mps is not None and len(leg.velocity_mps) != self.dim:
                    raise ValueError(f"{where}.legs[{j}].velocity_mps has "
                                     f"{len(leg.velocity_mps)} components; expected "
                                     f"{self.dim} (dim)")
        if self.linear_system:
            allowed = {f"x{i}" for i in range(1, n + 1)}
            bad = [g for g in self.report.groups if g not in allowed]
            if bad:
                raise ValueError(f"report.groups has {bad}; a Linear target's state has no "
                                 f"positions or velocities, so expected groups among "
                                 f"{sorted(allowed)}")
        for i, o in enumerate(self.observers):
            r = o.sensor.r_diag_si
            if (o.sensor.model == "Position" and r is not None and not self.linear_system
                    and len(r) != self.dim):
                raise ValueError(f"observers[{i}].sensor.r_diag_si has {len(r)} values; a "
                                 f"Position sensor measures the {self.dim} position "
                                 "components (dim)")
        return self

    @property
    def linear_system(self) -> bool:
        """The target follows a ``Linear`` model (a state that is not [pos, vel])."""
        return self.target.motion.model == "Linear"

    @property
    def state_dim(self) -> int:
        if self.linear_system:
            return len(self.target.motion.F)
        return 2 * self.dim + len(self.target.extras)
