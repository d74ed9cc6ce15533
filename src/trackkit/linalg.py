"""Batched linear algebra for covariances: symmetrise, check, factor, solve.

All functions take arrays with leading batch axes, ``(..., n, n)``, and never loop in Python
over them. Errors name the quantity (``name``) so that a user learns *which* covariance
was bad, not just that a Cholesky failed somewhere.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "symmetrize",
    "cholesky",
    "cholesky_t",
    "solve_psd",
    "check_covariance",
    "gaussian_loglik",
    "quadratic_form",
    "mm",
    "mmT",
    "psd_factor",
]

Array = NDArray[np.float64]


def symmetrize(P: Array) -> Array:
    """``(P + P^T) / 2`` over the last two axes."""
    out = P + P.mT
    out *= 0.5
    return out


def mm(A: Array, B: Array) -> Array:
    """Batched matrix product ``A B`` over the last two axes, with broadcasting.

    For stacks of many tiny matrices where one dimension is 1 (a scalar measurement: P h,
    K k^T), numpy's einsum kernel is about twice as fast as matmul, which dispatches one
    small GEMM per matrix; with every dimension 2 or more einsum is 3-10x slower than matmul
    (numpy 2.4, measured), so it is used only in the first case.
    """
    if A.ndim <= 2 and B.ndim <= 2:
        return A @ B
    if 1 in (A.shape[-2], A.shape[-1], B.shape[-1]):
        return np.einsum("...ij,...jk->...ik", A, B)
    return A @ B


def mmT(A: Array, B: Array) -> Array:
    """Batched ``A B^T`` over the last two axes (see ``mm``)."""
    if A.ndim <= 2 and B.ndim <= 2:
        return A @ B.T
    if 1 in (A.shape[-2], A.shape[-1], B.shape[-2]):
        return np.einsum("...ij,...kj->...ik", A, B)
    return A @ B.mT


class _Triu(NamedTuple):
    """Upper-triangle bookkeeping of an n x n matrix (row-major, read-only arrays)."""

    i: NDArray[np.intp]  # row of each upper entry, (T,) with T = n (n + 1) / 2
    j: NDArray[np.intp]  # its column
    flat: NDArray[np.intp]  # its position in the flattened matrix, i * n + j
    twin: NDArray[np.intp]  # for every entry of the full matrix, its upper-triangle index
    full_twin: NDArray[np.intp]  # ... and that entry's position in the flattened matrix


_TRIU: dict[int, _Triu] = {}


def triu(n: int) -> _Triu:
    """Cached upper-triangle indices for n x n matrices (see ``mirror``)."""
    t = _TRIU.get(n)
    if t is None:
        i, j = np.triu_indices(n)
        pos = np.empty((n, n), dtype=np.intp)
        pos[i, j] = np.arange(i.size)
        pos[j, i] = pos[i, j]
        flat = i * n + j
        t = _Triu(i, j, flat, pos.ravel(), flat[pos.ravel()])
        for a in t:
            a.flags.writeable = False
        _TRIU[n] = t
    return t


def mirror(upper: Array, n: int) -> Array:
    """Full symmetric matrices ``(..., n, n)`` from their upper triangles ``(..., T)``
    (row-major order, as ``triu(n).flat``): exactly symmetric, whatever rounding produced
    the upper triangle."""
    return upper[..., triu(n).twin].reshape(upper.shape[:-1] + (n, n))


def _where_bad(mask: NDArray[np.bool_]) -> str:
    idx = np.argwhere(mask)
    first = tuple(int(i) for i in idx[0]) if idx.size else ()
    return f"{int(mask.sum())} of {mask.size} batch rows (first at index {first})"


#: smallest stack for which the vectorised small-matrix Cholesky (factor columns, batch
#: last) beats LAPACK's per-matrix calls (numpy 2.4, n = 4: about equal at 200 matrices,
#: twice as fast at 1000); :func:`cholesky`, which also transposes the result back to
#: ``(..., n, n)``, switches at ``CHOL_MIN_BATCH_FULL``
CHOL_MIN_BATCH = 200
CHOL_MIN_BATCH_FULL = 300
CHOL_MAX_N = 6


def cholesky_t(P: Array) -> Array | None:
    """Lower Cholesky factors of a stack ``P (N, n, n)``, batch axis last:
    ``C[j, i] = L[:, i, j]`` (shape ``(n, n, N)``, zeros above the diagonal), or ``None``
    when some matrix is not positive definite (a pivot not > 0, or nan).

    Cholesky-Crout with every scalar formula vectorised over the batch, so about 2 n^2
    numpy calls on contiguous length-N rows replace N LAPACK calls; only the lower triangle
    of ``P`` is read, as LAPACK does. ``C[j].T`` is column j of every factor, which is what
    sigma points need (``x +- c L[:, j]``).
    """
    N, n = P.shape[0], P.shape[-1]
    C = np.zeros((n, n, N))
    with np.errstate(invalid="ignore", divide="ignore"):  # a bad pivot is caught below
        for j in range(n):
            s = C[j, j]
            np.copyto(s, P[:, j, j])
            for k in range(j):
                lk = C[k, j]
                s -= lk * lk
            np.sqrt(s, out=s)
            if j + 1 < n:
                t = C[j, j + 1:]  # rows i > j of column j
                np.copyto(t, P[:, j + 1:, j].T)
                for k in range(j):
                    t -= C[k, j + 1:] * C[k, j]
                t /= s
    # every pivot > 0 (a negative one became nan and a zero one 0, and both are caught here)
    if not (C.reshape(n * n, N)[:: n + 1] > 0).all():
        return None
    return C


def cholesky(P: Array, name: str = "covariance") -> Array:
    """Lower Cholesky factor ``L`` with ``L L^T = P``, batched.

    Raises ``ValueError`` naming ``name`` and the first failing batch row when some ``P`` is
    not positive definite; nothing is repaired (no jitter is added). Large stacks of small
    matrices are factored by :func:`cholesky_t` (same factor up to rounding).
    """
    P = np.asarray(P)
    n = P.shape[-1] if P.ndim > 2 and P.shape[-2] == P.shape[-1] else 0
    if (0 < n <= CHOL_MAX_N and P.dtype == np.float64
            and P.size >= CHOL_MIN_BATCH_FULL * n * n):
        C = cholesky_t(P.reshape(-1, n, n))
        if C is not None:
            return np.ascontiguousarray(C.transpose(2, 1, 0)).reshape(P.shape)
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        P = np.asarray(P)
        eig_min = np.linalg.eigvalsh(P)[..., 0] if P.size else np.zeros(0)
        bad = ~(eig_min > 0)
        where = _where_bad(np.atleast_1d(bad)) if P.ndim > 2 else "the matrix"
        raise ValueError(
            f"{name} is not positive definite: smallest eigenvalue "
            f"{float(np.min(eig_min)):.3g} in {where}; expected a symmetric positive "
            f"definite matrix of shape {P.shape}"
        ) from None


def solve_psd(S: Array, B: Array, name: str = "innovation covariance") -> Array:
    """``S^{-1} B`` for symmetric positive-definite ``S`` of shape ``(..., m, m)``.

    ``B`` has shape ``(..., m, k)``. For m = 1 and m = 2, the usual sizes of a tracking
    measurement, the explicit inverse is used: it is exact for SPD matrices of that size and
    avoids LAPACK's per-matrix call overhead, which dominates small batched problems.
    """
    m = S.shape[-1]
    if S.ndim == 2:
        return _solve_single(S, B, name)
    if m == 1:
        s = S[..., 0, 0]
        if not (s > 0).all():
            raise ValueError(f"{name} is not positive definite: {_where_bad(~(s > 0))}")
        return B / S[..., :1, :]
    if m == 2:
        a, b, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
        det = a * d - b * b
        if not (np.all(det > 0) and np.all(a > 0)):
            bad = ~((det > 0) & (a > 0))
            raise ValueError(f"{name} is not positive definite: {_where_bad(bad)}")
        inv = np.empty(S.shape)
        inv[..., 0, 0], inv[..., 1, 1] = d / det, a / det
        inv[..., 0, 1] = inv[..., 1, 0] = -b / det
        return mm(inv, B)
    L = cholesky(S, name)
    y = np.linalg.solve(L, B)
    return np.linalg.solve(L.mT, y)


def _solve_single(S: Array, B: Array, name: str) -> Array:
    """Unbatched ``S^{-1} B``; explicit for m <= 2, else Cholesky proves S definite."""
    m = S.shape[0]
    if m == 1:
        s = float(S[0, 0])
        if not s > 0:
            raise ValueError(f"{name} is not positive definite: S = {s!r}")
        return B / s
    if m == 2:
        a, b, _, d = S.ravel().tolist()
        det = a * d - b * b
        if not (a > 0 and det > 0):
            raise ValueError(f"{name} is not positive definite: S = {S.tolist()}")
        return np.array([[d, -b], [-b, a]]) @ B / det
    try:
        np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        cholesky(S, name)  # raises with the diagnosis
        raise
    return np.linalg.solve(S, B)


def quadratic_form(S: Array, r: Array, name: str = "innovation covariance") -> Array:
    """``r^T S^{-1} r`` over the last axis of ``r`` (shape ``(..., m)``), e.g. NIS or NEES.

    For m > 2 it is ``|L^{-1} r|^2`` with ``L L^T = S``: one triangular solve.
    """
    if S.shape[-1] <= 2:
        return (r * solve_psd(S, r[..., None], name)[..., 0]).sum(-1)
    y = np.linalg.solve(cholesky(S, name), r[..., None])[..., 0]
    return (y * y).sum(-1)


_LOG_2PI = float(np.log(2.0 * np.pi))


def gaussian_loglik(nu: Array, S: Array) -> Array:
    """``log N(nu; 0, S) = -(nu^T S^-1 nu + log det S + m log 2 pi) / 2`` per batch row."""
    m = S.shape[-1]
    if m == 1:
        logdet = np.log(S[..., 0, 0])
    elif m == 2:
        logdet = np.log(S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0])
    else:
        logdet = np.linalg.slogdet(S)[1]
    return -0.5 * (quadratic_form(S, nu) + logdet + m * _LOG_2PI)


def check_covariance(P: Array, name: str, n: int | None = None, psd: bool = True) -> Array:
    """Validate a batched covariance and return it as a float array.

    Checks the trailing shape ``(n, n)``, finiteness, symmetry (to 1e-9 relative) and, when
    ``psd``, positive semi-definiteness via the eigenvalues. Raises ``ValueError`` that names
    ``name``, the shape and what was expected.
    """
    P = np.asarray(P, dtype=float)
    if P.ndim < 2 or P.shape[-1] != P.shape[-2] or (n is not None and P.shape[-1] != n):
        want = f"(..., {n}, {n})" if n is not None else "(..., n, n)"
        raise ValueError(f"{name} has shape {P.shape}; expected {want}")
    if not np.all(np.isfinite(P)):
        raise ValueError(f"{name} has non-finite entries: {_where_bad(~np.isfinite(P))}")
    scale = np.max(np.abs(P), axis=(-1, -2), keepdims=True)
    asym = np.abs(P - np.swapaxes(P, -1, -2)) > 1e-9 * np.maximum(scale, 1e-300)
    if np.any(asym):
        raise ValueError(f"{name} is not symmetric: {_where_bad(asym.any(axis=(-1, -2)))}")
    if psd:
        eig_min = np.linalg.eigvalsh(P)[..., 0]
        bad = eig_min < -1e-10 * np.max(scale, axis=(-1, -2))
        if np.any(bad):
            raise ValueError(
                f"{name} is not positive semi-definite: smallest eigenvalue "
                f"{float(np.min(eig_min)):.3g} in {_where_bad(np.atleast_1d(bad))}"
            )
    return P


def psd_factor(P: ArrayLike, name: str = "covariance", sample: bool = False) -> Array:
    """A factor ``L`` with ``L L^T = P`` for symmetric positive semi-definite ``P``
    ``(..., n, n)``: the Cholesky factor for one matrix when it exists, else (and always for
    a stack, so that each row's factor depends on that row alone) ``V sqrt(diag(lambda))`` from
    the eigen-decomposition, with eigenvalues down to ``-1e-10 max|P|`` taken as 0. A
    singular P (a component without noise) is fine; an indefinite one raises ValueError
    naming ``name``. ``sample``: P is a weighted sample covariance (PSD by construction), so
    a negative eigenvalue is the rounding of its sums and is taken as 0 whatever its size: a
    cloud collapsed to a point has ``max|P|`` at the rounding level of its offsets."""
    P = np.asarray(P, dtype=float)
    if P.ndim == 2:
        try:
            return np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            pass
    lam, V = np.linalg.eigh(P)
    scale = np.abs(P).max(axis=(-2, -1)) if P.size else np.zeros(P.shape[:-2])
    bad = lam[..., 0] < -1e-10 * scale
    if not sample and np.any(bad):
        raise ValueError(f"{name} is not positive semi-definite: smallest eigenvalue "
                         f"{float(lam[..., 0].min()):.3g} in {int(np.sum(bad))} of "
                         f"{max(1, bad.size)} matrices; expected a symmetric PSD matrix")
    return V * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]
