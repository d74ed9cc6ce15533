"""The scenario file schema (TOML), validated with pydantic.

Units are declared in field names at the edge (``_m``, ``_s``, ``_kn``, ``_deg``, ``_deg_s``,
``_mps``, ``_hz``) and converted to SI once, by the ``si`` helpers here; lists of state values
(``state``, prior ``mean`` and ``std``) are SI in trackkit's state ordering. Every field has a
description (and, without a unit suffix, a ``unit``): ``trackkit.scenario.reference``
generates ``docs/scenario-reference.md`` from them.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from trackkit.models.classes import CLASSES
from trackkit.scenario.options import (
    CLASS_TYPES,
    CONSTANT_GAIN_TYPES,
    FILTER_TYPES,
    FUZZY_TYPES,
    IMM_INNER_TYPES,
    check_options,
    make_filter,
)

KNOT = 1852.0 / 3600.0  # m/s
KMH = 1000.0 / 3600.0  # m/s

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]

#: a scenario name is the report's folder name under trackkit-out/: one plain file name
PLAIN_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]*")
#: an error window's name (report.windows): a label for tables and results.json
WINDOW_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")


def check_plain_name(name: str) -> str:
    """A scenario's ``name`` is a folder of trackkit-out/: a plain file name, nothing else."""
    if not PLAIN_NAME.fullmatch(name):
        raise ValueError("expected a plain file name (letters, digits, '.', '_', '-', not "
                         "starting with '.'): the report is written to trackkit-out/NAME")
    return name


def window_steps(start_s: float, end_s: float, steps: int, step_s: float) -> tuple[int, int]:
    """The step indices ``k0 .. k1 - 1`` of an error window: the measurement times
    ``t_k = (k + 1) step_s`` with ``start_s <= t_k < end_s`` (times compared within 1e-9
    relative), and the last measurement too when ``end_s`` is the scenario's end."""
    eps = 1e-9 * step_s
    k0 = max(0, math.ceil((start_s - eps) / step_s) - 1)
    if end_s >= steps * step_s - eps:
        k1 = steps
    else:
        k1 = max(0, math.ceil((end_s - eps) / step_s) - 1)
    return min(k0, steps), min(k1, steps)


def raise_at(loc: tuple[str | int, ...], value: Any, message: str) -> None:
    """Raise a validation error at ``loc`` below the model being validated, so that the
    message names the exact field (``filters.2.options.alpha``), not the enclosing table."""
    error = PydanticCustomError("scenario", "{message}", {"message": message})
    raise ValidationError.from_exception_data(
        "Scenario", [InitErrorDetails(type=error, loc=loc, input=value)])


def unit(unit: str) -> dict[str, str]:
    """The unit of a field whose name carries no unit suffix (for the reference)."""
    return {"unit": unit}


class Strict(BaseModel):
    """The base of every scenario section: unknown keys are refused and the model is frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class TimeSpec(Strict):
    """Scenario time: ``duration_s`` and ``step_s``; measurements at every step after 0."""

    duration_s: PositiveFloat = Field(description="length of the scenario")
    step_s: PositiveFloat = Field(description="time between measurements (the filters' step)")

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


class Kinematics(Strict):
    """Initial position and velocity: position in metres, velocity as course and speed
    (nautical course, clockwise from north) or as components; ``z_m`` and ``vz_mps`` for 3-D.
    """

    x_m: Finite = Field(0.0, description="east position")
    y_m: Finite = Field(0.0, description="north position")
    z_m: Finite | None = Field(None, description="height (up; negative below the surface), "
                               "dim = 3 only")
    course_deg: Finite | None = Field(None, description="course, clockwise from north (with "
                                      "speed_kn)")
    speed_kn: NonNegFloat | None = Field(None, description="speed over ground (with "
                                         "course_deg)")
    vx_mps: Finite | None = Field(None, description="east velocity (instead of course and "
                                  "speed)")
    vy_mps: Finite | None = Field(None, description="north velocity")
    vz_mps: Finite | None = Field(None, description="vertical velocity, dim = 3 only")

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


class Leg(Strict):
    """A manoeuvre from ``start_s``: a new course and/or speed at once; a constant turn at
    ``turn_rate_deg_s`` (positive to starboard, i.e. clockwise) until ``end_s``; or a
    tangential ``acceleration_mps2`` until ``end_s``."""

    start_s: NonNegFloat = Field(description="when the leg starts")
    end_s: NonNegFloat | None = Field(None, description="when a turn or acceleration leg ends")
    course_deg: Finite | None = Field(None, description="new course from start_s, clockwise "
                                      "from north")
    speed_kn: NonNegFloat | None = Field(None, description="new speed from start_s")
    turn_rate_deg_s: Finite | None = Field(None, description="constant turn from start_s to "
                                           "end_s, positive to starboard (clockwise)")
    acceleration_mps2: Finite | None = Field(None, description="tangential acceleration "
                                             "from start_s to end_s")
    velocity_mps: list[Finite] | None = Field(
        None, description="new velocity by components (dim values) from start_s: a "
        "piecewise velocity schedule")

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


class MotionSpec(Strict):
    """A motion model by name with its parameters (SI)."""

    model: Literal["ConstantVelocity", "ConstantAcceleration", "Singer", "CoordinatedTurn",
                   "Linear", "ContinuousLinear"] = Field(
        description="the motion model (trackkit.models); ContinuousLinear: dx/dt = A x + L w, "
        "E[w w^T] = Qc delta(t), discretised exactly (Van Loan) for the step")
    q: NonNegFloat = Field(0.0, description="spectral density of the white process noise: of "
                           "the acceleration (ConstantVelocity, CoordinatedTurn) or of the "
                           "jerk (ConstantAcceleration; m^2/s^5)", json_schema_extra=unit(
                               "m^2/s^3"))
    q_diag: list[NonNegFloat] | None = Field(
        None, description="Q per step as a diagonal, in state order, instead of from q: the "
        "additive Q = q I of Naseri Solhdar (ConstantVelocity and Linear)",
        json_schema_extra=unit("SI squared"))
    F: list[list[Finite]] | None = Field(
        None, description="the transition matrix per step of a Linear model (any state, e.g. "
        "Naseri Solhdar's chapter 3)", json_schema_extra=unit("SI"))
    A: list[list[Finite]] | None = Field(
        None, description="the continuous-time system matrix of a ContinuousLinear model",
        json_schema_extra=unit("SI"))
    L: list[list[Finite]] | None = Field(
        None, description="the noise gain of a ContinuousLinear model (n rows, one column "
        "per noise input)", json_schema_extra=unit("SI"))
    Qc: list[list[Finite]] | None = Field(
        None, description="the spectral density of the white noise w of a ContinuousLinear "
        "model (symmetric, positive semi-definite)", json_schema_extra=unit("SI squared"))
    q_omega: NonNegFloat = Field(1e-6, description="spectral density of the turn rate "
                                 "(CoordinatedTurn)", json_schema_extra=unit("rad^2/s^3"))
    q_extra: NonNegFloat = Field(0.0, description="random-walk density of the constant "
                                 "extras (e.g. f0), for filters' models",
                                 json_schema_extra=unit("SI^2/s"))
    tau: PositiveFloat = Field(20.0, description="manoeuvre time constant (Singer)",
                               json_schema_extra=unit("s"))
    sigma: NonNegFloat = Field(1.0, description="standard deviation of the acceleration "
                               "(Singer)", json_schema_extra=unit("m/s^2"))

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
        if self.model == "ContinuousLinear":
            self._continuous_shapes()
        elif any(m is not None for m in (self.A, self.L, self.Qc)):
            raise ValueError(f"A, L and Qc are only for motion model ContinuousLinear, not "
                             f"{self.model}")
        return self

    def _continuous_shapes(self) -> None:
        """A (n, n), L (n, s) and Qc (s, s) symmetric positive semi-definite."""
        if self.A is None or self.L is None or self.Qc is None:
            raise ValueError("motion model ContinuousLinear needs A (n x n), L (n x s) and Qc "
                             "(s x s)")
        n = len(self.A)
        if any(len(row) != n for row in self.A):
            raise ValueError(f"A has rows of lengths {[len(r) for r in self.A]}; expected a "
                             "square matrix")
        s = len(self.L[0]) if self.L else 0
        if len(self.L) != n or s == 0 or any(len(row) != s for row in self.L):
            raise ValueError(f"L has rows of lengths {[len(r) for r in self.L]}; expected {n} "
                             "rows (the size of A) of one length, the number of noise inputs")
        if len(self.Qc) != s or any(len(row) != s for row in self.Qc):
            raise ValueError(f"Qc has rows of lengths {[len(r) for r in self.Qc]}; expected "
                             f"{s} x {s} (L's columns)")
        import numpy as np

        Qc = np.asarray(self.Qc, dtype=float)
        if not np.array_equal(Qc, Qc.T):
            raise ValueError("Qc is not symmetric; expected a symmetric positive "
                             "semi-definite matrix")
        low = float(np.linalg.eigvalsh(Qc)[0])
        if low < -1e-12 * max(float(np.abs(Qc).max()), 1e-300):
            raise ValueError(f"Qc is not positive semi-definite (smallest eigenvalue "
                             f"{low:.3g}); expected a spectral density")


class Target(Strict):
    """The target's truth: initial kinematics (or a full initial state), its motion model and
    process noise, scripted manoeuvres and constant extra state components."""

    initial: Kinematics = Field(default_factory=Kinematics,
                                description="initial position and velocity")
    state: list[Finite] | None = Field(
        None, description="the full initial state in state order, instead of initial "
        "(required with motion model Linear or ContinuousLinear)", json_schema_extra=unit("SI"))
    motion: MotionSpec = Field(default_factory=lambda: MotionSpec(model="ConstantVelocity"),
                               description="the truth's motion model and process noise (also "
                               "the filters' unless a filter has its own)")
    legs: list[Leg] = Field(default_factory=list, description="scripted manoeuvres")
    extras: list[Finite] = Field(
        default_factory=list, description="constant extra state components appended after "
        "the kinematics (e.g. the tone frequency f0 for Doppler-bearing tracking)",
        json_schema_extra=unit("SI"))


class SensorSpec(Strict):
    """A sensor model by name. Noise as a standard deviation with units in the field name,
    or as ``snr_db`` (noise variance per channel = mean square of the noise-free measurement
    over the nominal truth / 10^(snr/10))."""

    model: Literal["Bearing", "RangeBearing", "Position", "AzimuthElevation",
                   "BearingFrequency", "MultipathDelay", "Sine"] = Field(
        description="the measurement: bearing; range and bearing; position; azimuth and "
        "elevation; bearing and received frequency; surface and bottom multipath delays; "
        "a sin(theta) of the state [theta, omega, a] (the random sine of the "
        "missing-measurements thesis)")
    sigma_deg: PositiveFloat | None = Field(None, description="standard deviation of the "
                                            "bearing (and elevation) noise")
    sigma_m: PositiveFloat | None = Field(None, description="standard deviation of the range "
                                          "(or each position component) noise")
    sigma_hz: PositiveFloat | None = Field(None, description="standard deviation of the "
                                           "frequency noise")
    sigma_s: PositiveFloat | None = Field(None, description="standard deviation of each "
                                          "delay's noise")
    r_diag_si: list[PositiveFloat] | None = Field(
        None, description="the noise covariance's diagonal per channel (m^2, rad^2, Hz^2, "
        "s^2) instead of the sigmas; for Position it also sets the dimension (H = [I 0], "
        "e.g. Naseri Solhdar's chapter 3)", json_schema_extra=unit("SI squared"))
    snr_db: Finite | None = Field(None, description="signal-to-noise ratio instead of the "
                                  "sigmas: noise variance per channel = mean square of the "
                                  "noise-free measurement over the nominal truth / "
                                  "10^(snr_db / 10)")
    convention: Literal["nautical", "math"] = Field(
        "nautical", description="angles clockwise from north (nautical) or counter-clockwise "
        "from east (math)")
    c_mps: PositiveFloat = Field(1500.0, description="speed of sound (BearingFrequency, "
                                 "MultipathDelay)")
    h_surface_m: PositiveFloat | None = Field(None, description="depth of the sensor below "
                                              "the surface (MultipathDelay)")
    h_bottom_m: PositiveFloat | None = Field(None, description="height of the sensor above "
                                             "the bottom (MultipathDelay)")
    p_detect: Annotated[float, Field(gt=0, le=1)] = Field(
        1.0, description="probability that a scan has a measurement (1 = always); missing "
        "ones are nan")
    amplitude: bool = Field(True, description="Sine only: y = a sin(theta) on the state "
                            "[theta, omega, a] (true, section 2-5-5-2 of the missing-measurements "
                            "thesis), or y = sin(theta) on [theta, omega] (false, its section "
                            "4-4)")

    @model_validator(mode="after")
    def _noise_given(self) -> SensorSpec:
        need = {
            "Bearing": ["sigma_deg"],
            "RangeBearing": ["sigma_m", "sigma_deg"],
            "Position": ["sigma_m"],
            "AzimuthElevation": ["sigma_deg"],
            "BearingFrequency": ["sigma_deg", "sigma_hz"],
            "MultipathDelay": ["sigma_s"],
            "Sine": [],
        }[self.model]
        if self.model == "Sine" and self.snr_db is None and self.r_diag_si is None:
            raise ValueError("sensor Sine needs r_diag_si (its R, one value) or snr_db")
        if self.snr_db is None and self.r_diag_si is None:
            missing = [f for f in need if getattr(self, f) is None]
            if missing:
                raise ValueError(f"sensor {self.model} needs {', '.join(missing)} (or snr_db "
                                 "or r_diag_si)")
        if self.model != "Sine" and not self.amplitude:
            raise ValueError(f"amplitude = false is for sensor Sine, not {self.model}")
        if self.model == "MultipathDelay" and (self.h_surface_m is None
                                               or self.h_bottom_m is None):
            raise ValueError("sensor MultipathDelay needs h_surface_m and h_bottom_m")
        return self


class Observer(Strict):
    """A sensor platform: its initial kinematics, its manoeuvres and its sensor."""

    initial: Kinematics = Field(default_factory=Kinematics,
                                description="initial position and velocity")
    legs: list[Leg] = Field(default_factory=list, description="scripted manoeuvres")
    sensor: SensorSpec = Field(description="what it measures and how noisily")


class GAInitSpec(Strict):
    """The GA initialiser of Hashemi and Alfi (2019) (``trackkit.filters.initialise``): per run, a
    genetic algorithm searches the initial target position that minimises an auxiliary EKF's
    normalised residuals over the first ``measurements`` measurements; every filter then
    starts from ``N([p_GA, velocity_guess_mps, f0_guess], diag(std^2))`` at the prior time,
    with f0_guess the run's first measured frequency. Doppler-bearing scenarios only (state
    [x, y, vx, vy, f0], one observer with a BearingFrequency sensor). The auxiliary filter
    predicts with the first filter's motion model."""

    measurements: Annotated[int, Field(ge=1)] = Field(
        800, description="K, the first measurements the GA's auxiliary filter sees (range is "
        "not observable from a few tens: about 600 to 800 are needed for the paper's "
        "< 1000 m, see trackkit.filters.initialise)", json_schema_extra=unit("measurements"))
    block: Annotated[int, Field(ge=1)] = Field(
        25, description="average blocks of this many measurements (odd, dividing K) before "
        "the auxiliary filter runs: the same information at a 25th of the cost",
        json_schema_extra=unit("measurements"))
    population: Annotated[int, Field(ge=2)] = Field(50, description="GA population (the "
                                                    "paper's 50)",
                                                    json_schema_extra=unit("candidates"))
    generations: Annotated[int, Field(ge=0)] = Field(200, description="GA generations (the "
                                                     "paper's 200)",
                                                     json_schema_extra=unit("generations"))
    crossover: float = Field(0.8, ge=0, le=1, description="GA crossover rate (the paper's "
                             "0.8)", json_schema_extra=unit("probability"))
    mutation: float = Field(0.05, ge=0, le=1, description="GA per-gene mutation rate (the "
                            "paper's 0.05)", json_schema_extra=unit("probability"))
    cost: Literal["nis", "nll"] = Field(
        "nis", description="the auxiliary filter's cost: the sum of the NIS (the paper's "
        "residual, normalised) or twice the negative log likelihood (NIS + log det S)")
    max_range_m: PositiveFloat = Field(20_000.0, description="half-width of the square "
                                       "searched around the observer's first position")
    velocity_guess_mps: list[Finite] = Field(
        default_factory=lambda: [0.0, 0.0], description="the velocity [vx, vy] every run's "
        "filters (and the auxiliary filter) start from: the GA searches the position only")
    aux_std: list[PositiveFloat] = Field(
        default_factory=lambda: [200.0, 200.0, 10.0, 10.0, 5.0],
        description="the auxiliary filter's prior standard deviations [x, y, vx, vy, f0]: "
        "small in position so that the cost scores the candidate position itself",
        json_schema_extra=unit("SI"))
    std: list[PositiveFloat] = Field(
        default_factory=lambda: [1000.0, 1000.0, 10.0, 10.0, 5.0],
        description="the filters' initial standard deviations [x, y, vx, vy, f0] after a GA "
        "start: P0 = diag(std^2). Default: 1000 m, the accuracy the paper claims (Fig. 17), "
        "10 m/s around the velocity guess (a ship's speed) and 5 Hz around the first measured "
        "frequency (the Doppler shift f0 v / c is 5 Hz at 15 kn and 500 Hz)",
        json_schema_extra=unit("SI"))

    @model_validator(mode="after")
    def _block_divides(self) -> GAInitSpec:
        if self.block % 2 == 0:
            raise_at(("block",), self.block, f"prior.ga.block = {self.block}; expected an "
                     "odd number (each block stands for its centre measurement)")
        if self.measurements % self.block:
            raise_at(("measurements",), self.measurements,
                     f"prior.ga.measurements = {self.measurements} is not a multiple of "
                     f"block = {self.block}; expected a whole number of blocks")
        if len(self.velocity_guess_mps) != 2:
            raise_at(("velocity_guess_mps",), self.velocity_guess_mps,
                     f"prior.ga.velocity_guess_mps has {len(self.velocity_guess_mps)} values; "
                     "expected 2, [vx, vy]")
        for name in ("aux_std", "std"):
            values = getattr(self, name)
            if len(values) != 5:
                raise_at((name,), values, f"prior.ga.{name} has {len(values)} values; "
                         "expected 5, for the Doppler-bearing state [x, y, vx, vy, f0]")
        return self


class PriorSpec(Strict):
    """Filter prior: ``std`` (SI, state order) gives P0 = diag(std^2), or ``cov`` gives P0 in
    full (symmetric positive definite). Without ``mean`` the prior mean of each run is the
    truth plus a draw from N(0, P0) (a consistent prior); with ``mean``, every run starts
    from that mean."""

    std: list[PositiveFloat] | None = Field(
        None, description="standard deviations in state order: P0 = diag(std^2)",
        json_schema_extra=unit("SI"))
    cov: list[list[Finite]] | None = Field(
        None, description="P0 in full (symmetric positive definite), instead of std",
        json_schema_extra=unit("SI squared"))
    mean: list[Finite] | None = Field(
        None, description="the prior mean of every run; without it, each run's is the truth "
        "plus a draw from N(0, P0)", json_schema_extra=unit("SI"))
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


class ScenarioPriorSpec(PriorSpec):
    """The scenario's prior (``[prior]``): a filter prior (``std`` or ``cov``, ``mean``) that
    is also the PCRLB's ``J0 = P0^-1``, and how every filter's first estimate is made:
    ``initialiser = "draw"`` (the prior) or ``"ga"`` (the GA initialiser of Hashemi and Alfi (2019),
    settings in ``prior.ga``)."""

    initialiser: Literal["draw", "ga"] = Field(
        "draw", description="how every filter's first estimate is made: \"draw\", the "
        "prior above (mean, or the truth plus a draw from N(0, P0)); \"ga\", the GA "
        "initialiser of Hashemi and Alfi (2019) from the first measurements (settings in "
        "prior.ga; Doppler-bearing scenarios only). With \"ga\" the prior above is still the "
        "PCRLB's J0 = P0^-1, which a GA-started filter does not use")
    ga: GAInitSpec | None = Field(None, description="the GA initialiser's settings (with "
                                  "initialiser = \"ga\"; defaults: the paper's GA, 800 "
                                  "measurements in blocks of 25)")

    @model_validator(mode="after")
    def _initialiser(self) -> ScenarioPriorSpec:
        if self.ga is not None and self.initialiser != "ga":
            raise_at(("ga",), "...", f"prior.ga is set but initialiser = "
                     f"{self.initialiser!r}; expected initialiser = \"ga\" with a ga table "
                     "(or no ga table)")
        if self.initialiser == "ga" and self.mean is not None:
            raise_at(("mean",), self.mean, "prior.mean is set with initialiser = \"ga\", "
                     "which makes each run's mean from the GA; expected no mean (or "
                     "initialiser = \"draw\")")
        return self

    @property
    def ga_settings(self) -> GAInitSpec:
        """The GA initialiser's settings (the defaults when ``ga`` is not given)."""
        return self.ga if self.ga is not None else GAInitSpec()


class GapsSpec(Strict):
    """Missing measurements (the missing-measurements thesis, chapter 4): every listed interval is
    masked out of the simulated measurements of every filter (nan, as if the radar saw nothing).
    Intervals by time, by sample index or by count, several of each, combined (their union);
    measurement k (0-based) is taken at ``t = (k + 1) step_s``. What each filter is fed instead is
    its own
    ``gaps`` handler (default B0: nothing, the filter coasts)."""

    time_s: list[tuple[NonNegFloat, NonNegFloat]] = Field(
        default_factory=list, description="[start_s, stop_s] intervals, half-open: missing "
        "where start_s <= t < stop_s (ends compared within 1e-9 relative), so [2, 5] at "
        "step_s = 0.1 hides the 30 measurements at t = 2.0 .. 4.9 s; each must hold one")
    samples: list[tuple[Annotated[int, Field(ge=0)], Annotated[int, Field(ge=0)]]] = Field(
        default_factory=list, description="[first, last] measurement indices, 0-based, both "
        "included (the missing-measurements thesis's samples 50 to 90, counted from 1, are "
        "[49, 89])",
        json_schema_extra=unit("index"))
    counts: list[tuple[Annotated[int, Field(ge=0)], Annotated[int, Field(ge=1)]]] = Field(
        default_factory=list, description="[start, count]: count consecutive measurements "
        "from index start (0-based)", json_schema_extra=unit("index, samples"))

    @model_validator(mode="after")
    def _some(self) -> GapsSpec:
        if not (self.time_s or self.samples or self.counts):
            raise ValueError("gaps has no interval; expected at least one of time_s, samples "
                             "or counts")
        for i, (a, b) in enumerate(self.time_s):
            if not a < b:
                raise_at(("time_s", i), [a, b], f"time_s[{i}] = [{a}, {b}]; expected start_s "
                         "< stop_s")
        for i, (a, b) in enumerate(self.samples):
            if not a <= b:
                raise_at(("samples", i), [a, b], f"samples[{i}] = [{a}, {b}]; expected first "
                         "<= last")
        return self

    def mask(self, steps: int, step_s: float) -> Any:
        """The (steps,) bool mask of missing measurements (True = missing)."""
        import numpy as np

        from trackkit.filters.gaps import (
            mask_by_count,
            mask_by_samples,
            mask_by_time,
            measurement_times,
        )

        t = measurement_times(steps, step_s)
        out = np.zeros(steps, bool)
        for a, b in self.time_s:
            out |= mask_by_time(t, a, b)
        for a, b in self.samples:
            out |= mask_by_samples(steps, a, b)
        for a, c in self.counts:
            out |= mask_by_count(steps, a, c)
        return out


class DetectorSpec(Strict):
    """The manoeuvre detector that switches a P' handler to its short window
    (``trackkit.filters.maneuver``); fed the innovations of real measurements only."""

    type: Literal["NIS", "fading", "window"] = Field(
        description="NIS: eps = nu^T S^-1 nu against the chi-square quantile; fading: rho = "
        "alpha rho + eps (Imhof threshold); window: the sum of the last L residuals")
    pfa: Annotated[float, Field(gt=0, lt=1, allow_inf_nan=False)] = Field(
        0.01, description="false-alarm probability per step of the on threshold",
        json_schema_extra=unit("-"))
    alpha: Annotated[float, Field(gt=0, lt=1, allow_inf_nan=False)] | None = Field(
        None, description="fading memory's factor (fading only; default 0.8)",
        json_schema_extra=unit("-"))
    L: Annotated[int, Field(ge=1)] | None = Field(
        None, description="window length (window only; default 5)",
        json_schema_extra=unit("steps"))

    @model_validator(mode="after")
    def _fields_of_type(self) -> DetectorSpec:
        if self.alpha is not None and self.type != "fading":
            raise_at(("alpha",), self.alpha, f"alpha is for detector type \"fading\", not "
                     f"{self.type!r}")
        if self.L is not None and self.type != "window":
            raise_at(("L",), self.L, f"L is for detector type \"window\", not {self.type!r}")
        return self

    def build(self, dim_z: int) -> Any:
        from trackkit.filters import maneuver as mv

        if self.type == "NIS":
            return mv.NISDetector(pfa=self.pfa, dim_z=dim_z)
        if self.type == "fading":
            return mv.FadingMemoryDetector(alpha=0.8 if self.alpha is None else self.alpha,
                                           pfa=self.pfa, dim_z=dim_z)
        return mv.WindowDetector(L=5 if self.L is None else self.L, pfa=self.pfa, dim_z=dim_z)


#: the handler options each handler takes (the rest are refused)
_HANDLER_OPTIONS = {
    "B0": set(), "B1": set(), "B2": {"n"},
    "P": {"degree", "window", "function", "amplitude"},
    "P'": {"degree", "window", "function", "amplitude", "short_window", "detector"},
}


class GapHandlerSpec(Strict):
    """What a filter is fed at a missing measurement (the missing-measurements thesis, chapter 4;
    ``trackkit.filters.gaps``): B0 nothing (coast on the prediction), B1 the last real
    measurement, B2 the mean of the last n, P a least-squares fit through the last ``window``
    real measurements extrapolated over the gap (a polynomial in time of ``degree``, or the
    sine ``y = a sin(theta0 + omega tau)`` of a [theta, omega(, a)] state), and P' the same fit
    over the last ``short_window`` only in the runs whose manoeuvre ``detector`` is on when
    the gap begins. The steps fed a pseudo-measurement are counted in the results."""

    handler: Literal["B0", "B1", "B2", "P", "P'"] = Field(
        "B0", description="the handler (B0: the plain nan convention)")
    n: Annotated[int, Field(ge=1)] | None = Field(
        None, description="B2: measurements averaged (default 5)", json_schema_extra=unit(
            "samples"))
    function: Literal["polynomial", "sine"] | None = Field(
        None, description="P, P': the fitted function (default polynomial; sine needs a "
        "one-channel sensor and the state's theta, omega at indices 0, 1)")
    degree: Annotated[int, Field(ge=0)] | None = Field(
        None, description="P, P' polynomial: its degree (default 1: 1 for a CV target, 2 for "
        "CA)", json_schema_extra=unit("-"))
    window: Annotated[int, Field(ge=1)] | None = Field(
        None, description="P, P': real measurements fitted (default 10 polynomial, 30 sine)",
        json_schema_extra=unit("samples"))
    amplitude: Annotated[int, Field(ge=0)] | None = Field(
        None, description="P, P' sine: the state index of the amplitude a, fitted too "
        "(default none: a = 1)", json_schema_extra=unit("index"))
    short_window: Annotated[int, Field(ge=1)] | None = Field(
        None, description="P' (required): the window while the detector is on",
        json_schema_extra=unit("samples"))
    detector: DetectorSpec | None = Field(None, description="P' (required): the manoeuvre "
                                          "detector")

    @model_validator(mode="after")
    def _options_of_handler(self) -> GapHandlerSpec:
        allowed = _HANDLER_OPTIONS[self.handler]
        for name in ("n", "function", "degree", "window", "amplitude", "short_window",
                     "detector"):
            value = getattr(self, name)
            if value is not None and name not in allowed:
                takes = ", ".join(sorted(allowed)) or "no options"
                raise_at((name,), value if name != "detector" else value.model_dump(),
                         f"{name} is not an option of handler {self.handler!r}; it takes "
                         f"{takes}")
        if self.handler == "P'":
            for name in ("short_window", "detector"):
                if getattr(self, name) is None:
                    raise_at((name,), None, f"handler \"P'\" needs {name} (the window and "
                             "the manoeuvre detector that shortens it)")
        if self.function == "sine" and self.degree is not None:
            raise_at(("degree",), self.degree, "degree is for function \"polynomial\", not "
                     "\"sine\"")
        if self.function != "sine" and self.amplitude is not None:
            raise_at(("amplitude",), self.amplitude, "amplitude is for function \"sine\"")
        try:
            self.build()
        except ValueError as err:
            named = [k for k in ("short_window", "window", "degree", "n", "amplitude")
                     if k in str(err) and getattr(self, k) is not None]
            where = named[0] if named else "handler"
            raise_at((where,), getattr(self, where), str(err))
        return self

    def build(self) -> Any:
        """The ``trackkit.filters.gaps`` handler."""
        from trackkit.filters.gaps import make_handler

        opts = {k: getattr(self, k) for k in ("n", "degree", "window", "amplitude",
                                               "short_window")
                if getattr(self, k) is not None}
        if self.function is not None:
            opts["function"] = self.function
        return make_handler(self.handler, **opts)


class TuneSpec(Strict):
    """Off-line tuning of a fuzzy-adaptive filter's membership functions (Naseri Solhdar, section
    3-2):
    ``runs`` independent optimiser runs on the DOM cost of ``realisations`` simulated runs of
    the scenario drawn from ``seed``, which is kept apart from the Monte Carlo seed so the
    filter is never scored on the data it was tuned on; the best run's parameters are used.
    ``on``: reuse the tuning of the same-named filter of that bundled scenario instead."""

    optimizer: Literal["GA", "PSO", "ICA"] = Field(
        "ICA", description="genetic algorithm, particle swarm or imperialist competitive "
        "algorithm")
    population: Annotated[int, Field(ge=2)] = Field(50, description="candidates per "
                                                    "generation")
    iterations: Annotated[int, Field(ge=1)] = Field(30, description="generations")
    runs: Annotated[int, Field(ge=1)] = Field(15, description="independent optimiser runs; "
                                              "the best is kept")
    seed: Annotated[int, Field(ge=0)] = Field(1, description="seed of the tuning data and "
                                              "the optimiser (apart from run.seed)")
    realisations: Annotated[int, Field(ge=1)] = Field(1, description="simulated runs of the "
                                                      "scenario the cost averages over")
    on: str | None = Field(None, description="reuse the tuning of the same-named filter of "
                           "this bundled scenario instead")


FilterTypeName = Literal[tuple(FILTER_TYPES)]  # type: ignore[valid-type]


def motion_dim(spec: MotionSpec, dim: int) -> int:
    """The state length of a motion model over ``dim`` positions (no extras)."""
    if spec.model == "Linear":
        return len(spec.F)
    if spec.model == "ContinuousLinear":
        return len(spec.A)
    return {"ConstantVelocity": 2 * dim, "ConstantAcceleration": 3 * dim, "Singer": 3 * dim,
            "CoordinatedTurn": 5}[spec.model]


class IMMModelSpec(Strict):
    """One model of an IMM: its motion and the filter that runs it."""

    motion: MotionSpec = Field(description="the model's motion (its state is the first "
                               "components of the IMM's union state: CV [x, y, vx, vy] "
                               "inside CT [x, y, vx, vy, omega])")
    filter: Literal[IMM_INNER_TYPES] = Field(  # type: ignore[valid-type]
        "EKF", description="the filter of this model")
    options: dict[str, Any] = Field(default_factory=dict, description="the inner filter's "
                                    "options (see Filter types below)")

    @field_validator("options")
    @classmethod
    def _valid_options(cls, options: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        type_ = info.data.get("filter")
        if type_ is None:
            return options
        out, problems = check_options(type_, options)
        if problems:
            line_errors = [InitErrorDetails(
                type=PydanticCustomError("scenario", "{message}",
                                         {"message": f"IMM model ({type_}): {message}"}),
                loc=(name,), input=value) for name, value, message in problems]
            raise ValidationError.from_exception_data("IMMModelSpec", line_errors)
        return out


class IMMSpec(Strict):
    """The models of an IMM filter, the mode transition matrix and the initial mode
    probabilities; ``extra_std`` (and ``extra_mean``) is the prior of the union state's
    components beyond the scenario's state (a CT model's turn rate omega), which the truth
    does not carry and the metrics do not score."""

    models: list[IMMModelSpec] = Field(min_length=1, description="the models, each a motion "
                                       "and its filter")
    transition: list[list[Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]]] = Field(
        description="p_ij = P(model j at k | model i at k-1): r x r, rows summing to 1",
        json_schema_extra=unit("probability"))
    mu0: list[Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]] | None = Field(
        None, description="initial mode probabilities (r values summing to 1); default: "
        "equal", json_schema_extra=unit("probability"))
    extra_std: list[PositiveFloat] = Field(
        default_factory=list, description="prior standard deviations of the union state's "
        "components after the scenario's state, in order (omega of a CT model: rad/s)",
        json_schema_extra=unit("SI"))
    extra_mean: list[Finite] | None = Field(
        None, description="prior means of those components (default: zeros)",
        json_schema_extra=unit("SI"))

    @model_validator(mode="after")
    def _probabilities(self) -> IMMSpec:
        r = len(self.models)
        P = self.transition
        if len(P) != r or any(len(row) != r for row in P):
            raise ValueError(f"transition has rows of lengths {[len(row) for row in P]}; "
                             f"expected {r} x {r} (one row and column per model)")
        for i, row in enumerate(P):
            if abs(math.fsum(row) - 1.0) > 1e-9:
                raise ValueError(f"transition row {i} = {row} sums to {math.fsum(row)!r}; "
                                 "expected rows summing to 1")
        if self.mu0 is not None:
            if len(self.mu0) != r:
                raise ValueError(f"mu0 has {len(self.mu0)} values; expected {r} (one per "
                                 "model)")
            if abs(math.fsum(self.mu0) - 1.0) > 1e-9:
                raise ValueError(f"mu0 = {self.mu0} sums to {math.fsum(self.mu0)!r}; expected "
                                 "probabilities summing to 1")
        if self.extra_mean is not None and len(self.extra_mean) != len(self.extra_std):
            raise ValueError(f"extra_mean has {len(self.extra_mean)} values; expected "
                             f"{len(self.extra_std)} (one per extra_std)")
        kinds = {m.motion.model for m in self.models}
        if "CoordinatedTurn" in kinds and kinds & {"ConstantAcceleration", "Singer"}:
            raise ValueError(f"models {sorted(kinds)}: a CT state [x, y, vx, vy, omega] and "
                             "an acceleration state [x, y, vx, vy, ax, ay] do not nest (each "
                             "model's state is the first components of the union); expected "
                             "CV with CT, or CV with CA or Singer")
        return self

    def union_dim(self, dim: int) -> int:
        return max(motion_dim(m.motion, dim) for m in self.models)


class FilterSpec(Strict):
    """A filter to compare: its type, its options (see the table of each type's options),
    and optionally its own motion model, prior, believed R and fuzzy-system tuning."""

    name: str = Field(min_length=1, description="the filter's name in tables and plots "
                      "(unique in the scenario)")
    type: FilterTypeName = Field(description="the filter (see Filter types below)")
    options: dict[str, Any] = Field(default_factory=dict, description="the type's options "
                                    "(see Filter types below); omitted ones take their "
                                    "defaults")
    motion: MotionSpec | None = Field(None, description="the filter's motion model; default: "
                                      "the target's")
    prior: PriorSpec | None = Field(None, description="the filter's prior; default: the "
                                    "scenario's")
    r0_diag_si: list[PositiveFloat] | None = Field(
        None, description="the R the filter believes (diagonal per channel) instead of the "
        "true R", json_schema_extra=unit("SI squared"))
    tune: TuneSpec | None = Field(None, description="tune the fuzzy system off-line "
                                  "(fuzzy-adaptive types without options.params)")
    gaps: GapHandlerSpec | None = Field(None, description="what the filter is fed at a "
                                        "missing measurement (see `filters[].gaps`); "
                                        "default: nothing (B0, it coasts)")
    imm: IMMSpec | None = Field(None, description="type IMM: its models, transition and mu0 "
                                "(see `filters[].imm`)")

    @field_validator("options")
    @classmethod
    def _valid_options(cls, options: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        type_ = info.data.get("type")
        if type_ is None:  # the type itself is wrong: that is the error to report
            return options
        out, problems = check_options(type_, options)
        if problems:
            who = f"filter {info.data.get('name')!r} ({type_})"
            line_errors = [InitErrorDetails(
                type=PydanticCustomError("scenario", "{message}",
                                         {"message": f"{who}: {message}"}),
                loc=(name,), input=value) for name, value, message in problems]
            raise ValidationError.from_exception_data("FilterSpec", line_errors)
        return out

    @model_validator(mode="after")
    def _buildable(self) -> FilterSpec:
        fuzzy = self.type in FUZZY_TYPES
        if fuzzy and (self.tune is None) == ("params" not in self.options):
            raise ValueError(f"filter {self.name!r} ({self.type}) needs exactly one of tune "
                             "(tune the fuzzy system) or options.params (15 values)")
        if self.tune is not None and not fuzzy:
            raise ValueError(f"filter {self.name!r} ({self.type}): tune is only for the "
                             f"fuzzy-adaptive filters {sorted(FUZZY_TYPES)}")
        if (self.type == "IMM") != (self.imm is not None):
            raise ValueError(f"filter {self.name!r} ({self.type}): " + (
                "an IMM needs its imm table (models, transition)" if self.imm is None
                else "the imm table is only for type IMM"))
        if self.type == "IMM" and self.motion is not None:
            raise ValueError(f"filter {self.name!r} (IMM): motion = {self.motion.model}; an "
                             "IMM's motions are its imm.models[].motion, so expected no "
                             "filters[].motion")
        try:  # what one option alone cannot say: ceiling > floor, the fuzzy params' order
            make_filter(self.type, self.options)
        except ValueError as err:
            raise_at(("options",), self.options, f"filter {self.name!r} ({self.type}): {err}")
        return self

#: a sweep range: "LOW:HIGH" (uniform) or "log:LOW:HIGH" (log-uniform, LOW > 0)
SWEEP_RANGE = re.compile(r"(log:)?([^:]+):([^:]+)")


def parse_range(text: str) -> tuple[float, float, bool] | None:
    """``(low, high, log)`` of a sweep range ``"LOW:HIGH"`` or ``"log:LOW:HIGH"``; None when
    ``text`` is not of that form (a value); ValueError when it is but the numbers are not a
    range (finite, low < high, low > 0 for log)."""
    m = SWEEP_RANGE.fullmatch(text.strip())
    if m is None:
        return None
    try:
        low, high = float(m.group(2)), float(m.group(3))
    except ValueError:
        return None
    log = m.group(1) is not None
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise ValueError(f"range {text!r}: expected finite LOW < HIGH")
    if log and low <= 0:
        raise ValueError(f"range {text!r}: a log range needs 0 < LOW < HIGH")
    return low, high, log


class SweepSpec(Strict):
    """A parameter sweep for ``trackkit sweep`` (ignored by ``trackkit run``): each swept
    field by its dotted path, as ``trackkit show`` prints it (``observers.0.sensor.sigma_deg``,
    ``sensor.sigma_deg`` for every observer's sensor, ``filters.EKF.motion.q`` for a filter's
    own assumption apart from the truth), with a list of values or a range; the command's
    ``--param``, ``--design`` and ``--points`` replace these."""

    params: dict[str, list[Any] | str] = Field(
        description="path -> values (a list) or a range \"LOW:HIGH\" (uniform) or "
        "\"log:LOW:HIGH\" (log-uniform); a grid takes `points` evenly spaced values of a range",
        json_schema_extra=unit("the field's"))
    design: Literal["grid", "random", "lhs"] = Field(
        "grid", description="the full grid of the values, or `points` points drawn at random "
        "or by Latin hypercube (seeded by the campaign seed)")
    points: Annotated[int, Field(ge=1)] | None = Field(
        None, description="random, lhs: the number of points; grid: the values per range",
        json_schema_extra=unit("points"))

    @model_validator(mode="after")
    def _ranges(self) -> SweepSpec:
        if not self.params:
            raise ValueError("sweep.params is empty; expected at least one path = values")
        for path, values in self.params.items():
            if isinstance(values, list):
                if not values:
                    raise_at(("params", path), values, f"{path}: no values; expected a "
                             "non-empty list or a range \"LOW:HIGH\"")
                continue
            try:
                if parse_range(values) is None:
                    raise ValueError(f"{values!r} is neither a list of values nor a range")
            except ValueError as err:
                raise_at(("params", path), values, f"{path}: {err}; expected a list of "
                         "values, \"LOW:HIGH\" or \"log:LOW:HIGH\"")
        ranged = [p for p, v in self.params.items() if isinstance(v, str)]
        if (self.design != "grid" or ranged) and self.points is None:
            what = (f"a {self.design} design" if self.design != "grid"
                    else f"the ranges of {ranged} in a grid")
            raise ValueError(f"sweep.points is missing; {what} needs it")
        return self


class RunSpec(Strict):
    """The Monte Carlo runs."""

    runs: Annotated[int, Field(ge=1)] = Field(100, description="Monte Carlo runs")
    seed: Annotated[int, Field(ge=0)] = Field(0, description="master seed; run i draws from "
                                              "its own child of SeedSequence(seed)")
    block: Annotated[int, Field(ge=1)] = Field(
        250, description="runs per simulation block: the unit of work that makes results "
        "independent of how runs are split over executors")


ErrorGroup = Literal["position", "velocity", "speed", "course", "x", "y", "z", "vx", "vy", "vz",
                    "x1", "x2", "x3", "frequency", "bearing"]


class PublishedSpec(Strict):
    """A paper's error table for this scenario, as the paper prints it: a report marks its
    ratios (each filter's error over the reference filter's, derived, never typed in) beside
    ours."""

    group: ErrorGroup = Field("position", description="the error group of the table")
    versus: str = Field(description="the reference filter the ratios divide by (a filter "
                        "name of this scenario)")
    rmse: dict[str, PositiveFloat] = Field(description="the published RMSE by filter name "
                                           "(SI units), the reference filter's included")
    source: str = Field(description="where the numbers are printed (paper, table)")

    @model_validator(mode="after")
    def _has_reference(self) -> PublishedSpec:
        if self.versus not in self.rmse:
            raise_at(("versus",), self.versus, f"report.published versus = {self.versus!r} "
                     f"has no rmse entry; expected one of {sorted(self.rmse)}")
        return self

    def ratio(self, name: str) -> float:
        """The paper's RMSE of ``name`` over that of ``versus``."""
        return self.rmse[name] / self.rmse[self.versus]

    def filters(self) -> list[str]:
        """The filters the paper gives a ratio for (all but the reference)."""
        return [f for f in self.rmse if f != self.versus]


class ReportSpec(Strict):
    """What the report shows."""

    groups: list[ErrorGroup] = Field(
        default_factory=lambda: ["position", "velocity"],
        description="the error groups of the RMSE tables and plots (x1, x2, x3: the states "
        "of a Linear or ContinuousLinear target, whose positions and velocities, when its "
        "state has them, are its first 2 dim components)")
    average_from_s: NonNegFloat = Field(0.0, description="RMSE, ANEES and ANIS are averaged "
                                        "from this time on (after convergence)")
    windows: dict[str, list[NonNegFloat]] = Field(
        default_factory=dict, description="named error windows, each [start_s, end_s]: RMSE, "
        "RMSE/PCRLB, ANEES and ANIS over the measurement times start_s <= t < end_s (a window "
        "ending at duration_s includes the last measurement), reported beside the average "
        "from average_from_s; e.g. { transient = [600, 1000], steady = [1000, 2000] }",
        json_schema_extra=unit("s"))
    published: list[PublishedSpec] = Field(
        default_factory=list, description="a paper's error tables for this scenario "
        "({ group, versus, rmse = { FILTER = RMSE, ... }, source }): the sweep report marks "
        "the paper's ratios beside ours")
    matching: bool = Field(False, description="report Naseri Solhdar's J1-J4 and the per-step R, "
                           "S, C, DOM of run 0 (trackkit.eval.covariance_matching)")
    dom_alpha: PositiveFloat = Field(1000.0, description="the alpha of J4 = alpha sum_i "
                                     "RMS(DOM(i,i)) (Naseri Solhdar: 1000 in chapter 3, 5000 "
                                     "after)")
    angle_states: list[Annotated[int, Field(ge=0)]] = Field(
        default_factory=list, description="state indices (0-based) whose errors are angles, "
        "wrapped to (-pi, pi] in every metric (e.g. the phase theta of the sine of the "
        "missing-measurements thesis, which "
        "a measurement of sin(theta) cannot tell from theta + 2 pi)", json_schema_extra=unit(
            "index"))
    true_class: Literal[tuple(CLASSES)] | None = Field(  # type: ignore[valid-type]
        None, description="the target's class, for the filters that classify (JTC, "
        "MultiFilterJTC): the report gives the probability they put on it against time and "
        "the runs that end above 0.9", json_schema_extra=unit("class name"))
    after_gap_s: NonNegFloat = Field(1.0, description="with [gaps]: the window after each "
                                     "gap over which the recovery's RMSE is reported (the "
                                     "round(after_gap_s / step_s) measurements that follow "
                                     "the gap's last missing one, themselves not missing)")

    @field_validator("windows")
    @classmethod
    def _windows_ordered(cls, windows: dict[str, list[float]]) -> dict[str, list[float]]:
        for name, span in windows.items():
            if not WINDOW_NAME.fullmatch(name):
                raise_at((name,), name, f"report.windows has a window named {name!r}; "
                         "expected a name of letters, digits, '_' and '-', starting with a "
                         "letter (it labels the report's columns)")
            if len(span) != 2:
                raise_at((name,), span, f"report.windows.{name} has {len(span)} values; "
                         "expected 2, [start_s, end_s]")
            a, b = span
            if not a < b:
                raise_at((name,), [a, b], f"report.windows.{name} = [{a:g}, {b:g}]; "
                         "expected [start_s, end_s] with start_s < end_s")
        return windows


class Scenario(Strict):
    """A scenario: the truth, the observers and their sensors, the filters to compare, the
    Monte Carlo runs and the report."""

    name: str = Field(max_length=255, description="the scenario's name; the report goes to "
                      "trackkit-out/NAME, so a plain file name: letters, digits, '.', '_', "
                      "'-', not starting with '.'")
    description: str = Field("", description="one line for `trackkit list` and the report")
    dim: Literal[2, 3] = Field(2, description="2-D ([x, y, vx, vy]) or 3-D ([x, y, z, vx, vy, "
                               "vz]) kinematics")
    time: TimeSpec = Field(description="duration and step")
    target: Target = Field(description="the target's truth")
    observers: list[Observer] = Field(min_length=1, description="the sensor platforms (their "
                                      "measurements are stacked)")
    prior: ScenarioPriorSpec = Field(description="the filters' prior (and the PCRLB's), "
                                     "and how they start (initialiser)")
    filters: list[FilterSpec] = Field(min_length=1, description="the filters compared")
    run: RunSpec = Field(default_factory=RunSpec, description="the Monte Carlo runs")
    report: ReportSpec = Field(default_factory=ReportSpec, description="what the report shows")
    notes: list[str] = Field(default_factory=list, description="notes printed with the "
                             "results (sources, choices, readings of a paper)")
    gaps: GapsSpec | None = Field(None, description="missing measurements for every filter "
                                  "(see `gaps`)")
    sweep: SweepSpec | None = Field(None, description="a parameter sweep for `trackkit sweep` "
                                    "(see `sweep`); `trackkit run` ignores it")

    _plain_name = field_validator("name")(classmethod(lambda cls, v: check_plain_name(v)))

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
        self._check_windows()
        self._check_published(names)
        self._check_initialiser()
        if self.dim == 2 and (self.target.initial.z_m is not None):
            raise ValueError("target.initial.z_m is set but dim = 2")
        if self.linear_system and (self.target.state is None or self.target.legs):
            raise ValueError(f"a target with motion model {self.target.motion.model} needs "
                             "target.state and takes no legs")
        for i, f in enumerate(self.filters):
            self._check_special_filter(i, f)
            if f.motion is not None and f.motion.model == "Linear" and (
                    len(f.motion.F) != n):
                raise ValueError(f"filters[{i}].motion.F is {len(f.motion.F)} x "
                                 f"{len(f.motion.F)}; expected {n} x {n}")
            if f.motion is not None and f.motion.model == "ContinuousLinear" and (
                    len(f.motion.A) != n):
                raise ValueError(f"filters[{i}].motion.A is {len(f.motion.A)} x "
                                 f"{len(f.motion.A)}; expected {n} x {n}")
            kappa = f.options.get("kappa")
            if f.type == "UKF" and kappa is not None and not kappa > -n:
                # lambda = alpha^2 (n + kappa) - n: the sigma points need n + lambda > 0
                raise_at(("filters", i, "options", "kappa"), kappa,
                         f"filter {f.name!r} (UKF): expected a number > -n = {-n} (n = {n}, "
                         "the state length), so that n + lambda = alpha^2 (n + kappa) > 0")
        self._check_gaps()
        for j, i in enumerate(self.report.angle_states):
            if i >= n:
                raise_at(("report", "angle_states", j), i, f"report.angle_states has {i}; "
                         f"expected state indices 0 .. {n - 1}")
        platforms = [("target", self.target.legs)] + [
            (f"observers[{i}]", o.legs) for i, o in enumerate(self.observers)]
        for where, legs in platforms:
            for j, leg in enumerate(legs):
                if leg.velocity_mps is not None and len(leg.velocity_mps) != self.dim:
                    raise ValueError(f"{where}.legs[{j}].velocity_mps has "
                                     f"{len(leg.velocity_mps)} components; expected "
                                     f"{self.dim} (dim)")
        if self.linear_system:
            # a full state follows trackkit's state ordering: with at least 2 dim components its
            # head is [positions, velocities] (a CWPA's [x, y, vx, vy, ax, ay])
            allowed = {f"x{i}" for i in range(1, n + 1)}
            if n >= 2 * self.dim:
                allowed |= {"position", "velocity", "speed", "course", "bearing", "x", "y",
                            "z", "vx", "vy", "vz"}
            bad = [g for g in self.report.groups if g not in allowed]
            if bad:
                raise ValueError(
                    f"report.groups has {bad}; a {self.target.motion.model} target's state "
                    f"of {n} components has positions and velocities only when it has at "
                    f"least 2 dim = {2 * self.dim} (positions, velocities, then the rest), "
                    f"so expected groups among {sorted(allowed)}")
        for i, o in enumerate(self.observers):
            sine_n = 3 if o.sensor.amplitude else 2
            if o.sensor.model == "Sine" and not (self.linear_system and n == sine_n):
                what = ("a sin(theta) of the state [theta, omega, a]" if o.sensor.amplitude
                        else "sin(theta) of the state [theta, omega] (amplitude = false)")
                raise ValueError(f"observers[{i}].sensor is Sine, which measures {what}; "
                                 "expected a target with motion Linear or ContinuousLinear and "
                                 f"a {sine_n}-component target.state, not "
                                 f"{self.target.motion.model} with {n} components")
            r = o.sensor.r_diag_si
            if (o.sensor.model == "Position" and r is not None and not self.linear_system
                    and len(r) != self.dim):
                raise ValueError(f"observers[{i}].sensor.r_diag_si has {len(r)} values; a "
                                 f"Position sensor measures the {self.dim} position "
                                 "components (dim)")
        return self

    def _check_special_filter(self, i: int, f: FilterSpec) -> None:
        """A constant-gain tracker measures positions (one Position sensor) and carries 2 or
        3 blocks of dim; an IMM's union state holds the scenario's state and extra_std
        gives the rest."""
        n, dim = self.state_dim, self.dim
        who = f"filters[{i}] {f.name!r} ({f.type})"
        if f.type in CLASS_TYPES and (dim != 2 or n != 4):
            raise ValueError(f"{who}: the scenario's state has {n} components (dim = {dim}); "
                             "a classifying particle filter moves [x, y, vx, vy] by its "
                             "classes' modes, so expected dim = 2 and no extras")
        if f.type in CLASS_TYPES and f.gaps is not None:
            raise ValueError(f"{who}: gaps = {{handler = {f.gaps.handler!r}}}; a classifying "
                             "particle filter takes no gap handler (it coasts through a "
                             "missing plot by itself); expected no gaps table")
        blocks = CONSTANT_GAIN_TYPES.get(f.type)
        if blocks is not None:
            sensors = [o.sensor.model for o in self.observers]
            r = self.observers[0].sensor.r_diag_si
            if sensors != ["Position"] or (r is not None and len(r) != dim):
                raise ValueError(f"{who}: the sensors are {sensors}; a constant-gain tracker "
                                 f"measures the {dim} position components, so expected one "
                                 "observer with a Position sensor of dim channels")
            if n != blocks * dim:
                what = "[x, y, vx, vy]" if blocks == 2 else "[x, y, vx, vy, ax, ay]"
                raise ValueError(f"{who}: the scenario's state has {n} components; expected "
                                 f"{blocks * dim} = {blocks} x dim ({what} for dim = 2)")
            motion = f.motion or self.target.motion
            allowed = (("ConstantVelocity",) if blocks == 2 else
                       ("ConstantAcceleration", "Linear", "ContinuousLinear"))
            if blocks == 2 and self.linear_system and f.motion is None:
                allowed = (motion.model,)  # the run checks its transition is the CV one
            if motion.model not in allowed:
                raise ValueError(f"{who}: motion {motion.model}; the tracker predicts with "
                                 f"its own transition, so expected a motion among {allowed} "
                                 "(whose Q it adds to P)")
        if f.imm is not None:
            for j, m in enumerate(f.imm.models):
                if m.motion.model == "CoordinatedTurn" and dim != 2:
                    raise ValueError(f"{who}: imm.models[{j}] is CoordinatedTurn, which is "
                                     f"2-D; the scenario has dim = {dim}")
            u = f.imm.union_dim(dim)
            if u - n != len(f.imm.extra_std):
                raise ValueError(
                    f"{who}: the IMM's union state has {u} components and the scenario's "
                    f"{n}; expected imm.extra_std with {u - n} values (the prior of the "
                    f"components after the first {n}), got {len(f.imm.extra_std)}"
                    if u >= n else
                    f"{who}: the IMM's union state has {u} components, fewer than the "
                    f"scenario's {n}; expected models whose largest state holds the "
                    "scenario's")

    def _check_published(self, names: list[str]) -> None:
        """A published table names filters of this scenario."""
        for i, pub in enumerate(self.report.published):
            unknown = sorted(set(pub.rmse) - set(names))
            if unknown:
                raise_at(("report", "published", i, "rmse"), unknown,
                         f"report.published.{i}.rmse names {unknown}, which are not filters "
                         f"of this scenario; expected names among {names}")

    def _check_windows(self) -> None:
        """Every error window ends within the scenario and holds a measurement time."""
        T, dt, end = self.time.steps, self.time.step_s, self.time.duration_s
        for name, (a, b) in self.report.windows.items():
            if b > end * (1 + 1e-12):
                raise_at(("report", "windows", name), [a, b],
                         f"report.windows.{name} = [{a:g}, {b:g}] ends after the scenario "
                         f"(duration_s = {end:g}); expected 0 <= start_s < end_s <= {end:g}")
            k0, k1 = window_steps(a, b, T, dt)
            if k1 <= k0:
                raise_at(("report", "windows", name), [a, b],
                         f"report.windows.{name} = [{a:g}, {b:g}] holds no measurement time "
                         f"(t = {dt:g} .. {T * dt:g} s, every {dt:g} s); expected start_s "
                         "<= t < end_s for at least one")

    def _check_initialiser(self) -> None:
        """The GA initialiser needs a Doppler-bearing problem and owns every filter's start."""
        if self.prior.initialiser != "ga":
            return
        ga = self.prior.ga_settings
        sensors = [o.sensor.model for o in self.observers]
        if (self.dim != 2 or self.linear_system or len(self.target.extras) != 1
                or sensors != ["BearingFrequency"]):
            raise_at(("prior", "initialiser"), "ga",
                     f"prior.initialiser = \"ga\" searches the initial position of a "
                     "Doppler-bearing target; expected dim = 2, the state [x, y, vx, vy, f0] "
                     "(one target.extras) and one observer with a BearingFrequency sensor, "
                     f"got dim = {self.dim}, {self.state_dim} state components and sensors "
                     f"{sensors}")
        if ga.measurements > self.time.steps:
            raise_at(("prior", "ga", "measurements"), ga.measurements,
                     f"prior.ga.measurements = {ga.measurements}; the scenario has "
                     f"{self.time.steps} measurements, so expected at most {self.time.steps}")
        for i, f in enumerate(self.filters):
            if f.prior is not None:
                raise_at(("filters", i, "prior"), "...",
                         f"filter {f.name!r} has its own prior, but prior.initialiser = "
                         "\"ga\" starts every filter from the GA estimate; expected no "
                         "filters[].prior (or initialiser = \"draw\")")

    def _check_gaps(self) -> None:
        """Every gap interval lies within the scenario's measurements, and a sine fit has
        a one-channel sensor."""
        T = self.time.steps
        if self.gaps is not None:
            for i, (a, b) in enumerate(self.gaps.samples):
                if b > T - 1:
                    raise_at(("gaps", "samples", i), [a, b], f"gaps.samples[{i}] = [{a}, {b}]; "
                             f"expected 0 <= first <= last <= {T - 1} (the last measurement "
                             "index)")
            for i, (a, c) in enumerate(self.gaps.counts):
                if a + c - 1 > T - 1:
                    raise_at(("gaps", "counts", i), [a, c], f"gaps.counts[{i}] = [{a}, {c}] "
                             f"reaches index {a + c - 1}; expected start + count - 1 <= {T - 1} "
                             "(the last measurement index)")
            for i, (a, b) in enumerate(self.gaps.time_s):
                try:
                    self.gaps.model_copy(update={"time_s": [(a, b)], "samples": [],
                                                 "counts": []}).mask(T, self.time.step_s)
                except ValueError:
                    raise_at(("gaps", "time_s", i), [a, b], f"gaps.time_s[{i}] = [{a}, {b}] "
                             f"holds no measurement time (t = {self.time.step_s:g} .. "
                             f"{T * self.time.step_s:g} s, every {self.time.step_s:g} s); "
                             "expected start_s <= t < stop_s for at least one")
        dim_z = sum(channels(o.sensor, self.dim) for o in self.observers)
        for i, f in enumerate(self.filters):
            g = f.gaps
            if g is not None and g.function == "sine" and dim_z != 1:
                raise_at(("filters", i, "gaps", "function"), "sine",
                         f"filter {f.name!r}: the sine fit needs a sensor of one channel; "
                         f"the scenario measures {dim_z}")

    @property
    def linear_system(self) -> bool:
        """The target follows a ``Linear`` or ``ContinuousLinear`` model: its full state is
        given (``target.state``), not built from [pos, vel] and extras."""
        return self.target.motion.model in ("Linear", "ContinuousLinear")

    @property
    def state_dim(self) -> int:
        if self.linear_system:
            m = self.target.motion
            return len(m.F if m.model == "Linear" else m.A)
        return 2 * self.dim + len(self.target.extras)


#: the measurement channels of each sensor model but Position (whose count is its dimension)
CHANNELS = {
    "Bearing": ["bearing"],
    "RangeBearing": ["range", "bearing"],
    "AzimuthElevation": ["bearing", "elevation"],
    "BearingFrequency": ["bearing", "frequency"],
    "MultipathDelay": ["delay", "delay"],
    "Sine": ["signal"],
}


def channels(spec: SensorSpec, dim: int) -> int:
    """Number of measurement channels of the sensor."""
    if spec.model == "Position":
        return len(spec.r_diag_si) if spec.r_diag_si is not None else dim
    return len(CHANNELS[spec.model])
