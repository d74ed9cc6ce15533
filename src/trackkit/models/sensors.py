r"""Sensor models :math:`\mathbf{z} = h(\mathbf{x}) + \mathbf{v}`,
:math:`\mathbf{v} \sim \mathcal{N}(0, R)`.

Each sensor is a small frozen dataclass with vectorised ``h(x)`` (``(..., m)``),
``jacobian(x)`` (``(..., m, n)``), ``hessian(x)`` (``(..., m, n, n)``), the measurement
noise covariance ``noise`` (R, ``(m, m)``) and ``residual(z, zhat)``, which wraps the angle
components to (-pi, pi]. ``angular`` marks those components. The sensor pose (``origin``,
``velocity``) is a field that may carry batch axes, so a moving observer is either a new small
object per step or one object whose pose has the batch shape.

Sensors read the target position from the first ``d`` state components (and the velocity from
the next ``d`` where they need it), so one sensor serves CV, CA, CT and DBT states alike.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import block_diag

from trackkit.angles import wrap
from trackkit.models.protocols import SensorModel

__all__ = [
    "SensorModel",
    "SensorBase",
    "Position",
    "Bearing",
    "RangeBearing",
    "AzimuthElevation",
    "BearingFrequency",
    "MultipathDelay",
    "Sine",
    "Stack",
]

Array = NDArray[np.float64]


def _positive(value: ArrayLike, name: str, shape: tuple[int, ...] = ()) -> Array:
    v = np.asarray(value, dtype=float)
    if shape and v.ndim == 0:
        v = np.broadcast_to(v, shape)
    if v.shape != shape or not np.all(np.isfinite(v)) or not np.all(v > 0):
        want = "a positive number" if not shape else f"a positive number or shape {shape}"
        raise ValueError(f"{name} = {np.asarray(value).tolist()!r}; expected {want}")
    return v


def _pose(value: ArrayLike, name: str, d: int) -> Array:
    v = np.asarray(value, dtype=float)
    if v.ndim < 1 or v.shape[-1] != d or not np.all(np.isfinite(v)):
        raise ValueError(
            f"{name} has shape {v.shape}; expected finite values of shape (..., {d})"
        )
    return v


def _own(sensor: SensorModel, cls: type) -> bool:
    """Whether ``sensor`` uses ``cls``'s own h and jacobian (a subclass that overrides
    either must not get ``cls``'s fused ``linearize``)."""
    t = type(sensor)
    return t is cls or (t.h is cls.h and t.jacobian is cls.jacobian)


def _offset(x: Array, origin: Array) -> tuple[Array, Array]:
    """``x[..., 0] - origin[..., 0]`` and the same for component 1, as contiguous arrays
    (numpy's transcendental loops are several times slower on strided views)."""
    return x[..., 0] - origin[..., 0], x[..., 1] - origin[..., 1]


def wrap_small(a: Array) -> Array:
    """``wrap(a)`` for a float array, returning ``a`` itself when every entry is within
    (-3, 3): there ``wrap`` is the identity (``ceil((a - pi) / (2 pi))`` is -0), so the
    common case of small angle residuals costs two reductions instead of a dozen passes."""
    if a.size and -3.0 < a.min() and a.max() < 3.0:  # false for nan
        return a
    return wrap(a)


def _bearing_gradient(u: Array, v: Array, r2: Array, convention: str, out_u: Array,
                      out_v: Array) -> None:
    """The bearing's gradient over (u, v), ``sign * (v, -u) / r^2``, written into two
    (strided) views. (Negating before dividing: numpy 2.4's ``np.negative`` with a strided
    ``out`` and a strided input reads the input as if contiguous.)"""
    if convention == "nautical":
        np.divide(v, r2, out=out_u)
        np.divide(-u, r2, out=out_v)
    else:
        np.divide(-v, r2, out=out_u)
        np.divide(u, r2, out=out_v)


def check_convention(convention: str) -> None:
    if convention not in ("nautical", "math"):
        raise ValueError(f"convention = {convention!r}; expected 'nautical' or 'math'")


def _pad(J: Array, n: int) -> Array:
    """Place a Jacobian over the leading state components into ``n`` columns."""
    k = J.shape[-1]
    if k == n:
        return J
    out = np.zeros(J.shape[:-1] + (n,))
    out[..., :k] = J
    return out


def _pad2(Hs: Array, n: int) -> Array:
    k = Hs.shape[-1]
    if k == n:
        return Hs
    out = np.zeros(Hs.shape[:-2] + (n, n))
    out[..., :k, :k] = Hs
    return out


def _norm_grad_hess(w: Array) -> tuple[Array, Array, Array]:
    """``|w|``, its gradient ``w/|w|`` and Hessian ``(I - w w^T/|w|^2)/|w|``."""
    r = np.linalg.norm(w, axis=-1)
    g = w / r[..., None]
    eye = np.eye(w.shape[-1])
    H = (eye - g[..., :, None] * g[..., None, :]) / r[..., None, None]
    return r, g, H


def _bearing_terms(u: Array, v: Array, convention: str) -> tuple[Array, Array, Array]:
    """Bearing of (u, v) east/north, its gradient over (u, v) and its 2x2 Hessian."""
    r2 = u * u + v * v
    sign = 1.0 if convention == "nautical" else -1.0
    b = np.arctan2(u, v) if convention == "nautical" else np.arctan2(v, u)
    g = sign * np.stack([v / r2, -u / r2], -1)
    huu, huv = -2 * u * v / r2**2, (u * u - v * v) / r2**2
    H = sign * np.stack([np.stack([huu, huv], -1), np.stack([huv, -huu], -1)], -2)
    return b, g, H


class SensorBase:
    """Shared behaviour of the bundled sensors: angle-aware residuals, R built once, and
    ``noise_cov``. A sensor need only satisfy :class:`SensorModel`."""

    dim_z: int
    angular: tuple[bool, ...]
    linear: bool = False

    @property
    def noise(self) -> Array:
        """R, built once per sensor (read-only)."""
        R = self.__dict__.get("_R")
        if R is None:
            R = np.asarray(self._noise(), dtype=float)
            R.flags.writeable = False
            self.__dict__["_R"] = R
        return R

    def _noise(self) -> Array:  # pragma: no cover - interface
        raise NotImplementedError

    def noise_cov(self, x: Array | None = None) -> Array:
        """R, the covariance of the measurement noise at ``x`` (``(..., m, m)``): read as
        ``motion.noise_cov(x, dt)`` reads Q. A bundled sensor's R does not depend on x."""
        return self.noise

    def _angle_mask(self):
        """None (no angle components), True (all) or the boolean mask; cached per sensor."""
        try:
            return self.__dict__["_angle_mask_"]
        except KeyError:
            ang = tuple(self.angular)
            mask = None if not any(ang) else True if all(ang) else np.asarray(ang)
            self.__dict__["_angle_mask_"] = mask
            return mask

    def residual(self, z: Array, zhat: Array) -> Array:
        """``z - zhat`` with the angle components wrapped to (-pi, pi]."""
        r = z - zhat
        mask = self._angle_mask()
        if mask is None:
            return r
        if mask is True:
            return wrap_small(r)
        if r.ndim == 0 or r.shape[-1] != mask.size:
            return np.where(mask, wrap(r), r)
        # r is a fresh array: wrap only its angle columns, in place (a range or a Doppler
        # column is left alone rather than wrapped and then thrown away)
        for j in np.flatnonzero(mask):
            a = r[..., j]
            w = wrap_small(a)
            if w is not a:
                r[..., j] = w
        return r

    def linearize(self, x: Array) -> tuple[Array, Array]:
        """``(h(x), jacobian(x))`` together (sensors override it to share the work)."""
        return self.h(x), self.jacobian(x)


@dataclass(frozen=True, eq=False)
class Position(SensorBase):
    """Position of dimension ``dim`` (the first ``dim`` state components); linear."""

    dim: int = 2
    sigma: ArrayLike = 1.0
    linear: bool = field(default=True, init=False)

    def __post_init__(self) -> None:
        if self.dim not in (1, 2, 3):
            raise ValueError(f"dim = {self.dim!r}; expected 1, 2 or 3")
        object.__setattr__(self, "sigma", _positive(self.sigma, "sigma", (self.dim,)))

    @property
    def dim_z(self) -> int:
        return self.dim

    @property
    def angular(self) -> tuple[bool, ...]:
        return (False,) * self.dim

    def _noise(self) -> Array:
        return np.diag(self.sigma**2)

    def h(self, x: Array) -> Array:
        return x[..., : self.dim]

    def jacobian(self, x: Array) -> Array:
        n = x.shape[-1]
        try:
            return self.__dict__["_H"][n]
        except KeyError:
            H = np.eye(self.dim, n)
            H.flags.writeable = False
            self.__dict__.setdefault("_H", {})[n] = H
            return H

    def linearize(self, x: Array) -> tuple[Array, Array]:
        if type(self) is Position or _own(self, Position):
            return x[..., : self.dim], self.jacobian(x)
        return self.h(x), self.jacobian(x)

    def hessian(self, x: Array) -> Array:
        return np.zeros(x.shape[:-1] + (self.dim, x.shape[-1], x.shape[-1]))


@dataclass(frozen=True, eq=False)
class Bearing(SensorBase):
    r"""2-D bearing from ``origin`` :math:`(x_o, y_o)` to the target, z = [b]: nautical
    (default, clockwise from north) or ``convention="math"`` (counter-clockwise from east):

    .. math::

        b_{\text{nautical}} = \operatorname{atan2}(x - x_o,\; y - y_o), \qquad
        b_{\text{math}} = \operatorname{atan2}(y - y_o,\; x - x_o)

    ``velocity`` is the observer's velocity (default at rest): h does not use it, but a filter
    whose state is relative to the observer does (the modified-polar EKF).
    """

    origin: ArrayLike = (0.0, 0.0)
    sigma: float = 0.01
    convention: str = "nautical"
    velocity: ArrayLike = (0.0, 0.0)
    dim_z: int = field(default=1, init=False)
    angular: tuple[bool, ...] = field(default=(True,), init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _pose(self.origin, "origin", 2))
        object.__setattr__(self, "velocity", _pose(self.velocity, "velocity", 2))
        object.__setattr__(self, "sigma", float(_positive(self.sigma, "sigma")))
        check_convention(self.convention)

    def _noise(self) -> Array:
        return np.array([[self.sigma**2]])

    def _terms(self, x: Array) -> tuple[Array, Array, Array]:
        return _bearing_terms(*_offset(x, self.origin), self.convention)

    def _bearing(self, u: Array, v: Array) -> Array:
        b = np.arctan2(u, v) if self.convention == "nautical" else np.arctan2(v, u)
        return b[..., None]

    def _jacobian(self, u: Array, v: Array, n: int) -> Array:
        """``sign * [v, -u] / r^2`` in the first two of n columns (sign -1 for "math")."""
        r2 = u * u + v * v
        J = np.zeros(r2.shape + (1, n))
        _bearing_gradient(u, v, r2, self.convention, J[..., 0, 0], J[..., 0, 1])
        return J

    def h(self, x: Array) -> Array:
        return self._bearing(*_offset(x, self.origin))

    def jacobian(self, x: Array) -> Array:
        return self._jacobian(*_offset(x, self.origin), x.shape[-1])

    def linearize(self, x: Array) -> tuple[Array, Array]:
        if not _own(self, Bearing):
            return self.h(x), self.jacobian(x)
        u, v = _offset(x, self.origin)
        return self._bearing(u, v), self._jacobian(u, v, x.shape[-1])

    def hessian(self, x: Array) -> Array:
        return _pad2(self._terms(x)[2][..., None, :, :], x.shape[-1])


@dataclass(frozen=True, eq=False)
class RangeBearing(SensorBase):
    r"""2-D radar: z = [range, bearing] from ``origin`` :math:`(x_o, y_o)`; the bearing's
    convention as :class:`Bearing`'s (nautical shown):

    .. math::

        h(\mathbf{x}) = \begin{bmatrix}
            \sqrt{(x - x_o)^2 + (y - y_o)^2} \\
            \operatorname{atan2}(x - x_o,\; y - y_o)
        \end{bmatrix}
    """

    origin: ArrayLike = (0.0, 0.0)
    sigma_range: float = 1.0
    sigma_bearing: float = 0.01
    convention: str = "nautical"
    dim_z: int = field(default=2, init=False)
    angular: tuple[bool, ...] = field(default=(False, True), init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _pose(self.origin, "origin", 2))
        object.__setattr__(self, "sigma_range", float(_positive(self.sigma_range, "sigma_range")))
        object.__setattr__(
            self, "sigma_bearing", float(_positive(self.sigma_bearing, "sigma_bearing"))
        )
        check_convention(self.convention)

    def _noise(self) -> Array:
        return np.diag([self.sigma_range**2, self.sigma_bearing**2])

    def _h(self, u: Array, v: Array) -> Array:
        out = np.empty(np.broadcast_shapes(u.shape, v.shape) + (2,))
        np.hypot(u, v, out=out[..., 0])
        if self.convention == "nautical":
            np.arctan2(u, v, out=out[..., 1])
        else:
            np.arctan2(v, u, out=out[..., 1])
        return out

    def _jacobian(self, u: Array, v: Array, n: int) -> Array:
        """Rows ``[u, v] / r`` and ``sign * [v, -u] / r^2`` (sign -1 for "math")."""
        r2 = u * u + v * v
        r = np.sqrt(r2)
        J = np.zeros(r.shape + (2, n))
        np.divide(u, r, out=J[..., 0, 0])
        np.divide(v, r, out=J[..., 0, 1])
        _bearing_gradient(u, v, r2, self.convention, J[..., 1, 0], J[..., 1, 1])
        return J

    def h(self, x: Array) -> Array:
        return self._h(*_offset(x, self.origin))

    def jacobian(self, x: Array) -> Array:
        return self._jacobian(*_offset(x, self.origin), x.shape[-1])

    def linearize(self, x: Array) -> tuple[Array, Array]:
        if not _own(self, RangeBearing):
            return self.h(x), self.jacobian(x)
        u, v = _offset(x, self.origin)
        return self._h(u, v), self._jacobian(u, v, x.shape[-1])

    def hessian(self, x: Array) -> Array:
        d = x[..., :2] - self.origin
        _, _, Hr = _norm_grad_hess(d)
        _, _, Hb = _bearing_terms(d[..., 0], d[..., 1], self.convention)
        return _pad2(np.stack([Hr, Hb], -3), x.shape[-1])


@dataclass(frozen=True, eq=False)
class AzimuthElevation(SensorBase):
    """3-D angles from ``origin``: z = [azimuth, elevation] (Naseri Solhdar, chapter 5).

    azimuth as ``Bearing`` on (x, y) (nautical by default; the thesis measures it from the x
    axis, ``convention="math"``); elevation ``atan2(dz, sqrt(dx^2 + dy^2))``, up positive.
    """

    origin: ArrayLike = (0.0, 0.0, 0.0)
    sigma_az: float = 0.01
    sigma_el: float = 0.01
    convention: str = "nautical"
    dim_z: int = field(default=2, init=False)
    angular: tuple[bool, ...] = field(default=(True, True), init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _pose(self.origin, "origin", 3))
        object.__setattr__(self, "sigma_az", float(_positive(self.sigma_az, "sigma_az")))
        object.__setattr__(self, "sigma_el", float(_positive(self.sigma_el, "sigma_el")))
        check_convention(self.convention)

    def _noise(self) -> Array:
        return np.diag([self.sigma_az**2, self.sigma_el**2])

    def h(self, x: Array) -> Array:
        d = x[..., :3] - self.origin
        az, _, _ = _bearing_terms(d[..., 0], d[..., 1], self.convention)
        el = np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1]))
        return np.stack([az, el], -1)

    def jacobian(self, x: Array) -> Array:
        d = x[..., :3] - self.origin
        u, v, w = d[..., 0], d[..., 1], d[..., 2]
        rho2 = u * u + v * v
        rho, R2 = np.sqrt(rho2), rho2 + w * w
        _, gaz, _ = _bearing_terms(u, v, self.convention)
        gaz = np.concatenate([gaz, np.zeros_like(u)[..., None]], -1)
        gel = np.stack([-u * w / (R2 * rho), -v * w / (R2 * rho), rho / R2], -1)
        return _pad(np.stack([gaz, gel], -2), x.shape[-1])

    def hessian(self, x: Array) -> Array:
        """Analytic: azimuth as the 2-D bearing; elevation ``e = atan2(w, rho)`` with
        ``e_p = (-w p / rho, rho) / R^2`` differentiated once more (p = (u, v))."""
        d = x[..., :3] - self.origin
        u, v, w = d[..., 0], d[..., 1], d[..., 2]
        rho2 = u * u + v * v
        rho, R2 = np.sqrt(rho2), rho2 + w * w
        _, _, Haz2 = _bearing_terms(u, v, self.convention)
        Haz = np.zeros(u.shape + (3, 3))
        Haz[..., :2, :2] = Haz2
        # e_u = -u w / (R2 rho) = -w * g(u, v, w) with g = u / (R2 rho); likewise for v.
        # d(1/(R2 rho))/du = -(2u rho + R2 u / rho) / (R2 rho)^2
        inv = 1.0 / (R2 * rho)
        dinv_du = -u * (2 * rho + R2 / rho) * inv**2
        dinv_dv = -v * (2 * rho + R2 / rho) * inv**2
        dinv_dw = -(2 * w * rho) * inv**2
        Hel = np.empty(u.shape + (3, 3))
        Hel[..., 0, 0] = -w * (inv + u * dinv_du)
        Hel[..., 0, 1] = Hel[..., 1, 0] = -w * u * dinv_dv
        Hel[..., 1, 1] = -w * (inv + v * dinv_dv)
        Hel[..., 0, 2] = Hel[..., 2, 0] = -u * (inv + w * dinv_dw)
        Hel[..., 1, 2] = Hel[..., 2, 1] = -v * (inv + w * dinv_dw)
        Hel[..., 2, 2] = -2 * w * rho / R2**2
        return _pad2(np.stack([Haz, Hel], -3), x.shape[-1])


@dataclass(frozen=True, eq=False)
class BearingFrequency(SensorBase):
    r"""Doppler-bearing sensor (Hashemi and Alfi 2019): z = [bearing, received frequency].

    State [x, y, vx, vy, f0]; ``origin`` and ``velocity`` are the observer's. With
    :math:`\mathbf{d}` = target - observer (position), :math:`r = \lVert \mathbf{d} \rVert`
    and :math:`\Delta\mathbf{v}` the relative velocity, the bearing (nautical), the range rate
    :math:`V_D` (positive opening) and the received frequency are

    .. math::

        b = \operatorname{atan2}(d_x, d_y), \qquad
        V_D = \frac{\Delta\mathbf{v} \cdot \mathbf{d}}{r}, \qquad
        f = f_0 \Bigl(1 - \frac{V_D}{c}\Bigr)

    ``c`` (sound speed, m/s) defaults to 1500.
    """

    origin: ArrayLike = (0.0, 0.0)
    velocity: ArrayLike = (0.0, 0.0)
    sigma_bearing: float = 0.01
    sigma_freq: float = 0.1
    c: float = 1500.0
    dim_z: int = field(default=2, init=False)
    angular: tuple[bool, ...] = field(default=(True, False), init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _pose(self.origin, "origin", 2))
        object.__setattr__(self, "velocity", _pose(self.velocity, "velocity", 2))
        object.__setattr__(
            self, "sigma_bearing", float(_positive(self.sigma_bearing, "sigma_bearing"))
        )
        object.__setattr__(self, "sigma_freq", float(_positive(self.sigma_freq, "sigma_freq")))
        object.__setattr__(self, "c", float(_positive(self.c, "c")))

    def _noise(self) -> Array:
        return np.diag([self.sigma_bearing**2, self.sigma_freq**2])

    def _check(self, x: Array) -> None:
        if x.shape[-1] != 5:
            raise ValueError(
                f"BearingFrequency needs the state [x, y, vx, vy, f0]; got length {x.shape[-1]}"
            )

    def h(self, x: Array) -> Array:
        self._check(x)
        d, dv = x[..., :2] - self.origin, x[..., 2:4] - self.velocity
        r = np.hypot(d[..., 0], d[..., 1])
        vd = (d * dv).sum(-1) / r
        return np.stack([np.arctan2(d[..., 0], d[..., 1]), x[..., 4] * (1 - vd / self.c)], -1)

    def jacobian(self, x: Array) -> Array:
        self._check(x)
        d, dv = x[..., :2] - self.origin, x[..., 2:4] - self.velocity
        u, v = d[..., 0], d[..., 1]
        r = np.hypot(u, v)
        k = x[..., 4] / self.c
        cross = dv[..., 0] * v - dv[..., 1] * u
        vd = (d * dv).sum(-1) / r
        zero = np.zeros_like(u)
        rb = np.stack([v / r**2, -u / r**2, zero, zero, zero], -1)
        rf = np.stack(
            [-k * v * cross / r**3, k * u * cross / r**3, -k * u / r, -k * v / r,
             1 - vd / self.c], -1,
        )
        return np.stack([rb, rf], -2)

    def linearize(self, x: Array) -> tuple[Array, Array]:
        """``(h(x), jacobian(x))``, the shared terms once and the rows written in place: the
        same operations, so the same bits (a Doppler-bearing EKF calls it every step)."""
        self._check(x)
        d, dv = x[..., :2] - self.origin, x[..., 2:4] - self.velocity
        u, v = d[..., 0], d[..., 1]
        r = np.hypot(u, v)
        vd = (d * dv).sum(-1) / r
        z = np.empty(x.shape[:-1] + (2,))
        z[..., 0] = np.arctan2(u, v)
        z[..., 1] = x[..., 4] * (1 - vd / self.c)
        k = x[..., 4] / self.c
        cross = dv[..., 0] * v - dv[..., 1] * u
        r2, r3 = r**2, r**3
        H = np.zeros(x.shape[:-1] + (2, 5))
        H[..., 0, 0], H[..., 0, 1] = v / r2, -u / r2
        H[..., 1, 0], H[..., 1, 1] = -k * v * cross / r3, k * u * cross / r3
        H[..., 1, 2], H[..., 1, 3] = -k * u / r, -k * v / r
        H[..., 1, 4] = 1 - vd / self.c
        return z, H

    def hessian(self, x: Array) -> Array:
        """Analytic. With V_D(d, dv) = dv.d / r: grad_d V_D = dv/r - (dv.d) d / r^3 and
        Hess_dd V_D = -(dv d^T + d dv^T)/r^3 - (dv.d) I / r^3 + 3 (dv.d) d d^T / r^5,
        Hess_d,dv V_D = I/r - d d^T / r^3; f = f0 (1 - V_D/c) is bilinear in f0 and V_D."""
        self._check(x)
        d, dv = x[..., :2] - self.origin, x[..., 2:4] - self.velocity
        u, v = d[..., 0], d[..., 1]
        r = np.hypot(u, v)
        dd = (d * dv).sum(-1)
        outer = d[..., :, None] * d[..., None, :]
        eye = np.eye(2)
        r3, r5 = (r**3)[..., None, None], (r**5)[..., None, None]
        Hdd = (
            -(dv[..., :, None] * d[..., None, :] + d[..., :, None] * dv[..., None, :]) / r3
            - dd[..., None, None] * eye / r3
            + 3 * dd[..., None, None] * outer / r5
        )
        Hdv = eye / r[..., None, None] - outer / r3
        grad_vd = np.concatenate(
            [dv / r[..., None] - dd[..., None] * d / r3[..., 0], d / r[..., None]], -1
        )
        k = (x[..., 4] / self.c)[..., None, None]
        Hf = np.zeros(u.shape + (5, 5))
        Hf[..., :2, :2] = -k * Hdd
        Hf[..., :2, 2:4] = -k * Hdv
        Hf[..., 2:4, :2] = -k * np.swapaxes(Hdv, -1, -2)
        Hf[..., :4, 4] = -grad_vd / self.c
        Hf[..., 4, :4] = -grad_vd / self.c
        _, _, Hb2 = _bearing_terms(u, v, "nautical")
        Hb = np.zeros(u.shape + (5, 5))
        Hb[..., :2, :2] = Hb2
        return np.stack([Hb, Hf], -3)


@dataclass(frozen=True, eq=False)
class MultipathDelay(SensorBase):
    """Surface and bottom multipath delays at one hydrophone (Naseri Solhdar, chapter 4).

    z = [tau1, tau2]: the surface-reflected and bottom-reflected arrival times minus the
    direct one. By the image method, with d = target - sensor (z up), ``R = |d|``,
    ``S1 = |d - 2 h_s e_z|`` and ``S2 = |d + 2 h_b e_z|``:
    ``tau1 = (S1 - R)/c`` and ``tau2 = (S2 - R)/c``, where ``h_surface`` is the sensor's depth
    below the surface and ``h_bottom`` its height above the floor. Equal to eqs 4-1 and 4-2;
    the tau2 Jacobian is the corrected one ((dz + 2 h_b)/S2, not the thesis's minus sign).
    """

    origin: ArrayLike = (0.0, 0.0, 0.0)
    h_surface: float = 50.0
    h_bottom: float = 50.0
    sigma: ArrayLike = 1e-4
    c: float = 1500.0
    dim_z: int = field(default=2, init=False)
    angular: tuple[bool, ...] = field(default=(False, False), init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _pose(self.origin, "origin", 3))
        object.__setattr__(self, "h_surface", float(_positive(self.h_surface, "h_surface")))
        object.__setattr__(self, "h_bottom", float(_positive(self.h_bottom, "h_bottom")))
        object.__setattr__(self, "sigma", _positive(self.sigma, "sigma", (2,)))
        object.__setattr__(self, "c", float(_positive(self.c, "c")))

    def _noise(self) -> Array:
        return np.diag(self.sigma**2)

    def _images(self, x: Array) -> tuple[Array, Array, Array]:
        d = x[..., :3] - self.origin
        return d, d - [0.0, 0.0, 2 * self.h_surface], d + [0.0, 0.0, 2 * self.h_bottom]

    def h(self, x: Array) -> Array:
        d, s1, s2 = (np.linalg.norm(w, axis=-1) for w in self._images(x))
        return np.stack([s1 - d, s2 - d], -1) / self.c

    def jacobian(self, x: Array) -> Array:
        (_, g, _), (_, g1, _), (_, g2, _) = (_norm_grad_hess(w) for w in self._images(x))
        return _pad(np.stack([g1 - g, g2 - g], -2) / self.c, x.shape[-1])

    def hessian(self, x: Array) -> Array:
        (_, _, H), (_, _, H1), (_, _, H2) = (_norm_grad_hess(w) for w in self._images(x))
        return _pad2(np.stack([H1 - H, H2 - H], -3) / self.c, x.shape[-1])

    def inverse(self, z: ArrayLike) -> tuple[Array, Array]:
        """Closed-form inverse (eqs 4-3, 4-4): delays -> (slant range R, vertical offset dz).

        R = [4 h_s h_b (h_s + h_b) - c^2 (tau1^2 h_b + tau2^2 h_s)] / [2 c (tau1 h_b + tau2 h_s)]
        dz = (tau2^2 c^2 + 2 R tau2 c - 4 h_b^2) / (4 h_b)
        """
        z = np.asarray(z, dtype=float)
        t1, t2 = z[..., 0], z[..., 1]
        hs, hb, c = self.h_surface, self.h_bottom, self.c
        R = (4 * hs * hb * (hs + hb) - c**2 * (t1**2 * hb + t2**2 * hs)) / (
            2 * c * (t1 * hb + t2 * hs)
        )
        dz = (t2**2 * c**2 + 2 * R * t2 * c - 4 * hb**2) / (4 * hb)
        return R, dz


@dataclass(frozen=True, eq=False)
class Sine(SensorBase):
    """The sine measurement of the missing-measurements thesis: ``y = a sin(theta)`` on the state
    [theta, omega, a] (sections 2-5-5-2 and 2-5-6-4), or ``y = sin(theta)`` on [theta, omega] with
    ``amplitude=False`` (section 4-4)."""

    sigma: float = 1.0
    amplitude: bool = True
    dim_z: int = field(default=1, init=False)
    angular: tuple[bool, ...] = field(default=(False,), init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigma", float(_positive(self.sigma, "sigma")))

    def _noise(self) -> Array:
        return np.array([[self.sigma**2]])

    def _a(self, x: Array) -> Array:
        return x[..., 2] if self.amplitude else np.ones_like(x[..., 0])

    def h(self, x: Array) -> Array:
        return (self._a(x) * np.sin(x[..., 0]))[..., None]

    def jacobian(self, x: Array) -> Array:
        J = np.zeros(x.shape[:-1] + (1, x.shape[-1]))
        J[..., 0, 0] = self._a(x) * np.cos(x[..., 0])
        if self.amplitude:
            J[..., 0, 2] = np.sin(x[..., 0])
        return J

    def hessian(self, x: Array) -> Array:
        n = x.shape[-1]
        Hs = np.zeros(x.shape[:-1] + (1, n, n))
        Hs[..., 0, 0, 0] = -self._a(x) * np.sin(x[..., 0])
        if self.amplitude:
            Hs[..., 0, 0, 2] = Hs[..., 0, 2, 0] = np.cos(x[..., 0])
        return Hs


@dataclass(frozen=True, eq=False)
class Stack(SensorBase):
    """Several sensors observing the same state at once, z = [z_1, z_2, ...].

    R is block diagonal: the sensors' noises are independent.
    """

    sensors: tuple[SensorModel, ...] = ()

    def __post_init__(self) -> None:
        sensors = tuple(self.sensors)
        if not sensors:
            raise ValueError("Stack.sensors is empty; expected at least one sensor")
        object.__setattr__(self, "sensors", sensors)

    @property
    def dim_z(self) -> int:
        return sum(s.dim_z for s in self.sensors)

    @property
    def angular(self) -> tuple[bool, ...]:
        return sum((tuple(s.angular) for s in self.sensors), ())

    @property
    def linear(self) -> bool:  # type: ignore[override]
        return all(s.linear for s in self.sensors)

    def _noise(self) -> Array:
        return block_diag(*(s.noise for s in self.sensors))

    def h(self, x: Array) -> Array:
        return np.concatenate([s.h(x) for s in self.sensors], -1)

    def jacobian(self, x: Array) -> Array:
        Js = [np.broadcast_to(s.jacobian(x), x.shape[:-1] + (s.dim_z, x.shape[-1]))
              for s in self.sensors]
        return np.concatenate(Js, -2)

    def hessian(self, x: Array) -> Array:
        return np.concatenate([s.hessian(x) for s in self.sensors], -3)
