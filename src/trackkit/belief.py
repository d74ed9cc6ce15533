"""Beliefs: what a filter carries from one step to the next.

A belief is plain data, a NamedTuple of arrays whose leading axes are batch axes (Monte
Carlo runs, tracks, particles, agents) and, for a filtered sequence, a leading time axis.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.linalg import check_covariance

__all__ = ["Gaussian", "Innovation", "check_gaussian"]


class Gaussian(NamedTuple):
    """Gaussian belief N(mean, cov): ``mean`` is ``(..., n)``, ``cov`` is ``(..., n, n)``."""

    mean: NDArray[np.float64]
    cov: NDArray[np.float64]

    @property
    def dim(self) -> int:
        return int(np.shape(self.mean)[-1])

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return tuple(np.shape(self.mean)[:-1])

    def at(self, index) -> Gaussian:
        """The belief at a batch (or time) index: ``b.at(3)``, ``b.at((slice(None), 0))``.

        (Plain ``b[0]`` is the tuple's first field, the mean, as for any NamedTuple.)
        """
        return Gaussian(self.mean[index], self.cov[index])


class Innovation(NamedTuple):
    """Measurement innovation ``residual = z - zhat`` (angles wrapped) and its covariance S.

    Rows with a missing measurement (``nan`` in z) have a ``nan`` residual.
    """

    residual: NDArray[np.float64]
    cov: NDArray[np.float64]

    @property
    def nis(self) -> NDArray[np.float64]:
        """Normalised innovation squared ``r^T S^{-1} r`` per batch row (nan where missing)."""
        from trackkit.linalg import quadratic_form

        return quadratic_form(self.cov, self.residual)


def check_gaussian(mean: ArrayLike, cov: ArrayLike, name: str = "belief") -> Gaussian:
    """Validate a Gaussian fully (shapes, finite, symmetric PSD covariance) and return it.

    This is the thorough check for priors and user-built beliefs; filters run a cheaper
    shape-and-finiteness check every step.
    """
    m = np.asarray(mean, dtype=float)
    if m.ndim < 1:
        raise ValueError(f"{name}.mean is a scalar; expected shape (..., n)")
    if not np.all(np.isfinite(m)):
        raise ValueError(f"{name}.mean has non-finite entries; expected finite values")
    n = m.shape[-1]
    P = check_covariance(cov, f"{name}.cov", n=n)
    try:
        np.broadcast_shapes(m.shape[:-1], P.shape[:-2])
    except ValueError:
        raise ValueError(
            f"{name}: mean batch shape {m.shape[:-1]} and cov batch shape {P.shape[:-2]} "
            "do not broadcast"
        ) from None
    return Gaussian(m, P)
