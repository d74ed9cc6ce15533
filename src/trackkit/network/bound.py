"""Posterior Cramer-Rao bound of constant-velocity targets seen by several moving bearing
sensors at asynchronous times (Jalalipoor and Kardehi Moghaddam 2021 give no such reference).

Each target's state x = [x, y, vx, vy] follows ``models.ConstantVelocity(dim=2, q=q)``
(F(dt), Q(dt)). The bearings of a run, from any agents at any times, are sorted into an event
grid t_1 <= t_2 <= ... <= t_M (the union of the bearing times; t_0 is the prior's time). With
J_0 = P0^{-1} the recursion over the events is, per run and per target::

    J_{k+1} = (Q(dt_k) + F(dt_k) J_k^{-1} F(dt_k)^T)^{-1} + I_{k+1},   dt_k = t_{k+1} - t_k
    I_{k+1} = sum over the bearings at t_{k+1} of  H^T H / sigma^2
    H       = [dh/dx, dh/dy, 0, 0] = [dy, -dx, 0, 0] / r^2   (nautical h = atan2(dx, dy))

with (dx, dy) the true target position minus the sensor's position at that time and
r^2 = dx^2 + dy^2 (``models.Bearing.jacobian``). For F and Q that do not depend on the state,
as here, this is Tichavsky, Muravchik and Nehorai's recursion exactly (``eval.crlb``, whose
covariance-form prediction is reused), and ``E[(xhat - x)(xhat - x)^T] >= J_k^{-1}``. The
bound is reported as the position RMSE bound ``sqrt(tr [J_k^{-1}]_pos)`` after each event's
update (and the velocity one likewise).

With q = 0 the prediction is ``J_{k+1|k} = F(dt)^{-T} J_k F(dt)^{-1}``, F(dt)^{-1} = F(-dt)
(the same value, without inverting J), so the recursion also runs with no prior
(``prior_cov=None``, J_0 = 0), where the information may stay singular (e.g. the range of one
stationary sensor's target): its bound is then inf. With q > 0 a prior is required: the
information form ``D22 - D21 (J + D11)^{-1} D12`` that avoids J^{-1} needs Q^{-1}, and two
agents' executions a millisecond apart give Q(dt) ~ q dt^3 / 3 so small that the form's
cancellation destroys positive definiteness.

Events at equal times (dt = 0) skip the prediction, so bearings taken at the same instant
simply add. Rows of a batch are independent: ``...`` (runs) and Nt (targets) are batch axes.

Per run, the bound is conditional on that run's schedule, agent paths and target truth (H is
evaluated on the run's own truth). With q = 0 and a deterministic initial state that is the
PCRLB of the run. With q > 0 the unconditional PCRLB averages I over the truths at a common
schedule: run ``information_recursion`` with the run-averaged information.

A centralised-fusion bound uses every agent's bearings; a single agent's bound only its own
(``network_run_pcrlb(..., agents=[i])``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.eval.crlb import inverse_spd, predict_information, rmse_bound
from trackkit.linalg import check_covariance, symmetrize
from trackkit.models.motion import ConstantVelocity
from trackkit.models.sensors import Bearing, check_convention
from trackkit.sim.sensor_network import NetworkRun

__all__ = [
    "NetworkBound",
    "bearing_information",
    "information_recursion",
    "network_pcrlb",
    "network_run_pcrlb",
]

Array = NDArray[np.float64]

#: a J whose unit-diagonal form has lambda_min / lambda_max below this is singular (its
#: bound is inf): the state is not observed (used only without a prior)
_RCOND = 1e-12


class NetworkBound(NamedTuple):
    """The bound on an event grid, batch shape ``...`` (runs), Nt targets, M events.

    ``time`` ``(..., M)``: the sorted event times. ``order`` ``(..., M)``: the input index of
    each sorted event (``time = take_along_axis(input_time, order, -1)``).
    ``position_rmse`` ``(..., M, Nt)``: ``sqrt(tr [J_k^{-1}]_{xy})`` after event k's update
    (m; inf where J_k is singular). ``velocity_rmse`` ``(..., M, Nt)`` likewise (m/s).
    ``information`` ``(..., Nt, 4, 4)``: J after the last event. ``history``
    ``(..., M, Nt, 4, 4)``: J after every event, when asked for (else None).
    """

    time: Array
    order: NDArray[np.intp]
    position_rmse: Array
    velocity_rmse: Array
    information: Array
    history: Array | None


def _check_q(q: float) -> float:
    q = float(q)
    if not (q >= 0 and np.isfinite(q)):
        raise ValueError(f"q = {q!r}; expected a finite spectral density >= 0 (m^2/s^3)")
    return q


def _rmse(J: Array, have_prior: bool) -> tuple[Array, Array]:
    """Position and velocity RMSE bounds of J ``(..., 4, 4)``; inf where J is singular."""
    if have_prior:  # J >= P0^-1 is positive definite
        P = inverse_spd(J, "PCRLB information matrix J_k")
        return rmse_bound(P, [0, 1]), rmse_bound(P, [2, 3])
    # without a prior, judge singularity on the unit-diagonal scale, where metres and m/s
    # weigh alike (J's raw eigenvalues span the squared ratio of ranges to times)
    d = np.diagonal(J, axis1=-2, axis2=-1)
    ok = np.all(d > 0, axis=-1)
    s = 1.0 / np.sqrt(np.where(d > 0, d, 1.0))
    Js = J * s[..., :, None] * s[..., None, :]
    lam, V = np.linalg.eigh(Js)
    ok &= lam[..., 0] > _RCOND * lam[..., -1]
    inv_lam = 1.0 / np.where(ok[..., None], lam, 1.0)
    P = (V * inv_lam[..., None, :]) @ V.mT * s[..., :, None] * s[..., None, :]
    pos, vel = rmse_bound(P, [0, 1]), rmse_bound(P, [2, 3])
    return np.where(ok, pos, np.inf), np.where(ok, vel, np.inf)


def _recursion(
    prior_cov: ArrayLike | None,
    t0: ArrayLike,
    time: ArrayLike,
    info_at: Callable[[NDArray[np.intp]], Array],
    n_targets: int,
    q: float,
    history: bool,
) -> NetworkBound:
    """The recursion of the module docstring over the sorted events; ``info_at(order[..., k])``
    gives event k's measurement information ``(..., Nt, 4, 4)``."""
    q = _check_q(q)
    t = np.asarray(time, dtype=float)
    if t.ndim < 1 or t.shape[-1] < 1 or not np.all(np.isfinite(t)):
        raise ValueError(f"time has shape {t.shape}; expected finite event times (..., M)")
    batch, M = t.shape[:-1], t.shape[-1]
    start = np.broadcast_to(np.asarray(t0, dtype=float), batch)
    if not np.all(np.isfinite(start)):
        raise ValueError(f"t0 = {t0!r}; expected finite prior time(s)")
    if np.any(t < start[..., None]):
        raise ValueError(f"time has events before t0 (earliest {t.min()!r} s, t0 "
                         f"{start.min()!r} s); expected every event at or after the prior")
    order = np.argsort(t, axis=-1, kind="stable")
    ts = np.take_along_axis(t, order, -1)
    dts = np.diff(np.concatenate([start[..., None], ts], -1), axis=-1)

    shape = batch + (n_targets, 4, 4)
    have_prior = prior_cov is not None
    if not have_prior and q > 0:
        raise ValueError(f"prior_cov is None with q = {q!r}; expected a prior covariance "
                         "when q > 0 (without one, only q = 0 is supported)")
    if have_prior:
        P0 = check_covariance(prior_cov, "prior_cov", n=4)
        try:
            P0 = np.broadcast_to(P0, shape)
        except ValueError:
            raise ValueError(f"prior_cov has shape {P0.shape}; expected (4, 4) or a batch "
                             f"broadcastable to {shape}") from None
        J = inverse_spd(np.ascontiguousarray(P0), "prior_cov")
    else:
        J = np.zeros(shape)

    cv = ConstantVelocity(dim=2, q=q)
    pos = np.empty(batch + (M, n_targets))
    vel = np.empty_like(pos)
    hist = np.empty(batch + (M,) + shape[len(batch):]) if history else None
    for k in range(M):
        dt = dts[..., k]
        moved = dt > 0
        if moved.any():
            # rows with dt = 0 take a dummy step (their Q = 0 has no inverse) and are
            # put back below
            step = np.where(moved, dt, 1.0)[..., None]  # broadcast over the targets
            if q == 0:
                Finv = cv.jacobian(None, -step)
                Jp = symmetrize(Finv.mT @ J @ Finv)
            else:
                F, Q = cv.jacobian(None, step), cv.noise(None, step)
                Jp = predict_information(J, F, Q, runs_axis=False)
            J = np.where(moved[..., None, None, None], Jp, J)
        J = symmetrize(J + info_at(order[..., k]))
        pos[..., k, :], vel[..., k, :] = _rmse(J, have_prior)
        if hist is not None:
            hist[..., k, :, :, :] = J
    return NetworkBound(ts, order, pos, vel, J, hist)


def _take(a: Array, idx: NDArray[np.intp], n_trailing: int) -> Array:
    """Row-wise ``a[..., idx[...], <n_trailing axes>]``: one event per batch row, ``a``
    shaped ``idx.shape + (M,) + trailing``."""
    ix = idx.reshape(idx.shape + (1,) * (1 + n_trailing))
    return np.take_along_axis(a, ix, axis=idx.ndim).squeeze(axis=idx.ndim)


def information_recursion(
    prior_cov: ArrayLike | None,
    time: ArrayLike,
    information: ArrayLike,
    *,
    q: float = 0.0,
    t0: ArrayLike = 0.0,
    history: bool = False,
) -> NetworkBound:
    """The bound's recursion with any measurement information (module docstring).

    Args:

        prior_cov: P0 ``(4, 4)`` or broadcastable to ``(..., Nt, 4, 4)`` at ``t0``; None for
            no prior (J_0 = 0; q = 0 only).
        time: ``(..., M)`` event times >= t0, any order (sorted here, stably).
        information: ``(..., M, Nt, 4, 4)`` each event's measurement information
            (e.g. ``H^T R^{-1} H`` of a position sensor, or ``bearing_information``).
        q: the CV process-noise spectral density (m^2/s^3).
        t0: the prior's time, scalar or ``(...)``.
        history: keep J after every event.

    Returns:

        ``NetworkBound``.
    """
    t = np.asarray(time, dtype=float)
    info = np.asarray(information, dtype=float)
    if info.ndim != t.ndim + 3 or info.shape[:t.ndim] != t.shape or info.shape[-2:] != (4, 4):
        raise ValueError(f"information has shape {info.shape}; expected (..., M, Nt, 4, 4) "
                         f"with (..., M) = {t.shape}, the shape of time")
    if not np.all(np.isfinite(info)):
        raise ValueError("information has non-finite entries; expected finite matrices")
    return _recursion(prior_cov, t0, t, lambda idx: _take(info, idx, 3), info.shape[-3], q,
                      history)


def bearing_information(
    truth: ArrayLike,
    sensor_pos: ArrayLike,
    sigma: ArrayLike,
    valid: ArrayLike | None = None,
    convention: str = "nautical",
) -> Array:
    """``valid H^T H / sigma^2`` ``(..., Nt, 4, 4)`` of one bearing per target.

    ``truth`` ``(..., Nt, 4)`` the true states; ``sensor_pos`` ``(..., 2)`` the sensor
    position; ``sigma`` (rad) broadcastable to ``(...)``; ``valid`` ``(..., Nt)`` booleans
    (False: no bearing, no information). H is ``models.Bearing.jacobian`` at the truth.
    """
    x = np.asarray(truth, dtype=float)
    S = np.asarray(sensor_pos, dtype=float)
    if x.ndim < 2 or x.shape[-1] != 4:
        raise ValueError(f"truth has shape {x.shape}; expected (..., Nt, 4) states")
    if S.ndim < 1 or S.shape[-1] != 2:
        raise ValueError(f"sensor_pos has shape {S.shape}; expected (..., 2) positions")
    sig = np.asarray(sigma, dtype=float)
    if not (np.all(sig > 0) and np.all(np.isfinite(sig))):
        raise ValueError(f"sigma = {sig.tolist()}; expected finite values > 0 (rad)")
    v = np.ones(x.shape[:-1], bool) if valid is None else np.asarray(valid, dtype=bool)
    # an absent slot may hold anything (nan padding, a target on the sensor): read a
    # harmless point there, then give it no weight
    S = np.broadcast_to(S[..., None, :], np.broadcast_shapes(S[..., None, :].shape,
                                                             x[..., :2].shape))
    good = np.broadcast_to(v, S.shape[:-1])
    xs = np.where(good[..., None], x[..., :2], S + 1.0)
    if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(S[good]))):
        raise ValueError("truth or sensor_pos has non-finite positions at a valid bearing")
    if np.any(np.all(xs == S, axis=-1)):
        raise ValueError("a valid bearing's sensor sits on its target; expected r > 0")
    H = Bearing(origin=S, convention=convention).jacobian(xs)[..., 0, :]  # (..., Nt, 2)
    w = np.where(good, 1.0, 0.0) / (sig**2)[..., None]
    out = np.zeros(H.shape[:-1] + (4, 4))
    out[..., :2, :2] = w[..., None, None] * H[..., :, None] * H[..., None, :]
    return out


def network_pcrlb(
    prior_cov: ArrayLike | None,
    time: ArrayLike,
    sensor_pos: ArrayLike,
    truth: ArrayLike,
    sigma: ArrayLike,
    valid: ArrayLike | None = None,
    *,
    q: float = 0.0,
    t0: ArrayLike = 0.0,
    history: bool = False,
    convention: str = "nautical",
) -> NetworkBound:
    """The multi-sensor bearings-only PCRLB of Nt CV targets (module docstring).

    An event is one execution: a sensor position and at most one bearing of each target.

    Args:

        prior_cov: P0 ``(4, 4)`` or broadcastable to ``(..., Nt, 4, 4)`` at ``t0``; None
            for no prior (q = 0 only).
        time: ``(..., M)`` event times >= t0 (any order; several events may share a time).
        sensor_pos: ``(..., M, 2)`` the sensor's position at each event (m).
        truth: ``(..., M, Nt, 4)`` the true target states at each event.
        sigma: bearing std (rad): scalar, or broadcastable to ``(..., M)``.
        valid: ``(..., M, Nt)`` booleans: whether the event has a bearing of the target
            (e.g. ``Bearings.in_range``); default all.
        q, t0, history: as ``information_recursion``.
        convention: "nautical" or "math".

    Returns:

        ``NetworkBound``.
    """
    check_convention(convention)
    t = np.asarray(time, dtype=float)
    S = np.asarray(sensor_pos, dtype=float)
    x = np.asarray(truth, dtype=float)
    if S.shape != t.shape + (2,):
        raise ValueError(f"sensor_pos has shape {S.shape}; expected (..., M, 2) = "
                         f"{t.shape + (2,)}")
    if x.ndim != t.ndim + 2 or x.shape[:t.ndim] != t.shape or x.shape[-1] != 4:
        raise ValueError(f"truth has shape {x.shape}; expected (..., M, Nt, 4) with "
                         f"(..., M) = {t.shape}")
    Nt = x.shape[-2]
    v = np.ones(t.shape + (Nt,), bool) if valid is None else np.asarray(valid, dtype=bool)
    if v.shape != t.shape + (Nt,):
        raise ValueError(f"valid has shape {v.shape}; expected (..., M, Nt) = "
                         f"{t.shape + (Nt,)}")
    sig = np.broadcast_to(np.asarray(sigma, dtype=float), t.shape)
    if not (np.all(sig > 0) and np.all(np.isfinite(sig))):
        raise ValueError(f"sigma has entries {np.unique(sig)[:5].tolist()}; expected finite "
                         "values > 0 (rad)")

    def info_at(idx: NDArray[np.intp]) -> Array:
        return bearing_information(_take(x, idx, 2), _take(S, idx, 1), _take(sig, idx, 0),
                                   _take(v, idx, 1), convention)

    return _recursion(prior_cov, t0, t, info_at, Nt, q, history)


def network_run_pcrlb(
    run: NetworkRun,
    prior_cov: ArrayLike | None,
    agents: Sequence[int] | None = None,
    *,
    q: float = 0.0,
    history: bool = False,
    convention: str = "nautical",
) -> NetworkBound:
    """The bound of a ``sim.sensor_network`` run from the bearings of ``agents`` (default all: the
    centralised-fusion bound; ``[i]``: agent i alone), prior at t = 0, batch axis runs.

    ``q`` should be the run's; out-of-range slots carry no information.
    """
    b = run.bearings
    A = b.time.shape[1]
    sel = np.arange(A) if agents is None else np.asarray(agents, dtype=int)
    if sel.ndim != 1 or sel.size < 1 or np.any((sel < 0) | (sel >= A)):
        raise ValueError(f"agents = {agents!r}; expected a non-empty list of indices in "
                         f"[0, {A})")
    R, E, Nt = b.time.shape[0], b.time.shape[2], b.z.shape[-1]
    M = sel.size * E
    sigma = np.broadcast_to(b.sigma[sel][:, None], (R, sel.size, E))
    return network_pcrlb(
        prior_cov,
        b.time[:, sel].reshape(R, M),
        b.sensor[:, sel].reshape(R, M, 2),
        run.target_at_bearing[:, sel].reshape(R, M, Nt, 4),
        sigma.reshape(R, M),
        b.in_range[:, sel].reshape(R, M, Nt),
        q=q,
        t0=0.0,
        history=history,
        convention=convention,
    )
