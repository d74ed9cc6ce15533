"""Particle filter speed against Stone Soup and a plain numpy bootstrap PF, in one process.

A 2-D nearly-constant-velocity target (q = 1), 1 s steps, measured by a position sensor
(sigma 10 m) or a range-bearing radar at the origin (10 m, 0.01 rad). Each filter step is a
prediction, an update and systematic resampling of every run at every step:

* Stone Soup: ``ParticlePredictor`` over ``CombinedLinearGaussianTransitionModel`` of two
  ``ConstantVelocity``, ``ParticleUpdater(resampler=SystematicResampler())`` with a
  ``LinearGaussian`` (position) or ``CartesianToBearingRange`` model; one run, step by step
  (its prediction, detection and hypothesis objects made every step, as in its tutorials);
* plain numpy: a vectorised bootstrap PF written here for one run (F x + L e,
  Gaussian log-likelihood, weights, searchsorted on the cumulative sum), no checks;
* trackkit: ``PF(N, ess_threshold=1.0)`` batched over ``--runs`` runs (each its own
  measurements), predict, update and ``estimate`` (the Gaussian the metrics need) per step;
  ``ess_threshold=1.0`` resamples every row at every step, as the other two do.

Ratios are Stone Soup's time per step over trackkit's time per run-step; timings are the best
of ``--repeat``, interleaved (a change of machine load hits every filter alike).

    python benchmarks/bench_particle.py [--particles 1000 5000] [--runs 100] [--steps 50]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from datetime import datetime, timedelta

import numpy as np
import stonesoup
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
from stonesoup.models.transition.linear import (
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.resampler.particle import SystematicResampler
from stonesoup.types.array import StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import ParticleState
from stonesoup.updater.particle import ParticleUpdater

import trackkit as tk
from trackkit.filters.particle import PF

Q, DT = 1.0, 1.0
SIGMA_POS, SIGMA_R, SIGMA_B = 10.0, 10.0, 0.01
X0 = np.array([2000.0, 3000.0, -10.0, 5.0])
P0 = np.diag([400.0, 400.0, 25.0, 25.0])
SS_ORDER = [0, 2, 1, 3]  # trackkit [x, y, vx, vy] -> Stone Soup [x, vx, y, vy]
T0 = datetime(2024, 1, 1)


def sensor_of(kind: str):
    if kind == "position":
        return tk.models.Position(dim=2, sigma=SIGMA_POS)
    return tk.models.RangeBearing(sigma_range=SIGMA_R, sigma_bearing=SIGMA_B,
                                  convention="math")


def data(kind: str, runs: int, steps: int, seed: int = 0) -> np.ndarray:
    """Measurements ``(steps, runs, 2)`` of independent truths, trackkit's order."""
    rng = np.random.default_rng(seed)
    motion, sensor = tk.models.ConstantVelocity(dim=2, q=Q), sensor_of(kind)
    L = np.linalg.cholesky(motion.noise(None, DT))
    x = X0 + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T
    sd = np.sqrt(np.diag(sensor.noise))
    z = np.empty((steps, runs, 2))
    for k in range(steps):
        x = motion.f(x, DT) + rng.standard_normal((runs, 4)) @ L.T
        z[k] = sensor.h(x) + sd * rng.standard_normal((runs, 2))
    return z


def time_stonesoup(kind: str, z: np.ndarray, N: int) -> float:
    """Seconds per step of Stone Soup's particle filter on run 0."""
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(Q),
                                                        ConstantVelocity(Q)])
    if kind == "position":
        model = LinearGaussian(ndim_state=4, mapping=(0, 2),
                               noise_covar=np.diag([SIGMA_POS**2] * 2))
        zs = [np.array([[zk[0]], [zk[1]]]) for zk in z[:, 0]]
    else:
        model = CartesianToBearingRange(ndim_state=4, mapping=(0, 2),
                                        noise_covar=np.diag([SIGMA_B**2, SIGMA_R**2]))
        zs = [np.array([[zk[1]], [zk[0]]]) for zk in z[:, 0]]
    predictor = ParticlePredictor(transition)
    updater = ParticleUpdater(model, resampler=SystematicResampler())
    rng = np.random.default_rng(1)
    X = X0 + rng.standard_normal((N, 4)) @ np.linalg.cholesky(P0).T
    state = ParticleState(StateVectors(X[:, SS_ORDER].T), log_weight=np.full(N, -np.log(N)),
                          timestamp=T0)
    t0 = time.perf_counter()
    for k, zk in enumerate(zs):
        t = T0 + timedelta(seconds=(k + 1) * DT)
        pred = predictor.predict(state, timestamp=t)
        det = Detection(zk, timestamp=t, measurement_model=model)
        state = updater.update(SingleHypothesis(pred, det))
        state.state_vector @ np.exp(state.log_weight)  # its estimate: the weighted mean
    return (time.perf_counter() - t0) / len(zs)


def time_numpy(kind: str, z: np.ndarray, N: int) -> float:
    """Seconds per step of a plain vectorised bootstrap PF on run 0."""
    motion = tk.models.ConstantVelocity(dim=2, q=Q)
    F = np.asarray(motion.jacobian(None, DT))
    L = np.linalg.cholesky(np.asarray(motion.noise(None, DT)))
    rng = np.random.default_rng(1)
    X = X0 + rng.standard_normal((N, 4)) @ np.linalg.cholesky(P0).T
    zs = z[:, 0]
    t0 = time.perf_counter()
    for zk in zs:
        X = X @ F.T + rng.standard_normal((N, 4)) @ L.T
        if kind == "position":
            r = (zk - X[:, :2]) / SIGMA_POS
            ll = -0.5 * (r[:, 0] ** 2 + r[:, 1] ** 2)
        else:
            rr = (zk[0] - np.hypot(X[:, 0], X[:, 1])) / SIGMA_R
            rb = np.angle(np.exp(1j * (zk[1] - np.arctan2(X[:, 1], X[:, 0])))) / SIGMA_B
            ll = -0.5 * (rr**2 + rb**2)
        w = np.exp(ll - ll.max())
        w /= w.sum()
        w @ X  # the estimate
        c = np.cumsum(w)
        idx = np.searchsorted(c, (rng.random() + np.arange(N)) / N * c[-1], side="right")
        X = X[np.minimum(idx, N - 1)]
    return (time.perf_counter() - t0) / len(zs)


def time_trackkit(kind: str, z: np.ndarray, N: int, threshold: float = 1.0) -> float:
    """Seconds per step for all runs of z, batched."""
    runs = z.shape[1]
    motion, sensor = tk.models.ConstantVelocity(dim=2, q=Q), sensor_of(kind)
    f = PF(N, ess_threshold=threshold)
    b = f.init(tk.Gaussian(np.tile(X0, (runs, 1)), np.tile(P0, (runs, 1, 1))),
               rng=np.random.default_rng(1))
    t0 = time.perf_counter()
    for zk in z:
        b = f.predict(b, motion, DT)
        b, _ = f.update(b, zk, sensor)
        f.estimate(b)
    return (time.perf_counter() - t0) / z.shape[0]


def check_agreement(kind: str) -> None:
    """Before timing: trackkit's PF (100 000 particles, 20 runs, 10 steps) agrees with its
    UKF on this problem to 0.5 standard deviations (a check that the PF is set up right,
    not an oracle: tests/oracles/test_pf_stonesoup.py is)."""
    z = data(kind, 20, 10, seed=5)
    motion, sensor = tk.models.ConstantVelocity(dim=2, q=Q), sensor_of(kind)
    f, u = PF(100_000), tk.filters.UKF()
    g = tk.Gaussian(np.tile(X0, (20, 1)), np.tile(P0, (20, 1, 1)))
    b = f.init(g, rng=np.random.default_rng(2))
    for zk in z:
        b = f.predict(b, motion, DT)
        b, _ = f.update(b, zk, sensor)
        g = u.predict(g, motion, DT)
        g, _ = u.update(g, zk, sensor)
    e = f.estimate(b)
    d = np.linalg.solve(np.linalg.cholesky(g.cov), (e.mean - g.mean)[..., None])[..., 0]
    assert np.all(np.abs(d) < 0.5), np.abs(d).max()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, nargs="+", default=[1000, 5000])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--repeat", type=int, default=3, help="best of this many timings")
    ap.add_argument("--sensors", nargs="+", default=["position", "range-bearing"])
    a = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, numpy {np.__version__}, "
          f"Stone Soup {stonesoup.__version__}")
    print(f"CV target, {a.steps} steps; trackkit batched over {a.runs} runs; systematic "
          "resampling every step")
    for kind in a.sensors:
        check_agreement(kind)
        z = data(kind, a.runs, a.steps)
        print(f"\n{kind}: trackkit's PF agrees with its UKF (to 0.5 sigma, 20 runs)")
        print(f"{'N':>6s} {'Stone Soup ms/step':>19s} {'numpy ms/step':>14s} "
              f"{'trackkit us/run-step':>21s} {'(ESS < N/2)':>12s} {'vs SS':>7s} "
              f"{'vs numpy':>9s}")
        for N in a.particles:
            t_ss = t_np = t_tk = t_tk5 = float("inf")
            for _ in range(a.repeat):
                t_ss = min(t_ss, time_stonesoup(kind, z, N))
                t_np = min(t_np, time_numpy(kind, z, N))
                t_tk = min(t_tk, time_trackkit(kind, z, N) / a.runs)
                t_tk5 = min(t_tk5, time_trackkit(kind, z, N, 0.5) / a.runs)
            print(f"{N:6d} {t_ss * 1e3:19.2f} {t_np * 1e3:14.3f} {t_tk * 1e6:21.1f} "
                  f"{t_tk5 * 1e6:12.1f} {t_ss / t_tk:6.1f}x {t_np / t_tk:8.2f}x")


if __name__ == "__main__":
    main()
