"""The manoeuvring model of a waterjet search-and-rescue boat (Zolfagharnasab and Seif
2025), identified with an EKF on the state augmented by its 16 coefficients.

Body state ``x = [u, v, r]``: surge (m/s, forward), sway (m/s, positive to starboard) and yaw
rate (rad/s, positive turning to starboard). Inputs ``s = [delta, n]``: nozzle angle (rad,
positive to starboard) and engine speed (rpm). Coefficients
``theta = [a1..a9, b1..b4, c1..c3]``. The model (paper eq. 2), in normalised variables::

    f1 = a1 u^2 + a2 v^2 + a3 r^2 + a4 d^2 + a5 v r + a6 v d + a7 r d + a8 u n + a9 n^2
    f2 = b1 v + b2 r + b3 d + b4 u r
    f3 = c1 v + c2 r + c3 d

It is linear in theta, ``f = Phi(x, s) theta`` with the block-sparse regressor matrix ``Phi``
(3 x 16). Discretised by forward Euler with the mean input (paper eq. 4)::

    x_{k+1} = x_k + dt f(x_k, s_m(k), theta),  s_m(k) = (s_k + s_{k+1}) / 2

The printed eq. 4 has "a9 r n^2"; the continuous eq. 2 has a9 n^2, which is what is used here.

Normalisation (our choice; the paper states none). Coefficients act on the prime variables of
a *fixed* reference length L, speed U0 and engine speed n0::

    u' = u / U0,  v' = v / U0,  r' = r L / U0,  t' = t U0 / L,  delta' = delta,  n' = n / n0

so ``dx'/dt' = f(x', s', theta)`` and, in SI, ``dx/dt = D f(x', s', theta)`` with
``D = diag(U0^2/L, U0^2/L, U0^2/L^2)``. A fixed U0 (not the instantaneous speed) keeps the
model polynomial and linear in theta. ``Normalisation()`` (L = U0 = n0 = 1) is the identity:
the coefficients read literally in SI. The public interface is SI throughout.

Checked here: no positive rescaling can make the paper's Tables 3-5 stable.
A positive rescaling of states and time maps the sway-yaw block
``A(u) = [[b1, b2 + b4 u], [c1, c2]]`` to ``c S A S^-1`` (S diagonal, c > 0): its eigenvalues
are multiplied by c > 0, and ``tr A = b1 + c2 = +0.0467 > 0`` at every speed, so one
eigenvalue always has a positive real part. Literally in SI the eigenvalues are
``+0.02335 +/- i w`` above u = 2.99 m/s (u = 5, 8.74, 9.26 m/s: w = 0.1834, 0.3102, 0.3239
rad/s), two positive reals between 2.96 and 2.99 m/s, and +0.2470 and -0.2003 at u = 0. In
surge, on a straight line, every term of ``a1 u^2 + a8 u n + a9 n^2`` is positive for u, n > 0
under any positive scaling: there is no equilibrium and u' >= a1 u^2 escapes in finite time
1/(a1 u0). Even reversing the sign of the whole of f leaves surge without a positive
equilibrium. Tables 3-5 must use conventions the paper does not give.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from importlib.resources import files
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.models.motion import MotionBase
from trackkit.renamed import renamed_keywords

__all__ = [
    "COEFFICIENT_NAMES",
    "KNOT",
    "Normalisation",
    "IDENTITY",
    "regressors",
    "rhs",
    "rhs_jacobian",
    "sway_yaw_block",
    "straight_line_speed",
    "mean_input",
    "step",
    "step_jacobian_state",
    "step_jacobian_theta",
    "augmented_step",
    "augmented_jacobian",
    "AugmentedVessel",
    "pose_rate",
    "advance_pose",
    "integrate_pose",
    "Particulars",
    "CoefficientSet",
    "naji7",
    "paper_coefficients",
    "reference_vessel",
]

Array = NDArray[np.float64]

#: The names of the 16 coefficients theta, in order: a1..a9, b1..b4, c1..c3.
COEFFICIENT_NAMES: tuple[str, ...] = (
    tuple(f"a{i}" for i in range(1, 10)) + tuple(f"b{i}" for i in range(1, 5))
    + tuple(f"c{i}" for i in range(1, 4))
)
N_THETA = 16
#: One knot in m/s.
KNOT = 1852.0 / 3600.0  # m/s


def _array(value: ArrayLike, last: int, name: str) -> Array:
    """``value`` as a finite float array of shape ``(..., last)``."""
    a = np.asarray(value, dtype=float)
    if a.ndim < 1 or a.shape[-1] != last:
        raise ValueError(f"{name} has shape {a.shape}; expected (..., {last})")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has non-finite entries; expected finite values")
    return a


def _finite_step(dt: ArrayLike, name: str = "dt") -> Array:
    t = np.asarray(dt, dtype=float)
    if not np.all(np.isfinite(t)) or np.any(t < 0):
        raise ValueError(f"{name} = {np.asarray(dt).tolist()!r}; expected a finite step >= 0 s")
    return t


@dataclass(frozen=True)
class Normalisation:
    """Prime system with fixed reference length ``length`` (m), speed ``speed`` (m/s) and
    engine speed ``rpm``: ``x = state_scale * x'``, ``dx/dt = rate_scale * f(x', s')``."""

    length: float = 1.0
    speed: float = 1.0
    rpm: float = 1.0

    def __post_init__(self) -> None:
        for name in ("length", "speed", "rpm"):
            v = getattr(self, name)
            try:
                f = float(v)
            except (TypeError, ValueError):
                f = math.nan
            if not (math.isfinite(f) and f > 0):
                raise ValueError(f"Normalisation.{name} = {v!r}; expected a finite number > 0")
            object.__setattr__(self, name, f)

    @property
    def time(self) -> float:
        """Time unit L / U0 (s)."""
        return self.length / self.speed

    @property
    def state_scale(self) -> Array:
        """``[U0, U0, U0 / L]``: SI = scale * prime."""
        return np.array([self.speed, self.speed, self.speed / self.length])

    @property
    def rate_scale(self) -> Array:
        """``[U0^2/L, U0^2/L, U0^2/L^2]``: SI rate = scale * prime rate."""
        a = self.speed**2 / self.length
        return np.array([a, a, a / self.length])

    def to_prime(self, x: ArrayLike) -> Array:
        return np.asarray(x, dtype=float) / self.state_scale

    def from_prime(self, x: ArrayLike) -> Array:
        return np.asarray(x, dtype=float) * self.state_scale

    def inputs_to_prime(self, s: ArrayLike) -> Array:
        return np.asarray(s, dtype=float) / np.array([1.0, self.rpm])


#: The identity normalisation (unit length, speed and engine speed): SI units as they are.
IDENTITY = Normalisation()


#: The equation (0 surge, 1 sway, 2 yaw) of each coefficient a1..a9, b1..b4, c1..c3.
EQUATION = np.array([0] * 9 + [1] * 4 + [2] * 3)


# Eq. 2 on its components. These take prime scalars or equal-shape arrays and the coefficients
# as anything indexed a[0] .. a[15], so numpy (arrays) and the compiled identifier
# (``trackkit.identify.fused``, scalars) run the same expressions, operation for operation.


def prime_rates(u, v, r, d, n, a):
    """``f'(u', v', r', delta, n')``: the prime surge, sway and yaw rates of eq. 2."""
    f1 = (a[0] * u * u + a[1] * v * v + a[2] * r * r + a[3] * d * d + a[4] * v * r
          + a[5] * v * d + a[6] * r * d + a[7] * u * n + a[8] * n * n)
    f2 = a[9] * v + a[10] * r + a[11] * d + a[12] * u * r
    f3 = a[13] * v + a[14] * r + a[15] * d
    return f1, f2, f3


def prime_terms(u, v, r, d, n):
    """The 16 regressors of eq. 2, coefficient by coefficient (``f'_e = sum of a_i t_i`` over
    the coefficients of equation e, ``EQUATION``)."""
    return (u * u, v * v, r * r, d * d, v * r, v * d, r * d, u * n, n * n,
            v, r, d, u * r, v, r, d)


def prime_jacobian(u, v, r, d, n, a):
    """``J' = d f' / d(u', v', r')`` row by row (nine entries)::

        [[2a1u + a8n, 2a2v + a5r + a6d, 2a3r + a5v + a7d], [b4r, b1, b2 + b4u], [0, c1, c2]]
    """
    return (2 * a[0] * u + a[7] * n, 2 * a[1] * v + a[4] * r + a[5] * d,
            2 * a[2] * r + a[4] * v + a[6] * d,
            a[12] * r, a[9], a[10] + a[12] * u,
            0.0, a[13], a[14])


def _prime(x: Array, s: Array, norm: Normalisation):
    """Prime components ``u, v, r, d, n`` (each of the broadcast batch shape)."""
    U0, L = norm.speed, norm.length
    return x[..., 0] / U0, x[..., 1] / U0, x[..., 2] * (L / U0), s[..., 0], s[..., 1] / norm.rpm


def rhs_unchecked(x: Array, s: Array, th: Array, norm: Normalisation) -> Array:
    """Unchecked f in SI: ``D f(x', s', theta)`` (elementwise, so batches are bitwise equal
    to single rows)."""
    f1, f2, f3 = prime_rates(*_prime(x, s, norm), [th[..., i] for i in range(N_THETA)])
    D = norm.rate_scale
    return np.stack([D[0] * f1, D[1] * f2, D[2] * f3], -1)


def regressors(x: ArrayLike, s: ArrayLike, norm: Normalisation = IDENTITY) -> Array:
    """Regressor matrix ``Phi (..., 3, 16)`` with ``rhs = Phi theta``: rows
    ``D1 [u^2, v^2, r^2, d^2, vr, vd, rd, un, n^2 | 0]``, ``D2 [0 | v, r, d, ur | 0]``,
    ``D3 [0 | v, r, d]`` in prime variables, D = ``norm.rate_scale``."""
    x, s = _array(x, 3, "x"), _array(s, 2, "s")
    shape = np.broadcast_shapes(x.shape[:-1], s.shape[:-1])
    P = np.zeros(shape + (3, N_THETA))
    for i, t in enumerate(prime_terms(*_prime(x, s, norm))):
        P[..., EQUATION[i], i] = t
    return P * norm.rate_scale[:, None]


def rhs(x: ArrayLike, s: ArrayLike, theta: ArrayLike, norm: Normalisation = IDENTITY) -> Array:
    """``dx/dt = f(x, s, theta)`` in SI (..., 3) for SI ``x`` and ``s`` and ``theta`` in
    ``norm``'s prime units."""
    return rhs_unchecked(_array(x, 3, "x"), _array(s, 2, "s"), _array(theta, N_THETA, "theta"),
                         norm)


def _jac(x: Array, s: Array, th: Array, norm: Normalisation) -> Array:
    """Unchecked ``df/dx`` in SI: ``D J' diag(1 / state_scale)`` with the prime Jacobian
    ``J'`` of ``prime_jacobian``."""
    u, v, r, d, n = _prime(x, s, norm)
    shape = np.broadcast_shapes(u.shape, n.shape, th.shape[:-1])
    J = np.zeros(shape + (3, 3))
    entries = prime_jacobian(u, v, r, d, n, [th[..., i] for i in range(N_THETA)])
    for e, value in enumerate(entries):
        J[..., e // 3, e % 3] = value
    return J * (norm.rate_scale[:, None] / norm.state_scale[None, :])


def rhs_jacobian(x: ArrayLike, s: ArrayLike, theta: ArrayLike,
                 norm: Normalisation = IDENTITY) -> Array:
    """``df/dx`` in SI, ``(..., 3, 3)``."""
    return _jac(_array(x, 3, "x"), _array(s, 2, "s"), _array(theta, N_THETA, "theta"), norm)


def sway_yaw_block(u: ArrayLike, theta: ArrayLike, norm: Normalisation = IDENTITY) -> Array:
    """The linear sway-yaw matrix ``d(f2, f3)/d(v, r)`` in SI at surge speed u (m/s):
    ``diag(D2, D3) [[b1, b2 + b4 u'], [c1, c2]] diag(1/U0, L/U0)``, shape ``(..., 2, 2)``."""
    u = np.asarray(u, dtype=float)
    x = np.stack([u, np.zeros_like(u), np.zeros_like(u)], -1)
    return rhs_jacobian(x, np.zeros(2), theta, norm)[..., 1:, 1:]


def straight_line_speed(theta: ArrayLike, rpm: ArrayLike,
                        norm: Normalisation = IDENTITY) -> Array:
    """Equilibrium surge speed (m/s) at zero nozzle angle: the root ``u' = k n'`` of
    ``a1 u'^2 + a8 u' n' + a9 n'^2 = 0`` with ``k > 0`` and stable slope ``2 a1 k + a8 < 0``,
    i.e. ``k = 2 a9 / (sqrt(a8^2 - 4 a1 a9) - a8)``; ``nan`` where there is none."""
    th = _array(theta, N_THETA, "theta")
    a1, a8, a9 = th[..., 0], th[..., 7], th[..., 8]
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(a8 * a8 - 4 * a1 * a9)  # the slope 2 a1 k + a8 at the root is -sq
        k = 2 * a9 / (sq - a8)  # = -(a8 + sq) / (2 a1), without cancellation as a1 -> 0
    k = np.where((sq > 0) & (k > 0) & np.isfinite(k), k, np.nan)
    return k * np.asarray(rpm, dtype=float) / norm.rpm * norm.speed


def mean_input(s_k: ArrayLike, s_next: ArrayLike) -> Array:
    """``s_m(k) = (s_k + s_{k+1}) / 2``."""
    return 0.5 * (_array(s_k, 2, "s_k") + _array(s_next, 2, "s_next"))


@renamed_keywords(T="dt")
def step(x: ArrayLike, s_m: ArrayLike, theta: ArrayLike, dt: ArrayLike,
         norm: Normalisation = IDENTITY) -> Array:
    """Forward Euler ``x_{k+1} = x_k + dt f(x_k, s_m, theta)``."""
    x = _array(x, 3, "x")
    dt = _finite_step(dt)
    return x + dt[..., None] * rhs_unchecked(x, _array(s_m, 2, "s_m"),
                                             _array(theta, N_THETA, "theta"), norm)


@renamed_keywords(T="dt")
def step_jacobian_state(x: ArrayLike, s_m: ArrayLike, theta: ArrayLike, dt: ArrayLike,
                        norm: Normalisation = IDENTITY) -> Array:
    """``d x_{k+1} / d x_k = I + dt df/dx``, ``(..., 3, 3)``."""
    dt = _finite_step(dt)
    return np.eye(3) + dt[..., None, None] * rhs_jacobian(x, s_m, theta, norm)


@renamed_keywords(T="dt")
def step_jacobian_theta(x: ArrayLike, s_m: ArrayLike, dt: ArrayLike,
                        norm: Normalisation = IDENTITY) -> Array:
    """``d x_{k+1} / d theta = dt Phi(x_k, s_m)``, ``(..., 3, 16)``."""
    dt = _finite_step(dt)
    return dt[..., None, None] * regressors(x, s_m, norm)


@renamed_keywords(T="dt")
def augmented_step(xa: ArrayLike, s_m: ArrayLike, dt: ArrayLike,
                   norm: Normalisation = IDENTITY) -> Array:
    """``[x + dt f(x, s_m, theta), theta]`` for ``xa = [u, v, r, theta]`` (..., 19)."""
    xa = _array(xa, 3 + N_THETA, "xa")
    x1 = step(xa[..., :3], s_m, xa[..., 3:], dt, norm)
    theta = np.broadcast_to(xa[..., 3:], x1.shape[:-1] + (N_THETA,))
    return np.concatenate([x1, theta], -1)


@renamed_keywords(T="dt")
def augmented_jacobian(xa: ArrayLike, s_m: ArrayLike, dt: ArrayLike,
                       norm: Normalisation = IDENTITY) -> Array:
    """The 19 x 19 transition Jacobian ``[[I + dt df/dx, dt Phi], [0, I]]`` (theta is a random
    walk)."""
    xa = _array(xa, 3 + N_THETA, "xa")
    x, th = xa[..., :3], xa[..., 3:]
    Fx = step_jacobian_state(x, s_m, th, dt, norm)
    Ft = step_jacobian_theta(x, s_m, dt, norm)
    shape = np.broadcast_shapes(Fx.shape[:-2], Ft.shape[:-2])
    F = np.zeros(shape + (19, 19))
    F[..., :3, :3] = Fx
    F[..., :3, 3:] = Ft
    F[..., 3:, 3:] = np.eye(N_THETA)
    return F


@dataclass(frozen=True, eq=False)
class AugmentedVessel(MotionBase):
    """Motion model of the augmented state ``[u, v, r, theta]`` (19) for the filters.

    ``f(x, dt) = augmented_step(x, s_m, dt, norm)``, ``jacobian`` its 19 x 19 Jacobian and
    ``noise(x, dt) = diag(q_body dt, q_theta dt)``: random walks of spectral densities
    ``q_body`` (3, SI: m^2/s^3, m^2/s^3, rad^2/s^3) and ``q_theta`` (16, prime units^2 / s).
    ``s_m`` is the mean input of the step ``(..., 2)`` (rad, rpm) and may carry batch axes:
    build a new small object per step.
    """

    s_m: ArrayLike
    norm: Normalisation
    q_body: ArrayLike = 0.0
    q_theta: ArrayLike = 0.0
    dim_x: int = field(default=3 + N_THETA, init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "s_m", _array(self.s_m, 2, "AugmentedVessel.s_m"))
        if not isinstance(self.norm, Normalisation):
            raise ValueError(f"AugmentedVessel.norm = {self.norm!r}; expected a Normalisation")
        for name, k in (("q_body", 3), ("q_theta", N_THETA)):
            q = np.asarray(getattr(self, name), dtype=float)
            q = np.broadcast_to(q, (k,)) if q.ndim == 0 else q
            if q.shape != (k,) or not np.all(np.isfinite(q)) or np.any(q < 0):
                raise ValueError(f"AugmentedVessel.{name} = {np.asarray(q).tolist()!r}; "
                                 f"expected a scalar or ({k},) of finite values >= 0")
            object.__setattr__(self, name, q)

    def f(self, x: Array, dt: ArrayLike) -> Array:
        return augmented_step(x, self.s_m, dt, self.norm)

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        return augmented_jacobian(x, self.s_m, dt, self.norm)

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        q = np.concatenate([self.q_body, self.q_theta])
        dt = _finite_step(dt, "dt")
        return (dt[..., None] * q)[..., None, :] * np.eye(self.dim_x)


# --- kinematics: pose = [east, north, psi], psi clockwise from north ------------------------


def pose_rate(pose: ArrayLike, x: ArrayLike) -> Array:
    """``[east', north', psi'] = [u sin psi + v cos psi, u cos psi - v sin psi, r]``."""
    pose, x = _array(pose, 3, "pose"), _array(x, 3, "x")
    sp, cp = np.sin(pose[..., 2]), np.cos(pose[..., 2])
    u, v, r = x[..., 0], x[..., 1], x[..., 2]
    return np.stack(np.broadcast_arrays(u * sp + v * cp, u * cp - v * sp, r), -1)


def advance_pose_unchecked(pose: Array, x: Array, dt: float | Array) -> Array:
    """Exact pose after ``dt`` with constant body velocity ``x``: the body displacement
    ``(u S - v C, u C + v S)`` (forward, starboard) with ``S = sin(r dt)/r`` and
    ``C = (1 - cos(r dt))/r`` rotated to east/north by the initial heading."""
    u, v, r = x[..., 0], x[..., 1], x[..., 2]
    a = r * dt
    small = np.abs(a) < 1e-4
    rs = np.where(small, 1.0, r)  # a safe divisor; series below 1e-4 rad per step
    S = np.where(small, dt * (1.0 - a * a / 6.0), np.sin(a) / rs)
    C = np.where(small, dt * a * (0.5 - a * a / 24.0), (1.0 - np.cos(a)) / rs)
    fwd, stb = u * S - v * C, u * C + v * S
    psi = pose[..., 2]
    sp, cp = np.sin(psi), np.cos(psi)
    return np.stack([pose[..., 0] + fwd * sp + stb * cp, pose[..., 1] + fwd * cp - stb * sp,
                     psi + a], -1)


def advance_pose(pose: ArrayLike, x: ArrayLike, dt: float) -> Array:
    """Pose after ``dt`` seconds at constant body velocity ``x = [u, v, r]`` (an exact arc)."""
    return advance_pose_unchecked(_array(pose, 3, "pose"), _array(x, 3, "x"),
                                  float(_finite_step(dt, "dt")))


def integrate_pose(x: ArrayLike, dt: float, pose0: ArrayLike = (0.0, 0.0, 0.0)) -> Array:
    """Poses ``(..., K, 3)`` from body states sampled every ``dt`` seconds ``(..., K, 3)``:
    over each interval the body velocity is held at the mean of its end samples and the pose
    follows the exact arc. psi is not wrapped."""
    x = _array(x, 3, "x")
    if x.ndim < 2:
        raise ValueError(f"x has shape {x.shape}; expected (..., K, 3) samples")
    dt = float(_finite_step(dt, "dt"))
    pose = np.broadcast_to(_array(pose0, 3, "pose0"), x.shape[:-2] + (3,))
    out = [pose]
    for k in range(x.shape[-2] - 1):
        pose = advance_pose_unchecked(pose, 0.5 * (x[..., k, :] + x[..., k + 1, :]), dt)
        out.append(pose)
    return np.stack(out, -2)


# --- data: Table 2, Tables 3-5 and our reference vessel (vessel_data.toml) ------------------


class Particulars(NamedTuple):
    """Naji 7 (paper Table 2), in SI."""

    length_overall: float  # m
    beam: float  # m
    draft: float  # m
    mass: float  # kg (Table 2's "net weight", 35 t)
    engines: int
    engine_power: float  # W per engine
    max_speed: float  # m/s
    gross_tonnage: float  # GT (dimensionless)


@dataclass(frozen=True, eq=False)
class CoefficientSet:
    """Sixteen coefficients ``theta`` (a1..a9, b1..b4, c1..c3) in the units of ``norm``."""

    name: str
    theta: Array
    norm: Normalisation
    note: str = ""
    design: dict = field(default_factory=dict)

    def as_dict(self) -> dict[str, float]:
        return dict(zip(COEFFICIENT_NAMES, self.theta.tolist(), strict=True))


def _data() -> dict:
    with (files("trackkit.models") / "vessel_data.toml").open("rb") as fh:
        return tomllib.load(fh)


def _theta(table: dict, where: str) -> Array:
    missing = [k for k in COEFFICIENT_NAMES if k not in table]
    if missing:
        raise ValueError(f"vessel_data.toml [{where}] lacks {missing}")
    theta = np.array([float(table[k]) for k in COEFFICIENT_NAMES])
    theta.flags.writeable = False
    return theta


def naji7() -> Particulars:
    """Table 2 converted to SI (t -> kg, kW -> W, kn -> m/s)."""
    t = _data()["naji7"]
    return Particulars(
        length_overall=float(t["length_overall_m"]), beam=float(t["beam_m"]),
        draft=float(t["draft_m"]), mass=float(t["net_weight_t"]) * 1000.0,
        engines=int(t["engines"]), engine_power=float(t["engine_power_kw"]) * 1000.0,
        max_speed=float(t["max_speed_kn"]) * KNOT, gross_tonnage=float(t["gross_tonnage"]))


def paper_coefficients() -> CoefficientSet:
    """Tables 3-5 as printed (signs reconstructed), read literally in SI (identity
    normalisation): unstable, see the module docstring."""
    t = _data()["paper"]
    return CoefficientSet("paper", _theta(t["coefficients"], "paper.coefficients"), IDENTITY,
                          t["note"])


def reference_vessel() -> CoefficientSet:
    """Our stable reference coefficient set (prime units, L = 19.6 m, U0 = 18 kn,
    n0 = 2000 rpm) with its design condition in SI (``design``)."""
    t = _data()["reference"]
    nm = t["normalisation"]
    norm = Normalisation(float(nm["length_m"]), float(nm["speed_kn"]) * KNOT, float(nm["rpm"]))
    d = t["design"]
    design = {"speed": float(d["speed_kn"]) * KNOT, "rpm": float(d["rpm"]),
              "delta": float(np.deg2rad(d["nozzle_deg"])),
              "rate_limit": float(np.deg2rad(d["nozzle_rate_deg_s"])),
              "max_delta": float(np.deg2rad(d["max_nozzle_deg"])),
              "length": float(nm["length_m"])}
    return CoefficientSet("reference", _theta(t["coefficients"], "reference.coefficients"),
                          norm, t["note"], design)
