"""Target classes for joint tracking and classification (Hosseini, Haeri and Khaloozadeh 2019).

A class is what a target *is* (an airliner, a fighter): it does not change in time, and it
shows in how the target moves. Each class has

* a speed likelihood ``g(v | c)``, the class's speed envelope, standing in for the feature
  measurements a radar does not give;
* a set of manoeuvre modes, each a constant turn rate ``omega`` and a constant acceleration
  ``u`` held over a step, between which the target switches by a Markov chain.

One step of mode (omega, u) on the state ``x = [x, y, vx, vy]`` with white acceleration noise
``w ~ N(0, sigma^2 I)`` (the paper's common noise gain ``G``) is

    x_{k+1} = F(omega) x_k + G (a(x_k) + w_k),      G = [[T^2/2, 0], [0, T^2/2], [T, 0], [0, T]]

with ``F(0)`` the constant-velocity matrix and, for ``omega != 0``, the standard coordinated
turn (``s = sin(omega T)``, ``c = cos(omega T)``; positive omega counter-clockwise)::

    F(omega) = [[1, 0,  s/omega,      -(1 - c)/omega],
                [0, 1,  (1 - c)/omega, s/omega      ],
                [0, 0,  c,            -s            ],
                [0, 0,  s,             c            ]]

(the paper prints it for ``[x, y, vx, vy]`` although it states ``[x, vx, y, vy]``, and drops the
minus sign of ``-s``; fixed here). The acceleration ``a`` of a CA mode is ``u`` along the
velocity, ``a = u v / |v|`` (``along="velocity"``, the default), or the paper's literal ``G u``
with the scalar u on both axes (``along="axes"``). We choose the velocity: a CA mode is then a
longitudinal speed change, complementing the CT modes' change of heading, while the literal
form pushes a target north-east (u > 0) or south-west whatever its heading, which no aircraft
does and which makes the class's manoeuvres depend on its course.

Units: SI inside. The paper's turn rates (``omega = +-1`` for the fighter, ``+-0.5`` for the
airliner) carry no unit; we read them as deg/s. In rad/s, ``omega = 1`` at the fighter's 300 m/s
is a centripetal acceleration ``omega v = 300 m/s^2``, about 31 g (and the airliner's 0.5 rad/s
at 200 m/s is 100 m/s^2, 10 g, four times an airliner's 2.5 g structural limit); in deg/s they
are 5.2 m/s^2 (0.53 g) and 1.7 m/s^2 (0.18 g), gentle turns of the two kinds of aircraft. The CA
inputs ``u = +-20`` (fighter) and ``+-5`` (airliner) are read as m/s^2 (2 g and 0.5 g).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.models.motion import turn_coefficients

__all__ = [
    "SpeedLikelihood",
    "Mode",
    "TargetClass",
    "paper_modes",
    "transition_matrix",
    "turn_terms",
    "mode_step",
    "AIRLINER",
    "FIGHTER",
    "PAPER_CLASSES",
    "CLASSES",
    "class_by_name",
]

Array = NDArray[np.float64]

ALONG = ("velocity", "axes")


@dataclass(frozen=True)
class SpeedLikelihood:
    """``g(v | c)``: constant below ``v_low`` and above ``v_high``, a ramp between::

        g(v) = g_low                                               v <= v_low
             = g_low + (g_high - g_low) / (v_high - v_low) (v - v_low)   v_low < v <= v_high
             = g_high                                              v > v_high

    Speeds in m/s. It is a likelihood, not a density: only its ratio between classes matters.
    """

    v_low: float
    g_low: float
    v_high: float
    g_high: float

    def __post_init__(self) -> None:
        for name in ("v_low", "g_low", "v_high", "g_high"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ValueError(f"SpeedLikelihood.{name} = {v!r}; expected a finite number")
        if not 0 <= self.v_low < self.v_high:
            raise ValueError(f"SpeedLikelihood: v_low = {self.v_low!r}, v_high = "
                             f"{self.v_high!r}; expected 0 <= v_low < v_high (m/s)")
        for name in ("g_low", "g_high"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SpeedLikelihood.{name} = {getattr(self, name)!r}; expected "
                                 "a likelihood > 0 (a class no speed can have is no class)")

    @property
    def slope(self) -> float:
        """``(g_high - g_low) / (v_high - v_low)``, per m/s."""
        return (self.g_high - self.g_low) / (self.v_high - self.v_low)

    def __call__(self, speed: ArrayLike) -> Array:
        v = np.clip(np.asarray(speed, dtype=float), self.v_low, self.v_high)
        if v.ndim == 0:
            return self.g_low + self.slope * (v - self.v_low)
        v -= self.v_low  # in place: v is clip's fresh copy
        v *= self.slope
        v += self.g_low
        return v


@dataclass(frozen=True)
class Mode:
    """A manoeuvre mode: ``turn_rate`` omega (rad/s, positive counter-clockwise) and
    ``acceleration`` u (m/s^2), both held constant over a step. (0, 0) is constant velocity;
    (0, u) constant acceleration; (omega, 0) a coordinated turn."""

    name: str
    turn_rate: float = 0.0
    acceleration: float = 0.0

    def __post_init__(self) -> None:
        for f in ("turn_rate", "acceleration"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ValueError(f"Mode {self.name!r}: {f} = {v!r}; expected a finite number")


def paper_modes(u: float, omega: float) -> tuple[Mode, ...]:
    """The five modes of a class: CV; CA with +u and -u (m/s^2); CT with
    +omega and -omega (rad/s)."""
    return (Mode("CV"), Mode("CA+", acceleration=u), Mode("CA-", acceleration=-u),
            Mode("CT+", turn_rate=omega), Mode("CT-", turn_rate=-omega))


def transition_matrix(modes: int = 5, diagonal: float = 0.6) -> Array:
    """``p_ij = P(m_k = j | m_{k-1} = i)``: ``diagonal`` on the diagonal and the rest shared
    equally, ``(1 - diagonal) / (modes - 1)``, off it (the paper's 0.6 and 0.1 for 5 modes)."""
    if isinstance(modes, bool) or not isinstance(modes, int | np.integer) or modes < 1:
        raise ValueError(f"modes = {modes!r}; expected an integer >= 1")
    if not (isinstance(diagonal, int | float) and 0 <= diagonal <= 1):
        raise ValueError(f"diagonal = {diagonal!r}; expected a probability in [0, 1]")
    if modes == 1:
        return np.ones((1, 1))
    P = np.full((modes, modes), (1.0 - diagonal) / (modes - 1))
    np.fill_diagonal(P, diagonal)
    return P


@dataclass(frozen=True, eq=False)
class TargetClass:
    """A target class: its ``name``, speed likelihood, modes and the modes' transition matrix
    ``p_ij = P(m_k = j | m_{k-1} = i)`` (default: :func:`transition_matrix`, 0.6 on the
    diagonal). The transition is checked: square, one row per mode, entries in [0, 1], rows
    summing to 1 (to 1e-12)."""

    name: str
    speed_likelihood: SpeedLikelihood
    modes: tuple[Mode, ...]
    transition: Array = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if not self.name or not isinstance(self.name, str):
            raise ValueError(f"TargetClass.name = {self.name!r}; expected a non-empty string")
        if not isinstance(self.speed_likelihood, SpeedLikelihood):
            raise ValueError(f"TargetClass {self.name!r}: speed_likelihood is a "
                             f"{type(self.speed_likelihood).__name__}; expected a "
                             "SpeedLikelihood")
        modes = tuple(self.modes)
        if not modes or not all(isinstance(m, Mode) for m in modes):
            raise ValueError(f"TargetClass {self.name!r}: modes = {self.modes!r}; expected "
                             "one or more Mode")
        object.__setattr__(self, "modes", modes)
        M = len(modes)
        P = transition_matrix(M) if self.transition is None else np.array(
            self.transition, dtype=float)
        if P.shape != (M, M):
            raise ValueError(f"TargetClass {self.name!r}: transition has shape {P.shape}; "
                             f"expected ({M}, {M}), one row and column per mode")
        if not (np.isfinite(P).all() and (P >= 0).all() and (P <= 1).all()):
            raise ValueError(f"TargetClass {self.name!r}: transition has entries outside "
                             "[0, 1]; expected probabilities")
        sums = P.sum(1)
        bad = np.flatnonzero(np.abs(sums - 1.0) > 1e-12)
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"TargetClass {self.name!r}: transition row {i} sums to "
                             f"{sums[i]!r}; expected rows summing to 1")
        P.flags.writeable = False
        object.__setattr__(self, "transition", P)

    @property
    def n_modes(self) -> int:
        return len(self.modes)

    @property
    def turn_rates(self) -> Array:
        return np.array([m.turn_rate for m in self.modes])

    @property
    def accelerations(self) -> Array:
        return np.array([m.acceleration for m in self.modes])

    def with_transition(self, diagonal: float) -> TargetClass:
        """The class with the default transition's diagonal set to ``diagonal``."""
        return TargetClass(self.name, self.speed_likelihood, self.modes,
                           transition_matrix(self.n_modes, diagonal))


def turn_terms(omega: ArrayLike, dt: float) -> tuple[Array, Array, Array, Array]:
    """``(sin(omega T)/omega, (1 - cos(omega T))/omega, cos(omega T), sin(omega T))`` for
    the step ``T = dt``; the ratios tend to ``(T, 0)`` as omega -> 0 (a Taylor series near 0,
    trackkit.models.motion)."""
    s, c, _, _, cos, sin = turn_coefficients(np.asarray(omega, dtype=float), np.asarray(dt, float))
    return s, c, cos, sin


def mode_step(x: ArrayLike, omega: ArrayLike, u: ArrayLike, dt: float,
              w: ArrayLike | None = None, along: str = "velocity") -> Array:
    """One step of the mode (omega, u) with acceleration noise ``w`` (m/s^2, ``(..., 2)``)::

        x_{k+1} = F(omega) x_k + G (a(x_k) + w_k)

    ``x`` is ``(..., 4)`` in ``[x, y, vx, vy]``; ``omega`` (rad/s) and ``u`` (m/s^2) broadcast
    against its batch axes (one per particle). ``a = u v / |v|`` (``along="velocity"``; 0 at
    rest) or ``a = (u, u)`` (``along="axes"``)."""
    if along not in ALONG:
        raise ValueError(f"along = {along!r}; expected one of {ALONG}")
    x = np.asarray(x, dtype=float)
    omega, u = np.asarray(omega, dtype=float), np.asarray(u, dtype=float)
    w = None if w is None else np.asarray(w, dtype=float)
    shape = np.broadcast_shapes(x.shape[:-1], omega.shape, u.shape,
                                () if w is None else w.shape[:-1])

    def flat(a: Array) -> Array:  # the kernel works in place on 1-D arrays
        return np.broadcast_to(a, shape).reshape(-1)

    s, c, cos, sin = turn_terms(flat(omega), dt)
    parts = mode_step_components(*(flat(x[..., i]) for i in range(4)), s, c, cos, sin, flat(u), dt,
                  None if w is None else flat(w[..., 0]), None if w is None else flat(w[..., 1]),
                  along)
    return np.stack(parts, -1).reshape(shape + (4,))


def mode_step_components(px: Array, py: Array, vx: Array, vy: Array, s: Array, c: Array, cos: Array,
          sin: Array, u: Array, dt: float, wx: Array | None, wy: Array | None,
          along: str) -> tuple[Array, Array, Array, Array]:
    """:func:`mode_step` on the components ``(x, y, vx, vy)``, with the turn terms given (a
    filter gathers them per particle from a table of its modes); returns the new components.

    Along the velocity, ``a = q v`` with ``q = u / |v|``, so the acceleration folds into the
    coefficients of v: ``x' = x + (s + q T^2/2) vx - c vy + T^2/2 wx``,
    ``vx' = (cos + q T) vx - sin vy + T wx`` (and the same for y). The arithmetic runs in
    place: for a million particles a numpy temporary is fresh memory whose page faults cost
    as much as the arithmetic itself.
    """
    h = 0.5 * dt * dt
    shape = np.broadcast_shapes(np.shape(px), np.shape(s), np.shape(u))
    tmp = np.empty(shape)
    if along == "velocity":
        sp = np.multiply(vx, vx)
        np.multiply(vy, vy, out=tmp)
        sp += tmp
        np.sqrt(sp, out=sp)
        sp[sp == 0] = np.inf  # no direction at rest: no acceleration
        np.divide(u, sp, out=sp)  # q = u / |v|
        cv = np.multiply(sp, dt)
        cv += cos
        sp *= h
        sp += s
        ax = ay = None
    else:
        sp, cv, ax, ay = s, cos, u, u
    if wx is not None:
        ax = wx if ax is None else ax + wx
        ay = wy if ay is None else ay + wy
    x1 = np.multiply(sp, vx)
    np.multiply(c, vy, out=tmp)
    x1 -= tmp
    x1 += px
    y1 = np.multiply(c, vx)
    np.multiply(sp, vy, out=tmp)
    y1 += tmp
    y1 += py
    vx1 = np.multiply(cv, vx)
    np.multiply(sin, vy, out=tmp)
    vx1 -= tmp
    vy1 = np.multiply(sin, vx)
    np.multiply(cv, vy, out=tmp)
    vy1 += tmp
    if ax is not None:
        for r, a, k in ((x1, ax, h), (y1, ay, h), (vx1, ax, dt), (vy1, ay, dt)):
            np.multiply(a, k, out=tmp)
            r += tmp
    return x1, y1, vx1, vy1


# the paper's two classes, with the c2 sign typo fixed (0.1 + ..., not
# 0.1 - ...) and the turn rates read in deg/s (module docstring)
#: The paper's airliner class: speed likelihood falling from 0.8 at 100 m/s to 0.1 at
#: 300 m/s, modes with u = 5 m/s^2 and omega = 0.5 deg/s.
AIRLINER = TargetClass(
    "airliner", SpeedLikelihood(v_low=100.0, g_low=0.8, v_high=300.0, g_high=0.1),
    paper_modes(u=5.0, omega=math.radians(0.5)))
#: The paper's fighter class: speed likelihood rising from 0.1 at 150 m/s to 0.95 at
#: 650 m/s, modes with u = 20 m/s^2 and omega = 1 deg/s.
FIGHTER = TargetClass(
    "fighter", SpeedLikelihood(v_low=150.0, g_low=0.1, v_high=650.0, g_high=0.95),
    paper_modes(u=20.0, omega=math.radians(1.0)))

#: c1 (low manoeuvre, airliner) and c2 (high manoeuvre, fighter), in the paper's order
PAPER_CLASSES = (AIRLINER, FIGHTER)
#: the ready-made classes by name
CLASSES = {c.name: c for c in PAPER_CLASSES}


def class_by_name(name: str) -> TargetClass:
    """A ready-made class by name ("airliner", "fighter")."""
    try:
        return CLASSES[name]
    except KeyError:
        raise ValueError(f"class {name!r} is not a ready-made class; expected one of "
                         f"{sorted(CLASSES)}") from None
