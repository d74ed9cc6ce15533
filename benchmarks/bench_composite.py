"""Composite measurement (Jalalipoor and Kardehi Moghaddam 2021) speed and agreement against
``scipy.optimize.least_squares``, in one process, on two problem families.

``crossing`` (the family of the first measurement): a CV target seen by two sensors 15 km
apart (one heading north at 5 m/s, one west at 4 m/s), ``--bearings`` bearings at random
times over 300 s (2 degree noise), the reference time t_f in the middle of the window, and an
initial guess off by about 500 m and 2 m/s.

``turning`` (``turning_problems``): two or three observers, each starting in a 10 km square
at 5-10 m/s on a random heading and turning once (45-135 degrees either way, at 30-70% of
the window); a CV target 10-20 km from the square's centre at 3-10 m/s on a random heading;
10-30 bearings (uniform) at random times over 600 s, each from a random observer, 1 degree
noise; t_f at the end of the window; the initial guess off by about 500 m and 2 m/s. Rows
hold different numbers of bearings (nan-padded to 30 for trackkit's batch).

trackkit estimates all problems of a family in one batched call of
``composite_measurement`` (default tol: the Gauss-Newton step below 1e-8 standard
deviations); scipy runs ``least_squares`` on each problem in turn, on the same whitened,
wrapped residuals, from the same guess:

* ``default``: ``least_squares(fun, x0)`` as it comes (``trf``, 2-point differences,
  tolerances 1e-8);
* ``trf`` and ``lm``: the analytic Jacobian (so that they spend nothing on differences),
  ``xtol = ftol = gtol = 1e-10``.

Agreement is against a tight reference, ``least_squares`` with ``trf``, its own 3-point
Jacobian, ``x_scale="jac"`` and tolerances 1e-15 (the oracle of
``tests/network/test_composite.py``), over the rows trackkit reports CONVERGED: the largest
difference relative to the largest component of the state, and in standard deviations,
``|x_tk - x_ref| / sqrt(diag(J^-1))`` (J^-1 trackkit's CRLB at its estimate). Rows not
converged are counted, with their largest relative difference (they are flagged, not
compared). The timed scipy runs' own agreement is printed too (their tolerances stop them
short of the optimum). Times are the best of ``--repeat``, scipy and trackkit in turn, by the
wall clock and by the process's CPU time.

    python benchmarks/bench_composite.py [--problems 1000] [--bearings 30] [--repeat 3]
        [--turning-problems 500] [--family both|crossing|turning]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from typing import NamedTuple

import numpy as np
import scipy
from scipy.optimize import least_squares

from trackkit.network.composite import CONVERGED, STATUS_NAMES, composite_measurement

SIGMA = np.deg2rad(2.0)
T_END, T_F = 300.0, 150.0
SCIPY_TOL = 1e-10
REF_TOL = 1e-15


class Family(NamedTuple):
    """Problems of one family: z (n, M) (nan: no bearing), t (n, M), sensor positions
    (n, M, 2), initial guesses (n, 4), the bearing noise and t_f."""

    name: str
    z: np.ndarray
    t: np.ndarray
    S: np.ndarray
    x0: np.ndarray
    sigma: float
    t_f: float

    def row(self, i: int):
        """Problem i's bearings, times and sensor positions (present bearings only)."""
        ok = ~np.isnan(self.z[i])
        return self.z[i, ok], self.t[i, ok], self.S[i, ok]


def problems(n: int, m: int, seed: int = 0) -> Family:
    """``n`` crossing problems of ``m`` bearings (module docstring)."""
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
    return Family("crossing", z, t, S, x0, SIGMA, T_F)


def _turning_observers(rng, n: int, T: float, t: np.ndarray, which: np.ndarray) -> np.ndarray:
    """Positions (n, M, 2) at times t of observers ``which`` (n, M) of 3 per problem, each
    on one leg then another after a single turn within the window [0, T]."""
    p0 = rng.uniform(-5000.0, 5000.0, (n, 3, 2))
    speed = rng.uniform(5.0, 10.0, (n, 3))
    h0 = rng.uniform(0.0, 2 * np.pi, (n, 3))
    h1 = h0 + rng.uniform(np.pi / 4, 3 * np.pi / 4, (n, 3)) * rng.choice([-1.0, 1.0], (n, 3))
    t_turn = rng.uniform(0.3, 0.7, (n, 3)) * T

    def velocity(h):
        return speed[..., None] * np.stack([np.sin(h), np.cos(h)], -1)

    rows = np.arange(n)[:, None]
    v0, v1 = velocity(h0)[rows, which], velocity(h1)[rows, which]
    tt = t_turn[rows, which]
    return (p0[rows, which] + v0 * np.minimum(t, tt)[..., None]
            + v1 * np.maximum(t - tt, 0.0)[..., None])


def turning_problems(n: int, seed: int = 1, T: float = 600.0, sigma_deg: float = 1.0,
                     m_max: int = 30) -> Family:
    """``n`` turning-observer problems (module docstring), t_f = T."""
    rng = np.random.default_rng(seed)
    sigma = np.deg2rad(sigma_deg)
    t = np.sort(rng.uniform(0.0, T, (n, m_max)), axis=1)
    observers = rng.integers(2, 4, n)
    which = rng.integers(0, 6, (n, m_max)) % observers[:, None]
    S = _turning_observers(rng, n, T, t, which)
    r, b = rng.uniform(10000.0, 20000.0, n), rng.uniform(0.0, 2 * np.pi, n)
    s, h = rng.uniform(3.0, 10.0, n), rng.uniform(0.0, 2 * np.pi, n)
    x = np.c_[r * np.sin(b), r * np.cos(b), s * np.sin(h), s * np.cos(h)]
    d = x[:, None, :2] + t[..., None] * x[:, None, 2:] - S
    z = np.arctan2(d[..., 0], d[..., 1]) + sigma * rng.standard_normal((n, m_max))
    m = rng.integers(10, m_max + 1, n)
    z[~rng.permuted(np.arange(m_max) < m[:, None], axis=1)] = np.nan
    x_f = x + np.c_[T * x[:, 2:], np.zeros((n, 2))]
    x0 = x_f + rng.normal(0, [500, 500, 2, 2], (n, 4))
    return Family("turning", z, t, S, x0, sigma, T)


def _residuals(z, t, S, sigma, t_f):
    """The whitened wrapped residuals and their analytic Jacobian of one problem."""
    dt = t - t_f

    def fun(x):
        d = x[:2] + dt[:, None] * x[2:] - S
        r = np.arctan2(d[:, 0], d[:, 1]) - z
        return (r - 2 * np.pi * np.round(r / (2 * np.pi))) / sigma

    def jac(x):
        d = x[:2] + dt[:, None] * x[2:] - S
        q = 1.0 / (sigma * (d * d).sum(1))
        a, b = d[:, 1] * q, -d[:, 0] * q
        return np.column_stack([a, b, a * dt, b * dt])

    return fun, jac


#: scipy's solvers as timed and as the reference: least_squares keyword arguments
SOLVERS = {
    "default": {},
    "trf": dict(method="trf", xtol=SCIPY_TOL, ftol=SCIPY_TOL, gtol=SCIPY_TOL),
    "lm": dict(method="lm", xtol=SCIPY_TOL, ftol=SCIPY_TOL, gtol=SCIPY_TOL),
    "reference": dict(method="trf", jac="3-point", x_scale="jac", xtol=REF_TOL,
                      ftol=REF_TOL, gtol=REF_TOL),
}


def scipy_one(fam: Family, i: int, solver: str):
    """``least_squares`` on problem i with one of ``SOLVERS``."""
    fun, jac = _residuals(*fam.row(i), fam.sigma, fam.t_f)
    kw = dict(SOLVERS[solver])
    if solver in ("trf", "lm"):
        kw["jac"] = jac
    return least_squares(fun, fam.x0[i], **kw)


def solve(fam: Family):
    return composite_measurement(fam.z, fam.t, fam.S, fam.sigma, fam.t_f, fam.x0)


def _clocks() -> np.ndarray:
    return np.array([time.perf_counter(), time.process_time()])


def time_scipy(fam: Family, solver: str, count: int) -> np.ndarray:
    """(wall, CPU) seconds per problem."""
    t0 = _clocks()
    for i in range(count):
        scipy_one(fam, i, solver)
    return (_clocks() - t0) / count


def time_trackkit(fam: Family) -> np.ndarray:
    """(wall, CPU) seconds per problem."""
    t0 = _clocks()
    solve(fam)
    return (_clocks() - t0) / len(fam.z)


def agreement(fam: Family, c, solver: str, count: int) -> tuple[float, float, float]:
    """Over the first ``count`` problems: the largest relative and standard-deviation
    differences of the CONVERGED rows from ``solver``'s estimates, and the largest relative
    difference of the others (0 if none)."""
    X = np.array([scipy_one(fam, i, solver).x for i in range(count)])
    mean, ok = c.mean[:count], c.status[:count] == CONVERGED
    rel = np.abs(X - mean).max(1) / np.abs(X).max(1)
    sd = np.sqrt(np.diagonal(c.cov[:count], 0, -2, -1))
    with np.errstate(invalid="ignore"):
        sig = (np.abs(X - mean) / sd).max(1)
    flagged = float(rel[~ok].max()) if (~ok).any() else 0.0
    return float(rel[ok].max()), float(sig[ok].max()), flagged


def check_agreement(fam: Family, count: int = 50) -> float:
    """The crossing family: every row converges and equals scipy's lm and trf (with the
    analytic Jacobian, tolerances 1e-10) to 1e-6 relative; returns the largest difference."""
    c = composite_measurement(fam.z[:count], fam.t[:count], fam.S[:count], fam.sigma,
                              fam.t_f, fam.x0[:count])
    assert (c.status == CONVERGED).all()
    worst = max(agreement(fam, c, s, count)[0] for s in ("lm", "trf"))
    assert worst < 1e-6, worst
    return worst


def timings(fam: Family, solvers: tuple[str, ...], count: int, repeat: int) -> None:
    """Best of ``repeat`` interleaved timings (a change of machine load hits all alike), by
    the wall clock and by the process's CPU time (the steadier of the two on a loaded
    machine)."""
    best = {k: np.full(2, np.inf) for k in solvers + ("trackkit",)}
    for _ in range(repeat):
        for s in solvers:
            best[s] = np.minimum(best[s], time_scipy(fam, s, count))
        best["trackkit"] = np.minimum(best["trackkit"], time_trackkit(fam))
    tk = best["trackkit"] * 1e6
    print(f"{'solver':>36s} {'wall us':>9s} {'ratio':>6s} {'CPU us':>9s} {'ratio':>6s}")
    for s in solvers:
        us = best[s] * 1e6
        print(f"{'least_squares ' + s + ' (1 by 1)':>36s} {us[0]:9.1f} {us[0] / tk[0]:5.0f}x "
              f"{us[1]:9.1f} {us[1] / tk[1]:5.0f}x")
    print(f"{'trackkit batched':>36s} {tk[0]:9.2f} {'1':>5s}x {tk[1]:9.2f} {'1':>5s}x")


def report_agreement(fam: Family, c, solvers: tuple[str, ...], count: int) -> None:
    print(f"agreement over the first {count} problems:")
    for s in solvers:
        rel, sig, flagged = agreement(fam, c, s, count)
        print(f"against {s:>9s}: converged rows to {rel:.1e} relative, {sig:.1e} standard "
              f"deviations; the other rows differ by up to {flagged:.1e} relative")


def crossing(a) -> None:
    fam = problems(a.problems, a.bearings)
    c = solve(fam)
    print(f"\ncrossing: {a.problems} problems x {a.bearings} bearings, "
          f"{np.mean(c.iterations):.1f} steps per problem (max {c.iterations.max()}), "
          f"{np.mean(c.status == CONVERGED):.1%} converged")
    worst = check_agreement(fam)
    print(f"trackkit's estimates equal scipy's (lm and trf) to {worst:.1e} relative")
    report_agreement(fam, c, ("reference", "trf", "lm"), min(a.scipy_problems, a.problems))
    timings(fam, ("lm", "trf"), min(a.scipy_problems, a.problems), a.repeat)


def turning(a) -> None:
    fam = turning_problems(a.turning_problems)
    n = len(fam.z)
    c = solve(fam)
    counts = ", ".join(f"{np.sum(c.status == k)} {name}" for k, name in STATUS_NAMES.items())
    m = (~np.isnan(fam.z)).sum(1)
    print(f"\nturning: {n} problems of {m.min()}-{m.max()} bearings, "
          f"{np.mean(c.iterations):.1f} steps per problem (max {c.iterations.max()}); {counts}")
    report_agreement(fam, c, ("reference", "default", "trf", "lm"), n)
    timings(fam, ("default", "trf", "lm"), min(a.scipy_problems, n), a.repeat)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=1000)
    ap.add_argument("--bearings", type=int, default=30)
    ap.add_argument("--turning-problems", type=int, default=500)
    ap.add_argument("--family", choices=("both", "crossing", "turning"), default="both")
    ap.add_argument("--scipy-problems", type=int, default=200,
                    help="problems scipy solves per timing (its time per problem is flat)")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many timings")
    a = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}"
          f", load average {os.getloadavg()[0]:.1f}")
    if a.family in ("both", "crossing"):
        crossing(a)
    if a.family in ("both", "turning"):
        turning(a)


if __name__ == "__main__":
    main()
