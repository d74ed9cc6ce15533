"""Zolfagharnasab and Seif (2025): the vessel identification Monte Carlo, a demonstrated sea trial,
the standard trials of an identified model with the IMO criteria, and the identification of a
recorded GPS/INS log.

    sc = load_vessel("vessel-zigzag-20")
    res = run_vessel(sc, runs=10)                  # VesselResult, pure: no files, no printing
    res.filters["ekf"].rel_error                   # (R, 16)
    rec = identify_recorded(measurements, inputs)  # RecordedIdentification (trackkit identify)

**Data.** The truth is the scenario's coefficient set (the reference vessel). With
``identification.data = "programme"`` it sails ``identify.DEFAULT_PROGRAMME`` (seven trials,
joined); with ``"trial"`` the demonstrated trial alone. The measurements are made the way a
sea trial makes them: the simulated GPS fixes (position, SOG, COG) and INS samples (heading,
yaw rate) of ``sim.gnss`` at their own rates, then ``io.navigation.preprocess_sim`` to the
body-frame ``z = [u, v, r]`` on the grid ``t_k = k dt``. Run r draws its sensor noise from
``SeedSequence(seed, spawn_key=(r, 3))`` for the programme and ``(r, 4)`` for the trial (and
its prior guess from ``(r, 2)``, ``identify.initial_guess``), so a run depends on (seed, r)
alone. The programme's joined record is sensed in one pass per run: the sensors sample the
truth between grid times by Hermite interpolation, which is meaningless across a join, but the
grid times fall on samples of every stream (rates that are multiples of 1/dt), and a grid value
is the sample there.

**Per filter** (``ekf``, ``ukf``, ``ckf``: ``identify.identify`` on the augmented state;
``ls``: ``identify.least_squares``), over the runs ``(R,)``:

* ``rel_error = |theta_hat - theta| / |theta|`` per coefficient ``(R, 16)``;
* ``settling``: the first step from which a coefficient stays within ``settle_tol`` of the
  truth (``identify.settling_step``; K when it is outside at the end; filters only);
* ``nees = e^T P^-1 e`` of the 16 coefficients at the end (``identify.coefficient_nees``),
  chi-square with 16 degrees of freedom when the stated covariance is right; ``inside``: the
  fraction of runs within the two-sided 95% band;
* ``body_rmse``: the filtered ``u, v, r`` against the truth, RMS over the samples ``(R, 3)``,
  beside ``noise_rmse``, the measurements' own (the paper's claim: the filter removes noise);
* ``seconds``: wall-clock time of the identification of all runs (for timings.json only).

**The demonstrated trial** (zig-zag or turn, Figs. 8-11). Its GPS/INS record per run; the
shown filter over it (from the identified coefficients and their standard deviations, median
over runs, when identified from the programme); the paper's Fig. 10 is the raw GPS track and
Fig. 11 the filtered one: the filtered ``u, v`` integrated with the measured heading
(``identify.dead_reckon``), placed by the least-squares fit of its start to the GPS fixes
(the mean offset), so no truth is used. The identified model's prediction is driven by the
trial's inputs from the first grid sample's measured pose and body state (``identify.predict``,
the paper's "second test": only the inputs are given). Position errors are against the truth.

**Standard trials** of a model (:func:`model_trials`): a 20 deg starboard turning circle and
10/10 and 20/20 zig-zags at a given speed and engine speed, their metrics
(``eval.manoeuvres``) and ``imo_criteria`` (IMO MSC.137(76), for reference only below 100 m,
and the paper's 2 <= D/L <= 7). IMO's turning test is at the maximum rudder (30 deg for the
reference waterjet); the paper's and this one's is at 20 deg. A model whose straight-line
motion at the approach speed is unstable (an eigenvalue of ``df/dx`` with a positive real
part) is flagged ``stable = False``; its trials are simulated anyway (at most
``max_duration``) and non-finite metrics are nan.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from trackkit.eval.manoeuvres import (
    Criterion,
    TurningMetrics,
    ZigZagMetrics,
    imo_criteria,
    turning_metrics,
    zigzag_metrics,
)
from trackkit.eval.metrics import chi2_ppf
from trackkit.identify import (
    DEFAULT_NOISE,
    DEFAULT_SUBSTEPS,
    METHODS,
    SUBSTEPS_SAMPLED_INPUTS,
    Segment,
    coefficient_nees,
    dead_reckon,
    identify,
    initial_guess,
    least_squares,
    predict,
    programme,
    relative_error,
    run_seed,
    settling_step,
)
from trackkit.io.navigation import BodyMeasurements, MeasuredInputs, inputs_on_grid
from trackkit.models.manoeuvring import (
    N_THETA,
    CoefficientSet,
    Normalisation,
    reference_vessel,
    rhs_jacobian,
)
from trackkit.renamed import renamed_keywords
from trackkit.sim import seatrials

__all__ = [
    "FilterStats",
    "ModelTrials",
    "RecordedIdentification",
    "REL_SD_LIMIT",
    "TrialDemo",
    "VesselResult",
    "identify_recorded",
    "inputs_at_substeps",
    "model_trials",
    "nees_band",
    "run_vessel",
    "stable",
]

Array = NDArray[np.float64]

#: a coefficient whose standard deviation exceeds this fraction of its value is reported as
#: not identified by the data
REL_SD_LIMIT = 0.5
#: the spawn keys' second entry of the sensor noise: the programme's, the trial's
_PROGRAMME_KEY, _TRIAL_KEY = 3, 4
#: the standard trials: nozzle and check angles (rad)
_TURN_DELTA = math.radians(20.0)
_ZZ = {"zigzag10": math.radians(10.0), "zigzag20": math.radians(20.0)}
_MAX_TRIAL_S = 600.0


def nees_band(dof: int = N_THETA, confidence: float = 0.95) -> tuple[float, float]:
    """The two-sided chi-square band of the NEES with ``dof`` degrees of freedom."""
    lo, hi = chi2_ppf([(1 - confidence) / 2, (1 + confidence) / 2], dof)
    return float(lo), float(hi)


# ---------------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class FilterStats:
    """One identifier over R runs and K samples (module docstring). ``history`` and
    ``history_std`` ``(K, 16)`` are run 0's coefficient estimates after each sample (None
    for least squares); ``body (R, K, 3)`` the filtered u, v, r (None for least squares)."""

    name: str
    theta: Array
    theta_std: Array
    cov: Array
    history: Array | None
    history_std: Array | None
    body: Array | None
    rel_error: Array
    settling: Array | None
    nees: Array
    body_rmse: Array
    seconds: float


class ModelTrials(NamedTuple):
    """The standard trials of a model (module docstring) at ``speed`` (m/s) and ``rpm``:
    the simulated ``turn``, ``zigzag10``, ``zigzag20`` (``seatrials.Trial``, leading axes as
    theta's), their metrics, the criteria and ``stable`` (straight-line stability)."""

    speed: float
    rpm: float
    length: float
    turn: seatrials.Trial
    zigzag10: seatrials.Trial
    zigzag20: seatrials.Trial
    turning: TurningMetrics
    zz10: ZigZagMetrics
    zz20: ZigZagMetrics
    criteria: dict[str, Criterion]
    stable: NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class TrialDemo:
    """The demonstrated trial over R runs and K samples (module docstring): ``t (K,)``,
    ``inputs (K, 2)`` [delta rad, n rpm], the truth ``truth_pose``, ``truth_body`` ``(K, 3)``;
    per run the measured ``gps (R, K, 2)``, ``heading (R, K)``, ``z (R, K, 3)``, the
    ``filtered (R, K, 3)`` body and its track ``filtered_pose (R, K, 3)`` (None without a
    filter), the model's ``model_pose (R, K, 3)``; position RMSE of the raw GPS, of the
    filtered track and of the model, the model's largest error ``(R,)``; ``metrics``: the
    trial's metrics of the truth, the measurements and the model."""

    kind: str
    params: dict
    t: Array
    inputs: Array
    truth_pose: Array
    truth_body: Array
    gps: Array
    heading: Array
    z: Array
    filtered: Array | None
    filtered_pose: Array | None
    model_pose: Array
    gps_rmse: Array
    filtered_rmse: Array | None
    model_rmse: Array
    model_max: Array
    metrics: dict[str, TurningMetrics | ZigZagMetrics]


@dataclass(frozen=True, eq=False)
class VesselResult:
    """A vessel scenario's Monte Carlo (module docstring). ``t (K,)`` and ``segments``: the
    identification data's samples and trials; ``sigma_z (3,)`` the identifier's measurement
    standard deviations; ``noise_rmse (R, 3)`` the measurements' error; ``filters`` by name;
    ``shown`` the filter the figures show; ``trial`` the demonstrated trial (or None);
    ``model`` and ``model_truth`` the standard trials of the shown filter's identified
    models (R) and of the truth."""

    scenario: str
    runs: int
    seed: int
    dt: float
    truth: CoefficientSet
    data: str
    t: Array
    segments: tuple[Segment, ...]
    sigma_z: Array
    noise_rmse: Array
    filters: dict[str, FilterStats]
    shown: str
    settle_tol: float
    trial: TrialDemo | None
    model: ModelTrials
    model_truth: ModelTrials
    seconds: dict[str, float] = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------
# pieces
# ---------------------------------------------------------------------------------------------


def _sensed(t: Array, pose: Array, x: Array, run_ids: list[int], seed: int, key: int,
            sensors, dt: float) -> BodyMeasurements:
    """GPS/INS of the truth ``pose, x (R, K, 3)`` per run, pre-processed to the grid (batched
    over runs)."""
    from trackkit.io.navigation import preprocess_sim
    from trackkit.sim.gnss import KHOR_MUSA, simulate_gnss

    rngs = [run_seed(seed, r, key) for r in run_ids]  # each run's noise from its own stream
    G, Ii = simulate_gnss(t, pose[..., 0], pose[..., 1], pose[..., 2], x[..., 0], x[..., 1],
                          x[..., 2], rng=rngs, gps=sensors.gps(), ins=sensors.ins())
    return preprocess_sim(G, Ii, dt=dt, reference=KHOR_MUSA)


def _body(m: BodyMeasurements) -> Array:
    return np.stack([m.u, m.v, m.r], -1)


def _run_filter(name: str, z: Array, s: Array, dt: float, *, norm: Normalisation,
                starts: Array, theta0: Array, theta_sd0: float | Array, sigma_z: Array,
                q_body, q_theta: float, substeps: int):
    """``(theta, theta_std, cov16, history, history_std, body, seconds)`` of one identifier;
    history and body are None for least squares."""
    t0 = time.perf_counter()
    if name == "ls":
        fit = least_squares(z, s, dt, norm=norm, starts=starts)
        sd = np.sqrt(np.diagonal(fit.cov, axis1=-2, axis2=-1))
        return fit.theta, sd, fit.cov, None, None, None, time.perf_counter() - t0
    r = identify(z, s, dt, norm=norm, starts=starts, filter=name, theta0=theta0,
                 theta_sd0=theta_sd0, sigma_z=sigma_z, q_body=q_body, q_theta=q_theta,
                 substeps=substeps)
    return (r.theta, r.theta_std[..., -1, :], r.cov[..., 3:, 3:], r.theta_history,
            r.theta_std, r.body, time.perf_counter() - t0)


def _rms(e: Array, axis: int) -> Array:
    """RMS over ``axis`` of the finite entries (nan where there are none)."""
    ok = np.isfinite(e)
    n = ok.sum(axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.sqrt(np.where(ok, e * e, 0.0).sum(axis) / n), np.nan)


def _fill(t: Array, y: Array) -> Array:
    """``y (..., K)`` with its non-finite entries interpolated linearly in ``t`` (held at the
    ends), per row; a row with none is returned as it is."""
    y = np.array(y, dtype=float)
    if np.isfinite(y).all():  # simulated records have no gaps
        return y
    flat = y.reshape(-1, y.shape[-1])
    for row in flat:  # only records with gaps: a recorded log, one row
        ok = np.isfinite(row)
        if ok.any() and not ok.all():
            row[~ok] = np.interp(t[~ok], t[ok], row[ok])
    return flat.reshape(y.shape)


def _model_error(pred: Array, east: Array, north: Array) -> tuple[Array, Array]:
    """RMS and largest distance ``(...)`` of the predicted poses ``(..., K, 3)`` from the
    positions ``(..., K)`` (samples where those are missing left out); inf for a prediction
    that diverged (overflowed to a non-finite pose)."""
    with np.errstate(all="ignore"):
        err = np.hypot(pred[..., 0] - east, pred[..., 1] - north)
    diverged = ~np.isfinite(pred[..., :2]).all((-1, -2))
    rms = np.where(diverged, np.inf, _rms(err, -1))
    big = np.where(diverged, np.inf, np.where(np.isfinite(err), err, -np.inf).max(-1))
    return rms, big


def anchored_track(body: Array, heading: Array, dt: float, gps: Array, t: Array) -> Array:
    """The track ``(..., K, 3)`` of body states ``(..., K, 3)`` and the measured heading
    ``(..., K)`` (``identify.dead_reckon``), shifted by the mean offset of the GPS positions
    ``(..., K, 2)`` from it: the least-squares start. Missing headings are interpolated."""
    heading = np.unwrap(_fill(t, heading), axis=-1)
    zero = np.zeros(np.broadcast_shapes(body.shape[:-2], heading.shape[:-1]) + (3,))
    track = dead_reckon(_fill(t, np.moveaxis(body, -1, -2)).swapaxes(-1, -2), heading, dt, zero)
    d = gps - track[..., :2]
    ok = np.isfinite(d).all(-1, keepdims=True)
    n = np.maximum(ok.sum(-2), 1)
    off = np.where(ok, d, 0.0).sum(-2) / n
    track[..., :2] += off[..., None, :]
    return track


def stable(theta: Array, norm: Normalisation, speed: float, rpm: float) -> NDArray[np.bool_]:
    """Whether the straight-line motion at ``speed`` (m/s), zero nozzle and ``rpm`` is
    locally stable: every eigenvalue of ``df/dx`` at ``[speed, 0, 0]`` has a negative real
    part (there ``df/dx`` is block triangular: the surge slope and the sway-yaw block)."""
    J = rhs_jacobian(np.array([speed, 0.0, 0.0]), np.array([0.0, rpm]), theta, norm)
    return np.linalg.eigvals(J).real.max(-1) < 0


@renamed_keywords(T="dt")
def model_trials(theta: Array, norm: Normalisation, speed: float, rpm: float, length: float,
                 *, dt: float = 1.0, substeps: int = 10) -> ModelTrials:
    """The standard trials of the model ``theta (..., 16)`` (module docstring): simulated
    with ``seatrials`` from ``speed`` at ``rpm``, dt and ``substeps`` Euler steps per sample,
    their metrics and criteria (all of theta's leading shape)."""
    theta = np.asarray(theta, dtype=float)
    kw = dict(rpm=rpm, speed=speed, dt=dt, substeps=substeps, max_duration=_MAX_TRIAL_S)
    with np.errstate(all="ignore"):  # an unstable model overflows: its metrics become nan
        turn = seatrials.turning_circle(theta, norm, delta=_TURN_DELTA, **kw)
        zz = {k: seatrials.zigzag(theta, norm, delta=a, alpha=a, **kw) for k, a in _ZZ.items()}
        tm = turning_metrics(turn.t, turn.east, turn.north, turn.psi, length, side=1.0)
        zm = {k: zigzag_metrics(tr.t, tr.psi, _ZZ[k], tr.east, tr.north)
              for k, tr in zz.items()}
        tm = TurningMetrics(*(np.where(np.isfinite(v), v, np.nan) for v in tm))
        zm = {k: ZigZagMetrics(*(np.where(np.isfinite(v), v, np.nan) for v in m))
              for k, m in zm.items()}
        crit = imo_criteria(length, speed, turning=tm, zigzag10=zm["zigzag10"],
                            zigzag20=zm["zigzag20"])
    return ModelTrials(float(speed), float(rpm), float(length), turn, zz["zigzag10"],
                       zz["zigzag20"], tm, zm["zigzag10"], zm["zigzag20"], crit,
                       stable(theta, norm, speed, rpm))


def _trial_metrics(kind: str, params: dict, t: Array, east: Array, north: Array, psi: Array,
                   length: float) -> TurningMetrics | ZigZagMetrics:
    with np.errstate(all="ignore"):
        if kind == "turn":
            return turning_metrics(t, east, north, psi, length, side=params["side"])
        return zigzag_metrics(t, psi, params["alpha"], east, north, side=params["side"])


# ---------------------------------------------------------------------------------------------
# the scenario
# ---------------------------------------------------------------------------------------------


def run_vessel(scenario, *, runs: int | None = None, seed: int | None = None,
               filters: list[str] | None = None) -> VesselResult:
    """The Monte Carlo of a vessel scenario (``scenario.vessel.VesselScenario``; module
    docstring); ``runs``, ``seed`` and ``filters`` override the scenario's."""
    idn = scenario.identification
    R = scenario.run.runs if runs is None else int(runs)
    seed = scenario.run.seed if seed is None else int(seed)
    if R < 1 or seed < 0:
        raise ValueError(f"runs = {R}, seed = {seed}; expected runs >= 1 and seed >= 0")
    names = list(idn.filters if filters is None else filters)
    bad = [f for f in names if f not in METHODS]
    if bad or not names:
        raise ValueError(f"filters = {names!r}; expected one or more of {', '.join(METHODS)}")
    shown = next((f for f in names if f != "ls"), names[0])
    truth = scenario.vessel.truth()
    norm, th = truth.norm, truth.theta
    dt, m_sub, t_sub = idn.period_s, idn.substeps, scenario.vessel.substeps
    run_ids = list(range(R))
    sigma_z = scenario.sigma_z()
    speed, rpm = scenario.speed(), scenario.rpm()
    length = truth.design["length"]
    clock: dict[str, float] = {}

    # the demonstrated trial: one truth, each run's sensors
    demo = None
    if scenario.trial is not None:
        t0 = time.perf_counter()
        params = scenario.trial_kwargs()
        fn = seatrials.zigzag if scenario.trial.kind == "zigzag" else seatrials.turning_circle
        tr = fn(th, norm, dt=dt, substeps=t_sub, **params)
        pose = np.broadcast_to(np.stack([tr.east, tr.north, tr.psi], -1), (R, tr.t.size, 3))
        xb = np.broadcast_to(np.stack([tr.u, tr.v, tr.r], -1), (R, tr.t.size, 3))
        m_trial = _sensed(tr.t, pose, xb, run_ids, seed, _TRIAL_KEY, scenario.sensors, dt)
        K = m_trial.t.size  # the grid may end before the truth (sensor rates)
        trial_truth = (tr, pose[0, :K], xb[0, :K])
        s_trial = np.stack([tr.delta, tr.n], -1)[:K]
        clock["trial"] = time.perf_counter() - t0

    # the identification data
    t0 = time.perf_counter()
    if idn.data == "programme":
        rec = programme(R, seed, truth=truth, dt=dt, substeps=t_sub)
        m = _sensed(rec.t, rec.pose, rec.x, run_ids, seed, _PROGRAMME_KEY, scenario.sensors, dt)
        K = m.t.size
        z, s, x_true = _body(m), rec.s[:, :K], rec.x[:, :K]
        starts, t_id, segments = rec.starts[:K], m.t, rec.segments
    else:
        z, s = _body(m_trial), s_trial
        x_true = np.broadcast_to(trial_truth[2], z.shape)
        t_id, starts = m_trial.t, np.zeros(m_trial.t.size, bool)
        segments = (Segment(scenario.trial.kind, 0, t_id.size),)
    clock["data"] = time.perf_counter() - t0
    theta0 = (initial_guess(th, R, seed, idn.guess_spread) if idn.theta0 == "guess"
              else np.zeros(N_THETA))
    common = dict(norm=norm, sigma_z=sigma_z, q_body=idn.q_body, q_theta=idn.q_theta,
                  substeps=m_sub)
    stats: dict[str, FilterStats] = {}
    for name in names:
        theta, sd, cov, hist, hist_sd, body, secs = _run_filter(
            name, z, s, dt, starts=starts, theta0=theta0, theta_sd0=idn.theta_sd0, **common)
        stats[name] = FilterStats(
            name=name, theta=theta, theta_std=sd, cov=cov,
            history=None if hist is None else hist[0],
            history_std=None if hist_sd is None else hist_sd[0], body=body,
            rel_error=relative_error(theta, th),
            settling=None if hist is None else settling_step(hist, th, idn.settle_tol),
            nees=coefficient_nees(theta, cov, th),
            body_rmse=(np.full((R, 3), np.nan) if body is None
                       else _rms(body - x_true, -2)),
            seconds=secs)
    noise_rmse = _rms(z - x_true, -2)
    best = stats[shown]

    if scenario.trial is not None:
        t0 = time.perf_counter()
        demo = _demo(scenario, params, trial_truth, m_trial, s_trial, best,
                     own=idn.data == "trial", dt=dt, common=common, length=length)
        clock["trial"] += time.perf_counter() - t0
    t0 = time.perf_counter()
    model = model_trials(best.theta, norm, speed, rpm, length, dt=dt, substeps=m_sub)
    model_truth = model_trials(th, norm, speed, rpm, length, dt=dt, substeps=t_sub)
    clock["model_trials"] = time.perf_counter() - t0
    return VesselResult(scenario=scenario.name, runs=R, seed=seed, dt=dt, truth=truth,
                        data=idn.data, t=t_id, segments=tuple(segments), sigma_z=sigma_z,
                        noise_rmse=noise_rmse, filters=stats, shown=shown,
                        settle_tol=idn.settle_tol, trial=demo, model=model,
                        model_truth=model_truth, seconds=clock)


def _demo(scenario, params: dict, truth: tuple, m: BodyMeasurements, s: Array,
          best: FilterStats, *, own: bool, dt: float, common: dict, length: float
          ) -> TrialDemo:
    """The demonstrated trial (module docstring)."""
    tr, pose, xb = truth
    kind = scenario.trial.kind
    t = m.t
    z = _body(m)
    gps = np.stack([m.east, m.north], -1)
    filtered = None
    if best.body is not None:
        if own:  # identified over the trial itself: the identification's own filtering
            filtered = best.body
        else:  # filtered from the identified coefficients (prior sd: median over runs)
            sd0 = np.maximum(np.median(best.theta_std, 0), 1e-9)
            filtered = identify(z, s, dt, filter=best.name, theta0=best.theta, theta_sd0=sd0,
                                **common).body
    filtered_pose = None if filtered is None else anchored_track(filtered, m.psi, dt, gps, t)
    pose0 = np.stack([m.east[:, 0], m.north[:, 0], m.psi[:, 0]], -1)
    with np.errstate(all="ignore"):  # a run's unstable model may overflow: its error is inf
        pred = predict(best.theta, s, dt, z[:, 0], norm=common["norm"], pose0=pose0,
                       substeps=common["substeps"])
    model_rmse, model_max = _model_error(pred.pose, pose[:, 0], pose[:, 1])
    gps_err = np.hypot(gps[..., 0] - pose[:, 0], gps[..., 1] - pose[:, 1])
    fil_rmse = None
    if filtered_pose is not None:
        fil_rmse = _rms(np.hypot(filtered_pose[..., 0] - pose[:, 0],
                                 filtered_pose[..., 1] - pose[:, 1]), -1)
    metrics = {
        "truth": _trial_metrics(kind, params, t, pose[:, 0], pose[:, 1], pose[:, 2], length),
        "measured": _trial_metrics(kind, params, t, m.east, m.north, m.psi, length),
        "model": _trial_metrics(kind, params, t, pred.pose[..., 0], pred.pose[..., 1],
                                pred.pose[..., 2], length),
    }
    return TrialDemo(kind=kind, params=params, t=t, inputs=s, truth_pose=pose, truth_body=xb,
                     gps=gps, heading=m.psi, z=z, filtered=filtered,
                     filtered_pose=filtered_pose, model_pose=pred.pose,
                     gps_rmse=_rms(gps_err, -1), filtered_rmse=fil_rmse,
                     model_rmse=model_rmse, model_max=model_max, metrics=metrics)


# ---------------------------------------------------------------------------------------------
# a recorded log (trackkit identify LOG --inputs CSV)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RecordedIdentification:
    """The identification of one recorded log (:func:`identify_recorded`): the grid ``t
    (K,)`` (s from the log's epoch), the inputs ``s (K, 2)`` [delta rad, n rpm], the measured
    ``z (K, 3)`` and ``pose (K, 3)`` [east, north, psi]; ``theta``, ``theta_std`` (16,) and
    ``rel_std = theta_std / |theta|``; ``history``, ``history_std`` ``(K, 16)`` (None for
    least squares); ``body (K, 3)`` the filtered u, v, r (the measured ones for least
    squares); ``filtered_pose`` its track placed on the GPS fixes, ``model_pose`` the
    identified model driven by the log's inputs from the first sample, ``model_rmse`` and
    ``filtered_rmse`` (m) their RMS distances from the GPS fixes (inf: the model diverged);
    ``speed`` (m/s) and
    ``rpm``: the log's medians, at which ``trials`` are simulated; ``stable`` the model's
    straight-line stability there; ``dropped``: leading samples dropped (no measurement)."""

    filter: str
    dt: float
    t: Array
    s: Array
    z: Array
    pose: Array
    theta: Array
    theta_std: Array
    rel_std: Array
    history: Array | None
    history_std: Array | None
    body: Array
    filtered_pose: Array
    model_pose: Array
    model_rmse: float
    filtered_rmse: float
    speed: float
    rpm: float
    trials: ModelTrials
    stable: bool
    norm: Normalisation
    sigma_z: Array
    substeps: int
    dropped: int
    missing: int


def inputs_at_substeps(inputs: MeasuredInputs, t: Array, dt: float, substeps: int) -> Array:
    """The measured inputs ``[delta (rad), n (rpm)]`` at the ends of the filter's ``m =
    substeps`` sub-steps of the grid ``t (K,)`` of period ``dt``: ``(..., (K - 1) m + 1, 2)``
    at ``t_0 + j dt / m`` (nan outside the
    record). A rate-limited nozzle starts and stops between grid samples; interpolated
    between the samples of a 1 s grid it is smoothed, which biases c1 by 10-20%
    (docs/vessel-comparison.md)."""
    t_sub = np.minimum(t[0] + (dt / substeps) * np.arange((t.size - 1) * substeps + 1), t[-1])
    nozzle, rev_s = inputs_on_grid(inputs, t_sub)
    return np.stack([nozzle, 60.0 * rev_s], -1)  # rev/s to rpm, the identifier's unit


def _inputs_resolve_substeps(inputs: MeasuredInputs, dt: float) -> bool:
    """Whether the inputs are logged at least every ``dt / 5`` (median interval): fine enough
    to follow the nozzle's starts and stops between grid samples. A log at exactly ``dt / 5``
    counts, whatever the rounding of its times' differences (0.2 s as 0.20000000000000107)."""
    return inputs.t.size > 1 and float(np.median(np.diff(inputs.t))) <= dt / 5 * (1 + 1e-9)


def identify_recorded(m: BodyMeasurements, inputs: MeasuredInputs, *, filter: str = "ekf",
                      substeps: int | None = None, sigma_z: Array = DEFAULT_NOISE.body,
                      q_body: Array | None = None, norm: Normalisation | None = None,
                      length: float | None = None, inputs_name: str = "the inputs"
                      ) -> RecordedIdentification:
    """Identify the 16 coefficients from a pre-processed log ``m`` and its measured
    ``inputs`` (engine speed in rev/s, converted to rpm here), with ``filter`` (one of
    ``identify.METHODS``); the prior is identify's (zero, sd 1), the coefficients in the prime
    units of ``norm`` (default the reference vessel's). Inputs logged at least every dt / 5
    are given to the filter at its sub-steps' ends (``inputs_at_substeps``; identify's
    defaults: 50 sub-steps), coarser ones at the grid samples only (interpolated; identify's
    defaults for that: ten sub-steps and a larger Q).
    ValueError, naming ``inputs_name``, when the inputs do not cover the log's grid."""
    ref = reference_vessel()
    norm = ref.norm if norm is None else norm
    length = ref.design["length"] if length is None else float(length)
    if filter not in METHODS:
        raise ValueError(f"filter = {filter!r}; expected one of {', '.join(METHODS)}")
    t, dt = m.t, float(m.dt)
    pose = np.stack([m.east, m.north, m.psi], -1)
    z = _body(m)
    ok = np.isfinite(z).all(-1) & np.isfinite(pose).all(-1)
    if not ok.any():
        raise ValueError("the log gives no grid sample with position, velocity, heading and "
                         "yaw rate together; expected GPS fixes with speed and course, and "
                         "INS heading and rate of turn, over a common time span")
    k0 = int(np.argmax(ok))  # the record starts at its first complete sample
    t, z, pose = t[k0:], z[k0:], pose[k0:]
    if t.size < 3:
        raise ValueError(f"the log gives {t.size} grid samples at dt = {dt:g} s; expected at "
                         "least 3")
    lo, hi = (float(inputs.t[0]), float(inputs.t[-1])) if inputs.t.size else (math.nan,) * 2
    fine = _inputs_resolve_substeps(inputs, dt) and filter != "ls"
    if substeps is None:
        substeps = DEFAULT_SUBSTEPS if fine else SUBSTEPS_SAMPLED_INPUTS
    s_sub = inputs_at_substeps(inputs, t, dt, substeps)
    if not np.all(np.isfinite(s_sub)):
        raise ValueError(f"{inputs_name} cover t = {lo:.3f} to {hi:.3f} s but the log's grid "
                         f"spans {t[0]:.3f} to {t[-1]:.3f} s (from the log's first record); "
                         "expected nozzle angle and rpm over the whole log")
    s = s_sub[..., ::substeps, :]
    if not fine:
        s_sub = s  # interpolated between the samples, with the Q that covers it
    starts = np.zeros(t.size, bool)
    hint = "" if filter == "ekf" else "; the EKF (filter 'ekf') is the most robust here"
    try:
        with np.errstate(invalid="ignore", over="ignore"):  # reported below
            theta, sd, _, hist, hist_sd, body, _ = _run_filter(
                filter, z, s_sub, dt, norm=norm, starts=starts,
                theta0=np.zeros(N_THETA),
                theta_sd0=1.0, sigma_z=sigma_z, q_body=q_body, q_theta=0.0,
                substeps=substeps)
    except ValueError as err:  # a numerical failure on data the model does not fit
        raise ValueError(f"the {filter} identification failed on this record: {err}{hint}"
                         ) from None
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(sd))):
        raise ValueError(f"the {filter} identification failed on this record: the "
                         "coefficients' covariance lost its positive diagonal (standard "
                         f"deviations {np.round(sd, 4).tolist()}){hint}")
    if body is None:  # least squares filters nothing: its track is the measured one
        body = z
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(theta != 0, sd / np.abs(theta), np.inf)
    gps = pose[:, :2]
    filtered_pose = anchored_track(body, pose[:, 2], dt, gps, t)
    with np.errstate(all="ignore"):
        pred = predict(theta, s, dt, z[0], norm=norm, pose0=pose[0], substeps=substeps)
    model_rmse, _ = _model_error(pred.pose, gps[:, 0], gps[:, 1])
    speed = float(np.median(z[np.isfinite(z[:, 0]), 0]))
    rpm = float(np.median(s[:, 1]))
    if not (speed > 0):
        raise ValueError(f"the log's median surge speed is {speed:.3g} m/s; expected a "
                         "vessel under way (the standard trials start from it)")
    trials = model_trials(theta, norm, speed, rpm, length, dt=dt, substeps=substeps)
    filt_err = np.hypot(filtered_pose[:, 0] - gps[:, 0], filtered_pose[:, 1] - gps[:, 1])
    return RecordedIdentification(
        filter=filter, dt=dt, t=t, s=s, z=z, pose=pose, theta=theta, theta_std=sd,
        rel_std=rel, history=hist, history_std=hist_sd, body=body,
        filtered_pose=filtered_pose, model_pose=pred.pose,
        model_rmse=float(model_rmse), filtered_rmse=float(_rms(filt_err, 0)), speed=speed,
        rpm=rpm, trials=trials,
        stable=bool(trials.stable), norm=norm, sigma_z=np.asarray(sigma_z, dtype=float),
        substeps=substeps, dropped=k0, missing=int((~np.isfinite(z).all(-1)).sum()))
