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


class _GaussianFields(NamedTuple):
    mean: NDArray[np.float64]
    cov: NDArray[np.float64]


class Gaussian(_GaussianFields):
    """Gaussian belief N(mean, cov): ``mean`` is ``(..., n)``, ``cov`` is ``(..., n, n)``.

    Construction checks what is cheap: the shapes (and that the batch shapes broadcast) and
    that every entry is finite, naming the field. Symmetry and positive definiteness cost an
    eigen-decomposition and are checked where a filter first takes the covariance in.
    ``Gaussian._make((mean, cov))`` is the unchecked constructor, for a filter's own outputs
    (they are checked when they come back in, and a diverging filter's nan must reach the
    metrics rather than stop a Monte Carlo study).
    """

    __slots__ = ()

    def __new__(cls, mean: ArrayLike, cov: ArrayLike) -> Gaussian:
        m = mean if type(mean) is np.ndarray and mean.dtype == np.float64 else (
            np.asarray(mean, dtype=float))
        P = cov if type(cov) is np.ndarray and cov.dtype == np.float64 else (
            np.asarray(cov, dtype=float))
        if m.ndim < 1:
            raise ValueError("Gaussian.mean is a scalar; expected shape (..., n)")
        n = m.shape[-1]
        if P.ndim < 2 or P.shape[-2:] != (n, n):
            raise ValueError(f"Gaussian.cov has shape {P.shape}; the mean has {n} components, "
                             f"so expected (..., {n}, {n})")
        if P.ndim - 2 > m.ndim - 1:
            raise ValueError(f"Gaussian: cov has batch shape {P.shape[:-2]} but mean only "
                             f"{m.shape[:-1]}; expected one mean per covariance")
        try:
            np.broadcast_shapes(m.shape[:-1], P.shape[:-2])
        except ValueError:
            raise ValueError(f"Gaussian: mean batch shape {m.shape[:-1]} and cov batch shape "
                             f"{P.shape[:-2]} do not broadcast") from None
        for name, a in (("mean", m), ("cov", P)):
            if not np.isfinite(np.add.reduce(a, axis=None)) and not np.isfinite(a).all():
                where = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
                raise ValueError(f"Gaussian.{name} has a non-finite entry ({a[where]} at "
                                 f"index {where}); expected finite values")
        return super().__new__(cls, m, P)

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
        return Gaussian._make((self.mean[index], self.cov[index]))


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
    return Gaussian._make((m, P))
