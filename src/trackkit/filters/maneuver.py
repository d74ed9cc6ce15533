"""Manoeuvre detection from innovations, and the responses to a detection (the missing-measurements
thesis, sections 3-3-4-1 and 3-3-4-2).

A filter with the right motion model has white innovations; a manoeuvre makes them large and
correlated. Three detectors test that, each a small frozen dataclass of parameters with pure
kernels over any batch of tracks or runs:

    det = NISDetector(pfa=1e-2, dim_z=2)       # eps(k) = nu^T S^-1 nu              (3-17)
    det = FadingMemoryDetector(alpha=0.8, pfa=1e-2, dim_z=2)  # rho = alpha rho + eps (3-20)
    det = WindowDetector(L=5, pfa=1e-2, dim_z=2)  # D_L = sum of the last L residuals (3-21)
    s = det.init(batch_shape)                  # a NamedTuple of arrays of batch_shape
    s = det.step(s, innov)                     # innov: Innovation (nu (..., m), cov)
    s.on, s.fired, s.statistic, s.onset, det.threshold, det.memory

**Thresholds.** ``pfa`` is the per-step probability, under the no-manoeuvre hypothesis (a
correctly specified filter: innovations independent, ``nu(k) ~ N(0, S(k))``), that the
statistic exceeds the on threshold. NIS and the window statistic are exactly chi-square(m)
(``m = dim_z``), so their threshold is the chi-square quantile. The fading-memory statistic
in steady state is ``rho = sum_j alpha^j eps_j``, an infinite weighted sum of independent
chi-square(m) variables; its threshold is computed from that distribution by Imhof's
inversion of the characteristic function, truncated where ``alpha^J`` no longer moves the
probability (``method="imhof"``, the default; thresholds good to about 1e-9 relative for
pfa >= 1e-6), or by the two-moment scaled chi-square of Satterthwaite and Welch
(``method="satterthwaite"``), whose tail is too light: for alpha 0.5-0.9 and m = 1, 2 its
actual false-alarm probability is 1.2-1.3 times the design at pfa = 1e-2, about twice at
1e-3 and 2.5-3.6 times at 1e-4. After ``n`` measurements ``rho`` holds only n terms and is
smaller; with ``startup=True`` each age n gets the quantile of the n-term sum, until the age
at which the steady threshold's false-alarm probability is within 0.1% of ``pfa``.

**On and off (hysteresis).** A detector turns on at a step whose statistic exceeds the on
threshold; it turns off after ``n_off`` consecutive steps whose statistic is below the off
threshold, the ``1 - pfa_off`` quantile of the same distribution (``pfa <= pfa_off <= 0.5``,
default ``max(pfa, 0.1)``); a step above the on threshold keeps it on. ``fired`` marks the
step at which it turned on and ``onset`` keeps that step's index (the detection time). A row
whose innovation residual is nan (no measurement) keeps its statistic and its decision.

**Memory.** ``det.memory`` is how far back the evidence of a detection reaches, in steps: 0
for NIS, ``L - 1`` for the window, and for the fading memory ``round(alpha / (1 - alpha))``,
the memory of the window whose statistic has the same mean (``L = 1 / (1 - alpha)``), which is
also the mean lag of the weights ``alpha^j``. The variable-order filter re-initialises at
``k - memory``.

**Responses** (section 3-3-4-2): ``QInflation(factor)`` scales Q in the rows that are on
(through :class:`ScaledNoise`, a motion model whose Q is scaled per batch row),
``PInflation(factor)`` scales the filtered covariance of the rows that fired, once, at the
detection step; both change the filter from the step after the detection.
:func:`run_with_detector` runs any filter with a detector and a response over a measurement
sequence; :func:`run_variable_order` is the variable-order filter of section 3-3-4-3 (CV,
switched to CA re-initialised at ``k - s`` on a detection, and back to CV when the estimated
acceleration is no longer significant).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize
from scipy.special import chdtrc, chdtri  # chi2.sf, chi2.isf, without scipy.stats (0.5 s)

from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import register
from trackkit.filters.kalman import KF
from trackkit.linalg import quadratic_form
from trackkit.models.motion import ConstantAcceleration, ConstantVelocity
from trackkit.models.protocols import SensorModel

__all__ = [
    "DetectorState",
    "WindowState",
    "NISDetector",
    "FadingMemoryDetector",
    "WindowDetector",
    "chi2_threshold",
    "fading_threshold",
    "weighted_chi2_sf",
    "fading_memory",
    "ScaledNoise",
    "inflate_q",
    "inflate_p",
    "QInflation",
    "PInflation",
    "DetectorRun",
    "run_with_detector",
    "VariableOrderRun",
    "run_variable_order",
]

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]
Int = NDArray[np.int64]


# ------------------------------------------------------------------------------------------
# Parameter checks


def _probability(value: float, name: str, owner: str, hi: float = 1.0) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}: {name} = {value!r}; expected a probability in "
                         f"(0, {hi:g}{')' if hi == 1.0 else ']'}") from None
    if not (0.0 < v < 1.0 and v <= hi):
        raise ValueError(f"{owner}: {name} = {value!r}; expected a probability in "
                         f"(0, {hi:g}{')' if hi == 1.0 else ']'}")
    return v


def _count(value: int, name: str, owner: str, lo: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < lo:
        raise ValueError(f"{owner}: {name} = {value!r}; expected an integer >= {lo}")
    return int(value)


def _factor(value: float, name: str, owner: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (1.0 <= v < math.inf):
        raise ValueError(f"{owner}: {name} = {value!r}; expected a finite factor >= 1")
    return v


# ------------------------------------------------------------------------------------------
# Thresholds: chi-square, and the weighted sum of chi-squares of the fading memory


def chi2_threshold(pfa: float, dof: int) -> float:
    """The ``1 - pfa`` quantile of chi-square(dof) (``isf``, accurate for small pfa)."""
    pfa = _probability(pfa, "pfa", "chi2_threshold")
    return float(chdtri(_count(dof, "dof", "chi2_threshold"), pfa))


_GL_X, _GL_W = np.polynomial.legendre.leggauss(10)  # nodes per panel of a quarter period


class _Imhof:
    """P(Q > x) for ``Q = sum_j lam_j chi2_h`` (independent, lam_j > 0), Imhof (1961):

        P(Q > x) = 1/2 + 1/pi int_0^inf sin(phi(u) - x u / 2) / (u rho(u)) du,
        phi(u) = h/2 sum_j atan(lam_j u),   rho(u) = prod_j (1 + lam_j^2 u^2)^(h/4),

    for every x in ``[x_lo, x_hi]`` on one fixed quadrature: Gauss-Legendre panels (10 nodes)
    growing from ``1 / (4 lam_max)`` near 0 to a quarter of the shortest period ``4 pi / x_hi``
    and kept at that up to U, and beyond U the first two terms
    of integration by parts, ``g cos psi / psi' - (g / psi')' sin psi / psi'`` with
    ``g = 1 / (u rho)`` and ``psi = phi - x u / 2`` (the next term is below ``eps``). g, phi
    and their derivatives do not depend on x, so each x costs one dot product.
    """

    def __init__(self, lam: Array, h: float, x_lo: float, x_hi: float, eps: float) -> None:
        self.lam, self.h = lam, h
        w_lo, w_hi = 0.5 * x_lo, 0.5 * x_hi
        panel = 0.5 * math.pi / w_hi
        N = lam.size * h
        # g ~ u^-(1 + N/2) at large u; the third by-parts term is ~ g (N/2+2)^2 / (u^2 w^3)
        U = 8.0 * panel
        while True:
            lg = self._log_g(np.array([U]))[0]
            if lg < math.log(eps * w_lo) or (
                    lg + 2.0 * math.log(N / 2 + 2) - 2.0 * math.log(U) - 3.0 * math.log(w_lo)
                    < math.log(eps)):
                break
            U *= 1.5
        # near 0 the amplitude varies on the scale 1 / lam_max: panels grow from a quarter of
        # it, geometrically, up to the quarter period, which they keep to U
        edges = [0.0]
        while edges[-1] < U and 0.25 * (1.0 / lam[0] + edges[-1]) < panel:
            edges.append(edges[-1] + 0.25 * (1.0 / lam[0] + edges[-1]))
        n_uniform = max(0, math.ceil((U - edges[-1]) / panel))
        if n_uniform > 400_000:
            raise ValueError(f"weighted chi-square: {n_uniform} quadrature panels needed for "
                             f"x in [{x_lo:.3g}, {x_hi:.3g}]; expected a smaller range")
        edges = np.concatenate([edges, edges[-1] + panel * np.arange(1, n_uniform + 1)])
        U = float(edges[-1])
        start, width = edges[:-1, None], np.diff(edges)[:, None]
        self.u = (start + 0.5 * width * (_GL_X + 1.0)).ravel()
        self.w = (0.5 * width * _GL_W).ravel()
        self.phi = self._phi(self.u)
        self.wg = self.w * np.exp(self._log_g(self.u))
        self.U = U
        # at U: g, g'/g, phi, phi', phi''
        u = np.array([U])
        self.gU = math.exp(self._log_g(u)[0])
        lu2 = (lam * U) ** 2
        self.dlogg = -1.0 / U - 0.5 * h * float(np.sum(lam**2 * U / (1 + lu2)))
        self.phiU = float(self._phi(u)[0])
        self.dphi = 0.5 * h * float(np.sum(lam / (1 + lu2)))
        self.d2phi = -h * float(np.sum(lam**3 * U / (1 + lu2) ** 2))

    def _sums(self, u: Array, fn) -> Array:
        out = np.zeros(u.shape)
        step = max(1, 2_000_000 // max(u.size, 1))  # bounded memory for long sums
        for j in range(0, self.lam.size, step):
            out += fn(u[:, None] * self.lam[None, j:j + step]).sum(-1)
        return out

    def _phi(self, u: Array) -> Array:
        return 0.5 * self.h * self._sums(u, np.arctan)

    def _log_g(self, u: Array) -> Array:
        return -0.25 * self.h * self._sums(u, lambda a: np.log1p(a * a)) - np.log(u)

    def sf(self, x: ArrayLike) -> Array:
        x = np.atleast_1d(np.asarray(x, dtype=float))
        w = 0.5 * x
        body = np.sin(self.phi[:, None] - self.u[:, None] * w[None, :]).T @ self.wg
        psi = self.phiU - w * self.U
        d1 = self.dphi - w
        g = self.gU
        dg_over_d1 = g * self.dlogg / d1 - g * self.d2phi / d1**2  # (g / psi')'
        tail = g * np.cos(psi) / d1 - dg_over_d1 * np.sin(psi) / d1
        return 0.5 + (body + tail) / math.pi


def weighted_chi2_sf(x: ArrayLike, weights: ArrayLike, dof: int) -> Array:
    """``P(sum_j w_j chi2_dof > x)`` for independent chi-squares and weights ``w_j > 0``
    (Imhof's inversion, see ``_Imhof``). The formula is 1/2 plus an integral, so the
    accuracy is absolute, a few 1e-14 (rounding): 1e-8 relative at a tail of 1e-6."""
    lam = np.asarray(weights, dtype=float).ravel()
    if lam.size == 0 or not np.all((lam > 0) & np.isfinite(lam)):
        raise ValueError(f"weighted_chi2_sf: weights = {lam.tolist()}; expected finite "
                         "values > 0")
    dof = _count(dof, "dof", "weighted_chi2_sf")
    x = np.asarray(x, dtype=float)
    if not np.all(x > 0):
        raise ValueError(f"weighted_chi2_sf: x has entries <= 0 (min {float(np.min(x))!r}); "
                         "expected x > 0")
    if lam.size == 1:
        return np.asarray(chdtrc(dof, x / lam[0]))
    q = _Imhof(np.sort(lam)[::-1], float(dof), float(np.min(x)), float(np.max(x)), 1e-16)
    return q.sf(x.ravel()).reshape(x.shape)


def _fading_weights(alpha: float, n: int | None, dof: int) -> Array:
    """alpha^j for j < n; for the steady state (n None) up to where the tail's mean
    ``dof alpha^J / (1 - alpha)`` is below 1e-13."""
    if n is None:
        n = math.ceil(math.log(1e-13 * (1 - alpha) / dof) / math.log(alpha))
    return alpha ** np.arange(n, dtype=float)


def _satterthwaite(pfa: float, lam: Array, dof: int) -> float:
    """``c chi2_nu`` with the mean ``dof sum lam`` and variance ``2 dof sum lam^2`` of the sum:
    ``c = sum lam^2 / sum lam``, ``nu = dof (sum lam)^2 / sum lam^2``."""
    s1, s2 = float(lam.sum()), float((lam * lam).sum())
    return s2 / s1 * float(chdtri(dof * s1 * s1 / s2, pfa))


def _chernoff_bound(p: float, lam: Array, dof: int) -> float:
    """An x with ``P(Q > x) < p`` (Chernoff at s = 1/4: ``P(Q > x) <= exp(K(s) - s x)``,
    ``K(s) = -dof/2 sum log(1 - 2 lam s)``, for lam <= 1)."""
    K = -0.5 * dof * float(np.log1p(-0.5 * lam).sum())
    return 4.0 * (K + math.log(10.0 / p))


def _quantile(q: _Imhof, pfa: float, lo: float, hi: float) -> float:
    """The x in [lo, hi] with ``P(Q > x) = pfa`` (``lo`` if the tail there is already <= pfa),
    solved on log P so that small probabilities keep their relative precision."""
    def f(x: float) -> float:
        return math.log(max(float(q.sf(x)[0]), 1e-300)) - math.log(pfa)

    if f(lo) <= 0.0:
        return lo
    return optimize.brentq(f, lo, hi, xtol=1e-13 * hi, rtol=1e-15, maxiter=200)


@lru_cache(maxsize=256)
def _imhof_quantiles(pfa: float, alpha: float, dof: int, startup: bool) -> tuple[float, ...]:
    """Thresholds ``(t_1, ..., t_n, t_inf)``: t_n the ``1 - pfa`` quantile of the n-term sum,
    for the ages at which using ``t_inf`` instead would lower the false-alarm probability by
    more than 0.1%; ``(t_inf,)`` without start-up handling."""
    lam_inf = _fading_weights(alpha, None, dof)
    x_lo = float(chdtri(dof, pfa))  # rho >= eps(k): every quantile is above this
    x_hi = _chernoff_bound(pfa, lam_inf, dof)
    eps = 1e-10 * pfa
    t_inf = _quantile(_Imhof(lam_inf, float(dof), x_lo, x_hi, eps), pfa, x_lo, x_hi)
    if not startup:
        return (t_inf,)
    out = [x_lo]  # one term: chi-square(dof) exactly
    for n in range(2, lam_inf.size):
        q = _Imhof(lam_inf[:n], float(dof), out[-1], t_inf, eps)
        if q.sf(t_inf)[0] >= (1 - 1e-3) * pfa:
            break
        out.append(_quantile(q, pfa, out[-1], t_inf))
    return (*out, t_inf)


def fading_threshold(pfa: float, dof: int, alpha: float, n: int | None = None,
                     method: str = "imhof") -> float:
    """Threshold of the fading-memory statistic ``rho = sum_{j<n} alpha^j eps_j`` (eps_j
    independent chi-square(dof)) for a false-alarm probability pfa: the steady state for
    ``n=None``, else after n measurements. ``method`` is ``"imhof"`` (exact up to the
    numerical inversion) or ``"satterthwaite"`` (moment-matched scaled chi-square)."""
    pfa = _probability(pfa, "pfa", "fading_threshold")
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        a = math.nan
    if not 0.0 < a < 1.0:
        raise ValueError(f"fading_threshold: alpha = {alpha!r}; expected 0 < alpha < 1")
    dof = _count(dof, "dof", "fading_threshold")
    if n is not None:
        n = _count(n, "n", "fading_threshold")
    lam = _fading_weights(a, n, dof)
    if method == "satterthwaite":
        return _satterthwaite(pfa, lam, dof)
    if method != "imhof":
        raise ValueError(f"fading_threshold: method = {method!r}; expected 'imhof' or "
                         "'satterthwaite'")
    if lam.size == 1:
        return float(chdtri(dof, pfa))
    if n is None:
        return _imhof_quantiles(pfa, a, dof, False)[-1]
    x_lo = float(chdtri(dof, pfa))
    x_hi = _chernoff_bound(pfa, lam, dof)
    return _quantile(_Imhof(lam, float(dof), x_lo, x_hi, 1e-10 * pfa), pfa, x_lo, x_hi)


def fading_memory(alpha: float) -> int:
    """Effective memory of the fading statistic, in steps: ``round(alpha / (1 - alpha))``."""
    return int(round(alpha / (1.0 - alpha)))


# ------------------------------------------------------------------------------------------
# Detector states and the shared on/off logic


class DetectorState(NamedTuple):
    """State of an NIS or fading-memory detector, every field of the batch shape.

    ``statistic`` (float): the latest test statistic (held where a measurement is missing);
    ``on`` (bool): the decision; ``fired`` (bool): it turned on at the latest step;
    ``below`` (int): consecutive steps below the off threshold while on; ``age`` (int):
    measurements since init or reset; ``onset`` (int): index of the step at which it last
    turned on (-1: never); ``k`` (int): steps taken, i.e. the index of the next step.
    """

    statistic: Array
    on: Bool
    fired: Bool
    below: Int
    age: Int
    onset: Int
    k: Int


class WindowState(NamedTuple):
    """State of a :class:`WindowDetector`: the fields of :class:`DetectorState` and the last
    L residuals ``(..., L, m)`` and their covariances ``(..., L, m, m)``, oldest first (zeros
    where fewer than L measurements have come)."""

    statistic: Array
    on: Bool
    fired: Bool
    below: Int
    age: Int
    onset: Int
    k: Int
    residuals: Array
    covs: Array


def _innovation(innov: Any, m: int, batch: tuple[int, ...], owner: str) -> tuple[Array, Array]:
    """(residual, S) checked: residual ``batch + (m,)``, S broadcast to ``batch + (m, m)``."""
    r = np.asarray(innov.nu, dtype=float)
    if r.shape != batch + (m,):
        raise ValueError(f"{owner}.step: innovation residual has shape {r.shape}; the detector "
                         f"state has batch shape {batch} and dim_z = {m}, so expected "
                         f"{batch + (m,)}")
    S = np.asarray(innov.cov, dtype=float)
    try:
        S = np.broadcast_to(S, batch + (m, m))
    except ValueError:
        raise ValueError(f"{owner}.step: innovation cov has shape {S.shape}; expected "
                         f"{batch + (m, m)} (or broadcastable to it)") from None
    return r, S


def _nis(r: Array, S: Array, have: Bool) -> Array:
    """``eps = r^T S^-1 r`` on the rows with a measurement (0 elsewhere)."""
    if have.all():
        return quadratic_form(S, r)
    eye = np.eye(r.shape[-1])
    return quadratic_form(np.where(have[..., None, None], S, eye),
                          np.where(have[..., None], r, 0.0))


class _Detector:
    """On/off logic shared by the detectors (subclasses define the statistic)."""

    name = "Detector"
    dim_z: int
    pfa: float
    pfa_off: float | None
    n_off: int

    def _check_common(self) -> None:
        owner = type(self).__name__
        object.__setattr__(self, "pfa", _probability(self.pfa, "pfa", owner))
        _count(self.dim_z, "dim_z", owner)
        off = max(self.pfa, 0.1) if self.pfa_off is None else _probability(
            self.pfa_off, "pfa_off", owner, hi=0.5)
        if self.pfa_off is not None and off < self.pfa:
            raise ValueError(f"{owner}: pfa_off = {self.pfa_off!r} is below pfa = {self.pfa!r}; "
                             "expected pfa <= pfa_off <= 0.5 (the off threshold at or below the "
                             "on threshold)")
        object.__setattr__(self, "pfa_off", off)
        _count(self.n_off, "n_off", owner)

    def thresholds(self, age: ArrayLike) -> tuple[Any, Any]:
        """The (on, off) thresholds of a decision made with ``age`` measurements (per row;
        only the fading memory's start-up depends on age)."""
        return self.threshold, self.threshold_off

    @staticmethod
    def _init_fields(batch: tuple[int, ...]) -> tuple:
        return (np.zeros(batch), np.zeros(batch, bool), np.zeros(batch, bool),
                np.zeros(batch, np.int64), np.zeros(batch, np.int64),
                np.full(batch, -1, np.int64), np.zeros(batch, np.int64))

    def _decide(self, s: Any, stat: Array, have: Bool) -> tuple:
        """The hysteresis rule on rows with a measurement; the others keep their decision."""
        age = s.age + have
        t_on, t_off = self.thresholds(age)
        above = stat > t_on
        below = np.where(s.on & (stat < t_off) & ~above, s.below + 1, 0)
        on = above | (s.on & (below < self.n_off))
        on = np.where(have, on, s.on)
        below = np.where(have & on, below, np.where(have, 0, s.below))
        statistic = np.where(have, stat, s.statistic)
        fired = on & ~s.on
        onset = np.where(fired, s.k, s.onset)
        return statistic, on, fired, below, age, onset, s.k + 1

    def _reset_fields(self, s: Any, where: ArrayLike) -> tuple:
        w = np.asarray(where, dtype=bool)
        return (np.where(w, 0.0, s.statistic), s.on & ~w, s.fired & ~w,
                np.where(w, 0, s.below), np.where(w, 0, s.age), s.onset, s.k)

    @property
    def threshold_off(self) -> float:
        return self._threshold_off

    @property
    def threshold(self) -> float:
        return self._threshold_on


def _batch(batch_shape: int | tuple[int, ...]) -> tuple[int, ...]:
    if isinstance(batch_shape, int | np.integer):
        return (int(batch_shape),)
    return tuple(int(b) for b in batch_shape)


@dataclass(frozen=True, eq=False)
class NISDetector(_Detector):
    """Normalised innovation squared, ``eps(k) = nu(k)^T S(k)^-1 nu(k)`` (eq. 3-17), against
    the chi-square(dim_z) quantile at ``1 - pfa``. Memory 0: the evidence is this step's."""

    pfa: float = 1e-2
    dim_z: int = 2
    pfa_off: float | None = None
    n_off: int = 3
    name = "NIS"

    def __post_init__(self) -> None:
        self._check_common()
        object.__setattr__(self, "_threshold_on", chi2_threshold(self.pfa, self.dim_z))
        object.__setattr__(self, "_threshold_off", chi2_threshold(self.pfa_off, self.dim_z))

    @property
    def memory(self) -> int:
        return 0

    def init(self, batch_shape: int | tuple[int, ...]) -> DetectorState:
        """A detector state for ``batch_shape`` tracks or runs: off, statistic 0."""
        return DetectorState(*self._init_fields(_batch(batch_shape)))

    def step(self, state: DetectorState, innov: Innovation) -> DetectorState:
        """Test this step's innovation (nan residual rows: no measurement, state held)."""
        r, S = _innovation(innov, self.dim_z, np.shape(state.on), type(self).__name__)
        have = ~np.isnan(r).any(-1)
        return DetectorState(*self._decide(state, _nis(r, S, have), have))

    def reset(self, state: DetectorState, where: ArrayLike) -> DetectorState:
        """Rows ``where`` back to the initial state (the step count and onset kept)."""
        return DetectorState(*self._reset_fields(state, where))


@dataclass(frozen=True, eq=False)
class FadingMemoryDetector(_Detector):
    """Fading-memory NIS, ``rho(k) = alpha rho(k-1) + eps(k)`` (eq. 3-20), rho(0) = 0.

    In steady state ``rho = sum_j alpha^j eps(k-j)``, mean ``dim_z / (1 - alpha)``; the
    threshold is that distribution's ``1 - pfa`` quantile (``method``: ``"imhof"``, exact up
    to the numerical inversion, or ``"satterthwaite"``). With ``startup=True`` a row that has
    had n measurements is tested against the quantile of the n-term sum (see the module
    docstring). The first construction for a given (alpha, pfa, dim_z) computes the tables
    (0.1-1 s; cached afterwards). Memory ``round(alpha / (1 - alpha))`` steps.
    """

    alpha: float = 0.8
    pfa: float = 1e-2
    dim_z: int = 2
    pfa_off: float | None = None
    n_off: int = 3
    startup: bool = True
    method: str = "imhof"
    name = "fading memory"

    def __post_init__(self) -> None:
        self._check_common()
        try:
            a = float(self.alpha)
        except (TypeError, ValueError):
            a = math.nan
        if not 0.0 < a < 1.0:
            raise ValueError(f"FadingMemoryDetector: alpha = {self.alpha!r}; expected a "
                             "forgetting factor 0 < alpha < 1")
        object.__setattr__(self, "alpha", a)
        if self.method not in ("imhof", "satterthwaite"):
            raise ValueError(f"FadingMemoryDetector: method = {self.method!r}; expected "
                             "'imhof' or 'satterthwaite'")
        on, off = (self._table(p) for p in (self.pfa, self.pfa_off))
        object.__setattr__(self, "_on_table", on)
        object.__setattr__(self, "_off_table", off)
        object.__setattr__(self, "_threshold_on", float(on[-1]))
        object.__setattr__(self, "_threshold_off", float(off[-1]))

    def _table(self, pfa: float) -> Array:
        """Thresholds indexed by age (entry 0 unused; the last entry is the steady state)."""
        if self.method == "imhof":
            t = _imhof_quantiles(pfa, self.alpha, self.dim_z, bool(self.startup))
        else:
            t_inf = fading_threshold(pfa, self.dim_z, self.alpha, None, "satterthwaite")
            t = [t_inf]
            if self.startup:
                lam = _fading_weights(self.alpha, None, self.dim_z)
                t = [fading_threshold(pfa, self.dim_z, self.alpha, n, "satterthwaite")
                     for n in range(1, lam.size)]
                # the start-up ends where the n-term threshold is within 0.1% of the steady one
                stop = next((i for i, v in enumerate(t) if v >= (1 - 1e-3) * t_inf), len(t))
                t = [*t[:stop], t_inf]
        table = np.array([t[0], *t])
        table.flags.writeable = False
        return table

    def thresholds(self, age: ArrayLike) -> tuple[Any, Any]:
        """The (on, off) thresholds after ``age`` measurements: the start-up table's entries
        (the n-term quantiles), the steady state beyond it."""
        if self._on_table.size == 2 and self._off_table.size == 2:
            return self._threshold_on, self._threshold_off
        age = np.asarray(age)
        return (self._on_table[np.minimum(age, self._on_table.size - 1)],
                self._off_table[np.minimum(age, self._off_table.size - 1)])

    @property
    def memory(self) -> int:
        return fading_memory(self.alpha)

    def init(self, batch_shape: int | tuple[int, ...]) -> DetectorState:
        """A detector state for ``batch_shape`` tracks or runs: off, rho = 0."""
        return DetectorState(*self._init_fields(_batch(batch_shape)))

    def step(self, state: DetectorState, innov: Innovation) -> DetectorState:
        """``rho = alpha rho + eps`` on rows with a measurement, then the on/off rule."""
        r, S = _innovation(innov, self.dim_z, np.shape(state.on), type(self).__name__)
        have = ~np.isnan(r).any(-1)
        rho = self.alpha * state.statistic + _nis(r, S, have)
        return DetectorState(*self._decide(state, rho, have))

    def reset(self, state: DetectorState, where: ArrayLike) -> DetectorState:
        """Rows ``where`` back to rho = 0, off, age 0 (the step count and onset kept)."""
        return DetectorState(*self._reset_fields(state, where))


@dataclass(frozen=True, eq=False)
class WindowDetector(_Detector):
    """Sliding-window residual sum ``D_L(k) = sum_{i=k-L+1}^{k} nu(i)`` (eq. 3-21), tested by
    ``D_L^T (sum_i S(i))^-1 D_L``: chi-square(dim_z) when the innovations are independent
    (a correctly specified filter), so the threshold is the chi-square quantile. The window
    holds the last L measurements received; before L have come it sums those there are (the
    statistic is still chi-square). Memory ``L - 1`` steps."""

    L: int = 5
    pfa: float = 1e-2
    dim_z: int = 2
    pfa_off: float | None = None
    n_off: int = 3
    name = "window"

    def __post_init__(self) -> None:
        self._check_common()
        object.__setattr__(self, "L", _count(self.L, "L", "WindowDetector"))
        object.__setattr__(self, "_threshold_on", chi2_threshold(self.pfa, self.dim_z))
        object.__setattr__(self, "_threshold_off", chi2_threshold(self.pfa_off, self.dim_z))

    @property
    def memory(self) -> int:
        return self.L - 1

    def init(self, batch_shape: int | tuple[int, ...]) -> WindowState:
        """A detector state for ``batch_shape`` tracks or runs: off, empty window."""
        batch = _batch(batch_shape)
        m, L = self.dim_z, self.L
        return WindowState(*self._init_fields(batch), np.zeros(batch + (L, m)),
                           np.zeros(batch + (L, m, m)))

    def step(self, state: WindowState, innov: Innovation) -> WindowState:
        """Push the residual into the window (rows with a measurement), then test
        ``D_L^T (sum S)^-1 D_L``."""
        r, S = _innovation(innov, self.dim_z, np.shape(state.on), type(self).__name__)
        have = ~np.isnan(r).any(-1)
        shifted_r = np.concatenate([state.residuals[..., 1:, :], r[..., None, :]], -2)
        shifted_S = np.concatenate([state.covs[..., 1:, :, :], S[..., None, :, :]], -3)
        res = np.where(have[..., None, None], shifted_r, state.residuals)
        covs = np.where(have[..., None, None, None], shifted_S, state.covs)
        D = res.sum(-2)
        S_sum = covs.sum(-3)
        empty = (state.age + have) == 0
        if empty.any():  # no measurement yet: statistic 0
            S_sum = np.where(empty[..., None, None], np.eye(self.dim_z), S_sum)
        stat = quadratic_form(S_sum, D)
        return WindowState(*self._decide(state, stat, have), res, covs)

    def reset(self, state: WindowState, where: ArrayLike) -> WindowState:
        """Rows ``where`` back to an empty window, off (the step count and onset kept)."""
        w = np.asarray(where, dtype=bool)
        return WindowState(*self._reset_fields(state, w),
                           np.where(w[..., None, None], 0.0, state.residuals),
                           np.where(w[..., None, None, None], 0.0, state.covs))


# ------------------------------------------------------------------------------------------
# Responses: Q inflation and P inflation


class ScaledNoise:
    """``motion`` with ``Q(x, dt)`` scaled per batch row: ``noise = scale[..., None, None] Q``.

    ``scale`` has the batch shape (or broadcasts to it); everything else (f, the Jacobian,
    ``linear``, ``dim_x``) is the wrapped model's. (``models.noise.with_noise`` replaces Q by
    a fixed matrix; this keeps the model's own Q(x, dt) and scales it.)
    """

    def __init__(self, motion: Any, scale: ArrayLike) -> None:
        scale = np.asarray(scale, dtype=float)
        bad = ~(np.isfinite(scale) & (scale >= 0))
        if bad.any():
            raise ValueError(f"ScaledNoise: scale has entries {scale[bad][:3].tolist()}; "
                             "expected finite values >= 0")
        self.motion = motion
        self.scale = scale

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        return self.scale[..., None, None] * np.asarray(self.motion.noise(x, dt), dtype=float)

    def __getattr__(self, name: str) -> Any:  # all but the noise is the motion model's
        return getattr(self.motion, name)

    def __repr__(self) -> str:
        return f"ScaledNoise({self.motion!r}, scale shape {self.scale.shape})"


def inflate_q(motion: Any, factor: float, on: ArrayLike) -> Any:
    """The motion model with ``Q -> factor Q`` in the rows where ``on`` (the model itself when
    no row is on, so that a quiet step costs nothing and is bitwise the plain prediction)."""
    factor = _factor(factor, "factor", "inflate_q")
    on = np.asarray(on, dtype=bool)
    if not on.any():
        return motion
    return ScaledNoise(motion, np.where(on, factor, 1.0))


def inflate_p(belief: Any, factor: float, where: ArrayLike) -> Any:
    """The belief with ``P -> factor P`` in the rows ``where``; other rows are the same
    arrays' values, bitwise. ``belief`` is a Gaussian or any NamedTuple with ``mean`` and
    ``cov`` fields."""
    factor = _factor(factor, "factor", "inflate_p")
    w = np.asarray(where, dtype=bool)
    if not w.any():
        return belief
    P = np.asarray(belief.cov)
    P = np.where(w[..., None, None], factor * P, P)  # a scaled symmetric P stays symmetric
    return belief._replace(cov=register(P))


@dataclass(frozen=True)
class QInflation:
    """Response: Q scaled by ``factor`` in every step's prediction while the detector is on
    (from the step after it turned on until the step after it turned off)."""

    factor: float = 10.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "factor", _factor(self.factor, "factor", "QInflation"))

    def motion(self, motion: Any, state: DetectorState | WindowState) -> Any:
        return inflate_q(motion, self.factor, state.on)

    def belief(self, belief: Any, state: DetectorState | WindowState) -> Any:
        return belief


@dataclass(frozen=True)
class PInflation:
    """Response: the filtered covariance scaled by ``factor`` once, at the step the detector
    turned on (``state.fired``), so the next update weighs the measurements more."""

    factor: float = 10.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "factor", _factor(self.factor, "factor", "PInflation"))

    def motion(self, motion: Any, state: DetectorState | WindowState) -> Any:
        return motion

    def belief(self, belief: Any, state: DetectorState | WindowState) -> Any:
        return inflate_p(belief, self.factor, state.fired)


# ------------------------------------------------------------------------------------------
# Runners


def _steps(dt: Any, K: int) -> list:
    """One time step per measurement: a scalar, or a sequence of K (each scalar or per row)."""
    if np.ndim(dt) == 0:
        return [dt] * K
    steps = list(dt)
    if len(steps) != K:
        raise ValueError(f"dt has {len(steps)} steps but there are {K} measurements; expected "
                         "a scalar or one step per measurement")
    return steps


class DetectorRun(NamedTuple):
    """What :func:`run_with_detector` returns: per step (leading axis K) the filter's
    estimate, the detector's statistic, on and fired, and the final belief and detector
    state."""

    estimate: Gaussian
    statistic: Array
    on: Bool
    fired: Bool
    belief: Any
    state: DetectorState | WindowState


def run_with_detector(
    f: Any,
    prior: Any,
    motion: Any,
    sensor: Any,
    measurements: Iterable[ArrayLike],
    dt: Any,
    detector: NISDetector | FadingMemoryDetector | WindowDetector,
    response: QInflation | PInflation | None = None,
) -> DetectorRun:
    """Run filter ``f`` over ``measurements`` (each ``(..., m)``, nan where missing) with a
    manoeuvre detector fed by its innovations and an optional response.

    Each step: ``motion_k = response.motion(motion, s)`` (s: the detector after the previous
    step), predict by ``dt``, update, ``s = detector.step(s, innovation)``, then
    ``belief = response.belief(belief, s)``. ``prior`` is a Gaussian (``f.init`` builds the
    filter's belief) or the filter's own belief type. Without a response it only monitors.
    """
    b = f.init(prior) if type(prior) is Gaussian else prior
    zs = list(measurements)
    if not zs:
        raise ValueError("run_with_detector: no measurements; expected at least one step")
    steps = _steps(dt, len(zs))
    s = None
    means, covs, stats_, ons, fireds = [], [], [], [], []
    for z, step in zip(zs, steps, strict=True):
        m_k = motion if (response is None or s is None) else response.motion(motion, s)
        b = f.predict(b, m_k, step)
        b, innov = f.update(b, z, sensor)
        if s is None:
            s = detector.init(np.shape(innov.nu)[:-1])
        s = detector.step(s, innov)
        if response is not None:
            b = response.belief(b, s)
        g = f.estimate(b)
        means.append(g.mean)
        covs.append(np.broadcast_to(g.cov, g.mean.shape + g.mean.shape[-1:]))
        stats_.append(s.statistic)
        ons.append(s.on)
        fireds.append(s.fired)
    est = Gaussian._make((np.stack(means), np.stack(covs)))
    return DetectorRun(est, np.stack(stats_), np.stack(ons), np.stack(fireds), b, s)


class VariableOrderRun(NamedTuple):
    """What :func:`run_variable_order` returns, leading axis K (time):

    ``estimate``: Gaussian ``(K, ..., 3d)`` in the CA order [positions, velocities,
    accelerations]; rows in CV mode have acceleration 0 with zero variance (the CV model has
    no acceleration state). ``mode``: True where the CA model is in use (after the step's
    switching). ``statistic``, ``on``: the detector's. ``switched_on`` / ``switched_off``:
    the steps at which a row went to CA (re-initialised) or back to CV.
    """

    estimate: Gaussian
    mode: Bool
    statistic: Array
    on: Bool
    switched_on: Bool
    switched_off: Bool


def _embed(mean: Array, cov: Array, d: int, accel_var: float | None) -> tuple[Array, Array]:
    """A CV [p, v] belief as a CA [p, v, a] one: acceleration 0 with variance ``accel_var``
    (0: the CV estimate as such), uncorrelated with position and velocity."""
    n = 2 * d
    m6 = np.zeros(mean.shape[:-1] + (3 * d,))
    m6[..., :n] = mean
    P6 = np.zeros(mean.shape[:-1] + (3 * d, 3 * d))
    P6[..., :n, :n] = cov
    if accel_var:
        idx = np.arange(n, 3 * d)
        P6[..., idx, idx] = accel_var
    return m6, P6


def run_variable_order(
    prior: Gaussian,
    sensor: SensorModel,
    z: ArrayLike,
    dt: Any,
    detector: NISDetector | FadingMemoryDetector | WindowDetector,
    q_cv: ArrayLike,
    q_ca: ArrayLike,
    s: int | None = None,
    accel_std: float = 30.0,
    end_window: int = 3,
    end_pfa: float = 0.05,
) -> VariableOrderRun:
    """The variable-order filter (the missing-measurements thesis, section 3-3-4-3; Bar-Shalom and
    Birmiwal 1982).

    ``z`` is ``(K, ..., m)`` (nan where missing), ``prior`` a CV Gaussian ``(..., 2d)`` one
    ``dt`` before the first measurement, ``sensor`` a linear sensor of the position
    (``Position(dim=d, ...)``) and ``detector`` fed by the innovations of the model in use.
    Every row starts on a CV Kalman filter (spectral density ``q_cv``).

    - **Switch up.** When the detector is on at step k in a CV row, the row switches to a CA
      Kalman filter (``q_ca``) re-initialised at ``k - s`` (``s = detector.memory`` unless
      given): its prior is the row's estimate at ``k - s - 1`` (the prior itself if
      ``k - s <= 0``), whose acceleration, if that estimate came from the CV model, is
      ``N(0, accel_std^2 I)``; the CA filter is then run over the stored measurements
      ``z(k - s), ..., z(k)``. The rows that fire at one step are re-filtered as one batch.
    - **Switch down** (a test on the estimated acceleration, as the thesis says): with
      ``delta_a(j) = a(j)^T P_aa(j)^-1 a(j)`` the acceleration's normalised square, a CA row
      returns to CV when ``sum`` of the last ``end_window`` values (re-filtered steps
      included) falls below the chi-square(``end_window d``) quantile at ``1 - end_pfa``
      (the acceleration is no longer significant; successive values are correlated, so the
      level is nominal). The CV filter restarts from the CA estimate's position and
      velocity, and the detector is reset for that row.

    The whole history is kept (K x rows x (3d)^2 floats for the covariances). Rows that never
    switch are, bitwise, the CV Kalman filter on its own (when some row has
    switched back from CA with a prior covariance shared by all rows, the covariances become
    one per row and the others agree to rounding instead).

    The arguments come in :func:`~trackkit.filters.run_filter`'s order (without a filter and a
    motion model: the KFs and their CV and CA models are its own).
    """
    if not (hasattr(prior, "mean") and hasattr(sensor, "dim_z")):
        raise TypeError("run_variable_order: expected (prior, sensor, z, dt, detector, ...); "
                        f"got a {type(prior).__name__} for prior and a "
                        f"{type(sensor).__name__} for sensor")
    z = np.asarray(z, dtype=float)
    if z.ndim < 2:
        raise ValueError(f"run_variable_order: z has shape {z.shape}; expected (K, ..., m)")
    K, batch, m = z.shape[0], z.shape[1:-1], z.shape[-1]
    mean0 = np.asarray(prior.mean, dtype=float)
    n = mean0.shape[-1]
    if n % 2 or n // 2 not in (1, 2, 3):
        raise ValueError(f"run_variable_order: prior has {n} state components; expected a "
                         "CV state [p, v] of 2, 4 or 6")
    d = n // 2
    if mean0.shape[:-1] not in (batch, ()):
        raise ValueError(f"run_variable_order: prior mean has batch shape {mean0.shape[:-1]} "
                         f"but z has {batch}; expected equal (or an unbatched prior)")
    s = detector.memory if s is None else _count(s, "s", "run_variable_order", lo=0)
    p = _count(end_window, "end_window", "run_variable_order")
    end_pfa = _probability(end_pfa, "end_pfa", "run_variable_order")
    accel_var = _accel_variance(accel_std)
    steps = _steps(dt, K)
    N = math.prod(batch)
    cov0 = np.asarray(prior.cov, dtype=float)
    if cov0.shape[:-2] not in (batch, ()) or cov0.shape[-2:] != (n, n):
        raise ValueError(f"run_variable_order: prior cov has shape {cov0.shape}; expected "
                         f"{batch + (n, n)} or ({n}, {n})")
    b_cv = Gaussian(mean0.reshape((N, n)) if mean0.ndim > 1 else mean0,
                    cov0.reshape((N, n, n)) if cov0.ndim > 2 else cov0)
    run = _VariableOrder(z.reshape(K, N, m), steps, b_cv, sensor, d, q_cv, q_ca, s, p,
                         accel_var, float(chdtri(p * d, end_pfa)))
    ds = detector.init((N,))
    for k in range(K):
        ds = run.step(k, detector, ds)
    return run.result(batch)


def _accel_variance(accel_std: float) -> float:
    """``accel_std^2``, checked."""
    try:
        a_std = float(accel_std)
    except (TypeError, ValueError):
        a_std = math.nan
    accel_var = a_std * a_std
    if not (0 < a_std and accel_var < math.inf):
        raise ValueError(f"run_variable_order: accel_std = {accel_std!r}; expected a finite "
                         "value > 0 (m/s^2)")
    return accel_var


class _VariableOrder:
    """:func:`run_variable_order` in progress over ``N`` rows: the CV filter on every row
    (so rows that never switch are the plain CV filter), the CA filter on the rows in CA
    mode, the last ``p`` acceleration tests and the history."""

    def __init__(self, zf: Array, steps: list, b_cv: Gaussian, sensor: Any, d: int,
                 q_cv: ArrayLike, q_ca: ArrayLike, s: int, p: int, accel_var: float,
                 thr_end: float) -> None:
        K, N = zf.shape[:2]
        n = 2 * d
        self.zf, self.steps, self.sensor, self.d, self.s = zf, steps, sensor, d, s
        self.accel_var, self.thr_end = accel_var, thr_end
        self.kf = KF()
        self.cv, self.ca = ConstantVelocity(dim=d, q=q_cv), ConstantAcceleration(dim=d, q=q_ca)
        self.b_cv = b_cv
        self.prior_mean = np.broadcast_to(b_cv.mean, (N, n))
        self.prior_cov = np.broadcast_to(b_cv.cov, (N, n, n))
        self.mode = np.zeros(N, bool)
        self.ca_mean, self.ca_cov = np.zeros((N, 3 * d)), np.zeros((N, 3 * d, 3 * d))
        self.delta_a = np.full((N, p), np.nan)  # the last p acceleration tests, oldest first
        self.hist_mean = np.empty((K, N, 3 * d))
        self.hist_cov = np.empty((K, N, 3 * d, 3 * d))
        self.hist_mode = np.zeros((K, N), bool)
        self.stat_hist, self.on_hist = np.empty((K, N)), np.zeros((K, N), bool)
        self.up_hist, self.down_hist = np.zeros((K, N), bool), np.zeros((K, N), bool)

    def accel_test(self, mu: Array, P: Array) -> Array:
        """``delta_a = a^T P_aa^-1 a``."""
        d = self.d
        return quadratic_form(P[..., 2 * d:, 2 * d:], mu[..., 2 * d:],
                              "CA acceleration covariance")

    def step(self, k: int, detector: Any, ds: Any) -> Any:
        """Step k: both filters, the detector on the innovations of the model in use, the
        switches up and down; returns the detector's state."""
        ds = detector.step(ds, self._filter(k))
        up = np.flatnonzero(ds.on & ~self.mode)
        if up.size:
            self._switch_up(k, up)
        # false while the window has a nan
        down = self.mode & (self.delta_a.sum(-1) < self.thr_end)
        if down.any():
            self._switch_down(k, down)
            ds = detector.reset(ds, down)
        self._record(k, ds)
        return ds

    def _filter(self, k: int) -> Innovation:
        """The CV filter on every row and the CA filter on the CA rows over step k: the
        innovations of the model each row uses."""
        kf, sensor, zf = self.kf, self.sensor, self.zf
        N, m = zf.shape[1:]
        self.b_cv = kf.predict(self.b_cv, self.cv, self.steps[k])
        self.b_cv, inn = kf.update(self.b_cv, zf[k], sensor)
        r = np.broadcast_to(inn.nu, (N, m))
        S = np.broadcast_to(inn.cov, (N, m, m))
        rows = np.flatnonzero(self.mode)
        if rows.size:
            g = kf.predict(Gaussian._make((self.ca_mean[rows], register(self.ca_cov[rows]))),
                           self.ca, self.steps[k])
            g, inn_ca = kf.update(g, zf[k, rows], sensor)
            self.ca_mean[rows], self.ca_cov[rows] = g.mean, g.cov
            r, S = r.copy(), S.copy()
            r[rows], S[rows] = inn_ca.nu, inn_ca.cov
            self.delta_a[rows] = np.concatenate(
                [self.delta_a[rows, 1:], self.accel_test(g.mean, g.cov)[:, None]], -1)
        return Innovation(r, S)

    def _switch_up(self, k: int, up: Array) -> None:
        """Rows ``up`` to CA, re-initialised at ``k - s`` and re-filtered over the stored
        measurements ``z(k - s) .. z(k)`` as one batch."""
        d, p = self.d, self.delta_a.shape[1]
        j0 = max(k - self.s, 0)
        if j0 == 0:
            m0, P0 = _embed(self.prior_mean[up], self.prior_cov[up], d, self.accel_var)
        else:
            m0, P0 = self.hist_mean[j0 - 1, up].copy(), self.hist_cov[j0 - 1, up].copy()
            was_cv = ~self.hist_mode[j0 - 1, up]
            if was_cv.any():  # the CV estimate gets the acceleration prior
                ia = np.arange(2 * d, 3 * d)
                P0[np.ix_(np.flatnonzero(was_cv), ia, ia)] = self.accel_var * np.eye(d)
        g = Gaussian._make((m0, register(P0)))
        tests = []
        for j in range(j0, k + 1):
            g = self.kf.predict(g, self.ca, self.steps[j])
            g, _ = self.kf.update(g, self.zf[j, up], self.sensor)
            tests.append(self.accel_test(g.mean, g.cov))
        self.ca_mean[up], self.ca_cov[up] = g.mean, g.cov
        last = np.stack(tests[-p:], -1)
        self.delta_a[up] = np.concatenate([np.full((up.size, p - last.shape[-1]), np.nan),
                                           last], -1)
        self.mode[up] = True
        self.up_hist[k, up] = True

    def _switch_down(self, k: int, down: Array) -> None:
        """Rows ``down`` back to CV, restarted from the CA estimate's position and
        velocity."""
        N, n = self.mode.size, 2 * self.d
        rows = np.flatnonzero(down)
        cv_mean = np.array(np.broadcast_to(self.b_cv.mean, (N, n)))
        cv_cov = np.array(np.broadcast_to(self.b_cv.cov, (N, n, n)))
        cv_mean[rows] = self.ca_mean[rows, :n]
        cv_cov[rows] = self.ca_cov[rows, :n, :n]
        self.b_cv = Gaussian._make((cv_mean, register(cv_cov)))
        self.mode[rows] = False
        self.delta_a[rows] = np.nan
        self.down_hist[k] = down

    def _record(self, k: int, ds: Any) -> None:
        """Step k's estimate (CV rows embedded in the CA state), mode and detector."""
        N, n = self.mode.size, 2 * self.d
        m6, P6 = _embed(np.broadcast_to(self.b_cv.mean, (N, n)),
                        np.broadcast_to(self.b_cv.cov, (N, n, n)), self.d, None)
        self.hist_mean[k] = np.where(self.mode[:, None], self.ca_mean, m6)
        self.hist_cov[k] = np.where(self.mode[:, None, None], self.ca_cov, P6)
        self.hist_mode[k] = self.mode
        self.stat_hist[k], self.on_hist[k] = ds.statistic, ds.on

    def result(self, batch: tuple[int, ...]) -> VariableOrderRun:
        """The history, rows back to ``batch``."""
        K, d = self.hist_mode.shape[0], self.d
        shape = (K, *batch)
        est = Gaussian._make((self.hist_mean.reshape(shape + (3 * d,)),
                              self.hist_cov.reshape(shape + (3 * d, 3 * d))))
        return VariableOrderRun(est, self.hist_mode.reshape(shape),
                                self.stat_hist.reshape(shape), self.on_hist.reshape(shape),
                                self.up_hist.reshape(shape), self.down_hist.reshape(shape))
