"""Multi-target scenarios: a bundled radar scene, the trackers to compare, the Monte Carlo
runs and the report settings, as a TOML file validated with pydantic .

    sc = load_multitarget("radar-crossing")       # bundled by name, or a path to a .toml file
    scene, trackers = build(sc)                   # trackkit.sim.scene.Scene, {name: Tracker}

The file (units in the field names as in the single-target schema; ``q`` in m^2/s^3)::

    name = "radar-crossing"
    description = "three craft whose paths cross and run close"
    notes = ["..."]

    [scene]
    builder = "radar_crossing"     # radar_crossing, radar_clutter or radar_dense
    pd = 0.9                       # detection probability
    clutter_per_scan = 20.0        # mean false plots per scan (Poisson)
    q = 1e-4                       # the targets' process noise
    # n = 200                      # number of targets (radar_dense only)

    [[trackers]]
    name = "GNN"
    filter = "EKF"                 # KF (position radars only), EKF, UKF, CKF
    q = 1.0                        # the tracker's constant-velocity model
    associator = "GNN"             # or "JPDA"
    cost = "loglik"                # GNN only: loglik, distance, saturating
    # missed_distance = 10.0       # cost "distance" only: a miss's cost and the gate
    logic = "score"                # SPRT score (alpha, beta, new_target_density) or
    alpha = 0.01                   # "history" (confirm = [M, N], delete = [P, R])
    beta = 0.001
    new_target_density = 4e-7
    initiator = "single"           # single (v_std_mps) or "two-point" (v_max_mps, margin_m)
    v_std_mps = 100.0
    p_gate = 0.99

    [run]
    runs = 100
    seed = 2026
    block = 10

    [report]
    c_m = 500.0                    # OSPA and GOSPA cut-off (and the truth-track assignment's)
    ospa_p = 1.0                   # OSPA order (GOSPA: p = 2, alpha = 2)
    confirm_within_scans = 5       # "confirmed within N scans" of a target's birth

The tracker's ``pd`` and ``clutter_density`` default to the scene's (the tracker knows the
radar); a field that belongs to another kind (``cost`` with JPDA, ``confirm`` with the score
logic, ``v_max_mps`` with single-point initiation, ``n`` with a builder other than
radar_dense) is an error, not silently ignored. Messages name the field and the value, as
``trackkit.scenario.load``'s do.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from trackkit.scenario import (
    Missing,
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
    "BUILDERS",
    "MultiTargetScenario",
    "ReportSpec",
    "RunSpec",
    "SceneSpec",
    "TrackerSpec",
    "build",
    "bundled_multitarget",
    "is_multitarget",
    "load_multitarget",
    "parse_multitarget",
]

#: The scene builders a multi-target scenario's ``builder`` may name.
BUILDERS = ("radar_crossing", "radar_clutter", "radar_dense")
_MAX_WINDOW = 64  # the history logic's longest window (trackkit.tracking.logic)

Probability = Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)]
OpenProbability = Annotated[float, Field(gt=0, lt=1, allow_inf_nan=False)]


class SceneSpec(Strict):
    """The simulated scene: one of the bundled builders of ``trackkit.sim.scene`` with
    its detection probability, clutter and the targets' process noise."""

    builder: Literal["radar_crossing", "radar_clutter", "radar_dense"] = Field(
        description="radar_crossing: three craft that cross and run close (one radar, 3 s "
        "scans); radar_clutter: ten aircraft through an air surveillance radar's coverage "
        "(4 s scans); radar_dense: n targets over the same radar's coverage, for scale")
    pd: Probability = Field(0.9, description="probability that a target in view is "
                            "detected at a scan", json_schema_extra=unit("1"))
    clutter_per_scan: NonNegFloat = Field(20.0, description="mean number of false plots per "
                                          "scan (Poisson, uniform in the field of view)",
                                          json_schema_extra=unit("plots"))
    q: NonNegFloat = Field(description="the targets' process noise: spectral density of a "
                           "white acceleration per axis", json_schema_extra=unit("m^2/s^3"))
    n: Annotated[int, Field(ge=1)] | None = Field(None, description="number of targets "
                                                  "(radar_dense only; default 200)")

    @model_validator(mode="after")
    def _n_for_dense(self) -> SceneSpec:
        if self.n is not None and self.builder != "radar_dense":
            raise_at(("n",), self.n, f"n is for builder radar_dense only, not "
                     f"{self.builder!r} (its targets are fixed)")
        return self


class TrackerSpec(Strict):
    """One tracker to compare: filter and constant-velocity model, associator, track logic,
    initiator and gate (``trackkit.tracking.Tracker``)."""

    name: str = Field(min_length=1, description="the tracker's name in tables and plots "
                      "(unique in the scenario)")
    filter: Literal["KF", "EKF", "UKF", "CKF"] = Field(
        "EKF", description="the filter (KF needs a linear, position radar)")
    q: NonNegFloat = Field(description="process noise of the tracker's constant-velocity "
                           "model: spectral density of a white acceleration per axis",
                           json_schema_extra=unit("m^2/s^3"))
    associator: Literal["GNN", "JPDA"] = Field(description="global nearest neighbour or "
                                               "joint probabilistic data association")
    cost: Literal["loglik", "distance", "saturating"] | None = Field(
        None, description="GNN only: the assignment cost (default loglik: negative "
        "log-likelihood ratio; distance: Mahalanobis; saturating: K1 (1 - exp(-K2 d^2)), "
        "Jalalipoor and Kardehi Moghaddam 2021)")
    missed_distance: PositiveFloat | None = Field(
        None, description="GNN with cost distance only: the Mahalanobis distance a missed "
        "detection costs, which is also the gate (default: the gate's edge, "
        "sqrt(chi2.ppf(p_gate)))", json_schema_extra=unit("1"))
    star: bool | None = Field(None, description="JPDA only: JPDA* (prune the joint events "
                              "that a swap of two tracks' detections would make more likely, "
                              "against track coalescence; default false)")
    logic: Literal["score", "history"] = Field("score", description="track confirmation "
                                               "and deletion: SPRT score or M-of-N history")
    alpha: OpenProbability | None = Field(None, description="score logic: probability of "
                                          "confirming a false track (SPRT; default 0.01)",
                                          json_schema_extra=unit("1"))
    beta: OpenProbability | None = Field(None, description="score logic: probability of "
                                         "deleting a true track (SPRT; default 0.001)",
                                         json_schema_extra=unit("1"))
    new_target_density: PositiveFloat | None = Field(
        None, description="score logic: density of new targets per unit of measurement space "
        "per scan (default 4e-7)", json_schema_extra=unit("1/(m rad) per scan"))
    confirm: list[int] | None = Field(None, description="history logic: [M, N], confirm on "
                                      "M hits in the last N scans (default [2, 3])")
    delete: list[int] | None = Field(None, description="history logic: [P, R], delete a "
                                     "confirmed track on P misses in the last R scans "
                                     "(default [3, 3])")
    initiator: Literal["single", "two-point"] = Field(
        "single", description="a tentative track from every unassigned plot (single) or from "
        "two plots of consecutive scans (two-point)")
    v_std_mps: PositiveFloat | None = Field(None, description="single: the new track's "
                                            "velocity standard deviation per axis "
                                            "(default 100)")
    v_max_mps: PositiveFloat | None = Field(None, description="two-point: the largest target "
                                            "speed (default 300)")
    margin_m: NonNegFloat | None = Field(None, description="two-point: extra distance allowed "
                                         "between the two plots (default 0)")
    p_gate: OpenProbability = Field(0.99, description="gate probability (the ellipsoidal "
                                    "gate's chi-square quantile)", json_schema_extra=unit("1"))
    pd: Probability | None = Field(None, description="the detection probability the tracker "
                                   "assumes (default: the scene's)", json_schema_extra=unit("1"))
    clutter_density: PositiveFloat | None = Field(
        None, description="the clutter density the tracker assumes, false plots per unit of "
        "measurement space per scan (default: the scene's; required when the scene has no "
        "clutter)", json_schema_extra=unit("1/(m rad) per scan"))

    @field_validator("cost", mode="before")
    @classmethod
    def _renamed_cost(cls, v: object) -> object:
        if v == "seed004":
            raise ValueError("cost 'seed004' is now spelled 'saturating'")
        return v

    @field_validator("confirm", "delete")
    @classmethod
    def _window(cls, v: list[int] | None, info) -> list[int] | None:
        if v is None:
            return v
        what = "M, N" if info.field_name == "confirm" else "P, R"
        if len(v) != 2 or not 1 <= v[0] <= v[1] <= _MAX_WINDOW:
            raise ValueError(f"expected [{what}], two integers with 1 <= {what[0]} <= "
                             f"{what[-1]} <= {_MAX_WINDOW}")
        return v

    @model_validator(mode="after")
    def _fields_of_kind(self) -> TrackerSpec:
        own = {"cost": self.associator == "GNN", "star": self.associator == "JPDA",
               "missed_distance": self.associator == "GNN" and self.cost == "distance",
               "alpha": self.logic == "score", "beta": self.logic == "score",
               "new_target_density": self.logic == "score",
               "confirm": self.logic == "history", "delete": self.logic == "history",
               "v_std_mps": self.initiator == "single",
               "v_max_mps": self.initiator == "two-point",
               "margin_m": self.initiator == "two-point"}
        kind = {"cost": f"associator {self.associator!r}",
                "missed_distance": (f"cost {self.gnn_cost!r}" if self.associator == "GNN"
                                    else f"associator {self.associator!r}"),
                "star": f"associator {self.associator!r}",
                "alpha": f"logic {self.logic!r}", "beta": f"logic {self.logic!r}",
                "new_target_density": f"logic {self.logic!r}",
                "confirm": f"logic {self.logic!r}", "delete": f"logic {self.logic!r}",
                "v_std_mps": f"initiator {self.initiator!r}",
                "v_max_mps": f"initiator {self.initiator!r}",
                "margin_m": f"initiator {self.initiator!r}"}
        for name, allowed in own.items():
            value = getattr(self, name)
            if value is not None and not allowed:
                raise_at((name,), value, f"tracker {self.name!r}: {name} does not apply to "
                         f"{kind[name]}")
        return self

    # the settings with their defaults filled in
    @property
    def gnn_cost(self) -> str:
        return self.cost or "loglik"

    @property
    def sprt(self) -> tuple[float, float, float]:
        """(alpha, beta, new_target_density) with defaults."""
        return (self.alpha if self.alpha is not None else 1e-2,
                self.beta if self.beta is not None else 1e-3,
                self.new_target_density if self.new_target_density is not None else 4e-7)

    @property
    def windows(self) -> tuple[tuple[int, int], tuple[int, int]]:
        """(confirm, delete) of the history logic with defaults."""
        c = tuple(self.confirm) if self.confirm else (2, 3)
        d = tuple(self.delete) if self.delete else (3, 3)
        return c, d  # type: ignore[return-value]


class RunSpec(Strict):
    """The Monte Carlo runs."""

    runs: Annotated[int, Field(ge=1)] = Field(20, description="Monte Carlo runs")
    seed: Annotated[int, Field(ge=0)] = Field(0, description="master seed; run i draws from "
                                              "its own child of SeedSequence(seed)")
    block: Annotated[int, Field(ge=1)] = Field(
        10, description="runs per block: the unit of work (results do not depend on it)")


class ReportSpec(Strict):
    """The metrics' settings."""

    c_m: PositiveFloat = Field(500.0, description="cut-off of OSPA and GOSPA, and of the "
                               "truth-to-track assignment of the track counts")
    ospa_p: Annotated[float, Field(ge=1, allow_inf_nan=False)] = Field(
        1.0, description="order p of OSPA (GOSPA uses p = 2, alpha = 2)",
        json_schema_extra=unit("1"))
    confirm_within_scans: Annotated[float, Field(ge=0, allow_inf_nan=False)] = Field(
        5.0, description="a target counts as confirmed in time if a track is assigned to it "
        "within this many scan periods of its birth", json_schema_extra=unit("scans"))


class MultiTargetScenario(Strict):
    """A multi-target scenario: the scene, the trackers compared, the runs and the report."""

    name: str = Field(max_length=255, description="the scenario's name; the report goes to "
                      "trackkit-out/NAME, so a plain file name: letters, digits, '.', '_', "
                      "'-', not starting with '.'")
    description: str = Field("", description="one line for `trackkit list` and the report")
    scene: SceneSpec = Field(description="the simulated scene")
    trackers: list[TrackerSpec] = Field(min_length=1, description="the trackers compared")
    run: RunSpec = Field(default_factory=RunSpec, description="the Monte Carlo runs")
    report: ReportSpec = Field(default_factory=ReportSpec, description="the metrics' settings")
    notes: list[str] = Field(default_factory=list, description="notes printed with the "
                             "results (choices and their reasons)")

    _plain_name = field_validator("name")(classmethod(lambda cls, v: check_plain_name(v)))

    @model_validator(mode="after")
    def _consistent(self) -> MultiTargetScenario:
        names = [t.name for t in self.trackers]
        for i, name in enumerate(names):
            if name in names[:i]:
                raise_at(("trackers", i, "name"), name, f"tracker names must be unique; got "
                         f"{names}")
        for i, t in enumerate(self.trackers):
            # every bundled builder has one range-bearing radar
            if t.filter == "KF":
                raise_at(("trackers", i, "filter"), t.filter, f"tracker {t.name!r}: KF needs "
                         f"a linear (position) radar; {self.scene.builder}'s radar measures "
                         "range and bearing: use EKF, UKF or CKF")
            if t.clutter_density is None and self.scene.clutter_per_scan == 0:
                raise_at(("trackers", i, "clutter_density"), Missing(), f"tracker {t.name!r}: "
                         "the scene has no clutter (scene.clutter_per_scan = 0), so give the "
                         "clutter density the tracker assumes (> 0, false plots per m rad per "
                         "scan)")
        return self


# ---------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------


def _bundled_dir():
    return resources.files("trackkit.scenario") / "scenes"


def bundled_multitarget() -> dict[str, str]:
    """Bundled multi-target scenario names and their one-line descriptions."""
    return descriptions(_bundled_dir())


def parse_multitarget(data: dict, source: str = "<scenario>") -> MultiTargetScenario:
    """Validate a multi-target scenario given as a dict (e.g. parsed TOML); every problem is
    a ScenarioError naming ``source``, the field, the value and what is expected."""
    return validated(MultiTargetScenario, data, source)


def is_multitarget(name_or_path: str | Path) -> bool:
    """Whether ``name_or_path`` is a bundled multi-target scenario's name, or a TOML file with
    a ``[scene]`` table (a single-target scenario has none). A file that cannot be read or
    parsed is not claimed (the single-target loader then reports its problem)."""
    return holds_table(name_or_path, _bundled_dir(), "scene", dict)


def load_multitarget(name_or_path: str | Path) -> MultiTargetScenario:
    """Load a bundled multi-target scenario by name or a TOML file by path."""
    return parse_multitarget(*read_scenario(name_or_path, _bundled_dir(), "multi-target "))


def build_scene(scenario: MultiTargetScenario):
    """The ``trackkit.sim.scene.Scene`` of ``scenario.scene``."""
    from trackkit.sim import scene as mt

    s = scenario.scene
    kw: dict[str, Any] = {"pd": s.pd, "clutter": s.clutter_per_scan, "q": s.q}
    if s.builder == "radar_dense":
        return mt.radar_dense(200 if s.n is None else s.n, **kw)
    return getattr(mt, s.builder)(**kw)


def build_tracker(spec: TrackerSpec, scene):
    """The ``trackkit.tracking.Tracker`` of one tracker spec on ``scene``."""
    from trackkit import filters
    from trackkit import tracking as tt
    from trackkit.models import ConstantVelocity

    sensors = scene.sensors
    sensor = sensors[0] if len(sensors) == 1 else dict(enumerate(sensors))
    pd = spec.pd if spec.pd is not None else float(scene.radars[0].pd)
    lam = (spec.clutter_density if spec.clutter_density is not None
           else float(max(scene.clutter_density)))
    if spec.associator == "GNN":
        associator = tt.GNN(cost=spec.gnn_cost, missed_distance=spec.missed_distance)
    else:
        associator = tt.JPDA(star=bool(spec.star))
    if spec.logic == "score":
        alpha, beta, beta_nt = spec.sprt
        logic = tt.ScoreLogic.from_sprt(alpha=alpha, beta=beta, pd=pd, clutter_density=lam,
                                        new_target_density=beta_nt)
    else:
        confirm, delete = spec.windows
        logic = tt.HistoryLogic(confirm=confirm, delete=delete)
    if spec.initiator == "single":
        initiator = tt.SinglePoint(v_std=spec.v_std_mps if spec.v_std_mps is not None else 100.0)
    else:
        initiator = tt.TwoPoint(v_max=spec.v_max_mps if spec.v_max_mps is not None else 300.0,
                                margin=spec.margin_m if spec.margin_m is not None else 0.0)
    f = getattr(filters, spec.filter)()
    return tt.Tracker(f, ConstantVelocity(dim=2, q=spec.q), sensor, pd=pd, clutter_density=lam,
                      p_gate=spec.p_gate, associator=associator, logic=logic,
                      initiator=initiator)


def build(scenario: MultiTargetScenario):
    """``(scene, {name: tracker})`` of a multi-target scenario."""
    scene = build_scene(scenario)
    return scene, {t.name: build_tracker(t, scene) for t in scenario.trackers}


def scan_period(scene) -> float:
    """The shortest interval between distinct scan times of ``scene`` (s): the unit of
    ``report.confirm_within_scans``."""
    import numpy as np

    t = np.unique(scene.scan_times()[0])
    gaps = np.diff(t)
    return float(gaps.min()) if gaps.size else math.inf
