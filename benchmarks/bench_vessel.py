"""Identification speed (Zolfagharnasab and Seif 2025): the 19-state augmented EKF batched over
runs, against FilterPy's ``ExtendedKalmanFilter``, measured in one process.

Data: ``trackkit.identify.programme`` (the default near-continuous truth, T = 1 s), the first
``--steps`` samples of each run. The identifier is the paper's: one forward-Euler step per
sample with the mean input (eq. 4), coefficients as a random walk, H = [I3 0]. FilterPy runs
one problem step by step with a hand-written model and its analytic
Jacobians (``predict_x`` overridden with the nonlinear step, ``F`` set to the Jacobian, its
Joseph-form update); trackkit runs ``identify`` batched over ``--runs`` runs. Before timing,
trackkit's first run (in the batch) is checked against FilterPy's, sample by sample.

Rows: ``identify(filter="ekf")`` (the EKF by blocks of F = [[A, B], [0, I]], compiled:
``trackkit.identify.fused``; timed after a first call, which compiles or loads the kernel),
the generic ``trackkit.filters.EKF()``, ``UKF()`` and ``CKF()`` on the same model, the
compiled EKF with ten Euler sub-steps per sample, the default identifier (fifty sub-steps,
the inputs at their ends, its default Q), and batch least squares. Ratio =
FilterPy's time per step / trackkit's time per run-step. Best of ``--repeat``, FilterPy and
trackkit timed in turn.

    python benchmarks/bench_vessel.py [--runs 1000] [--steps 200] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

import trackkit as tk
from trackkit.identify import DEFAULT_SUBSTEPS, identify, least_squares, programme

L, U0, N0 = 19.6, 18.0 * 1852.0 / 3600.0, 2000.0
Q_BODY = np.array([3e-4, 3e-4, 3e-6])
D = np.array([U0**2 / L, U0**2 / L, U0**2 / L**2])  # SI rate per prime rate
DX = np.array([1 / U0, 1 / U0, L / U0])  # prime state per SI state


def _step_and_jacobian(xa: np.ndarray, s: np.ndarray, T: float):
    """Euler step of eq. 2 (prime coefficients, SI states) and its 19 x 19 Jacobian."""
    u, v, r = xa[0] / U0, xa[1] / U0, xa[2] * L / U0
    d, n = s[0], s[1] / N0
    a1, a2, a3, a4, a5, a6, a7, a8, a9, b1, b2, b3, b4, c1, c2, c3 = xa[3:]
    reg = np.zeros((3, 16))
    reg[0, :9] = (u * u, v * v, r * r, d * d, v * r, v * d, r * d, u * n, n * n)
    reg[1, 9:13] = (v, r, d, u * r)
    reg[2, 13:] = (v, r, d)
    J = np.array([[2 * a1 * u + a8 * n, 2 * a2 * v + a5 * r + a6 * d,
                   2 * a3 * r + a5 * v + a7 * d],
                  [b4 * r, b1, b2 + b4 * u],
                  [0.0, c1, c2]])
    F = np.eye(19)
    F[:3, :3] += T * (D[:, None] * J * DX[None, :])
    F[:3, 3:] = T * (D[:, None] * reg)
    x1 = xa.copy()
    x1[:3] += T * D * (reg @ xa[3:])
    return x1, F


class _VesselEKF(ExtendedKalmanFilter):
    def predict_x(self, u=0):
        self.x = self.next_x


def filterpy_run(z, s, starts, T, sigma, steps):
    """FilterPy over one run: ``(seconds, means (K, 19), stds (K, 19))``."""
    ekf = _VesselEKF(dim_x=19, dim_z=3)
    ekf.R = np.diag(sigma**2)
    ekf.Q = T * np.diag(np.concatenate([Q_BODY, np.zeros(16)]))
    H = np.hstack([np.eye(3), np.zeros((3, 16))])

    def HJ(x):
        return H

    def hx(x):
        return x[:3]

    means, stds = np.empty((steps, 19)), np.empty((steps, 19))
    t0 = time.perf_counter()
    for k in range(steps):
        if starts[k]:  # a trial's start: body states from the measurement
            x = np.concatenate([z[k], np.zeros(16)]) if k == 0 else ekf.x.copy()
            P = np.diag(np.r_[sigma**2, np.ones(16)]) if k == 0 else ekf.P.copy()
            x[:3] = z[k]
            P[:3, :] = 0.0
            P[:, :3] = 0.0
            P[:3, :3] = ekf.R
            ekf.x, ekf.P = x, P
        else:
            ekf.next_x, ekf.F = _step_and_jacobian(ekf.x, 0.5 * (s[k - 1] + s[k]), T)
            ekf.predict()
            ekf.update(z[k], HJ, hx)
        means[k] = ekf.x
        stds[k] = np.sqrt(np.diag(ekf.P))
    return time.perf_counter() - t0, means, stds


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3, help="best of this many timings")
    a = ap.parse_args()
    rec = programme(a.runs, seed=2025)
    K = min(a.steps, rec.t.size)
    z, s, starts, sigma = rec.z[:, :K], rec.s[:, :K], rec.starts[:K], rec.noise.body
    kw = dict(starts=starts, sigma_z=sigma, q_body=Q_BODY, substeps=1)
    # the default identifier takes the inputs at its sub-steps' ends (a log's measured ones;
    # here the samples' interpolated, which costs the same)
    t_sub = np.linspace(0.0, K - 1.0, (K - 1) * DEFAULT_SUBSTEPS + 1)
    s_sub = np.stack([np.stack([np.interp(t_sub, np.arange(K), s[r, :, j]) for j in range(2)],
                               -1) for r in range(a.runs)])
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, numpy {np.__version__}")
    print(f"vessel identification, 19 states, {K} samples (T = 1 s, {int(starts.sum())} "
          f"trial starts); trackkit batched over {a.runs} runs\n")

    # first: trackkit's first run (in the batch) is FilterPy's
    _, ours = timed(lambda: identify(z, s, rec.dt, **kw))
    _, fp_mean, fp_std = filterpy_run(z[0], s[0], starts, rec.dt, sigma, K)
    mean0 = np.concatenate([ours.body[0], ours.theta_history[0]], -1)
    std0 = np.concatenate([ours.body_std[0], ours.theta_std[0]], -1)
    dm = np.abs(mean0 - fp_mean) / fp_std
    ds = np.abs(std0 - fp_std) / fp_std
    print(f"check, run 0 against FilterPy over {K} samples: max |mean difference| = "
          f"{dm.max():.1e} sd, max relative sd difference = {ds.max():.1e}")
    if not (dm.max() < 1e-9 and ds.max() < 1e-9):
        raise SystemExit("trackkit's first run differs from FilterPy's")

    rows = {
        "EKF, `identify(filter=\"ekf\")` (by blocks, compiled)": lambda: identify(
            z, s, rec.dt, **kw),
        "EKF, generic `tk.filters.EKF()`": lambda: identify(z, s, rec.dt, filter=tk.filters.EKF(),
                                                             **kw),
        "UKF, `tk.filters.UKF()`": lambda: identify(z, s, rec.dt, filter="ukf", **kw),
        "CKF, `tk.filters.CKF()`": lambda: identify(z, s, rec.dt, filter="ckf", **kw),
        "EKF by blocks, compiled, 10 sub-steps per sample": lambda: identify(
            z, s, rec.dt, **(kw | {"substeps": 10})),
        f"EKF by blocks, compiled, the default: {DEFAULT_SUBSTEPS} sub-steps, inputs at "
        "their ends": lambda: identify(z, s_sub, rec.dt, starts=starts, sigma_z=sigma),
        "batch least squares (QR, three equations)": lambda: least_squares(
            z, s, rec.dt, starts=starts),
    }
    t_fp = float("inf")
    best = dict.fromkeys(rows, float("inf"))
    for _ in range(a.repeat):  # in turn: a change of machine load hits all alike
        t_fp = min(t_fp, filterpy_run(z[0], s[0], starts, rec.dt, sigma, K)[0])
        for name, fn in rows.items():
            best[name] = min(best[name], timed(fn)[0])
    steps = K - 1  # transitions per run (the starts are re-initialisations, cheap for both)
    fp = t_fp / steps
    print(f"FilterPy ExtendedKalmanFilter, one run: {fp * 1e6:.1f} us per step "
          f"({t_fp * 1e3:.1f} ms for {steps} steps)\n")
    print("| method | runs | total s | us per run-step | ms per run-step | ratio vs FilterPy |")
    print("|---|---|---|---|---|---|")
    print(f"| FilterPy `ExtendedKalmanFilter` | 1 | {t_fp:.3f} | {fp * 1e6:.1f} | "
          f"{fp * 1e3:.4f} | 1x |")
    for name, t in best.items():
        per = t / (a.runs * steps)
        print(f"| {name} | {a.runs} | {t:.3f} | {per * 1e6:.2f} | {per * 1e3:.5f} | "
              f"{fp / per:.1f}x |")
    print("\ntarget: >= 100x per run-step for the batched EKF")


if __name__ == "__main__":
    main()
