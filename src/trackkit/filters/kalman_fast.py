"""Fast paths of the Kalman kernels in ``trackkit.filters.kalman``: the same equations, ordered
for speed on small matrices and large batches.

Prediction, ``P- = F P F^T + Q``. For an unbatched F (n x n) and P flattened row-major,
``vec(F P F^T) = (F kron F) vec(P)``; only the T = n (n + 1) / 2 rows of ``F kron F`` that
give the upper triangle are kept (``K_u``, T x n^2), so a whole batch of P is one GEMM
``vec_u(P-) = vec(P) K_u^T + vec_u(Q)`` (one GEMV for one P) and the result is mirrored,
exactly symmetric. ``K_u`` grows as n^4: it is used up to ``_KRON_MAX_N`` states; above,
``F P F^T`` is two plain products with the batch folded into their rows.

Update, the Joseph form ``P+ = (I - K H) P (I - K H)^T + K R K^T``, evaluated without forming
``I - K H`` (n x n per row). With ``A = P H^T`` and ``S = H P H^T + R``:

* for the gain ``K = A U``, U the computed inverse of S (one problem; one-dimensional
  measurements in a batch), expanding the Joseph form gives ``P+ = P - A G A^T``,
  ``G = U + U^T - U S U^T`` (m x m). In exact arithmetic ``G = S^{-1}``; an error E in U
  changes G only by ``-E S E^T``, which is the Joseph form's second-order insensitivity to
  gain errors;
* for any gain K (batches of m >= 2 measurements), ``M = (I - K H) P = P - K A^T`` and
  ``P+ = M - (M H^T) K^T + K R K^T = M - W K^T``, ``W = A - K S``, so
  ``P+ = P - K A^T - W K^T`` (W vanishes for the optimal gain).

Both expressions are symmetric in exact arithmetic; only their upper triangle is kept, and
mirrored (for m >= 2 the two products ``K A^T`` and ``W K^T`` are whole batched GEMMs, whose
upper triangle is taken: gathering the triangle's rows of K, A and W first costs 3-30 times
more).

The update kernels take over from the textbook form
(:func:`trackkit.filters.kalman.joseph_update`) for measurements of up to ``FAST_MAX_M``
components; the IMM's fast path updates every model through them too.
``tests/test_fast_paths.py`` pins every path (both sides of ``_KRON_MAX_N``, one problem and
batches, m = 1 to 4) against the textbook form.
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from trackkit.linalg import mirror, mm, mmT, solve_psd, symmetrize, triu

Array = NDArray[np.float64]
_F64 = np.dtype(np.float64)

#: the largest measurement (m components) the update kernels take. At m = 1, 2 they beat the
#: textbook Joseph form 3x for one problem and 1.2-5x for batches of 100-1000 rows (n = 4, 6;
#: below about 30 rows the two are within 20%). From m = 3 the two are within 15% either way
#: (n = 6 .. 10, 1000 rows) but at n = 12, m = 6 the textbook form is 2.2x faster. Up to
#: m = 4 (a multipath-delay sensor's four delays, two azimuth-elevation arrays) the
#: measurements stay here so that their numbers do not move; above it ``kalman.condition``
#: runs the textbook form as written
FAST_MAX_M = 4

#: the Kronecker (upper-triangle GEMM) prediction is used up to this state size: its matrix
#: has n^2 (n + 1) / 2 entries
_KRON_MAX_N = 6



class IdentityCache:
    """Values computed from read-only arrays (a model's or sensor's cached matrices), found
    again by those very arrays.

    An entry holds its key arrays, so no other object can take their ids while it exists,
    and is returned only to the same objects (``is``): an array never gets another's value.
    Only read-only arrays are kept (they cannot change after the value was computed). At
    most ``size`` entries (a few models and step sizes at a time): cleared when full.
    """

    def __init__(self, size: int) -> None:
        self.size = size
        self._entries: dict[tuple[int, int, Hashable], tuple[Array, Any, Any]] = {}

    def get(self, a: Array, b: Array | None = None, tag: Hashable = None) -> Any:
        """The value stored for exactly the arrays ``a`` (and ``b``) and ``tag``, or None."""
        hit = self._entries.get((id(a), id(b), tag))
        if hit is not None and hit[0] is a and hit[1] is b:
            return hit[2]
        return None

    def put(self, value: Any, a: Array, b: Array | None = None, tag: Hashable = None) -> None:
        """Remember ``value`` for the arrays ``a`` (and ``b``) and ``tag`` if neither is
        writeable."""
        if a.flags.writeable or (b is not None and b.flags.writeable):
            return
        if len(self._entries) >= self.size:
            self._entries.clear()
        self._entries[(id(a), id(b), tag)] = (a, b, value)


# Caches of small constant matrices: by value (bytes), or by identity for read-only arrays.
# (F bytes, Q bytes) -> (K_u, K_u^T, Q_u), see predict_matrices
_PREDICT_CACHE: dict[tuple[bytes, bytes], tuple[Array, Array, Array]] = {}
# (F, Q) -> (K_u, Q_u, twin): the unbatched prediction without checks
_SAME = IdentityCache(65)
# (Q_u; N) -> Q_u tiled N times: + Q on a stack as one contiguous pass
_TILED = IdentityCache(9)
# H -> contiguous H^T
_HT = IdentityCache(65)
_ZEROS: dict[int, Array] = {}


# -- prediction ------------------------------------------------------------------------------


def _kron_upper(F: Array) -> Array:
    """Rows of ``F kron F`` for the upper triangle: ``vec_u(F P F^T) = K_u vec(P)``."""
    return np.ascontiguousarray(np.kron(F, F)[triu(F.shape[0]).flat])


def _noise_upper(Q: Array) -> Array:
    """Upper triangle(s) ``(..., T)`` of Q, averaged with the lower one where Q is not exactly
    symmetric (what symmetrising ``F P F^T + Q`` would do)."""
    n = Q.shape[-1]
    if not (Q == Q.mT).all():
        Q = symmetrize(Q)
    return Q.reshape(Q.shape[:-2] + (n * n,))[..., triu(n).flat]


def predict_matrices(F: Array, Q: Array) -> tuple[Array, Array, Array]:
    """``(K_u, K_u^T, Q_u)`` for an unbatched F (n x n, float) and Q (K_u^T contiguous: a
    GEMM with a transposed operand is slower); remembered (by value) when Q is unbatched
    too (the usual case: a model's cached matrices for one step size)."""
    if Q.ndim != 2:
        K_u = _kron_upper(F)
        return K_u, np.ascontiguousarray(K_u.T), _noise_upper(Q)
    key = (F.tobytes(), Q.tobytes())
    value = _PREDICT_CACHE.get(key)
    if value is None:
        K_u = _kron_upper(F)
        value = (K_u, np.ascontiguousarray(K_u.T), _noise_upper(Q))
        for a in value:
            a.flags.writeable = False
        if len(_PREDICT_CACHE) > 256:
            _PREDICT_CACHE.clear()
        _PREDICT_CACHE[key] = value
    return value


def _tiled(Q_u: Array, N: int) -> Array:
    """``Q_u`` repeated N times (flat), remembered for a read-only ``Q_u``."""
    tiled = _TILED.get(Q_u, tag=N)
    if tiled is None:
        tiled = np.tile(Q_u, N)
        tiled.flags.writeable = False
        _TILED.put(tiled, Q_u, tag=N)
    return tiled


def _zeros(n: int) -> Array:
    """A read-only n x n zero matrix (the Q of a bare ``A P A^T``), one per n."""
    z = _ZEROS.get(n)
    if z is None:
        z = _ZEROS[n] = np.zeros((n, n))
        z.flags.writeable = False
    return z


def sandwich(A: Array, P: Array) -> Array:
    """``A P A^T`` for symmetric P ``(..., n, n)`` and A ``(k, n)`` or ``(..., k, n)``.

    For an unbatched A and a stack of P, the product is one matrix multiply on the flattened
    covariances, ``vec(A P A^T) = (A kron A) vec(P)`` (row-major vec), instead of thousands
    of tiny ones. Only the upper triangle is computed and then mirrored, so the result is
    exactly symmetric. For larger n, where the Kronecker matrix grows as n^4, the batch is
    folded into the rows of two plain products (``P A^T``, then ``(A P) A^T``).
    """
    if A.ndim == 2 and P.ndim == 2:
        return A @ P @ A.T
    if A.ndim == 2:
        n, k = P.shape[-1], A.shape[0]
        P = np.ascontiguousarray(P)
        if n <= _KRON_MAX_N and k == n:
            A = np.asarray(A, dtype=float)
            upper = P.reshape(-1, n * n).dot(predict_matrices(A, _zeros(n))[1])
            return mirror(upper, n).reshape(P.shape)
        PAt = (P.reshape(-1, n) @ A.T).reshape(P.shape[:-1] + (k,))
        return (np.ascontiguousarray(PAt.mT).reshape(-1, n) @ A.T).reshape(
            P.shape[:-2] + (k, k)
        )
    return mmT(mm(A, P), A)


def predict_cov(F: Array, P: Array, Q: Array) -> Array | None:
    """``P- = F P F^T + Q``, exactly symmetric (the upper triangle, mirrored); None when F or
    Q is not n x n like P (a model with other shapes: the caller takes the formula as it
    comes).

    Up to ``_KRON_MAX_N`` states with an unbatched F, ``vec_u(P-) = K_u vec(P) + vec_u(Q)``:
    one GEMV for one P (its matrices remembered for a model's read-only F and Q), one GEMM
    for a stack; otherwise the upper triangle of :func:`sandwich` plus that of Q.
    """
    n = P.shape[-1]
    if P.ndim == 2:  # one problem (or a covariance shared by a batch): the shortest path
        hit = _SAME.get(F, Q)
        if hit is not None:
            K_u, Q_u, twin = hit
        elif (n <= _KRON_MAX_N and type(F) is np.ndarray and type(Q) is np.ndarray
                and F.dtype is _F64 and Q.dtype is _F64 and F.shape == Q.shape == (n, n)):
            K_u, _, Q_u = predict_matrices(F, Q)
            twin = triu(n).twin
            _SAME.put((K_u, Q_u, twin), F, Q)  # (a model's read-only matrices only)
        else:
            K_u = None
        if K_u is not None:
            upper = K_u.dot(P.ravel())
            upper += Q_u
            return upper[twin].reshape(n, n)
    F = np.asarray(F, dtype=float)
    Q = np.asarray(Q, dtype=float)
    if F.shape[-2:] != (n, n) or Q.shape[-2:] != (n, n):
        return None
    flat = triu(n).flat
    if F.ndim == 2 and n <= _KRON_MAX_N:
        K_u, K_uT, Q_u = predict_matrices(F, Q)
        if P.ndim == 2:
            upper = K_u.dot(P.ravel())
        else:
            P = np.ascontiguousarray(P)
            upper = P.reshape(-1, n * n).dot(K_uT)
            if Q_u.ndim == 1:  # + Q as one contiguous pass (a short broadcast row is slow)
                flat_upper = upper.reshape(-1)
                flat_upper += _tiled(Q_u, upper.shape[0])
                return mirror(upper, n).reshape(P.shape)
            upper = upper.reshape(P.shape[:-2] + (flat.size,))
    else:
        M = sandwich(F, P)
        upper = M.reshape(M.shape[:-2] + (n * n,))[..., flat]
        Q_u = _noise_upper(Q)
    if Q_u.ndim == 1 or Q_u.shape == upper.shape:
        upper += Q_u
    else:
        upper = upper + Q_u
    return mirror(upper, n)


# -- update ----------------------------------------------------------------------------------


def _transposed(H: Array) -> Array:
    """``H^T`` as a contiguous array (a dot with a transposed operand costs more), kept for
    a read-only H (a sensor's cached Jacobian)."""
    HT = _HT.get(H)
    if HT is None:
        if H.flags.writeable:
            return H.T
        HT = np.ascontiguousarray(H.T)
        _HT.put(HT, H)
    return HT


def update_one(x: Array, P: Array, r: Array, H: Array, R: Array):
    """The Joseph update of one problem (x ``(n,)``, P ``(n, n)``, float H and R, m <=
    ``FAST_MAX_M``): returns ``(x+, P+, S)`` with ``x+ = x + A U r`` and ``P+ = P - A G A^T``,
    ``G = U + U^T - U S U^T`` (the module docstring), U the computed inverse of
    ``S = H P H^T + R``.

    ndarray.dot on contiguous operands (the cheapest call for tiny arrays), the m x m algebra
    in Python floats for m <= 2."""
    AT = H.dot(P)  # A^T = H P (P symmetric)
    m, n = AT.shape
    if m == 2:  # S symmetrised as symmetrize() would, and inverted explicitly
        a, b, c, d = AT.dot(_transposed(H)).ravel().tolist()
        r00, r01, r10, r11 = R.ravel().tolist()
        a, b, d = a + r00, ((b + r01) + (c + r10)) * 0.5, d + r11
        det = a * d - b * b
        if not (a > 0 and det > 0):
            raise ValueError("innovation covariance is not positive definite: "
                             f"S = {[[a, b], [b, d]]}")
        u0, u1, u2 = d / det, -b / det, a / det  # U = [[u0, u1], [u1, u2]]
        v0, v1 = u0 * a + u1 * b, u0 * b + u1 * d  # first row of U S
        v2, v3 = u1 * a + u2 * b, u1 * b + u2 * d  # second row
        g0 = 2.0 * u0 - (v0 * u0 + v1 * u1)  # G = 2 U - U S U
        g1 = 2.0 * u1 - (v0 * u1 + v1 * u2)
        g2 = 2.0 * u2 - (v2 * u1 + v3 * u2)
        r0, r1 = r.tolist()
        SWG = np.array((a, b, b, d, u0 * r0 + u1 * r1, u1 * r0 + u2 * r1, g0, g1, g1, g2))
        S = SWG[:4].reshape(2, 2)
        out = SWG[4:].reshape(3, 2).dot(AT)  # rows: (K r)^T = (U r)^T A^T, then G A^T
        Kr, GAT = out[0], out[1:]
    elif m == 1:
        S = AT.dot(H.T)
        S += R
        s = float(S[0, 0])
        if not s > 0:
            raise ValueError(f"innovation covariance is not positive definite: S = {s!r}")
        u = 1.0 / s
        Kr = AT[0] * (u * float(r[0]))
        GAT = AT * (2.0 * u - u * s * u)
    elif m <= FAST_MAX_M:
        S = symmetrize(AT.dot(H.T) + R)
        U = solve_psd(S, np.eye(m))
        Kr = AT.T.dot(U.dot(r))
        GAT = (U + U.T - U.dot(S).dot(U.T)).dot(AT)
    else:
        raise ValueError(f"update_one takes measurements of 1 to {FAST_MAX_M} components; "
                         f"got {m} (kalman.condition gives larger ones the textbook form)")
    M = P - AT.T.dot(GAT)  # P - A G A^T
    return x + Kr, M.ravel()[triu(n).full_twin].reshape(n, n), S


#: multiply-adds per GEMM call above which OpenBLAS starts a second thread (its
#: SMP_THRESHOLD_MIN x GEMM_MULTITHREAD_THRESHOLD); see :func:`dot_rows`
_ONE_THREAD_GEMM = 65536 * 4

#: batch rows from which :func:`update_batch` hands measurements of m <= 2 with one H and R
#: to :func:`update_columns`: from 1024 rows it is 1.5-2x faster at m = 2 (3-4x at 20 000),
#: and as fast at m = 1 (1.5x at 20 000); n = 4, 6, a position sensor and a general H
COLUMNS_MIN_ROWS = 1024


def dot_rows(a: Array, B: Array) -> Array:
    """``a @ B`` for a tall ``a (N, k)`` and a small ``B (k, m)``, in blocks of rows small
    enough for OpenBLAS to use one thread. These products are memory-bound: a second thread
    gains little on an idle machine and, when the other core is busy, makes the product
    several times slower (measured at 10 000 runs: 3.6 ms against 0.3 ms per call)."""
    N, k = a.shape
    m = B.shape[1]
    if N * k * m <= _ONE_THREAD_GEMM:
        return a.dot(B)
    out = np.empty((N, m))
    step = max(1, _ONE_THREAD_GEMM // (k * m))
    for s in range(0, N, step):
        np.dot(a[s:s + step], B, out=out[s:s + step])
    return out


def _selected(H: Array) -> Array | None:
    """The state indices a 0/1 selection matrix H picks (each row a unit vector), or None."""
    k = H.argmax(axis=1)
    if (H == np.eye(H.shape[1])[k]).all():
        return k
    return None


def update_columns(x: Array, P: Array, r: Array, H: Array, R: Array):
    """The Joseph update of N rows (``x (N, n)``, ``P (N, n, n)``, ``r (N, m)``) with one H
    and R and m <= 2, as :func:`update_one` on whole columns: ``A = P H^T`` as m contiguous
    ``(N, n)`` columns (for a sensor that picks state components, entries of P), the m x m
    algebra entry by entry, ``x+ = x + A U r`` and the upper triangle of
    ``P+ = P - A G A^T``, ``G = 2 U - U S U`` (the module docstring). Returns
    ``(x+, P+, S)``."""
    N, n = x.shape
    m = H.shape[0]
    tri = triu(n)
    Pu = P.reshape(N, n * n)[:, tri.flat]
    k = _selected(H)
    if k is not None:
        Ac = np.stack([P[:, :, ka] for ka in k])
        HA = np.stack([np.stack([P[:, ka, kb] for ka in k], -1) for kb in k])
    else:
        Ac = np.ascontiguousarray(dot_rows(P.reshape(-1, n), H.T).reshape(N, n, m)
                                  .transpose(2, 0, 1))
        HA = dot_rows(Ac.reshape(m * N, n), H.T).reshape(m, N, m)
    if m == 1:
        s = HA[0, :, 0] + R[0, 0]
        if not (s > 0).all():
            solve_psd(s.reshape(N, 1, 1), np.ones((N, 1, 1)))  # raises, naming the row
        u = 1.0 / s
        g = u * (2.0 - s * u)  # G = 2 U - U S U
        xn = x + Ac[0] * (u * r[:, 0])[:, None]
        B0 = g[:, None] * Ac[0]
        Pu -= B0[:, tri.i] * Ac[0][:, tri.j]
        return xn, mirror(Pu, n), s.reshape(N, 1, 1)
    a = HA[0, :, 0] + R[0, 0]
    b = ((HA[1, :, 0] + R[0, 1]) + (HA[0, :, 1] + R[1, 0])) * 0.5  # symmetrised
    d = HA[1, :, 1] + R[1, 1]
    det = a * d - b * b
    if not ((a > 0) & (det > 0)).all():
        solve_psd(np.stack([a, b, b, d], -1).reshape(N, 2, 2), np.ones((N, 2, 1)))  # raises
    u0, u1, u2 = d / det, -b / det, a / det  # U = [[u0, u1], [u1, u2]]
    s0, s1 = u0 * a + u1 * b, u0 * b + u1 * d  # first row of U S
    s2, s3 = u1 * a + u2 * b, u1 * b + u2 * d  # second row
    g0 = 2.0 * u0 - (s0 * u0 + s1 * u1)  # G = 2 U - U S U, entry by entry
    g1 = 2.0 * u1 - (s0 * u1 + s1 * u2)
    g2 = 2.0 * u2 - (s2 * u1 + s3 * u2)
    Ur0 = u0 * r[:, 0] + u1 * r[:, 1]
    Ur1 = u1 * r[:, 0] + u2 * r[:, 1]
    xn = x + Ac[0] * Ur0[:, None] + Ac[1] * Ur1[:, None]
    # A G A^T on the upper triangle: sum_b (A G)_b[i] A_b[j]
    B0 = g0[:, None] * Ac[0] + g1[:, None] * Ac[1]
    B1 = g1[:, None] * Ac[0] + g2[:, None] * Ac[1]
    Pu -= B0[:, tri.i] * Ac[0][:, tri.j] + B1[:, tri.i] * Ac[1][:, tri.j]
    return xn, mirror(Pu, n), np.stack([a, b, b, d], -1).reshape(N, 2, 2)


def _flat(a: Array, batch: tuple[int, ...], N: int, core: tuple[int, ...]) -> Array:
    """``a`` broadcast to ``batch + core`` and reshaped to ``(N,) + core``."""
    if a.shape[: a.ndim - len(core)] != batch:
        a = np.broadcast_to(a, batch + core)
    return a.reshape((N,) + core)


def update_batch(x: Array, P: Array, r: Array, H: Array, R: Array):
    """The Joseph update on any batch shapes (broadcast together, flattened to N rows):
    returns ``(x+, P+, S)``, ``x+ = x + K r`` and the upper triangle of P+ mirrored.

    One measurement (m = 1): ``K = A u``, ``u = 1 / s``, ``P+ = P - g A A^T`` with
    ``g = 2 u - u s u``; m >= 2: ``K = A S^{-1}`` (Cholesky solve), ``W = A - K S`` and
    ``P+ = P - K A^T - W K^T`` (the module docstring). An unbatched H is one GEMM over the
    flattened batch."""
    n, m = P.shape[-1], H.shape[-2]
    batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2], r.shape[:-1], H.shape[:-2],
                                R.shape[:-2])
    N = math.prod(batch)
    if N >= COLUMNS_MIN_ROWS and m <= 2 and H.ndim == 2 and R.ndim == 2:
        xn, Pn, S = update_columns(_flat(x, batch, N, (n,)), _flat(P, batch, N, (n, n)),
                                   _flat(r, batch, N, (m,)), H, R)
        return (xn.reshape(batch + (n,)), Pn.reshape(batch + (n, n)),
                S.reshape(batch + (m, m)))
    P2 = _flat(P, batch, N, (n, n))
    x2, r2 = _flat(x, batch, N, (n,)), _flat(r, batch, N, (m,))
    tri = triu(n)
    i, j = tri.i, tri.j
    Pu = P2.reshape(N, n * n)[:, tri.flat]
    A, S = _gain_terms(P2, H, R, batch)
    if m == 1:
        s = S
        if not (s > 0).all():
            solve_psd(s.reshape(batch + (1, 1)), np.ones(batch + (1, 1)))  # raises
        u = 1.0 / s
        g = u * s
        g *= u
        g -= u
        g -= u  # g = u s u - 2 u = -G
        xn = x2 + A * (u * r2[:, 0])[:, None]  # K r, K = A u
        Pu += g[:, None] * (A[:, i] * A[:, j])
        S = s.reshape(N, 1, 1)
    else:
        K = solve_psd(S, A.mT).mT
        xn = x2 + np.einsum("nij,nj->ni", K, r2)
        W = A - mm(K, S)
        # K A^T + W K^T as two batched products, then its upper triangle: gathering the
        # triangle's rows of K, A and W first builds (N, T, m) temporaries, 3-30x slower
        E = np.matmul(K, A.mT)
        E += np.matmul(W, K.mT)
        Pu -= E.reshape(N, n * n)[:, tri.flat]
    return (xn.reshape(batch + (n,)), mirror(Pu, n).reshape(batch + (n, n)),
            S.reshape(batch + (m, m)))


def _gain_terms(P2: Array, H: Array, R: Array, batch: tuple[int, ...]) -> tuple[Array, Array]:
    """``A = P H^T`` and ``S = H P H^T + R`` of :func:`update_batch` for ``P2 (N, n, n)``
    (the batch flattened): for m = 1 ``A (N, n)`` and ``s (N,)``; for m >= 2 ``A (N, n, m)``
    and ``S (N, m, m)``, symmetrised. An unbatched H is one GEMM over the flattened batch."""
    N, n = P2.shape[0], P2.shape[-1]
    m = H.shape[-2]
    if m == 1:
        h = H[..., 0, :] if H.ndim == 2 else _flat(H, batch, N, (1, n))[:, 0]
        if h.ndim == 1:
            A = P2.reshape(N * n, n).dot(h).reshape(N, n)
            s = A.dot(h)
        else:
            A = np.einsum("nij,nj->ni", P2, h)
            s = np.einsum("ni,ni->n", A, h)
        s += R[..., 0, 0] if R.ndim == 2 else _flat(R, batch, N, (1, 1))[:, 0, 0]
        return A, s
    H2 = H if H.ndim == 2 else _flat(H, batch, N, (m, n))
    R2 = R if R.ndim == 2 else _flat(R, batch, N, (m, m))
    if H2.ndim == 2:
        A = P2.reshape(N * n, n).dot(H2.T).reshape(N, n, m)
    else:
        A = mmT(P2, H2)
    return A, symmetrize(mm(H2, A) + R2)


def innovation_cov(P: Array, H: Array, R: Array) -> Array | None:
    """``S = H P H^T + R`` ``(..., m, m)`` for a batch of P ``(..., n, n)``, computed as the
    batched update (:func:`update_batch`) computes it, so that it equals the S the Kalman
    update returns to the last bit; None where ``kalman.condition`` takes another kernel for
    these shapes (one problem, the column kernel, more than ``FAST_MAX_M`` components)."""
    n, m = P.shape[-1], H.shape[-2]
    batch = np.broadcast_shapes(P.shape[:-2], H.shape[:-2], R.shape[:-2])
    N = math.prod(batch)
    if (P.ndim < 3 or m > FAST_MAX_M
            or (N >= COLUMNS_MIN_ROWS and m <= 2 and H.ndim == 2 and R.ndim == 2)):
        return None
    _, S = _gain_terms(_flat(P, batch, N, (n, n)), H, R, batch)
    return S.reshape(batch + (m, m))
