r"""Fuzzy-adaptive Kalman filtering by innovation covariance matching (Naseri Solhdar,
chapter 3): the Mamdani fuzzy system and the OFKF / OFEKF wrappers around the KF, EKF and UKF.

**Covariance matching** (thesis eqs 3-3 to 3-6). With the innovation
:math:`\mathbf{r}_k = \mathbf{z}_k - h(\mathbf{x}^-_k)` and its theoretical covariance
:math:`S_k = H P^-_k H^\top + R_k`, the innovations' window covariance (N = 25;
:math:`C_k = 0` until N innovations) and the degree of matching are

.. math::

    C_k = \frac1N \sum_{i=k-N+1}^{k} \mathbf{r}_i \mathbf{r}_i^\top, \qquad
    \mathrm{DOM}_k = S_k - C_k

DOM > 0: the innovations are smaller than the filter thinks, so decrease R (or Q); DOM < 0:
increase it.

**Mamdani fuzzy system** (eq 3-10): singleton fuzzifier, product inference, centre-average
defuzzifier, one input and five Gaussian sets:

.. math::

    y(x) = \frac{\sum_l \bar y_l\, \mu_l(x)}{\sum_l \mu_l(x)}, \qquad
    \mu_l(x) = \exp\Bigl(-\Bigl(\frac{x - c_l}{s_l}\Bigr)^2\Bigr)

with the rules NM -> IL, NS -> I, ZE -> M, PS -> D, PM -> DL (IF DOM is Negative Medium THEN
the adjustment is Increase Large, ...). The parameters are one flat vector
``[c_1..c_5, s_1..s_5, ybar_1..ybar_5]`` in rule order. The output sets' widths do not enter
a centre-average defuzzifier, so they are not parameters.

**Adaptation** (eqs 3-7 to 3-9, 3-21), per diagonal entry, from step k to k + 1, of R
(``adapt="R"``) or Q (``adapt="Q"``):

.. math::

    R_{k+1}(i,i) &= R_k(i,i) + \mathrm{Adj}R_k(i), \qquad
    \mathrm{Adj}R_k(i) = \mathrm{FIS}\bigl(\mathrm{DOM}_k(i,i)\bigr) \\
    Q_{k+1}(j,j) &= Q_k(j,j) + \mathrm{Adj}Q_k(j), \qquad \mathrm{Adj}Q_k(j) = \mathrm{FIS}(d_j)

where for Q the input d_j is DOM(i,i) for the pair ``q_inputs[j] = (i, i)`` and DOM(i,l)^2 for
an off-diagonal pair (the thesis's eq 3-21, DOM(3,3) := DOM(1,2)^2, which gives a 3 x 3 Q a
third input from a 2 x 2 DOM).

Choices the thesis leaves open (Naseri Solhdar), documented:

- ``normalise`` sets the units the fuzzy system works in (the thesis tunes raw DOM and
  adjustments for one problem at a time):

  - ``"current"`` (default):
    :math:`\mathrm{Adj}R(i) = R_k(i,i)\, \mathrm{FIS}\bigl(\mathrm{DOM}_k(i,i) /
    S_k(i,i)\bigr)`. The input is the relative mismatch ``1 - C/S`` (at most 1) and the
    adjustment a fraction of the current R, so the law is scale-free: one shared system serves
    channels of different units (seconds^2 and rad^2), one set of bounds serves every problem,
    and R can travel over orders of magnitude (the thesis's chapter-4 R0 is 100 times the true
    noise) without overshooting. For Q: input ``DOM(i,l)/S(i,l)`` with S's diagonal (squared for
    an off-diagonal pair: ``DOM(i,l)^2 / (S(i,i) S(l,l))``), output times ``Q_k(j,j)``.
  - ``"initial"``: the same with the initial R0 (and Q0) in place of S_k and R_k (Q_k).
  - ``"none"``: the literal additive law on raw DOM.

- ``floor`` and ``ceiling`` (not in the thesis): ``floor R0(i,i) <= R(i,i) <= ceiling
  R0(i,i)`` and likewise for Q with Q0 (defaults 1e-3 and 1e6), which keep them positive and
  finite whatever a candidate system does during tuning.
- ``warmup="wait"`` (default): no adaptation until the window is full (with C = 0 the DOM
  equals S and would only ever push R down); ``"adapt"`` adapts from the first step.
- Off-diagonal entries of R and Q keep their initial values.

Memory lives in :class:`FuzzyBelief`; the parameters may carry batch axes (``(..., 15)``,
broadcast against the belief's batch), so a whole optimiser population is filtered in one
pass.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian, Innovation
from trackkit.filters.adaptive import push_innovation, window_covariance
from trackkit.filters.base import Filter, check_belief, missing_rows
from trackkit.filters.kalman import EKF
from trackkit.models.noise import with_noise
from trackkit.models.protocols import MotionModel, SensorModel

__all__ = [
    "INPUT_SETS",
    "OUTPUT_SETS",
    "N_PARAMS",
    "DEFAULT_PARAMS",
    "PARAM_BOUNDS",
    "fis",
    "matching_covariance",
    "dom_cost",
    "FuzzyBelief",
    "FuzzyAdaptive",
]

Array = NDArray[np.float64]

#: The input (DOM) sets in rule order: Negative Medium, Negative Small, Zero, Positive Small,
#: Positive Medium.
INPUT_SETS = ("NM", "NS", "ZE", "PS", "PM")
#: The output (adjustment) sets in rule order: Increase Large, Increase, Maintain, Decrease,
#: Decrease Large.
OUTPUT_SETS = ("IL", "I", "M", "D", "DL")
#: The length of the flat parameter vector ``[c_1..c_5, s_1..s_5, ybar_1..ybar_5]``.
N_PARAMS = 15

#: An untuned, symmetric system (normalised units): input centres -2..2, widths 0.6, output
#: centres +0.2 .. -0.2 (a DOM of minus twice R0 adds a fifth of R0 per step).
DEFAULT_PARAMS = np.array([-2.0, -1.0, 0.0, 1.0, 2.0,
                           0.6, 0.6, 0.6, 0.6, 0.6,
                           0.2, 0.05, 0.0, -0.05, -0.2])
DEFAULT_PARAMS.flags.writeable = False

#: Search box of the tuners (normalised units), one disjoint interval per centre so every
#: candidate keeps the order NM < NS < ZE < PS < PM and IL > I > M > D > DL that the rule
#: names promise. The output centres allow at most +-50% of the reference per step: with
#: ``normalise="current"`` wider steps let a system tuned on one realisation oscillate
#: (R halved and tripled in turn on window noise) and diverge on others, as it did on 16 of
#: 100 runs of uw-ch3-r when DL could reach -100% and IL +200%.
PARAM_BOUNDS = np.array(
    [[-8.0, -1.5], [-1.5, -0.2], [-0.2, 0.2], [0.2, 1.5], [1.5, 8.0]]  # input centres
    + [[0.05, 4.0]] * 5  # input widths
    + [[0.05, 0.5], [0.0, 0.1], [-0.01, 0.01], [-0.1, 0.0], [-0.5, -0.05]]  # output centres
)
PARAM_BOUNDS.flags.writeable = False


def fis(params: ArrayLike, x: ArrayLike) -> Array:
    """The Mamdani system's output y(x) (module docstring), batched.

    ``params (..., 15)``: ``[centres, widths, output centres]`` in rule order, the centres
    increasing (checked by :class:`FuzzyAdaptive`, not here on the hot path); its batch axes
    broadcast against ``x (...)``.

    The input is saturated to the universe of discourse, ``[c_1, c_5]`` (the outermost
    centres), as fuzzy controllers do: with Gaussian sets of different widths, an input far
    outside would otherwise be claimed by the widest set whatever its side (a far negative
    DOM would "decrease large"). The memberships are scaled by their largest value before the
    ratio (which leaves it unchanged), so the output never becomes 0/0.
    """
    p = np.asarray(params, dtype=float)
    if p.ndim < 1 or p.shape[-1] != N_PARAMS:
        raise ValueError(f"fuzzy parameters have shape {p.shape}; expected (..., {N_PARAMS}) "
                         "= [5 input centres, 5 widths, 5 output centres]")
    c, s, ybar = p[..., 0:5], p[..., 5:10], p[..., 10:15]
    if not np.all(s > 0):
        raise ValueError("fuzzy parameters: the widths (entries 5-9) must be > 0")
    x = np.clip(np.asarray(x, dtype=float), c[..., 0], c[..., 4])
    e = ((x[..., None] - c) / s) ** 2
    mu = np.exp(-(e - e.min(-1, keepdims=True)))
    return (mu * ybar).sum(-1) / mu.sum(-1)


def matching_covariance(residuals: Array, count: ArrayLike) -> Array:
    """Eq 3-5, ``C_k = (1/N) sum_{i=k-N+1}^{k} r_i r_i^T`` from the ring buffer
    ``residuals (..., N, m)``; zero where fewer than N innovations have been seen."""
    N = residuals.shape[-2]
    full = np.asarray(count) >= N
    return np.where(full[..., None, None], window_covariance(residuals, count), 0.0)


def dom_cost(dom_sq_sum: ArrayLike, steps: int, alpha: float = 1000.0) -> Array:
    """The tuning cost and J4 metric: ``alpha sum_i sqrt((1/K) sum_k DOM_k(i,i)^2)`` from the
    running sums ``dom_sq_sum (..., m)`` of ``DOM_k(i,i)^2`` over K = ``steps`` steps (the
    thesis's ``1000 (sqrt(sum(DOM(1,1)^2)/500) + sqrt(sum(DOM(2,2)^2)/500))``)."""
    return alpha * np.sqrt(np.asarray(dom_sq_sum) / steps).sum(-1)


class FuzzyBelief(NamedTuple):
    """Belief of the fuzzy-adaptive filters: a Gaussian plus the adaptation memory.

    ``R (..., m, m)`` the current measurement noise (``(..., 0, 0)`` until the first update
    starts it from ``sensor.noise``), ``Q (..., n, n)`` the current process noise
    (``(..., 0, 0)`` until the first prediction starts it from ``motion.noise``),
    ``Q0 (..., n)`` the diagonal of the initial Q (the reference of ``floor``, ``ceiling``
    and ``normalise="initial"``), ``residuals (..., N, m)`` the innovation ring buffer
    (slot ``i mod N`` holds the i-th), ``count (...)`` innovations seen, and the last step's
    ``S`` and ``C`` (``(..., m, m)``) for the logs (``DOM = S - C``).
    """

    mean: Array
    cov: Array
    R: Array
    Q: Array
    Q0: Array
    residuals: Array
    count: NDArray[np.int64]
    S: Array
    C: Array

    def at(self, index) -> FuzzyBelief:
        """The belief at a batch index (every field indexed alike)."""
        return FuzzyBelief(*(np.asarray(a)[index] for a in self))

    @property
    def dom(self) -> Array:
        """The last step's degree of matching ``S - C``."""
        return self.S - self.C


def _diag(M: Array) -> Array:
    return np.diagonal(M, axis1=-2, axis2=-1)


def _with_diag(M: Array, d: Array) -> Array:
    out = np.array(np.broadcast_to(M, d.shape[:-1] + M.shape[-2:]))
    i = np.arange(d.shape[-1])
    out[..., i, i] = d
    return out


class FuzzyAdaptive(Filter):
    """A KF, EKF or UKF whose R (``adapt="R"``) or Q (``adapt="Q"``) is adapted on-line by a
    Mamdani fuzzy system driving the degree of matching to zero: the thesis's OFKF / OFEKF.

    ``FuzzyAdaptive(EKF(), params)`` is the OFEKF; ``params`` ``(15,)`` or batched
    ``(..., 15)`` (see :func:`fis`), by default :data:`DEFAULT_PARAMS` (untuned). Tune them
    with ``trackkit.experiments.tuning``. The filter's name is "OF" + the base filter's name.
    See the module docstring for the equations and the choices (``normalise``, ``floor``,
    ``warmup``, ``q_inputs``). The returned innovation is the base filter's.
    """

    def __init__(self, base: Filter | None = None, params: ArrayLike = DEFAULT_PARAMS,
                 adapt: str = "R", window: int = 25, normalise: str = "current",
                 floor: float = 1e-3, ceiling: float = 1e6, warmup: str = "wait",
                 q_inputs: tuple[tuple[int, int], ...] | None = None) -> None:
        base = EKF() if base is None else base
        if not hasattr(base, "update") or isinstance(base, FuzzyAdaptive):
            raise ValueError(f"FuzzyAdaptive base = {base!r}; expected a KF, EKF or UKF")
        p = np.array(params, dtype=float)
        if p.shape[-1:] != (N_PARAMS,) or not np.all(np.isfinite(p)):
            raise ValueError(f"FuzzyAdaptive params has shape {p.shape}; expected finite "
                             f"(..., {N_PARAMS})")
        if np.any(p[..., 5:10] <= 0):
            raise ValueError("FuzzyAdaptive params: the widths (entries 5-9) must be > 0")
        if np.any(np.diff(p[..., 0:5], axis=-1) < 0):
            raise ValueError("FuzzyAdaptive params: the input centres (entries 0-4) must be in "
                             "increasing order NM <= NS <= ZE <= PS <= PM (the rules and the "
                             "saturation to [c_1, c_5] rely on it)")
        if adapt not in ("R", "Q"):
            raise ValueError(f"FuzzyAdaptive adapt = {adapt!r}; expected 'R' or 'Q'")
        if not (isinstance(window, int | np.integer) and window >= 1):
            raise ValueError(f"FuzzyAdaptive window = {window!r}; expected an integer >= 1")
        if not (np.isfinite(floor) and 0 < floor):
            raise ValueError(f"FuzzyAdaptive floor = {floor!r}; expected a value > 0")
        if not (np.isfinite(ceiling) and ceiling > floor):
            raise ValueError(f"FuzzyAdaptive ceiling = {ceiling!r}; expected a finite value "
                             f"> floor = {floor}")
        if warmup not in ("wait", "adapt"):
            raise ValueError(f"FuzzyAdaptive warmup = {warmup!r}; expected 'wait' or 'adapt'")
        if q_inputs is not None and any(len(pair) != 2 or min(pair) < 0 for pair in q_inputs):
            raise ValueError(f"FuzzyAdaptive q_inputs = {q_inputs!r}; expected pairs (i, l) of "
                             "non-negative DOM indices")
        p.flags.writeable = False
        self.base = base
        self.params = p
        self.adapt = adapt
        self.window = int(window)
        if normalise not in ("current", "initial", "none"):
            raise ValueError(f"FuzzyAdaptive normalise = {normalise!r}; expected 'current', "
                             "'initial' or 'none'")
        self.normalise = normalise
        self.floor = float(floor)
        self.ceiling = float(ceiling)
        self.warmup = warmup
        self.q_inputs = None if q_inputs is None else tuple(
            (int(i), int(j)) for i, j in q_inputs)
        self.name = "OF" + getattr(base, "name", type(base).__name__)

    def with_params(self, params: ArrayLike) -> FuzzyAdaptive:
        """The same filter with other fuzzy parameters (e.g. a population, ``(P, 15)``)."""
        return FuzzyAdaptive(self.base, params, self.adapt, self.window, self.normalise,
                             self.floor, self.ceiling, self.warmup, self.q_inputs)

    # --- belief ------------------------------------------------------------------------

    def init(self, g: Gaussian) -> FuzzyBelief:
        """Initial belief from a Gaussian prior; R, Q and the window start empty."""
        if isinstance(g, FuzzyBelief):
            return g
        x, P = check_belief(g, None, f"{self.name}.init prior")
        batch = x.shape[:-1]
        empty = np.zeros(batch + (0, 0))
        return FuzzyBelief(x, P, empty, empty, np.zeros(batch + (0,)),
                           np.zeros(batch + (self.window, 0)),
                           np.zeros(batch, np.int64), empty, empty)

    def estimate(self, belief: FuzzyBelief) -> Gaussian:
        return Gaussian._make((belief.mean, belief.cov))

    # --- predict and update ----------------------------------------------------------------

    def predict(self, belief: FuzzyBelief, motion: MotionModel, dt: ArrayLike) -> FuzzyBelief:
        """The base filter's prediction with the current Q."""
        b = self.init(belief)
        Q, Q0 = b.Q, b.Q0
        if self.adapt == "Q":
            if Q.shape[-1] == 0:
                Qm = np.asarray(motion.noise(b.mean, dt), dtype=float)
                Q = np.array(np.broadcast_to(Qm, b.mean.shape[:-1] + Qm.shape[-2:]))
                Q0 = _diag(Q).copy()
            motion = with_noise(motion, Q)
        g = self.base.predict(Gaussian._make((b.mean, b.cov)), motion, dt)
        return b._replace(mean=g.mean, cov=g.cov, Q=Q, Q0=Q0)

    def update(self, belief: FuzzyBelief, z: ArrayLike,
               sensor: SensorModel) -> tuple[FuzzyBelief, Innovation]:
        b = self.init(belief)
        m = sensor.dim_z
        R0 = np.asarray(sensor.noise, dtype=float)
        R = b.R if b.R.shape[-1] else R0
        post, innov = self.base.update(Gaussian._make((b.mean, b.cov)), z,
                                       with_noise(sensor, R))
        batch = post.mean.shape[:-1]
        miss = missing_rows(np.asarray(z, dtype=float))
        keep = np.ones(batch, bool) if miss is None else ~np.broadcast_to(miss, batch)

        buf, count = push_innovation(b.residuals, b.count, innov.nu, keep, self.window,
                                     batch, f"{self.name}.update")
        S = np.broadcast_to(innov.cov, batch + (m, m))
        C = matching_covariance(buf, count)
        dom = S - C
        active = keep if self.warmup == "adapt" else keep & (count >= self.window)
        params = self.params[..., None, :]  # one system shared by the channels

        R_out = np.broadcast_to(R, batch + (m, m))
        Q_out = b.Q
        if self.adapt == "R":
            ref_in, ref_out = {
                "current": (_diag(S), _diag(R_out)), "initial": (_diag(R0), _diag(R0)),
                "none": (1.0, 1.0)}[self.normalise]
            d = _diag(R_out) + ref_out * fis(params, _diag(dom) / ref_in)
            d = np.clip(d, self.floor * _diag(R0), self.ceiling * _diag(R0))
            R_out = np.where(active[..., None, None], _with_diag(R_out, d), R_out)
        elif Q_out.shape[-1]:
            Q_out = self._adapt_q(Q_out, b.Q0, dom, S, R0, active, batch)
        out = FuzzyBelief(post.mean, post.cov, np.asarray(R_out, dtype=float), Q_out, b.Q0,
                          buf, count, np.asarray(S, dtype=float), C)
        return out, innov

    def _adapt_q(self, Q: Array, Q0: Array, dom: Array, S: Array, R0: Array, active: Array,
                 batch: tuple[int, ...]) -> Array:
        """``Q(j,j) += ref_j FIS(d_j / s_j)`` with d_j from the pairs of ``q_inputs``."""
        n, m = Q.shape[-1], dom.shape[-1]
        pairs = self.q_inputs or tuple((j, j) for j in range(n))
        if len(pairs) != n or any(not (0 <= i < m and 0 <= k < m) for i, k in pairs):
            raise ValueError(f"{self.name}: q_inputs = {pairs}; expected {n} pairs (i, l) "
                             f"of DOM entries with 0 <= i, l < {m}")
        ii = np.array([i for i, _ in pairs])
        kk = np.array([k for _, k in pairs])
        d = dom[..., ii, kk]
        off = ii != kk
        d = np.where(off, d * d, d)  # eq 3-21: DOM(i,l)^2 for an off-diagonal pair
        Q = np.broadcast_to(Q, batch + (n, n))
        if self.normalise == "none":
            ref_in, ref_out = 1.0, 1.0
        else:
            scale = _diag(S) if self.normalise == "current" else _diag(R0)
            ref_in = np.sqrt(scale[..., ii] * scale[..., kk])
            ref_in = np.where(off, ref_in * ref_in, ref_in)
            ref_out = _diag(Q) if self.normalise == "current" else Q0
        new = _diag(Q) + ref_out * fis(self.params[..., None, :], d / ref_in)
        new = np.clip(new, self.floor * Q0, self.ceiling * Q0)
        return np.where(active[..., None, None], _with_diag(Q, new), Q)
