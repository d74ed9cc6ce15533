"""The trial programme that generates identification data for the vessel model of Zolfagharnasab and
Seif (2025).

A sea-trial identification programme is a sequence of separate trials, each started on a
straight course at the steady speed of its engine setting, recorded at ``dt`` and joined into
one record. ``DEFAULT_PROGRAMME`` (our choice; the paper gives none) is, at dt = 1 s::

    acceleration    rpm 1000 -> 2000 at t = 10 s, zero nozzle                60 s
    zigzag_20       20/20 zig-zag to starboard first, 2000 rpm, 9 commands  120 s
    zigzag_20_1500  20/20 zig-zag to port first, 1500 rpm, 9 commands       120 s
    turn_port       20 deg turning circle to port, 2000 rpm                  90 s
    deceleration    rpm 2000 -> 1200 at t = 10 s, zero nozzle                60 s
    zigzag_10       10/10 zig-zag to starboard first, 2000 rpm, 9 commands  110 s
    turn_starboard  20 deg turning circle to starboard, 2000 rpm             90 s

657 samples (each trial has ``duration / dt + 1``). The zig-zags and turns excite sway and
yaw; the rpm changes are what separates the surge terms ``a1 u^2, a8 u n, a9 n^2`` (at a
constant engine speed their regressors are nearly proportional), and the second zig-zag at
1500 rpm puts the turning data at a second speed. A zig-zag of fixed duration holds its last
command after the ninth; the durations are chosen so that this lasts only a few seconds.

Each trial is a fresh ``trackkit.sim.seatrials`` run from ``[speed, 0, 0]`` at the origin,
heading north, so the body state jumps at a join: ``starts[k]`` marks the first sample of a
trial, and the identifiers do not model the transition into it (the augmented filters
re-initialise the body states there, least squares drops the pair). The pose restarts at
each trial's origin.

Truth: ``substeps`` forward-Euler sub-steps per sample. ``substeps=1`` is exactly the
identifiers' discrete model (paper eq. 4, Euler with the mean input ``s_m``), the unbiased
case; the default 10 is close to the continuous model (the realistic case: an Euler
identifier at dt = 1 s then carries a discretisation bias, since the yaw time constant is
only about 1.7 s at 18 kn).

Measurements, per sample (our choice of realistic levels, all white and independent):

* body states ``z = [u, v, r] + e``: 0.05 m/s on u and v and 0.1 deg/s on r, what a GPS/INS
  pre-processing gives (Doppler GNSS velocity 0.05 m/s, rotated to the body frame with a
  0.2 deg heading; a MEMS/FOG rate gyro after the INS's filtering);
* GPS positions ``[east, north]``: 2.5 m per axis (a single-frequency receiver without SBAS);
* heading ``psi``: 0.2 deg (a dual-antenna GNSS compass or FOG gyrocompass).

Runs are batch rows. Run ``r`` with master seed ``s`` draws its measurement noise from
``SeedSequence(s, spawn_key=(r, 0))`` (in the order body noise (K, 3), GPS (K, 2), heading
(K), every draw made whatever its sigma) and the process noise of trial i (when ``q`` is
given) from ``SeedSequence(s, spawn_key=(r, 1, i))``: a run depends on ``(seed, r)`` alone,
so a block of runs is the same whatever the other runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.models.manoeuvring import N_THETA, CoefficientSet, reference_vessel
from trackkit.renamed import renamed_keywords
from trackkit.sim import seatrials

__all__ = [
    "TrialSpec",
    "Segment",
    "NoiseLevels",
    "Record",
    "DEFAULT_PROGRAMME",
    "DEFAULT_NOISE",
    "programme",
    "run_seed",
]

Array = NDArray[np.float64]


class TrialSpec(NamedTuple):
    """One trial of a programme: ``kind`` is ``"zigzag"``, ``"turn"`` or ``"acceleration"``
    and ``params`` the keyword arguments of the matching ``trackkit.sim.seatrials`` function
    (SI: rad, rpm, s), without theta, norm, T, substeps, q or rng."""

    name: str
    kind: str
    params: dict


class Segment(NamedTuple):
    """Samples ``start:stop`` of a record belong to trial ``name``."""

    name: str
    start: int
    stop: int


class NoiseLevels(NamedTuple):
    """Measurement noise standard deviations (SI): ``body`` (3,) on ``[u, v, r]`` (m/s, m/s,
    rad/s), ``gps`` per horizontal axis (m), ``heading`` (rad)."""

    body: Array
    gps: float
    heading: float


_DEG = math.pi / 180.0

#: The default trial programme: an acceleration run, zigzags 20/20 at 2000 and 1500 rpm, a
#: port turning circle, a deceleration run, a zigzag 10/10 and a starboard turning circle.
DEFAULT_PROGRAMME: tuple[TrialSpec, ...] = (
    TrialSpec("acceleration", "acceleration",
              {"rpm_start": 1000.0, "rpm_end": 2000.0, "t_step": 10.0, "duration": 60.0}),
    TrialSpec("zigzag_20", "zigzag", {"delta": 20 * _DEG, "alpha": 20 * _DEG, "rpm": 2000.0,
                                      "commands": 9, "duration": 120.0}),
    TrialSpec("zigzag_20_1500", "zigzag",
              {"delta": 20 * _DEG, "alpha": 20 * _DEG, "rpm": 1500.0, "side": -1.0,
               "commands": 9, "duration": 120.0}),
    TrialSpec("turn_port", "turn",
              {"delta": 20 * _DEG, "rpm": 2000.0, "side": -1.0, "duration": 90.0}),
    TrialSpec("deceleration", "acceleration",
              {"rpm_start": 2000.0, "rpm_end": 1200.0, "t_step": 10.0, "duration": 60.0}),
    TrialSpec("zigzag_10", "zigzag", {"delta": 10 * _DEG, "alpha": 10 * _DEG, "rpm": 2000.0,
                                      "commands": 9, "duration": 110.0}),
    TrialSpec("turn_starboard", "turn",
              {"delta": 20 * _DEG, "rpm": 2000.0, "side": 1.0, "duration": 90.0}),
)

#: The default measurement noise: 0.05 m/s on u and v, 0.1 deg/s on r, 2.5 m of GPS per
#: axis and 0.2 deg of heading.
DEFAULT_NOISE = NoiseLevels(body=np.array([0.05, 0.05, 0.1 * _DEG]), gps=2.5,
                            heading=0.2 * _DEG)

_KINDS = {"zigzag": seatrials.zigzag, "turn": seatrials.turning_circle,
          "acceleration": seatrials.acceleration_run}


class Record(NamedTuple):
    """Identification data of ``R`` runs and ``K`` samples at period ``dt`` (SI throughout).

    ``t (K,)`` s from the programme start; ``s (R, K, 2)`` the applied inputs ``[delta, n]``
    (rad, rpm); ``x (R, K, 3)`` the true and ``z (R, K, 3)`` the measured ``[u, v, r]``;
    ``pose (R, K, 3)`` the true ``[east, north, psi]`` (m, m, rad clockwise from north,
    restarting at each trial's origin); ``gps (R, K, 2)`` the measured east and north,
    ``heading (R, K)`` the measured psi; ``starts (K,)`` True at each trial's first sample;
    ``segments`` the trials; ``theta`` and ``norm`` the truth's coefficients; ``noise`` the
    measurement standard deviations; ``substeps`` the truth's Euler sub-steps per sample."""

    t: Array
    dt: float
    s: Array
    x: Array
    z: Array
    pose: Array
    gps: Array
    heading: Array
    starts: Array
    segments: tuple[Segment, ...]
    truth: CoefficientSet
    noise: NoiseLevels
    substeps: int

    def segment(self, name: str) -> slice:
        """The samples of trial ``name``."""
        for seg in self.segments:
            if seg.name == name:
                return slice(seg.start, seg.stop)
        raise KeyError(f"segment {name!r} not in {[s.name for s in self.segments]}")


def run_seed(seed: int, run: int, *key: int) -> np.random.Generator:
    """The generator of ``SeedSequence(seed, spawn_key=(run, *key))``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(run), *key)))


def _runs(runs: int | Sequence[int]) -> list[int]:
    if isinstance(runs, int | np.integer):
        if runs < 1:
            raise ValueError(f"runs = {runs!r}; expected a number of runs >= 1 or run indices")
        return list(range(int(runs)))
    out = [int(r) for r in runs]
    if not out or min(out) < 0:
        raise ValueError(f"runs = {runs!r}; expected a non-empty sequence of run indices >= 0")
    return out


def _noise(noise: NoiseLevels) -> NoiseLevels:
    body = np.asarray(noise.body, dtype=float)
    body = np.broadcast_to(body, (3,)).copy() if body.ndim == 0 else body
    gps, heading = float(noise.gps), float(noise.heading)
    if body.shape != (3,) or not np.all(np.isfinite(body)) or np.any(body < 0):
        raise ValueError(f"noise.body = {np.asarray(noise.body).tolist()!r}; expected 3 "
                         "standard deviations >= 0 (m/s, m/s, rad/s)")
    for name, v in (("gps", gps), ("heading", heading)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"noise.{name} = {v!r}; expected a standard deviation >= 0")
    return NoiseLevels(body, gps, heading)


@renamed_keywords(T="dt")
def programme(runs: int | Sequence[int], seed: int, *,
              trials: Sequence[TrialSpec] = DEFAULT_PROGRAMME,
              truth: CoefficientSet | None = None, dt: float = 1.0, substeps: int = 10,
              noise: NoiseLevels = DEFAULT_NOISE, q: ArrayLike | None = None) -> Record:
    """Simulate the trial programme ``trials`` of the vessel ``truth`` (default
    ``reference_vessel()``) for ``runs`` (a count, or run indices for a block) and join it
    into one ``Record``: ``z = x + e``, ``e ~ N(0, diag(noise.body^2))`` per sample, with
    GPS positions and heading measured likewise. ``q`` (3, m^2/s^3, m^2/s^3, rad^2/s^3) adds
    process noise to the truth (``seatrials``' white-noise densities); without it every
    run's truth is the same and is simulated once."""
    run_ids = _runs(runs)
    truth = reference_vessel() if truth is None else truth
    if not isinstance(truth, CoefficientSet) or np.shape(truth.theta) != (N_THETA,):
        raise ValueError(f"truth = {truth!r}; expected a CoefficientSet with one theta (16,)")
    noise = _noise(noise)
    if not trials:
        raise ValueError("trials is empty; expected at least one TrialSpec")
    R = len(run_ids)
    parts, segments, k0 = [], [], 0
    for i, spec in enumerate(trials):
        if spec.kind not in _KINDS:
            raise ValueError(f"trials[{i}].kind = {spec.kind!r}; expected one of "
                             f"{sorted(_KINDS)}")
        if q is None:
            kw = {}
        else:
            kw = {"q": q, "rng": [run_seed(seed, r, 1, i) for r in run_ids],
                  "psi0": np.zeros(R)}  # psi0 gives the batch its run axis
        tr = _KINDS[spec.kind](truth.theta, truth.norm, dt=dt, substeps=substeps,
                               **spec.params, **kw)
        K = tr.t.size
        parts.append(tr)
        segments.append(Segment(spec.name, k0, k0 + K))
        k0 += K
    K = k0

    def cat(*fields: str) -> Array:
        a = np.concatenate([np.stack([getattr(p, f) for f in fields], -1) for p in parts], -2)
        return np.broadcast_to(a, (R, K, len(fields))).copy()

    s, x, pose = cat("delta", "n"), cat("u", "v", "r"), cat("east", "north", "psi")
    starts = np.zeros(K, bool)
    starts[[seg.start for seg in segments]] = True
    e = np.empty((R, K, 3))
    g = np.empty((R, K, 2))
    h = np.empty((R, K))
    for j, r in enumerate(run_ids):  # the draws of each run from its own generator
        rng = run_seed(seed, r, 0)
        e[j], g[j], h[j] = (rng.standard_normal((K, 3)), rng.standard_normal((K, 2)),
                            rng.standard_normal(K))
    return Record(t=dt * np.arange(K), dt=float(dt), s=s, x=x, z=x + noise.body * e, pose=pose,
                  gps=pose[..., :2] + noise.gps * g, heading=pose[..., 2] + noise.heading * h,
                  starts=starts, segments=tuple(segments), truth=truth, noise=noise,
                  substeps=int(substeps))
