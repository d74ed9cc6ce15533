"""Beliefs: what a filter carries from one step to the next.

A belief is plain data, a NamedTuple of arrays whose leading axes are batch axes (Monte
Carlo runs, tracks, particles, agents) and, for a filtered sequence, a leading time axis.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.linalg import check_covariance, symmetrize
from trackkit.renamed import renamed_attribute

__all__ = ["Gaussian", "Particles", "Innovation", "check_gaussian", "moment_match"]


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


class _ParticlesFields(NamedTuple):
    states: NDArray[np.float64]
    log_weights: NDArray[np.float64]
    rng: np.random.Generator | None = None
    lost: NDArray[np.int64] | None = None


class Particles(_ParticlesFields):
    """Weighted particles ``{x_i, w_i}``, i = 1..N, per batch row.

    ``states`` is ``(..., N, n)``: leading batch axes (runs or tracks), then the particles.
    ``log_weights`` is ``(..., N)``, normalised per row: ``logsumexp(log_weights, -1) == 0``
    (a particle may have weight 0, ``-inf``; a whole row may not). ``rng`` is the generator a
    stochastic filter draws from (it travels with the belief, so a run is reproducible from
    its seed alone). ``lost`` counts, per batch row, the updates in which no particle could
    explain the measurement (every likelihood zero), which the particle filter rejects rather
    than turn into nan; None means none yet.

    Construction checks the shapes, that the states are finite and that every row's weights
    are normalised (to 1e-9), naming the field. ``Particles._make((states, log_weights, rng))``
    is the unchecked constructor for a filter's own outputs (``lost`` may be left out there).
    """

    __slots__ = ()

    def __new__(cls, states: ArrayLike, log_weights: ArrayLike,
                rng: np.random.Generator | None = None,
                lost: ArrayLike | None = None) -> Particles:
        X = np.asarray(states, dtype=float)
        lw = np.asarray(log_weights, dtype=float)
        if X.ndim < 2:
            raise ValueError(f"Particles.states has shape {X.shape}; expected (..., N, n): "
                             "batch axes, then particles, then state components")
        if lw.shape != X.shape[:-1]:
            raise ValueError(f"Particles.log_weights has shape {lw.shape}; the states "
                             f"{X.shape} need ({', '.join(map(str, X.shape[:-1]))}), one "
                             "log-weight per particle")
        if not np.isfinite(X).all():
            where = tuple(int(i) for i in np.argwhere(~np.isfinite(X))[0])
            raise ValueError(f"Particles.states has a non-finite entry ({X[where]} at index "
                             f"{where}); expected finite values")
        if np.isnan(lw).any() or (lw == np.inf).any():
            bad = lw[np.isnan(lw) | (lw == np.inf)][0]
            raise ValueError(f"Particles.log_weights has an entry {bad}; expected finite "
                             "values or -inf (weight 0)")
        top = lw.max(-1, keepdims=True)
        with np.errstate(invalid="ignore"):
            lse = (np.log(np.exp(lw - top).sum(-1, keepdims=True)) + top)[..., 0]
        off = ~(np.abs(lse) <= 1e-9)
        if off.any():
            where = tuple(int(i) for i in np.argwhere(off)[0])
            raise ValueError(
                f"Particles.log_weights are not normalised: logsumexp over the particles is "
                f"{float(lse[where]):.6g} in row {where} ({int(off.sum())} of {off.size} "
                "rows); expected 0 (use trackkit.filters.resample.normalise_log_weights)")
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise ValueError(f"Particles.rng is a {type(rng).__name__}; expected a "
                             "numpy.random.Generator or None")
        if lost is not None:
            lost = np.asarray(lost)
            if lost.shape != X.shape[:-2] or not np.issubdtype(lost.dtype, np.integer):
                raise ValueError(f"Particles.lost has shape {lost.shape} and dtype "
                                 f"{lost.dtype}; expected integers of the batch shape "
                                 f"{X.shape[:-2]}")
        return super().__new__(cls, X, lw, rng, lost)

    @classmethod
    def _make(cls, iterable) -> Particles:
        t = tuple(iterable)
        if not 2 <= len(t) <= 4:
            raise TypeError(f"Particles._make: expected 2 to 4 fields, got {len(t)}")
        return tuple.__new__(cls, t + (None,) * (4 - len(t)))

    @property
    def dim(self) -> int:
        return int(np.shape(self.states)[-1])

    @property
    def n_particles(self) -> int:
        return int(np.shape(self.states)[-2])

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return tuple(np.shape(self.states)[:-2])

    @property
    def weights(self) -> NDArray[np.float64]:
        """``exp(log_weights)``, ``(..., N)``: each row sums to 1."""
        return np.exp(self.log_weights)

    def at(self, index) -> Particles:
        """The particles of a batch index (the index applies to the batch axes only)."""
        if not self.batch_shape:
            raise IndexError("Particles.at: this belief has no batch axes")
        probe = np.empty(self.batch_shape, dtype=bool)[index]  # an index past the batch fails
        del probe
        lost = None if self.lost is None else self.lost[index]
        return Particles._make((self.states[index], self.log_weights[index], self.rng, lost))


class Innovation(NamedTuple):
    """Measurement innovation ``nu = z - zhat`` (angles wrapped) and its covariance S.

    Rows with a missing measurement (``nan`` in z) have a ``nan`` innovation.
    """

    nu: NDArray[np.float64]
    cov: NDArray[np.float64]

    residual = renamed_attribute("Innovation", "residual", "nu")

    @property
    def nis(self) -> NDArray[np.float64]:
        """Normalised innovation squared ``nu^T S^{-1} nu`` per batch row (nan where missing)."""
        from trackkit.linalg import quadratic_form

        return quadratic_form(self.cov, self.nu)


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


def moment_match(w: NDArray[np.float64], X: NDArray[np.float64], P: NDArray[np.float64],
                 group: NDArray[np.intp] | None = None, size: int | None = None
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The Gaussian with the first two moments of the mixture ``sum_k w_k N(x_k, P_k)``
    (weights summing to 1):

        x = sum_k w_k x_k
        P = sum_k w_k (P_k + (x_k - x)(x_k - x)^T)          (symmetrised)

    Without ``group``, one mixture per batch row, its components along the last batch axis:
    ``w (..., K)``, ``X (..., K, n)``, ``P (..., K, n, n)``. With ``group (K,)``, ``size``
    mixtures whose components are scattered along axis 0 (``w (K, ...)``, ``X (K, ..., n)``,
    ``P (K, ..., n, n)``), component k in mixture ``group[k]`` (e.g. a track's prediction
    and its gated hypotheses), summed in the order of k; a mixture without components gets
    zeros. Returns ``(x, P)``.
    """
    if group is None:
        x = np.einsum("...k,...kn->...n", w, X)
        d = X - x[..., None, :]
        Pm = np.einsum("...k,...kab->...ab", w, P + d[..., :, None] * d[..., None, :])
        return x, symmetrize(Pm)
    x = np.zeros((size,) + X.shape[1:])
    np.add.at(x, group, w[..., None] * X)
    d = X - x[group]
    Pm = np.zeros((size,) + P.shape[1:])
    np.add.at(Pm, group, w[..., None, None] * (P + d[..., :, None] * d[..., None, :]))
    return x, symmetrize(Pm)
