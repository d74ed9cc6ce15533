"""Identification of the 16 coefficients of Zolfagharnasab and Seif (2025) by a Kalman filter on the
augmented state.

The state is ``x_a = [u, v, r, theta]`` (19): the body states in SI (m/s, m/s, rad/s) and the
coefficients ``theta = [a1..a9, b1..b4, c1..c3]`` in the prime units of ``norm``, exactly as
``trackkit.models.manoeuvring.AugmentedVessel`` takes them. Between samples k - 1 and k the
prediction takes ``substeps = m`` forward-Euler steps of ``h = dt / m`` (``SampledVessel``)::

    x <- x + h f(x, s_j, theta),   s_j = s_{k-1} + (j + 1/2) / m (s_k - s_{k-1}),
    theta <- theta,   then  x_a <- x_a + w,   w ~ N(0, dt diag(q_body, q_theta))

or, with the inputs measured at the sub-steps' ends ``t_{k-1} + j h`` (``s`` given every
``dt / m``), ``s_j = (s(t_{k-1} + j h) + s(t_{k-1} + (j + 1) h)) / 2``

(random-walk coefficients). m = 1 is the paper's eq. 4, one Euler step with the mean input
``s_m = (s_{k-1} + s_k) / 2`` (``AugmentedVessel`` itself). The update uses
``y_k = H x_a + e_k``, ``H = [I3 0]``, ``e ~ N(0, diag(sigma_z^2))``. Batched over the
leading run axes of the data; only time is looped over. ``filter="ekf"`` (the default) runs
the EKF with ``F = [[A, B], [0, I]]`` and ``H = [I3 0]`` written out by blocks, one compiled
pass over the runs per sample (``trackkit.identify.fused``: O(n^2) per run and step instead
of O(n^3), and the same bits for a run alone or in any batch); a filter instance
(``trackkit.filters.EKF()``, ``UKF()``, ``CKF()``) runs that filter on the model
(``SampledVessel``, or ``AugmentedVessel`` for m = 1). The generic ``EKF()`` is the textbook
form the compiled one is pinned to (``tests/identify/test_augmented.py``); both match
FilterPy (``tests/oracles/test_vessel_filterpy.py``).

Initialisation (k = 0) and trial joins (``starts[k]``): the body states are taken from the
measurement, ``N(y_k, R)`` (the posterior of one measurement under a flat prior), independent
of theta; at a join the coefficients keep their mean and covariance, and their correlation
with the body states is dropped, since the new trial's start does not follow from the last
sample of the previous one. The coefficients start at ``theta0`` with standard deviation
``theta_sd0``. Default: ``theta0 = 0``, ``theta_sd0 = 1`` (prime units): no knowledge of the
hull beyond the order of magnitude of prime coefficients (the reference set's are 0.12-1.0).
``initial_guess`` gives the alternative of a perturbed reference set.

Defaults at dt = 1 s, for measured inputs (``docs/vessel-comparison.md``,
``tests/statistical/test_vessel_coefficient_nees.py``: 105 trials of three programmes other
than ``identify.programme``'s, random hulls, a truth integrated at 0.005 s):

* ``substeps = 50`` (h = 0.02 s), each taking the mean of the inputs measured at its ends
  (pass ``s`` at ``dt / 50``; ``experiments.vessel_mc.inputs_at_substeps`` does for a log). The
  nozzle is rate-limited and starts and stops between samples: interpolated between 1 s
  samples its corners are smoothed, which biases c1 by -10 to -18%, c2 by -2 to -6% and c3
  by +0.4 to +2.5% (about one reported sd) whatever the noise. With the measured inputs,
  the Euler error of h = 0.1 s (ten sub-steps) against a yaw time constant of 1.7 s still
  biases c3 by about one sd; h = 0.02 s leaves 0.2-0.4 sd.
* ``sigma_z``: the programme's 0.05 m/s, 0.05 m/s, 0.1 deg/s.
* ``q_body = (2e-5, 2e-5, 2e-7)`` (m^2/s^3, m^2/s^3, rad^2/s^3), a per-sample standard
  deviation of 0.0045 m/s, 0.0045 m/s and 0.026 deg/s: the model's remaining error. The
  coefficient NEES (16 dof) has mean 15.9 over the 105 trials; with 1e-5, 1e-5, 1e-7 17.2
  (at the 99% band's edge), with 3e-4, 3e-4, 3e-6 (the old default) about 8: conservative.
* ``q_theta = 0``: constant coefficients.

With inputs known only at the samples (``s (..., K, 2)``, as ``identify.programme``
records them) the interpolation error is the model's largest, and the defaults are those
before: ten sub-steps (``SUBSTEPS_SAMPLED_INPUTS``) and ``Q_BODY_SAMPLED_INPUTS = (3e-4,
3e-4, 3e-6)``, which give a NEES mean of 20.8 on the programme's near-continuous truth,
where a Q matched to the rms of the model's error per sample leaves the coefficients
overconfident (mean 42; ``tests/statistical/test_vessel_identification.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian
from trackkit.filters import CKF, EKF, SRCKF, UKF
from trackkit.filters.base import Filter
from trackkit.identify import fused
from trackkit.identify.programme import DEFAULT_NOISE, run_seed
from trackkit.models.manoeuvring import (
    N_THETA,
    AugmentedVessel,
    Normalisation,
    augmented_step,
    reference_vessel,
    step,
    step_jacobian_state,
    step_jacobian_theta,
)
from trackkit.models.motion import MotionBase
from trackkit.models.sensors import Position
from trackkit.renamed import renamed_keywords

__all__ = [
    "METHODS",
    "Identification",
    "SampledVessel",
    "DEFAULT_Q_BODY",
    "DEFAULT_SUBSTEPS",
    "Q_BODY_SAMPLED_INPUTS",
    "SUBSTEPS_SAMPLED_INPUTS",
    "identify",
    "initial_guess",
    "relative_error",
    "settling_step",
    "coefficient_nees",
]

Array = NDArray[np.float64]

#: q_body for inputs measured at the sub-steps (``s`` every ``dt / m``)
DEFAULT_Q_BODY = np.array([2e-5, 2e-5, 2e-7])
#: q_body for inputs known at the samples only: it covers their interpolation's error
Q_BODY_SAMPLED_INPUTS = np.array([3e-4, 3e-4, 3e-6])
#: Euler sub-steps per sample of the prediction with the inputs measured at their ends (h =
#: 0.02 s at dt = 1 s), and with the inputs known at the samples only (the module docstring)
DEFAULT_SUBSTEPS, SUBSTEPS_SAMPLED_INPUTS = 50, 10
_FILTERS = {"ekf": EKF, "ukf": UKF, "ckf": CKF, "srckf": SRCKF}
#: the identifiers by name: the filters on the augmented state and batch least squares
METHODS = (*_FILTERS, "ls")


class Identification(NamedTuple):
    """Result of ``identify`` for runs ``(...)`` and K samples.

    ``theta (..., 16)`` and ``cov (..., 19, 19)``: the final estimate and its covariance;
    ``theta_history``, ``theta_std`` ``(..., K, 16)``: the coefficients' filtered mean and
    standard deviation after each sample (the paper's Figs. 5-7); ``body``, ``body_std``
    ``(..., K, 3)``: the filtered ``[u, v, r]`` (SI) and their standard deviations;
    ``nis (..., K)``: the normalised innovation squared (nan at initialisations and missing
    samples); ``cov_history (..., K, 19, 19)`` if asked for, else None."""

    theta: Array
    cov: Array
    theta_history: Array
    theta_std: Array
    body: Array
    body_std: Array
    nis: Array
    cov_history: Array | None
    filter: str


@dataclass(frozen=True, eq=False)
class SampledVessel(MotionBase):
    """The augmented model over one sample period ``dt`` in ``substeps = m`` forward-Euler
    steps of ``h = dt / m``, the input interpolated linearly between the samples
    ``s_prev`` and ``s_next`` (each ``(..., 2)``): sub-step j uses the mean of the
    interpolated input at its ends, ``s_j = s_prev + (j + 1/2) / m (s_next - s_prev)``; or,
    given ``s_sub (m + 1, ..., 2)``, the inputs measured at the sub-steps' ends,
    ``s_j = (s_sub[j] + s_sub[j + 1]) / 2``::

        x_{j+1} = x_j + h f(x_j, s_j, theta),   j = 0 .. m - 1;   theta unchanged

    The Jacobian is the product of the sub-steps' ``[[A_j, B_j], [0, I]]``
    (``A_j = I + h df/dx``, ``B_j = h Phi(x_j, s_j)``): ``A = A_{m-1} .. A_0`` and
    ``B = sum_j A_{m-1} .. A_{j+1} B_j``. The noise is one random walk over the period,
    ``Q = dt diag(q_body, q_theta)``, added at its end (for m = 1 this is exactly
    ``AugmentedVessel`` with ``s_m = (s_prev + s_next) / 2``)."""

    s_prev: ArrayLike
    s_next: ArrayLike
    norm: Normalisation
    q_body: ArrayLike = 0.0
    q_theta: ArrayLike = 0.0
    substeps: int = 1
    s_sub: ArrayLike | None = None
    dim_x: int = field(default=3 + N_THETA, init=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.substeps, int | np.integer) and self.substeps >= 1):
            raise ValueError(f"SampledVessel.substeps = {self.substeps!r}; expected an "
                             "integer >= 1")
        s0, s1 = np.asarray(self.s_prev, dtype=float), np.asarray(self.s_next, dtype=float)
        m = int(self.substeps)
        if self.s_sub is not None and m > 1:  # measured inputs at the sub-steps' ends
            sf = np.asarray(self.s_sub, dtype=float)
            if sf.ndim < 2 or sf.shape[0] != m + 1:
                raise ValueError(f"SampledVessel.s_sub has shape {sf.shape}; expected "
                                 f"({m + 1}, ..., 2), the inputs at the sub-steps' ends")
            inputs = [0.5 * (sf[j] + sf[j + 1]) for j in range(m)]
        else:
            inputs = [s0 + ((j + 0.5) / m) * (s1 - s0) if m > 1 else 0.5 * (s0 + s1)
                      for j in range(m)]
        # the models of the sub-steps (they check s, norm and the densities)
        subs = tuple(AugmentedVessel(s_j, self.norm, self.q_body, self.q_theta)
                     for s_j in inputs)
        object.__setattr__(self, "_subs", subs)

    def _inputs(self) -> tuple[Array, ...]:
        return tuple(sub.s_m for sub in self._subs)

    def f(self, x: Array, dt: ArrayLike) -> Array:
        h = np.asarray(dt, dtype=float) / self.substeps
        if self.substeps == 1:
            return augmented_step(x, self._subs[0].s_m, h, self.norm)
        body, theta = x[..., :3], x[..., 3:]
        for s_j in self._inputs():
            body = step(body, s_j, theta, h, self.norm)
        return np.concatenate([body, np.broadcast_to(theta, body.shape[:-1] + (N_THETA,))],
                              -1)

    def blocks(self, x: Array, dt: ArrayLike) -> tuple[Array, Array, Array]:
        """``(body', A, B)``: the predicted body states ``(..., 3)`` and the Jacobian's blocks
        ``A = d body' / d body (..., 3, 3)`` and ``B = d body' / d theta (..., 3, 16)``."""
        h = np.asarray(dt, dtype=float) / self.substeps
        body, theta = x[..., :3], x[..., 3:]
        A = B = None
        for s_j in self._inputs():
            Aj = step_jacobian_state(body, s_j, theta, h, self.norm)
            Bj = step_jacobian_theta(body, s_j, h, self.norm)
            A, B = (Aj, Bj) if A is None else (Aj @ A, Aj @ B + Bj)
            body = step(body, s_j, theta, h, self.norm)
        return body, A, B

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        _, A, B = self.blocks(x, dt)
        F = np.zeros(np.broadcast_shapes(A.shape[:-2], B.shape[:-2]) + (19, 19))
        F[..., :3, :3] = A
        F[..., :3, 3:] = B
        F[..., 3:, 3:] = np.eye(N_THETA)
        return F

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        return self._subs[0].noise(x, dt)


def _filter(filter: str | Filter) -> Filter | None:
    """The filter strategy; None for ``"ekf"``, which runs the structured kernels below."""
    if isinstance(filter, str):
        if filter.lower() == "ekf":
            return None
        try:
            return _FILTERS[filter.lower()]()
        except KeyError:
            raise ValueError(f"filter = {filter!r}; expected one of {sorted(_FILTERS)} or a "
                             "trackkit filter instance") from None
    if not (hasattr(filter, "predict") and hasattr(filter, "update")):
        raise ValueError(f"filter = {filter!r}; expected 'ekf', 'ukf', 'ckf' or a filter "
                         "with predict and update")
    return filter


def _vector(value: ArrayLike, n: int, name: str, positive: bool = False) -> Array:
    a = np.asarray(value, dtype=float)
    a = np.broadcast_to(a, (n,)).copy() if a.ndim == 0 else a
    bad = a.shape != (n,) or not np.all(np.isfinite(a)) or np.any(a < 0)
    if bad or (positive and np.any(a == 0)):
        want = "> 0" if positive else ">= 0"
        raise ValueError(f"{name} = {np.asarray(value).tolist()!r}; expected a scalar or "
                         f"({n},) of finite values {want}")
    return a


@renamed_keywords(T="dt")
def identify(z: ArrayLike, s: ArrayLike, dt: float, *, norm: Normalisation | None = None,
             starts: ArrayLike | None = None, filter: str | Filter = "ekf",
             theta0: ArrayLike | None = None, theta_sd0: ArrayLike = 1.0,
             sigma_z: ArrayLike = DEFAULT_NOISE.body, q_body: ArrayLike | None = None,
             q_theta: ArrayLike = 0.0, substeps: int | None = None,
             keep_cov: bool = False) -> Identification:
    """Run the augmented filter over measured body states ``z (..., K, 3)`` (SI; nan where
    missing) and applied inputs ``s (..., K, 2)`` (``[delta, n]``, rad and rpm; or ``(K, 2)``
    shared by the runs) sampled every ``dt`` seconds, or ``s (..., (K - 1) m + 1, 2)`` sampled
    every ``dt / m`` at the ends of the ``m = substeps`` sub-steps (each sub-step then takes
    the mean of its ends instead of the interpolation between samples: see the module).

    ``norm`` is the prime system of the coefficients (default: the reference vessel's,
    L = 19.6 m, U0 = 18 kn, n0 = 2000 rpm); ``starts (K,)`` marks trial joins (see the module
    docstring; default: sample 0 only); ``filter`` is ``"ekf"`` (the compiled kernel),
    ``"ukf"``, ``"ckf"``, ``"srckf"`` (the square-root CKF) or a filter instance; ``theta0
    (..., 16)`` and ``theta_sd0`` (scalar or 16) the coefficients' prior mean and standard
    deviation; ``sigma_z`` (3) the measurement standard deviations, ``R = diag(sigma_z^2)``;
    ``q_body`` (3) and ``q_theta`` (16 or scalar) the random-walk densities, ``Q = dt
    diag(q_body, q_theta)`` per sample (default ``DEFAULT_Q_BODY`` for inputs at the
    sub-steps, ``Q_BODY_SAMPLED_INPUTS`` for inputs at the samples); ``substeps`` the Euler
    steps per sample (1: the paper's eq. 4; default ``DEFAULT_SUBSTEPS`` with inputs at the
    sub-steps, ``SUBSTEPS_SAMPLED_INPUTS`` with inputs at the samples). ``keep_cov`` keeps
    every sample's 19 x 19 covariance."""
    f = _filter(filter)
    norm = reference_vessel().norm if norm is None else norm
    if not isinstance(norm, Normalisation):
        raise ValueError(f"norm = {norm!r}; expected a trackkit.models.manoeuvring.Normalisation")
    z, s, s_fine, substeps = _samples(z, s, substeps)
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt = {dt!r}; expected a sample period > 0 s")
    starts = _trial_starts(starts, z)
    theta0 = np.zeros(N_THETA) if theta0 is None else np.asarray(theta0, dtype=float)
    if theta0.ndim < 1 or theta0.shape[-1] != N_THETA or not np.all(np.isfinite(theta0)):
        raise ValueError(f"theta0 has shape {theta0.shape}; expected finite (..., 16)")
    sd0 = _vector(theta_sd0, N_THETA, "theta_sd0", positive=True)
    sigma_z = _vector(sigma_z, 3, "sigma_z", positive=True)
    if q_body is None:
        q_body = Q_BODY_SAMPLED_INPUTS if s_fine is None else DEFAULT_Q_BODY
    q_body = _vector(q_body, 3, "q_body")
    q_theta = _vector(q_theta, N_THETA, "q_theta")
    batch, z, s, s_fine = _broadcast(z, s, s_fine, theta0)
    R = np.diag(sigma_z**2)
    Qd = dt * np.concatenate([q_body, q_theta])
    mean = np.concatenate([z[..., 0, :], np.broadcast_to(theta0, batch + (N_THETA,))], -1)
    cov = np.zeros(batch + (19, 19))
    cov[..., 3:, 3:] = np.diag(sd0**2)
    if f is None:
        return _identify_ekf(z, s, dt, norm, substeps, starts, mean, cov, R, Qd, keep_cov,
                             s_fine)

    def model(k: int) -> AugmentedVessel | SampledVessel:
        if substeps == 1:  # the paper's eq. 4, exactly
            return AugmentedVessel(0.5 * (s[..., k - 1, :] + s[..., k, :]), norm, q_body,
                                   q_theta)
        sub = None if s_fine is None else np.moveaxis(
            s_fine[..., (k - 1) * substeps:k * substeps + 1, :], -2, 0)
        return SampledVessel(s[..., k - 1, :], s[..., k, :], norm, q_body, q_theta, substeps,
                             sub)

    return _identify_filter(f, z, dt, model, starts, mean, cov, R, sigma_z, keep_cov)


def _samples(z: ArrayLike, s: ArrayLike, substeps: int | None
             ) -> tuple[Array, Array, Array | None, int]:
    """``identify``'s ``z`` and ``s`` checked: ``(z, s at the samples, s at the sub-steps'
    ends or None, substeps)``."""
    z, s = np.asarray(z, dtype=float), np.asarray(s, dtype=float)
    if z.ndim < 2 or z.shape[-1] != 3:
        raise ValueError(f"z has shape {z.shape}; expected (..., K, 3) samples of [u, v, r]")
    K = z.shape[-2]
    if substeps is None:
        fine = s.ndim >= 2 and s.shape[-2] != K
        substeps = DEFAULT_SUBSTEPS if fine else SUBSTEPS_SAMPLED_INPUTS
    if not (isinstance(substeps, int | np.integer) and substeps >= 1):
        raise ValueError(f"substeps = {substeps!r}; expected an integer >= 1")
    Kf = (K - 1) * int(substeps) + 1  # the sub-steps' ends
    if s.ndim < 2 or s.shape[-1] != 2 or s.shape[-2] not in (K, Kf):
        raise ValueError(f"s has shape {s.shape}; expected (..., {K}, 2) inputs [delta, n] "
                         f"at the samples of z, or (..., {Kf}, 2) at the ends of its "
                         f"{substeps} sub-steps per sample")
    if not np.all(np.isfinite(s)):
        raise ValueError("s has non-finite entries; expected finite inputs at every sample")
    s_fine = s if s.shape[-2] != K else None
    s = s[..., ::substeps, :] if s_fine is not None else s
    return z, s, s_fine, substeps


def _trial_starts(starts: ArrayLike | None, z: Array) -> Array:
    """``starts (K,)`` checked, with sample 0 a start; ``z`` must be finite at each."""
    K = z.shape[-2]
    if starts is None:
        starts = np.zeros(K, bool)
    starts = np.asarray(starts)
    if starts.shape != (K,) or starts.dtype != bool:
        raise ValueError(f"starts has shape {starts.shape} and dtype {starts.dtype}; expected "
                         f"({K},) booleans")
    starts = starts.copy()
    starts[0] = True
    if not np.all(np.isfinite(z[..., starts, :])):
        raise ValueError("z has missing or non-finite samples at a trial start; expected "
                         "finite [u, v, r] there (they initialise the body states)")
    return starts


def _broadcast(z: Array, s: Array, s_fine: Array | None, theta0: Array
               ) -> tuple[tuple[int, ...], Array, Array, Array | None]:
    """The runs' shape ``batch`` and ``z``, ``s``, ``s_fine`` broadcast to it."""
    try:
        batch = np.broadcast_shapes(z.shape[:-2], s.shape[:-2], theta0.shape[:-1])
    except ValueError:
        raise ValueError(f"run axes do not broadcast: z {z.shape[:-2]}, s {s.shape[:-2]}, "
                         f"theta0 {theta0.shape[:-1]}") from None
    K = z.shape[-2]
    z = np.broadcast_to(z, batch + (K, 3))
    s = np.broadcast_to(s, batch + (K, 2))
    if s_fine is not None:
        s_fine = np.broadcast_to(s_fine, batch + (s_fine.shape[-2], 2))
    return batch, z, s, s_fine


def _identify_filter(f: Filter, z: Array, dt: float,
                     model: Callable[[int], AugmentedVessel | SampledVessel], starts: Array,
                     mean: Array, cov: Array, R: Array, sigma_z: Array, keep_cov: bool
                     ) -> Identification:
    """``identify`` with a filter instance: ``f.predict`` with ``model(k)`` from sample
    ``k - 1`` to ``k``, ``f.update`` with ``z_k``; initialisation and joins as in
    ``identify``."""
    batch, K = z.shape[:-2], z.shape[-2]
    out_theta = np.empty(batch + (K, N_THETA))
    out_theta_sd = np.empty(batch + (K, N_THETA))
    out_body = np.empty(batch + (K, 3))
    out_body_sd = np.empty(batch + (K, 3))
    nis = np.full(batch + (K,), np.nan)
    covs = np.empty(batch + (K, 19, 19)) if keep_cov else None
    sensor = Position(dim=3, sigma=sigma_z)
    b = None  # the filter's belief (kept, so that its checks stay cheap)
    for k in range(K):
        if starts[k]:
            # (re-)initialise the body states from y_k; theta keeps its mean and covariance
            mean, cov = np.array(mean), np.array(cov)
            mean[..., :3] = z[..., k, :]
            cov[..., :3, :] = 0.0
            cov[..., :, :3] = 0.0
            cov[..., :3, :3] = R
            b = None
        else:
            b = f.predict(Gaussian(mean, cov) if b is None else b, model(k), dt)
            b, innov = f.update(b, z[..., k, :], sensor)
            mean, cov = b.mean, b.cov
            nis[..., k] = innov.nis
        sd = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
        out_theta[..., k, :] = mean[..., 3:]
        out_theta_sd[..., k, :] = sd[..., 3:]
        out_body[..., k, :] = mean[..., :3]
        out_body_sd[..., k, :] = sd[..., :3]
        if covs is not None:
            covs[..., k, :, :] = cov
    name = getattr(f, "name", type(f).__name__)
    return Identification(theta=np.array(mean[..., 3:]), cov=np.array(cov),
                          theta_history=out_theta, theta_std=out_theta_sd, body=out_body,
                          body_std=out_body_sd, nis=nis, cov_history=covs, filter=name)


def _identify_ekf(z: Array, s: Array, dt: float, norm: Normalisation, substeps: int,
                  starts: Array, mean: Array, cov: Array, R: Array, Qd: Array,
                  keep_cov: bool, s_fine: Array | None = None) -> Identification:
    """``identify``'s EKF: the equations of ``trackkit.filters.EKF`` on ``SampledVessel``
    with ``F = [[A, B], [0, I]]`` and ``H = [I3 0]`` written out, one compiled pass over the
    runs per sample (``trackkit.identify.fused``), the runs as the last axis and the
    covariance as its lower triangle. Initialisation and joins as in ``identify``."""
    batch, K = z.shape[:-2], z.shape[-2]
    N = math.prod(batch)
    zs = np.ascontiguousarray(z.reshape(N, K, 3).transpose(1, 2, 0))  # (K, 3, N)
    ss = np.ascontiguousarray(s.reshape(N, K, 2).transpose(1, 2, 0))  # (K, 2, N)
    m = int(substeps)
    sf = None if s_fine is None else np.ascontiguousarray(
        s_fine.reshape(N, -1, 2).transpose(1, 2, 0))  # ((K - 1) m + 1, 2, N)
    x = np.ascontiguousarray(mean.reshape(N, 19).T)
    P = fused.pack(cov.reshape(N, 19, 19))
    body_rows = np.unique(fused.TRI[:3])  # the rows of P with a body index
    R_rows, R_tri = fused.TRI[:3, :3][np.tril_indices(3)], R[np.tril_indices(3)]
    diagonal = fused.TRI[np.arange(19), np.arange(19)]
    theta, theta_sd = np.empty((K, N_THETA, N)), np.empty((K, N_THETA, N))
    body, body_sd = np.empty((K, 3, N)), np.empty((K, 3, N))
    nis = np.full((K, N), np.nan)
    covs = np.empty((K, N, 19, 19)) if keep_cov else None
    plan = fused.plan(norm, substeps, dt)
    for k in range(K):
        if starts[k]:
            x[:3] = zs[k]
            P[body_rows] = 0.0
            P[R_rows] = R_tri[:, None]
        else:
            sub = None if sf is None else sf[(k - 1) * m:k * m + 1]
            nis[k] = fused.predict_update(x, P, ss[k - 1], ss[k], plan, Qd, zs[k], R, sub)
        sd = np.sqrt(P[diagonal])
        theta[k], theta_sd[k] = x[3:], sd[3:]
        body[k], body_sd[k] = x[:3], sd[:3]
        if covs is not None:
            covs[k] = fused.unpack(P)

    def runs_first(a: Array) -> Array:  # (K, ..., N) -> batch + (K, ...)
        return np.moveaxis(a, -1, 0).reshape(batch + a.shape[:-1])

    return Identification(
        theta=runs_first(x[3:]), cov=fused.unpack(P).reshape(batch + (19, 19)),
        theta_history=runs_first(theta), theta_std=runs_first(theta_sd),
        body=runs_first(body), body_std=runs_first(body_sd), nis=runs_first(nis),
        cov_history=None if covs is None else np.moveaxis(covs, 0, 1).reshape(
            batch + (K, 19, 19)), filter="EKF")


def initial_guess(theta: ArrayLike, runs: int | Sequence[int], seed: int,
                  spread: float = 0.5) -> Array:
    """Per-run guesses ``theta (1 + spread U)``, ``U ~ uniform(-1, 1)`` per coefficient, run
    r drawing from ``SeedSequence(seed, spawn_key=(r, 2))``: ``(R, 16)``."""
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (N_THETA,) or not np.all(np.isfinite(theta)):
        raise ValueError(f"theta has shape {theta.shape}; expected finite (16,)")
    if not (math.isfinite(spread) and spread >= 0):
        raise ValueError(f"spread = {spread!r}; expected a finite fraction >= 0")
    ids = range(int(runs)) if isinstance(runs, int | np.integer) else [int(r) for r in runs]
    U = np.stack([run_seed(seed, r, 2).uniform(-1.0, 1.0, N_THETA) for r in ids])
    return theta * (1.0 + spread * U)


def relative_error(theta_hat: ArrayLike, theta: ArrayLike) -> Array:
    """``|theta_hat - theta| / |theta|``, elementwise over ``(..., 16)``."""
    theta = np.asarray(theta, dtype=float)
    return np.abs(np.asarray(theta_hat, dtype=float) - theta) / np.abs(theta)


def settling_step(history: ArrayLike, theta: ArrayLike, tol: float = 0.2) -> Array:
    """The first sample ``k`` from which ``|theta_hat_j - theta_j| <= tol |theta_j|`` holds to
    the end of ``history (..., K, 16)``, per run and coefficient ``(..., 16)``; K where the
    last sample is outside."""
    e = relative_error(history, np.asarray(theta)[..., None, :]) <= tol
    K = e.shape[-2]
    # index of the last sample outside, + 1 (0 when always inside)
    outside = ~e
    last_out = K - 1 - np.argmax(outside[..., ::-1, :], axis=-2)
    return np.where(outside.any(-2), last_out + 1, 0)


def coefficient_nees(theta_hat: ArrayLike, cov: ArrayLike, theta: ArrayLike,
                     index: ArrayLike | None = None) -> Array:
    """``e^T P^-1 e`` for the coefficients' error ``e = theta_hat - theta`` and their block
    ``P`` of ``cov (..., 19, 19)`` (or of a ``(..., 16, 16)`` covariance), restricted to the
    coefficients ``index`` (default all 16): chi-square with ``len(index)`` degrees of freedom
    for a consistent estimator."""
    cov = np.asarray(cov, dtype=float)
    P = cov[..., 3:, 3:] if cov.shape[-1] == 19 else cov
    idx = np.arange(N_THETA) if index is None else np.asarray(index)
    e = (np.asarray(theta_hat, dtype=float) - np.asarray(theta, dtype=float))[..., idx]
    Pi = P[..., idx[:, None], idx[None, :]]
    return np.einsum("...i,...i->...", e, np.linalg.solve(Pi, e[..., None])[..., 0])
