r"""Adaptive filters of Hashemi and Alfi (2019) (Doppler-bearing tracking):
the modified-covariance EKF, its second-order Jacobian term, the innovation-based R and the
new Q adaptation (the proposed AMCEKF), and a Sage-Husa adaptive EKF as the paper's
baseline [16].

Notation follows the paper: prediction :math:`\mathbf{x}^- = \mathbf{x}(t|t-1)`,
:math:`P^- = P(t|t-1)`; update :math:`\mathbf{x}^+ = \mathbf{x}(t|t)`, :math:`P^+ = P(t|t)`;
innovation and its covariance (the bearing wrapped to (-pi, pi] by ``sensor.residual``)

.. math::

    \nu = \mathbf{z} - h(\mathbf{x}^-), \qquad S = H P^- H^\top + R

Equation numbers are the paper's.

Memory lives in the belief: :class:`AdaptiveBelief` for the AMCEKF (R and Q scale factors and
the innovation window), :class:`SageHusaBelief` for the AEKF (the estimated R and Q). Build it
with ``f.init(prior)``; a plain :class:`~trackkit.belief.Gaussian` given to ``predict`` or
``update`` is initialised on the spot. Every kernel works on any leading batch shape; rows with
a missing measurement (nan in z) keep the prediction and their memory unchanged.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import (
    Filter,
    check_belief,
    check_dt,
    check_measurement,
    keep_prior_where_missing,
    missing_rows,
    output,
)
from trackkit.filters.kalman import (
    Linearised,
    condition,
    dim_x_of,
    jacobian_predict,
    kalman_gain,
    linearize,
    sandwich,
)
from trackkit.linalg import mm, mmT, quadratic_form, solve_psd, symmetrize
from trackkit.models.protocols import MotionModel, SensorModel

__all__ = [
    "MCEKF",
    "AMCEKF",
    "AEKF",
    "AdaptiveBelief",
    "SageHusaBelief",
    "second_order_jacobian",
    "window_covariance",
    "push_innovation",
    "r_factor",
    "q_factor",
    "sage_husa_weight",
    "Q_FORMS",
]

Array = NDArray[np.float64]

#: the forms of the Q factor lambda(t) of eq. 21 (see :func:`q_factor`)
Q_FORMS = ("normalised", "mean-square", "inverse-mean-square", "normalised-n")


# --------------------------------------------------------------------------------------------
# Beliefs
# --------------------------------------------------------------------------------------------


class AdaptiveBelief(NamedTuple):
    """Belief of the AMCEKF: a Gaussian plus the adaptation memory.

    ``mean (..., n)``, ``cov (..., n, n)``; ``r_scale``, ``q_scale`` ``(...)``: the current
    ``R_t = r_scale R0`` and ``Q_t = q_scale Q0(x, dt)`` with R0 = ``sensor.noise`` and
    Q0 = ``motion.noise``, so eqs. 19 and 21 (``R(t+1) = alpha R(t)``, ``Q(t+1) = lambda Q(t)``)
    are ``r_scale <- alpha r_scale`` and ``q_scale <- lambda q_scale``; ``residuals (..., N, m)``
    a ring buffer of the last N innovations (slot ``i mod N`` holds the i-th, counting from 0;
    shape ``(..., N, 0)`` until the first update tells the measurement size m); ``count (...)``
    how many innovations each row has seen.
    """

    mean: Array
    cov: Array
    r_scale: Array
    q_scale: Array
    residuals: Array
    count: NDArray[np.int64]

    def at(self, index) -> AdaptiveBelief:
        """The belief at a batch index (every field indexed alike)."""
        return AdaptiveBelief(*(np.asarray(a)[index] for a in self))


class SageHusaBelief(NamedTuple):
    """Belief of the Sage-Husa AEKF: a Gaussian plus the noise estimates.

    ``R (..., m, m)`` the current measurement-noise estimate (shape ``(..., 0, 0)`` until the
    first update, which starts it from ``sensor.noise``); ``Q (..., n, n)`` the process-noise
    estimate when Q is adapted (``(..., 0, 0)`` until the first prediction, which starts it
    from ``motion.noise``); ``count (...)`` the number of updates each row has had (the k of
    the fading-memory weight ``d_k``).
    """

    mean: Array
    cov: Array
    R: Array
    Q: Array
    count: NDArray[np.int64]

    def at(self, index) -> SageHusaBelief:
        """The belief at a batch index (every field indexed alike)."""
        return SageHusaBelief(*(np.asarray(a)[index] for a in self))


# --------------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------------


def second_order_jacobian(sensor: SensorModel, x: Array) -> Array:
    r"""The paper's eq. 12 "Jacobian with a second-order term", read element-wise:

    .. math::

        H_{ij} = \frac{\partial h_i}{\partial x_j}
            + \frac12 \frac{\partial^2 h_i}{\partial x_j^2}

    i.e. ``J_h(x) + 1/2 diag(Hess h_i(x))`` row by row, which keeps the m x n shape. The paper
    writes ``H = dh/dx + d2h/(2 dx^2)`` without saying how the second derivative becomes an m x
    n matrix; this is the most plausible reading. It is NOT the second-order EKF of Athans,
    Wishner and Bertolini (``EKF(order=2)``), which corrects the predicted measurement and S
    with the full Hessians. Note that the added term is not dimensionally a derivative: it is
    the paper's heuristic. For the DBT sensor at a few km it is about 1e-4 of the Jacobian's
    entries, so its effect on the estimates is negligible there.
    """
    return _with_half_hessian(np.asarray(sensor.jacobian(x)), sensor, x)


def _with_half_hessian(J: Array, sensor: SensorModel, x: Array) -> Array:
    return J + 0.5 * np.diagonal(np.asarray(sensor.hessian(x)), axis1=-2, axis2=-1)


def _jacobian(sensor: SensorModel, x: Array, second_order: bool) -> Array:
    J = np.asarray(sensor.jacobian(x))
    return _with_half_hessian(J, sensor, x) if second_order else J


def _linearize(sensor: SensorModel, x: Array, second_order: bool) -> tuple[Array, Array]:
    """``(h(x), H)``: the sensor's fused ``linearize``, with the paper's half Hessian added
    when ``second_order``."""
    zhat, J = linearize(sensor, x)
    return zhat, _with_half_hessian(J, sensor, x) if second_order else J


def _mc_update(x: Array, P: Array, r: Array, H: Array, R: Array, sensor: SensorModel,
               second_order: bool) -> tuple[Array, Array, Array, Array, Array]:
    """MC-EKF update (eqs. 10-11, with eq. 12-13's H when ``second_order``).

    ``K = P- H^T (H P- H^T + R)^{-1}``, ``delta = K r``, ``x+ = x- + delta``; then
    ``H+ = J_h(x+)``, ``K+ = P- H+^T (H+ P- H+^T + R)^{-1}`` and the Joseph form
    ``P+ = (I - K+ H+) P- (I - K+ H+)^T + K+ R K+^T``. Returns ``(x+, P+, S, K, delta)``.
    """
    _, S, K = kalman_gain(P, H, R)
    delta = K @ r if (r.ndim == 1 and K.ndim == 2) else mm(K, r[..., None])[..., 0]
    x_new = x + delta
    H_plus = _jacobian(sensor, x_new, second_order)
    _, P_new, _ = condition(x_new, P, np.zeros_like(r), H_plus, R)  # Joseph with K+, H+
    return x_new, P_new, S, K, delta


def window_covariance(residuals: Array, count: ArrayLike) -> Array:
    r"""Eq. 15, from the ring buffer:

    .. math::

        C_r(t) = \frac1N \sum_{i=t-N+1}^{t} \mathbf{r}_i \mathbf{r}_i^\top

    Before N innovations have been seen, the average is over the k = count available ones,
    :math:`C_r = \frac1k \sum_{i=1}^{k} \mathbf{r}_i \mathbf{r}_i^\top` (empty slots hold
    zeros); ``count = 0`` gives 0.
    """
    N = residuals.shape[-2]
    k = np.maximum(np.minimum(np.asarray(count), N), 1)
    # entry by entry over the upper triangle (m is small): each a contiguous reduction over
    # the window, much faster than einsum or a broadcast outer product on the batch
    m = residuals.shape[-1]
    cols = np.moveaxis(residuals, -1, 0)  # (m, ..., N)
    C = np.empty(residuals.shape[:-2] + (m, m))
    for a in range(m):
        for b in range(a, m):
            C[..., a, b] = C[..., b, a] = (cols[a] * cols[b]).sum(-1)
    return C / k[..., None, None]


def push_innovation(residuals: Array, count: ArrayLike, r: Array, keep: Array, window: int,
                    batch: tuple[int, ...], where: str) -> tuple[Array, NDArray[np.int64]]:
    """Put innovation ``r (..., m)`` into slot ``count mod N`` of the ring buffer
    ``residuals (..., N, m)`` for the rows in ``keep`` and count it; the buffer and count are
    broadcast to the output ``batch`` (z may carry more batch axes than the belief). An empty
    buffer (``(..., N, 0)``, before the first update) is created with m components."""
    m = r.shape[-1]
    buf = residuals
    if buf.shape[-1] == 0:
        buf = np.zeros(batch + (window, m))
    elif buf.shape[-1] != m:
        raise ValueError(
            f"{where}: the innovation window holds {buf.shape[-1]}-component residuals but "
            f"the sensor measures {m}; expected one sensor per belief"
        )
    buf = np.array(np.broadcast_to(buf, batch + buf.shape[-2:]))  # a new array: no aliasing
    count = np.broadcast_to(count, batch)
    keep = np.broadcast_to(keep, batch)
    flat = buf.reshape(-1, window, m)
    rows = np.flatnonzero(keep)
    slots = (count.reshape(-1) % window)[rows]
    flat[rows, slots] = np.broadcast_to(r, batch + (m,)).reshape(-1, m)[rows]
    return buf, np.asarray(count + keep, np.int64)


def r_factor(residuals: Array, count: ArrayLike, S: Array) -> Array:
    r"""Eq. 18, the innovation-covariance matching ratio (eq. 17), with :math:`C_r` of eq. 15
    (:func:`window_covariance`):

    .. math::

        \alpha(t) = \frac{\operatorname{tr} C_r(t)}{\operatorname{tr} S(t)}
    """
    N = residuals.shape[-2]
    k = np.maximum(np.minimum(np.asarray(count), N), 1)
    tr_C = (residuals * residuals).sum((-2, -1)) / k
    return tr_C / np.trace(S, axis1=-2, axis2=-1)


def _mean_square(delta: Array, inverse: bool) -> Array:
    """``(1/n) sum_i delta_i^2``, or its reciprocal."""
    ms = (delta * delta).mean(-1)
    if not inverse:
        return ms
    with np.errstate(divide="ignore"):
        return 1.0 / ms


def q_factor(delta: Array, P: Array, form: str = "normalised", K: Array | None = None,
             H: Array | None = None) -> Array:
    r"""The Q factor lambda(t) of eq. 21 from ``delta = x+ - x-`` (eq. 20).

    - ``"mean-square"``: ``lambda = (1/n) sum_i delta_i^2``, the most literal reading of the
      garbled eq. 21. It has units (m^2, (m/s)^2, Hz^2 mixed), so ``Q <- lambda Q``
      explodes or collapses geometrically unless delta happens to be of order 1.
    - ``"inverse-mean-square"``: ``lambda = 1 / ((1/n) sum_i delta_i^2)``, the other reading
      allowed by the extra "1" token in the printed equation; as unit-laden as the first.
    - ``"normalised"`` (default): ``lambda = delta^T P-^{-1} delta / tr(K H)``. Dimensionless,
      and equal to 1 on average for a consistent filter: :math:`\delta = K \mathbf{r}` with
      :math:`E[\mathbf{r} \mathbf{r}^\top] = S` gives (at most m, not n)

      .. math::

          E[\delta^\top (P^-)^{-1} \delta] = \operatorname{tr}\bigl((P^-)^{-1} K S K^\top\bigr)
              = \operatorname{tr}(S^{-1} H P^- H^\top) = \operatorname{tr}(K H)
              = m - \operatorname{tr}(S^{-1} R)

      So Q grows when the estimate moves more than P- predicts and shrinks when it moves
      less. Needs the state-update gain K and Jacobian H.
    - ``"normalised-n"``: ``lambda = (1/n) delta^T P-^{-1} delta``. Dimensionless, but its mean
      is ``tr(K H)/n <= m/n`` (2/5 for DBT), so it drives Q down to its lower bound; kept for
      comparison only.

    Returns ``lambda (...)``. ``delta = 0`` in the inverse form gives ``inf`` (clamp it).
    """
    if form in ("mean-square", "inverse-mean-square"):
        return _mean_square(delta, form == "inverse-mean-square")
    if form not in ("normalised", "normalised-n"):
        raise ValueError(f"q_form = {form!r}; expected one of {Q_FORMS}")
    nees = quadratic_form(P, delta, "predicted covariance P-")
    if form == "normalised-n":
        return nees / delta.shape[-1]
    if K is None or H is None:
        raise ValueError("q_form 'normalised' needs the gain K and Jacobian H of the update")
    trKH = np.einsum("...ij,...ji->...", K, H)
    return nees / np.maximum(trKH, np.finfo(float).tiny)


def _q_factor_update(form: str, delta: Array, r: Array, S: Array, R: Array) -> Array:
    """lambda of :func:`q_factor` for ``delta = K r``, ``K = P- H^T S^{-1}``, evaluated in
    measurement space: ``delta^T P-^{-1} delta = u^T (S - R) u`` with ``u = S^{-1} r`` (since
    ``P-^{-1} K = H^T S^{-1}`` and ``H P- H^T = S - R``) and ``tr(K H) = m - tr(S^{-1} R)``;
    m x m work instead of an n x n factorisation."""
    if form in ("mean-square", "inverse-mean-square"):
        return _mean_square(delta, form == "inverse-mean-square")
    m = S.shape[-1]
    S_inv = solve_psd(S, np.broadcast_to(np.eye(m), S.shape))
    u = (S_inv * r[..., None, :]).sum(-1)
    nees = (u[..., :, None] * (S - R) * u[..., None, :]).sum((-2, -1))
    if form == "normalised-n":
        return nees / delta.shape[-1]
    trKH = m - (S_inv * R).sum((-2, -1))  # R symmetric: tr(S^-1 R) = sum(S^-1 * R)
    return nees / np.maximum(trKH, np.finfo(float).tiny)


def sage_husa_weight(b: float, k: ArrayLike) -> Array:
    r"""Fading-memory weight of the k-th update (k = 0, 1, ...),

    .. math::

        d_k = \frac{1 - b}{1 - b^{k+1}}

    so :math:`d_0 = 1` and :math:`d_k \to 1 - b`."""
    k = np.asarray(k)
    return (1.0 - b) / (1.0 - b ** (k + 1.0))


def _clip(a: Array, bounds: tuple[float, float] | None) -> Array:
    return a if bounds is None else np.clip(a, bounds[0], bounds[1])


def _positive_definite(M: Array) -> NDArray[np.bool_]:
    """Rows where the symmetric M ``(..., k, k)`` is positive definite (closed form for
    k <= 2, eigenvalues otherwise)."""
    k = M.shape[-1]
    if k == 1:
        return M[..., 0, 0] > 0
    if k == 2:
        a, b, d = M[..., 0, 0], M[..., 0, 1], M[..., 1, 1]
        return (a > 0) & (a * d - b * b > 0)
    return np.linalg.eigvalsh(M)[..., 0] > 0


def _positive_semidefinite(M: Array) -> NDArray[np.bool_]:
    """Rows where the symmetric M is PSD to rounding (a Q with constant components)."""
    ev = np.linalg.eigvalsh(M)
    scale = np.abs(M).max((-2, -1))
    return ev[..., 0] >= -1e-12 * scale


def _check_bounds(bounds, name: str) -> tuple[float, float] | None:
    if bounds is None:
        return None
    lo, hi = (float(v) for v in bounds)
    if not (0 < lo <= hi and np.isfinite(lo)):
        raise ValueError(f"{name} = {bounds!r}; expected None or (lo, hi) with 0 < lo <= hi")
    return lo, hi


def _keep_mask(miss: Array | None, batch: tuple[int, ...]) -> Array:
    """True for rows that had a measurement (their memory is updated)."""
    if miss is None:
        return np.ones(batch, dtype=bool)
    return ~np.broadcast_to(miss, batch)


# --------------------------------------------------------------------------------------------
# MC-EKF
# --------------------------------------------------------------------------------------------


class MCEKF(Linearised):
    r"""Modified-covariance EKF (Hashemi and Alfi 2019, eqs. 10-11).

    Prediction as the EKF: :math:`\mathbf{x}^- = f(\mathbf{x})`, :math:`P^- = F P F^\top + Q`.
    Update (eq. 9; eq. 10 re-linearises at the update; eq. 11), with :math:`J_h` the Jacobian
    of h:

    .. math::

        H &= J_h(\mathbf{x}^-), \qquad K = P^- H^\top (H P^- H^\top + R)^{-1}, \qquad
        \mathbf{x}^+ = \mathbf{x}^- + K \bigl(\mathbf{z} - h(\mathbf{x}^-)\bigr), \\
        H^+ &= J_h(\mathbf{x}^+), \qquad K^+ = P^- H^{+\top} (H^+ P^- H^{+\top} + R)^{-1}, \\
        P^+ &= (I - K^+ H^+) P^- (I - K^+ H^+)^\top + K^+ R K^{+\top}

    The paper prints the innovation as ``z - H x-``; for a nonlinear h the meaningful
    innovation is ``z - h(x-)``, used here (bearing wrapped). The paper writes eq. 11 as
    ``P+ = P- - K+ H+ P-``; for the optimal K+ that equals the Joseph form used here, which
    keeps P+ symmetric positive semi-definite under rounding (DESIGN: covariances use the
    Joseph form).

    ``second_order=True`` uses eqs. 12-13's element-wise ``H = J_h + 1/2 diag(Hess h)``
    (see :func:`second_order_jacobian`) for both H (at x-) and H+ (at x+); needs
    ``sensor.hessian``.

    The returned innovation is ``nu = z - h(x-)`` with ``S = H P- H^T + R``.
    """

    name = "MCEKF"

    def __init__(self, second_order: bool = False) -> None:
        self.second_order = bool(second_order)

    def init(self, g: Gaussian) -> Gaussian:
        """The initial belief: the checked Gaussian prior (the MC-EKF keeps no memory)."""
        x, P = check_belief(g, None, f"{self.name}.init prior")
        return Gaussian._make((x, P))

    def update(self, belief: Gaussian, z: ArrayLike,
               sensor: SensorModel) -> tuple[Gaussian, Innovation]:
        x, P, z = self._inputs(belief, z, sensor)
        miss = missing_rows(z)
        zhat, H = _linearize(sensor, x, self.second_order)
        R = sensor.noise
        r = sensor.residual(z, zhat)
        if miss is not None:
            r = np.where(np.isnan(r), 0.0, r)
        xn, Pn, S, _, _ = _mc_update(x, P, r, H, R, sensor, self.second_order)
        return keep_prior_where_missing(miss, (x, P), output(xn, Pn), Innovation(r, S))


# --------------------------------------------------------------------------------------------
# The proposed adaptive MC-EKF
# --------------------------------------------------------------------------------------------


class AMCEKF(Filter):
    r"""Adaptive modified-covariance EKF, the filter proposed by Hashemi and Alfi (2019).

    MC-EKF update (eqs. 10-13, :class:`MCEKF`) with ``R_t = r_scale R0`` and
    ``Q_t = q_scale Q0``, then, per row with a measurement (eqs. 14-16, 18-21; lambda as
    ``q_form`` says, :func:`q_factor`):

    .. math::

        \mathbf{r} &= \mathbf{z} - h(\mathbf{x}^-), \qquad
        C_r = \frac1N \sum_{i=t-N+1}^{t} \mathbf{r}_i \mathbf{r}_i^\top, \qquad
        S = H P^- H^\top + R(t), \\
        \alpha &= \frac{\operatorname{tr} C_r}{\operatorname{tr} S}, \qquad
        R(t+1) = \alpha R(t) \quad (\texttt{r\_scale} \leftarrow \alpha\, \texttt{r\_scale}),
        \\
        \delta &= \mathbf{x}^+ - \mathbf{x}^- = K \mathbf{r}, \qquad
        Q(t+1) = \lambda Q(t) \quad (\texttt{q\_scale} \leftarrow \lambda\, \texttt{q\_scale})

    Both updates compound, as in the paper; alpha and lambda from step t apply from step t+1.

    Choices the paper leaves open (Hashemi and Alfi 2019), all documented here:

    - ``window`` N (paper: 25). ``warmup="partial"`` (default): before N innovations have
      been seen, C_r averages the k available ones (1/k, not 1/N, so alpha is not biased
      low); ``warmup="wait"``: R is not adapted until the window is full.
    - ``q_form``: ``"normalised"`` (default), ``"mean-square"`` (the literal reading),
      ``"inverse-mean-square"`` or ``"normalised-n"``; see :func:`q_factor`. The literal
      form is not dimensionless, so Q collapses or explodes geometrically; the normalised
      form is 1 on average for a consistent filter, so Q only moves when the filter is not.
    - Bounds (the paper has none): ``r_bounds`` clamps r_scale (default [1e-3, 1e3]),
      ``q_bounds`` clamps q_scale (default [1e-2, 1e2]) and ``lam_bounds`` (default none)
      clamps each lambda before it compounds. ``None`` removes a bound. Because lambda is a
      noisy per-step ratio and the recursion multiplies, log q_scale drifts with
      E[log lambda] < log E[lambda] = 0; the lower bound is what keeps Q from vanishing on a
      target that truly moves without process noise.
    - The innovation window and the alpha of eq. 18 use the innovation at the prediction
      with the S of that step (eq. 16), H being the second-order H when ``second_order``.
      The traces add components of different units (rad^2 and Hz^2 for DBT), so alpha is
      dominated by the component with the largest variance (the frequency); that is eq. 18
      as printed.
    - The normalised lambda is evaluated in measurement space,
      ``delta^T P-^{-1} delta = u^T (S - R) u`` with ``u = S^{-1} r``, and
      ``tr(K H) = m - tr(S^{-1} R)`` (exact identities for ``delta = K r``), so no n x n
      factorisation is needed.

    ``adapt_r=False, adapt_q=False`` is the plain MC-EKF (with ``second_order`` as given).
    The returned innovation is ``nu = z - h(x-)`` with ``S = H P- H^T + R(t)``.
    """

    name = "AMCEKF"

    def __init__(
        self,
        window: int = 25,
        second_order: bool = True,
        adapt_r: bool = True,
        adapt_q: bool = True,
        q_form: str = "normalised",
        warmup: str = "partial",
        r_bounds: tuple[float, float] | None = (1e-3, 1e3),
        q_bounds: tuple[float, float] | None = (1e-2, 1e2),
        lam_bounds: tuple[float, float] | None = None,
    ) -> None:
        if not (isinstance(window, int | np.integer) and window >= 1):
            raise ValueError(f"AMCEKF window = {window!r}; expected an integer >= 1")
        if q_form not in Q_FORMS:
            raise ValueError(f"AMCEKF q_form = {q_form!r}; expected one of {Q_FORMS}")
        if warmup not in ("partial", "wait"):
            raise ValueError(f"AMCEKF warmup = {warmup!r}; expected 'partial' or 'wait'")
        self.window = int(window)
        self.second_order = bool(second_order)
        self.adapt_r = bool(adapt_r)
        self.adapt_q = bool(adapt_q)
        self.q_form = q_form
        self.warmup = warmup
        self.r_bounds = _check_bounds(r_bounds, "AMCEKF r_bounds")
        self.q_bounds = _check_bounds(q_bounds, "AMCEKF q_bounds")
        self.lam_bounds = _check_bounds(lam_bounds, "AMCEKF lam_bounds")

    def init(self, g: Gaussian) -> AdaptiveBelief:
        """Initial belief from a Gaussian prior: ``R(0) = R0``, ``Q(0) = Q0`` (scales 1),
        an empty innovation window, ``count = 0``."""
        if isinstance(g, AdaptiveBelief):
            return g
        x, P = check_belief(g, None, f"{self.name}.init prior")
        batch = x.shape[:-1]
        return AdaptiveBelief(x, P, np.ones(batch), np.ones(batch),
                              np.zeros(batch + (self.window, 0)), np.zeros(batch, np.int64))

    def estimate(self, belief: AdaptiveBelief) -> Gaussian:
        return Gaussian._make((belief.mean, belief.cov))

    def predict(self, belief: AdaptiveBelief, motion: MotionModel, dt: ArrayLike) -> AdaptiveBelief:
        """``x- = f(x)``, ``P- = F P F^T + q_scale Q0(x, dt)``."""
        b = self.init(belief)
        x, P = check_belief(b, dim_x_of(motion), f"{self.name}.predict belief")
        check_dt(dt, f"{self.name}.predict")
        if self.adapt_q:
            F = np.asarray(motion.jacobian(x, dt))
            Q = b.q_scale[..., None, None] * np.asarray(motion.noise(x, dt))
            g = output(motion.f(x, dt), sandwich(F, P) + Q)
        else:
            g = jacobian_predict(x, P, motion, dt)
        return b._replace(mean=g.mean, cov=g.cov)

    def update(self, belief: AdaptiveBelief, z: ArrayLike,
               sensor: SensorModel) -> tuple[AdaptiveBelief, Innovation]:
        b = self.init(belief)
        x, P = check_belief(b, None, f"{self.name}.update belief")
        z = check_measurement(z, sensor.dim_z, f"{self.name}.update", x.shape[:-1])
        miss = missing_rows(z)
        zhat, H = _linearize(sensor, x, self.second_order)
        R = b.r_scale[..., None, None] * sensor.noise  # R(t)
        r = sensor.residual(z, zhat)  # (14), z - h(x-)
        if miss is not None:
            r = np.where(np.isnan(r), 0.0, r)
        xn, Pn, S, _, delta = _mc_update(x, P, r, H, R, sensor, self.second_order)
        post, innov = keep_prior_where_missing(miss, (x, P), output(xn, Pn), Innovation(r, S))
        batch = post.mean.shape[:-1]
        keep = _keep_mask(miss, batch)

        buf, count = push_innovation(b.residuals, b.count, r, keep, self.window, batch,
                                     f"{self.name}.update")
        r_scale = np.broadcast_to(b.r_scale, batch)
        q_scale = np.broadcast_to(b.q_scale, batch)

        if self.adapt_r:  # (15)-(19)
            alpha = r_factor(buf, count, S)
            active = keep if self.warmup == "partial" else keep & (count >= self.window)
            r_scale = np.where(active, _clip(r_scale * alpha, self.r_bounds), r_scale)
        if self.adapt_q:  # (20)-(21)
            lam = _clip(_q_factor_update(self.q_form, delta, r, S, R), self.lam_bounds)
            q_scale = np.where(keep, _clip(q_scale * lam, self.q_bounds), q_scale)

        out = AdaptiveBelief(post.mean, post.cov, np.array(r_scale, dtype=float),
                             np.array(q_scale, dtype=float), buf, np.asarray(count, np.int64))
        return out, innov


# --------------------------------------------------------------------------------------------
# The adaptive-EKF baseline: Sage-Husa
# --------------------------------------------------------------------------------------------


class AEKF(Filter):
    r"""Adaptive EKF baseline (stands for the paper's ref. [16]): the Sage-Husa noise
    estimator with fading memory.

    The paper's [16] tunes Q and R online by steepest descent but gives no equations, so
    any documented adaptive EKF will do. This is the widely used
    Sage-Husa estimator (A. P. Sage and G. W. Husa, "Adaptive filtering with unknown prior
    statistics", Proc. JACC, 1969) with the exponential forgetting factor b. At the k-th
    update of a row (k = 0, 1, ...), with :math:`\nu = \mathbf{z} - h(\mathbf{x}^-)` and
    :math:`H = J_h(\mathbf{x}^-)` (the covariance in Joseph form):

    .. math::

        d_k &= \frac{1 - b}{1 - b^{k+1}}, \qquad
        R_k = (1 - d_k) R_{k-1} + d_k (\nu \nu^\top - H P^- H^\top), \\
        S &= H P^- H^\top + R_k, \qquad K = P^- H^\top S^{-1}, \qquad
        \mathbf{x}^+ = \mathbf{x}^- + K \nu, \\
        P^+ &= (I - K H) P^- (I - K H)^\top + K R_k K^\top

    and, with ``adapt_q=True``, using :math:`F P F^\top = P^- - Q_{k-1}` and
    :math:`\delta = \mathbf{x}^+ - \mathbf{x}^-`:

    .. math::

        Q_k &= (1 - d_k) Q_{k-1} + d_k (K \nu \nu^\top K^\top + P^+ - F P F^\top) \\
            &= Q_{k-1} + d_k (\delta \delta^\top + P^+ - P^-)

    used by the next prediction ``P- = F P F^T + Q_k``. R_{-1} = ``sensor.noise`` and
    Q_{-1} = ``motion.noise`` of the first prediction (the estimated Q then replaces the
    model's, so it assumes a constant step dt).

    Choices: the current innovation enters R_k before the gain is formed (the classical
    ordering). The innovation form ``r r^T - H P- H^T`` is not positive definite in general
    (with d_0 = 1 the first estimate is a single such term, never PD for m >= 2), so rows
    whose candidate R_k is not positive definite keep R_{k-1} (likewise a Q_k that is not
    positive semi-definite keeps Q_{k-1}); nothing else is repaired. ``forgetting`` b in
    (0, 1), default 0.97 (an effective memory of about 1/(1-b) = 33 steps).

    The returned innovation is ``nu = z - h(x-)`` with ``S = H P- H^T + R_k``.
    """

    name = "AEKF"

    def __init__(self, forgetting: float = 0.97, adapt_q: bool = False) -> None:
        b = float(forgetting)
        if not (0.0 < b < 1.0):
            raise ValueError(f"AEKF forgetting = {forgetting!r}; expected 0 < b < 1")
        self.forgetting = b
        self.adapt_q = bool(adapt_q)

    def init(self, g: Gaussian) -> SageHusaBelief:
        """Initial belief from a Gaussian prior; R and Q start from the models' at the first
        update and prediction."""
        if isinstance(g, SageHusaBelief):
            return g
        x, P = check_belief(g, None, f"{self.name}.init prior")
        batch = x.shape[:-1]
        return SageHusaBelief(x, P, np.zeros(batch + (0, 0)), np.zeros(batch + (0, 0)),
                              np.zeros(batch, np.int64))

    def estimate(self, belief: SageHusaBelief) -> Gaussian:
        return Gaussian._make((belief.mean, belief.cov))

    def predict(self, belief: SageHusaBelief, motion: MotionModel, dt: ArrayLike) -> SageHusaBelief:
        """``x- = f(x)``, ``P- = F P F^T + Q`` (Q the estimate when ``adapt_q``)."""
        b = self.init(belief)
        x, P = check_belief(b, dim_x_of(motion), f"{self.name}.predict belief")
        check_dt(dt, f"{self.name}.predict")
        if not self.adapt_q:
            g = jacobian_predict(x, P, motion, dt)
            return b._replace(mean=g.mean, cov=g.cov)
        n = x.shape[-1]
        Q = b.Q
        if Q.shape[-1] == 0:
            Q = np.broadcast_to(np.asarray(motion.noise(x, dt)), x.shape[:-1] + (n, n)).copy()
        F = np.asarray(motion.jacobian(x, dt))
        g = output(motion.f(x, dt), sandwich(F, P) + Q)
        return SageHusaBelief(g.mean, g.cov, b.R, Q, b.count)

    def update(self, belief: SageHusaBelief, z: ArrayLike,
               sensor: SensorModel) -> tuple[SageHusaBelief, Innovation]:
        b = self.init(belief)
        x, P = check_belief(b, None, f"{self.name}.update belief")
        z = check_measurement(z, sensor.dim_z, f"{self.name}.update", x.shape[:-1])
        m = sensor.dim_z
        miss = missing_rows(z)
        zhat, H = linearize(sensor, x)
        r = sensor.residual(z, zhat)
        if miss is not None:
            r = np.where(np.isnan(r), 0.0, r)
        batch = np.broadcast_shapes(x.shape[:-1], r.shape[:-1])
        keep = _keep_mask(miss, batch)
        count = np.broadcast_to(b.count, batch)
        R_prev = b.R
        if R_prev.shape[-1] == 0:
            R_prev = np.asarray(sensor.noise)
        elif R_prev.shape[-1] != m:
            raise ValueError(f"{self.name}.update: the R estimate is {R_prev.shape[-1]} x "
                             f"{R_prev.shape[-1]} but the sensor measures {m}")
        R_prev = np.broadcast_to(R_prev, batch + (m, m))

        d = sage_husa_weight(self.forgetting, count)[..., None, None]
        HPHt = mm(H, mmT(P, H)) if (H.ndim > 2 or P.ndim > 2) else H @ P @ H.T
        rrT = r[..., :, None] * r[..., None, :]
        R_new = symmetrize((1.0 - d) * R_prev + d * (rrT - HPHt))
        R_k = np.where((keep & _positive_definite(R_new))[..., None, None], R_new, R_prev)

        xn, Pn, S = condition(x, P, r, H, R_k)
        post, innov = keep_prior_where_missing(miss, (x, P), output(xn, Pn), Innovation(r, S))

        Q_k = b.Q
        if self.adapt_q and Q_k.shape[-1] != 0:
            n = x.shape[-1]
            Q_prev = np.broadcast_to(Q_k, batch + (n, n))
            delta = xn - x
            Q_new = symmetrize(
                Q_prev + d * (delta[..., :, None] * delta[..., None, :] + post.cov - P))
            ok = keep & _positive_semidefinite(Q_new)
            Q_k = np.where(ok[..., None, None], Q_new, Q_prev)
        out = SageHusaBelief(post.mean, post.cov, np.array(R_k), Q_k,
                             np.asarray(count + keep, np.int64))
        return out, innov
