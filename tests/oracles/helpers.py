"""Shared inputs and comparison for the oracle tests (FilterPy, Stone Soup).

Everything here is written independently of trackkit (hand-written F, Q, h and Jacobians),
so that an oracle test compares trackkit with another library on identical inputs and not
trackkit with itself.

Problems are 2-D constant-velocity targets in trackkit's state ordering ``[x, y, vx, vy]``:

* ``linear``: position measurements ``z = [x, y] + v``;
* ``range_bearing``: ``z = [range, bearing]`` from a moving observer (radar on a ship);
* ``bearings_only``: ``z = [bearing]`` from a manoeuvring observer (passive sonar).

Measurements are stored in trackkit's default order and convention: ``[range, bearing]``
with the nautical bearing ``atan2(dx, dy)``. Tests convert them for an oracle that uses
another convention (Stone Soup: ``[bearing, range]``, bearing ``atan2(dy, dx)``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

__all__ = [
    "RTOL",
    "FLOOR",
    "Problem",
    "make_problem",
    "problem",
    "stack_problems",
    "cv_F",
    "cv_Q",
    "wrap",
    "nautical_to_math",
    "assert_gaussian_close",
]

#: Relative agreement required on every step's mean and covariance.
RTOL = 1e-9
#: Absolute floor, in units of the reference standard deviations: a mean component may differ
#: by ``FLOOR * sigma_i`` and a covariance entry by ``FLOOR * sigma_i * sigma_j`` (that is, a
#: correlation coefficient by FLOOR). Rounding in an update perturbs every component by a
#: fraction of its own spread, so a component whose value passes near zero (a velocity that
#: changes sign; in the linear problem the x-y cross-covariances decay to rounding noise,
#: ~1e-16 sigma_x sigma_y, and are even exactly 0 in some Stone Soup steps) has no meaningful
#: relative error; relative to its spread it still must agree to 1e-11. Observed differences
#: on these problems are below 1e-12 sigma; the factor 10 is headroom for other BLAS builds.
FLOOR = 1e-11


def wrap(a):
    """Wrap to [-pi, pi) (the oracles' own wrap, not trackkit's)."""
    return (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi


def nautical_to_math(b):
    """Clockwise-from-north bearing to counter-clockwise-from-east angle."""
    return wrap(np.pi / 2.0 - np.asarray(b, dtype=float))


def cv_F(dt: float, dim: int = 2) -> np.ndarray:
    """Constant-velocity transition in the ordering [positions..., velocities...]."""
    F = np.eye(2 * dim)
    F[:dim, dim:] = dt * np.eye(dim)
    return F


def cv_Q(dt: float, q: float, dim: int = 2) -> np.ndarray:
    """Continuous white-noise acceleration, ordering [positions..., velocities...]."""
    e = np.eye(dim)
    return q * np.block([[dt**3 / 3 * e, dt**2 / 2 * e], [dt**2 / 2 * e, dt * e]])


def _correlated_cov(sd, rng) -> np.ndarray:
    """A well-conditioned covariance diag(sd) C diag(sd) with moderate correlations |c| < 0.3
    (so that a transposed or permuted formula shows up)."""
    n = len(sd)
    A = rng.uniform(-1.0, 1.0, (n, n))
    C = np.eye(n) + 0.15 * (A + A.T) / 2.0
    np.fill_diagonal(C, 1.0)
    assert np.linalg.eigvalsh(C)[0] > 0.4
    sd = np.asarray(sd, dtype=float)
    return sd[:, None] * C * sd[None, :]


@dataclass(frozen=True)
class Problem:
    """One tracking problem: prior, step lengths, observer track and measurements.

    ``dts[k]`` is the prediction interval before measurement ``k``; ``observer[k]`` is the
    observer position at measurement ``k``; ``z[k]`` is in trackkit's default order and
    nautical convention.
    """

    kind: str
    x0: np.ndarray
    P0: np.ndarray
    dts: np.ndarray
    observer: np.ndarray
    z: np.ndarray
    truth: np.ndarray
    q: float
    sigma: tuple[float, ...]

    @property
    def T(self) -> int:
        return len(self.dts)

    @property
    def dim_z(self) -> int:
        return self.z.shape[-1]


def _observer_track(path: str, times: np.ndarray, rng) -> np.ndarray:
    if path == "static":
        return np.zeros((len(times), 2))
    if path == "circle":
        # a circle of radius ~4 km around the target area: bearings sweep through every
        # direction, so both the nautical and the mathematical +-pi cut are crossed.
        radius = rng.uniform(3500.0, 4500.0)
        period = rng.uniform(110.0, 140.0)
        phase = rng.uniform(0.0, 2 * np.pi)
        ang = phase + 2 * np.pi * times / period
        return radius * np.stack([np.cos(ang), np.sin(ang)], -1)
    if path == "zigzag":
        # classic target-motion-analysis legs at 8 m/s, turning every 40 s
        speed, leg = 8.0, 40.0
        h0 = rng.uniform(0.0, 2 * np.pi)
        heading = h0 + np.where((times // leg) % 2 == 0, 0.0, np.pi / 2)
        v = speed * np.stack([np.sin(heading), np.cos(heading)], -1)
        steps = np.diff(np.concatenate([[0.0], times]))
        return np.cumsum(v * steps[:, None], axis=0)
    raise ValueError(path)


def make_problem(kind: str, seed: int, T: int = 150, observer: str | None = None) -> Problem:
    """A fixed-seed problem of the given kind (see the module docstring)."""
    rng = np.random.default_rng(seed)
    dts = rng.uniform(0.6, 1.4, T)
    times = np.cumsum(dts)
    if kind == "linear":
        q, sigma, sd0 = 0.3, (4.0, 6.0), (30.0, 40.0, 4.0, 3.0)
        x_true = np.array([*rng.normal(0.0, 300.0, 2), *rng.normal(0.0, 8.0, 2)])
        observer = observer or "static"
    elif kind == "range_bearing":
        q, sigma, sd0 = 0.05, (15.0, np.deg2rad(0.8)), (200.0, 250.0, 3.0, 4.0)
        x_true = np.array([*rng.normal(0.0, 400.0, 2), *rng.normal(0.0, 4.0, 2)])
        observer = observer or "circle"
    elif kind == "bearings_only":
        q, sigma, sd0 = 0.01, (np.deg2rad(1.0),), (600.0, 700.0, 2.0, 2.5)
        observer = observer or "zigzag"
        if observer == "circle":
            x_true = np.array([*rng.normal(0.0, 400.0, 2), *rng.normal(0.0, 3.0, 2)])
        else:
            r, b = rng.uniform(5000.0, 7000.0), rng.uniform(0.0, 2 * np.pi)
            x_true = np.array([r * np.sin(b), r * np.cos(b), *rng.normal(0.0, 4.0, 2)])
    else:
        raise ValueError(kind)
    obs = _observer_track(observer, times, rng)
    P0 = _correlated_cov(sd0, rng)
    x0 = x_true + np.linalg.cholesky(P0) @ rng.standard_normal(4)

    truth, z = np.empty((T, 4)), np.empty((T, len(sigma)))
    x = x_true
    for k, dt in enumerate(dts):
        x = cv_F(dt) @ x + np.linalg.cholesky(cv_Q(dt, q)) @ rng.standard_normal(4)
        truth[k] = x
        d = x[:2] - obs[k]
        if kind == "linear":
            zk = x[:2]
        elif kind == "range_bearing":
            zk = np.array([np.hypot(*d), np.arctan2(d[0], d[1])])
        else:
            zk = np.array([np.arctan2(d[0], d[1])])
        zk = zk + np.asarray(sigma) * rng.standard_normal(len(sigma))
        if kind != "linear":
            zk[-1] = wrap(zk[-1])
        z[k] = zk
    for a in (x0, P0, dts, obs, z, truth):
        a.setflags(write=False)  # problems are cached and shared: nobody may modify them
    return Problem(kind, x0, P0, dts, obs, z, truth, q, tuple(float(s) for s in sigma))


@cache
def problem(kind: str, seed: int, observer: str | None = None, T: int = 150) -> Problem:
    """Cached ``make_problem`` (problems are shared by several tests; treat as read-only)."""
    return make_problem(kind, seed, T, observer)


def stack_problems(problems: list[Problem]) -> dict[str, np.ndarray]:
    """Batch problems of one kind along a leading batch axis (time first where it applies):
    x0 (B, 4), P0 (B, 4, 4), dts (T, B), observer (T, B, 2), z (T, B, m)."""
    assert len({p.kind for p in problems}) == 1 and len({p.sigma for p in problems}) == 1
    return {
        "x0": np.stack([p.x0 for p in problems]),
        "P0": np.stack([p.P0 for p in problems]),
        "dts": np.stack([p.dts for p in problems], 1),
        "observer": np.stack([p.observer for p in problems], 1),
        "z": np.stack([p.z for p in problems], 1),
    }


def assert_gaussian_close(mean, cov, mean_ref, cov_ref, what: str, rtol=RTOL, floor=FLOOR):
    """Assert that sequences of means ``(T, n)`` and covariances ``(T, n, n)`` agree with the
    reference at every step: ``|a - r| <= rtol |r| + FLOOR sigma`` (see FLOOR).

    Implemented as ``assert_allclose`` on the values standardised by the reference standard
    deviations (``x_i / sigma_i``, ``P_ij / (sigma_i sigma_j)``), which is the same inequality.
    On failure the message names the first step that disagrees.
    """
    mean, cov = np.asarray(mean, float), np.asarray(cov, float)
    mean_ref, cov_ref = np.asarray(mean_ref, float), np.asarray(cov_ref, float)
    assert mean.shape == mean_ref.shape, (what, mean.shape, mean_ref.shape)
    assert cov.shape == cov_ref.shape, (what, cov.shape, cov_ref.shape)
    sd = np.sqrt(np.diagonal(cov_ref, axis1=-2, axis2=-1))
    outer = sd[..., :, None] * sd[..., None, :]
    for name, a, r, s in (("mean", mean, mean_ref, sd), ("cov", cov, cov_ref, outer)):
        ok = np.abs(a - r) <= floor * s + rtol * np.abs(r)
        if not ok.all():
            k = int(np.argwhere(~ok.reshape(len(a), -1).all(-1))[0, 0])
            np.testing.assert_allclose(
                a[k] / s[k], r[k] / s[k], rtol=rtol, atol=floor,
                err_msg=f"{what}: {name} differs first at step {k} of {len(a)} "
                f"(values standardised by the reference sigmas)",
            )
            raise AssertionError(f"{what}: {name} differs first at step {k}")
