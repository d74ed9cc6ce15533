"""What every filter shares: input checks, missing measurements and the output register.

Input checks are thorough once and cheap after that: a covariance that a trackkit filter
produced is symmetric by construction and is remembered (by identity, weakly), so only
covariances from outside (a user's prior, a hand-edited belief) pay for the full symmetry and
positive-semi-definiteness check. Shapes and finiteness are checked on every call.
"""

from __future__ import annotations

import math
import weakref
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian, Innovation
from trackkit.linalg import check_covariance, symmetrize
from trackkit.models.protocols import MotionModel, SensorModel

Array = NDArray[np.float64]

# id -> weak reference; a stale entry (its array gone, its id reused) fails the identity test
_produced: dict[int, weakref.ref] = {}


def register(P: Array) -> Array:
    """Mark ``P`` as produced (and so already checked) by a trackkit filter."""
    if len(_produced) > 4096:
        _produced.clear()  # forgetting only costs a full check of a later input
    _produced[id(P)] = weakref.ref(P)
    return P


def produced(P: Any) -> bool:
    """Whether ``P`` is an array that ``register`` marked (this very object, still alive)."""
    ref = _produced.get(id(P))
    return ref is not None and ref() is P


_F64 = np.dtype(np.float64)
_SMALL = 32  # arrays up to this size are summed in Python (cheaper than a numpy call)


def _finite_sum(a: Array) -> bool:
    """Whether the sum of ``a`` is finite: false for any nan or infinite entry (and, as for
    any float sum, if finite entries near the float limit overflow)."""
    if a.size <= _SMALL:
        return math.isfinite(sum(a.ravel().tolist()))
    return math.isfinite(np.add.reduce(a, axis=None))


def _raise_non_finite(x: Array, where: str):
    """The error for a non-finite mean or (when the mean is finite) covariance."""
    what = "mean" if not _finite_sum(x) else "cov"
    raise ValueError(f"{where}.{what} has non-finite entries; expected finite values")


def check_belief(b: Gaussian, n: int | None, where: str) -> tuple[Array, Array]:
    """Return ``(mean, cov)`` as float arrays after checking them.

    Raises ``ValueError`` naming ``where`` (e.g. ``"EKF.predict belief"``) on a wrong state
    length, mismatched shapes, non-finite entries, or (for covariances from outside) an
    asymmetric or non-PSD covariance.
    """
    x, P = b.mean, b.cov
    if type(x) is np.ndarray and x.ndim == 1 and x.size <= 5 and x.dtype is _F64:
        # one small problem (n + n^2 <= _SMALL): quick path for a covariance from a filter
        ref = _produced.get(id(P))
        if (ref is not None and ref() is P and P.shape == (x.size, x.size)
                and (n is None or n == x.size)):
            if math.isfinite(sum(x.tolist() + P.ravel().tolist())):
                return x, P
            _raise_non_finite(x, where)
    if type(x) is not np.ndarray or x.dtype is not _F64:
        x = np.asarray(x, dtype=float)
    if x.ndim < 1:
        raise ValueError(f"{where}.mean is a scalar; expected shape (..., n)")
    if n is not None and x.shape[-1] != n:
        raise ValueError(
            f"{where}.mean has shape {x.shape}; the model's state has {n} components, "
            f"so expected (..., {n})"
        )
    is_produced = produced(P)
    if is_produced and x.size + P.size <= _SMALL:  # one Python sum for both (one problem)
        if not math.isfinite(sum(x.ravel().tolist()) + sum(P.ravel().tolist())):
            _raise_non_finite(x, where)
    elif not _finite_sum(x):
        _raise_non_finite(x, where)
    Pshape = P.shape if type(P) is np.ndarray else np.shape(P)
    if len(Pshape) >= 2 and x.shape[:-1] != Pshape[:-2]:
        try:
            np.broadcast_shapes(x.shape[:-1], Pshape[:-2])
        except ValueError:
            raise ValueError(
                f"{where}: mean has batch shape {x.shape[:-1]} and cov {Pshape[:-2]}; "
                "expected batch shapes that broadcast (equal, or a shared (n, n) covariance)"
            ) from None
        if len(Pshape) - 2 > x.ndim - 1:
            raise ValueError(
                f"{where}: cov has batch shape {Pshape[:-2]} but mean only {x.shape[:-1]}; "
                "expected one mean per covariance"
            )
    if is_produced:
        if P.shape[-2:] != (x.shape[-1],) * 2:
            raise ValueError(f"{where}.cov has shape {P.shape}; expected (..., {x.shape[-1]}, "
                             f"{x.shape[-1]})")
        if x.size + P.size > _SMALL and not _finite_sum(P):
            raise ValueError(f"{where}.cov has non-finite entries; expected finite values")
    else:
        P = check_covariance(P, f"{where}.cov", n=x.shape[-1])
    return x, P


def check_dt(dt: ArrayLike, where: str) -> None:
    """A prediction's time step: finite and not negative (seconds), scalar or per batch row.
    (A negative step would be retrodiction, which these predictions are not.)"""
    if type(dt) is float or type(dt) is int:
        if not 0 <= dt < math.inf:
            raise ValueError(f"{where}: dt = {dt!r}; expected a finite time step >= 0 (s)")
        return
    d = np.asarray(dt, dtype=float)
    bad = ~((d >= 0) & (d < math.inf))
    if bad.any():
        first = float(d[bad].ravel()[0])
        raise ValueError(f"{where}: dt has {int(bad.sum())} bad entries (e.g. {first!r}); "
                         "expected finite time steps >= 0 (s)")


def check_measurement(z: ArrayLike, m: int, where: str,
                      batch: tuple[int, ...] = ()) -> Array:
    """z as a float array of shape ``(..., m)`` whose batch axes broadcast with ``batch``."""
    if type(z) is not np.ndarray or z.dtype is not _F64:
        z = np.asarray(z, dtype=float)
    if z.ndim < 1 or z.shape[-1] != m:
        raise ValueError(
            f"{where}: z has shape {z.shape}; the sensor measures {m} components, so "
            f"expected (..., {m}) (nan marks a missing measurement)"
        )
    if z.shape[:-1] != batch:
        try:
            np.broadcast_shapes(z.shape[:-1], batch)
        except ValueError:
            raise ValueError(
                f"{where}: z has shape {z.shape} but the belief's batch shape is {batch}; "
                f"expected z of shape {batch + (m,)} (or broadcastable to it)"
            ) from None
    total = sum(z.ravel().tolist()) if z.size <= _SMALL else np.add.reduce(z, axis=None)
    if math.isinf(total) or (math.isnan(total) and np.isinf(z).any()):
        bad = float(z[np.isinf(z)][0])
        raise ValueError(f"{where}: z has an infinite entry ({bad}); expected finite values, "
                         "or nan to mark a missing measurement")
    return z


def missing_rows(z: Array) -> Array | None:
    """Boolean mask of rows with any nan in z, or None when nothing is missing."""
    if not math.isnan(sum(z.ravel().tolist()) if z.size <= _SMALL else np.add.reduce(z, None)):
        return None
    return np.isnan(z).any(-1)


def output(x: Array, P: Array, symmetric: bool = False) -> Gaussian:
    """Package a filter result: symmetric covariance (``symmetric``: already exactly so),
    registered as produced."""
    return Gaussian._make((x, register(P if symmetric else symmetrize(P))))


def keep_prior_where_missing(
    miss: Array | None, prior: tuple[Array, Array], post: Gaussian, innov: Innovation
) -> tuple[Gaussian, Innovation]:
    """For rows without a measurement the update returns the prediction and a nan residual."""
    if miss is None:
        return post, innov
    x0, P0 = prior
    shape = np.broadcast_shapes(miss.shape, post.mean.shape[:-1])
    miss = np.broadcast_to(miss, shape)
    x = np.where(miss[..., None], x0, post.mean)
    P = np.where(miss[..., None, None], P0, post.cov)
    r = np.where(miss[..., None], np.nan, innov.nu)
    return Gaussian._make((x, register(P))), Innovation(r, innov.cov)


@runtime_checkable
class Filter(Protocol):
    """A stateless filter strategy, the interface every filter satisfies.

    ``init(prior) -> belief`` (a filter with memory builds its belief type here; a stochastic
    one, ``stochastic = True``, also takes ``rng=``), ``predict(belief, motion, dt) -> belief``,
    ``update(belief, z, sensor) -> (belief, Innovation)`` (nan in z: no measurement, the row
    keeps its prediction) and ``estimate(belief) -> Gaussian``. The bundled filters inherit the
    identity ``init`` and ``estimate`` of a Gaussian belief from here.
    """

    name: str = "Filter"

    def __init__(self) -> None:
        # a filter without options keeps an empty signature (a Protocol's default would
        # show ``*args, **kwargs`` to the option tables that read it)
        pass

    def init(self, prior: Gaussian) -> Any:
        return prior

    def predict(self, belief: Any, motion: MotionModel | None, dt: ArrayLike) -> Any:
        raise NotImplementedError

    def update(self, belief: Any, z: ArrayLike, sensor: SensorModel) -> tuple[Any, Innovation]:
        raise NotImplementedError

    def estimate(self, belief: Any) -> Gaussian:
        return belief

    def __repr__(self) -> str:
        fields = ", ".join(f"{k}={v!r}" for k, v in vars(self).items())
        return f"{type(self).__name__}({fields})"
