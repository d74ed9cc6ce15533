r"""Motion models :math:`\mathbf{x}_{k+1} = f(\mathbf{x}_k, \Delta t) + \mathbf{w}`,
:math:`\mathbf{w} \sim \mathcal{N}\bigl(0, Q(\mathbf{x}_k, \Delta t)\bigr)`.

Each model is a small frozen dataclass with vectorised methods over leading batch axes:
``f(x, dt)``, ``jacobian(x, dt)`` (shape broadcastable to ``(..., n, n)``) and
``noise(x, dt)`` (Q, broadcastable to ``(..., n, n)``). ``dt`` is a float or an array that
broadcasts against the batch axes (asynchronous steps). State ordering (trackkit's convention):
positions, then velocities, then accelerations, then extras.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from math import factorial
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.models.discretize import discretize
from trackkit.models.protocols import MotionModel

__all__ = [
    "MotionModel",
    "MotionBase",
    "LinearMotion",
    "ContinuousLinear",
    "ConstantVelocity",
    "ConstantAcceleration",
    "Singer",
    "KnownTurnRate",
    "CoordinatedTurn",
    "RandomSine",
    "Augmented",
]

Array = NDArray[np.float64]


def _apply(F: Array, x: Array) -> Array:
    """``F x`` for ``F`` of shape ``(n, n)`` or ``(..., n, n)`` and ``x`` of shape ``(..., n)``."""
    if F.ndim == 2:
        return F.dot(x) if x.ndim == 1 else x @ F.T  # dot: half the cost for one state
    return np.einsum("...ij,...j->...i", F, x)


def _per_axis(value: ArrayLike, dim: int, name: str) -> Array:
    v = np.broadcast_to(np.asarray(value, dtype=float), (dim,)) if np.ndim(value) == 0 else (
        np.asarray(value, dtype=float)
    )
    if v.shape != (dim,):
        raise ValueError(f"{name} has shape {v.shape}; expected a scalar or ({dim},)")
    if np.any(v < 0) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} = {v.tolist()}; expected finite values >= 0")
    return v


def interleave_axes(B: Array, per_axis: Array) -> Array:
    """Interleave a per-axis block into the state ordering [pos..., vel..., acc...].

    ``B`` has shape ``(..., k, k)`` (one axis's block, e.g. [[1, dt], [0, 1]]) and the result
    has ``result[..., i*d + a, j*d + b] = B[..., i, j] * per_axis[a] * (a == b)``.
    """
    d = per_axis.shape[0]
    k = B.shape[-1]
    out = B[..., :, None, :, None] * np.diag(per_axis)[:, None, :]
    return out.reshape(B.shape[:-2] + (k * d, k * d))


def _dt(dt: ArrayLike) -> Array:
    return np.asarray(dt, dtype=float)


_SCALARS = (float, int)


def _memo(model: object, kind: str, dt: ArrayLike, build) -> Array:
    """``build(dt)``, remembered per model for scalar steps (most runs use one or two dt).

    Cached matrices are read-only so that no caller can change a model by accident.
    """
    if not isinstance(dt, _SCALARS) and np.ndim(dt) != 0:
        return build(dt)
    cache = model.__dict__.get("_cache")
    if cache is None:
        cache = model.__dict__["_cache"] = {}
    key = (kind, float(dt))
    value = cache.get(key)
    if value is None:
        value = build(dt)
        for a in value if isinstance(value, tuple) else (value,):
            a.flags.writeable = False
        if len(cache) > 512:
            cache.clear()
        cache[key] = value
    return value


class MotionBase:
    """Shared base of the bundled motion models: the optional members' defaults and
    ``noise_cov``. A model need only satisfy :class:`MotionModel`."""

    dim_x: int
    linear: bool = False
    #: which state components are angles (wrapped in residuals, averaged circularly)
    angular: tuple[bool, ...] | None = None
    #: the state components' names where the model fixes them (None: not named)
    state_names: ClassVar[tuple[str, ...] | None] = None

    def f(self, x: Array, dt: ArrayLike) -> Array:  # pragma: no cover - interface
        raise NotImplementedError

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:  # pragma: no cover - interface
        raise NotImplementedError

    def noise(self, x: Array, dt: ArrayLike) -> Array:  # pragma: no cover - interface
        raise NotImplementedError

    def noise_cov(self, x: Array, dt: ArrayLike) -> Array:
        """Q, the covariance of the process noise over the step ``dt`` from ``x``
        (broadcastable to ``(..., n, n)``): read as ``sensor.noise_cov(x)`` reads R."""
        return self.noise(x, dt)


@dataclass(frozen=True, eq=False)
class LinearMotion(MotionBase):
    """``x' = F x + w``, ``w ~ N(0, Q)`` with constant F and Q (``dt`` is ignored)."""

    F: Array
    Q: Array
    linear: bool = field(default=True, init=False)

    def __post_init__(self) -> None:
        F = np.asarray(self.F, dtype=float)
        Q = np.asarray(self.Q, dtype=float)
        if F.ndim != 2 or F.shape[0] != F.shape[1] or Q.shape != F.shape:
            raise ValueError(f"F has shape {F.shape} and Q {Q.shape}; expected both (n, n)")
        F, Q = F.copy(), Q.copy()
        F.flags.writeable = Q.flags.writeable = False  # returned as they are: keep them safe
        object.__setattr__(self, "F", F)
        object.__setattr__(self, "Q", Q)

    @property
    def dim_x(self) -> int:
        return self.F.shape[0]

    def f(self, x: Array, dt: ArrayLike = 0.0) -> Array:
        return _apply(self.F, x)

    def jacobian(self, x: Array, dt: ArrayLike = 0.0) -> Array:
        return self.F

    def noise(self, x: Array, dt: ArrayLike = 0.0) -> Array:
        return self.Q


@dataclass(frozen=True, eq=False)
class ContinuousLinear(MotionBase):
    """``dx/dt = A x + L w`` with white ``w`` of spectral density ``Qc``, discretised exactly
    (Van Loan) for each ``dt``."""

    A: Array
    L: Array
    Qc: Array
    linear: bool = field(default=True, init=False)

    @property
    def dim_x(self) -> int:
        return np.shape(self.A)[0]

    def matrices(self, dt: ArrayLike) -> tuple[Array, Array]:
        return _memo(self, "FQ", dt, lambda t: discretize(self.A, self.L, self.Qc, t))

    def f(self, x: Array, dt: ArrayLike) -> Array:
        return _apply(self.matrices(dt)[0], x)

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        return self.matrices(dt)[0]

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        return self.matrices(dt)[1]


@dataclass(frozen=True, eq=False)
class _NearlyConstant(MotionBase):
    """The white-noise derivative family: the k-th derivative of position is white noise of
    spectral density q, state [p..., v..., (a...)] with k blocks per axis.

    Per axis, exactly: F_ij = dt^(j-i) / (j-i)! for j >= i, and
    Q_ij = q dt^(2k-1-i-j) / ((k-1-i)! (k-1-j)! (2k-1-i-j)).
    """

    dim: int = 2
    q: ArrayLike = 1.0
    linear: bool = field(default=True, init=False)
    _order: ClassVar[int] = 2

    def __post_init__(self) -> None:
        if self.dim not in (1, 2, 3):
            raise ValueError(f"dim = {self.dim!r}; expected 1, 2 or 3")
        object.__setattr__(self, "q", _per_axis(self.q, self.dim, "q"))

    @property
    def dim_x(self) -> int:
        return self._order * self.dim

    def _F(self, dt: ArrayLike) -> Array:
        return _memo(self, "F", dt, self._build_F)

    def _build_F(self, dt: ArrayLike) -> Array:
        dt, k = _dt(dt), self._order
        B = np.zeros(dt.shape + (k, k))
        for i in range(k):
            for j in range(i, k):
                B[..., i, j] = dt ** (j - i) / factorial(j - i)
        return interleave_axes(B, np.ones(self.dim))

    def f(self, x: Array, dt: ArrayLike) -> Array:
        return _apply(self._F(dt), x)

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        return self._F(dt)

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        return _memo(self, "Q", dt, self._build_Q)

    def _build_Q(self, dt: ArrayLike) -> Array:
        dt, k = _dt(dt), self._order
        B = np.zeros(dt.shape + (k, k))
        for i in range(k):
            for j in range(k):
                p = 2 * k - 1 - i - j
                B[..., i, j] = dt**p / (factorial(k - 1 - i) * factorial(k - 1 - j) * p)
        return interleave_axes(B, self.q)


@dataclass(frozen=True, eq=False)
class ConstantVelocity(_NearlyConstant):
    r"""Nearly constant velocity (continuous white-noise acceleration), state [p..., v...].

    Per axis with spectral density q:

    .. math::

        F = \begin{bmatrix} 1 & \Delta t \\ 0 & 1 \end{bmatrix}, \qquad
        Q = q \begin{bmatrix} \Delta t^3/3 & \Delta t^2/2 \\ \Delta t^2/2 & \Delta t
        \end{bmatrix}

    ``q`` is a scalar or one value per axis.
    """

    _order: ClassVar[int] = 2


@dataclass(frozen=True, eq=False)
class ConstantAcceleration(_NearlyConstant):
    r"""Nearly constant acceleration (continuous white-noise jerk), state [p..., v..., a...].

    Per axis with spectral density q:

    .. math::

        F = \begin{bmatrix} 1 & \Delta t & \Delta t^2/2 \\ 0 & 1 & \Delta t \\ 0 & 0 & 1
        \end{bmatrix}, \qquad
        Q = q \begin{bmatrix}
            \Delta t^5/20 & \Delta t^4/8 & \Delta t^3/6 \\
            \Delta t^4/8 & \Delta t^3/3 & \Delta t^2/2 \\
            \Delta t^3/6 & \Delta t^2/2 & \Delta t
        \end{bmatrix}
    """

    _order: ClassVar[int] = 3


@dataclass(frozen=True, eq=False)
class Singer(MotionBase):
    r"""Singer manoeuvre model: acceleration is a first-order Gauss-Markov process.

    Per axis, with white noise :math:`w` of spectral density :math:`2 \sigma^2 / \tau` so that
    the stationary acceleration standard deviation is ``sigma``; state [p..., v..., a...]:

    .. math::

        \dot a = -\frac{a}{\tau} + w

    F and Q are the exact discretisation (Van Loan), which equals Singer's closed form
    (Singer 1970); with :math:`\alpha = 1/\tau`, :math:`T = \Delta t` and
    :math:`E = e^{-\alpha T}`:

    .. math::

        F = \begin{bmatrix}
            1 & T & (\alpha T - 1 + E) / \alpha^2 \\
            0 & 1 & (1 - E) / \alpha \\
            0 & 0 & E
        \end{bmatrix}, \qquad
        Q = 2 \alpha \sigma^2 \begin{bmatrix}
            q_{11} & q_{12} & q_{13} \\ q_{12} & q_{22} & q_{23} \\ q_{13} & q_{23} & q_{33}
        \end{bmatrix}

    .. math::

        q_{11} &= \bigl(1 - E^2 + 2 \alpha T + \tfrac23 (\alpha T)^3 - 2 (\alpha T)^2
            - 4 \alpha T E\bigr) / (2 \alpha^5), \\
        q_{12} &= \bigl(E^2 + 1 - 2 E + 2 \alpha T E - 2 \alpha T + (\alpha T)^2\bigr)
            / (2 \alpha^4), \qquad
        q_{13} = (1 - E^2 - 2 \alpha T E) / (2 \alpha^3), \\
        q_{22} &= (4 E - 3 - E^2 + 2 \alpha T) / (2 \alpha^3), \qquad
        q_{23} = (E^2 + 1 - 2 E) / (2 \alpha^2), \qquad
        q_{33} = (1 - E^2) / (2 \alpha)
    """

    dim: int = 2
    tau: float = 20.0
    sigma: ArrayLike = 1.0
    linear: bool = field(default=True, init=False)

    def __post_init__(self) -> None:
        if self.dim not in (1, 2, 3):
            raise ValueError(f"dim = {self.dim!r}; expected 1, 2 or 3")
        if not (np.isfinite(self.tau) and self.tau > 0):
            raise ValueError(f"tau = {self.tau!r}; expected a finite time constant > 0 s")
        object.__setattr__(self, "sigma", _per_axis(self.sigma, self.dim, "sigma"))

    @property
    def dim_x(self) -> int:
        return 3 * self.dim

    def _axis(self, dt: ArrayLike) -> tuple[Array, Array]:
        """One axis's F and Q (spectral density 2 sigma^2 / tau folded in per axis later).

        Van Loan for a dt / tau < 1; Singer's closed form beyond, where Van Loan's
        exp(+dt/tau) block loses precision and the closed form no longer cancels.
        """
        dt = _dt(dt)
        a = 1.0 / self.tau
        long = a * dt >= 1.0
        A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -a]])
        L = np.array([[0.0], [0.0], [1.0]])
        Fv, Qv = discretize(A, L, [[2.0 * a]], np.where(long, 0.0, dt))
        Fc, Qc = _singer_closed_form(np.where(long, dt, self.tau), a)
        sel = long[..., None, None]
        return np.where(sel, Fc, Fv), np.where(sel, Qc, Qv)

    def f(self, x: Array, dt: ArrayLike) -> Array:
        return _apply(self.jacobian(x, dt), x)

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        return _memo(self, "F", dt, lambda t: interleave_axes(self._axis(t)[0], np.ones(self.dim)))

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        return _memo(self, "Q", dt, lambda t: interleave_axes(self._axis(t)[1], self.sigma**2))


def _singer_closed_form(T: Array, a: float) -> tuple[Array, Array]:
    """Singer (1970) F and Q per axis for unit stationary acceleration variance
    (spectral density q = 2a), with a = 1/tau and step T."""
    e1, e2, aT = np.exp(-a * T), np.exp(-2 * a * T), a * T
    one, zero = np.ones_like(T), np.zeros_like(T)
    F = np.stack([np.stack([one, T, (aT - 1 + e1) / a**2], -1),
                  np.stack([zero, one, (1 - e1) / a], -1),
                  np.stack([zero, zero, e1], -1)], -2)
    q = 2 * a
    q11 = (1 - e2 + 2 * aT + 2 * aT**3 / 3 - 2 * aT**2 - 4 * aT * e1) / (2 * a**5)
    q12 = (e2 + 1 - 2 * e1 + 2 * aT * e1 - 2 * aT + aT**2) / (2 * a**4)
    q13 = (1 - e2 - 2 * aT * e1) / (2 * a**3)
    q22 = (4 * e1 - 3 - e2 + 2 * aT) / (2 * a**3)
    q23 = (e2 + 1 - 2 * e1) / (2 * a**2)
    q33 = (1 - e2) / (2 * a)
    Q = q * np.stack([np.stack([q11, q12, q13], -1), np.stack([q12, q22, q23], -1),
                      np.stack([q13, q23, q33], -1)], -2)
    return F, Q


def turn_coefficients(w: Array, dt: Array) -> tuple[Array, Array, Array, Array, Array, Array]:
    """``s = sin(w dt)/w``, ``c = (1 - cos(w dt))/w``, their w-derivatives, cos and sin.

    Near ``w = 0`` the ratios are evaluated by their Taylor series (to w^3), so CT is smooth
    through straight-line motion.
    """
    wt = w * dt
    small = np.abs(wt) < 1e-3
    ws = np.where(small, 1.0, w)  # safe divisor
    sin, cos = np.sin(wt), np.cos(wt)
    w2, w3, dt2, dt3, dt4 = w**2, w**3, dt**2, dt**3, dt**4
    versin, ws2 = 1 - cos, ws**2
    s = np.where(small, dt - w2 * dt3 / 6, sin / ws)
    c = np.where(small, w * dt2 / 2 - w3 * dt4 / 24, versin / ws)
    ds = np.where(small, -w * dt3 / 3 + w3 * dt**5 / 30, (wt * cos - sin) / ws2)
    dc = np.where(small, dt2 / 2 - w2 * dt4 / 8, (wt * sin - versin) / ws2)
    return s, c, ds, dc, cos, sin


def turn_transition(w: Array, dt: Array) -> Array:
    s, c, _, _, cos, sin = turn_coefficients(w, dt)
    return _turn_block(s, c, cos, sin)


def _turn_block(s: Array, c: Array, cos: Array, sin: Array) -> Array:
    """The 4 x 4 transition of [x, y, vx, vy] from the coefficients of
    :func:`turn_coefficients`."""
    one, zero = np.ones_like(s), np.zeros_like(s)
    return np.stack(
        [
            np.stack([one, zero, s, -c], -1),
            np.stack([zero, one, c, s], -1),
            np.stack([zero, zero, cos, -sin], -1),
            np.stack([zero, zero, sin, cos], -1),
        ],
        -2,
    )


@dataclass(frozen=True, eq=False)
class KnownTurnRate(MotionBase):
    r"""Constant turn at a known rate ``omega`` (rad/s, positive counter-clockwise), state
    [x, y, vx, vy]; Q is the constant-velocity Q with density q. The transition, with
    :math:`s = \sin(\omega \Delta t)/\omega` and :math:`c = (1 - \cos(\omega \Delta t))/\omega`
    (their limits :math:`\Delta t` and 0 as :math:`\omega \to 0`):

    .. math::

        F(\omega) = \begin{bmatrix}
            1 & 0 & s & -c \\
            0 & 1 & c & s \\
            0 & 0 & \cos \omega \Delta t & -\sin \omega \Delta t \\
            0 & 0 & \sin \omega \Delta t & \cos \omega \Delta t
        \end{bmatrix}
    """

    omega: float = 0.0
    q: ArrayLike = 1.0
    linear: bool = field(default=True, init=False)
    dim_x: int = field(default=4, init=False)

    def __post_init__(self) -> None:
        if not np.isfinite(self.omega):
            raise ValueError(f"omega = {self.omega!r}; expected a finite turn rate (rad/s)")
        object.__setattr__(self, "q", _per_axis(self.q, 2, "q"))

    def f(self, x: Array, dt: ArrayLike) -> Array:
        return _apply(self.jacobian(x, dt), x)

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        return _memo(self, "F", dt,
                     lambda t: turn_transition(np.asarray(float(self.omega)), _dt(t)))

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        return _memo(self, "Q", dt, lambda t: ConstantVelocity(2, self.q).noise(x, t))


@dataclass(frozen=True, eq=False)
class CoordinatedTurn(MotionBase):
    r"""Coordinated turn with the turn rate in the state, [x, y, vx, vy, omega].

    With :math:`s = \sin(\omega \Delta t)/\omega` and
    :math:`c = (1 - \cos(\omega \Delta t))/\omega` (omega positive counter-clockwise):

    .. math::

        x' &= x + s\, v_x - c\, v_y, \qquad y' = y + c\, v_x + s\, v_y, \\
        \begin{bmatrix} v_x' \\ v_y' \end{bmatrix} &=
        \begin{bmatrix} \cos \omega \Delta t & -\sin \omega \Delta t \\
            \sin \omega \Delta t & \cos \omega \Delta t \end{bmatrix}
        \begin{bmatrix} v_x \\ v_y \end{bmatrix}, \qquad \omega' = \omega

    Q is the CV Q (density q) on the kinematic block and ``q_omega dt`` on omega:

    .. math::

        Q = \begin{bmatrix} Q_{CV}(\Delta t) & 0 \\ 0 & q_\omega \Delta t \end{bmatrix}
    """

    q: ArrayLike = 1.0
    q_omega: float = 1e-4
    dim_x: int = field(default=5, init=False)
    state_names: ClassVar[tuple[str, ...] | None] = ("x", "y", "vx", "vy", "turn_rate")

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", _per_axis(self.q, 2, "q"))
        if not (np.isfinite(self.q_omega) and self.q_omega >= 0):
            raise ValueError(f"q_omega = {self.q_omega!r}; expected a finite value >= 0")

    def f(self, x: Array, dt: ArrayLike) -> Array:
        dt = _dt(dt)
        return self._f(x, dt, turn_coefficients(x[..., 4], dt))

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        dt = _dt(dt)
        return self._jacobian(x, dt, turn_coefficients(x[..., 4], dt))

    def f_and_jacobian(self, x: Array, dt: ArrayLike) -> tuple[Array, Array]:
        """``(f(x, dt), jacobian(x, dt))`` from one evaluation of the turn coefficients (a
        subclass that overrides f or jacobian gets its own two)."""
        t = type(self)
        if t is not CoordinatedTurn and (t.f is not CoordinatedTurn.f
                                         or t.jacobian is not CoordinatedTurn.jacobian):
            return self.f(x, dt), self.jacobian(x, dt)
        dt = _dt(dt)
        k = turn_coefficients(x[..., 4], dt)
        return self._f(x, dt, k), self._jacobian(x, dt, k)

    @staticmethod
    def _f(x: Array, dt: Array, k: tuple[Array, ...]) -> Array:
        px, py, vx, vy, w = (x[..., i] for i in range(5))
        s, c, _, _, cos, sin = k
        return np.stack(
            [px + s * vx - c * vy, py + c * vx + s * vy, cos * vx - sin * vy,
             sin * vx + cos * vy, w + 0 * dt],
            -1,
        )

    @staticmethod
    def _jacobian(x: Array, dt: Array, k: tuple[Array, ...]) -> Array:
        vx, vy, w = x[..., 2], x[..., 3], x[..., 4]
        s, c, ds, dc, cos, sin = k
        J = np.zeros(np.broadcast_shapes(w.shape, dt.shape) + (5, 5))
        J[..., :4, :4] = _turn_block(s, c, cos, sin)
        J[..., 0, 4] = ds * vx - dc * vy
        J[..., 1, 4] = dc * vx + ds * vy
        J[..., 2, 4] = -dt * (sin * vx + cos * vy)
        J[..., 3, 4] = dt * (cos * vx - sin * vy)
        J[..., 4, 4] = 1.0
        return J

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        dt = _dt(dt)
        Q = np.zeros(dt.shape + (5, 5))
        Q[..., :4, :4] = ConstantVelocity(2, self.q).noise(x, dt)
        Q[..., 4, 4] = self.q_omega * dt
        return Q


@dataclass(frozen=True, eq=False)
class RandomSine(MotionBase):
    """The random-sine example of the missing-measurements thesis (sections 2-5-5-2 and 2-5-6-4):
    state [theta, omega, a], phase, angular velocity and amplitude; omega and a are random walks.

    F = [[1, dt, 0], [0, 1, 0], [0, 0, 1]],
    Q = [[q1 dt^3/3, q1 dt^2/2, 0], [q1 dt^2/2, q1 dt, 0], [0, 0, q2 dt]].
    The two-state variant of section 4-4, [theta, omega] is ``ConstantVelocity(dim=1, q=q1)``.
    """

    q1: float = 0.2
    q2: float = 0.1
    linear: bool = field(default=True, init=False)
    dim_x: int = field(default=3, init=False)

    def __post_init__(self) -> None:
        for name in ("q1", "q2"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} = {v!r}; expected a finite value >= 0")

    def _F(self, dt: ArrayLike) -> Array:
        return _memo(self, "F", dt, self._build_F)

    def _build_F(self, dt: ArrayLike) -> Array:
        dt = _dt(dt)
        F = np.broadcast_to(np.eye(3), dt.shape + (3, 3)).copy()
        F[..., 0, 1] = dt
        return F

    def f(self, x: Array, dt: ArrayLike) -> Array:
        return _apply(self._F(dt), x)

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        return self._F(dt)

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        return _memo(self, "Q", dt, self._build_Q)

    def _build_Q(self, dt: ArrayLike) -> Array:
        dt = _dt(dt)
        Q = np.zeros(dt.shape + (3, 3))
        Q[..., :2, :2] = ConstantVelocity(1, self.q1).noise(None, dt)
        Q[..., 2, 2] = self.q2 * dt
        return Q


@dataclass(frozen=True, eq=False)
class Augmented(MotionBase):
    """A kinematic model with ``extras`` nearly constant components appended to the state,
    e.g. the radiated frequency f0 of Doppler-bearing tracking: ``[kinematics, f0]``.

    F = blockdiag(F_base, I), Q = blockdiag(Q_base, q_extra dt I) (a random walk with
    spectral density ``q_extra``; 0 keeps them constant).
    """

    base: MotionModel
    extras: int = 1
    q_extra: float = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.extras, int) and self.extras >= 1):
            raise ValueError(f"extras = {self.extras!r}; expected an integer >= 1")
        if not (np.isfinite(self.q_extra) and self.q_extra >= 0):
            raise ValueError(f"q_extra = {self.q_extra!r}; expected a finite value >= 0")

    @property
    def dim_x(self) -> int:
        return self.base.dim_x + self.extras

    @property
    def linear(self) -> bool:  # type: ignore[override]
        return bool(getattr(self.base, "linear", False))

    def f(self, x: Array, dt: ArrayLike) -> Array:
        nb = self.base.dim_x
        head = self.base.f(x[..., :nb], dt)
        tail = np.broadcast_to(x[..., nb:], head.shape[:-1] + (self.extras,))
        return np.concatenate([head, tail], -1)

    def _blockdiag(self, A: Array, B: Array) -> Array:
        nb, n = A.shape[-1], self.dim_x
        shape = np.broadcast_shapes(A.shape[:-2], B.shape[:-2]) + (n, n)
        out = np.zeros(shape)
        out[..., :nb, :nb] = A
        out[..., nb:, nb:] = B
        return out

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        J = np.asarray(self.base.jacobian(x[..., : self.base.dim_x], dt))
        if J.ndim == 2:
            return _memo(self, "F", dt, lambda t: self._blockdiag(J, np.eye(self.extras)))
        return self._blockdiag(J, np.eye(self.extras))

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        Q = np.asarray(self.base.noise(x if x is None else x[..., : self.base.dim_x], dt))
        if Q.ndim == 2:
            return _memo(self, "Q", dt, lambda t: self._blockdiag(
                Q, self.q_extra * float(t) * np.eye(self.extras)))
        dt = _dt(dt)
        return self._blockdiag(Q, self.q_extra * dt[..., None, None] * np.eye(self.extras))
