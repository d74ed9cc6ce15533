"""Resampling, weights and kernel moves of particle filters, batched over leading axes.

Every function takes weights ``w (..., N)`` normalised on the last axis (or log-weights) and
works on all batch rows at once; no Python loop over rows or particles.

Effective sample size (Kish; Liu and Chen 1995): ``ESS = 1 / sum_i w_i^2``, in [1, N]. A
filter resamples a row only when its ESS falls below a fraction of N.

Resamplers return ancestor indices ``a (..., n)``, sorted per row; ``o_i = #{j : a_j = i}``
is particle i's offspring count, ``sum_i o_i = n``, and ``E[o_i] = n w_i`` for all four.
With ``c_i = w_1 + ... + w_i`` (``c_0 = 0``), particle i owns the interval ``[c_{i-1}, c_i)``
of [0, 1), and a point ``u`` in it selects i. The schemes differ in their points:

* multinomial: n independent uniforms; ``o ~ Multinomial(n, w)``,
  ``Var o_i = n w_i (1 - w_i)``;
* stratified (Kitagawa 1996): one uniform in each stratum, ``u_k = (k + U_k) / n``,
  k = 0..n-1; ``o_i`` is a sum of independent Bernoulli(p_ik), ``p_ik = n |[c_{i-1}, c_i) cap
  [k/n, (k+1)/n)|``, ``Var o_i = sum_k p_ik (1 - p_ik)``;
* systematic (Carpenter, Clifford and Fearnhead 1999): one uniform, ``u_k = (k + U) / n``;
  ``o_i`` is ``floor(n w_i)`` or ``ceil(n w_i)``, ``Var o_i = f (1 - f)`` with
  ``f = n w_i - floor(n w_i)``;
* residual (Liu and Chen 1998): ``floor(n w_i)`` copies, then a multinomial draw of the
  remaining ``n_r = n - sum_i floor(n w_i)`` with probabilities ``r_i / n_r``,
  ``r_i = n w_i - floor(n w_i)``; ``Var o_i = n_r p_i (1 - p_i)``, ``p_i = r_i / n_r``.

What each keeps: residual keeps every particle with ``w_i >= 1/n``; systematic every one with
``w_i > 1/n`` (its count is at least ``floor(n w_i) >= 1``). Stratified keeps every particle
with ``w_i >= 2/n`` (its interval then holds a whole stratum) but not every one above 1/n: an
interval of length in (1/n, 2/n) can straddle a stratum boundary without holding a stratum, and
with ``a`` and ``b`` the parts of it (in units of 1/n) in the two strata it touches, the
particle is lost with probability ``(1 - a)(1 - b)``, up to 1/4 for a weight just above 1/n.
Multinomial keeps nothing for sure.

Nothing searches the points one by one. With ``K_i = #{k : u_k < c_i}`` (in closed form:
systematic ``ceil(n c_i - U)`` clipped to [0, n]; stratified, with ``m = floor(n c_i)``,
``m + [U_m < n c_i - m]``; multinomial and residual the cumulative sums of their counts),
point k goes to particle ``#{i : K_i <= k}``, a cumulative histogram of K that one
``np.bincount`` computes for every row at once; so a resampling costs a few passes over
``(..., N)``.

Regularisation (Musso, Oudjane and Le Gland 2001): after resampling, ``x_i <- x_i + h D e_i``,
``e_i ~ N(0, I)``, with ``D D^T = S`` the weighted covariance of the particles and the
bandwidth optimal for a Gaussian kernel and a Gaussian density,
``h = A N^(-1/(n+4))``, ``A = (4 / (n + 2))^(1/(n+4))``. The jitter keeps the mean and
inflates the covariance to ``(1 + h^2) S`` in expectation. With shrinkage (Liu and West
2001) each particle is first pulled towards the mean ``m``,
``x_i <- m + a (x_i - m) + h D e_i``, ``a = sqrt(1 - h^2)``, so the jittered cloud keeps both
the mean and the covariance ``a^2 S + h^2 S = S``: repeated resampling no longer widens it.

Roughening (Gordon, Salmond and Smith 1993): ``x_ij <- x_ij + sigma_j e_ij`` with
``sigma_j = K E_j N^(-1/n)``, ``E_j`` the range (max - min) of component j over the particles
and K a tuning constant (0.2 in the paper).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit import linalg
from trackkit.angles import wrap
from trackkit.filters import particle_fast as pf

__all__ = [
    "systematic",
    "stratified",
    "residual",
    "multinomial",
    "RESAMPLERS",
    "effective_sample_size",
    "normalise_log_weights",
    "logsumexp",
    "weighted_mean_cov",
    "regularise",
    "roughen",
    "optimal_bandwidth",
]

Array = NDArray[np.float64]
Indices = NDArray[np.intp]

#: how far a row of weights may sum from 1 (relative) before a resampler refuses it
_SUM_TOL = 1e-9


# --------------------------------------------------------------------------------------------
# Weights
# --------------------------------------------------------------------------------------------


def logsumexp(a: ArrayLike, axis: int = -1) -> Array:
    """``log(sum(exp(a)))`` along ``axis`` without overflow or underflow; a row of ``-inf``
    gives ``-inf`` (not nan)."""
    a = np.asarray(a, dtype=float)
    top = a.max(axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)  # an all -inf row: exp(-inf) = 0, log 0 = -inf
    with np.errstate(divide="ignore"):
        out = np.log(np.exp(a - top).sum(axis=axis, keepdims=True)) + top
    return np.squeeze(out, axis=axis)


def normalise_log_weights(log_weights: ArrayLike) -> tuple[Array, Array]:
    """``(log w - L, L)`` per row with ``L = logsumexp(log w)`` over the last axis.

    ``L`` is the log of the row's total weight (after a particle filter's update, the log of
    its estimate of the measurement's likelihood when the weights include the constants). A
    row whose every entry is ``-inf`` has ``L = -inf`` and is returned unchanged (all
    ``-inf``), for the caller to deal with; nan is refused.
    """
    lw = np.asarray(log_weights, dtype=float)
    if lw.ndim < 1:
        raise ValueError("log_weights is a scalar; expected shape (..., N)")
    L = logsumexp(lw)
    if np.isnan(L).any():
        raise ValueError(f"log_weights has nan entries in {int(np.isnan(L).sum())} rows; "
                         "expected finite values or -inf")
    if (L == np.inf).any():
        raise ValueError("log_weights has +inf entries; expected finite values or -inf")
    dead = L == -np.inf
    return lw - np.where(dead, 0.0, L)[..., None], L


def effective_sample_size(log_weights: ArrayLike) -> Array:
    """Kish's ``ESS = 1 / sum_i w_i^2`` per row, ``(...,)``, from normalised log-weights."""
    lw = np.asarray(log_weights, dtype=float)
    return np.exp(-logsumexp(2.0 * lw))


def _check_weights(weights: ArrayLike, n: int | None, where: str) -> tuple[Array, int]:
    w = np.asarray(weights, dtype=float)
    if w.ndim < 1 or w.shape[-1] < 1:
        raise ValueError(f"{where}: weights has shape {w.shape}; expected (..., N), N >= 1")
    lo = w.min() if w.size else 0.0
    if not (lo >= 0) or not np.isfinite(w).all():
        raise ValueError(f"{where}: weights has entries that are negative or not finite "
                         f"(smallest {lo}); expected finite weights >= 0")
    s = w.sum(-1)
    off = ~(np.abs(s - 1.0) <= _SUM_TOL)
    if off.any():
        first = float(s[off].ravel()[0])
        raise ValueError(f"{where}: weights sum to {first!r} in {int(off.sum())} of "
                         f"{off.size} rows; expected each row to sum to 1")
    if n is None:
        n = w.shape[-1]
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"{where}: n = {n!r}; expected an integer >= 1 (offspring per row)")
    return w, int(n)


def _cdf(w: Array) -> Array:
    """Cumulative weights ``c_i``, ending at exactly 1 on every row."""
    c = np.cumsum(w, axis=-1)
    c /= c[..., -1:]
    return c


def _ancestors(K: NDArray[np.integer], n: int) -> Indices:
    """Sorted ancestor indices ``(..., n)`` from ``K_i = #{points < c_i}`` ``(..., N)``
    (non-decreasing, ``K_N = n``): point k goes to particle ``#{i : K_i <= k}``, a
    cumulative histogram of K, all rows in one ``np.bincount``."""
    N = K.shape[-1]
    rows = math.prod(K.shape[:-1])
    offset = (n + 1) * np.arange(rows, dtype=np.intp).reshape(K.shape[:-1] + (1,))
    h = np.bincount((K + offset).ravel(), minlength=rows * (n + 1))
    a = np.cumsum(h.reshape(K.shape[:-1] + (n + 1,))[..., :n], axis=-1)
    return np.minimum(a, N - 1, out=a)  # (K_N = n: no point lies past the last particle)


def _below_from_counts(counts: NDArray[np.integer]) -> NDArray[np.intp]:
    return np.cumsum(counts, axis=-1, dtype=np.intp)


# --------------------------------------------------------------------------------------------
# Resamplers
# --------------------------------------------------------------------------------------------


def systematic(weights: ArrayLike, rng: np.random.Generator | None,
               n: int | None = None) -> Indices:
    """Systematic resampling: points ``u_k = (k + U) / n``, one ``U ~ U[0, 1)`` per row
    (``rng.random(batch_shape)``). Returns sorted ancestor indices ``(..., n)``."""
    w, n = _check_weights(weights, n, "systematic")
    return _systematic(w, np.random.default_rng() if rng is None else rng, n)


def _systematic(w: Array, rng: np.random.Generator, n: int) -> Indices:
    U = np.asarray(rng.random(w.shape[:-1]), dtype=float)
    if w.size >= pf.COMPILED_WEIGHTS:
        return pf.systematic_ancestors(w, U, n)
    return _systematic_numpy(w, U, n)


def _systematic_numpy(w: Array, U: Array, n: int) -> Indices:
    c = _cdf(w)
    # #{k in 0..n-1 : (k + U) / n < c} = ceil(n c - U), in [0, n]
    c *= n
    c -= U[..., None]
    np.ceil(c, out=c)
    np.clip(c, 0, n, out=c)
    return _ancestors(c.astype(np.intp), n)


def stratified(weights: ArrayLike, rng: np.random.Generator | None,
               n: int | None = None) -> Indices:
    """Stratified resampling: points ``u_k = (k + U_k) / n``, independent ``U_k ~ U[0, 1)``
    (``rng.random(batch_shape + (n,))``). Returns sorted ancestor indices ``(..., n)``."""
    w, n = _check_weights(weights, n, "stratified")
    return _stratified(w, np.random.default_rng() if rng is None else rng, n)


def _stratified(w: Array, rng: np.random.Generator, n: int) -> Indices:
    U = np.asarray(rng.random(w.shape[:-1] + (n,)), dtype=float)
    x = n * _cdf(w)
    m = np.minimum(np.floor(x), n).astype(np.intp)  # the stratum holding c (n when c = 1)
    Um = np.take_along_axis(U, np.minimum(m, n - 1), axis=-1)
    # strata below m all lie below c; stratum m's point does when U_m < n c - m
    K = m + ((m < n) & (Um < x - m))
    return _ancestors(K, n)


def multinomial(weights: ArrayLike, rng: np.random.Generator | None,
                n: int | None = None) -> Indices:
    """Multinomial resampling: ``o ~ Multinomial(n, w)`` per row (``rng.multinomial``).
    Returns sorted ancestor indices ``(..., n)``."""
    w, n = _check_weights(weights, n, "multinomial")
    return _multinomial(w, np.random.default_rng() if rng is None else rng, n)


def _multinomial(w: Array, rng: np.random.Generator, n: int) -> Indices:
    p = w / w.sum(-1, keepdims=True)
    return _ancestors(_below_from_counts(rng.multinomial(n, p)), n)


def residual(weights: ArrayLike, rng: np.random.Generator | None,
             n: int | None = None) -> Indices:
    """Residual resampling: ``floor(n w_i)`` copies of particle i, then a multinomial draw of
    the rest from the residual weights. Returns sorted ancestor indices ``(..., n)``."""
    w, n = _check_weights(weights, n, "residual")
    return _residual(w, np.random.default_rng() if rng is None else rng, n)


def _residual(w: Array, rng: np.random.Generator, n: int) -> Indices:
    nw = n * (w / w.sum(-1, keepdims=True))
    base = np.floor(nw)
    r = nw - base
    n_r = n - base.sum(-1).astype(np.int64)
    tot = r.sum(-1, keepdims=True)
    # a row with nothing left to draw gets any valid probabilities (it draws 0 of them)
    p = np.where(tot > 0, r / np.where(tot > 0, tot, 1.0), 1.0 / w.shape[-1])
    counts = base.astype(np.int64) + rng.multinomial(np.maximum(n_r, 0), p)
    return _ancestors(_below_from_counts(counts), n)


#: the resamplers by name (``PF(resampler=...)``)
RESAMPLERS: dict[str, Callable[..., Indices]] = {
    "systematic": systematic,
    "stratified": stratified,
    "residual": residual,
    "multinomial": multinomial,
}

#: the same without the input checks, ``kernel(w, rng, n)``, for a filter's own weights
KERNELS: dict[str, Callable[[Array, np.random.Generator, int], Indices]] = {
    "systematic": _systematic,
    "stratified": _stratified,
    "residual": _residual,
    "multinomial": _multinomial,
}


# --------------------------------------------------------------------------------------------
# Moments, kernel moves
# --------------------------------------------------------------------------------------------


def _angle_list(angles: Sequence[int], n: int, where: str) -> list[int]:
    out = []
    for j in angles:
        if isinstance(j, bool) or not isinstance(j, int | np.integer) or not -n <= j < n:
            raise ValueError(f"{where}: angles = {tuple(angles)!r}; expected indices of "
                             f"state components in [0, {n})")
        out.append(int(j) % n)
    return sorted(set(out))


def weighted_mean_cov(states: ArrayLike, weights: ArrayLike | None,
                      angles: Sequence[int] = ()) -> tuple[Array, Array]:
    """Weighted mean ``(..., n)`` and covariance ``(..., n, n)`` of particles ``(..., N, n)``.

    ``m = sum_i w_i x_i``, ``P = sum_i w_i (x_i - m)(x_i - m)^T`` (the weights sum to 1 on
    each row; P is exactly symmetric); ``weights`` None means equal weights 1/N. Components
    listed in ``angles`` get the circular mean ``atan2(sum w sin, sum w cos)`` and residuals
    wrapped to (-pi, pi].
    """
    X = np.asarray(states, dtype=float)
    if X.ndim < 2:
        raise ValueError(f"weighted_mean_cov: states has shape {X.shape}; expected (..., N, n)")
    N, n = X.shape[-2:]
    if weights is None:
        w = np.broadcast_to(1.0 / N, X.shape[:-1])
    else:
        w = np.asarray(weights, dtype=float)
        if w.shape != X.shape[:-1]:
            raise ValueError(f"weighted_mean_cov: states {X.shape} and weights {w.shape}; "
                             "expected (..., N, n) and (..., N)")
    ang = _angle_list(angles, n, "weighted_mean_cov")
    wc = w[..., :, None]
    # deviations from one particle of the row (small numbers, so the second moment about it
    # loses nothing), stored components-first: every later pass runs along the particles
    ref = X[..., 0, :]
    D = np.empty(X.shape[:-2] + (n, N))
    np.subtract(X.mT, ref[..., :, None], out=D)
    dm = D.mean(-1) if weights is None else (D @ wc)[..., 0]  # sum_i w_i (x_i - ref)
    if ang:
        Xa = X[..., ang].mT
        ma = np.arctan2((np.sin(Xa) @ wc)[..., 0], (np.cos(Xa) @ wc)[..., 0])
        Da = wrap(Xa - ma[..., :, None])  # angles: deviations from the circular mean
        D[..., ang, :] = Da
        dm[..., ang] = (Da @ wc)[..., 0]
        c = dm.copy()
        c[..., ang] = 0.0
        m = ref + c
        m[..., ang] = ma
    else:
        c, m = dm, ref + dm
    if weights is None:
        M = D @ D.mT
        M /= N
    else:
        M = (D * w[..., None, :]) @ D.mT
    # P = sum_i w_i (d_i - c)(d_i - c)^T with c the mean deviation (0 on angles)
    P = M - c[..., :, None] * dm[..., None, :]
    P -= dm[..., :, None] * c[..., None, :]
    P += c[..., :, None] * c[..., None, :]
    P += P.mT
    P *= 0.5
    return m, P


def optimal_bandwidth(n_particles: int, dim: int) -> float:
    """``h = (4 / (n + 2))^(1/(n+4)) N^(-1/(n+4))``: the Gaussian kernel's bandwidth that
    minimises the mean integrated squared error for a Gaussian density (Musso et al.)."""
    return (4.0 / (dim + 2)) ** (1.0 / (dim + 4)) * n_particles ** (-1.0 / (dim + 4))


def regularise(states: ArrayLike, weights: ArrayLike, rng: np.random.Generator | None,
               bandwidth: float | None = None, cov: ArrayLike | None = None,
               angles: Sequence[int] = (), shrink: bool = False,
               mean: ArrayLike | None = None, cov_is_sample: bool = False) -> Array:
    """Gaussian-kernel jitter ``x_i + h D e_i``, ``D D^T = S``, ``e_i ~ N(0, I)``; with
    ``shrink``, ``m + a (x_i - m) + h D e_i``, ``a = sqrt(1 - h^2)`` (Liu and West).

    ``m`` and ``S`` are the weighted mean and covariance of ``(states, weights)`` unless
    ``mean`` (``(..., n)``) and ``cov`` (``(..., n, n)``) are given (a filter passes those of
    its particles before resampling; with ``cov_is_sample`` that covariance is taken as
    :func:`weighted_mean_cov` made it, PSD but for rounding); ``h`` is ``bandwidth`` or
    :func:`optimal_bandwidth`, below 1 with ``shrink``. The expected weighted mean is
    unchanged; the expected covariance becomes ``(1 + h^2) S``, or stays ``S`` with
    ``shrink``. Angle components are shrunk along
    their wrapped deviations from the circular mean and wrapped afterwards.
    """
    X = np.asarray(states, dtype=float)
    w = np.asarray(weights, dtype=float)
    N, n = X.shape[-2:]
    if bandwidth is None:
        bandwidth = optimal_bandwidth(N, n)
    if not (math.isfinite(bandwidth) and bandwidth >= 0):
        raise ValueError(f"regularise: bandwidth = {bandwidth!r}; expected a finite value >= 0")
    if shrink and not bandwidth < 1:
        raise ValueError(f"regularise: bandwidth = {bandwidth!r} with shrink; expected a value "
                         "below 1 (the shrink factor is sqrt(1 - h^2))")
    ang = _angle_list(angles, n, "regularise")
    if cov is None or (shrink and mean is None):
        m, S = weighted_mean_cov(X, w, ang)
    if cov is not None:
        S = np.asarray(cov, dtype=float)
    D = linalg.psd_factor(S, "regularise: the particles' covariance",
                   sample=cov is None or cov_is_sample)
    rng = np.random.default_rng() if rng is None else rng
    e = pf.standard_normals(rng, X.shape)
    out = bandwidth * (e @ D.mT if D.ndim > 2 else e @ D.T)
    if shrink:
        if mean is not None:
            m = np.asarray(mean, dtype=float)
        d = X - m[..., None, :]
        if ang:
            d[..., ang] = wrap(d[..., ang])
        d *= math.sqrt(1.0 - bandwidth**2)
        out += d
        out += m[..., None, :]
    else:
        out += X
    if ang:
        out[..., ang] = wrap(out[..., ang])
    return out


def roughen(states: ArrayLike, rng: np.random.Generator | None, K: float = 0.2,
            angles: Sequence[int] = ()) -> Array:
    """Gordon-Salmond-Smith roughening: ``x_ij + sigma_j e_ij``, ``sigma_j = K E_j N^(-1/n)``
    with ``E_j`` the range of component j over each row's particles (for an angle component,
    the range of its wrapped deviations from the circular mean)."""
    X = np.asarray(states, dtype=float)
    if not (math.isfinite(K) and K >= 0):
        raise ValueError(f"roughen: K = {K!r}; expected a finite value >= 0")
    N, n = X.shape[-2:]
    ang = _angle_list(angles, n, "roughen")
    E = X.max(-2) - X.min(-2)
    if ang:
        a = X[..., ang]
        centre = np.arctan2(np.sin(a).mean(-2), np.cos(a).mean(-2))
        d = wrap(a - centre[..., None, :])
        E[..., ang] = d.max(-2) - d.min(-2)
    sigma = K * E * N ** (-1.0 / n)
    rng = np.random.default_rng() if rng is None else rng
    out = X + sigma[..., None, :] * pf.standard_normals(rng, X.shape)
    if ang:
        out[..., ang] = wrap(out[..., ang])
    return out
