r"""Constant-gain trackers of the missing-measurements thesis (sections 2-1 to 2-4): the
alpha-beta and alpha-beta-gamma filters, their gain designers, variance-reduction ratios,
steady-state covariances and stability tests.

Each position coordinate is filtered on its own with the same gains. Per coordinate, with
scan period :math:`\Delta t`, measured position :math:`x_0(n)`, predicted :math:`x_p(n)` and
smoothed :math:`x_s(n)` (thesis eqs. 2-4..2-6 and 2-33..2-36; the acceleration line is the
alpha-beta-gamma filter's only):

.. math::

    r(n) &= x_0(n) - x_p(n) \\
    x_s(n) &= x_p(n) + \alpha\, r(n) \\
    v_s(n) &= v_s(n-1) + \Delta t\, a_s(n-1) + \frac{\beta}{\Delta t}\, r(n) \\
    a_s(n) &= a_s(n-1) + \frac{2 \gamma}{\Delta t^2}\, r(n) \\
    x_p(n+1) &= x_s(n) + \Delta t\, v_s(n) + \frac{\Delta t^2}{2}\, a_s(n)

In matrix form (2-1..2-3, 2-13..2-16, 2-41..2-44), with :math:`\Phi` the polynomial
transition:

.. math::

    \mathbf{x}(n|n) = A\, \mathbf{x}(n-1|n-1) + K\, y(n), \qquad A = (I - K G)\, \Phi, \qquad
    G = [1 \;\; 0 \;\; (0)], \qquad
    K = \Bigl[\alpha, \;\frac{\beta}{\Delta t}, \;\frac{2\gamma}{\Delta t^2}\Bigr]^\top

**One gamma convention for the whole module: the acceleration gain is 2 gamma / dt^2**
(eq. 2-35, the thesis's characteristic polynomial 2-49, Brookner's g-h-k filter and
FilterPy's ``GHKFilter``, whose k is our gamma). The thesis's VRR formulas 2-45..2-47 are
exact for an acceleration gain gamma'/dt^2 (the missing-measurements thesis, section 2-4), so they
are evaluated here at
``gamma' = 2 gamma``. Fading-memory and growing-memory gains for alpha-beta-gamma are given
in this convention too.

Memory lives in the belief (:class:`AlphaBetaBelief`): the scan count ``k`` (for the
start-up rules and Simpson's gains) and ``tau``, the time since the row's last update (the dt
of the next update's gains). The belief also carries the exact covariance of the
constant-gain estimator, the prediction and the Joseph form (valid for any gain),

.. math::

    P^- = F P F^\top + Q, \qquad P^+ = (I - K H) P^- (I - K H)^\top + K R K^\top

so NEES and NIS are meaningful; with Q = 0 and noise-only input P converges to
:func:`steady_state_cov`.
"""

from __future__ import annotations

import math
import weakref
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import (
    Filter,
    check_belief,
    check_dt,
    check_measurement,
    missing_rows,
    register,
)
from trackkit.linalg import symmetrize
from trackkit.models.protocols import MotionModel, SensorModel
from trackkit.models.sensors import Position
from trackkit.renamed import renamed_keywords

__all__ = [
    "kohn",
    "benedict_bordner",
    "benedict_bordner_gamma",
    "fading_memory",
    "fading_memory_abg",
    "simpson",
    "simpson_abg",
    "VRR",
    "VRR3",
    "vrr",
    "vrr_abg",
    "benedict_bordner_vrr",
    "fading_memory_vrr",
    "steady_state_cov",
    "characteristic_polynomial",
    "roots",
    "is_stable",
    "in_stability_region",
    "in_stability_region_abg",
    "ABTrack",
    "ABGTrack",
    "alpha_beta_track",
    "alpha_beta_gamma_track",
    "AlphaBetaBelief",
    "AlphaBeta",
    "AlphaBetaGamma",
    "STARTUPS",
]

Array = NDArray[np.float64]

#: the start-up rules of the filters (see :class:`AlphaBeta`)
STARTUPS = ("thesis", "prior", "simpson")


def _array(value: ArrayLike, name: str) -> Array:
    """``value`` as a float array with every entry finite, or a ValueError naming it."""
    a = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {np.asarray(value).tolist()!r}; expected finite values")
    return a


def _positive(value: ArrayLike, name: str) -> Array:
    a = _array(value, name)
    if not np.all(a > 0):
        raise ValueError(f"{name} = {np.asarray(value).tolist()!r}; expected values > 0")
    return a


def _result(a: Array) -> Array | float:
    """A 0-d result as a Python float, otherwise the array."""
    return float(a) if np.ndim(a) == 0 else a


# --------------------------------------------------------------------------------------------
# Gain designers
# --------------------------------------------------------------------------------------------


def kohn() -> tuple[float, float]:
    """Kohn's alpha-beta gains as the thesis prints them: ``(alpha, beta) = (0.5, 0.167)``.

    They lie on the Benedict-Bordner curve (``benedict_bordner(0.5) = 1/6``) to the three
    printed digits.
    """
    return 0.5, 0.167


def benedict_bordner(alpha: ArrayLike) -> Array | float:
    r"""Benedict-Bordner beta for a given alpha (eq. 2-24):

    .. math::

        \beta = \frac{\alpha^2}{2 - \alpha}

    It minimises the noise VRR plus the transient error to a velocity step. ``0 < alpha < 2``;
    the pair is stable only for ``alpha < 4 - 2 sqrt(2) = 1.1716``.
    """
    a = _array(alpha, "alpha")
    if not np.all((a > 0) & (a < 2)):
        raise ValueError(f"alpha = {np.asarray(alpha).tolist()!r}; expected 0 < alpha < 2")
    return _result(a * a / (2.0 - a))


def benedict_bordner_gamma(alpha: ArrayLike, beta: ArrayLike) -> Array | float:
    r"""Benedict-Bordner gamma of the alpha-beta-gamma filter, from eq. 2-50
    :math:`2 \beta - \alpha (\alpha + \beta + \gamma / 2) = 0` solved for gamma:

    .. math::

        \gamma = \frac{4 \beta}{\alpha} - 2 \alpha - 2 \beta

    in the module's convention (acceleration gain 2 gamma / dt^2, the convention of the
    characteristic polynomial 2-49 that the thesis states beside it). With gamma = 0 the
    condition is eq. 2-24. ``alpha > 0``.
    """
    a, b = _array(alpha, "alpha"), _array(beta, "beta")
    if not np.all(a > 0):
        raise ValueError(f"alpha = {np.asarray(alpha).tolist()!r}; expected alpha > 0")
    return _result(4.0 * b / a - 2.0 * a - 2.0 * b)


def _check_xi(xi: ArrayLike) -> Array:
    x = _array(xi, "xi")
    if not np.all((x >= 0) & (x <= 1)):
        raise ValueError(f"xi = {np.asarray(xi).tolist()!r}; expected 0 <= xi <= 1")
    return x


def fading_memory(xi: ArrayLike) -> tuple[Array | float, Array | float]:
    r"""Critically damped (fading-memory) alpha-beta gains (eqs. 2-27, 2-28):

    .. math::

        \alpha = 1 - \xi^2, \qquad \beta = (1 - \xi)^2

    Both roots of the characteristic polynomial are at ``z = xi``. ``0 <= xi <= 1``: xi -> 1
    smooths heavily, xi = 0 is the dead-beat filter (the line through the last two points).
    """
    x = _check_xi(xi)
    return _result(1.0 - x * x), _result((1.0 - x) ** 2)


def fading_memory_abg(xi: ArrayLike) -> tuple[Array | float, Array | float, Array | float]:
    r"""Critically damped (fading-memory) alpha-beta-gamma gains, acceleration gain
    2 gamma / dt^2:

    .. math::

        \alpha = 1 - \xi^3, \qquad \beta = \tfrac32 (1 - \xi)^2 (1 + \xi), \qquad
        \gamma = \tfrac12 (1 - \xi)^3

    Derivation: the characteristic polynomial (eq. 2-49)
    ``z^3 + (alpha + beta + gamma - 3) z^2 + (3 - 2 alpha - beta + gamma) z - (1 - alpha)``
    equals ``(z - xi)^3 = z^3 - 3 xi z^2 + 3 xi^2 z - xi^3`` when ``1 - alpha = xi^3``,
    ``alpha + beta + gamma = 3 - 3 xi`` and ``3 - 2 alpha - beta + gamma = 3 xi^2``; adding
    the last two gives ``2 gamma - alpha = 3 xi^2 - 3 xi``, so
    ``gamma = (1 - xi^3 + 3 xi^2 - 3 xi) / 2 = (1 - xi)^3 / 2`` and
    ``beta = 3 - 3 xi - alpha - gamma``. With an acceleration gain gamma'/dt^2 the same
    filter has ``gamma' = (1 - xi)^3``.
    """
    x = _check_xi(xi)
    return (_result(1.0 - x**3), _result(1.5 * (1.0 - x) ** 2 * (1.0 + x)),
            _result(0.5 * (1.0 - x) ** 3))


def _check_k(k: ArrayLike) -> Array:
    a = np.asarray(k)
    kf = np.asarray(k, dtype=float)
    if not (np.all(np.isfinite(kf)) and np.all(kf >= 1) and np.all(kf == np.floor(kf))):
        raise ValueError(f"k = {a.tolist()!r}; expected integers >= 1 (the scan count)")
    return kf


def simpson(k: ArrayLike) -> tuple[Array | float, Array | float]:
    r"""Simpson's time-varying alpha-beta gains (eq. 2-32), k = 1, 2, ...:

    .. math::

        \alpha_k = \frac{2 (2k - 1)}{k (k + 1)}, \qquad \beta_k = \frac{6}{k (k + 1)}

    With these gains the filter's position and velocity at scan k (k >= 2) are those of the
    least-squares straight line through all k measurements (growing memory): recursive
    least squares of a line. (1, 3), (1, 1), (5/6, 1/2), (7/10, 3/10), (3/5, 1/5) for
    k = 1..5; at k = 2 the line through two points forgets everything before.
    """
    kf = _check_k(k)
    den = kf * (kf + 1.0)
    return _result(2.0 * (2.0 * kf - 1.0) / den), _result(6.0 / den)


def simpson_abg(k: ArrayLike) -> tuple[Array | float, Array | float, Array | float]:
    r"""Growing-memory alpha-beta-gamma gains (acceleration gain 2 gamma / dt^2):

    .. math::

        \alpha_k = \frac{3 (3k^2 - 3k + 2)}{k (k+1) (k+2)}, \qquad
        \beta_k = \frac{18 (2k - 1)}{k (k+1) (k+2)}, \qquad
        \gamma_k = \frac{30}{k (k+1) (k+2)}

    Derivation: recursive least squares of a quadratic. With scan times ``i = 1..k`` and
    ``phi_i = (1, (i-k) dt, (i-k)^2 dt^2 / 2)``, the fit's (position, velocity, acceleration)
    at scan k moves by ``M_k^{-1} phi_k r`` for a new residual r, ``M_k = sum_i phi_i
    phi_i^T``; the components of ``M_k^{-1} phi_k`` are ``alpha_k``, ``beta_k / dt`` and
    ``2 gamma_k / dt^2`` above. From k = 3 (gains (1, 3/2, 1/2), the quadratic through three
    points) the filter equals the least-squares quadratic of all data so far.
    """
    kf = _check_k(k)
    den = kf * (kf + 1.0) * (kf + 2.0)
    return (_result(3.0 * (3.0 * kf * kf - 3.0 * kf + 2.0) / den),
            _result(18.0 * (2.0 * kf - 1.0) / den), _result(30.0 / den))


# --------------------------------------------------------------------------------------------
# Analysis: VRR, steady-state covariance, stability
# --------------------------------------------------------------------------------------------


class VRR(NamedTuple):
    """Variance-reduction ratios of the alpha-beta filter: the steady-state covariance of
    the smoothed state on pure measurement noise divided by the noise variance sigma^2.

    ``x`` = C_xx / sigma^2, ``v`` = C_vv / sigma^2 (1/s^2), ``xv`` = C_xv / sigma^2 (1/s).
    """

    x: Array | float
    v: Array | float
    xv: Array | float


class VRR3(NamedTuple):
    """Variance-reduction ratios of the alpha-beta-gamma filter (see :class:`VRR`):
    ``x``, ``v`` (1/s^2), ``a`` (1/s^4) and the cross terms ``xv`` (1/s), ``xa`` (1/s^2),
    ``va`` (1/s^3)."""

    x: Array | float
    v: Array | float
    a: Array | float
    xv: Array | float
    xa: Array | float
    va: Array | float


def in_stability_region(alpha: ArrayLike, beta: ArrayLike) -> NDArray[np.bool_] | bool:
    """The alpha-beta stability region ``0 < alpha < 2, 0 < beta < 4 - 2 alpha`` (the Jury
    conditions of ``z^2 - (2 - alpha - beta) z + (1 - alpha)``; the thesis's 2-23 is
    garbled). Batched over arrays of gains."""
    a, b = np.asarray(alpha, dtype=float), np.asarray(beta, dtype=float)
    out = (a > 0) & (a < 2) & (b > 0) & (b < 4 - 2 * a)
    return bool(out) if out.ndim == 0 else out


def in_stability_region_abg(alpha: ArrayLike, beta: ArrayLike,
                            gamma: ArrayLike) -> NDArray[np.bool_] | bool:
    r"""The alpha-beta-gamma stability region (acceleration gain 2 gamma / dt^2):

    .. math::

        0 < \alpha < 2, \qquad 0 < \beta < 4 - 2 \alpha, \qquad
        0 < \gamma < \frac{\alpha \beta}{2 - \alpha}

    The Jury conditions of eq. 2-49, ``f(z) = z^3 + a2 z^2 + a1 z + a0``: ``f(1) = 2 gamma
    > 0``, ``-f(-1) = 8 - 4 alpha - 2 beta > 0``, ``|a0| = |1 - alpha| < 1`` and
    ``|a0^2 - 1| > |a0 a2 - a1|``, which is ``alpha (2 - alpha) > |alpha beta - (2 - alpha)
    (alpha + gamma)|`` and reduces to the bound on gamma given the others."""
    a = np.asarray(alpha, dtype=float)
    b = np.asarray(beta, dtype=float)
    g = np.asarray(gamma, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = (a > 0) & (a < 2) & (b > 0) & (b < 4 - 2 * a) & (g > 0) & (g < a * b / (2 - a))
    return bool(out) if out.ndim == 0 else out


@renamed_keywords(T="dt")
def vrr(alpha: ArrayLike, beta: ArrayLike, dt: ArrayLike = 1.0) -> VRR:
    r"""Steady-state VRR of the alpha-beta filter (eqs. 2-17..2-19):

    .. math::

        \frac{C}{\sigma^2} = \frac{1}{\alpha (4 - 2 \alpha - \beta)}
        \begin{bmatrix}
            2 \alpha^2 - 3 \alpha \beta + 2 \beta & \beta (2 \alpha - \beta) / \Delta t \\
            \beta (2 \alpha - \beta) / \Delta t & 2 \beta^2 / \Delta t^2
        \end{bmatrix}

    Batched over arrays of gains and dt; nan where the gains are outside the stability
    region (no steady state).
    """
    a, b = np.asarray(alpha, dtype=float), np.asarray(beta, dtype=float)
    dt = _positive(dt, "dt")
    ok = in_stability_region(a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = np.where(ok, a * (4 - 2 * a - b), np.nan)
        x = (2 * a**2 - 3 * a * b + 2 * b) / den
        xv = b * (2 * a - b) / (dt * den)
        v = 2 * b**2 / (dt**2 * den)
    return VRR(_result(x), _result(v), _result(xv))


@renamed_keywords(T="dt")
def vrr_abg(alpha: ArrayLike, beta: ArrayLike, gamma: ArrayLike,
            dt: ArrayLike = 1.0) -> VRR3:
    r"""Steady-state VRR of the alpha-beta-gamma filter: eqs. 2-45..2-47 evaluated at
    ``gamma' = 2 gamma`` (the thesis's formulas hold for an acceleration gain gamma'/dt^2;
    this module's gain is 2 gamma / dt^2), with the cross terms (derived from the discrete
    Lyapunov equation :math:`C = A C A^\top + K K^\top \sigma^2`), with :math:`s = \sigma^2`:

    .. math::

        D &= (4 - 2 \alpha - \beta) (2 \alpha \beta + \alpha \gamma' - 2 \gamma') \\
        C_{xx} / s &= \bigl[2 \beta (2 \alpha^2 + 2 \beta - 3 \alpha \beta)
            - \alpha \gamma' (4 - 2 \alpha - \beta)\bigr] / D \\
        C_{vv} / s &= \bigl[4 \beta^3 - 4 \beta^2 \gamma' + 2 \gamma'^2 (2 - \alpha)\bigr]
            / (\Delta t^2 D) \\
        C_{aa} / s &= 4 \beta \gamma'^2 / (\Delta t^4 D) \\
        C_{xv} / s &= \beta (2 \alpha - \beta) (2 \beta - \gamma') / (\Delta t\, D) \\
        C_{xa} / s &= \gamma' (4 \alpha \beta + 2 \alpha \gamma' - 2 \beta^2 + \beta \gamma'
            - 4 \gamma') / (\Delta t^2 D) \\
        C_{va} / s &= 2 \beta \gamma' (2 \beta - \gamma') / (\Delta t^3 D)

    Batched; nan outside the stability region.
    """
    a = np.asarray(alpha, dtype=float)
    b = np.asarray(beta, dtype=float)
    g2 = 2.0 * np.asarray(gamma, dtype=float)  # gamma' of the thesis's formulas
    dt = _positive(dt, "dt")
    ok = in_stability_region_abg(a, b, np.asarray(gamma, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        D = np.where(ok, (4 - 2 * a - b) * (2 * a * b + a * g2 - 2 * g2), np.nan)
        x = (2 * b * (2 * a**2 + 2 * b - 3 * a * b) - a * g2 * (4 - 2 * a - b)) / D
        v = (4 * b**3 - 4 * b**2 * g2 + 2 * g2**2 * (2 - a)) / (dt**2 * D)
        acc = 4 * b * g2**2 / (dt**4 * D)
        xv = b * (2 * a - b) * (2 * b - g2) / (dt * D)
        xa = g2 * (4 * a * b + 2 * a * g2 - 2 * b**2 + b * g2 - 4 * g2) / (dt**2 * D)
        va = 2 * b * g2 * (2 * b - g2) / (dt**3 * D)
    return VRR3(*(_result(q) for q in (x, v, acc, xv, xa, va)))


@renamed_keywords(T="dt")
def benedict_bordner_vrr(alpha: ArrayLike, dt: ArrayLike = 1.0) -> VRR:
    r"""VRR of the Benedict-Bordner filter (beta = alpha^2 / (2 - alpha)) in closed form
    (eqs. 2-25 and 2-26; the cross term derived):

    .. math::

        \mathrm{VRR}(x) &= \frac{\alpha (6 - 5 \alpha)}{\alpha^2 - 8 \alpha + 8}, \qquad
        \mathrm{VRR}(v) = \frac{2 \alpha^3 / (2 - \alpha)}{\Delta t^2 (\alpha^2 - 8 \alpha + 8)},
        \\
        C_{xv} / s &= \frac{\alpha^2 (4 - 3 \alpha)}{\Delta t\, (2 - \alpha)
            (\alpha^2 - 8 \alpha + 8)}

    The Benedict-Bordner gains are stable only for ``alpha < 4 - 2 sqrt(2) = 1.1716``
    (beta < 4 - 2 alpha); beyond, the result is nan, as for :func:`vrr`.
    """
    a = _array(alpha, "alpha")
    if not np.all((a > 0) & (a < 2)):
        raise ValueError(f"alpha = {np.asarray(alpha).tolist()!r}; expected 0 < alpha < 2")
    dt = _positive(dt, "dt")
    q = np.where(a < 4 - 2 * math.sqrt(2), a**2 - 8 * a + 8, np.nan)
    return VRR(_result(a * (6 - 5 * a) / q), _result(2 * a**3 / (2 - a) / (dt**2 * q)),
               _result(a**2 * (4 - 3 * a) / (dt * (2 - a) * q)))


@renamed_keywords(T="dt")
def fading_memory_vrr(xi: ArrayLike, dt: ArrayLike = 1.0) -> VRR:
    r"""VRR of the fading-memory alpha-beta filter in closed form (0 <= xi < 1; eqs. 2-29,
    2-30 corrected, and 2-31):

    .. math::

        \mathrm{VRR}(x) &= \frac{(1 - \xi) (1 + 4 \xi + 5 \xi^2)}{(1 + \xi)^3} \\
        C_{xv} / s &= \frac{(1 - \xi)^2 (1 + 3 \xi)}{\Delta t\, (1 + \xi)^3} \\
        \mathrm{VRR}(v) &= \frac{2 (1 - \xi)^3}{\Delta t^2 (1 + \xi)^3}

    The thesis's 2-30 prints (as far as it can be read) ``(1 - xi)^2 (1 + 2 xi + 3 xi^2)``
    in the numerator, which disagrees with the general formula 2-17; the corrected form
    above is 2-17 at alpha = 1 - xi^2, beta = (1 - xi)^2.
    """
    x = _check_xi(xi)
    if not np.all(x < 1):
        raise ValueError(f"xi = {np.asarray(xi).tolist()!r}; expected 0 <= xi < 1 "
                         "(xi = 1 has zero gains and no steady state)")
    dt = _positive(dt, "dt")
    c = (1 + x) ** 3
    return VRR(_result((1 - x) * (1 + 4 * x + 5 * x**2) / c),
               _result(2 * (1 - x) ** 3 / (dt**2 * c)),
               _result((1 - x) ** 2 * (1 + 3 * x) / (dt * c)))


@renamed_keywords(T="dt")
def steady_state_cov(alpha: ArrayLike, beta: ArrayLike, gamma: ArrayLike | None = None,
                     dt: ArrayLike = 1.0, sigma: ArrayLike = 1.0) -> Array:
    """Steady-state covariance of one coordinate's smoothed state on pure measurement
    noise of standard deviation ``sigma``: ``(..., 2, 2)`` over (x, v) from eq. 2-17
    (:func:`vrr`), or with ``gamma`` ``(..., 3, 3)`` over (x, v, a) (:func:`vrr_abg`).
    Batched over gains, dt and sigma; nan outside the stability region."""
    s2 = _positive(sigma, "sigma") ** 2
    if gamma is None:
        r = vrr(alpha, beta, dt)
        rows = [[r.x, r.xv], [r.xv, r.v]]
    else:
        r = vrr_abg(alpha, beta, gamma, dt)
        rows = [[r.x, r.xv, r.xa], [r.xv, r.v, r.va], [r.xa, r.va, r.a]]
    shape = np.broadcast_shapes(*(np.shape(e) for row in rows for e in row), np.shape(s2))
    C = np.stack([np.stack([np.broadcast_to(e, shape) for e in row], -1) for row in rows], -2)
    return C * np.asarray(s2)[..., None, None]


def characteristic_polynomial(alpha: ArrayLike, beta: ArrayLike,
                              gamma: ArrayLike | None = None) -> Array:
    r"""Coefficients, highest power first, of ``det(z I - A)``, ``A = (I - K G) Phi``
    (independent of dt), for the alpha-beta (2-20) and alpha-beta-gamma (2-49) filters:

    .. math::

        &z^2 + (\alpha + \beta - 2) z + (1 - \alpha) \\
        &z^3 + (\alpha + \beta + \gamma - 3) z^2 + (3 - 2 \alpha - \beta + \gamma) z
            - (1 - \alpha)

    (acceleration gain 2 gamma / dt^2). Shape ``(..., 3)`` or ``(..., 4)``."""
    a, b = _array(alpha, "alpha"), _array(beta, "beta")
    if gamma is None:
        cs = [np.ones_like(a + b), a + b - 2, 1 - a]
    else:
        g = _array(gamma, "gamma")
        cs = [np.ones_like(a + b + g), a + b + g - 3, 3 - 2 * a - b + g, a - 1]
    shape = np.broadcast_shapes(*(np.shape(c) for c in cs))
    return np.stack([np.broadcast_to(c, shape) for c in cs], -1)


def roots(alpha: ArrayLike, beta: ArrayLike, gamma: ArrayLike | None = None) -> Array:
    """Roots (poles) of :func:`characteristic_polynomial`, complex ``(..., 2)`` or
    ``(..., 3)``. Alpha-beta (2-22): ``z = 1 - (alpha + beta)/2 +- sqrt((alpha + beta)^2 -
    4 beta) / 2``; alpha-beta-gamma: eigenvalues of the companion matrix."""
    c = characteristic_polynomial(alpha, beta, gamma)
    if gamma is None:
        s = np.add(alpha, beta, dtype=float)
        disc = np.sqrt((s * s - 4 * np.asarray(beta, dtype=float)).astype(complex))
        centre = 1 - s / 2
        z1, z2 = np.broadcast_arrays(centre + disc / 2, centre - disc / 2)
        return np.stack([z1, z2], -1)
    companion = np.zeros(c.shape[:-1] + (3, 3))
    companion[..., 0, :] = -c[..., 1:]
    companion[..., 1, 0] = companion[..., 2, 1] = 1.0
    return np.linalg.eigvals(companion).astype(complex)


def is_stable(alpha: ArrayLike, beta: ArrayLike,
              gamma: ArrayLike | None = None) -> NDArray[np.bool_] | bool:
    """The root test: every root of the characteristic polynomial strictly inside the unit
    circle. Batched over arrays of gains."""
    out = np.max(np.abs(roots(alpha, beta, gamma)), axis=-1) < 1.0
    return bool(out) if out.ndim == 0 else out


# --------------------------------------------------------------------------------------------
# The thesis's recursion on plain arrays
# --------------------------------------------------------------------------------------------


class ABTrack(NamedTuple):
    """Output of :func:`alpha_beta_track`, each ``(K, ...)`` like z: smoothed position and
    velocity ``x_s, v_s`` at each scan and the prediction ``x_p, v_p`` for each scan made at
    the scan before (row 0, which has none, is nan)."""

    x_s: Array
    v_s: Array
    x_p: Array
    v_p: Array


class ABGTrack(NamedTuple):
    """Output of :func:`alpha_beta_gamma_track` (see :class:`ABTrack`), with the
    acceleration ``a_s`` and its prediction ``a_p``."""

    x_s: Array
    v_s: Array
    a_s: Array
    x_p: Array
    v_p: Array
    a_p: Array


def _track_inputs(z: ArrayLike, dt: ArrayLike, gains: dict[str, ArrayLike], where: str):
    z = np.asarray(z, dtype=float)
    if z.ndim < 1 or z.shape[0] < 1:
        raise ValueError(f"{where}: z has shape {z.shape}; expected (K, ...) with K >= 1 "
                         "scans on axis 0")
    if not np.all(np.isfinite(z)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(z))[0])
        raise ValueError(f"{where}: z[{', '.join(map(str, bad))}] = {z[bad]}; expected finite "
                         "measurements (the thesis's recursion has no missing scans; use "
                         "the filter class to coast through nan)")
    dt = _positive(dt, f"{where}: dt")
    out = []
    for name, g in gains.items():
        a = _array(g, f"{where}: {name}")
        try:
            out.append(np.broadcast_to(a, np.broadcast_shapes(a.shape, z.shape)))
        except ValueError:
            raise ValueError(f"{where}: {name} has shape {a.shape}, which does not broadcast "
                             f"against z {z.shape}; expected a scalar or per-scan gains "
                             "(K, 1, ...)") from None
    return z, dt, out


@renamed_keywords(T="dt")
def alpha_beta_track(z: ArrayLike, dt: ArrayLike, alpha: ArrayLike,
                     beta: ArrayLike) -> ABTrack:
    """The thesis's alpha-beta recursion with its start-up rules over measurements
    ``z (K, ...)`` of one coordinate, scans on axis 0, batched over the other axes::

        x_s(1) = x_p(2) = x0(1),   v_s(1) = 0                               (2-7, 2-8)
        x_s(2) = x0(2),            v_s(2) = (x0(2) - x0(1)) / dt              (2-9)
        for n >= 3:
            x_p(n) = x_s(n-1) + dt v_s(n-1)                                    (2-6)
            x_s(n) = x_p(n) + alpha (x0(n) - x_p(n))                          (2-4)
            v_s(n) = v_s(n-1) + (beta / dt) (x0(n) - x_p(n))                   (2-5)

    (x_s(2) is not printed; x0(2) is the natural choice, as in the missing-measurements thesis,
    section 2-3.) ``alpha`` and
    ``beta`` are scalars or broadcast against z (per-scan gains such as Simpson's,
    shape ``(K, 1, ...)``); ``dt`` the scan period (s).
    """
    z, dt, (a, b) = _track_inputs(z, dt, {"alpha": alpha, "beta": beta}, "alpha_beta_track")
    x_s, v_s = np.empty(z.shape), np.empty(z.shape)
    x_p, v_p = np.full(z.shape, np.nan), np.full(z.shape, np.nan)
    x_s[0], v_s[0] = z[0], 0.0
    for n in range(1, z.shape[0]):
        x_p[n] = x_s[n - 1] + dt * v_s[n - 1]
        v_p[n] = v_s[n - 1]
        if n == 1:
            x_s[n] = z[n]
            v_s[n] = (z[n] - z[n - 1]) / dt
            continue
        r = z[n] - x_p[n]
        x_s[n] = x_p[n] + a[n] * r
        v_s[n] = v_s[n - 1] + b[n] / dt * r
    return ABTrack(x_s, v_s, x_p, v_p)


@renamed_keywords(T="dt")
def alpha_beta_gamma_track(z: ArrayLike, dt: ArrayLike, alpha: ArrayLike, beta: ArrayLike,
                           gamma: ArrayLike) -> ABGTrack:
    """The thesis's alpha-beta-gamma recursion with its start-up rules over ``z (K, ...)``
    (see :func:`alpha_beta_track`), acceleration gain 2 gamma / dt^2::

        x_s(1) = x_p(2) = x0(1),   v_s(1) = a_s(1) = 0                          (2-37, 2-38)
        x_s(2) = x0(2),  v_s(2) = (x0(2) - x0(1)) / dt,  a_s(2) = 0             (2-38, 2-39)
        a_s(3) = (x0(3) + x0(1) - 2 x0(2)) / dt^2                                (2-40)
        x_s(3) = x0(3),  v_s(3) = (x0(3) - x0(2)) / dt + dt a_s(3) / 2
        for n >= 4:
            x_p(n) = x_s(n-1) + dt v_s(n-1) + (dt^2/2) a_s(n-1)                   (2-36)
            r      = x0(n) - x_p(n)
            x_s(n) = x_p(n) + alpha r                                           (2-33)
            v_s(n) = v_s(n-1) + dt a_s(n-1) + (beta / dt) r                       (2-34)
            a_s(n) = a_s(n-1) + (2 gamma / dt^2) r                               (2-35)

    x_s(2), x_s(3) and v_s(3) are not printed; they are taken from the polynomial through
    the measurements so far (the line through two, the parabola through three), which is
    also what 2-39 and 2-40 are.
    """
    z, dt, (a, b, g) = _track_inputs(z, dt, {"alpha": alpha, "beta": beta, "gamma": gamma},
                                    "alpha_beta_gamma_track")
    x_s, v_s, a_s = np.empty(z.shape), np.empty(z.shape), np.empty(z.shape)
    x_p, v_p, a_p = (np.full(z.shape, np.nan) for _ in range(3))
    x_s[0], v_s[0], a_s[0] = z[0], 0.0, 0.0
    for n in range(1, z.shape[0]):
        x_p[n] = x_s[n - 1] + dt * v_s[n - 1] + dt**2 / 2 * a_s[n - 1]
        v_p[n] = v_s[n - 1] + dt * a_s[n - 1]
        a_p[n] = a_s[n - 1]
        if n == 1:
            x_s[n], v_s[n], a_s[n] = z[n], (z[n] - z[n - 1]) / dt, 0.0
            continue
        if n == 2:
            a_s[n] = (z[n] + z[n - 2] - 2 * z[n - 1]) / dt**2
            x_s[n] = z[n]
            v_s[n] = (z[n] - z[n - 1]) / dt + dt * a_s[n] / 2
            continue
        r = z[n] - x_p[n]
        x_s[n] = x_p[n] + a[n] * r
        v_s[n] = v_s[n - 1] + dt * a_s[n - 1] + b[n] / dt * r
        a_s[n] = a_s[n - 1] + 2 * g[n] / dt**2 * r
    return ABGTrack(x_s, v_s, a_s, x_p, v_p, a_p)


# --------------------------------------------------------------------------------------------
# Block kernels: per-axis matrices acting on the [p..., v..., a...] state
# --------------------------------------------------------------------------------------------
#
# Phi and I - K G act on every coordinate alike, so the full matrices are (per-axis) (x) I_d.
# The kernels view a state as (..., m, d) and a covariance as (..., m, d, m, d) and apply the
# per-axis matrices by a few in-place elementwise operations on those views (m = 2 or 3), in
# a fixed order: a row's result does not depend on the batch it is in (bitwise), and the cost
# is O(m^2) numpy calls whatever the batch size.


def _coef(c, extra: int):
    """A per-axis coefficient (a float or an array over the batch axes) ready to multiply a
    block with ``extra`` trailing axes."""
    return c if np.ndim(c) == 0 else np.asarray(c)[(...,) + (None,) * extra]


def _phi_coeffs(m: int, dt) -> list:
    """``c_j = dt^j / j!``: the per-axis transition is ``Phi[i, i + j] = c_j`` (2-13, 2-41)."""
    return [1.0] + [dt**j / math.factorial(j) for j in range(1, m)]


def _batched(a: Array, batch: tuple[int, ...], core: int) -> Array:
    """A writable copy of ``a`` with its batch axes broadcast to ``batch``."""
    if a.shape[:a.ndim - core] == batch:
        return a.copy()
    return np.array(np.broadcast_to(a, batch + a.shape[a.ndim - core:]))


def _predict_mean(x4: Array, c: list, batch: tuple[int, ...]) -> Array:
    """``(Phi (x) I) x`` on ``x4 (..., m, d)``: ``x_i <- x_i + sum_{k>i} c_{k-i} x_k``."""
    m = x4.shape[-2]
    out = _batched(x4, batch, 2)
    for i in range(m):
        for k in range(i + 1, m):
            out[..., i, :] += _coef(c[k - i], 1) * x4[..., k, :]
    return out


def _predict_cov(P4: Array, c: list, batch: tuple[int, ...]) -> Array:
    """``(Phi (x) I) P (Phi (x) I)^T`` on ``P4 (..., m, d, m, d)``: rows, then columns."""
    m = P4.shape[-4]
    L = _batched(P4, batch, 4)
    for i in range(m):
        for k in range(i + 1, m):
            L[..., i, :, :, :] += _coef(c[k - i], 3) * P4[..., k, :, :, :]
    M = L.copy()
    for j in range(m):
        for k in range(j + 1, m):
            M[..., :, :, j, :] += _coef(c[k - j], 3) * L[..., :, :, k, :]
    return M


def _joseph(P4: Array, g: Array, R: Array, batch: tuple[int, ...]) -> Array:
    """``(I - K G) P (I - K G)^T + K R K^T`` with ``K = g (x) I_d``, ``g (..., m)`` and
    ``G = [1 0 (0)] (x) I_d``: per axis ``I - K G`` is the identity less g in the first
    column, and block (i, j) of ``K R K^T`` is ``g_i g_j R``. Not symmetrised."""
    m = P4.shape[-4]
    L = _batched(P4, batch, 4)
    for i in range(1, m):
        L[..., i, :, :, :] -= g[..., i, None, None, None] * P4[..., 0, :, :, :]
    L[..., 0, :, :, :] *= (1.0 - g[..., 0])[..., None, None, None]
    M = L.copy()
    for j in range(1, m):
        M[..., :, :, j, :] -= g[..., j, None, None, None] * L[..., :, :, 0, :]
    M[..., :, :, 0, :] *= (1.0 - g[..., 0])[..., None, None, None]
    gg = g[..., :, None] * g[..., None, :]
    M += gg[..., :, None, :, None] * R[..., None, :, None, :]
    return M


def _phi_full(c: list, m: int, d: int) -> Array:
    """The full transition ``Phi (x) I_d``, ``(..., m d, m d)`` (to compare a motion model's)."""
    batch = np.broadcast_shapes(*(np.shape(cj) for cj in c))
    out = np.zeros(batch + (m, d, m, d))
    for i in range(m):
        for j in range(i, m):
            out[..., i, :, j, :] = _coef(c[j - i], 2) * np.eye(d)
    return out.reshape(batch + (m * d, m * d))


#: transitions already found equal to the tracker's: (id(F), dt) -> weak reference to F
_checked: dict[tuple[int, float], weakref.ref] = {}


def _check_motion(motion: MotionModel, x: Array, dt, c: list, m: int, d: int, where: str) -> None:
    """A motion model must share the tracker's transition (Q alone is taken from it)."""
    n = m * d
    if getattr(motion, "dim_x", None) != n:
        raise ValueError(f"{where}: motion {type(motion).__name__} has "
                         f"{getattr(motion, 'dim_x', None)} states; the belief has {n}")
    F = motion.jacobian(x, dt)
    key = (id(F), float(dt)) if np.ndim(dt) == 0 else None
    ref = _checked.get(key) if key is not None else None
    if ref is not None and ref() is F:
        return
    F = np.asarray(F, dtype=float)
    if F.shape[-2:] != (n, n) or not np.allclose(F, _phi_full(c, m, d), rtol=1e-12,
                                                 atol=1e-12):
        model = "ConstantVelocity" if m == 2 else "ConstantAcceleration"
        raise ValueError(f"{where}: motion {type(motion).__name__} has another transition "
                         f"than the tracker's polynomial Phi; expected {model}(dim={d}, "
                         "q=...) (or None for Q = 0)")
    if key is not None:
        if len(_checked) > 1024:
            _checked.clear()
        try:
            _checked[key] = weakref.ref(F)
        except TypeError:  # not weak-referenceable: check every time
            pass


# --------------------------------------------------------------------------------------------
# The filters
# --------------------------------------------------------------------------------------------


class AlphaBetaBelief(NamedTuple):
    """Belief of the constant-gain trackers.

    ``mean (..., n)`` in the state ordering [x, y, vx, vy] (alpha-beta) or
    [x, y, vx, vy, ax, ay] (alpha-beta-gamma) for d = 2; ``cov (..., n, n)`` the exact
    covariance of the estimator's error; ``k (...)`` the measurements taken since the start
    or the last ``AlphaBeta.reset`` (the next update uses the gains of scan k + 1);
    ``tau (...)`` the time predicted since the row's last update (s), the dt of the next
    update's gains.
    """

    mean: Array
    cov: Array
    k: NDArray[np.int64]
    tau: Array

    def at(self, index) -> AlphaBetaBelief:
        """The belief at a batch index (every field indexed alike)."""
        batch = np.shape(self.mean)[:-1]
        return AlphaBetaBelief(
            np.asarray(self.mean)[index],
            np.broadcast_to(self.cov, batch + np.shape(self.cov)[-2:])[index],
            np.broadcast_to(self.k, batch)[index], np.broadcast_to(self.tau, batch)[index])


def _last_k_above(growing, alpha: Array) -> Array:
    """Per entry of ``alpha``, the largest scan k whose growing-memory gain ``growing(k)``
    exceeds alpha (0 if none): the gains fall with k from k = 3 on, so this is where the
    growing memory has narrowed to the constant gain. Integer bisection, batched."""
    lo = np.zeros(alpha.shape)  # growing(lo) > alpha holds (k = 0 by convention)
    hi = np.full(alpha.shape, 2.0**50)  # growing(hi) <= alpha for any alpha > 1e-14
    for _ in range(52):
        mid = np.floor((lo + hi) / 2)
        above = growing(np.maximum(mid, 1.0))[0] > alpha
        done = hi - lo <= 1
        lo = np.where(~done & above, mid, lo)
        hi = np.where(~done & ~above, mid, hi)
    return lo.astype(np.int64)


class _ConstantGain(Filter):
    """The shared constant-gain tracker; ``_m`` = 2 (alpha-beta) or 3 (alpha-beta-gamma)."""

    _m: int = 2
    _names: tuple[str, ...] = ("alpha", "beta")

    def __init__(self, gains: tuple, startup: str, switch_after: int | None) -> None:
        where = self.name
        if startup not in STARTUPS:
            raise ValueError(f"{where} startup = {startup!r}; expected one of {STARTUPS}")
        given = [g is not None for g in gains]
        if not all(given):
            if any(given) or startup != "simpson":
                missing = [n for n, g in zip(self._names, given, strict=True) if not g]
                raise ValueError(
                    f"{where}: {', '.join(missing)} not given; expected all of "
                    f"{', '.join(self._names)} (or none, with startup='simpson', for "
                    "growing-memory gains at every scan)")
            gains_arr = None
        else:
            gains_arr = tuple(_array(g, f"{where} {n}") for n, g in
                              zip(self._names, gains, strict=True))
            try:
                np.broadcast_shapes(*(g.shape for g in gains_arr))
            except ValueError:
                raise ValueError(f"{where}: gain shapes {[g.shape for g in gains_arr]} do "
                                 "not broadcast; expected scalars or arrays over the batch "
                                 "axes") from None
            ok = (in_stability_region(*gains_arr) if self._m == 2
                  else in_stability_region_abg(*gains_arr))
            if not np.all(ok):
                flat = [np.broadcast_to(g, np.shape(ok)).ravel() for g in gains_arr]
                i = int(np.flatnonzero(~np.ravel(ok))[0])
                bad = ", ".join(f"{n} = {float(g[i])!r}"
                                for n, g in zip(self._names, flat, strict=True))
                region = ("0 < alpha < 2, 0 < beta < 4 - 2 alpha" if self._m == 2 else
                          "0 < alpha < 2, 0 < beta < 4 - 2 alpha, "
                          "0 < gamma < alpha beta / (2 - alpha)")
                raise ValueError(f"{where}: {bad} is outside the stability region "
                                 f"({region}); the filter would diverge")
        if switch_after is not None:
            if startup != "simpson" or gains_arr is None:
                raise ValueError(f"{where} switch_after = {switch_after!r}; it applies only "
                                 "to startup='simpson' with constant gains given")
            if not (isinstance(switch_after, int | np.integer) and switch_after >= 0):
                raise ValueError(f"{where} switch_after = {switch_after!r}; expected an "
                                 "integer >= 0 (scans with growing-memory gains)")
        elif startup == "simpson" and gains_arr is not None:
            growing = simpson if self._m == 2 else simpson_abg
            switch_after = _last_k_above(lambda k: np.asarray(growing(k)), gains_arr[0])
            switch_after = int(switch_after) if switch_after.ndim == 0 else switch_after
        self.gains = gains_arr
        self.startup = startup
        self.switch_after = switch_after
        #: batch shape of per-row gains (or () for scalar gains)
        self._gain_shape = (() if gains_arr is None else
                            np.broadcast_shapes(*(g.shape for g in gains_arr),
                                                np.shape(switch_after)))

    # -- the gain schedule --------------------------------------------------------------------

    def scheduled_gains(self, k: ArrayLike) -> tuple[Array, ...]:
        """The gains ``(alpha, beta[, gamma])`` used at the k-th measurement (k >= 1).

        - ``"thesis"``: the start-up rules 2-7..2-9 / 2-37..2-40 as gains: k = 1 takes the
          position from the measurement and keeps the prior's velocity (and acceleration),
          ``(1, 0, 0)`` (the thesis's prior has them 0); k = 2 is the line through two
          points, ``(1, 1, 0)``; for alpha-beta-gamma k = 3 is the parabola through three,
          ``(1, 3/2, 1/2)`` (the dead-beat gains, :func:`fading_memory` at xi = 0); then
          the constant gains.
        - ``"prior"``: the constant gains from the first measurement (the prior is the
          initial state, as in FilterPy's g-h filters).
        - ``"simpson"``: growing-memory least-squares gains (:func:`simpson`,
          :func:`simpson_abg`) for k <= ``switch_after``, the constant gains after.
        """
        k = np.asarray(k)
        m = self._m
        if self.startup == "prior":
            return self.gains
        if self.startup == "thesis":
            if k.min(initial=m + 1) > m:
                return self.gains
            a = np.where(k <= m, 1.0, self.gains[0])
            b = np.where(k == 1, 0.0, np.where(k <= m, 1.0 if m == 2 else
                                               np.where(k == 2, 1.0, 1.5), self.gains[1]))
            if m == 2:
                return a, b
            return a, b, np.where(k == 3, 0.5, np.where(k < 3, 0.0, self.gains[2]))
        if self.gains is not None and k.min(initial=1) > np.max(self.switch_after):
            return self.gains
        kf = np.maximum(k, 1).astype(float)
        early = [np.asarray(e) for e in (simpson(kf) if m == 2 else simpson_abg(kf))]
        if self.gains is None:
            return tuple(early)
        use = k <= np.asarray(self.switch_after)
        return tuple(np.where(use, e, g) for e, g in zip(early, self.gains, strict=True))

    # -- the Filter interface -----------------------------------------------------------------

    def _dims(self, n: int, where: str) -> int:
        m = self._m
        if n % m or not 1 <= n // m <= 3:
            state = ("[x..., vx...]" if m == 2 else "[x..., vx..., ax...]")
            raise ValueError(f"{where}.mean has {n} components; expected {m} d for d = 1, 2 "
                             f"or 3 position coordinates, ordered {state}")
        return n // m

    def init(self, prior: Gaussian | AlphaBetaBelief) -> AlphaBetaBelief:
        """The belief from a Gaussian prior: ``k = 0``, ``tau = 0``, its batch shape
        broadcast with that of per-row gains. (An :class:`AlphaBetaBelief` is returned as
        it is.)"""
        if isinstance(prior, AlphaBetaBelief):
            return prior
        x, P = check_belief(prior, None, f"{self.name}.init prior")
        self._dims(x.shape[-1], f"{self.name}.init prior")
        batch = np.broadcast_shapes(x.shape[:-1], self._gain_shape)  # a row per gain set
        if x.shape[:-1] != batch:
            x = np.broadcast_to(x, batch + x.shape[-1:])
        return AlphaBetaBelief(x, P, np.zeros(batch, np.int64), np.zeros(batch))

    def estimate(self, belief: AlphaBetaBelief) -> Gaussian:
        return Gaussian._make((belief.mean, belief.cov))

    def reset(self, belief: AlphaBetaBelief, rows: ArrayLike | None = None) -> AlphaBetaBelief:
        """Restart the scan count at 1 (the next measurement is scan 1 of the start-up or of
        Simpson's gains) for the rows where ``rows`` is true (a mask broadcasting to the
        batch shape), or for every row; mean and covariance are kept."""
        b = self.init(belief)
        batch = np.shape(b.mean)[:-1]
        if rows is None:
            return b._replace(k=np.zeros(batch, np.int64))
        mask = np.asarray(rows)
        if mask.dtype != bool:
            raise ValueError(f"{self.name}.reset rows has dtype {mask.dtype}; expected a "
                             "boolean mask over the batch axes")
        try:
            k = np.where(mask, 0, np.broadcast_to(b.k, batch))
        except ValueError:
            raise ValueError(f"{self.name}.reset rows has shape {mask.shape}; expected a mask "
                             f"broadcasting to the batch shape {batch}") from None
        if k.shape != batch:
            raise ValueError(f"{self.name}.reset rows has shape {mask.shape}; expected a mask "
                             f"broadcasting to the batch shape {batch}")
        return b._replace(k=k.astype(np.int64))

    def predict(self, belief: Gaussian | AlphaBetaBelief, motion: MotionModel | None,
                dt: ArrayLike) -> AlphaBetaBelief:
        """``x- = Phi x`` (2-6, 2-36, per coordinate), ``P- = Phi P Phi^T + Q`` and
        ``tau += dt``.

        ``motion`` gives Q (``motion.noise``) and must have the same transition as the
        tracker (``ConstantVelocity(dim=d, q=...)`` for alpha-beta,
        ``ConstantAcceleration`` for alpha-beta-gamma), so that P is the true error
        covariance when the target moves by that model; ``None`` means Q = 0.
        """
        b = self.init(belief)
        where = f"{self.name}.predict"
        x, P = check_belief(b, None, f"{where} belief")
        check_dt(dt, where)
        m = self._m
        n = x.shape[-1]
        d = self._dims(n, f"{where} belief")
        T = float(dt) if np.ndim(dt) == 0 else np.asarray(dt, dtype=float)
        c = _phi_coeffs(m, T)
        batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2], np.shape(T),
                                    np.shape(b.k), np.shape(b.tau))
        Pp = _predict_cov(P.reshape(P.shape[:-2] + (m, d, m, d)), c, batch).reshape(
            batch + (n, n))
        if motion is not None:
            _check_motion(motion, x, dt, c, m, d, where)
            Pp += np.asarray(motion.noise(x, dt), dtype=float)
        xp = _predict_mean(x.reshape(x.shape[:-1] + (m, d)), c, batch).reshape(batch + (n,))
        k, tau = np.asarray(b.k), np.asarray(b.tau + T)
        return AlphaBetaBelief(xp, register(symmetrize(Pp)),
                               k if k.shape == batch else np.broadcast_to(k, batch),
                               tau if tau.shape == batch else np.broadcast_to(tau, batch))

    def update(self, belief: Gaussian | AlphaBetaBelief, z: ArrayLike,
               sensor: SensorModel) -> tuple[AlphaBetaBelief, Innovation]:
        """``nu = z - H x-``, ``x+ = x- + K nu``, ``P+ = (I - K H) P- (I - K H)^T + K R K^T``
        with ``K = [alpha, beta/tau, 2 gamma/tau^2]^T (x) I_d`` at the row's scan count
        (:meth:`scheduled_gains`); the innovation covariance is ``S = H P- H^T + R``.

        ``sensor`` measures position, ``z = [x, y] + v`` (``tk.models.Position``,
        ``H = [I 0]``, R from ``sensor.noise``). Rows with nan in z coast: they keep the
        prediction, their scan count and their tau (so the next gains span the gap), and
        their residual is nan.
        """
        b = self.init(belief)
        where = f"{self.name}.update"
        x, P = check_belief(b, None, f"{where} belief")
        m = self._m
        n = x.shape[-1]
        d = self._dims(n, f"{where} belief")
        if not (type(sensor) is Position and sensor.dim == d) and not (
                getattr(sensor, "linear", False) and getattr(sensor, "dim_z", None) == d
                and np.array_equal(sensor.jacobian(x[(0,) * (x.ndim - 1)]), np.eye(d, n))):
            raise ValueError(f"{where}: sensor {type(sensor).__name__} does not measure the "
                             f"{d} position coordinates (H = [I 0]); expected "
                             f"tk.models.Position(dim={d})")
        z = check_measurement(z, d, where, x.shape[:-1])
        miss = missing_rows(z)
        batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2], z.shape[:-1], np.shape(b.k),
                                    np.shape(b.tau), self._gain_shape)
        got = None if miss is None else ~np.broadcast_to(miss, batch)
        k = b.k + 1 if got is None else np.where(got, b.k + 1, b.k)
        gains = self.scheduled_gains(np.maximum(k, 1))
        tau = np.asarray(b.tau, dtype=float)
        needs_T = (gains[1] != 0) | (gains[2] != 0) if m == 3 else gains[1] != 0
        bad = needs_T & ~(tau > 0) if got is None else needs_T & ~(tau > 0) & got
        if np.any(bad):
            raise ValueError(f"{where}: tau = 0 (no time predicted since the last update) in "
                             f"{int(np.sum(np.broadcast_to(bad, batch)))} row(s) whose gains "
                             "need the scan period; expected a predict by dt before each "
                             "update")
        T = np.where(tau > 0, tau, 1.0)
        g = [gains[0], gains[1] / T] + ([2 * gains[2] / T**2] if m == 3 else [])
        K = np.empty(np.broadcast_shapes(*(np.shape(gi) for gi in g)) + (m,))
        for i, gi in enumerate(g):  # K per axis, (..., m)
            K[..., i] = gi
        r = z - x[..., :d]
        if got is not None:
            r = np.where(got[..., None], r, 0.0)
        R = np.asarray(sensor.noise, dtype=float)
        Pn = _joseph(P.reshape(P.shape[:-2] + (m, d, m, d)), K, R, batch).reshape(
            batch + (n, n))
        xn = (x.reshape(x.shape[:-1] + (m, d)) + K[..., :, None] * r[..., None, :]).reshape(
            batch + (n,))
        Pn = symmetrize(Pn)
        S = P[..., :d, :d] + R
        tau_new = np.zeros(batch)
        if got is not None:
            xn = np.where(got[..., None], xn, x)
            Pn = np.where(got[..., None, None], Pn, P)
            r = np.where(got[..., None], r, np.nan)
            tau_new = np.where(got, 0.0, tau)
        k = np.asarray(k, dtype=np.int64)
        out = AlphaBetaBelief(xn, register(Pn), k if k.shape == batch else
                              np.broadcast_to(k, batch), tau_new)
        return out, Innovation(r if r.shape[:-1] == batch else
                               np.broadcast_to(r, batch + (d,)), S)


class AlphaBeta(_ConstantGain):
    """The alpha-beta tracker (the missing-measurements thesis, section 2-3), batched, with d = 1..3
    position coordinates filtered alike; state [x, y, vx, vy] for d = 2.

    ``AlphaBeta(alpha, beta)`` has the thesis's start-up rules (``startup="thesis"``);
    ``startup="prior"`` uses the constant gains from the first scan (the prior is the
    initial state, as FilterPy's ``GHFilter``); ``AlphaBeta(startup="simpson")`` uses
    Simpson's growing-memory gains at every scan, and
    ``AlphaBeta(alpha, beta, startup="simpson", switch_after=k0)`` for scans 1..k0 and the
    constant gains after (by default k0 is the last scan whose Simpson alpha_k exceeds
    alpha). ``reset`` restarts the scan count for chosen rows (a manoeuvre, a model
    change). Gains are scalars or arrays over the batch axes (one gain pair per row, for
    tuning), and must lie in the stability region.

    Memory is the :class:`AlphaBetaBelief` (``f.init(prior)``; a Gaussian given to
    predict or update is initialised on the spot). See the module docstring for the
    equations and the covariance.
    """

    name = "AlphaBeta"
    _m = 2
    _names = ("alpha", "beta")

    def __init__(self, alpha: ArrayLike | None = None, beta: ArrayLike | None = None, *,
                 startup: str = "thesis", switch_after: int | None = None) -> None:
        super().__init__((alpha, beta), startup, switch_after)


class AlphaBetaGamma(_ConstantGain):
    """The alpha-beta-gamma tracker (the missing-measurements thesis, section 2-4), acceleration
    gain 2 gamma / dt^2; state [x, y, vx, vy, ax, ay] for d = 2. Options as :class:`AlphaBeta`;
    Simpson's gains are the growing-memory quadratic (:func:`simpson_abg`)."""

    name = "AlphaBetaGamma"
    _m = 3
    _names = ("alpha", "beta", "gamma")

    def __init__(self, alpha: ArrayLike | None = None, beta: ArrayLike | None = None,
                 gamma: ArrayLike | None = None, *, startup: str = "thesis",
                 switch_after: int | None = None) -> None:
        super().__init__((alpha, beta, gamma), startup, switch_after)
