"""The particle filter converges to the Kalman filter on a linear-Gaussian problem.

2-D nearly-constant-velocity target (q = 0.5), position measurements (sigma 3 m), 3 steps of
1 s from the prior N([0, 0, 1, 0], diag(1, 1, 0.25, 0.25)); one fixed measurement sequence,
so the KF posterior is one fixed Gaussian N(m, P) and the PF's error is Monte Carlo error
alone. R independent PF replications are one batched filter (rows), for N = 500, 2 000,
8 000 and 32 000 particles (R = 2 000, 500, 200, 64).

For each N the normalised errors

    e_m = (m_PF - m)^T P^{-1} (m_PF - m),   e_P = |L^{-1} (P_PF - P) L^{-T}|_F^2  (L L^T = P)

are averaged over the replications. Monte Carlo theory (a central limit theorem for particle
filters with resampling, Chopin 2004) says both means are c / N with c fixed: the error of the
mean and of the covariance shrinks as 1 / sqrt(N). The test fits log E[e] = a + beta log N by
weighted least squares (variances of log E[e] from the sample, delta method) and requires
|beta + 1| < 4 standard errors of beta; the standard error itself must be below 0.05, so the
test can tell -1 from, say, -0.8 (a floor from a bias) or -1.2. With a fresh seed a correct
filter fails either check with probability about 1e-4 (two slopes at |z| < 4). The normalised
errors have a coefficient of variation of about 0.7 (mean) and 0.5 (covariance), measured.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.filters.particle import PF

pytestmark = pytest.mark.slow

MOTION = tk.models.ConstantVelocity(dim=2, q=0.5)
SENSOR = tk.models.Position(dim=2, sigma=3.0)
M0 = np.array([0.0, 0.0, 1.0, 0.0])
P0 = np.diag([1.0, 1.0, 0.25, 0.25])
STEPS = 3
RUNS = {500: 2000, 2000: 500, 8000: 200, 32000: 64}


def measurements() -> list[np.ndarray]:
    rng = np.random.default_rng(77)
    x = M0 + np.linalg.cholesky(P0) @ rng.standard_normal(4)
    L = np.linalg.cholesky(MOTION.noise(None, 1.0))
    zs = []
    for _ in range(STEPS):
        x = MOTION.f(x, 1.0) + L @ rng.standard_normal(4)
        zs.append(x[:2] + 3.0 * rng.standard_normal(2))
    return zs


def kalman(zs) -> tk.Gaussian:
    kf = tk.filters.KF()
    g = tk.Gaussian(M0, P0)
    for z in zs:
        g = kf.predict(g, MOTION, 1.0)
        g, _ = kf.update(g, z, SENSOR)
    return g


def normalised_errors(N: int, R: int, zs, g: tk.Gaussian) -> tuple[np.ndarray, np.ndarray]:
    f = PF(N)
    b = f.init(tk.Gaussian(np.tile(M0, (R, 1)), np.broadcast_to(P0, (R, 4, 4)).copy()),
               rng=np.random.default_rng(N))
    for z in zs:
        b = f.predict(b, MOTION, 1.0)
        b, _ = f.update(b, np.broadcast_to(z, (R, 2)), SENSOR)
    est = f.estimate(b)
    L = np.linalg.cholesky(g.cov)
    u = np.linalg.solve(L, (est.mean - g.mean)[..., None])[..., 0]
    D = np.linalg.solve(L, np.linalg.solve(L, est.cov - g.cov).mT)
    return (u * u).sum(-1), (D * D).sum((-2, -1))


@pytest.fixture(scope="module")
def errors():
    zs = measurements()
    g = kalman(zs)
    return {N: normalised_errors(N, R, zs, g) for N, R in RUNS.items()}


def slope(Ns, samples) -> tuple[float, float, np.ndarray]:
    """Weighted least-squares slope of log(mean) against log(N), its standard error, and
    the means."""
    means = np.array([s.mean() for s in samples])
    se_log = np.array([s.std(ddof=1) / np.sqrt(s.size) for s in samples]) / means
    x, y, w = np.log(Ns), np.log(means), 1 / se_log**2
    xb = (w * x).sum() / w.sum()
    beta = (w * (x - xb) * (y - (w * y).sum() / w.sum())).sum() / (w * (x - xb) ** 2).sum()
    return beta, 1 / np.sqrt((w * (x - xb) ** 2).sum()), means


@pytest.mark.parametrize("what", [0, 1], ids=["mean", "covariance"])
def test_error_shrinks_as_one_over_n(errors, what):
    Ns = np.array(list(RUNS))
    beta, se, means = slope(Ns, [errors[N][what] for N in Ns])
    assert se < 0.05, se
    assert abs(beta + 1) < 4 * se, (beta, se, means * Ns)


def test_pf_is_close_to_the_kf_at_many_particles(errors):
    """At 32 000 particles the PF's mean is within a few hundredths of the KF's standard
    deviations and its covariance within a few percent: E[e_m] and E[e_P] are below 2e-3 and
    6e-3 (c / N with the c measured at every N: about 13 and 45)."""
    e_m, e_P = errors[32000]
    assert e_m.mean() < 2e-3 and e_P.mean() < 6e-3
