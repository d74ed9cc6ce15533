"""How fast a bootstrap PF step can be on one core: a whole step compiled, against Stone Soup.

The problem of ``bench_jtc.py``'s "PF at 5000" row (and of ``bench_particle.py``'s
range-bearing rows): a nearly-constant-velocity target, 1 s steps, a range-bearing radar at the
origin (20 m, 0.2 deg), 5 000 particles per run, 100 runs, resampled systematically at every
step. The step below is written once, for this problem only, in the leanest form we know: one
compiled pass per run (numba, no fastmath) that draws the four normals of each particle from
the generator, predicts it (``F x + L e`` with the structural zeros of F and L skipped),
computes its range, bearing and log-likelihood, then the weights (one exp each), systematic
resampling by a cumulative histogram, the gather and the estimate's mean and covariance. No
checks, no missing measurements, no angle care beyond wrapping the bearing residual. It is a
lower bound for a general filter on one core, not a filter: trackkit does not use it.

    python benchmarks/floor_particle.py [--runs 100] [--particles 5000] [--repeat 7]
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import numpy as np

SIGMA_R, SIGMA_B = 20.0, math.radians(0.2)


@numba.njit(error_model="numpy")
def _move_and_weigh(rng, X, r, F, L, z, Linv, const, Y, a) -> float:
    """Predict row r's particles into Y and their log-likelihoods into a; returns the max."""
    top = -np.inf
    for i in range(X.shape[1]):
        e0, e1 = rng.standard_normal(), rng.standard_normal()
        e2, e3 = rng.standard_normal(), rng.standard_normal()
        x0, x1, x2, x3 = X[r, i, 0], X[r, i, 1], X[r, i, 2], X[r, i, 3]
        y0 = F[0, 0] * x0 + F[0, 2] * x2 + L[0, 0] * e0 + L[0, 2] * e2
        y1 = F[1, 1] * x1 + F[1, 3] * x3 + L[1, 1] * e1 + L[1, 3] * e3
        y2 = x2 + L[2, 0] * e0 + L[2, 2] * e2
        y3 = x3 + L[3, 1] * e1 + L[3, 3] * e3
        Y[i, 0], Y[i, 1], Y[i, 2], Y[i, 3] = y0, y1, y2, y3
        dr = z[r, 0] - math.hypot(y0, y1)
        db = z[r, 1] - math.atan2(y1, y0)
        db -= 2.0 * math.pi * round(db / (2.0 * math.pi))
        u0, u1 = Linv[0, 0] * dr, Linv[1, 0] * dr + Linv[1, 1] * db
        a[i] = -0.5 * (u0 * u0 + u1 * u1) - const
        top = max(top, a[i])
    return top


@numba.njit(error_model="numpy")
def _resample_and_estimate(rng, r, Y, a, top, out, m, P) -> None:
    N = Y.shape[0]
    c, h = np.empty(N), np.zeros(N + 1, dtype=np.int64)
    total = 0.0
    for i in range(N):
        total += math.exp(a[i] - top)
        c[i] = total
    U = rng.random()
    for i in range(N):
        h[min(max(math.ceil(c[i] / total * N - U), 0), N)] += 1
    k = 0
    for j in range(N):
        k += h[j]
        i = min(k, N - 1)
        for q in range(4):
            out[r, j, q] = Y[i, q]
    for q in range(4):
        s = 0.0
        for j in range(N):
            s += out[r, j, q]
        m[r, q] = s / N
    for q in range(4):
        for p in range(q + 1):
            s = 0.0
            for j in range(N):
                s += (out[r, j, q] - m[r, q]) * (out[r, j, p] - m[r, p])
            P[r, q, p] = s / N


@numba.njit(error_model="numpy")
def step(rng, X, F, L, z, Linv, const, out, m, P) -> None:
    """One predict-update-resample-estimate of every run's particles ``X (R, N, 4)``."""
    R, N, _ = X.shape
    Y, a = np.empty((N, 4)), np.empty(N)
    for r in range(R):
        top = _move_and_weigh(rng, X, r, F, L, z, Linv, const, Y, a)
        _resample_and_estimate(rng, r, Y, a, top, out, m, P)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--particles", type=int, default=5000)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    R, N = args.runs, args.particles
    g = np.random.default_rng(0)
    x0 = np.array([5000.0, 3000.0, -300.0, 100.0])
    X = x0 + g.standard_normal((R, N, 4)) * [50.0, 50.0, 10.0, 10.0]
    F = np.array([[1.0, 0, 1, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]])
    L = np.linalg.cholesky(np.array([[1 / 3, 0, 1 / 2, 0], [0, 1 / 3, 0, 1 / 2],
                                     [1 / 2, 0, 1, 0], [0, 1 / 2, 0, 1]]))
    z = np.tile([math.hypot(*x0[:2]), math.atan2(x0[1], x0[0])], (R, 1))
    Lc = np.diag([SIGMA_R, SIGMA_B])
    Linv, const = np.linalg.inv(Lc), float(np.log(np.diag(Lc)).sum() + math.log(2 * math.pi))
    out, m, P = np.empty_like(X), np.empty((R, 4)), np.empty((R, 4, 4))
    step(g, X, F, L, z, Linv, const, out, m, P)  # compile
    best = math.inf
    for _ in range(args.repeat):
        t = time.perf_counter()
        step(g, X, F, L, z, Linv, const, out, m, P)
        best = min(best, time.perf_counter() - t)
    print(f"numba {numba.__version__}, numpy {np.__version__}; {R} runs x {N} particles")
    print(f"a whole PF step compiled: {best / R * 1e6:.1f} us per run-step "
          f"({best / R / N * 1e9:.1f} ns per particle-step)")


if __name__ == "__main__":
    main()
