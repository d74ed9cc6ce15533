"""Oracle: trackkit's particle filter against Stone Soup's particle components.

Same particles in, same numbers out (1e-9 relative):

* update: the normalised log-weights after one update equal those of Stone Soup's
  ``ParticleUpdater`` with a ``LinearGaussian`` (position) and a ``CartesianToBearingRange``
  measurement model (mathematical bearings near +-pi, so the bearing residual is wrapped);
* prediction: Stone Soup's ``ParticlePredictor`` over its own nearly-constant-velocity model,
  given the same process-noise draws (its transition model's ``rvs`` is made to return the
  noise trackkit drew, ``L e`` with ``L = chol(Q)`` and ``e`` the generator's normals);
* systematic resampling: Stone Soup's ``SystematicResampler`` (and, inside a full update, its
  ``ESSResampler`` at N/2) given the same uniform draw. Stone Soup sorts the particles by
  weight before it lays the points on the cumulative weights, trackkit keeps their order, so
  the particles are given to both in increasing order of their (posterior) weight.

Stone Soup orders the CV state ``[x, vx, y, vy]``; trackkit ``[x, y, vx, vy]``: states are
permuted at the boundary, and Stone Soup's own F and Q are used on its side.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from datetime import datetime, timedelta

import numpy as np
import pytest
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
from stonesoup.models.transition.linear import (
    CombinedLinearGaussianTransitionModel,
)
from stonesoup.models.transition.linear import (
    ConstantVelocity as SSConstantVelocity,
)
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.resampler.particle import ESSResampler, SystematicResampler
from stonesoup.types.array import StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.prediction import ParticleStatePrediction
from stonesoup.types.state import ParticleState
from stonesoup.updater.particle import ParticleUpdater

import trackkit as tk
from trackkit.belief import Particles
from trackkit.filters.particle import PF
from trackkit.filters.resample import systematic

RTOL = 1e-9
T0 = datetime(2024, 1, 1)
SS_ORDER = [0, 2, 1, 3]  # trackkit [x, y, vx, vy] -> Stone Soup [x, vx, y, vy]


def to_ss(X: np.ndarray) -> StateVectors:
    return StateVectors(X[:, SS_ORDER].T)


def from_ss(sv) -> np.ndarray:
    out = np.empty((np.shape(sv)[1], 4))
    out[:, SS_ORDER] = np.asarray(sv, dtype=float).T
    return out


def cloud(seed: int, N: int = 500, centre=(-800.0, 30.0, 5.0, -2.0)) -> tuple:
    rng = np.random.default_rng(seed)
    X = np.asarray(centre) + rng.normal(0.0, [40.0, 40.0, 3.0, 3.0], (N, 4))
    lw = np.log(rng.dirichlet(np.full(N, 5.0)))
    return X, lw


@contextmanager
def global_seed(seed: int):
    """Stone Soup's resamplers draw from numpy's legacy global generator: seed it for the
    block and restore its state afterwards."""
    state = np.random.get_state()  # noqa: NPY002 - Stone Soup's own generator
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def first_uniform(seed: int, high: float) -> float:
    """The uniform on [0, high) that Stone Soup's ``SystematicResampler`` draws first after
    ``global_seed(seed)``."""
    return float(np.random.RandomState(seed).uniform(0, high))


class FixedUniform:
    """A stand-in generator whose ``random`` returns given values (the uniform Stone Soup
    drew), so both libraries lay their points from the same draw."""

    def __init__(self, values) -> None:
        self.values = np.asarray(values, dtype=float)

    def random(self, size=None):
        return self.values.reshape(size) if size is not None else float(self.values)


def stone_soup_update(X, lw, z_ss, model) -> np.ndarray:
    pred = ParticleStatePrediction(to_ss(X), log_weight=lw.copy(), timestamp=T0)
    det = Detection(z_ss, timestamp=T0, measurement_model=model)
    return np.asarray(ParticleUpdater(model).update(SingleHypothesis(pred, det)).log_weight,
                      dtype=float)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_update_log_weights_position(seed):
    X, lw = cloud(seed)
    sensor = tk.models.Position(dim=2, sigma=[15.0, 25.0])
    model = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag([225.0, 625.0]))
    z = np.array([-790.0, 45.0]) + seed
    want = stone_soup_update(X, lw, np.array([[z[0]], [z[1]]]), model)
    post, _ = PF(ess_threshold=0.0).update(Particles(X, lw), z, sensor)
    np.testing.assert_allclose(post.log_weights, want, rtol=RTOL)
    assert np.array_equal(post.states, X)


@pytest.mark.parametrize("seed", [0, 1])
def test_update_log_weights_range_bearing_across_the_cut(seed):
    """Targets west of the radar: mathematical bearings near +-pi on both sides of the cut,
    and the measured bearing on the other side of it from most particles."""
    X, lw = cloud(seed, centre=(-800.0, 0.0, 5.0, -2.0))
    b_math = np.arctan2(X[:, 1], X[:, 0])
    assert (b_math > 0).any() and (b_math < 0).any()
    sensor = tk.models.RangeBearing(sigma_range=10.0, sigma_bearing=0.02, convention="math")
    model = CartesianToBearingRange(ndim_state=4, mapping=(0, 2),
                                    noise_covar=np.diag([0.02**2, 10.0**2]))
    z = np.array([805.0, -np.pi + 0.01])  # trackkit: [range, bearing]
    want = stone_soup_update(X, lw, np.array([[z[1]], [z[0]]]), model)  # [bearing, range]
    post, _ = PF(ess_threshold=0.0).update(Particles(X, lw), z, sensor)
    np.testing.assert_allclose(post.log_weights, want, rtol=RTOL)


def test_predict_given_the_same_noise_draws():
    X, lw = cloud(3)
    q, dt = 0.7, 2.0
    motion = tk.models.ConstantVelocity(dim=2, q=q)
    b = Particles(X, lw, np.random.default_rng(4))
    out = PF().predict(b, motion, dt)
    ss_model = CombinedLinearGaussianTransitionModel([SSConstantVelocity(q),
                                                      SSConstantVelocity(q)])
    Q_ss = ss_model.covar(time_interval=timedelta(seconds=dt))
    # trackkit's draw, rebuilt outside trackkit: L e with L the Cholesky factor of Q
    Q = np.asarray(Q_ss)[np.ix_(SS_ORDER, SS_ORDER)]
    e = np.random.default_rng(4).standard_normal(X.shape)
    W = e @ np.linalg.cholesky(Q).T
    object.__setattr__(ss_model, "rvs", lambda num_samples=1, **kw: to_ss(W))
    prior = ParticleState(to_ss(X), log_weight=lw.copy(), timestamp=T0)
    pred = ParticlePredictor(ss_model).predict(prior, timestamp=T0 + timedelta(seconds=dt))
    want = from_ss(pred.state_vector)
    np.testing.assert_allclose(out.states, want, rtol=RTOL, atol=RTOL * np.abs(want).max())
    np.testing.assert_allclose(out.log_weights, np.asarray(pred.log_weight, float), rtol=RTOL)


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_systematic_resampling_given_the_same_uniform(seed):
    X, lw = cloud(seed, N=300)
    order = np.argsort(lw, kind="stable")  # increasing weight: Stone Soup's own order
    X, lw = X[order], lw[order]
    with global_seed(seed):
        out = SystematicResampler().resample(ParticleState(to_ss(X), log_weight=lw.copy(),
                                                           timestamp=T0))
    u = first_uniform(seed, 1 / 300)
    idx = systematic(np.exp(lw), FixedUniform(300 * u))
    np.testing.assert_allclose(X[idx], from_ss(out.state_vector), rtol=RTOL)
    np.testing.assert_allclose(np.asarray(out.log_weight, float), -math.log(300), rtol=RTOL)


def test_update_with_ess_resampling():
    """One PF update with systematic resampling below ESS = N/2 against Stone Soup's
    ``ParticleUpdater(resampler=ESSResampler(SystematicResampler()))``."""
    X, lw = cloud(8, N=400)
    sensor = tk.models.Position(dim=2, sigma=[5.0, 5.0])
    model = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag([25.0, 25.0]))
    z = np.array([-805.0, 35.0])
    # order the particles by their posterior weight (computed here), as Stone Soup sorts them
    d = (z - X[:, :2]) / 5.0
    order = np.argsort(lw - 0.5 * (d * d).sum(1), kind="stable")
    X, lw = X[order], lw[order]
    pred = ParticleStatePrediction(to_ss(X), log_weight=lw.copy(), timestamp=T0)
    det = Detection(np.array([[z[0]], [z[1]]]), timestamp=T0, measurement_model=model)
    updater = ParticleUpdater(model, resampler=ESSResampler(resampler=SystematicResampler()))
    with global_seed(9):
        ss = updater.update(SingleHypothesis(pred, det))
    b = Particles._make((X, lw, FixedUniform(400 * first_uniform(9, 1 / 400))))
    post, _ = PF(ess_threshold=0.5).update(b, z, sensor)
    w_post = stone_soup_update(X, lw, np.array([[z[0]], [z[1]]]), model)
    assert 1 / np.exp(2 * w_post).sum() < 200  # the update does resample
    np.testing.assert_allclose(post.states, from_ss(ss.state_vector), rtol=RTOL)
    np.testing.assert_allclose(post.log_weights, np.asarray(ss.log_weight, float), rtol=RTOL)
