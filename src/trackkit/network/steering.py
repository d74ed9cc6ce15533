"""Agent course control (Jalalipoor and Kardehi Moghaddam 2021, eqs. 52-64): three sub-optimisations
over the turn-rate-limited course interval, under range constraints, blended into one course.

Geometry (trackkit's convention): x east, y north; courses and bearings are nautical (clockwise from
north), so an agent at speed v on course C moves with velocity ``v (sin C, cos C)`` and the
bearing from p to q is ``B = atan2(q_x - p_x, q_y - p_y)``; every angle is wrapped to
(-pi, pi].

**Admissible courses.** An agent on course C that runs its program again after dt, with the
turn-rate limit w (2 deg/s in the paper), may command any course in

    [C - w dt, C + w dt]                                           (eqs. 52-64, "course bounds")

The interval is searched on a grid of ``n_candidates`` courses ``C + w dt g_k`` with g_k
evenly spaced on [-1, 1] (both ends and g = 0 included), ordered by ``|g_k|`` so that ties go to
the smallest turn. ``w dt < pi/2`` is required: the interval is then shorter than pi, which
the circular blend below needs.

**Prediction horizon.** Every distance and bearing is evaluated at the end of the step, t + dt:
the agent at ``P_a(c)``, where :func:`move` takes it when it commands candidate c (a turn at
rate w to c, then straight: exact for the agent itself); neighbours and targets at their
constant-velocity predictions ``Q + V dt`` (static without a velocity).

**Sub-objectives** (each minimised over the admissible candidates; R_ni, R_tj the distances at
t + dt, B_j the bearing from P_a(c) to target j):

    C_Rn = argmin_c  -sum_i R_ni(c)                                           (eqs. 52-53)
    C_Rt = argmin_c   sum_j R_tj(c)                                           (eqs. 54-55)
    C_Dt = argmin_c   sum_j K1 (1 - exp(-K2 (lambda_j - pi/2)^2)),
                      lambda_j = |wrap(B_j - c)|                              (eqs. 56-57)

**Constraints** (eqs. 58-63), for every neighbour i and every known target j:

    R_n,min = r_min min(CR_a, CR_i) <= R_ni <= r_max min(CR_a, CR_i) = R_n,max
    R_t,min = r_min MR_a            <= R_tj <= r_max MR_a            = R_t,max

with r_min = 0.05, r_max = 0.95. An infinite range ("very large", scenario 1) has no lower
bound (5% of infinity is no constraint) and no upper bound.

The paper checks the constraints at the predicted positions only (``safety="step"`` here). A
one-step check cannot keep them: an agent heading for a neighbour near the lower bound needs
a quarter turn, (pi/2)/w = 45 s and up to v/w = 859 m of closing at 30 m/s, to stop closing,
so it must start turning before a one-step check sees anything; and with several neighbours
the ways to turn away conflict. By default (``safety="circle"``) every pair is checked with
a *backup manoeuvre*: each agent's turning circle to starboard (clockwise), of radius
R = v / w and centre

    c = p + R (cos C, -sin C)

An agent that turns clockwise at the full rate stays on that circle for ever, and its centre
does not move. If for every pair (a, i)

    h_lo = |c_a - c_i| - R_a - R_i - R_n,min - m >= 0,
    h_hi = R_n,max - |c_a - c_i| - R_a - R_i - m >= 0           (m: ``margin``, metres)

the two stay within [R_n,min + m, R_n,max - m] of each other whatever they do next, as long as
they then circle: h >= 0 holds for all pairs at once (no conflict between neighbours), and
the full starboard turn (the candidate C + w dt) keeps every h where it is, so a safe
candidate always exists. Two neighbours decide at the same time, each seeing the other's
current centre, so each takes half of each barrier (a decentralised discrete-time control
barrier function): with u the unit vector c_a -> c_i now and alpha = c_a(c) - c_a the move of
a's own centre when it commands c,

    h_lo - u . alpha >= rho h_lo,    h_hi + u . alpha >= rho h_hi,    rho = ``share`` = 1/2

so that the two moves together leave h >= h - h/2 - h/2 = 0 to first order (the distance is
convex, so the first-order change over-states the loss for the lower bound; the margin m
absorbs what is left at the upper one, about ``|alpha|^2 / (2 |c_a - c_i|)``, a few metres). A
neighbour's centre comes from its position and velocity (its turn rate taken as w). The
price is a narrower band in practice: the agents' own distance can reach R_n,min only when
both circles' worst points face each other. The condition for the guarantee is to *start*
inside the set h >= 0 (two agents 0.06 CR apart closing head-on at 30 m/s each cannot avoid
passing within 0.05 CR: they need 2 v/w = 1.7 km to turn away).

A target does not steer and its circle is unknown: the agent takes it at its predicted
position T(t + dt) and keeps

    R_t,min + R_a + m <= |c_a(c) - T(t + dt)| <= R_t,max - R_a - m

alone (rho = 0). For static targets this set is kept like the neighbours' one; a moving
target can leave it faster than the agent follows, and the bounds can then break.

**Choosing among candidates** (the paper is silent). A candidate is *feasible* when every
pair meets its barrier. Each sub-objective is minimised over the feasible candidates. When
none is feasible, target constraints are relaxed before neighbour ones (connectivity first: a
lost link loses everything that neighbour knows, a target out of range only its own bearings):
the candidates meeting every neighbour barrier with the least total target shortfall, else
those with the least total neighbour shortfall (metres summed over the pairs). The agent then
turns back inside the constraints as fast as the turn rate allows.

**Blend** (eq. 64): the paper averages the three courses linearly,
``C = (K_Rn C_Rn + K_Rt C_Rt + K_Dt C_Dt) / (K_Rn + K_Rt + K_Dt)``, which blends 359 deg and
1 deg to 180 deg. Here it is the weighted circular mean

    C = atan2(sum_m K_m sin C_m, sum_m K_m cos C_m),    m in {Rn, Rt, Dt}

(:func:`blend_courses`). The sub-courses lie in an arc shorter than pi, and a positive
combination of unit vectors in such an arc points inside it, so C is admissible too (it is
clipped to the interval against rounding). A sub-objective without data (no neighbour, or no
known target) gets weight 0. If the blend itself is not feasible (the feasible set need not
be an interval), the feasible candidate nearest to it is commanded instead; with no weight at
all the agent keeps its course if it may.

``Steering(straight=True)`` commands the current course (no steering), for comparison.

All functions are batched over leading axes (runs) and the agent axis, with no Python loop
over either: the candidates are one more array axis.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import circular_mean, wrap

__all__ = [
    "TURN_RATE",
    "Steering",
    "CourseCommand",
    "admissible_courses",
    "blend_courses",
    "move",
    "steer",
    "swarm_neighbours",
]

Array = NDArray[np.float64]

#: the paper's turn-rate limit, 2 deg/s
TURN_RATE = float(np.deg2rad(2.0))
#: the constraint checks of :class:`Steering` (module docstring)
SAFETY = ("circle", "step")
#: shortfalls (m) below this count as ties when the least-violation candidates are chosen
_TIE = 1e-6


@dataclass(frozen=True)
class Steering:
    """Course-control parameters (Jalalipoor and Kardehi Moghaddam 2021, eqs. 52-64).

    ``k_rn``, ``k_rt``, ``k_dt``: blend weights K_Rn, K_Rt, K_Dt of eq. 64 (>= 0).
    ``K1``, ``K2``: the LOS-perpendicular cost K1 (1 - exp(-K2 (lambda - pi/2)^2)) (eq. 56).
    ``turn_rate``: w, rad/s (the paper's 2 deg/s). ``n_candidates``: odd grid size over the
    admissible interval (>= 3). ``r_min``, ``r_max``: the range factors 0.05 and 0.95.
    ``safety``: ``"circle"`` checks each pair with the backup turning circles and a shared
    barrier (module docstring); ``"step"`` is the paper's check at the predicted positions
    alone. ``share``: rho, the fraction of a neighbour barrier an agent must keep per step
    (1/2: two agents deciding at once). ``margin``: m, metres kept clear of every bound in
    ``"circle"`` (absorbs the second-order terms the barrier neglects). ``straight``: keep
    the course (no steering).
    """

    k_rn: float = 1.0
    k_rt: float = 1.0
    k_dt: float = 1.0
    K1: float = 1.0
    K2: float = 1.0
    turn_rate: float = TURN_RATE
    n_candidates: int = 41
    r_min: float = 0.05
    r_max: float = 0.95
    safety: str = "circle"
    share: float = 0.5
    margin: float = 20.0
    straight: bool = False

    def __post_init__(self) -> None:
        for name in ("k_rn", "k_rt", "k_dt", "K1", "margin"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"Steering.{name} = {v!r}; expected a finite number >= 0")
        for name in ("K2", "turn_rate"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"Steering.{name} = {v!r}; expected a finite number > 0")
        n = self.n_candidates
        if not (isinstance(n, int | np.integer) and n >= 3 and n % 2 == 1):
            raise ValueError(f"Steering.n_candidates = {n!r}; expected an odd integer >= 3 "
                             "(the grid holds both interval ends and the current course)")
        if not (0.0 <= self.r_min < self.r_max <= 1.0):
            raise ValueError(f"Steering.r_min, r_max = {self.r_min!r}, {self.r_max!r}; "
                             "expected 0 <= r_min < r_max <= 1")
        if self.safety not in SAFETY:
            raise ValueError(f"Steering.safety = {self.safety!r}; expected one of {SAFETY}")
        if not (0.0 <= self.share < 1.0):
            raise ValueError(f"Steering.share = {self.share!r}; expected a number in [0, 1)")


class CourseCommand(NamedTuple):
    """What :func:`steer` commands, per agent (shape ``(..., N)``).

    ``course``: the commanded course C (eq. 64), inside [C0 - w dt, C0 + w dt].
    ``sub``: ``(..., N, 3)`` the sub-courses (C_Rn, C_Rt, C_Dt); a sub-objective without data
    holds the current course. ``feasible``: the commanded course meets every constraint.
    ``violation``: its total shortfall in metres (neighbour plus target barriers; 0 when
    feasible).
    """

    course: Array
    sub: Array
    feasible: NDArray[np.bool_]
    violation: Array


# -- kinematics --------------------------------------------------------------------------------


def _arc(position: Array, course: Array, speed: Array, delta: Array, dt: Array,
         turn_rate: float) -> Array:
    """Position after turning by ``delta`` (|delta| <= w dt) at rate w, then straight to dt.

    The turn lasts tau = |delta| / w and covers the chord v tau sinc(delta / 2) along the mean
    course C + delta / 2 (sinc(x) = sin x / x keeps delta -> 0 exact); the straight part
    covers v (dt - tau) along C + delta.
    """
    tau = np.abs(delta) / turn_rate
    chord = speed * tau * np.sinc(delta / (2.0 * np.pi))
    rest = speed * np.maximum(dt - tau, 0.0)
    mid, end = course + 0.5 * delta, course + delta
    step = np.stack([chord * np.sin(mid) + rest * np.sin(end),
                     chord * np.cos(mid) + rest * np.cos(end)], axis=-1)
    return position + step


def move(position: ArrayLike, course: ArrayLike, speed: ArrayLike, commanded: ArrayLike,
         dt: ArrayLike, turn_rate: float = TURN_RATE, check: bool = True
         ) -> tuple[Array, Array]:
    """Move agents for dt at constant speed towards a commanded course.

    The agent turns the short way at the full rate w (``turn_rate``) until it reaches the
    commanded course, then runs straight: with ``delta = clip(wrap(C_cmd - C), -w dt, w dt)``
    the new course is ``wrap(C + delta)`` (the commanded course if it is reachable within
    dt, else C +- w dt) and the displacement is the arc of the turn plus the straight leg
    (see ``_arc``). A command of exactly C + pi turns clockwise.

    ``position`` ``(..., 2)``; ``course``, ``speed``, ``commanded``, ``dt`` broadcast to
    ``(...)``. Returns ``(position, course)``. Moving for dt1 then dt2 with the same command
    equals moving for dt1 + dt2. ``check=False`` skips the checks of the arguments (for the
    simulator's own float arrays, moved twice per agent execution; the same numbers).
    """
    if not check:
        p, C, v, cmd, T = (np.asarray(a, dtype=float) for a in (position, course, speed,
                                                                 commanded, dt))
        return _moved(p, C, v, cmd, T, turn_rate, np.broadcast_shapes(
            p.shape[:-1], C.shape, v.shape, cmd.shape, T.shape))
    p = _array(position, "position")
    if p.ndim < 1 or p.shape[-1] != 2:
        raise ValueError(f"position has shape {p.shape}; expected (..., 2), east and north")
    C = _array(course, "course")
    v = _array(speed, "speed")
    cmd = _array(commanded, "commanded")
    T = _array(dt, "dt")
    _nonneg(v, "speed")
    _nonneg(T, "dt")
    if not (np.isfinite(turn_rate) and turn_rate > 0):
        raise ValueError(f"turn_rate = {turn_rate!r}; expected a finite number > 0 (rad/s)")
    shape = _broadcast({"position[..., 0]": p.shape[:-1], "course": C.shape, "speed": v.shape,
                        "commanded": cmd.shape, "dt": T.shape})
    return _moved(p, C, v, cmd, T, turn_rate, shape)


def _moved(p: Array, C: Array, v: Array, cmd: Array, T: Array, turn_rate: float,
           shape: tuple[int, ...]) -> tuple[Array, Array]:
    """``move`` of checked arguments broadcasting to ``shape``."""
    reach = turn_rate * T
    delta = np.clip(wrap(cmd - C), -reach, reach)
    new = _arc(np.broadcast_to(p, shape + (2,)), C, v, delta, T, turn_rate)
    return new, np.broadcast_to(wrap(C + delta), shape).copy()


def admissible_courses(course: ArrayLike, dt: ArrayLike, turn_rate: float = TURN_RATE,
                       n_candidates: int = 41) -> Array:
    """The candidate courses ``wrap(C + w dt g_k)``, ``(..., K)`` with K = ``n_candidates``
    (odd): g_k evenly spaced on [-1, 1] in the order 0, +1/m, -1/m, +2/m, ..., +1, -1
    (m = (K - 1) / 2), so that the first of equal costs is the smallest turn."""
    C = _array(course, "course")
    T = _array(dt, "dt")
    params = Steering(turn_rate=turn_rate, n_candidates=n_candidates)
    _check_dt(T, params.turn_rate)
    return wrap(C[..., None] + _offsets(T[..., None], params))


def _grid(n: int) -> Array:
    m = (n - 1) // 2
    k = np.arange(1, m + 1) / m
    return np.concatenate([[0.0], np.stack([k, -k], axis=-1).ravel()])


def _offsets(dt: Array, params: Steering) -> Array:
    return params.turn_rate * dt * _grid(params.n_candidates)


# -- the blend -------------------------------------------------------------------------------


def blend_courses(courses: ArrayLike, weights: ArrayLike = (1.0, 1.0, 1.0)) -> Array:
    """Eq. 64 as a weighted circular mean: ``atan2(sum_m K_m sin C_m, sum_m K_m cos C_m)``.

    ``courses`` ``(..., 3)``: (C_Rn, C_Rt, C_Dt); ``weights`` ``(3,)`` or ``(..., 3)``:
    (K_Rn, K_Rt, K_Dt), >= 0 and not all 0. The paper's linear mean would blend 359 deg and
    1 deg to 180 deg; the circular mean gives 0.
    """
    C = _array(courses, "courses")
    K = _array(weights, "weights")
    if C.ndim < 1 or K.ndim < 1 or C.shape[-1] != K.shape[-1]:
        raise ValueError(f"courses has shape {C.shape} and weights {K.shape}; expected the "
                         "same last axis (one weight per course)")
    if not np.isfinite(C).all():
        raise ValueError("courses has a non-finite entry; expected finite angles (rad)")
    if not np.isfinite(K).all() or (K < 0).any():
        raise ValueError(f"weights = {K.tolist()!r}; expected finite numbers >= 0")
    if (K.sum(-1) <= 0).any():
        raise ValueError(f"weights = {K.tolist()!r}; expected a positive sum")
    return circular_mean(C, np.broadcast_to(K, np.broadcast_shapes(C.shape, K.shape)))


# -- the network -----------------------------------------------------------------------------


def swarm_neighbours(position: ArrayLike, course: ArrayLike, speed: ArrayLike,
                     comm_range: ArrayLike) -> tuple[Array, Array, Array]:
    """Every agent's neighbours in the disk graph of the paper (agents a and i linked when
    their distance is at most min(CR_a, CR_i)), as the per-agent arrays :func:`steer` takes.

    ``position`` ``(..., N, 2)``, ``course``, ``speed``, ``comm_range`` ``(..., N)``. Returns
    ``(neighbours, neighbour_velocity, neighbour_range)``, ``(..., N, N, 2)``,
    ``(..., N, N, 2)`` and ``(..., N, N)``: row a, column i holds agent i's position, velocity
    ``v_i (sin C_i, cos C_i)`` and CR_i, nan where i is a itself or not linked.
    """
    p = _array(position, "position")
    if p.ndim < 2 or p.shape[-1] != 2:
        raise ValueError(f"position has shape {p.shape}; expected (..., N, 2)")
    C, v, CR = (_array(a, n) for a, n in ((course, "course"), (speed, "speed"),
                                          (comm_range, "comm_range")))
    _positive(CR, "comm_range")
    shape = _broadcast({"position[..., 0]": p.shape[:-1], "course": C.shape, "speed": v.shape,
                        "comm_range": CR.shape})
    p = np.broadcast_to(p, shape + (2,))
    C, v, CR = (np.broadcast_to(a, shape) for a in (C, v, CR))
    vel = v[..., None] * np.stack([np.sin(C), np.cos(C)], -1)
    d = np.hypot(*np.moveaxis(p[..., None, :, :] - p[..., :, None, :], -1, 0))
    link = (d <= np.minimum(CR[..., :, None], CR[..., None, :])) & ~np.eye(shape[-1], dtype=bool)
    full = shape + (shape[-1],)
    nb = np.where(link[..., None], np.broadcast_to(p[..., None, :, :], full + (2,)), np.nan)
    nv = np.where(link[..., None], np.broadcast_to(vel[..., None, :, :], full + (2,)), np.nan)
    nr = np.where(link, np.broadcast_to(CR[..., None, :], full), np.nan)
    return nb, nv, nr


# -- the controller --------------------------------------------------------------------------


def steer(position: ArrayLike, course: ArrayLike, speed: ArrayLike, dt: ArrayLike, *,
          targets: ArrayLike | None = None, target_velocity: ArrayLike | None = None,
          neighbours: ArrayLike | None = None, neighbour_velocity: ArrayLike | None = None,
          neighbour_range: ArrayLike | None = None, comm_range: ArrayLike = np.inf,
          meas_range: ArrayLike = np.inf, params: Steering | None = None) -> CourseCommand:
    """The course each agent commands for its next dt (Jalalipoor and Kardehi Moghaddam 2021, eqs.
    52-64; see the module docstring for the maths, the horizon, the constraints and the choices
    made).

    Shapes (``...`` runs, N agents; every array broadcasts against the others):

    * ``position`` ``(..., N, 2)``; ``course``, ``speed``, ``dt`` ``(..., N)``: each agent's
      own state and the time until its next execution (``w dt < pi/2``).
    * ``targets`` ``(..., N, T, 2)``: agent a's estimated target positions (its tracks); a
      row of nan is a target a does not know. ``target_velocity`` the same shape (nan or
      None: static).
    * ``neighbours`` ``(..., N, M, 2)``: the neighbours' positions as a knows them, nan for
      none (:func:`swarm_neighbours` builds them from the agents' states);
      ``neighbour_velocity`` the same shape; ``neighbour_range`` ``(..., N, M)``: their CR_i
      (None: a's own).
    * ``comm_range``, ``meas_range`` ``(..., N)``: CR_a, MR_a (inf: unlimited).

    Returns a :class:`CourseCommand`; move the agents with :func:`move`.
    """
    params = Steering() if params is None else params
    p = _array(position, "position")
    if p.ndim < 2 or p.shape[-1] != 2:
        raise ValueError(f"position has shape {p.shape}; expected (..., N, 2), east and north "
                         "of each agent")
    C, v, T, CR, MR = (_array(a, n) for a, n in (
        (course, "course"), (speed, "speed"), (dt, "dt"), (comm_range, "comm_range"),
        (meas_range, "meas_range")))
    for a, n in ((C, "course"), (v, "speed"), (T, "dt")):
        if not np.isfinite(a).all():
            raise ValueError(f"{n} has a non-finite entry; expected finite numbers")
    _nonneg(v, "speed")
    _check_dt(T, params.turn_rate)
    _positive(CR, "comm_range")
    _positive(MR, "meas_range")
    tq, tv, tmask = _others(targets, target_velocity, None, "targets", "target_velocity", None)
    nq, nv, nmask = _others(neighbours, neighbour_velocity, neighbour_range, "neighbours",
                            "neighbour_velocity", "neighbour_range")
    nr = nmask[1] if nmask is not None else None
    nmask = nmask[0] if nmask is not None else None
    shapes = {"position[..., 0]": p.shape[:-1], "course": C.shape, "speed": v.shape,
              "dt": T.shape, "comm_range": CR.shape, "meas_range": MR.shape}
    if tq is not None:
        shapes["targets[..., 0, 0]"] = tq.shape[:-2]
    if nq is not None:
        shapes["neighbours[..., 0, 0]"] = nq.shape[:-2]
        if nr is not None:
            shapes["neighbour_range[..., 0]"] = nr.shape[:-1]
    shape = _broadcast(shapes)
    p = np.broadcast_to(p, shape + (2,))
    C, v, T, CR, MR = (np.broadcast_to(a, shape) for a in (C, v, T, CR, MR))

    if params.straight:
        zero = np.zeros(shape)
        sub = np.broadcast_to(C[..., None], shape + (3,)).copy()
        feas, viol = _evaluate(zero[..., None], p, C, v, T, CR, MR, tq, tv, tmask, nq, nv,
                               nmask, nr, params)[3:]
        return CourseCommand(C.copy(), sub, feas[..., 0], viol[..., 0])

    off = _offsets(T[..., None], params)  # (..., N, K)
    J_rn, J_rt, J_dt, feas, viol, nviol, tviol = _evaluate(
        off, p, C, v, T, CR, MR, tq, tv, tmask, nq, nv, nmask, nr, params, detail=True)

    # the allowed candidates: feasible, else targets relaxed first, else least neighbour
    # shortfall (connectivity first; module docstring)
    n_ok = nviol == 0.0
    t_least = tviol <= np.min(np.where(n_ok, tviol, np.inf), -1, keepdims=True) + _TIE
    n_least = nviol <= nviol.min(-1, keepdims=True) + _TIE
    allowed = np.where(feas.any(-1, keepdims=True), feas,
                       np.where(n_ok.any(-1, keepdims=True), n_ok & t_least, n_least))

    has_n = nmask.any(-1) if nmask is not None else np.zeros(shape, bool)
    has_t = tmask.any(-1) if tmask is not None else np.zeros(shape, bool)
    picks, weights = [], []
    for J, has, k in ((J_rn, has_n, params.k_rn), (J_rt, has_t, params.k_rt),
                      (J_dt, has_t, params.k_dt)):
        i = np.argmin(np.where(allowed, J, np.inf), axis=-1)
        picks.append(np.where(has, np.take_along_axis(off, i[..., None], -1)[..., 0], 0.0))
        weights.append(np.where(has, k, 0.0))
    sub_off = np.stack(picks, -1)
    K = np.stack(weights, -1)
    # the blend of the offsets from C (all within +-w dt < pi/2), so the circular mean stays
    # in the interval; the clip only removes rounding
    reach = params.turn_rate * T
    total = K.sum(-1)
    b = np.arctan2((K * np.sin(sub_off)).sum(-1), (K * np.cos(sub_off)).sum(-1))
    b = np.clip(np.where(total > 0, b, 0.0), -reach, reach)

    # the blend is commanded if it is as good as the allowed set; else the allowed candidate
    # nearest to it (the feasible set of courses need not be an interval)
    b_feas, b_viol, b_nv, b_tv = _evaluate(b[..., None], p, C, v, T, CR, MR, tq, tv, tmask,
                                           nq, nv, nmask, nr, params, detail=True)[3:]
    b_ok = np.where(feas.any(-1), b_feas[..., 0], False)
    nearest = np.argmin(np.where(allowed, np.abs(off - b[..., None]), np.inf), axis=-1)
    near_off = np.take_along_axis(off, nearest[..., None], -1)[..., 0]
    out_off = np.where(b_ok, b, near_off)
    out_viol = np.where(b_ok, b_viol[..., 0],
                        np.take_along_axis(viol, nearest[..., None], -1)[..., 0])
    return CourseCommand(course=wrap(C + out_off), sub=wrap(C[..., None] + sub_off),
                         feasible=out_viol == 0.0, violation=out_viol)


def _evaluate(off: Array, p: Array, C: Array, v: Array, T: Array, CR: Array, MR: Array,
              tq: Array | None, tv: Array | None, tmask: Array | None, nq: Array | None,
              nv: Array | None, nmask: Array | None, nr: Array | None, params: Steering,
              detail: bool = False) -> tuple[Array, ...]:
    """Costs and constraint shortfalls of candidate turns ``off`` ``(..., N, K)``.

    Returns ``(J_rn, J_rt, J_dt, feasible, violation)`` (``(..., N, K)`` each), and with
    ``detail`` also the neighbour and target shortfalls (metres, summed over the pairs).
    """
    w = params.turn_rate
    c = C[..., None] + off
    pa = _arc(p[..., None, :], C[..., None], v[..., None], off, T[..., None], w)
    circle = params.safety == "circle"
    if circle:
        Ra = v / w
        ca = _centre(pa, c, Ra[..., None])  # (..., N, K, 2): after the step
        ca0 = _centre(p, C, Ra)[..., None, :]  # (..., N, 1, 2): now
    zeros = np.zeros(off.shape)
    J_rn, J_rt, J_dt, n_sh, t_sh = zeros, zeros, zeros, zeros, zeros

    if nq is not None:
        T2 = T[..., None, None]
        d_pred = _dist(pa[..., :, None, :], (nq + nv * T2)[..., None, :, :])
        J_rn = -np.where(nmask[..., None, :], d_pred, 0.0).sum(-1)
        CRn = np.minimum(CR[..., None], nr) if nr is not None else CR[..., None]
        lo, hi = _bounds(CRn, params)  # (..., N, M)
        finite = np.isfinite(hi)
        hi = np.where(finite, hi, 0.0)
        if circle:
            # the neighbour's backup centre where it is now: its own step is its share
            vi = np.hypot(nv[..., 0], nv[..., 1])
            Ci = np.arctan2(nv[..., 0], nv[..., 1])
            Ri = vi / w
            ci = _centre(nq, Ci, Ri)  # (..., N, M, 2)
            D = ci - ca0  # (..., N, M, 2)
            dist = np.hypot(D[..., 0], D[..., 1])
            safe = np.where(dist > 0, dist, 1.0)
            u = np.where((dist > 0)[..., None], D / safe[..., None], 0.0)
            rad = Ra[..., None] + Ri
            h0_lo = dist - rad - lo - params.margin
            h0_hi = hi - dist - rad - params.margin
            # the own centre's move along the line of centres, to first order (the distance
            # is convex, so the linear change under-states the true one for the lower bound)
            alpha = ca[..., :, None, :] - ca0[..., :, None, :]  # (..., N, K, 1, 2)
            along = (alpha * u[..., None, :, :]).sum(-1)  # (..., N, K, M)
            rho = params.share
            h0_lo, h0_hi = h0_lo[..., None, :], h0_hi[..., None, :]
            sh = _shortfall(rho * h0_lo - (h0_lo - along)) + np.where(
                finite[..., None, :], _shortfall(rho * h0_hi - (h0_hi + along)), 0.0)
        else:
            sh = _shortfall(lo[..., None, :] - d_pred) + np.where(
                finite[..., None, :], _shortfall(d_pred - hi[..., None, :]), 0.0)
        n_sh = np.where(nmask[..., None, :], sh, 0.0).sum(-1)

    if tq is not None:
        t_pred = (tq + tv * T[..., None, None])[..., None, :, :]  # (..., N, 1, T, 2)
        dx = t_pred[..., 0] - pa[..., :, None, 0]
        dy = t_pred[..., 1] - pa[..., :, None, 1]
        d = np.hypot(dx, dy)
        m = tmask[..., None, :]
        J_rt = np.where(m, d, 0.0).sum(-1)
        lam = np.abs(wrap(np.arctan2(dx, dy) - c[..., None]))
        cost = params.K1 * (1.0 - np.exp(-params.K2 * (lam - 0.5 * np.pi) ** 2))
        J_dt = np.where(m, cost, 0.0).sum(-1)
        lo, hi = _bounds(MR[..., None, None], params)
        finite = np.isfinite(hi)
        hi = np.where(finite, hi, 0.0)
        if circle:
            # a target does not steer: the agent keeps the whole barrier itself (rho = 0)
            dc = _dist(ca[..., :, None, :], t_pred)
            rad = Ra[..., None, None]
            sh = _shortfall(lo + rad + params.margin - dc) + np.where(
                finite, _shortfall(dc + rad + params.margin - hi), 0.0)
        else:
            sh = _shortfall(lo - d) + np.where(finite, _shortfall(d - hi), 0.0)
        t_sh = np.where(m, sh, 0.0).sum(-1)

    viol = n_sh + t_sh
    out = (J_rn, J_rt, J_dt, viol == 0.0, viol)
    return out + (n_sh, t_sh) if detail else out


def _centre(p: Array, c: Array, R: Array) -> Array:
    """Centre of the clockwise (starboard) turning circle: ``p + R (cos c, -sin c)``."""
    return p + R[..., None] * np.stack([np.cos(c), -np.sin(c)], -1)


def _bounds(rng: Array, params: Steering) -> tuple[Array, Array]:
    """(R_min, R_max) = (r_min, r_max) x range; an infinite range bounds nothing."""
    finite = np.isfinite(rng)
    r = np.where(finite, rng, 0.0)
    return params.r_min * r, np.where(finite, params.r_max * r, np.inf)


def _shortfall(x: Array) -> Array:
    return np.maximum(x, 0.0)


def _dist(a: Array, b: Array) -> Array:
    return np.hypot(b[..., 0] - a[..., 0], b[..., 1] - a[..., 1])


# -- input checks ----------------------------------------------------------------------------


def _array(x: ArrayLike, name: str) -> Array:
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {x!r}; expected an array of numbers") from None


def _nonneg(a: Array, name: str) -> None:
    bad = ~(np.isfinite(a) & (a >= 0))
    if bad.any():
        raise ValueError(f"{name} has the entry {a[bad].ravel()[0]!r}; expected finite "
                         "numbers >= 0")


def _positive(a: Array, name: str) -> None:
    bad = np.isnan(a) | (a <= 0)
    if bad.any():
        raise ValueError(f"{name} has the entry {a[bad].ravel()[0]!r}; expected numbers > 0 "
                         "(metres; inf for unlimited)")


def _check_dt(T: Array, turn_rate: float) -> None:
    bad = ~(np.isfinite(T) & (T > 0) & (turn_rate * T < 0.5 * np.pi))
    if bad.any():
        limit = 0.5 * np.pi / turn_rate
        raise ValueError(f"dt has the entry {T[bad].ravel()[0]!r}; expected 0 < dt < "
                         f"{limit:.6g} s (turn_rate dt < pi/2, so that the admissible course "
                         "interval is shorter than pi)")


def _broadcast(shapes: dict[str, tuple[int, ...]]) -> tuple[int, ...]:
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        listed = ", ".join(f"{k} {v}" for k, v in shapes.items())
        raise ValueError(f"the (runs, agents) shapes do not broadcast: {listed}; expected "
                         "shapes that broadcast to (..., N)") from None


def _others(pos: ArrayLike | None, vel: ArrayLike | None, rng: ArrayLike | None, pname: str,
            vname: str, rname: str | None) -> tuple[Array | None, Array | None, object]:
    """Validate the positions (and velocities, ranges) of neighbours or targets, ``(..., N,
    M, 2)``; a row with a nan is absent. Returns them with absent rows zero-filled and the
    mask of present rows (for neighbours ``(mask, ranges)``)."""
    if pos is None:
        if vel is not None or (rng is not None):
            raise ValueError(f"{vname if vel is not None else rname} is given without {pname}; "
                             f"expected {pname} as well")
        return None, None, None
    q = _array(pos, pname)
    if q.ndim < 3 or q.shape[-1] != 2:
        raise ValueError(f"{pname} has shape {q.shape}; expected (..., N, M, 2): per agent, "
                         "M positions (east, north), nan where absent")
    if np.isinf(q).any():
        raise ValueError(f"{pname} has an infinite entry; expected finite positions (nan for "
                         "absent)")
    mask = ~np.isnan(q).any(-1)
    if vel is None:
        V = np.zeros(q.shape)
    else:
        V = _array(vel, vname)
        if V.shape != q.shape:
            try:
                V = np.broadcast_to(V, q.shape)
            except ValueError:
                raise ValueError(f"{vname} has shape {V.shape}; expected {q.shape}, the shape "
                                 f"of {pname}") from None
        if np.isinf(V).any() or np.isnan(V[mask]).any():
            raise ValueError(f"{vname} has a non-finite entry for a present {pname} row; "
                             "expected finite velocities (m/s)")
    q = np.where(mask[..., None], q, 0.0)
    V = np.where(mask[..., None], V, 0.0)
    if rname is None:
        return q, V, mask
    R = None
    if rng is not None:
        R = _array(rng, rname)
        try:
            R = np.broadcast_to(R, q.shape[:-1])
        except ValueError:
            raise ValueError(f"{rname} has shape {R.shape}; expected {q.shape[:-1]}, one "
                             f"range per row of {pname}") from None
        _positive(np.where(mask, R, 1.0), rname)
        R = np.where(mask, R, np.inf)
    return q, V, (mask, R)
