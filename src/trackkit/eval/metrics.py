"""Streamed Monte Carlo metrics: per-step sums over runs, mergeable exactly across chunks.

``MonteCarloMetrics`` keeps, for every time step k, the sums over runs of

* the squared error ``|e_g|^2`` of each error group g (``e = x_true - x_hat``, angle state
  components wrapped), giving ``MSE_k = sum |e_g|^2 / N_k`` and ``RMSE_k = sqrt(MSE_k)``;
* the NEES ``e^T P^{-1} e`` (P the estimate covariance), giving the average NEES;
* the NIS ``r^T S^{-1} r`` of the innovations (rows with a ``nan`` residual, i.e. a missing
  measurement, are not counted), giving the average NIS;

and the counts N_k and chi-square degrees of freedom behind them. Nothing is kept per run and
step: memory is O(steps) plus three small per-run counters for the divergence rule.

Consistency bounds: if the filter is consistent, N times the average NEES of N independent
runs is chi-square with N n degrees of freedom, so the two-sided ``confidence`` interval of the
average is ``[chi2.ppf(a/2, N n) / N, chi2.ppf(1 - a/2, N n) / N]`` with ``a = 1 - confidence``
(likewise NIS with the measurement dimension m; see ``chi2_bounds``).

Exact merging: the sums are kept in an exact fixed-point (Kulisch) accumulator, so adding the
runs in one batch, in chunks, on several workers and in any order gives bit-identical results
(``a.merge(b)`` of two chunks equals the one-shot accumulation of all their runs), and every
reported mean is the correctly rounded value of the exact sum.

Divergence rule (per run). A run is *bad* at a step when its estimate (mean or covariance) is
not finite, or its NEES exceeds ``nees_threshold`` (default
``100 * chi2.ppf(1 - 1e-6, n)``: a consistent filter passes ``chi2.ppf(1 - 1e-6, n)`` once in a
million steps, and a further factor 100 means the covariance understates the error by two
orders of magnitude: the track is lost, not merely overconfident), or, when ``distance`` is
set, the error norm of the group ``distance_group`` (default "position") exceeds it. A run has
*diverged* when it is bad at its last accumulated step or on more than ``max_bad_fraction`` of
its steps. Runs with a non-finite estimate are left out of the RMSE and NEES sums of that step
(they are counted by the divergence rule and in ``invalid``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

from trackkit.angles import wrap
from trackkit.belief import Gaussian, Innovation
from trackkit.linalg import quadratic_form

__all__ = ["MonteCarloMetrics", "chi2_bounds", "merge_all"]

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


@lru_cache(maxsize=64)
def _default_nees_threshold(n: int) -> float:
    return 100.0 * float(chi2.ppf(1 - 1e-6, n))


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
    lo = np.where(ok, chi2.ppf(a / 2, ds) / cs, np.nan)
    hi = np.where(ok, chi2.ppf(1 - a / 2, ds) / cs, np.nan)
    return lo, hi


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

    and chunks combine with ``acc.merge(other)``. See the module docstring for the maths and
    the divergence rule.
    """

    groups: Mapping[str, GroupSpec] = field(default_factory=dict)
    angular: Sequence[bool] | None = None
    nees_indices: Sequence[int] | None = None
    nees_threshold: float | None = None
    distance: float | None = None
    distance_group: str = "position"
    max_bad_fraction: float = 0.25

    n_steps: int = field(default=0, init=False)
    #: exact sums, ``(len(groups) + 2, capacity, _LIMBS)``: groups..., NEES, NIS
    sums: NDArray[np.int64] = field(init=False, repr=False)
    #: terms per sum ``(len(groups) + 2, capacity)``
    counts: NDArray[np.int64] = field(init=False, repr=False)
    #: chi-square degrees of freedom per sum (NEES and NIS rows; group rows: components)
    dof: NDArray[np.int64] = field(init=False, repr=False)
    #: runs with a non-finite estimate, per step
    invalid: NDArray[np.int64] = field(init=False, repr=False)
    #: per run: steps accumulated, bad steps, last step index, bad at the last step
    run_steps: NDArray[np.int64] = field(init=False, repr=False)
    run_bad: NDArray[np.int64] = field(init=False, repr=False)
    run_last: NDArray[np.int64] = field(init=False, repr=False)
    run_last_bad: NDArray[np.bool_] = field(init=False, repr=False)

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
        self.sums = np.zeros((K, 0, _LIMBS), np.int64)
        self.counts = np.zeros((K, 0), np.int64)
        self.dof = np.zeros((K, 0), np.int64)
        self.invalid = np.zeros(0, np.int64)
        self.run_steps = np.zeros(0, np.int64)
        self.run_bad = np.zeros(0, np.int64)
        self.run_last = np.zeros(0, np.int64)
        self.run_last_bad = np.zeros(0, bool)
        self._started = False

    # -- bookkeeping ---------------------------------------------------------------------------

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the accumulated sums: the error groups, then "nees" and "nis"."""
        return (*self.groups, "nees", "nis")

    @property
    def runs(self) -> int:
        """Number of runs accumulated (the per-run counters' length)."""
        return int(self.run_steps.size)

    def _row(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"{name!r} is not accumulated; expected one of {self.names}") from None

    def _grow(self, k: int) -> None:
        if k < 0:
            raise ValueError(f"step k = {k}; expected an index >= 0")
        cap = self.counts.shape[1]
        if k >= cap:
            new = max(k + 1, 2 * cap, 16)
            pad = new - cap
            self.sums = np.pad(self.sums, ((0, 0), (0, pad), (0, 0)))
            self.counts = np.pad(self.counts, ((0, 0), (0, pad)))
            self.dof = np.pad(self.dof, ((0, 0), (0, pad)))
            self.invalid = np.pad(self.invalid, (0, pad))
        self.n_steps = max(self.n_steps, k + 1)

    def _runs(self, R: int) -> None:
        if not self._started and self.runs == 0:
            self.run_steps = np.zeros(R, np.int64)
            self.run_bad = np.zeros(R, np.int64)
            self.run_last = np.full(R, -1, np.int64)
            self.run_last_bad = np.zeros(R, bool)
            self._started = True
        elif R != self.runs:
            raise ValueError(
                f"{R} runs given but this accumulator holds {self.runs}; each accumulator "
                "takes a fixed set of runs (merge accumulators of other chunks)"
            )

    def _accumulate(self, k: int, rows: Sequence[int], values: Array, ok: NDArray[np.bool_],
                    dof: Sequence[int]) -> None:
        """Add ``values[i][ok[i]]`` to sum ``rows[i]`` at step k, with counts and dof."""
        vals, slots = [], []
        cap = self.counts.shape[1]
        for r, v, mask, d in zip(rows, values, ok, dof, strict=True):
            vals.append(v[mask])
            slots.append(np.full(int(mask.sum()), r * cap + k, np.intp))
            self.counts[r, k] += int(mask.sum())
            self.dof[r, k] += int(mask.sum()) * d
        flat = self.sums.reshape(-1, _LIMBS)  # a view: the sums are contiguous
        _exact_add(flat, np.concatenate(slots), np.concatenate(vals))

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
        P = np.broadcast_to(P, batch + (n, n)).reshape(R, n, n)
        self._runs(R)
        self._grow(k)

        e = x - mean
        if self.angular is not None:
            if len(self.angular) != n:
                raise ValueError(f"angular has {len(self.angular)} entries; the state has {n}")
            mask = np.asarray(self.angular)
            e = np.where(mask, wrap(e), e)
        valid = np.isfinite(e).all(-1) & np.isfinite(P).all((-1, -2))

        values, rows, dofs = [], [], []
        sq_norms = {}
        e0 = np.where(valid[:, None], e, 0.0)
        for r, (name, spec) in enumerate(self.groups.items()):
            if callable(spec):
                eg = np.asarray(spec(x, mean), dtype=float).reshape(R, -1)
                eg = np.where(valid[:, None], eg, 0.0)
            else:
                eg = e0[:, list(spec)]
            sq = (eg * eg).sum(-1)
            sq_norms[name] = sq
            values.append(sq)
            rows.append(r)
            dofs.append(eg.shape[-1])

        idx = list(self.nees_indices) if self.nees_indices is not None else list(range(n))
        Ps = P[:, idx][:, :, idx]
        Ps = np.where(valid[:, None, None], Ps, np.eye(len(idx)))
        try:
            nees = quadratic_form(Ps, e0[:, idx], "estimate covariance (for NEES)")
        except ValueError:
            # a filter that lost positive definiteness has failed on those runs: count them
            # as invalid (and so bad for the divergence rule) instead of stopping the study
            eig = np.linalg.eigvalsh(Ps)
            pd = eig[:, 0] > 1e-12 * np.abs(eig[:, -1])  # condition number below 1e12
            valid &= pd
            Ps = np.where(pd[:, None, None], Ps, np.eye(len(idx)))
            e0 = np.where(valid[:, None], e0, 0.0)
            values = [np.where(valid, v, 0.0) for v in values]
            nees = quadratic_form(Ps, e0[:, idx], "estimate covariance (for NEES)")
        values.append(nees)
        rows.append(len(self.groups))
        dofs.append(len(idx))
        self._accumulate(k, rows, values, [valid] * len(rows), dofs)
        self.invalid[k] += int((~valid).sum())

        # divergence bookkeeping
        thr = self.nees_threshold
        if thr is None:
            thr = _default_nees_threshold(len(idx))
        bad = ~valid | (nees > thr)
        if self.distance is not None:
            bad |= sq_norms[self.distance_group] > self.distance**2
        self.run_steps += 1
        self.run_bad += bad
        later = k >= self.run_last
        self.run_last_bad = np.where(later, bad, self.run_last_bad)
        self.run_last = np.where(later, k, self.run_last)

        if innovation is not None:
            self.add_innovation(k, innovation)

    def add_innovation(self, k: int, innovation: Innovation) -> None:
        """Accumulate the NIS ``r^T S^{-1} r`` of step ``k``; rows whose residual has a
        ``nan`` (missing measurement) are skipped. Several calls at one step (several
        sensors) pool their terms and degrees of freedom."""
        r = np.asarray(innovation.residual, dtype=float)
        if r.ndim < 1:
            raise ValueError(f"innovation.residual has shape {r.shape}; expected (..., m)")
        m = r.shape[-1]
        S = np.asarray(innovation.cov, dtype=float)
        if S.shape[-2:] != (m, m):
            raise ValueError(f"innovation.cov has shape {S.shape}; expected (..., {m}, {m})")
        present = np.isfinite(r).all(-1)
        S = np.broadcast_to(S, r.shape[:-1] + (m, m))
        r0 = np.where(present[..., None], r, 0.0)
        nis = quadratic_form(S, r0, "innovation covariance (for NIS)")
        self._grow(k)
        self._accumulate(k, [len(self.groups) + 1], [nis.reshape(-1)], [present.reshape(-1)],
                         [m])

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
            out.sums[:, :t] += src.sums[:, :t]
            out.counts[:, :t] += src.counts[:, :t]
            out.dof[:, :t] += src.dof[:, :t]
            out.invalid[:t] += src.invalid[:t]
        _carry(out.sums)
        out.run_steps = np.concatenate([self.run_steps, other.run_steps])
        out.run_bad = np.concatenate([self.run_bad, other.run_bad])
        out.run_last = np.concatenate([self.run_last, other.run_last])
        out.run_last_bad = np.concatenate([self.run_last_bad, other.run_last_bad])
        out._started = self._started or other._started
        return out

    # -- results -------------------------------------------------------------------------------

    def total(self, name: str) -> Array:
        """The exact per-step sum over runs (correctly rounded), shape ``(n_steps,)``."""
        return _exact_value(self.sums[self._row(name), : self.n_steps])

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

    def rmse_time_average(self, group: str, start: int = 0) -> float:
        """Time-averaged RMSE from step ``start`` on: ``sqrt(mean_{k >= start} MSE_k)``, the
        root mean squared error over all runs and steps of the window (steps without data
        skipped)."""
        mse = self.mse(group)[start:]
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

    def fraction_inside(self, name: str, start: int = 0, confidence: float = 0.95) -> float:
        """Fraction of the steps ``k >= start`` with data whose average NEES/NIS lies inside
        the two-sided ``confidence`` bounds (about ``confidence`` for a consistent filter)."""
        avg = self._mean(name)[start:]
        lo, hi = (b[start:] for b in self.bounds(name, confidence))
        has = np.isfinite(avg)
        if not has.any():
            return float("nan")
        return float(((avg >= lo) & (avg <= hi))[has].mean())

    def diverged(self) -> NDArray[np.bool_]:
        """Per run: diverged by the rule in the module docstring."""
        frac = self.run_bad / np.maximum(self.run_steps, 1)
        return self.run_last_bad | (frac > self.max_bad_fraction)

    def summary(self, start: int = 0, confidence: float = 0.95) -> dict[str, float]:
        """Plain-float summary: runs, steps, time-averaged RMSE per group from ``start``, mean
        NEES/NIS over the steps from ``start`` and the fraction of those steps inside the
        ``confidence`` bounds, and the number and fraction of diverged runs."""
        out: dict[str, float] = {"runs": float(self.runs), "steps": float(self.n_steps)}
        for g in self.groups:
            out[f"rmse_{g}"] = self.rmse_time_average(g, start)
        for name in ("nees", "nis"):
            avg = self._mean(name)[start:]
            avg = avg[np.isfinite(avg)]
            out[f"{name}_mean"] = float(avg.mean()) if avg.size else float("nan")
            out[f"{name}_inside"] = self.fraction_inside(name, start, confidence)
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
