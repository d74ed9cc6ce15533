"""Composite measurement (Jalalipoor and Kardehi Moghaddam 2021, eqs. 13-33): the maximum-likelihood
constant-velocity state at a reference time from M asynchronous bearings, with its Cramer-Rao bound.

M bearings z(t_k), k = 1..M, of one target are taken from known sensor positions S(t_k) (one
or several sensors, any times). With the constant-velocity transition F(t_k, t_f) (F of
``ConstantVelocity`` with dt = t_k - t_f), the target state at t_k is
X(t_k) = F(t_k, t_f) X(t_f), and the bearing is

    z(t_k) = h(X(t_k), S(t_k)) + w_k,    w_k ~ N(0, sigma_k^2),
    h = atan2(x - x_s, y - y_s)          (nautical: clockwise from north)

The likelihood of X = X(t_f) is Lambda(X; Z) = prod_k p(z(t_k) | X), and

    lambda(X) = -ln Lambda + const = 1/2 sum_k r_k(X)^2,
    r_k(X)    = wrap(z(t_k) - h(F(t_k, t_f) X, S(t_k))) / sigma_k      (wrapped to (-pi, pi])

With H_k = dh/dX(t_f) = [da/dx, da/dy, (t_k - t_f) da/dx, (t_k - t_f) da/dy] (eqs. 30-33;
da/dx = dy_s / r^2, da/dy = -dx_s / r^2 for the nautical bearing, (dx_s, dy_s) the target
position at t_k minus S(t_k)), the Fisher information and the Gauss-Newton step are

    J = sum_k H_k^T H_k / sigma_k^2                                   (eq. 38)
    X^{j+1} = X^j + J^{-1} sum_k H_k^T r_k / sigma_k                 (eq. 26)

The paper's iteration (eq. 26) is undamped; here a step that does not lower lambda is refused
and the next one damped, Levenberg-Marquardt style with Marquardt's scaling:

    (J + mu diag(J)) delta = g,    g = sum_k H_k^T r_k / sigma_k

(the same as damping the unit-diagonal J_s = D^{-1/2} J D^{-1/2}, D = diag(J), by mu I, so
that positions in metres and velocities in m/s are damped alike). mu is 1e-12 (plain
Gauss-Newton) while steps succeed, and max(10 mu, 1e-3) after a refusal. The iteration stops
when the Gauss-Newton decrement g^T J^{-1} g (the step's squared length in standard deviations
of the estimate) is at most tol^2, and then takes that last small step without linearising
again (J and lambda are those of the point one step before the estimate). The composite
measurement is z_c = X_ML(t_f) with covariance R_c = J(X_ML)^{-1} (the CRLB at the estimate)
and H_c = I_4 (eqs. 42-43).

Every function is batched over leading axes (targets, runs), and no Python loop runs over
them. ``composite_measurement`` fits its rows in a compiled loop (``composite_fast``: each
row on its own, its missing bearings skipped, so its bits do not depend on its batch); the
numpy form below (``_fit_numpy``: the rows iterate together, each with its own mu, and leave
the loop when done) is the textbook it is pinned to.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.linalg import symmetrize
from trackkit.models.sensors import check_convention, wrap_small
from trackkit.network import composite_fast
from trackkit.network.composite_fast import (
    CONVERGED,
    MU_MAX,
    MU_MIN,
    MU_REFUSED,
    NOT_CONVERGED,
    ROUND,
    SINGULAR,
)

__all__ = [
    "CONVERGED",
    "NOT_CONVERGED",
    "SINGULAR",
    "STATUS_NAMES",
    "Composite",
    "composite_measurement",
    "fisher_information",
    "linearize_bearings",
]

Array = NDArray[np.float64]

#: the name of each status code
STATUS_NAMES = {CONVERGED: "converged", NOT_CONVERGED: "not converged", SINGULAR: "singular"}


class Composite(NamedTuple):
    """The composite measurement of each batch row (batch shape ``...``).

    ``mean`` ``(..., 4)``: X_ML(t_f) = [x, y, vx, vy]. ``information`` ``(..., 4, 4)``: J
    at the last linearisation point, which is ``mean`` before the final Gauss-Newton step
    (a step below tol standard deviations). ``cov`` ``(..., 4, 4)``: J^{-1}, the CRLB used as
    the measurement's covariance (nan where ``status`` is SINGULAR). ``status`` ``(...)``
    int8:

    ==  =============  =========================================================
    0   CONVERGED      the Gauss-Newton decrement sqrt(g^T J^-1 g) <= tol
    1   NOT_CONVERGED  max_iter spent, or no step lowers lambda any more
    2   SINGULAR       J rank-deficient or ill-conditioned, or fewer than 4 bearings
    ==  =============  =========================================================

    ``iterations`` ``(...)``: steps tried (accepted or refused). ``cost`` ``(...)``:
    lambda = 1/2 sum_k r_k^2 at the last linearisation point; 2 lambda ~ chi^2 with M degrees
    of freedom at the true state, about M - 4 at the estimate (M: the bearings present).
    """

    mean: Array
    cov: Array
    information: Array
    status: NDArray[np.int8]
    iterations: NDArray[np.int64]
    cost: Array


class _Problem(NamedTuple):
    """The bearings of N rows with the batch axis last, ``(M, N)`` (a sum over the M bearings
    is then M vector additions, several times faster than N short row sums). A missing
    bearing holds fillers (0) and weight 0."""

    z: Array  # bearings
    dt: Array  # t_k - t_f
    xs: Array  # sensor east position S(t_k)
    ys: Array  # sensor north position
    w: Array  # 1 / sigma_k
    pad: Array | None  # 1.0 where missing, else 0.0; None when every bearing is present
    sign: float  # +1 nautical, -1 math
    work: Array  # (6, M N) scratch of _linearize
    work_J: Array  # (16 N,) scratch of _normal's J

    def take(self, rows: NDArray[np.intp]) -> _Problem:
        """The sub-problem of some rows (it shares ``work``)."""
        z, dt, xs, ys, w, pad, sign, work, work_J = self
        return _Problem(*(_cols(a, rows) for a in (z, dt, xs, ys, w)),
                        None if pad is None else _cols(pad, rows), sign, work, work_J)


def _cols(a: Array, rows: NDArray[np.intp]) -> Array:
    """``a[..., rows]``, C-contiguous (``a[:, rows]`` comes out in Fortran order, and every
    later pass over it would stride)."""
    return np.take(a, rows, axis=-1)


# --- kernels (batch axis last: X is (4, N), J is (4, 4, N)) ---------------------------------


def _linearize(X: Array, p: _Problem) -> tuple[Array, Array]:
    """Whitened residuals ``r (M, N)`` and Jacobian ``A (4, M, N)`` at ``X (4, N)``:
    ``r_k = wrap(z_k - h(F(t_k, t_f) X, S(t_k))) / sigma_k`` and ``A_k = H_k / sigma_k``,
    both 0 for a missing bearing; a target on a sensor gives nan in A.

    h and its gradient are ``Bearing``'s: with (u, v) = target - sensor (east, north),
    ``h = atan2(u, v)``, ``dh/d(x, y) = (v, -u) / r^2`` (nautical; ``atan2(v, u)`` and
    ``(-v, u) / r^2`` for "math"). They are written out here because the whole linearisation
    runs in place on one scratch block: a fresh numpy temporary of this size is fresh memory,
    and its page faults made the linearisation three to four times slower (measured; see also
    ``models/classes.py``). ``r`` and ``A`` are views of that block, valid until the next call.
    """
    dt = p.dt
    shape, size = dt.shape, dt.size
    A = p.work[:4, :size].reshape((4,) + shape)
    r, q = (p.work[i, :size].reshape(shape) for i in (4, 5))
    v, u = A[0], A[1]  # become dh/dx and dh/dy, in place
    # X(t_k) = F(t_k, t_f) X(t_f): for CV the position is p + (t_k - t_f) v, two
    # multiply-adds where F @ X over (M, N, 4, 4) would cost eight times as much
    np.multiply(dt, X[2], out=u)
    u += X[0]
    u -= p.xs
    np.multiply(dt, X[3], out=v)
    v += X[1]
    v -= p.ys
    if p.sign > 0:
        np.arctan2(u, v, out=r)
    else:
        np.arctan2(v, u, out=r)
    np.subtract(p.z, r, out=r)
    r = wrap_small(r)
    r *= p.w
    np.multiply(u, u, out=q)
    np.multiply(v, v, out=A[2])
    q += A[2]
    if p.pad is not None:
        q += p.pad  # keeps 0 / 0 out of the fillers' weights
    with np.errstate(divide="ignore", invalid="ignore"):  # a target on a sensor: nan
        np.divide(p.w, q, out=q)  # 1 / (sigma_k r^2)
        # eqs. 30-31, whitened: (v, -u) q (nautical), (-v, u) q (math)
        first, second = (v, u) if p.sign > 0 else (u, v)
        first *= q
        np.negative(q, out=q)
        second *= q
    np.multiply(A[0], dt, out=A[2])  # eqs. 32-33: d alpha / d v = (t_k - t_f) d alpha / d p
    np.multiply(A[1], dt, out=A[3])
    return r, A


def _normal(X: Array, p: _Problem) -> tuple[Array, Array, Array]:
    """``lambda = 1/2 sum_k r_k^2`` (N,), ``J = sum_k A_k A_k^T`` (4, 4, N) and
    ``g = sum_k A_k r_k`` (4, N); J is a view of scratch, valid until the next call."""
    r, A = _linearize(X, p)
    n = X.shape[1]
    if n == 1:
        # einsum sums a lone column's bearings in another order than two or more columns'
        # (numpy 2.4): the column twice keeps a row's numbers the same in any batch
        return tuple(a[..., :1].copy() for a in _sums(np.repeat(r, 2, 1),
                                                       np.repeat(A, 2, 2), None))
    return _sums(r, A, p.work_J[: 16 * n].reshape(4, 4, n))


def _sums(r: Array, A: Array, out: Array | None) -> tuple[Array, Array, Array]:
    cost = np.einsum("mn,mn->n", r, r)
    cost *= 0.5
    J = np.einsum("imn,jmn->ijn", A, A, out=out)
    return cost, J, np.einsum("imn,mn->in", A, r)


def _scaled(J: Array) -> tuple[Array, Array]:
    """``s = diag(J)^{-1/2}`` (4, N) (1 where a diagonal entry is not positive) and
    ``J_s = diag(s) J diag(s)``, whose diagonal is 1 where J's is positive."""
    d = np.einsum("iin->in", J)
    s = 1.0 / np.sqrt(np.where(d > 0, d, 1.0))
    return s, J * s[:, None] * s[None, :]


def _spd_solve(P: Array, B: Array) -> Array:
    """``P^{-1} B`` for symmetric positive-definite ``P (n, n, N)`` and ``B (n, k, N)``,
    by Cholesky (``P = L L^T``) and two substitutions, each scalar formula vectorised over
    the batch (for n = 4 and N = 1000 several times faster than LAPACK's call per matrix).
    A row whose pivot is not > 0 (P not positive definite, or nan) comes back as nan
    rather than failing the call, as LAPACK's batched routines (and ``linalg.cholesky``) do
    for the whole stack.
    """
    n = P.shape[0]
    L: list[list[Array]] = [[] for _ in range(n)]  # L[i][j], j <= i, each (N,)
    with np.errstate(invalid="ignore", divide="ignore"):
        for i in range(n):
            for j in range(i + 1):
                acc = P[i, j].copy()
                for k in range(j):
                    acc -= L[i][k] * L[j][k]
                L[i].append(np.sqrt(acc) if i == j else acc / L[j][j])
        Y = np.empty(B.shape)
        for i in range(n):  # L Y = B
            acc = B[i].copy()
            for k in range(i):
                acc -= L[i][k] * Y[k]
            np.divide(acc, L[i][i], out=Y[i])
        for i in reversed(range(n)):  # L^T X = Y, in place
            acc = Y[i]
            for k in range(i + 1, n):
                acc -= L[k][i] * Y[k]
            acc /= L[i][i]
        bad = ~(np.min([L[i][i] for i in range(n)], axis=0) > 0)
    if bad.any():
        Y[..., bad] = np.nan
    return Y


# --- input checks --------------------------------------------------------------------------


def _float(name: str, value: ArrayLike) -> Array:
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r}; expected an array of numbers") from None


def _require_finite(name: str, a: Array, where: NDArray[np.bool_] | None, what: str) -> None:
    bad = ~np.isfinite(a) if where is None else where & ~np.isfinite(a)
    if bad.any():
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        raise ValueError(f"{name} has a non-finite entry ({float(a[i])!r} at index {i}; "
                         f"{int(bad.sum())} of {bad.size} entries); expected {what}")


def _prepare(
    x: ArrayLike,
    t: ArrayLike,
    sensor_pos: ArrayLike,
    sigma: ArrayLike,
    t_f: ArrayLike,
    z: ArrayLike | None,
    valid: ArrayLike | None,
    convention: str,
    x_name: str,
) -> tuple[tuple[int, ...], Array, _Problem, NDArray[np.intp]]:
    """Check and broadcast the inputs; return the batch shape, X ``(N, 4)``, the flattened
    problem and the number of bearings present in each row ``(N,)``."""
    X = _float(x_name, x)
    if X.ndim < 1 or X.shape[-1] != 4:
        raise ValueError(f"{x_name} has shape {X.shape}; expected (..., 4), the CV state "
                         "[x, y, vx, vy]")
    _require_finite(x_name, X, None, "finite values")
    T = _float("t", t)
    if T.ndim < 1 or T.shape[-1] < 1:
        raise ValueError(f"t has shape {T.shape}; expected (..., M) or (M,), the bearing times "
                         "in seconds")
    M = T.shape[-1]
    Z = None
    if z is not None:
        Z = _float("z", z)
        if Z.ndim < 1 or Z.shape[-1] != M:
            raise ValueError(f"z has shape {Z.shape}; expected (..., M) with M = {M} "
                             f"(the length of t, shape {T.shape})")
        if np.isinf(Z).any():
            _require_finite("z", Z, ~np.isnan(Z), "bearings in radians, nan for a missing one")
    S = _float("sensor_pos", sensor_pos)
    if S.ndim < 2 or S.shape[-2:] != (M, 2):
        raise ValueError(f"sensor_pos has shape {S.shape}; expected (..., {M}, 2), one sensor "
                         f"position (east, north) per bearing (M = {M} from t, shape {T.shape})")
    sig = _float("sigma", sigma)
    if sig.ndim > 0 and sig.shape[-1] not in (1, M):
        raise ValueError(f"sigma has shape {sig.shape}; expected a scalar or (..., {M})")
    tf = _float("t_f", t_f)
    _require_finite("t_f", tf, None, "finite reference times in seconds")
    V = None
    if valid is not None:
        V = np.asarray(valid)
        if V.dtype != np.bool_ or V.ndim < 1 or V.shape[-1] != M:
            raise ValueError(f"valid has shape {V.shape} and dtype {V.dtype}; expected booleans "
                             f"of shape (..., {M})")

    fields = {x_name: X.shape[:-1], "t": T.shape[:-1], "sensor_pos": S.shape[:-2],
              "sigma": sig.shape[:-1], "t_f": tf.shape}
    if Z is not None:
        fields["z"] = Z.shape[:-1]
    if V is not None:
        fields["valid"] = V.shape[:-1]
    try:
        batch = np.broadcast_shapes(*fields.values())
    except ValueError:
        shapes = ", ".join(f"{k} {v}" for k, v in fields.items())
        raise ValueError(f"the batch (leading) shapes do not broadcast: {shapes}; expected "
                         "shapes that broadcast, with the M bearings on the last axis of z, t "
                         "and sigma and the second last of sensor_pos") from None
    N = int(np.prod(batch, dtype=np.int64))
    # checks on the broadcast views, so that an error's index is the caller's
    T = np.broadcast_to(T, batch + (M,))
    S = np.broadcast_to(S, batch + (M, 2))
    sig = np.broadcast_to(sig, batch + (M,))
    present = np.ones(batch + (M,), dtype=bool)
    if Z is not None:
        Z = np.broadcast_to(Z, batch + (M,))
        present &= ~np.isnan(Z)
    if V is not None:
        present &= V
    everything = bool(present.all())
    where = None if everything else present
    _require_finite("t", T, where, "finite times in seconds where a bearing is present")
    _require_finite("sensor_pos", S, None if everything else present[..., None],
                    "finite positions (east, north) in metres where a bearing is present")
    _require_finite("sigma", sig, where, "finite standard deviations > 0 in radians")
    bad = ~(sig > 0) if everything else present & ~(sig > 0)
    if bad.any():
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        raise ValueError(f"sigma = {float(sig[i])!r} at index {i} ({int(bad.sum())} of "
                         f"{bad.size} entries); expected standard deviations > 0 in radians")

    # flatten the batch and put it last
    def last(a: Array) -> Array:  # always a copy: the fillers are written into it
        return np.array(a.reshape(N, M).T, order="C")

    dt = last(T - np.broadcast_to(tf, batch)[..., None])
    with np.errstate(divide="ignore", invalid="ignore"):  # sigma of a missing bearing
        w = last(1.0 / sig)
    zz = np.zeros((M, N)) if Z is None else last(Z)
    xs, ys = last(S[..., 0]), last(S[..., 1])
    pad = None
    if not everything:
        missing = last(~present)
        for a in (dt, w, zz, xs, ys):
            a[missing] = 0.0
        pad = missing.astype(float)
    check_convention(convention)
    X = np.array(np.broadcast_to(X, batch + (4,)).reshape(N, 4).T, order="C")
    p = _Problem(zz, dt, xs, ys, w, pad, 1.0 if convention == "nautical" else -1.0,
                 np.empty((6, M * N)), np.empty(16 * N))
    return batch, X, p, last(present).sum(0)


def _solve(
    X: Array, p: _Problem, count: NDArray[np.intp], max_iter: int, tol: float
) -> tuple[Array, Array, Array, NDArray[np.int8], NDArray[np.int64]]:
    """The damped Gauss-Newton iteration of every row (module docstring), from ``X (4, N)``.

    Each step solves ``(J + mu diag(J)) delta = g`` (the Marquardt scaling: the damping of
    J_s = D^{-1/2} J D^{-1/2} by mu I) and keeps ``X + delta`` if it lowers lambda. mu is
    mu_min (plain Gauss-Newton, eq. 26) while the steps succeed; a refused step sets it to
    max(10 mu, 1e-3). Returns X, J (4, 4, N), lambda, the status (CONVERGED or NOT_CONVERGED)
    and the number of steps of each row.
    """
    N = X.shape[1]
    cost, J, g = _normal(X, p)
    J = J.copy()  # out of the scratch
    status = np.full(N, NOT_CONVERGED, dtype=np.int8)
    iterations = np.zeros(N, dtype=np.int64)
    ok = (count >= 4) & np.isfinite(cost) & np.isfinite(np.einsum("iin->n", J))
    # the iteration works on the rows still running: ``rows`` and their state (…w), written
    # back to the full arrays when half of them are done and at the end
    rows = np.flatnonzero(ok)
    if rows.size == N:
        sub, Xw, cw, Jw, gw = p, X.copy(), cost.copy(), J.copy(), g
    else:
        sub = p.take(rows)
        Xw, cw, Jw, gw = _cols(X, rows), cost[rows], _cols(J, rows), _cols(g, rows)
    w2 = (sub.w * sub.w).sum(0)
    mu = np.full(rows.size, MU_MIN)
    it = np.zeros(rows.size, dtype=np.int64)
    st = np.full(rows.size, NOT_CONVERGED, dtype=np.int8)
    on = np.ones(rows.size, dtype=bool)
    Jd = np.empty_like(Jw)

    def write_back(keep: NDArray[np.bool_]) -> None:
        out = rows[~keep]
        X[:, out], cost[out], J[..., out] = Xw[:, ~keep], cw[~keep], Jw[..., ~keep]
        status[out], iterations[out] = st[~keep], it[~keep]

    for _ in range(max_iter):
        np.copyto(Jd, Jw)
        Jd.reshape(16, -1)[::5] *= 1.0 + mu
        delta = _spd_solve(Jd, gw[:, None])[:, 0]  # nan where J + mu D is not definite
        # at mu = mu_min, delta is the Gauss-Newton step and g^T delta its decrement.
        # lambda carries a rounding error of about ROUND sum_k |r_k| / sigma_k, at most
        # ROUND sqrt(2 lambda sum_k sigma_k^-2): a predicted decrease (decrement / 2) below
        # it cannot be seen by comparing costs, so the iteration also stops there. The last
        # step is taken without a new linearisation: it moves X by less than tol standard
        # deviations (or to the rounding floor), so J and lambda barely change
        decrement = (gw * delta).sum(0)
        floor = np.maximum(tol * tol, 2.0 * ROUND * np.sqrt(2.0 * cw * w2))
        done = on & (mu <= MU_MIN) & (decrement <= floor)
        np.add(Xw, delta, out=Xw, where=done)
        it += done
        st[done] = CONVERGED
        on &= ~done
        n_on = int(on.sum())
        if n_on == 0:
            break
        if n_on <= rows.size // 2:
            write_back(on)
            keep = np.flatnonzero(on)
            sub, rows = sub.take(keep), rows[keep]
            Xw, cw, Jw, gw = _cols(Xw, keep), cw[keep], _cols(Jw, keep), _cols(gw, keep)
            w2, mu, it, st = w2[keep], mu[keep], it[keep], st[keep]
            delta = _cols(delta, keep)
            on = np.ones(rows.size, dtype=bool)
            Jd = np.empty_like(Jw)
        Xt = Xw + delta
        ct, Jt, gt = _normal(Xt, sub)
        # nan or inf in the trial's J (a target on a sensor, a nan step) refuses it
        fine = np.isfinite(np.einsum("iin->n", Jt)) & np.isfinite(ct)
        better = on & fine & (ct < cw)
        for old, new in ((Xw, Xt), (cw, ct), (Jw, Jt), (gw, gt)):
            np.copyto(old, new, where=better)
        worse = on & ~better
        mu = np.where(better, MU_MIN, np.where(worse, np.maximum(10.0 * mu, MU_REFUSED), mu))
        it += on
        on &= ~(worse & (mu > MU_MAX))
    write_back(np.zeros(rows.size, dtype=bool))
    return X, J, cost, status, iterations


# --- public API ----------------------------------------------------------------------------


def linearize_bearings(
    x: ArrayLike,
    t: ArrayLike,
    sensor_pos: ArrayLike,
    t_f: ArrayLike = 0.0,
    *,
    convention: str = "nautical",
) -> tuple[Array, Array]:
    """The stacked bearings h_bar(X) and their Jacobian H with respect to X(t_f).

    ``h_bar(X)_k = h(F(t_k, t_f) X, S(t_k))`` (eq. 24) and
    ``H_k = [da/dx, da/dy, (t_k - t_f) da/dx, (t_k - t_f) da/dy]`` (eqs. 27-33).

    Args:

        x: ``(..., 4)`` the CV state [x, y, vx, vy] at ``t_f`` (m, m/s).
        t: ``(..., M)`` or ``(M,)`` bearing times (s).
        sensor_pos: ``(..., M, 2)`` sensor positions (east, north) at those times (m).
        t_f: reference time, scalar or ``(...)`` (s).
        convention: "nautical" (clockwise from north) or "math" (counter-clockwise from east).

    Returns:

        ``h_bar`` ``(..., M)`` in (-pi, pi] and ``H`` ``(..., M, 4)``.
    """
    batch, X, p, _ = _prepare(x, t, sensor_pos, 1.0, t_f, None, None, convention, "x")
    M = p.dt.shape[0]
    r, A = _linearize(X, p)  # z = 0 and sigma = 1 here, so r = wrap(-h_bar) and A = H
    return wrap(-r.T).reshape(batch + (M,)), A.transpose(2, 1, 0).reshape(batch + (M, 4)).copy()


def fisher_information(
    x: ArrayLike,
    t: ArrayLike,
    sensor_pos: ArrayLike,
    sigma: ArrayLike,
    t_f: ArrayLike = 0.0,
    *,
    valid: ArrayLike | None = None,
    convention: str = "nautical",
) -> Array:
    """Fisher information of X(t_f) from M bearings: ``J = sum_k H_k^T H_k / sigma_k^2``
    (eq. 38), with H_k the Jacobian of ``linearize_bearings`` evaluated at ``x``.

    Args:

        x: ``(..., 4)`` the state at which J is evaluated (the truth gives the CRLB J^{-1}).
        t, sensor_pos, t_f, convention: as ``linearize_bearings``.
        sigma: bearing standard deviation (rad), scalar or ``(..., M)``.
        valid: optional booleans ``(..., M)``; a False bearing does not count.

    Returns:

        ``J`` of shape ``(..., 4, 4)``; its inverse is the CRLB when J is regular.
    """
    batch, X, p, _ = _prepare(x, t, sensor_pos, sigma, t_f, None, valid, convention, "x")
    _, J, _ = _normal(X, p)
    return J.transpose(2, 0, 1).reshape(batch + (4, 4)).copy()


def composite_measurement(
    z: ArrayLike,
    t: ArrayLike,
    sensor_pos: ArrayLike,
    sigma: ArrayLike,
    t_f: ArrayLike,
    x0: ArrayLike,
    *,
    max_iter: int = 50,
    tol: float = 1e-8,
    rcond: float = 1e-10,
    convention: str = "nautical",
) -> Composite:
    """Maximum-likelihood CV state at ``t_f`` from asynchronous bearings, with J^{-1}.

    Minimises ``lambda(X) = 1/2 sum_k wrap(z(t_k) - h(F(t_k, t_f) X, S(t_k)))^2 / sigma_k^2``
    by damped Gauss-Newton (module docstring): per row, while
    ``g^T J^{-1} g > tol^2`` (the squared length of the Gauss-Newton step
    ``delta = J^{-1} g`` in the metric J, i.e. in standard deviations of the estimate), try
    ``X + D^{-1/2} (J_s + mu I)^{-1} D^{-1/2} g``; keep it if lambda falls.

    Args:

        z: ``(..., M)`` bearings (rad); nan marks a missing bearing, so rows may hold
            different numbers of bearings (pad with nan).
        t: ``(..., M)`` or ``(M,)`` bearing times (s), finite where z is present.
        sensor_pos: ``(..., M, 2)`` sensor position (east, north) at each bearing (m).
        sigma: bearing standard deviation (rad), scalar or ``(..., M)``, > 0.
        t_f: reference time (s), scalar or ``(...)``.
        x0: ``(..., 4)`` initial guess of X(t_f) (e.g. the track's prediction to t_f).
        max_iter: most damped steps per row.
        tol: convergence threshold on sqrt(g^T J^{-1} g) (standard deviations). With sigma
            below about 1e-8 rad the rounding of the residuals alone exceeds 1e-8: raise it.
        rcond: rows whose unit-diagonal information J_s has ``lambda_min / lambda_max`` below
            this are SINGULAR.
        convention: "nautical" (clockwise from north, default) or "math".

    Returns:

        ``Composite(mean, cov, information, status, iterations, cost)``, batch shape of the
        broadcast inputs; see ``Composite`` for the status table. Geometry that does not
        observe the state is a status, not an exception.

    Raises:

        ValueError: a shape, a non-finite value or sigma <= 0, naming the argument.
    """
    if not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"max_iter = {max_iter!r}; expected an integer >= 1")
    if not np.isfinite(tol) or tol <= 0:
        raise ValueError(f"tol = {tol!r}; expected a finite number > 0")
    if not 0 < rcond < 1:
        raise ValueError(f"rcond = {rcond!r}; expected a number in (0, 1)")
    batch, X, p, count = _prepare(x0, t, sensor_pos, sigma, t_f, z, None, convention, "x0")
    out = composite_fast.fit(p.z, p.dt, p.xs, p.ys, p.w, p.pad, p.sign, X, max_iter, tol, rcond)
    return Composite(*(a.reshape(batch + a.shape[1:]) for a in out))


def _fit_numpy(X: Array, p: _Problem, count: NDArray[np.intp], max_iter: int, tol: float,
               rcond: float) -> tuple[Array, Array, Array, NDArray[np.int8], NDArray[np.int64],
                                      Array]:
    """The fit of every row in numpy, all rows iterating together (the textbook form of
    ``composite_fast.fit``, which returns the same to rounding): ``mean (N, 4)``, ``cov``,
    ``information``, ``status``, ``iterations`` and ``cost``, as ``Composite``."""
    X, J, cost, status, iterations = _solve(X, p, count, max_iter, tol)
    # the conditioning of J on the unit-diagonal scale, and J^-1
    s, Js = _scaled(J)
    Js_inv = _spd_solve(Js, np.broadcast_to(np.eye(4)[:, :, None], J.shape))
    # 1 / (tr J_s max_i (J_s^-1)_ii) is within a factor 4 of lambda_min / lambda_max of J_s
    with np.errstate(divide="ignore", invalid="ignore"):
        rc = 1.0 / (np.einsum("iin->n", Js) * np.einsum("iin->in", Js_inv).max(0))
    well = (count >= 4) & (rc >= rcond)  # false for nan
    status[~well] = SINGULAR
    cov = Js_inv * s[:, None] * s[None, :]
    cov[..., ~well] = np.nan
    return X.T, symmetrize(cov.transpose(2, 0, 1)), J.transpose(2, 0, 1), status, iterations, cost
