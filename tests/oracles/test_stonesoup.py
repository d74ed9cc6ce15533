"""Oracle: trackkit's UKF, CKF and unscented RTS smoother against Stone Soup, step by step.

Sigma points depend on the Cholesky factor, which a permutation of the state changes, so
Stone Soup gets trackkit's state ordering [x, y, vx, vy]: a
``LinearGaussianTimeInvariantTransitionModel`` per step built from trackkit's F and Q, and
measurement models with ``mapping=(0, 1)`` whose ``translation_offset`` is the observer
position of that step. Stone Soup's bearing is mathematical (``atan2(dy, dx)``) and its
``CartesianToBearingRange`` measures ``[bearing, range]``; the tests convert the measurements
(trackkit's are nautical ``[range, bearing]``) and run trackkit both with its default
nautical convention and with ``convention="math"``. Both libraries average angles circularly
and wrap angle differences.

The CKF is compared with Stone Soup's UKF at alpha = 1, beta = 0, kappa = 0, which is the
same third-degree cubature rule (the centre point has weight 0). Stone Soup's own cubature
filter is not used: it mixes a circular mean into raw-moment formulas.

Stone Soup's ``UnscentedKalmanSmoother`` defaults to kappa = 0 (not 3 - n like its filter), so
the smoother is always given the filter's kappa explicitly.

Every step's filtered and smoothed mean and covariance must agree to 1e-9 relative (with an
absolute floor of ``FLOOR`` standard deviations, see ``helpers.FLOOR``).
"""

from __future__ import annotations

from datetime import datetime, timedelta
from functools import cache

import numpy as np
import pytest
from stonesoup.base import Property
from stonesoup.models.base import TimeVariantModel
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.measurement.nonlinear import (
    Cartesian2DToBearing,
    CartesianToBearingRange,
)
from stonesoup.models.transition.linear import LinearGaussianTimeInvariantTransitionModel
from stonesoup.models.transition.nonlinear import GaussianTransitionModel
from stonesoup.predictor.kalman import UnscentedKalmanPredictor
from stonesoup.smoother.kalman import UnscentedKalmanSmoother
from stonesoup.types.angle import Bearing
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import GaussianState
from stonesoup.types.track import Track
from stonesoup.updater.kalman import UnscentedKalmanUpdater

import trackkit as tk

from .helpers import (
    assert_gaussian_close,
    cv_Q,
    nautical_to_math,
    problem,
    stack_problems,
    wrap,
)

T0 = datetime(2025, 1, 1)

# --------------------------------------------------------------------------------------------
# Stone Soup runs


def _ss_measurement(kind: str, sigma, origin, z_nautical):
    """Stone Soup measurement model and measurement vector for one step (math bearing,
    [bearing, range] order)."""
    o = StateVector(np.array(origin, dtype=float))
    if kind == "linear":
        mm = LinearGaussian(ndim_state=4, mapping=(0, 1), noise_covar=np.diag(np.square(sigma)))
        return mm, StateVector(np.array(z_nautical, dtype=float))
    if kind == "range_bearing":
        mm = CartesianToBearingRange(
            ndim_state=4, mapping=(0, 1), translation_offset=o,
            noise_covar=np.diag([sigma[1] ** 2, sigma[0] ** 2]),
        )
        return mm, StateVector([Bearing(nautical_to_math(z_nautical[1])), z_nautical[0]])
    mm = Cartesian2DToBearing(
        ndim_state=4, mapping=(0, 1), translation_offset=o,
        noise_covar=np.array([[sigma[0] ** 2]]),
    )
    return mm, StateVector([Bearing(nautical_to_math(z_nautical[0]))])


def _ss_filter_and_smooth(x0, P0, steps, alpha, beta, kappa):
    """Run Stone Soup's UKF over ``steps`` = [(dt, transition model, measurement model,
    measurement vector)], then its unscented RTS smoother.

    Returns (filtered means, covs, smoothed means, covs) as float arrays, time first.
    """
    t = T0
    state = GaussianState(StateVector(np.array(x0, dtype=float)),
                          CovarianceMatrix(np.array(P0, dtype=float)), timestamp=t)
    track = Track()
    for dt, tm, mm, zv in steps:
        t = t + timedelta(seconds=float(dt))
        pred = UnscentedKalmanPredictor(tm, alpha=alpha, beta=beta, kappa=kappa).predict(
            state, timestamp=t)
        det = Detection(zv, timestamp=t, measurement_model=mm)
        state = UnscentedKalmanUpdater(mm, alpha=alpha, beta=beta, kappa=kappa).update(
            SingleHypothesis(pred, det))
        track.append(state)
    n = len(x0)
    smoother = UnscentedKalmanSmoother(
        transition_model=steps[0][1], alpha=alpha, beta=beta,
        kappa=3.0 - n if kappa is None else kappa,
    )
    smoothed = smoother.smooth(track)

    def arrays(states):
        return (np.array([np.asarray(s.state_vector, dtype=float).ravel() for s in states]),
                np.array([np.asarray(s.covar, dtype=float) for s in states]))

    return arrays(track) + arrays(smoothed)


@cache
def ss_run(kind: str, seed: int, observer: str | None, alpha, beta, kappa):
    """Stone Soup UKF + unscented RTS on one CV problem (cached: the filter and smoother tests
    and the batched tests share runs)."""
    p = problem(kind, seed, observer)
    cv = tk.models.ConstantVelocity(dim=2, q=p.q)
    steps = []
    for k in range(p.T):
        F, Q = cv.jacobian(p.x0, p.dts[k]), cv.noise(p.x0, p.dts[k])
        tm = LinearGaussianTimeInvariantTransitionModel(transition_matrix=np.array(F),
                                                        covariance_matrix=np.array(Q))
        mm, zv = _ss_measurement(kind, p.sigma, p.observer[k], p.z[k])
        steps.append((p.dts[k], tm, mm, zv))
    return _ss_filter_and_smooth(p.x0, p.P0, steps, alpha, beta, kappa)


# --------------------------------------------------------------------------------------------
# trackkit runs


def _measurements(p, convention: str) -> np.ndarray:
    z = np.array(p.z, dtype=float)
    if p.kind != "linear" and convention == "math":
        z[..., -1] = nautical_to_math(z[..., -1])
    return z


def _tk_sensors(p, convention: str):
    if p.kind == "linear":
        return tk.models.Position(dim=2, sigma=p.sigma)
    if p.kind == "range_bearing":
        return [tk.models.RangeBearing(origin=o, sigma_range=p.sigma[0],
                                       sigma_bearing=p.sigma[1], convention=convention)
                for o in p.observer]
    return [tk.models.Bearing(origin=o, sigma=p.sigma[0], convention=convention)
            for o in p.observer]


def tk_run(p, f, convention: str = "nautical"):
    motion = tk.models.ConstantVelocity(dim=2, q=p.q)
    prior = tk.Gaussian(np.array(p.x0), np.array(p.P0))
    _, filt = tk.filters.run_filter(f, prior, motion, _tk_sensors(p, convention),
                                    _measurements(p, convention), np.array(p.dts),
                                    history=True)
    return filt, tk.filters.smooth(f, filt, motion, np.array(p.dts[1:]))


def _tk_filter(name: str, alpha, beta, kappa):
    if name == "CKF":
        return tk.filters.CKF()
    return tk.filters.UKF(alpha=alpha, beta=beta, kappa=kappa)


# --------------------------------------------------------------------------------------------
# Single problems

PROBLEMS = [
    ("linear", 0, None),
    ("range_bearing", 0, "circle"),
    ("bearings_only", 0, "zigzag"),
    ("bearings_only", 2, "circle"),
]
# (alpha, beta, kappa): trackkit's defaults (= Stone Soup's: kappa = 3 - n), and two others
UKF_PARAMS = [(0.5, 2.0, None), (1.0, 2.0, 0.0), (0.8, 1.0, 2.0)]
CKF_AS_UKF = (1.0, 0.0, 0.0)
CONVENTIONS = ["nautical", "math"]


def _ids(case):
    return "-".join(str(c) for c in case if c is not None)


def _cases(params):
    out = []
    for kind, seed, observer in PROBLEMS:
        for conv in CONVENTIONS if kind != "linear" else ["nautical"]:
            for prm in params:
                out.append(pytest.param(kind, seed, observer, conv, prm,
                                        id=f"{_ids((kind, seed, observer))}-{conv}-{prm}"))
    return out


@pytest.mark.parametrize(("kind", "seed", "observer", "convention", "params"),
                         _cases(UKF_PARAMS))
def test_ukf_matches_stonesoup(kind, seed, observer, convention, params):
    """UKF (scaled sigma points; defaults and two other (alpha, beta, kappa)) filtered
    sequence against Stone Soup's UnscentedKalmanPredictor/Updater."""
    p = problem(kind, seed, observer)
    fx, fP, _, _ = ss_run(kind, seed, observer, *params)
    filt, _ = tk_run(p, _tk_filter("UKF", *params), convention)
    assert_gaussian_close(filt.mean, filt.cov, fx, fP,
                          f"UKF{params} {kind}/{observer}/{convention} vs Stone Soup")


@pytest.mark.parametrize(("kind", "seed", "observer", "convention", "params"),
                         _cases(UKF_PARAMS))
def test_unscented_rts_matches_stonesoup(kind, seed, observer, convention, params):
    """``smooth(UKF(...), ...)`` against Stone Soup's UnscentedKalmanSmoother on each
    library's own filtered track."""
    p = problem(kind, seed, observer)
    _, _, sx, sP = ss_run(kind, seed, observer, *params)
    _, sm = tk_run(p, _tk_filter("UKF", *params), convention)
    assert_gaussian_close(sm.mean, sm.cov, sx, sP,
                          f"URTS{params} {kind}/{observer}/{convention} vs Stone Soup")


@pytest.mark.parametrize(("kind", "seed", "observer", "convention", "params"),
                         _cases([CKF_AS_UKF]))
def test_ckf_and_smoother_match_stonesoup_ukf_1_0_0(kind, seed, observer, convention, params):
    """CKF against Stone Soup's UKF with alpha = 1, beta = 0, kappa = 0 (the cubature rule),
    filtered and RTS-smoothed."""
    p = problem(kind, seed, observer)
    fx, fP, sx, sP = ss_run(kind, seed, observer, *params)
    filt, sm = tk_run(p, tk.filters.CKF(), convention)
    what = f"CKF {kind}/{observer}/{convention} vs Stone Soup UKF(1, 0, 0)"
    assert_gaussian_close(filt.mean, filt.cov, fx, fP, f"{what} filtered")
    assert_gaussian_close(sm.mean, sm.cov, sx, sP, f"{what} smoothed")


# --------------------------------------------------------------------------------------------
# Batched path


class _Batch:
    """Stacked problems with the attributes ``tk_run`` reads; dt differs per row and step."""

    def __init__(self, kind, seeds, observers):
        problems = [problem(kind, s, o) for s, o in zip(seeds, observers, strict=True)]
        b = stack_problems(problems)
        self.kind, self.q, self.sigma = kind, problems[0].q, problems[0].sigma
        self.x0, self.P0, self.dts, self.observer, self.z = (
            b["x0"], b["P0"], b["dts"], b["observer"], b["z"])


BATCH_CASES = {
    "range_bearing": ([0, 1, 2, 3, 4], ["circle"] * 5),
    "bearings_only": ([0, 1, 2, 3, 4], ["zigzag", "zigzag", "circle", "zigzag", "circle"]),
}


@pytest.mark.parametrize("name", ["UKF", "CKF"])
@pytest.mark.parametrize("kind", list(BATCH_CASES))
def test_batched_sigma_point_filter_and_rts_match_stonesoup_per_row(kind, name):
    """Five different problems (own prior, own step lengths, own moving observer) in one
    batched trackkit run; row b of the filtered and smoothed sequences against Stone Soup
    run on problem b alone."""
    seeds, observers = BATCH_CASES[kind]
    params = (0.5, 2.0, None) if name == "UKF" else CKF_AS_UKF
    batch = _Batch(kind, seeds, observers)
    filt, sm = tk_run(batch, _tk_filter(name, *params))
    assert filt.mean.shape == (batch.z.shape[0], len(seeds), 4)
    for b, (seed, observer) in enumerate(zip(seeds, observers, strict=True)):
        fx, fP, sx, sP = ss_run(kind, seed, observer, *params)
        what = f"batched {name} {kind} row {b}"
        assert_gaussian_close(filt.mean[:, b], filt.cov[:, b], fx, fP, f"{what} filtered")
        assert_gaussian_close(sm.mean[:, b], sm.cov[:, b], sx, sP, f"{what} smoothed")


# --------------------------------------------------------------------------------------------
# Nonlinear motion: coordinated turn. With a linear motion model the unscented prediction and
# the smoother's cross-covariance are exact whatever the sigma points; a turn model makes them
# depend on the rule, so this checks the sigma-point prediction and the unscented RTS gain.


def _ct_f(X: np.ndarray, dt: float) -> np.ndarray:
    """Hand-written coordinated turn on columns X (5, k) = [x, y, vx, vy, omega] with
    s = sin(w dt)/w and c = (1 - cos(w dt))/w = 2 sin^2(w dt / 2)/w (no cancellation)."""
    px, py, vx, vy, w = X
    wt = w * dt
    small = np.abs(wt) < 1e-6
    ws = np.where(small, 1.0, w)
    s = np.where(small, dt * (1 - wt**2 / 6), np.sin(wt) / ws)
    c = np.where(small, w * dt**2 / 2 * (1 - wt**2 / 12), 2 * np.sin(wt / 2) ** 2 / ws)
    cos, sin = np.cos(wt), np.sin(wt)
    return np.array([px + s * vx - c * vy, py + c * vx + s * vy,
                     cos * vx - sin * vy, sin * vx + cos * vy, w])


def _ct_Q(dt: float, q: float, q_omega: float) -> np.ndarray:
    Q = np.zeros((5, 5))
    Q[:4, :4] = cv_Q(dt, q)
    Q[4, 4] = q_omega * dt
    return Q


class _CoordinatedTurnXY(GaussianTransitionModel, TimeVariantModel):
    """Stone Soup transition model: coordinated turn in trackkit's ordering
    [x, y, vx, vy, omega] over a fixed step ``dt`` (Stone Soup's ConstantTurn orders the
    state [x, vx, y, vy, omega], which changes the sigma points)."""

    dt: float = Property(doc="step length (s)")
    q: float = Property(doc="acceleration noise density")
    q_omega: float = Property(doc="turn-rate noise density")

    @property
    def ndim_state(self):
        return 5

    def function(self, state, noise=False, **kwargs):
        X = np.asarray(state.state_vector, dtype=float)
        return StateVectors(_ct_f(X, self.dt))

    def covar(self, **kwargs):
        return CovarianceMatrix(_ct_Q(self.dt, self.q, self.q_omega))


@cache
def _ct_problem(seed: int = 5, T: int = 120):
    rng = np.random.default_rng(seed)
    q, q_omega, sigma = 0.05, 1e-5, (10.0, np.deg2rad(0.5))
    dts = rng.uniform(0.7, 1.3, T)
    times = np.cumsum(dts)
    obs = 3000.0 * np.stack([np.cos(times / 40.0), np.sin(times / 40.0)], -1)
    sd = np.array([150.0, 150.0, 2.0, 2.0, 0.01])
    C = np.eye(5)
    C[0, 2] = C[2, 0] = 0.3
    C[1, 3] = C[3, 1] = -0.2
    C[2, 4] = C[4, 2] = 0.25
    P0 = sd[:, None] * C * sd[None, :]
    x = np.array([200.0, -100.0, 8.0, 3.0, 0.03])
    x0 = x + np.linalg.cholesky(P0) @ rng.standard_normal(5)
    zs = []
    for k, dt in enumerate(dts):
        x = _ct_f(x[:, None], dt)[:, 0]
        x = x + np.linalg.cholesky(_ct_Q(dt, q, q_omega)) @ rng.standard_normal(5)
        d = x[:2] - obs[k]
        z = np.array([np.hypot(*d), np.arctan2(d[0], d[1])])
        z = z + np.asarray(sigma) * rng.standard_normal(2)
        z[1] = wrap(z[1])
        zs.append(z)
    return x0, P0, dts, obs, np.array(zs), q, q_omega, sigma


@cache
def _ct_ss_run(alpha, beta, kappa):
    x0, P0, dts, obs, zs, q, q_omega, sigma = _ct_problem()
    steps = []
    for k, dt in enumerate(dts):
        tm = _CoordinatedTurnXY(dt=float(dt), q=q, q_omega=q_omega)
        mm = CartesianToBearingRange(
            ndim_state=5, mapping=(0, 1), translation_offset=StateVector(obs[k]),
            noise_covar=np.diag([sigma[1] ** 2, sigma[0] ** 2]),
        )
        zv = StateVector([Bearing(nautical_to_math(zs[k][1])), zs[k][0]])
        steps.append((dt, tm, mm, zv))
    return _ss_filter_and_smooth(x0, P0, steps, alpha, beta, kappa)


@pytest.mark.parametrize("name", ["UKF", "CKF"])
def test_coordinated_turn_filter_and_rts_match_stonesoup(name):
    """UKF (defaults) and CKF with trackkit's CoordinatedTurn against Stone Soup with a
    hand-written coordinated-turn model, range-bearing radar on a circling observer."""
    params = (0.5, 2.0, None) if name == "UKF" else CKF_AS_UKF
    fx, fP, sx, sP = _ct_ss_run(*params)
    x0, P0, dts, obs, zs, q, q_omega, sigma = _ct_problem()
    f = _tk_filter(name, *params)
    motion = tk.models.CoordinatedTurn(q=q, q_omega=q_omega)
    sensors = [tk.models.RangeBearing(origin=o, sigma_range=sigma[0], sigma_bearing=sigma[1])
               for o in obs]
    _, filt = tk.filters.run_filter(f, tk.Gaussian(x0, P0), motion, sensors, zs, dts,
                                    history=True)
    sm = tk.filters.smooth(f, filt, motion, dts[1:])
    assert_gaussian_close(filt.mean, filt.cov, fx, fP, f"{name} coordinated turn filtered")
    assert_gaussian_close(sm.mean, sm.cov, sx, sP, f"{name} coordinated turn smoothed")
