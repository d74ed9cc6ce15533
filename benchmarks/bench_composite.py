"""Composite measurement (seed 004) speed against ``scipy.optimize.least_squares``, in one
process.

Each problem: a CV target seen by two sensors 15 km apart (one heading north at 5 m/s, one
west at 4 m/s), ``--bearings`` bearings at random times over 300 s (2 degree noise), the
reference time t_f in the middle of the window, and an initial guess off by about 500 m and
2 m/s. trackkit estimates all ``--problems`` problems in one batched call of
``composite_measurement`` (default tol: the Gauss-Newton step below 1e-8 standard
deviations); scipy runs ``least_squares`` on each problem in turn, on the same whitened,
wrapped residuals, with the analytic Jacobian (so that it spends nothing on differences), from
the same guess, with ``xtol = ftol = gtol = 1e-10``, once with ``method="lm"`` (MINPACK, its
fastest here) and once with its default ``"trf"``. Before timing, the script checks that both
reach the same estimates (to 1e-6 relative). Times are the best of ``--repeat``, scipy and
trackkit in turn.

    python benchmarks/bench_composite.py [--problems 1000] [--bearings 30] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
import scipy
from scipy.optimize import least_squares

from trackkit.network.composite import CONVERGED, composite_measurement

SIGMA = np.deg2rad(2.0)
T_END, T_F = 300.0, 150.0
SCIPY_TOL = 1e-10


def problems(n: int, m: int, seed: int = 0):
    """``n`` problems of ``m`` bearings: z (n, m), t (n, m), sensor positions (n, m, 2),
    initial guesses (n, 4) and the true states at t_f (n, 4)."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, T_END, (n, m)), axis=1)
    second = np.arange(m) % 2 == 1
    S = np.zeros((n, m, 2))
    S[..., 0] = np.where(second, 15000.0 - 4.0 * t, 0.0)
    S[..., 1] = np.where(second, 0.0, 5.0 * t)
    x = np.array([5000.0, 12000.0, -4.0, 6.0]) + rng.normal(0, [300, 300, 1, 1], (n, 4))
    d = x[:, None, :2] + t[..., None] * x[:, None, 2:] - S
    z = np.arctan2(d[..., 0], d[..., 1]) + SIGMA * rng.standard_normal((n, m))
    x_f = x + np.c_[T_F * x[:, 2:], np.zeros((n, 2))]
    x0 = x_f + rng.normal(0, [500, 500, 2, 2], (n, 4))
    return z, t, S, x0, x_f


def scipy_one(z, t, S, x0, method: str):
    """``least_squares`` on one problem: whitened wrapped residuals, analytic Jacobian."""
    dt = t - T_F

    def fun(x):
        d = x[:2] + dt[:, None] * x[2:] - S
        r = np.arctan2(d[:, 0], d[:, 1]) - z
        return (r - 2 * np.pi * np.round(r / (2 * np.pi))) / SIGMA

    def jac(x):
        d = x[:2] + dt[:, None] * x[2:] - S
        q = 1.0 / (SIGMA * (d * d).sum(1))
        a, b = d[:, 1] * q, -d[:, 0] * q
        return np.column_stack([a, b, a * dt, b * dt])

    return least_squares(fun, x0, jac=jac, method=method, xtol=SCIPY_TOL, ftol=SCIPY_TOL,
                         gtol=SCIPY_TOL)


def time_scipy(data, method: str, count: int) -> float:
    z, t, S, x0, _ = data
    t0 = time.perf_counter()
    for i in range(count):
        scipy_one(z[i], t[i], S[i], x0[i], method)
    return (time.perf_counter() - t0) / count


def time_trackkit(data) -> float:
    z, t, S, x0, _ = data
    t0 = time.perf_counter()
    composite_measurement(z, t, S, SIGMA, T_F, x0)
    return (time.perf_counter() - t0) / len(z)


def check_agreement(data, count: int = 50) -> float:
    """Largest difference of the estimates over the first ``count`` problems, relative to
    the largest component of the state, for both scipy methods."""
    z, t, S, x0, _ = data
    c = composite_measurement(z[:count], t[:count], S[:count], SIGMA, T_F, x0[:count])
    assert (c.status == CONVERGED).all()
    worst = 0.0
    for method in ("lm", "trf"):
        for i in range(count):
            x = scipy_one(z[i], t[i], S[i], x0[i], method).x
            worst = max(worst, float(np.abs(x - c.mean[i]).max() / np.abs(x).max()))
    assert worst < 1e-6, worst
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=1000)
    ap.add_argument("--bearings", type=int, default=30)
    ap.add_argument("--scipy-problems", type=int, default=200,
                    help="problems scipy solves per timing (its time per problem is flat)")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many timings")
    a = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}")
    data = problems(a.problems, a.bearings)
    c = composite_measurement(data[0], data[1], data[2], SIGMA, T_F, data[3])
    print(f"composite measurement: {a.problems} problems x {a.bearings} bearings, "
          f"{np.mean(c.iterations):.1f} steps per problem (max {c.iterations.max()}), "
          f"{np.mean(c.status == CONVERGED):.1%} converged")
    worst = check_agreement(data)
    print(f"trackkit's estimates equal scipy's (lm and trf) to {worst:.1e} relative")
    n_sp = min(a.scipy_problems, a.problems)
    best = {"lm": float("inf"), "trf": float("inf"), "trackkit": float("inf")}
    for _ in range(a.repeat):  # interleaved: a change of machine load hits all alike
        for method in ("lm", "trf"):
            best[method] = min(best[method], time_scipy(data, method, n_sp))
        best["trackkit"] = min(best["trackkit"], time_trackkit(data))
    tk_us = best["trackkit"] * 1e6
    print(f"{'solver':>28s} {'us/problem':>11s} {'ratio':>7s}")
    for method in ("lm", "trf"):
        us = best[method] * 1e6
        print(f"{'least_squares ' + method + ' (1 by 1)':>28s} {us:11.1f} {us / tk_us:6.0f}x")
    print(f"{'trackkit batched':>28s} {tk_us:11.2f} {'1':>6s}x")


if __name__ == "__main__":
    main()
