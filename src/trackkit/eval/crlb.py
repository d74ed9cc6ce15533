r"""Posterior Cramer-Rao lower bound (PCRLB) for additive-Gaussian models, batched over truths.

For :math:`\mathbf{x}_{k+1} = f(\mathbf{x}_k) + \mathbf{w}_k`,
:math:`\mathbf{w}_k \sim \mathcal{N}(0, Q)` and
:math:`\mathbf{z}_k = h(\mathbf{x}_k) + \mathbf{v}_k`, :math:`\mathbf{v}_k \sim \mathcal{N}(0, R)`,
Tichavsky, Muravchik and Nehorai (IEEE TSP 46(5), 1998) give the Fisher information
:math:`J_k` of :math:`\mathbf{x}_k` by the recursion (:math:`J_0 = P_0^{-1}`, :math:`P_0` the
prior covariance of the truth)

.. math::

    J_{k+1} &= D^{22} - D^{21} (J_k + D^{11})^{-1} D^{12}, \\
    D^{11} &= E[F^\top Q^{-1} F], \qquad D^{12} = (D^{21})^\top = -E[F^\top]\, Q^{-1}, \qquad
    D^{22} = Q^{-1} + E[H^\top R^{-1} H]

with :math:`F = \partial f / \partial \mathbf{x}\,(\mathbf{x}_k)` and
:math:`H = \partial h / \partial \mathbf{x}\,(\mathbf{x}_{k+1})` at the true states. The bound
holds for every estimator :math:`\hat{\mathbf{x}}_k`:

.. math::

    E\bigl[(\hat{\mathbf{x}}_k - \mathbf{x}_k)(\hat{\mathbf{x}}_k - \mathbf{x}_k)^\top\bigr]
        \succeq J_k^{-1}

The expectations are
means over a batch of simulated truths: the first axis of ``truths`` (shape ``(runs, ..., n)``)
is the Monte Carlo axis that is averaged; further axes (targets, scenarios) are kept, so the
bound has shape ``(..., n, n)``.

Which form is used (``form="auto"``):

* **covariance form**, when F and Q are the same for every run (linear motion, or one truth):
  by the matrix inversion lemma the recursion equals the information filter,

  .. math::

      J_{k+1} = (F J_k^{-1} F^\top + Q)^{-1} + E[H^\top R^{-1} H]

  It needs no :math:`Q^{-1}`, so it is exact for a zero or singular Q as long as
  :math:`F J_k^{-1} F^\top + Q` is invertible (F invertible suffices); for :math:`Q = 0` it is
  :math:`J_{k+1} = F^{-\top} J_k F^{-1} + E[H^\top R^{-1} H]`. For a linear-Gaussian
  problem the bound is the Kalman filter's covariance.
* **information form** (the recursion above, expectations over runs), when F or Q vary over
  the runs and every Q is positive definite. Q is treated as independent of the state (its
  ``log det`` term is ignored), which is exact for every model in ``trackkit.models``.
* when F or Q vary over the runs *and* some Q is singular, the information form does not
  exist (and its limit Q -> 0 degenerates to infinite information for a state-dependent F).
  The covariance form with run averages, ``(E[F J^{-1} F^T] + E[Q])^{-1}``, is used instead:
  it is exact when the runs share F and Q and an approximation otherwise; a ``UserWarning``
  says so once per bound object. ``last_form`` records the form used by the last prediction.

Measurement information from several sensors at one time adds: call ``update`` once per
sensor. A detection probability or information-reduction factor (or 0/1 for a missing
measurement) enters as a per-run ``weight`` on ``H^T R^{-1} H``.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.linalg import check_covariance, cholesky, solve_psd, symmetrize

__all__ = ["PCRLB", "pcrlb", "rmse_bound"]

Array = NDArray[np.float64]
Form = Literal["auto", "information", "covariance"]
_FORMS = ("auto", "information", "covariance")


def inverse_spd(P: Array, name: str) -> Array:
    """``P^{-1}`` for symmetric positive-definite ``P`` (batched), symmetrised."""
    eye = np.broadcast_to(np.eye(P.shape[-1]), P.shape)
    return symmetrize(solve_psd(P, eye, name))


def _same_over_runs(A: Array) -> bool:
    """True when a per-run array ``(runs, ...)`` is identical across the runs axis."""
    return bool(np.all(A == A[:1]))


def predict_information(J: Array, F: Array, Q: Array, runs_axis: bool) -> Array:
    """``(E[F J^{-1} F^T + Q])^{-1}``; with ``runs_axis`` the mean is over the leading runs
    axis of F and Q ``(runs, ..., n, n)``, otherwise F and Q are shared by all runs."""
    P = inverse_spd(J, "PCRLB information matrix J_k")
    P_pred = symmetrize(F @ P @ F.mT + Q)
    if runs_axis:
        P_pred = P_pred.mean(axis=0)
    return inverse_spd(P_pred, "PCRLB predicted bound F J^-1 F^T + Q")


def _predict_information(J: Array, F: Array, Q: Array) -> Array:
    """Tichavsky-Muravchik-Nehorai prediction ``D22q - D21 (J + D11)^{-1} D12``.

    ``D11 = E[F^T Q^{-1} F]``, ``D12 = -E[F^T Q^{-1}]``, ``D22q = E[Q^{-1}]``, the means over
    the leading runs axis of F and Q ``(runs, ..., n, n)``; Q must be positive definite.
    """
    Qinv = inverse_spd(Q, "process noise Q (information-form PCRLB needs Q positive definite)")
    FtQinv = F.mT @ Qinv
    D11 = (FtQinv @ F).mean(axis=0)
    D12 = -FtQinv.mean(axis=0)
    D22q = Qinv.mean(axis=0)
    X = solve_psd(symmetrize(J + D11), D12, "PCRLB matrix J_k + D11")
    return symmetrize(D22q - D12.mT @ X)


def _broadcast_model(A: Any, batch: tuple[int, ...], n: int, name: str) -> Array:
    A = np.asarray(A, dtype=float)
    try:
        return np.broadcast_to(A, batch + (n, n)) if A.ndim > 2 else A
    except ValueError:
        raise ValueError(
            f"{name} has shape {A.shape}; expected (n, n) or a batch broadcastable to the "
            f"truths {batch + (n, n)}"
        ) from None


class PCRLB:
    """Streaming posterior CRLB: ``predict`` and ``update`` follow the filter's steps.

    ``PCRLB(P0)`` starts at ``J_0 = P0^{-1}``, where P0 is the covariance from which the
    truths' initial states are drawn. Then, per step::

        bound.predict(motion, truths_k, dt)   # truths at the step's start (F at x_k)
        bound.update(sensor, truths_k1)       # truths at the measurement time (H at x_{k+1})
        P_k1 = bound.bound                    # J_{k+1}^{-1}, shape (..., n, n)

    ``form`` is ``"auto"`` (see the module docstring), ``"information"`` or ``"covariance"``.
    Methods return ``self`` so steps chain.
    """

    def __init__(self, prior_cov: ArrayLike, form: Form = "auto") -> None:
        if form not in _FORMS:
            raise ValueError(f"form = {form!r}; expected one of {_FORMS}")
        P0 = check_covariance(prior_cov, "PCRLB prior_cov")
        self._J = inverse_spd(P0, "PCRLB prior_cov")
        self.form: Form = form
        self.last_form: str | None = None
        self._warned = False

    @classmethod
    def from_information(cls, J0: ArrayLike, form: Form = "auto") -> PCRLB:
        """Start from a prior information matrix ``J_0`` (positive definite)."""
        J0 = check_covariance(J0, "PCRLB J0")
        out = cls(inverse_spd(J0, "PCRLB J0"), form)
        out._J = J0
        return out

    @property
    def dim(self) -> int:
        return int(self._J.shape[-1])

    @property
    def information(self) -> Array:
        """The Fisher information ``J_k``, shape ``(..., n, n)``."""
        return self._J

    @property
    def bound(self) -> Array:
        """The bound ``J_k^{-1}`` on the error covariance, shape ``(..., n, n)``."""
        return inverse_spd(self._J, "PCRLB information matrix J_k")

    def _truths(self, truths: ArrayLike) -> Array:
        x = np.asarray(truths, dtype=float)
        n = self.dim
        if x.ndim < 2 or x.shape[-1] != n:
            raise ValueError(
                f"truths have shape {x.shape}; expected (runs, ..., {n}) true states"
            )
        if not np.all(np.isfinite(x)):
            raise ValueError("truths have non-finite entries; expected finite true states")
        return x

    def predict(self, motion: Any, truths: ArrayLike, dt: ArrayLike) -> PCRLB:
        """Propagate ``J_k -> J_{k+1|k}`` through ``motion`` over ``dt``.

        ``truths`` ``(runs, ..., n)`` are the true states at the start of the step, where
        ``F = motion.jacobian(x, dt)`` and ``Q = motion.noise(x, dt)`` are evaluated.
        """
        x = self._truths(truths)
        n, batch = self.dim, x.shape[:-1]
        F = _broadcast_model(motion.jacobian(x, dt), batch, n, "motion.jacobian")
        Q = _broadcast_model(motion.noise(x, dt), batch, n, "motion.noise")
        shared = (F.ndim == 2 or _same_over_runs(F)) and (Q.ndim == 2 or _same_over_runs(Q))
        form = self.form
        if form == "auto":
            if shared:
                form = "covariance"
            else:
                try:
                    cholesky(Q, "Q")
                    form = "information"
                except ValueError:
                    form = "covariance"
                    if not self._warned:
                        warnings.warn(
                            "PCRLB: the motion Jacobian or Q varies over the runs and Q is "
                            "singular; using the run-averaged covariance form "
                            "(E[F J^-1 F^T] + E[Q])^-1, an approximation of the bound",
                            UserWarning,
                            stacklevel=2,
                        )
                        self._warned = True
        if form == "covariance":
            if shared:  # drop the runs axis: one F and Q for all runs
                F = F if F.ndim == 2 else F[0]
                Q = Q if Q.ndim == 2 else Q[0]
            else:
                F = np.broadcast_to(F, batch + (n, n))
                Q = np.broadcast_to(Q, batch + (n, n))
            self._J = predict_information(self._J, F, Q, runs_axis=not shared)
        else:
            F = np.broadcast_to(F, batch + (n, n))
            Q = np.broadcast_to(Q, batch + (n, n))
            self._J = _predict_information(self._J, F, Q)
        self.last_form = form
        return self

    def update(self, sensor: Any, truths: ArrayLike, weight: ArrayLike = 1.0) -> PCRLB:
        """Add the measurement information ``E[w H^T R^{-1} H]`` at the true states.

        ``H = sensor.jacobian(x)``, ``R = sensor.noise``; the sensor's pose may carry the runs
        axis (a moving observer per run). ``weight`` (scalar or per run, broadcastable to
        ``truths.shape[:-1]``) scales each run's information: 1 for a measurement, 0 for none,
        a detection probability or an information-reduction factor otherwise.
        """
        x = self._truths(truths)
        n, batch = self.dim, x.shape[:-1]
        H = np.asarray(sensor.jacobian(x), dtype=float)
        m = H.shape[-2]
        H = np.broadcast_to(H, batch + (m, n))
        R = np.asarray(sensor.noise, dtype=float)
        RinvH = solve_psd(R, H, "measurement noise R")
        info = H.mT @ RinvH
        w = np.broadcast_to(np.asarray(weight, dtype=float), batch)
        if np.any(w < 0) or not np.all(np.isfinite(w)):
            raise ValueError("weight has negative or non-finite entries; expected values >= 0")
        self._J = symmetrize(self._J + (w[..., None, None] * info).mean(axis=0))
        return self


    def add_information(self, information: ArrayLike) -> PCRLB:
        """Add a precomputed expected measurement information ``E[H^T R^{-1} H]`` (n, n),
        e.g. summed over Monte Carlo blocks and divided by the number of runs."""
        info = check_covariance(information, "measurement information", n=self.dim)
        self._J = symmetrize(self._J + info)
        return self


def pcrlb(
    prior_cov: ArrayLike,
    motion: Any,
    sensor: Any,
    truths: ArrayLike,
    dt: float | Iterable[float],
    weights: Iterable[ArrayLike] | None = None,
    form: Form = "auto",
) -> Array:
    """The bound after each of T predict-update steps, shape ``(T, ..., n, n)``.

    ``truths`` ``(T + 1, runs, ..., n)`` start at the prior's time (``truths[0]`` drawn from
    N(m0, prior_cov)); the steps match ``trackkit.filters.run_filter``: predict by ``dt``
    (a float or one per step), then update. ``sensor`` is one model or a sequence of per-step
    models (``None`` for a step without a measurement); ``weights`` optionally one weight per
    step (see ``PCRLB.update``).
    """
    x = np.asarray(truths, dtype=float)
    T = x.shape[0] - 1
    if x.ndim < 3 or T < 1:
        raise ValueError(f"truths have shape {x.shape}; expected (T + 1, runs, ..., n), T >= 1")
    dts = list(dt) if np.ndim(dt) else [dt] * T
    sensors = list(sensor) if isinstance(sensor, Sequence) else [sensor] * T
    ws = list(weights) if weights is not None else [1.0] * T
    if not (len(dts) == len(sensors) == len(ws) == T):
        raise ValueError(
            f"{T} steps in truths but {len(dts)} dt, {len(sensors)} sensors and {len(ws)} "
            "weights; expected one per step"
        )
    b = PCRLB(prior_cov, form)
    out = []
    for k in range(T):
        b.predict(motion, x[k], dts[k])
        if sensors[k] is not None:
            b.update(sensors[k], x[k + 1], ws[k])
        out.append(b.bound)
    return np.stack(out)


def rmse_bound(bound: ArrayLike, indices: Sequence[int]) -> Array:
    """``sqrt(trace(bound[indices, indices]))``: the RMSE bound of a group of components,
    e.g. ``indices=[0, 1]`` for 2-D position. ``bound`` is ``(..., n, n)``."""
    B = np.asarray(bound, dtype=float)
    idx = np.asarray(indices, dtype=int)
    return np.sqrt(np.diagonal(B, axis1=-2, axis2=-1)[..., idx].sum(-1))
