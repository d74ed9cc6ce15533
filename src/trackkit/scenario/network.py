"""Network scenarios (Jalalipoor and Kardehi Moghaddam 2021): moving agents with bearing sensors
that track several targets together, the agents' settings, the Monte Carlo runs and the report, as a
TOML file validated with pydantic.

    sc = load_network("net-baseline")        # bundled by name, or a path to a .toml file
    targets = sc.target_states(seed, run)    # (Nt, 4) [x, y, vx, vy] at t = 0 (SI)
    agents = sc.agent_states()               # (A, 4)

The file (units in the field names; angles in degrees, nautical: clockwise from north, as
``trackkit.network.steering``; ranges ``inf`` for unlimited)::

    name = "net-baseline"
    description = "..."
    notes = ["..."]

    [network]
    duration_s = 1000.0        # the run's length
    period_s = 5.0             # every agent executes once per period ...
    jitter_s = 5.0             # ... delayed from the slot's start by U[0, jitter_s)
    q = 0.0                    # the targets' process noise (m^2/s^3)
    loss = 0.0                 # probability that one message delivery is lost

    [[agents]]                 # one table per agent, numbered 1, 2, ... in the report
    x_m = 0.0                  # initial position (east, north)
    y_m = 0.0
    course_deg = 90.0          # initial course
    speed_mps = 10.0           # constant speed
    sigma_deg = 2.0            # bearing standard deviation
    meas_range_m = inf         # measurement range
    comm_range_m = inf         # communication range

    [[targets]]                # fixed initial states ...
    x_m = 7000.0
    y_m = 16000.0
    course_deg = 120.0
    speed_mps = 9.0

    [random_targets]           # ... or drawn afresh in every run (instead of [[targets]])
    count = 4
    x_m = [-5000.0, 25000.0]   # uniform on [lo, hi]
    y_m = [10000.0, 25000.0]
    course_deg = [0.0, 360.0]
    speed_mps = [3.0, 15.0]

    [settings]                 # the agents' program (trackkit.network.agents.AgentSettings)
    steering = true            # course control (false: straight courses)
    combination = "information"  # information, paper, convex or ci
    # q = 1e-4                 # the agents' CV process noise (default: AgentSettings')

    [run]
    runs = 100
    seed = 2026
    central = true             # also run the centralised reference

    [report]
    c_m = 2000.0               # GOSPA cut-off and target-track assignment distance
    first_fraction = 0.2       # "early" RMSE window: the first 20% of the run
    last_fraction = 0.2        # "late" RMSE window: the last 20%
    example_agent = 1          # whose tracks the picture shows
    prior_pos_std_m = 10000.0  # the PCRLB's prior at t = 0, per axis
    prior_vel_std_mps = 30.0

**Random targets.** Run r of a scenario with ``[random_targets]`` draws its targets from
``numpy.random.default_rng(SeedSequence(seed, spawn_key=(r, RANDOM_TARGETS_KEY)))``: for
each target in order, x, y, course and speed, each uniform on its interval (4 draws of
``Generator.uniform`` per target, ``(count, 4)`` in one call). The key differs from the
children the simulator and the agents use (0 to 4), so the draw depends on (seed, r) alone.

A target faster than the agents' initiation assumes (``AgentSettings().v_max``) could never
be started, so it is refused. Messages name the field, the value and what is allowed, as
``trackkit.scenario.load``'s do.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, field_validator, model_validator

from trackkit.scenario import (
    Missing,
    descriptions,
    holds_table,
    read_scenario,
    validated,
)
from trackkit.scenario.schema import (
    Finite,
    NonNegFloat,
    PositiveFloat,
    Strict,
    check_plain_name,
    raise_at,
    unit,
)

__all__ = [
    "RANDOM_TARGETS_KEY",
    "AgentSpec",
    "NetworkReportSpec",
    "NetworkRunSpec",
    "NetworkScenario",
    "NetworkSpec",
    "RandomTargetsSpec",
    "SettingsSpec",
    "TargetSpec",
    "bundled_network",
    "is_network",
    "load_network",
    "parse_network",
]

#: the spawn key's second entry of the random targets' stream (module docstring)
RANDOM_TARGETS_KEY = 16

Array = NDArray[np.float64]
Probability = Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)]
Fraction = Annotated[float, Field(gt=0, le=0.5, allow_inf_nan=False)]


def _velocity(course_deg: float, speed_mps: float) -> tuple[float, float]:
    """(vx, vy) of a nautical course (clockwise from north) and a speed."""
    c = math.radians(course_deg)
    return speed_mps * math.sin(c), speed_mps * math.cos(c)


def _range(v: float) -> float:
    """A range: > 0, ``inf`` for unlimited, never nan."""
    if math.isnan(v) or v <= 0:
        raise ValueError("expected a range > 0 in metres (inf for unlimited)")
    return v


def _v_max() -> float:
    """The fastest target the agents' initiation assumes (``AgentSettings().v_max``, m/s)."""
    from trackkit.network.agents import AgentSettings

    return float(AgentSettings().v_max)


class NetworkSpec(Strict):
    """The run's length, the agents' execution schedule, the targets' motion and the
    channel."""

    duration_s: PositiveFloat = Field(1000.0, description="length of a run",
                                      json_schema_extra=unit("s"))
    period_s: PositiveFloat = Field(5.0, description="execution period: every agent runs "
                                    "its program once per period (the same for all agents)")
    jitter_s: NonNegFloat | None = Field(None, description="each execution is delayed from "
                                         "its period's start by U[0, jitter_s) (0: "
                                         "synchronous agents; default: the period)")
    q: NonNegFloat = Field(0.0, description="the targets' process noise: spectral density of "
                           "a white acceleration per axis (0: straight lines)",
                           json_schema_extra=unit("m^2/s^3"))
    loss: Probability = Field(0.0, description="probability that one message delivery is "
                              "lost", json_schema_extra=unit("1"))

    @model_validator(mode="after")
    def _schedule(self) -> NetworkSpec:
        if self.jitter_s is not None and self.jitter_s > self.period_s:
            raise_at(("jitter_s",), self.jitter_s, f"expected 0 <= jitter_s <= period_s = "
                     f"{self.period_s:g} s (a longer delay could reorder an agent's "
                     "executions)")
        if self.duration_s < self.period_s:
            raise_at(("duration_s",), self.duration_s, f"expected at least one execution "
                     f"period (period_s = {self.period_s:g} s)")
        return self

    @property
    def max_delay_s(self) -> float:
        """The jitter with its default (the period)."""
        return self.period_s if self.jitter_s is None else self.jitter_s


class AgentSpec(Strict):
    """One agent: where it starts, how it moves, what it measures and how far it talks."""

    x_m: Finite = Field(description="initial position, east")
    y_m: Finite = Field(description="initial position, north")
    course_deg: Finite = Field(description="initial course, clockwise from north")
    speed_mps: Annotated[float, Field(ge=0, le=30, allow_inf_nan=False)] = Field(
        description="constant speed (the paper's agents: at most 30 m/s)")
    sigma_deg: Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)] = Field(
        2.0, description="bearing standard deviation (the paper assumes at most 5 degrees, "
        "2 in its simulations)")
    meas_range_m: float = Field(math.inf, description="measurement range (inf: unlimited)",
                                json_schema_extra=unit("m"))
    comm_range_m: float = Field(math.inf, description="communication range (inf: unlimited)",
                                json_schema_extra=unit("m"))

    _ranges = field_validator("meas_range_m", "comm_range_m")(
        classmethod(lambda cls, v: _range(v)))


class TargetSpec(Strict):
    """One constant-velocity target's state at t = 0."""

    x_m: Finite = Field(description="initial position, east")
    y_m: Finite = Field(description="initial position, north")
    course_deg: Finite = Field(description="course, clockwise from north")
    speed_mps: NonNegFloat = Field(description="speed (at most the agents' AgentSettings "
                                   "v_max, 30 m/s)")

    @field_validator("speed_mps")
    @classmethod
    def _not_too_fast(cls, v: float) -> float:
        if v > _v_max():
            raise ValueError(f"expected a speed <= {_v_max():g} m/s (the agents' initiation "
                             "assumes no faster target: AgentSettings.v_max)")
        return v


def _interval(v: list[float]) -> list[float]:
    if len(v) != 2 or not all(math.isfinite(x) for x in v) or v[0] > v[1]:
        raise ValueError("expected [lo, hi], two finite numbers with lo <= hi")
    return v


class RandomTargetsSpec(Strict):
    """Targets drawn afresh in every run (module docstring: the draw)."""

    count: Annotated[int, Field(ge=1, le=100)] = Field(description="number of targets")
    x_m: list[float] = Field(description="[lo, hi] of the initial east position (uniform)")
    y_m: list[float] = Field(description="[lo, hi] of the initial north position (uniform)")
    course_deg: list[float] = Field([0.0, 360.0], description="[lo, hi] of the course "
                                    "(uniform)")
    speed_mps: list[float] = Field(description="[lo, hi] of the speed (uniform)")

    _intervals = field_validator("x_m", "y_m", "course_deg", "speed_mps")(
        classmethod(lambda cls, v: _interval(v)))

    @field_validator("speed_mps")
    @classmethod
    def _speeds(cls, v: list[float]) -> list[float]:
        if v[0] < 0 or v[1] > _v_max():
            raise ValueError(f"expected 0 <= lo <= hi <= {_v_max():g} m/s (the agents' "
                             "initiation assumes no faster target: AgentSettings.v_max)")
        return v


class SettingsSpec(Strict):
    """The agents' program settings exposed here (the rest: ``AgentSettings``' defaults)."""

    steering: bool = Field(True, description="course control (Jalalipoor and Kardehi "
                           "Moghaddam 2021, eqs. 52-64); false: straight courses")
    combination: Literal["information", "paper", "convex", "ci"] = Field(
        "information", description="the diffusion combination rule (information: covariance "
        "intersection with the uniform weights; paper: eqs. 49-50 as printed)")
    q: NonNegFloat | None = Field(None, description="the agents' CV process noise (default: "
                                  "AgentSettings')", json_schema_extra=unit("m^2/s^3"))


class NetworkRunSpec(Strict):
    """The Monte Carlo runs."""

    runs: Annotated[int, Field(ge=1)] = Field(20, description="Monte Carlo runs")
    seed: Annotated[int, Field(ge=0)] = Field(0, description="master seed; run r draws from "
                                              "SeedSequence(seed, spawn_key=(r, ...))")
    central: bool = Field(True, description="also run the centralised reference (one filter "
                          "that receives every agent's bearings)")


class NetworkReportSpec(Strict):
    """The metrics' settings."""

    c_m: PositiveFloat = Field(2000.0, description="cut-off of GOSPA and of the "
                               "target-to-track assignment behind the errors")
    first_fraction: Fraction = Field(0.2, description="the early RMSE window: the first "
                                     "fraction of the run", json_schema_extra=unit("1"))
    last_fraction: Fraction = Field(0.2, description="the late RMSE window: the last "
                                    "fraction of the run", json_schema_extra=unit("1"))
    example_agent: Annotated[int, Field(ge=1)] = Field(1, description="the agent (numbered "
                                                       "from 1) whose tracks the picture "
                                                       "shows")
    prior_pos_std_m: PositiveFloat = Field(10000.0, description="the PCRLB's prior at t = 0: "
                                           "position standard deviation per axis")
    prior_vel_std_mps: PositiveFloat = Field(30.0, description="the PCRLB's prior at t = 0: "
                                             "velocity standard deviation per axis")


class NetworkScenario(Strict):
    """A network scenario: agents, targets, the agents' settings, runs and report."""

    name: str = Field(max_length=255, description="the scenario's name; the report goes to "
                      "trackkit-out/NAME, so a plain file name: letters, digits, '.', '_', "
                      "'-', not starting with '.'")
    description: str = Field("", description="one line for `trackkit list` and the report")
    network: NetworkSpec = Field(default_factory=NetworkSpec, description="schedule, targets' "
                                 "motion, channel")
    agents: list[AgentSpec] = Field(min_length=1, description="the agents")
    targets: list[TargetSpec] | None = Field(None, description="fixed targets (or "
                                             "random_targets)")
    random_targets: RandomTargetsSpec | None = Field(None, description="targets drawn in "
                                                     "every run (or targets)")
    settings: SettingsSpec = Field(default_factory=SettingsSpec, description="the agents' "
                                   "program")
    run: NetworkRunSpec = Field(default_factory=NetworkRunSpec, description="the Monte Carlo "
                                "runs")
    report: NetworkReportSpec = Field(default_factory=NetworkReportSpec,
                                      description="the metrics' settings")
    notes: list[str] = Field(default_factory=list, description="notes printed with the "
                             "results (the invented geometry and why)")

    _plain_name = field_validator("name")(classmethod(lambda cls, v: check_plain_name(v)))

    @model_validator(mode="after")
    def _consistent(self) -> NetworkScenario:
        if self.targets is None and self.random_targets is None:
            raise_at(("targets",), Missing(), "give the targets: [[targets]] tables (fixed) "
                     "or one [random_targets] table (drawn in every run)")
        if self.targets is not None and self.random_targets is not None:
            raise_at(("random_targets",), "{...}", "give either [[targets]] or "
                     "[random_targets], not both")
        if self.targets is not None and not self.targets:
            raise_at(("targets",), [], "expected at least one target")
        if self.report.example_agent > len(self.agents):
            raise_at(("report", "example_agent"), self.report.example_agent,
                     f"expected an agent number from 1 to {len(self.agents)}")
        return self

    # -- SI arrays for trackkit.network.inprocess.run_network --------------------------------------

    @property
    def n_targets(self) -> int:
        return len(self.targets) if self.targets is not None else self.random_targets.count

    def agent_states(self) -> Array:
        """``(A, 4)`` agent states [x, y, vx, vy] at t = 0 (m, m/s)."""
        return np.array([[a.x_m, a.y_m, *_velocity(a.course_deg, a.speed_mps)]
                         for a in self.agents])

    def target_states(self, seed: int, run: int) -> Array:
        """``(Nt, 4)`` target states at t = 0 of run ``run`` (fixed targets: the same in
        every run; random targets: the draw of the module docstring)."""
        if self.targets is not None:
            return np.array([[t.x_m, t.y_m, *_velocity(t.course_deg, t.speed_mps)]
                             for t in self.targets])
        r = self.random_targets
        g = np.random.default_rng(np.random.SeedSequence(seed,
                                                         spawn_key=(run, RANDOM_TARGETS_KEY)))
        lo = np.array([r.x_m[0], r.y_m[0], r.course_deg[0], r.speed_mps[0]])
        hi = np.array([r.x_m[1], r.y_m[1], r.course_deg[1], r.speed_mps[1]])
        u = g.uniform(lo, hi, size=(r.count, 4))
        c = np.deg2rad(u[:, 2])
        return np.stack([u[:, 0], u[:, 1], u[:, 3] * np.sin(c), u[:, 3] * np.cos(c)], axis=1)

    def sigma_rad(self) -> Array:
        return np.deg2rad([a.sigma_deg for a in self.agents])

    def meas_range(self) -> Array:
        return np.array([a.meas_range_m for a in self.agents])

    def comm_range(self) -> Array:
        return np.array([a.comm_range_m for a in self.agents])


# ---------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------


def _bundled_dir():
    return resources.files("trackkit.scenario") / "networks"


def bundled_network() -> dict[str, str]:
    """Bundled network scenario names and their one-line descriptions."""
    return descriptions(_bundled_dir())


def parse_network(data: dict, source: str = "<scenario>") -> NetworkScenario:
    """Validate a network scenario given as a dict (e.g. parsed TOML); every problem is a
    ScenarioError naming ``source``, the field, the value and what is expected."""
    return validated(NetworkScenario, data, source)


def is_network(name_or_path: str | Path) -> bool:
    """Whether ``name_or_path`` is a bundled network scenario's name, or a TOML file with
    ``[[agents]]`` tables (no other kind of scenario has them). A file that cannot be read
    or parsed is not claimed (another loader then reports its problem)."""
    return holds_table(name_or_path, _bundled_dir(), "agents", list)


def load_network(name_or_path: str | Path) -> NetworkScenario:
    """Load a bundled network scenario by name or a TOML file by path."""
    return parse_network(*read_scenario(name_or_path, _bundled_dir(), "network "))
