r"""Streamed Monte Carlo metrics: per-step sums over runs, mergeable exactly across chunks.

``MonteCarloMetrics`` keeps, for every time step k, the sums over runs of

* the squared error :math:`\lVert \mathbf{e}_g \rVert^2` of each error group g
  (:math:`\mathbf{e} = \mathbf{x}_{\text{true}} - \hat{\mathbf{x}}`, angle state components
  wrapped), giving, over the :math:`N_k` runs counted at step k,

  .. math::

      \mathrm{MSE}_k = \frac{1}{N_k} \sum_{\text{runs}} \lVert \mathbf{e}_g \rVert^2, \qquad
      \mathrm{RMSE}_k = \sqrt{\mathrm{MSE}_k}

* the NEES (P the estimate covariance), giving the average NEES;
* the NIS of the innovations :math:`\mathbf{r}` with covariance S (rows with a ``nan``
  residual, i.e. a missing measurement, are not counted), giving the average NIS:

  .. math::

      \mathrm{NEES} = \mathbf{e}^\top P^{-1} \mathbf{e}, \qquad
      \mathrm{NIS} = \mathbf{r}^\top S^{-1} \mathbf{r}

and the counts N_k and chi-square degrees of freedom behind them. Nothing is kept per run and
step beyond a window of a few thousand run-steps: memory is O(steps) plus three small per-run
counters for the divergence rule.

Consistency bounds: if the filter is consistent, N times the average NEES of N independent
runs is chi-square with N n degrees of freedom, so the two-sided ``confidence`` interval of the
average is, with :math:`a = 1 - \text{confidence}` and :math:`F^{-1}_{\chi^2_\nu}` the
chi-square quantile (``chi2.ppf``),

.. math::

    \Bigl[\tfrac1N F^{-1}_{\chi^2_{Nn}}(a/2), \;\; \tfrac1N F^{-1}_{\chi^2_{Nn}}(1 - a/2)\Bigr]

(likewise NIS with the measurement dimension m; see ``chi2_bounds``).

Summation, and what is bit-identical. One accumulator takes one fixed batch of runs (in the
Monte Carlo engine, one block). Within it, the terms of a step are summed in float64 over the
batch, ``np.sum`` of the batch's vector of terms (numpy's pairwise order, which depends only on
the batch size), and only these batch totals enter an exact fixed-point (Kulisch)
accumulator. Merging accumulators adds their exact sums, so merging in any order, in any
grouping, on any worker gives bit-identical sums, and every reported mean is the correctly
rounded value of the exact sum of the batch totals. The same runs split into other batches
give other batch totals, equal to within float64 rounding of a sum (relative 1e-16 times the
batch size at worst for these non-negative terms): the engine keeps its batches fixed
(``run.block``), which is why a result is bit-identical for any chunking at one block size.

The terms are evaluated a window of steps at a time (``add`` copies its inputs into the
window; at most ``WINDOW_ROWS`` run-steps), with one numpy pass per quantity over the
window instead of one per step. Every per-run term is an elementwise computation (the NEES
and, for m > 2, the NIS through a Cholesky-Crout factor and a forward substitution written
out over the batch, ``_quadratic``), so a term's bits do not depend on the window or on the
run's place in it. Group functions (``groups`` given as callables) are called at ``add``, on
that step's batch, since they may depend on the step (an observer's position).

Divergence rule (per run). A run is *bad* at a step when its estimate (mean or covariance) is
not finite, or its NEES exceeds ``nees_threshold`` (default
``100 * chi2.ppf(1 - 1e-6, n)``: a consistent filter passes ``chi2.ppf(1 - 1e-6, n)`` once in a
million steps, and a further factor 100 means the covariance understates the error by two
orders of magnitude: the track is lost, not merely overconfident), or, when ``distance`` is
set, the error norm of the group ``distance_group`` (default "position") exceeds it. A run has
*diverged* when it is bad at its last accumulated step or on more than ``max_bad_fraction`` of
its steps. Runs with a non-finite estimate are left out of the RMSE and NEES sums of that step
(they are counted by the divergence rule and in ``invalid``), and so are, at a step where some
covariance is not positive definite, the runs whose covariance is not safely so (smallest
eigenvalue not above 1e-12 times the largest).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import gammaincinv

from trackkit.angles import wrap
from trackkit.belief import Gaussian, Innovation

__all__ = ["MonteCarloMetrics", "chi2_bounds", "chi2_ppf", "merge_all"]

Array = NDArray[np.float64]
ErrorFn = Callable[[Array, Array], Array]
GroupSpec = Sequence[int] | ErrorFn

# ---------------------------------------------------------------------------------------------
# Exact accumulation of float64 sums (a Kulisch long accumulator in 32-bit int64 limbs).
#
# A finite double is v = M 2^(e - 53) with an integer |M| < 2^53 (np.frexp); relative to the
# fixed point 2^-_OFFSET it is the integer M 2^s, s = e - 53 + _OFFSET >= 0, which spans three
# 32-bit limbs. Limbs are int64 so that partial sums carry without overflow; one vectorised
# carry pass after each addition keeps every limb below 2^33. The sum of the limbs (as an
# exact Python integer) divided by 2^_OFFSET is correctly rounded by Python's int division.
# ---------------------------------------------------------------------------------------------

_BITS = 32
_MASK = (1 << _BITS) - 1
_OFFSET = 1126  # 1074 (smallest subnormal) + 52, so that s >= 0 for every double
_LIMBS = 68  # bits up to 1024 - 53 + 1126 + 53 = 2150 < 68 * 32
_BLOCK = 1 << 20  # values per bincount: limb sums stay below 2^52, exact in float64


def _carry(acc: NDArray[np.int64]) -> None:
    """One carry pass over the last (limb) axis, in place; the value is unchanged."""
    c = acc[..., :-1] >> _BITS
    acc[..., :-1] &= _MASK
    acc[..., 1:] += c


def _exact_add(acc: NDArray[np.int64], slots: NDArray[np.intp], values: Array) -> None:
    """``acc[slot] += value`` exactly for each pair; ``acc`` is ``(S, _LIMBS)`` int64.

    Only the rows named in ``slots`` are touched (the cost does not grow with S).
    """
    rows, inv = np.unique(slots, return_inverse=True)
    U = rows.size
    local = np.zeros((U, _LIMBS), np.int64)
    for start in range(0, values.size, _BLOCK):
        v = values[start : start + _BLOCK]
        mant, e = np.frexp(v)
        M = (mant * 2.0**53).astype(np.int64)
        sign, A = np.sign(M), np.abs(M)
        s = e.astype(np.int64) + (_OFFSET - 53)
        j, o = s >> 5, s & 31
        p0 = (A & ((np.int64(1) << (32 - o)) - 1)) << o
        p1 = (A >> (32 - o)) & _MASK
        p2 = (A >> 32) >> (32 - o)
        base = inv[start : start + _BLOCK].astype(np.int64) * _LIMBS + j
        idx = np.concatenate([base, base + 1, base + 2])
        w = np.concatenate([sign * p0, sign * p1, sign * p2]).astype(np.float64)
        local += np.bincount(idx, weights=w, minlength=U * _LIMBS).astype(np.int64).reshape(
            U, _LIMBS
        )
        _carry(local)
    block = acc[rows] + local
    _carry(block)
    acc[rows] = block


def _exact_value(acc: NDArray[np.int64]) -> Array:
    """The correctly rounded float64 values of exact sums ``(..., _LIMBS)``."""
    a = acc.reshape(-1, _LIMBS).copy()
    while np.any((a[:, :-1] >> _BITS) != 0):
        _carry(a)
    out = np.zeros(a.shape[0])
    scale = 1 << _OFFSET
    for i in np.flatnonzero(np.any(a != 0, axis=1)):
        low = int.from_bytes(a[i, :-1].astype("<u4").tobytes(), "little")
        out[i] = (low + (int(a[i, -1]) << (_BITS * (_LIMBS - 1)))) / scale
    return out.reshape(acc.shape[:-1])


# ---------------------------------------------------------------------------------------------


def chi2_ppf(q: ArrayLike, dof: ArrayLike) -> Array:
    """The chi-square quantile ``chi2.ppf(q, dof)``, computed as scipy.stats does
    (``2 gammaincinv(dof / 2, q)``) without the 0.6 s import of scipy.stats."""
    return 2.0 * gammaincinv(np.asarray(dof, float) / 2, q)


@lru_cache(maxsize=64)
def _default_nees_threshold(n: int) -> float:
    return 100.0 * float(chi2_ppf(1 - 1e-6, n))


def chi2_bounds(
    count: ArrayLike, dof: ArrayLike, confidence: float = 0.95
) -> tuple[Array, Array]:
    """Two-sided ``confidence`` bounds of an average of ``count`` chi-square terms whose
    degrees of freedom add up to ``dof``: ``chi2.ppf(a/2, dof) / count`` and
    ``chi2.ppf(1 - a/2, dof) / count``, ``a = 1 - confidence``. For R runs of an n-dim NEES,
    ``count = R`` and ``dof = R n``. Entries with ``count == 0`` are nan."""
    if not 0 < confidence < 1:
        raise ValueError(f"confidence = {confidence!r}; expected a value in (0, 1)")
    c = np.asarray(count, dtype=float)
    d = np.asarray(dof, dtype=float)
    a = 1.0 - confidence
    ok = c > 0
    cs, ds = np.where(ok, c, 1.0), np.where(ok, d, 1.0)
    lo = np.where(ok, chi2_ppf(a / 2, ds) / cs, np.nan)
    hi = np.where(ok, chi2_ppf(1 - a / 2, ds) / cs, np.nan)
    return lo, hi


#: run-steps whose terms are evaluated together: ``add`` copies a step's inputs into a window
#: of ``max(1, WINDOW_ROWS // runs)`` steps and evaluates the window in one pass
WINDOW_ROWS = 8192


def _quadratic(S: Array, r: Array) -> tuple[Array, NDArray[np.bool_]]:
    """``r^T S^{-1} r`` per row (``S (N, m, m)``, ``r (N, m)``) and whether each ``S`` is
    positive definite (where it is not, the value is meaningless: callers mask it).

    m = 1: ``r (r / S)``; m = 2: the explicit inverse of ``trackkit.linalg.solve_psd``, its
    products written out (no einsum, whose SIMD loops may fuse a multiply-add in a loop's
    body and not in its tail). m > 2: the Cholesky-Crout factor
    ``L L^T = S`` (lower triangle of S read), ``y = L^{-1} r`` by forward substitution and
    ``|y|^2``, each scalar formula one numpy operation over the N rows, in a fixed order: a
    row's bits do not depend on the other rows (LAPACK's per-matrix calls cost ~0.3 us a
    matrix for a 4 x 4; these, about 40 ns at a few thousand rows).
    """
    N, m = r.shape
    if m == 1:
        s = S[:, 0, 0]
        ok = s > 0
        s = np.where(ok, s, 1.0)
        return r[:, 0] * (r[:, 0] / s), ok
    if m == 2:
        a, b, d = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
        det = a * d - b * b
        ok = (det > 0) & (a > 0)
        if not ok.all():
            a, b, d, det = (np.where(ok, v, w) for v, w in ((a, 1.0), (b, 0.0), (d, 1.0),
                                                            (det, 1.0)))
        i00, i11, i01 = d / det, a / det, -b / det
        r0, r1 = r[:, 0], r[:, 1]
        return r0 * (i00 * r0 + i01 * r1) + r1 * (i01 * r0 + i11 * r1), ok
    L = np.empty((m, m, N))  # L[i, j]: entry (i, j) of every factor, i >= j
    y = np.empty((m, N))
    tmp = np.empty(N)
    ok = np.ones(N, bool)
    with np.errstate(invalid="ignore", divide="ignore"):  # a bad pivot is masked by ok
        for j in range(m):
            d = L[j, j]
            np.copyto(d, S[:, j, j])
            for k in range(j):
                np.multiply(L[j, k], L[j, k], out=tmp)
                d -= tmp
            ok &= d > 0
            np.sqrt(d, out=d)
            for i in range(j + 1, m):
                t = L[i, j]
                np.copyto(t, S[:, i, j])
                for k in range(j):
                    np.multiply(L[i, k], L[j, k], out=tmp)
                    t -= tmp
                t /= d
        for i in range(m):
            t = y[i]
            np.copyto(t, r[:, i])
            for k in range(i):
                np.multiply(L[i, k], y[k], out=tmp)
                t -= tmp
            t /= L[i, i]
        q = y[0] * y[0]
        for i in range(1, m):
            np.multiply(y[i], y[i], out=tmp)
            q += tmp
    return q, ok


def _batch_sums(values: Array, valid: NDArray[np.bool_]) -> Array:
    """Per window step, the float64 sum over the batch of ``values (steps, R)`` where
    ``valid``: ``np.sum`` of each step's contiguous run vector (numpy's pairwise order, fixed
    by R), zeros standing in for the invalid terms."""
    if not valid.all():
        values = np.where(valid, values, 0.0)
    return np.ascontiguousarray(values).sum(axis=1)


def _finite_rows(a: Array, axes: int) -> NDArray[np.bool_]:
    """Whether every entry over the last ``axes`` axes of ``a`` is finite. A finite sum over
    them proves it (an inf or nan entry makes the sum inf or nan); only the rows whose sum is
    not finite (a bad entry, or an overflow of finite ones) are checked entry by entry."""
    flat = a.reshape(a.shape[: a.ndim - axes] + (-1,))
    with np.errstate(over="ignore", invalid="ignore"):
        ok = np.isfinite(np.einsum("...i->...", flat))
    if not ok.all():
        bad = ~ok
        ok[bad] = np.isfinite(flat[bad]).all(-1)
    return ok


def _squared_norm(e: Array) -> Array:
    """``|e|^2`` over the last axis, with the bits of ``(e * e).sum(-1)`` on a contiguous
    array (one or two components, the usual groups, written out: the same sums in any
    order, without a reduction over a length-2 axis)."""
    d = e.shape[-1]
    if d == 1:
        return e[..., 0] * e[..., 0]
    if d == 2:
        a, b = e[..., 0], e[..., 1]
        return a * a + b * b
    e = np.ascontiguousarray(e)
    return (e * e).sum(-1)


class _Window:
    """Copies of the inputs of up to ``size`` ``add`` calls of R runs, n states."""

    def __init__(self, size: int, R: int, n: int, derived: Sequence[int]) -> None:
        self.size, self.R, self.n, self.used = size, R, n, 0
        self.k = np.empty(size, np.int64)
        self.x = np.empty((size, R, n))
        self.mean = np.empty((size, R, n))
        self.P = np.empty((size, R, n, n))
        self.derived = [np.empty((size, R, d)) for d in derived]


def _as_spec(spec: GroupSpec) -> tuple[int, ...] | ErrorFn:
    if callable(spec):
        return spec
    idx = tuple(int(i) for i in spec)
    if not idx:
        raise ValueError("an error group has no state indices; expected at least one")
    return idx


@dataclass(eq=False)
class MonteCarloMetrics:
    """Streamed, mergeable Monte Carlo accumulator of RMSE, NEES, NIS and divergence.

    ``groups`` maps a name to the state indices whose errors it pools (``{"position": [0, 1],
    "velocity": [2, 3]}``) or to a function ``(truth, mean) -> errors (runs, d)`` for derived
    quantities (e.g. a wrapped course error). ``angular`` marks angle state components, wrapped
    in the errors. ``nees_indices`` restricts the NEES to a sub-state (default: all).

    Per step ``k``::

        acc.add(k, truth, estimate, innovation)   # truth (runs, n), estimate a tk.Gaussian

    and chunks combine with ``acc.merge(other)``. One accumulator takes one fixed batch of
    runs. ``add`` only copies its inputs into a window of steps; every read (and ``merge``)
    evaluates what is pending first, and ``flush()`` does so and releases the window (call it
    when the batch is done, before the accumulator is kept or sent to another process). See
    the module docstring for the maths, the summation and the divergence rule.
    """

    groups: Mapping[str, GroupSpec] = field(default_factory=dict)
    angular: Sequence[bool] | None = None
    nees_indices: Sequence[int] | None = None
    nees_threshold: float | None = None
    distance: float | None = None
    distance_group: str = "position"
    max_bad_fraction: float = 0.25

    n_steps: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        self.groups = {str(k): _as_spec(v) for k, v in dict(self.groups).items()}
        if "nees" in self.groups or "nis" in self.groups:
            raise ValueError("error groups may not be called 'nees' or 'nis'")
        if self.distance is not None:
            if not (np.isfinite(self.distance) and self.distance > 0):
                raise ValueError(f"distance = {self.distance!r}; expected a positive number")
            if self.distance_group not in self.groups:
                raise ValueError(
                    f"distance_group = {self.distance_group!r} is not an error group; "
                    f"expected one of {list(self.groups)}"
                )
        if not 0 <= self.max_bad_fraction <= 1:
            raise ValueError(f"max_bad_fraction = {self.max_bad_fraction!r}; expected [0, 1]")
        if self.angular is not None:
            self.angular = tuple(bool(a) for a in self.angular)
        if self.nees_indices is not None:
            self.nees_indices = tuple(int(i) for i in self.nees_indices)
        K = len(self.groups) + 2
        self._sums = np.zeros((K, 0, _LIMBS), np.int64)
        self._counts = np.zeros((K, 0), np.int64)
        self._dof = np.zeros((K, 0), np.int64)
        self._invalid = np.zeros(0, np.int64)
        self._run_steps = np.zeros(0, np.int64)
        self._run_bad = np.zeros(0, np.int64)
        self._run_last = np.zeros(0, np.int64)
        self._run_last_bad = np.zeros(0, bool)
        self._started = False
        self._window: _Window | None = None
        self._innovations: list[tuple[int, Array, Array]] = []
        self._innovation_rows = 0
        self._totals: dict[int, Array] = {}
        #: batch totals waiting for their exact addition: (sum rows, steps, values)
        self._pending: list[tuple[NDArray[np.intp], NDArray[np.int64], Array]] = []

    # -- state (every read evaluates what is pending first) ------------------------------------

    @property
    def sums(self) -> NDArray[np.int64]:
        """Exact sums ``(len(groups) + 2, capacity, _LIMBS)``: groups..., NEES, NIS."""
        self.flush()
        return self._sums

    @property
    def counts(self) -> NDArray[np.int64]:
        """Terms per sum ``(len(groups) + 2, capacity)``."""
        self.flush()
        return self._counts

    @property
    def dof(self) -> NDArray[np.int64]:
        """Chi-square degrees of freedom per sum (NEES and NIS rows; group rows: components)."""
        self.flush()
        return self._dof

    @property
    def invalid(self) -> NDArray[np.int64]:
        """Runs with a non-finite (or not positive definite) estimate, per step."""
        self.flush()
        return self._invalid

    @property
    def run_steps(self) -> NDArray[np.int64]:
        """Per run: steps accumulated."""
        self.flush()
        return self._run_steps

    @property
    def run_bad(self) -> NDArray[np.int64]:
        """Per run: bad steps."""
        self.flush()
        return self._run_bad

    @property
    def run_last(self) -> NDArray[np.int64]:
        """Per run: the last step index accumulated."""
        self.flush()
        return self._run_last

    @property
    def run_last_bad(self) -> NDArray[np.bool_]:
        """Per run: bad at the last step."""
        self.flush()
        return self._run_last_bad

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the accumulated sums: the error groups, then "nees" and "nis"."""
        return (*self.groups, "nees", "nis")

    @property
    def runs(self) -> int:
        """Number of runs accumulated (the per-run counters' length)."""
        return int(self._run_steps.size)

    def _row(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"{name!r} is not accumulated; expected one of {self.names}") from None

    def _grow(self, k: int) -> None:
        if k < 0:
            raise ValueError(f"step k = {k}; expected an index >= 0")
        cap = self._counts.shape[1]
        if k >= cap:
            new = max(k + 1, 2 * cap, 16)

            def wider(a: NDArray, axis: int) -> NDArray:
                shape = list(a.shape)
                shape[axis] = new
                out = np.zeros(shape, a.dtype)
                out[(slice(None),) * axis + (slice(0, cap),)] = a
                return out

            self._sums = wider(self._sums, 1)
            self._counts = wider(self._counts, 1)
            self._dof = wider(self._dof, 1)
            self._invalid = wider(self._invalid, 0)
        self.n_steps = max(self.n_steps, k + 1)

    def _runs(self, R: int) -> None:
        if not self._started and self.runs == 0:
            self._run_steps = np.zeros(R, np.int64)
            self._run_bad = np.zeros(R, np.int64)
            self._run_last = np.full(R, -1, np.int64)
            self._run_last_bad = np.zeros(R, bool)
            self._started = True
        elif R != self.runs:
            raise ValueError(
                f"{R} runs given but this accumulator holds {self.runs}; each accumulator "
                "takes a fixed set of runs (merge accumulators of other chunks)"
            )

    def _add_exact(self, rows: Sequence[int], ks: NDArray[np.int64], totals: Array,
                   counts: NDArray[np.int64], dof: Sequence[int]) -> None:
        """Add the batch totals ``totals[i, j]`` of sum ``rows[i]`` at step ``ks[j]`` exactly
        (they wait in ``_pending`` for one exact addition at the next read), with
        ``counts[j]`` terms of ``dof[i]`` degrees of freedom each."""
        r = np.asarray(rows, np.intp)[:, None]
        self._pending.append((np.broadcast_to(r, (r.size, ks.size)).ravel(),
                              np.broadcast_to(ks, (r.size, ks.size)).ravel(),
                              np.asarray(totals, dtype=float).ravel()))
        np.add.at(self._counts, (r, ks[None, :]), counts[None, :])
        np.add.at(self._dof, (r, ks[None, :]),
                  counts[None, :] * np.asarray(dof, np.int64)[:, None])
        self._totals = {}

    # -- accumulation --------------------------------------------------------------------------

    def add(self, k: int, truth: ArrayLike, estimate: Gaussian,
            innovation: Innovation | None = None) -> None:
        """Accumulate step ``k`` for a batch of runs.

        ``truth`` ``(..., n)`` true states, ``estimate`` a Gaussian with mean ``(..., n)`` and
        covariance ``(..., n, n)`` (or one ``(n, n)`` shared by all runs); the leading axes are
        the runs. ``innovation`` (optional) is passed to ``add_innovation``. A non-finite
        estimate, or a covariance that is not positive definite, makes the run invalid (and
        bad for the divergence rule) at this step: it is counted in ``invalid``, not
        repaired, and left out of that step's sums.
        """
        x = np.asarray(truth, dtype=float)
        mean = np.asarray(estimate.mean, dtype=float)
        if x.ndim < 1 or mean.shape != x.shape:
            raise ValueError(
                f"estimate.mean has shape {mean.shape} and truth {x.shape}; expected equal "
                "shapes (runs, n)"
            )
        n, batch = x.shape[-1], x.shape[:-1]
        x, mean = x.reshape(-1, n), mean.reshape(-1, n)
        R = x.shape[0]
        P = np.asarray(estimate.cov, dtype=float)
        if P.shape[-2:] != (n, n):
            raise ValueError(f"estimate.cov has shape {P.shape}; expected (..., {n}, {n})")
        if P.ndim > 2:
            P = np.broadcast_to(P, batch + (n, n)).reshape(R, n, n)
        if self.angular is not None and len(self.angular) != n:
            raise ValueError(f"angular has {len(self.angular)} entries; the state has {n}")
        if self.nees_indices is not None and not all(-n <= i < n for i in self.nees_indices):
            raise ValueError(f"nees_indices = {self.nees_indices}; the state has {n} components")
        self._runs(R)
        self._grow(k)
        # group functions see this step's batch (they may depend on the step)
        derived = [np.asarray(spec(x, mean), dtype=float).reshape(R, -1)
                   for spec in self.groups.values() if callable(spec)]
        w = self._window
        if w is not None and (w.n != n or [d.shape[-1] for d in w.derived]
                              != [d.shape[-1] for d in derived]):
            self._flush_states()
            w = None
        if w is None:
            w = self._window = _Window(max(1, WINDOW_ROWS // max(R, 1)), R, n,
                                       [d.shape[-1] for d in derived])
        j = w.used
        w.k[j] = k
        w.x[j] = x
        w.mean[j] = mean
        w.P[j] = P
        for buf, d in zip(w.derived, derived, strict=True):
            buf[j] = d
        w.used = j + 1
        if innovation is not None:
            self.add_innovation(k, innovation)
        if w.used == w.size:
            self._flush_states()

    def add_innovation(self, k: int, innovation: Innovation) -> None:
        """Accumulate the NIS ``r^T S^{-1} r`` of step ``k``; rows whose residual has a
        ``nan`` (missing measurement) are skipped. Several calls at one step (several
        sensors) pool their terms and degrees of freedom. An ``S`` that is not positive
        definite raises ``ValueError`` when the step is evaluated (at the latest at the
        next read or ``flush()``)."""
        r = np.asarray(innovation.nu, dtype=float)
        if r.ndim < 1:
            raise ValueError(f"innovation.nu has shape {r.shape}; expected (..., m)")
        m = r.shape[-1]
        S = np.asarray(innovation.cov, dtype=float)
        if S.shape[-2:] != (m, m):
            raise ValueError(f"innovation.cov has shape {S.shape}; expected (..., {m}, {m})")
        S = np.broadcast_to(S, r.shape[:-1] + (m, m))
        self._grow(k)
        self._innovations.append((k, np.array(r.reshape(-1, m)), np.array(S.reshape(-1, m, m))))
        self._innovation_rows += r.size // max(m, 1)
        if self._innovation_rows >= WINDOW_ROWS:
            self._flush_innovations()

    def add_steps(self, k0: int, truth: ArrayLike, estimate: Gaussian,
                  innovation: Innovation | None = None) -> None:
        """Accumulate the steps ``k0, k0 + 1, ...`` of a batch of runs at once: the first
        axis of every array is the step, the rest as in ``add`` (``truth (w, ..., n)``, the
        estimate's mean ``(w, ..., n)`` and covariance ``(w, ..., n, n)``, or ``(n, n)``
        shared, the innovation's residual ``(w, ..., m)``). The same sums as ``add`` step by
        step, except that group functions are called once with ``(w, R, n)`` arrays (the
        Monte Carlo engine's run over a window of steps)."""
        x = np.asarray(truth, dtype=float)
        mean = np.asarray(estimate.mean, dtype=float)
        if x.ndim < 2 or mean.shape != x.shape:
            raise ValueError(
                f"estimate.mean has shape {mean.shape} and truth {x.shape}; expected equal "
                "shapes (steps, runs, n)"
            )
        w, n = x.shape[0], x.shape[-1]
        x, mean = x.reshape(w, -1, n), mean.reshape(w, -1, n)
        R = x.shape[1]
        P = np.asarray(estimate.cov, dtype=float)
        if P.shape[-2:] != (n, n):
            raise ValueError(f"estimate.cov has shape {P.shape}; expected (..., {n}, {n})")
        P = np.broadcast_to(P, np.shape(truth)[:-1] + (n, n)).reshape(w, R, n, n)
        if self.angular is not None and len(self.angular) != n:
            raise ValueError(f"angular has {len(self.angular)} entries; the state has {n}")
        if self.nees_indices is not None and not all(-n <= i < n for i in self.nees_indices):
            raise ValueError(f"nees_indices = {self.nees_indices}; the state has {n} components")
        if w == 0:
            return
        self._runs(R)
        self._grow(k0 + w - 1)
        self._flush_steps()  # steps given one by one before these come first
        derived = [np.asarray(spec(x, mean), dtype=float).reshape(w, R, -1)
                   for spec in self.groups.values() if callable(spec)]
        ks = np.arange(k0, k0 + w, dtype=np.int64)
        self._evaluate(ks, x, mean, P, derived)
        if innovation is not None:
            r = np.asarray(innovation.nu, dtype=float)
            m = r.shape[-1]
            S = np.asarray(innovation.cov, dtype=float)
            if r.ndim < 2 or r.shape[0] != w or S.shape[-2:] != (m, m):
                raise ValueError(
                    f"innovation residual {r.shape} and cov {S.shape}; expected (steps = {w}, "
                    "..., m) and (..., m, m)")
            S = np.broadcast_to(S, r.shape[:-1] + (m, m))
            self._evaluate_innovations(ks, r.reshape(w, -1, m), S.reshape(w, -1, m, m))

    # -- evaluation of a window ----------------------------------------------------------------

    def flush(self) -> None:
        """Evaluate the pending steps, add their batch totals to the exact sums and release
        the window (reads do this themselves)."""
        self._flush_steps()
        self._window = None
        self._fold()

    def _flush_steps(self) -> None:
        if self._window is not None:
            self._flush_states()
        if self._innovations:
            self._flush_innovations()

    def _fold(self) -> None:
        """The exact addition of the batch totals waiting in ``_pending``."""
        if self._pending:
            rows, ks, totals = (np.concatenate(a) for a in zip(*self._pending, strict=True))
            self._pending = []
            cap = self._counts.shape[1]
            _exact_add(self._sums.reshape(-1, _LIMBS), rows * cap + ks, totals)

    def _flush_states(self) -> None:
        w = self._window
        u = 0 if w is None else w.used
        if u == 0:
            return
        w.used = 0
        self._evaluate(w.k[:u].copy(), w.x[:u], w.mean[:u], w.P[:u],
                       [d[:u] for d in w.derived])

    def _evaluate(self, ks: NDArray[np.int64], X: Array, M: Array, P: Array,
                  derived: list[Array]) -> None:
        """Accumulate ``u`` steps ``ks`` of R runs at once: truths and means ``(u, R, n)``,
        covariances ``(u, R, n, n)`` (a broadcast view is fine) and each group function's
        errors ``(u, R, d)``."""
        u, R, n = X.shape
        e = X - M
        if self.angular is not None:
            e = np.where(np.asarray(self.angular), wrap(e), e)
        valid = _finite_rows(e, 1) & _finite_rows(P, 2)  # (u, R)
        everywhere = bool(valid.all())
        e0 = e if everywhere else np.where(valid[..., None], e, 0.0)
        sq, dofs = [], []
        fns = iter(derived)
        for spec in self.groups.values():
            if callable(spec):
                eg = next(fns)
                if not everywhere:
                    eg = np.where(valid[..., None], eg, 0.0)
            else:
                eg = e0[..., list(spec)]
            sq.append(_squared_norm(eg))
            dofs.append(eg.shape[-1])

        full = self.nees_indices is None or list(self.nees_indices) == list(range(n))
        idx = list(range(n)) if full else list(self.nees_indices)
        ni = len(idx)
        Ps = P if full else P[..., idx, :][..., idx]
        if not everywhere:
            Ps = np.where(valid[..., None, None], Ps, np.eye(ni))
        en = e0 if full else e0[..., idx]
        nees, ok = _quadratic(Ps.reshape(-1, ni, ni), en.reshape(-1, ni))
        nees, ok = nees.reshape(u, R), ok.reshape(u, R)
        failed = np.flatnonzero(~ok.all(1))
        if failed.size:
            # a step where a filter lost positive definiteness: it has failed on those runs,
            # which count as invalid (and so bad for the divergence rule) instead of
            # stopping the study; the criterion is applied to every run of such a step
            Pf = Ps[failed]
            eig = np.linalg.eigvalsh(Pf)
            pd = eig[..., 0] > 1e-12 * np.abs(eig[..., -1])  # condition number below 1e12
            Pf = np.where(pd[..., None, None], Pf, np.eye(ni))
            vf = valid[failed] & pd
            ef = np.where(vf[..., None], en[failed], 0.0)
            q, ok2 = _quadratic(Pf.reshape(-1, ni, ni), ef.reshape(-1, ni))
            vf &= ok2.reshape(vf.shape)
            valid[failed] = vf
            nees[failed] = np.where(vf, q.reshape(vf.shape), 0.0)
        count = valid.sum(1)
        G = len(self.groups)
        totals = np.stack([_batch_sums(v, valid) for v in (*sq, nees)])
        self._add_exact([*range(G), G], ks, totals, count, [*dofs, ni])
        np.add.at(self._invalid, ks, R - count)

        # divergence bookkeeping
        thr = self.nees_threshold
        if thr is None:
            thr = _default_nees_threshold(ni)
        bad = ~valid | (nees > thr)
        if self.distance is not None:
            bad |= sq[list(self.groups).index(self.distance_group)] > self.distance**2
        self._run_steps += u
        self._run_bad += bad.sum(0)
        last = int(ks.max())
        j = u - 1 - int(np.argmax(ks[::-1] == last))  # the last add of the latest step
        later = last >= self._run_last
        self._run_last_bad = np.where(later, bad[j], self._run_last_bad)
        self._run_last = np.where(later, last, self._run_last)

    def _flush_innovations(self) -> None:
        entries, self._innovations, self._innovation_rows = self._innovations, [], 0
        shapes: dict[tuple[int, ...], list[int]] = {}
        for i, (_, r, _) in enumerate(entries):
            shapes.setdefault(r.shape, []).append(i)
        for which in shapes.values():
            self._evaluate_innovations(np.array([entries[i][0] for i in which], np.int64),
                                       np.stack([entries[i][1] for i in which]),
                                       np.stack([entries[i][2] for i in which]))

    def _evaluate_innovations(self, ks: NDArray[np.int64], r: Array, S: Array) -> None:
        """NIS of ``u`` steps ``ks`` at once: residuals ``(u, R, m)``, covariances
        ``(u, R, m, m)``."""
        m = r.shape[-1]
        present = np.isfinite(r).all(-1)
        r0 = np.where(present[..., None], r, 0.0)
        nis, ok = _quadratic(S.reshape(-1, m, m), r0.reshape(-1, m))
        if not ok.all():
            bad = np.argwhere(~ok.reshape(present.shape))
            step, run = int(ks[bad[0, 0]]), int(bad[0, 1])
            raise ValueError(
                "innovation covariance (for NIS) is not positive definite: "
                f"{len(bad)} of {ok.size} rows (first at step {step}, run {run})")
        totals = _batch_sums(nis.reshape(present.shape), present)
        self._add_exact([len(self.groups) + 1], ks, totals[None, :], present.sum(1), [m])

    # -- merging -------------------------------------------------------------------------------

    def _config(self) -> tuple:
        groups = tuple((k, v if not callable(v) else "fn") for k, v in self.groups.items())
        return (groups, self.angular, self.nees_indices, self.nees_threshold, self.distance,
                self.distance_group, self.max_bad_fraction)

    def merge(self, other: MonteCarloMetrics) -> MonteCarloMetrics:
        """The accumulator of both chunks' runs (a new object; exact and order-independent
        for every sum and count). The configurations must match."""
        if self._config() != other._config():
            raise ValueError(
                "cannot merge accumulators with different configurations: "
                f"{self._config()} vs {other._config()}"
            )
        self.flush()
        other.flush()
        out = MonteCarloMetrics(**{
            "groups": self.groups, "angular": self.angular, "nees_indices": self.nees_indices,
            "nees_threshold": self.nees_threshold, "distance": self.distance,
            "distance_group": self.distance_group, "max_bad_fraction": self.max_bad_fraction,
        })
        T = max(self.n_steps, other.n_steps)
        if T:
            out._grow(T - 1)
        for src in (self, other):
            t = src.n_steps
            out._sums[:, :t] += src._sums[:, :t]
            out._counts[:, :t] += src._counts[:, :t]
            out._dof[:, :t] += src._dof[:, :t]
            out._invalid[:t] += src._invalid[:t]
        _carry(out._sums)
        out._run_steps = np.concatenate([self._run_steps, other._run_steps])
        out._run_bad = np.concatenate([self._run_bad, other._run_bad])
        out._run_last = np.concatenate([self._run_last, other._run_last])
        out._run_last_bad = np.concatenate([self._run_last_bad, other._run_last_bad])
        out._started = self._started or other._started
        return out

    # -- results -------------------------------------------------------------------------------

    def total(self, name: str) -> Array:
        """The per-step sum over runs, shape ``(n_steps,)``: the correctly rounded exact sum
        of the batch totals (see the module docstring)."""
        self.flush()
        row = self._row(name)
        if row not in self._totals:
            self._totals[row] = _exact_value(self._sums[row, : self.n_steps])
        return self._totals[row].copy()

    def count(self, name: str) -> NDArray[np.int64]:
        """Number of terms in each step's sum, shape ``(n_steps,)``."""
        return self.counts[self._row(name), : self.n_steps].copy()

    def _mean(self, name: str) -> Array:
        c = self.count(name)
        t = self.total(name)
        return np.where(c > 0, t / np.maximum(c, 1), np.nan)

    def mse(self, group: str) -> Array:
        """Per-step mean squared error ``sum_runs |e_g|^2 / N_k`` (nan for a step without
        data)."""
        if group not in self.groups:
            raise KeyError(f"{group!r} is not an error group; expected one of {list(self.groups)}")
        return self._mean(group)

    def rmse(self, group: str) -> Array:
        """Per-step RMSE ``sqrt(MSE_k)`` of an error group."""
        return np.sqrt(self.mse(group))

    def rmse_time_average(self, group: str, start: int = 0, stop: int | None = None) -> float:
        """Time-averaged RMSE over steps ``start <= k < stop`` (default: to the end):
        ``sqrt(mean_k MSE_k)``, the root mean squared error over all runs and steps of the
        window (steps without data skipped). From the per-step sums alone, so a window costs
        nothing to accumulate and keeps their bits."""
        mse = self.mse(group)[start:stop]
        mse = mse[np.isfinite(mse)]
        return float(np.sqrt(mse.mean())) if mse.size else float("nan")

    def nees(self) -> Array:
        """Per-step average NEES over the runs."""
        return self._mean("nees")

    def nis(self) -> Array:
        """Per-step average NIS over the runs that had a measurement."""
        return self._mean("nis")

    def bounds(self, name: str, confidence: float = 0.95) -> tuple[Array, Array]:
        """Per-step two-sided chi-square bounds of the average ``name`` ("nees" or "nis")."""
        if name not in ("nees", "nis"):
            raise KeyError(f"{name!r}: bounds exist for 'nees' and 'nis'")
        r = self._row(name)
        return chi2_bounds(self.counts[r, : self.n_steps], self.dof[r, : self.n_steps],
                           confidence)

    def fraction_inside(self, name: str, start: int = 0, confidence: float = 0.95,
                        stop: int | None = None) -> float:
        """Fraction of the steps ``start <= k < stop`` with data whose average NEES/NIS lies
        inside the two-sided ``confidence`` bounds (about ``confidence`` for a consistent
        filter)."""
        avg = self._mean(name)[start:stop]
        lo, hi = (b[start:stop] for b in self.bounds(name, confidence))
        has = np.isfinite(avg)
        if not has.any():
            return float("nan")
        return float(((avg >= lo) & (avg <= hi))[has].mean())

    def diverged(self) -> NDArray[np.bool_]:
        """Per run: diverged by the rule in the module docstring."""
        self.flush()
        frac = self._run_bad / np.maximum(self._run_steps, 1)
        return self._run_last_bad | (frac > self.max_bad_fraction)

    def summary(self, start: int = 0, confidence: float = 0.95,
                stop: int | None = None) -> dict[str, float]:
        """Plain-float summary: runs, steps, time-averaged RMSE per group over the steps
        ``start <= k < stop`` (default: to the end), mean NEES/NIS over those steps and the
        fraction of them inside the ``confidence`` bounds, and the number and fraction of
        diverged runs (over whole runs: the divergence rule does not look at windows)."""
        out: dict[str, float] = {"runs": float(self.runs), "steps": float(self.n_steps)}
        for g in self.groups:
            out[f"rmse_{g}"] = self.rmse_time_average(g, start, stop)
        for name in ("nees", "nis"):
            avg = self._mean(name)[start:stop]
            avg = avg[np.isfinite(avg)]
            out[f"{name}_mean"] = float(avg.mean()) if avg.size else float("nan")
            out[f"{name}_inside"] = self.fraction_inside(name, start, confidence, stop)
        d = self.diverged()
        out["diverged"] = float(d.sum())
        out["diverged_fraction"] = float(d.mean()) if d.size else float("nan")
        return out


def merge_all(parts: Iterable[MonteCarloMetrics]) -> MonteCarloMetrics:
    """Merge the accumulators of several chunks (any order gives the same sums)."""
    it = iter(parts)
    try:
        out = next(it)
    except StopIteration:
        raise ValueError("merge_all got no accumulators; expected at least one") from None
    for p in it:
        out = out.merge(p)
    return out
