"""Core filter speed against FilterPy, measured in one process.

Bearings-only tracking of a constant-velocity target from a manoeuvring observer, 2 000 steps:
FilterPy runs one problem step by step; trackkit runs the same problem batched over 1 000
Monte Carlo runs. The ratio is FilterPy's time per step over trackkit's time per run-step.
Also one unbatched KF step (position measurements) against FilterPy's KalmanFilter.

    python benchmarks/bench_core.py [--runs 1000] [--steps 2000]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
from filterpy.kalman import (
    ExtendedKalmanFilter,
    KalmanFilter,
    MerweScaledSigmaPoints,
    UnscentedKalmanFilter,
)

import trackkit as tk

DT = 1.0
SIGMA = np.deg2rad(1.0)


def problem(runs: int, steps: int, seed: int = 0):
    """Truth, observer track and bearings for ``runs`` runs: (steps, runs, 1) bearings."""
    rng = np.random.default_rng(seed)
    motion = tk.models.ConstantVelocity(dim=2, q=1e-4)
    x = np.tile([6000.0, 9000.0, -4.0, -6.0], (runs, 1))
    t = np.arange(steps) * DT
    observer = np.stack([800.0 * np.sin(2 * np.pi * t / 600.0), 3.0 * t], -1)
    Lq = np.linalg.cholesky(motion.noise(x[0], DT))
    zs = np.empty((steps, runs, 1))
    for k in range(steps):
        x = motion.f(x, DT) + rng.standard_normal((runs, 4)) @ Lq.T
        zs[k] = tk.models.Bearing(observer[k], SIGMA).h(x) + SIGMA * rng.standard_normal(
            (runs, 1)
        )
    prior = tk.Gaussian(
        np.tile([5000.0, 10000.0, 0.0, 0.0], (runs, 1)),
        np.tile(np.diag([4e6, 4e6, 100.0, 100.0]), (runs, 1, 1)),
    )
    return motion, observer, zs, prior


def time_trackkit(f, motion, observer, zs, prior) -> float:
    sensors = [tk.models.Bearing(o, SIGMA) for o in observer]
    b = prior
    t0 = time.perf_counter()
    for k in range(zs.shape[0]):
        b = f.predict(b, motion, DT)
        b, _ = f.update(b, zs[k], sensors[k])
    return time.perf_counter() - t0


def _bearing_fns(o):
    def hx(x):
        x = np.ravel(x)
        return np.array([np.arctan2(x[0] - o[0], x[1] - o[1])])

    def H(x):
        x = np.ravel(x)
        dx, dy = x[0] - o[0], x[1] - o[1]
        r2 = dx * dx + dy * dy
        return np.array([[dy / r2, -dx / r2, 0.0, 0.0]])

    return hx, H


def time_filterpy_ekf(motion, observer, zs, prior) -> float:
    ekf = ExtendedKalmanFilter(4, 1)
    ekf.x = prior.mean[0][:, None].copy()
    ekf.P = prior.cov[0].copy()
    ekf.F = motion.jacobian(ekf.x[:, 0], DT)
    ekf.Q = motion.noise(ekf.x[:, 0], DT)
    ekf.R = np.array([[SIGMA**2]])
    fns = [_bearing_fns(o) for o in observer]
    t0 = time.perf_counter()
    for k in range(zs.shape[0]):
        hx, H = fns[k]
        ekf.predict()
        ekf.update(zs[k, 0].reshape(1, 1), H, hx)  # z as FilterPy keeps x: (m, 1)
    return time.perf_counter() - t0


def time_filterpy_ukf(motion, observer, zs, prior) -> float:
    F = motion.jacobian(prior.mean[0], DT)
    points = MerweScaledSigmaPoints(4, alpha=0.5, beta=2.0, kappa=-1.0)

    def residual(a, b):
        return (a - b + np.pi) % (2 * np.pi) - np.pi

    ukf = UnscentedKalmanFilter(4, 1, DT, hx=None, fx=lambda x, dt: F @ x, points=points,
                                residual_z=residual)
    ukf.x = prior.mean[0].copy()
    ukf.P = prior.cov[0].copy()
    ukf.Q = motion.noise(ukf.x, DT)
    ukf.R = np.array([[SIGMA**2]])
    fns = [_bearing_fns(o)[0] for o in observer]
    t0 = time.perf_counter()
    for k in range(zs.shape[0]):
        ukf.predict()
        ukf.update(zs[k, 0], hx=fns[k])
    return time.perf_counter() - t0


def kf_step(reps: int = 20000) -> tuple[float, float]:
    """Seconds per predict+update, unbatched, FilterPy vs trackkit (interleaved in blocks of
    ``reps // 5`` steps, so that a change of machine load hits both alike; best block)."""
    motion = tk.models.ConstantVelocity(dim=2, q=0.1)
    sensor = tk.models.Position(dim=2, sigma=5.0)
    x0, P0 = np.array([0.0, 0.0, 1.0, 1.0]), np.eye(4) * 10.0
    z = np.array([1.0, 2.0])
    kf = KalmanFilter(4, 2)
    kf.F, kf.Q = motion.jacobian(x0, DT), motion.noise(x0, DT)
    kf.H, kf.R = sensor.jacobian(x0), sensor.noise
    kf.x, kf.P = x0.copy(), P0.copy()
    f, b = tk.filters.KF(), tk.Gaussian(x0, P0)
    block = max(reps // 5, 1)
    t_fp = t_tk = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(block):
            kf.predict()
            kf.update(z)
        t_fp = min(t_fp, (time.perf_counter() - t0) / block)
        t0 = time.perf_counter()
        for _ in range(block):
            b = f.predict(b, motion, DT)
            b, _ = f.update(b, z, sensor)
        t_tk = min(t_tk, (time.perf_counter() - t0) / block)
    return t_fp, t_tk


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=3, help="best of this many timings")
    a = ap.parse_args()
    motion, observer, zs, prior = problem(a.runs, a.steps)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, numpy {np.__version__}")
    print(f"bearings-only CV, {a.steps} steps; trackkit batched over {a.runs} runs")
    rows = []
    for name, fp_timer, f in [
        ("EKF", time_filterpy_ekf, tk.filters.EKF()),
        ("UKF", time_filterpy_ukf, tk.filters.UKF()),
    ]:
        t_fp = t_tk = float("inf")
        for _ in range(a.repeat):  # interleaved: a change of machine load hits both alike
            t_fp = min(t_fp, fp_timer(motion, observer, zs, prior) / a.steps)
            t_tk = min(t_tk, time_trackkit(f, motion, observer, zs, prior) / (a.steps * a.runs))
        rows.append((name, t_fp, t_tk))
    for name in ("IEKF", "CKF"):
        f = {"IEKF": tk.filters.IEKF(3), "CKF": tk.filters.CKF()}[name]
        t_tk = min(time_trackkit(f, motion, observer, zs, prior) for _ in range(a.repeat))
        rows.append((name, float("nan"), t_tk / (a.steps * a.runs)))
    print(f"{'filter':8s} {'FilterPy us/step':>17s} {'trackkit us/run-step':>21s} {'ratio':>8s}")
    for name, t_fp, t_tk in rows:
        print(f"{name:8s} {t_fp * 1e6:17.2f} {t_tk * 1e6:21.3f} {t_fp / t_tk:8.1f}")
    times = [kf_step() for _ in range(a.repeat)]
    t_fp, t_tk = min(t[0] for t in times), min(t[1] for t in times)
    print(f"KF unbatched step: FilterPy {t_fp * 1e6:.1f} us, trackkit {t_tk * 1e6:.1f} us, "
          f"ratio {t_fp / t_tk:.2f}")


if __name__ == "__main__":
    main()
