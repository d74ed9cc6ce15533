"""IMM speed against FilterPy's ``IMMEstimator``, measured in one process.

Two nearly-constant-acceleration models in 6 states ``[x, y, vx, vy, ax, ay]`` (jerk
densities 0.01 and 2), each with a Kalman filter, position plots (sigma 5 m), p_ij =
[[0.97, 0.03], [0.1, 0.9]], 1 s steps. FilterPy runs one problem, one predict + update per
step (``IMMEstimator`` over two ``KalmanFilter``, which combines the estimate in both);
trackkit runs ``IMM`` batched over ``--runs`` problems (each its own plots), predict, update
and ``estimate`` (the combined Gaussian) per step. Before timing, the script checks that trackkit's
first row equals FilterPy's run (mode probabilities and combined estimate to 1e-9).

    python benchmarks/bench_imm.py [--runs 1000 10000] [--steps 200] [--repeat 3]

Also the IMM's general path (each model through its filter object, as for EKF or UKF
models) at the first run count, for comparison.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import IMMEstimator, KalmanFilter

import trackkit as tk
from trackkit.filters.imm import IMM

DT, SIGMA = 1.0, 5.0
QS = (0.01, 2.0)
M = np.array([[0.97, 0.03], [0.1, 0.9]])
MU0 = np.array([0.9, 0.1])
P0 = np.diag([100.0, 100.0, 25.0, 25.0, 4.0, 4.0])


def plots(runs: int, steps: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A target that accelerates now and then; ``(steps, runs, 2)`` plots, ``(runs, 6)``
    prior means."""
    rng = np.random.default_rng(seed)
    x = np.zeros((runs, 6))
    x[:, 2:4] = rng.normal(0, 10, (runs, 2))
    z = np.empty((steps, runs, 2))
    for k in range(steps):
        a = np.where((k // 25) % 3 == 1, 2.0, 0.0)
        x[:, 4:] = a
        x[:, :2] += DT * x[:, 2:4] + DT**2 / 2 * x[:, 4:]
        x[:, 2:4] += DT * x[:, 4:]
        z[k] = x[:, :2] + SIGMA * rng.standard_normal((runs, 2))
    x0 = np.zeros((runs, 6))
    x0[:, :2] = z[0]
    return z, x0


def filterpy_imm(x0: np.ndarray) -> IMMEstimator:
    e, o = np.eye(2), np.zeros((2, 2))
    F = np.block([[e, DT * e, DT**2 / 2 * e], [o, e, DT * e], [o, o, e]])
    kfs = []
    for q in QS:
        kf = KalmanFilter(dim_x=6, dim_z=2)
        kf.F = F
        kf.Q = Q_continuous_white_noise(3, DT, q, block_size=2, order_by_dim=False)
        kf.H = np.eye(2, 6)
        kf.R = SIGMA**2 * np.eye(2)
        kf.x = x0.reshape(6, 1).copy()
        kf.P = P0.copy()
        kfs.append(kf)
    return IMMEstimator(kfs, MU0.copy(), M)


class GeneralKF(tk.filters.KF):
    """The KF under another type: the IMM then takes its general path (each model through
    its filter object) instead of its fast path for sets of KFs."""


def trackkit_imm(general: bool = False) -> tuple[IMM, object]:
    models = [tk.models.ConstantAcceleration(dim=2, q=q) for q in QS]
    kf = GeneralKF() if general else tk.filters.KF()
    return IMM(models, kf, M, mu0=MU0), tk.models.Position(dim=2, sigma=SIGMA)


def time_filterpy(z: np.ndarray, x0: np.ndarray) -> float:
    imm = filterpy_imm(x0[0])
    zs = [zk[0].reshape(2, 1) for zk in z]
    t0 = time.perf_counter()
    for zk in zs:
        imm.predict()
        imm.update(zk)
    return time.perf_counter() - t0


def time_trackkit(z: np.ndarray, x0: np.ndarray, general: bool = False) -> float:
    f, sensor = trackkit_imm(general)
    b = f.init(tk.Gaussian(x0, P0))
    t0 = time.perf_counter()
    for zk in z:
        b = f.predict(b, None, DT)
        b, _ = f.update(b, zk, sensor)
        f.estimate(b)  # FilterPy's update combines the estimate too (x_post, P_post)
    return time.perf_counter() - t0


def check_agreement(z: np.ndarray, x0: np.ndarray) -> None:
    """trackkit's row 0 against FilterPy, every step: mu and the combined estimate."""
    imm = filterpy_imm(x0[0])
    f, sensor = trackkit_imm()
    b = f.init(tk.Gaussian(x0[:2], P0))
    for zk in z:
        imm.predict()
        imm.update(zk[0].reshape(2, 1))
        b = f.predict(b, None, DT)
        b, _ = f.update(b, zk[:2], sensor)
        g = f.estimate(b)
        np.testing.assert_allclose(b.mu[0], imm.mu, rtol=1e-9, atol=1e-15)
        sd = np.sqrt(np.diag(imm.P_post))
        np.testing.assert_allclose(g.mean[0] / sd, imm.x_post[:, 0] / sd, rtol=1e-9,
                                   atol=1e-11)
        np.testing.assert_allclose(g.cov[0], imm.P_post, rtol=1e-9, atol=1e-11 * sd.max()**2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, nargs="+", default=[1000, 10000])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3, help="best of this many timings")
    a = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, numpy {np.__version__}")
    print(f"two-model IMM (2 x KF, 6 states), position plots, {a.steps} steps")
    z, x0 = plots(max(a.runs), a.steps)
    check_agreement(z, x0)
    print("trackkit's row 0 equals FilterPy's run (mu, x, P to 1e-9)")
    print(f"{'runs':>7s} {'FilterPy us/step':>17s} {'trackkit us/run-step':>21s} "
          f"{'ratio':>8s}")
    for runs in a.runs:
        t_fp = t_tk = float("inf")
        for _ in range(a.repeat):  # interleaved: a change of machine load hits both alike
            t_fp = min(t_fp, time_filterpy(z, x0) / a.steps)
            t_tk = min(t_tk, time_trackkit(z[:, :runs], x0[:runs]) / (a.steps * runs))
        print(f"{runs:7d} {t_fp * 1e6:17.1f} {t_tk * 1e6:21.3f} {t_fp / t_tk:7.0f}x")
    runs = a.runs[0]
    t_gen = min(time_trackkit(z[:, :runs], x0[:runs], general=True) for _ in range(a.repeat))
    print(f"general path (each model through its KF object), {runs} runs: "
          f"{t_gen / (a.steps * runs) * 1e6:.3f} us/run-step")


if __name__ == "__main__":
    main()
