r"""Diffusion Kalman filter over a network of agents (Jalalipoor and Kardehi Moghaddam 2021, eqs.
44-50; Cattivelli and Sayed, "Diffusion strategies for distributed Kalman filtering and smoothing",
IEEE TAC 55(9), 2010).

N agents hold estimates of the same target(s). A belief is a :class:`~trackkit.Gaussian`
whose mean is ``(..., N, n)`` and covariance ``(..., N, n, n)``: the leading axes are runs
and targets, the last batch axis is the agent. One cycle, for agent k with neighbourhood
``N_k`` (k itself included):

* prediction (eqs. 44-45), :math:`\mathbf{x}_k^- = F \mathbf{x}_k`,
  :math:`P_k^- = F P_k F^\top + Q`: the core :class:`trackkit.filters.KF` prediction, applied
  to every agent at once;
* incremental update (eqs. 46-48, in information form), with the measurements
  :math:`\mathbf{z}_l` (:math:`H_l`, :math:`R_l`) of every :math:`l \in \mathcal{N}_k`:

  .. math::

      S_k &= \sum_{l \in \mathcal{N}_k} c_{lk} H_l^\top R_l^{-1} H_l, \qquad
      \mathbf{q}_k = \sum_{l \in \mathcal{N}_k} c_{lk} H_l^\top R_l^{-1} \mathbf{z}_l, \\
      (P_k^+)^{-1} &= (P_k^-)^{-1} + S_k, \qquad
      \psi_k = \mathbf{x}_k^- + P_k^+ (\mathbf{q}_k - S_k \mathbf{x}_k^-)

  which equals the paper's sequential single-measurement updates over ``l`` (with
  ``c_lk = 1``) in exact arithmetic;
* combination (eqs. 49-50) with weights :math:`a_{lk} \ge 0`,
  :math:`\sum_l a_{lk} = 1`, see :func:`combine`.

Adapt-then-combine (ATC, the paper's Fig. 5 order) updates and then combines; combine-then-
adapt (CTA) combines the predictions and then updates.

Weight matrices are stored row by row for the receiving agent: ``weights[..., k, l] =
a_lk``, the weight agent k gives agent l's estimate, so every row sums to 1 (Cattivelli and
Sayed's ``A`` is the transpose, with columns summing to 1). Likewise ``share[..., k, l] =
c_lk``. Every function works on any leading batch axes, and a weight matrix may carry batch
axes of its own (``(..., N, N)``: a proximity graph that differs by run or by step).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian
from trackkit.filters.base import check_belief, check_dt, output
from trackkit.filters.kalman import KF
from trackkit.linalg import check_covariance, cholesky, mm, solve_psd, symmetrize
from trackkit.models.protocols import MotionModel

__all__ = [
    "DiffusionKF",
    "neighbourhood",
    "uniform_weights",
    "metropolis_weights",
    "check_weights",
    "measurement_information",
    "adapt",
    "ci_weights",
    "combine",
    "COMBINATIONS",
]

Array = NDArray[np.float64]

#: the combination rules of :func:`combine`
COMBINATIONS = ("convex", "paper", "information", "ci")
_CRITERIA = ("det", "trace")
_ORDERS = ("atc", "cta")
#: tolerance on a weight row's sum
_ROW_TOL = 1e-12


# -- the network -----------------------------------------------------------------------------


def neighbourhood(adjacency: ArrayLike) -> NDArray[np.bool_]:
    """The neighbourhoods ``N_k`` as a boolean ``(..., N, N)`` matrix: ``adjacency`` with the
    self-loops set (k is always in ``N_k``).

    ``adjacency`` is ``(..., N, N)``, boolean or 0/1, symmetric (links are two-way, as in the
    paper's disk graph); its diagonal is ignored.
    """
    A = np.asarray(adjacency)
    if A.ndim < 2 or A.shape[-1] != A.shape[-2] or A.shape[-1] < 1:
        raise ValueError(f"adjacency has shape {A.shape}; expected (..., N, N) with N >= 1 "
                         "agents")
    if A.dtype != np.bool_:
        if not np.issubdtype(A.dtype, np.number):
            raise ValueError(f"adjacency has dtype {A.dtype}; expected booleans or 0/1")
        bad = ~np.isin(A, (0, 1))
        if bad.any():
            idx = [int(i) for i in np.argwhere(bad)[0]]
            raise ValueError(f"adjacency{idx} = {A[tuple(idx)].item()!r}; expected booleans or 0/1")
        A = A.astype(bool)
    asym = A != A.swapaxes(-1, -2)
    if asym.any():
        idx = [int(i) for i in np.argwhere(asym)[0]]
        k, l = idx[-2:]
        raise ValueError(f"adjacency is not symmetric: [{k}, {l}] is {bool(A[tuple(idx)])} "
                         f"but [{l}, {k}] is not (batch index {idx[:-2]}); expected two-way "
                         "links")
    return A | np.eye(A.shape[-1], dtype=bool)


def uniform_weights(adjacency: ArrayLike) -> Array:
    r"""Uniform weights :math:`a_{lk} = 1 / |\mathcal{N}_k|` for :math:`l \in \mathcal{N}_k`
    (self included), else 0.

    Rows sum to 1; the matrix is symmetric only when every agent has the same degree.
    """
    Nk = neighbourhood(adjacency)
    return Nk / Nk.sum(-1, keepdims=True)


def metropolis_weights(adjacency: ArrayLike) -> Array:
    r"""Metropolis-Hastings weights, 0 off the graph, with :math:`n_k = |\mathcal{N}_k|` (the
    degree plus one):

    .. math::

        a_{lk} = \frac{1}{\max(n_k, n_l)} \quad (l \in \mathcal{N}_k,\ l \ne k), \qquad
        a_{kk} = 1 - \sum_{l \ne k} a_{lk}


    Symmetric and doubly stochastic, with ``a_kk >= 1 / n_k > 0``: repeated combination
    converges to the network average on a connected graph (Xiao and Boyd 2004).
    """
    Nk = neighbourhood(adjacency)
    n = Nk.sum(-1).astype(float)
    off = Nk & ~np.eye(Nk.shape[-1], dtype=bool)
    W = np.where(off, 1.0 / np.maximum(n[..., :, None], n[..., None, :]), 0.0)
    diag = 1.0 - W.sum(-1)
    return W + diag[..., None] * np.eye(Nk.shape[-1])


def check_weights(weights: ArrayLike, adjacency: ArrayLike | None = None,
                  name: str = "weights") -> Array:
    """Validate a combination matrix ``weights[..., k, l] = a_lk`` and return it as floats.

    Finite, non-negative, rows summing to 1 (to 1e-12), and, given ``adjacency``, zero off
    the graph (``a_lk = 0`` for ``l`` not in ``N_k``). Raises ``ValueError`` naming
    ``name``, the offending entry and what is expected.
    """
    W = np.asarray(weights, dtype=float)
    if W.ndim < 2 or W.shape[-1] != W.shape[-2]:
        raise ValueError(f"{name} has shape {W.shape}; expected (..., N, N)")
    if not np.isfinite(W).all():
        bad = W[~np.isfinite(W)][0].item()
        raise ValueError(f"{name} has a non-finite entry ({bad}); expected finite weights")
    if (W < 0).any():
        idx = tuple(int(i) for i in np.argwhere(W < 0)[0])
        raise ValueError(f"{name}{list(idx)} = {W[idx].item()!r}; expected weights >= 0")
    rows = W.sum(-1)
    off = np.abs(rows - 1.0) > _ROW_TOL
    if off.any():
        idx = tuple(int(i) for i in np.argwhere(off)[0])
        raise ValueError(f"{name}: row {list(idx)} sums to {rows[idx].item()!r}; expected "
                         "every row (the weights one agent gives its neighbours) to sum to 1")
    if adjacency is not None:
        Nk = neighbourhood(adjacency)
        if Nk.shape[-1] != W.shape[-1]:
            raise ValueError(f"{name} has shape {W.shape} but the adjacency {Nk.shape}; "
                             "expected the same number of agents")
        outside = np.broadcast_to((W != 0) & ~Nk, np.broadcast_shapes(W.shape, Nk.shape))
        if outside.any():
            idx = tuple(int(i) for i in np.argwhere(outside)[0])
            bad = np.broadcast_to(W, outside.shape)[idx].item()
            raise ValueError(f"{name}{list(idx)} = {bad!r} but agents {idx[-2]} and "
                             f"{idx[-1]} are not linked; expected 0 off the graph")
    return W


def _mix(W: Array, A: Array, core: int) -> Array:
    """``sum_l W[..., k, l] A[..., l, c]`` for ``A`` of shape ``(..., N) + c`` with ``core``
    trailing axes ``c``: one matmul over the flattened core (several times faster than the
    equivalent einsum)."""
    shape = A.shape[A.ndim - core:]
    flat = A.reshape(A.shape[: A.ndim - core] + (-1,))
    out = W @ flat
    return out.reshape(out.shape[:-1] + shape)


def _pull(W: Array, A: Array, core: int) -> Array:
    """``sum_l W_kl (A_l - A_k)``: what agent k's combination adds to its own ``A_k``
    (``sum_l W_kl A_l = A_k + _pull(W, A)`` for rows summing to 1). Weighting deviations
    makes a consensus (every ``A_l`` the same) a fixed point bit for bit, and keeps large
    absolute values (positions) out of the weighted sum."""
    shape = A.shape[A.ndim - core:]
    flat = A.reshape(A.shape[: A.ndim - core] + (-1,))
    D = flat[..., None, :, :] - flat[..., :, None, :]  # D[..., k, l] = A_l - A_k
    out = (W[..., :, None, :] @ D)[..., 0, :]
    return out.reshape(out.shape[:-1] + shape)


def _inverse_pd(P: Array, name: str) -> Array:
    """``P^-1`` for positive-definite ``P``: the Cholesky factor proves it definite (the error
    names ``name``), then LAPACK's batched inverse, about 3x faster than two triangular
    solves per matrix here."""
    cholesky(P, name)
    return symmetrize(np.linalg.inv(P))


def _agents(x: Array, W: Array, name: str, where: str) -> None:
    if x.ndim < 2 or x.shape[-2] != W.shape[-1]:
        raise ValueError(f"{where}.mean has shape {x.shape}; {name} is {W.shape[-2:]}, so "
                         f"expected (..., {W.shape[-1]}, n): the agent axis before the state")


# -- the incremental update ------------------------------------------------------------------


def measurement_information(z: ArrayLike, R: ArrayLike,
                            H: ArrayLike | None = None) -> tuple[Array, Array, NDArray]:
    """Each agent's measurement in information form: ``(H^T R^-1 H, H^T R^-1 z, present)``.

    ``z`` is ``(..., N, m)`` (one measurement per agent; a row with any ``nan`` is missing
    and contributes zero), ``R`` broadcasts to ``(..., N, m, m)`` (its rows may be ``nan``
    where z is missing) and ``H`` is ``(m, n)`` or ``(..., N, m, n)``, by default the
    identity (the paper's composite measurement, ``H = I_4``, ``R = J^-1``). Returns arrays of
    shape ``(..., N, n, n)``, ``(..., N, n)`` and the boolean ``(..., N)``.
    """
    z = np.asarray(z, dtype=float)
    if z.ndim < 2:
        raise ValueError(f"z has shape {z.shape}; expected (..., N, m): one measurement per "
                         "agent (nan where an agent has none)")
    m = z.shape[-1]
    if np.isinf(z).any():
        raise ValueError(f"z has an infinite entry ({z[np.isinf(z)][0].item()}); expected finite "
                         "values, or nan to mark a missing measurement")
    H = np.eye(m) if H is None else np.asarray(H, dtype=float)
    if H.ndim < 2 or H.shape[-2] != m:
        raise ValueError(f"H has shape {H.shape}; z has {m} components, so expected (m, n) or "
                         f"(..., N, m, n) with m = {m}")
    if not np.isfinite(H).all():
        raise ValueError("H has non-finite entries; expected a finite matrix")
    R = np.asarray(R, dtype=float)
    if R.ndim < 2 or R.shape[-2:] != (m, m):
        raise ValueError(f"R has shape {R.shape}; z has {m} components, so expected "
                         f"(..., N, {m}, {m})")
    try:
        np.broadcast_shapes(z.shape[:-1], R.shape[:-2], H.shape[:-2])
    except ValueError:
        raise ValueError(f"z {z.shape}, R {R.shape} and H {H.shape} do not broadcast; expected "
                         "z (..., N, m), R (..., N, m, m) and H (..., N, m, n) or (m, n)"
                         ) from None
    present = ~np.isnan(z).any(-1)
    if not np.isfinite(R).all():
        # a missing row's R may be nan: a stand-in identity keeps the solve finite, and its
        # contribution is zeroed below
        R = np.where(present[..., None, None], R, np.eye(m))
    R = check_covariance(R, "R", psd=False)
    # the solve at the (often unbatched) shape of R and H, broadcast to the agents after
    own = np.broadcast_shapes(R.shape[:-2], H.shape[:-2])
    RinvH = solve_psd(np.broadcast_to(R, own + (m, m)),
                      np.broadcast_to(H, own + H.shape[-2:]), "R")
    info = symmetrize(mm(np.broadcast_to(H, RinvH.shape).mT, RinvH))
    vec = np.einsum("...mn,...m->...n", RinvH, np.where(present[..., None], z, 0.0))
    batch = vec.shape[:-1]
    info = np.where(present[..., None, None], info, 0.0)
    return info, vec, np.broadcast_to(present, batch)


def adapt(belief: Gaussian, z: ArrayLike, R: ArrayLike, share: ArrayLike,
          H: ArrayLike | None = None) -> Gaussian:
    r"""Incremental update (eqs. 46-48) in information form, every agent at once:

    .. math::

        S_k &= \sum_l c_{lk} H_l^\top R_l^{-1} H_l, \qquad
        \mathbf{q}_k = \sum_l c_{lk} H_l^\top R_l^{-1} \mathbf{z}_l, \\
        P_k^+ &= (P_k^{-1} + S_k)^{-1}, \qquad
        \psi_k = \mathbf{x}_k + P_k^+ (\mathbf{q}_k - S_k \mathbf{x}_k)

    ``share[..., k, l] = c_lk`` (``(..., N, N)``, >= 0; the neighbourhood indicator for the
    paper's update with every neighbour's measurement, or all ones for full sharing). ``z``,
    ``R`` and ``H`` as in :func:`measurement_information`; a missing ``z_l`` (``nan``)
    contributes nothing, and an agent that receives no measurement keeps its prior exactly.

    No gain is formed, so the Joseph form has nothing to protect here: ``P_k+`` is the
    inverse of a positive-definite sum, symmetric by construction (and exactly symmetric as
    returned). The prior covariances must be positive definite.
    """
    x, P = check_belief(belief, None, "adapt belief")
    C = np.asarray(share, dtype=float)
    if C.ndim < 2 or C.shape[-1] != C.shape[-2] or not np.isfinite(C).all() or (C < 0).any():
        raise ValueError(f"share has shape {C.shape} (finite, >= 0: "
                         f"{bool(np.isfinite(C).all() and (C >= 0).all())}); expected a "
                         "finite non-negative (..., N, N) matrix")
    _agents(x, C, "share", "adapt belief")
    n = x.shape[-1]
    info, vec, present = measurement_information(z, R, H)
    if info.shape[-1] != n or present.shape[-1] != C.shape[-1]:
        raise ValueError(f"the measurements give information of shape {info.shape} for the "
                         f"state of shape {x.shape}; expected (..., {C.shape[-1]}, {n}, {n}) "
                         "(H is (m, n), one z per agent)")
    S = _mix(C, info, 2)
    q = _mix(C, vec, 1)
    received = _mix(C, present.astype(float), 0) > 0
    Pinv = _inverse_pd(P, "adapt belief.cov")
    # a positive-definite plus a semi-definite matrix: definite, no check needed
    Pn = symmetrize(np.linalg.inv(Pinv + S))
    xn = x + np.einsum("...ij,...j->...i", Pn, q - np.einsum("...ij,...j->...i", S, x))
    xn = np.where(received[..., None], xn, x)
    Pn = np.where(received[..., None, None], Pn, P)
    return output(xn, Pn, symmetric=True)


# -- the combination -------------------------------------------------------------------------


def ci_weights(cov: ArrayLike, weights: ArrayLike, criterion: str = "det",
               iterations: int = 50) -> Array:
    r"""Covariance-intersection weights ``omega[..., k, l]`` for every agent at once:
    minimise :math:`\det P_k` or :math:`\operatorname{tr} P_k` over the simplex, with
    :math:`P_k^{-1} = \sum_l \omega_{kl} P_l^{-1}` and :math:`\omega_{kl}` zero wherever
    ``weights`` is.

    ``cov`` is ``(..., N, n, n)``, ``weights`` ``(..., N, N)`` (rows summing to 1; the
    start point and the support). The problem is a convex optimal-design problem (D- or
    A-optimality of the ``P_l^-1``); the multiplicative algorithm (Titterington 1976 for the
    determinant; Yu 2010 for the trace) decreases the criterion monotonically, step by
    step, for all rows at once (``"det"``, then ``"trace"``):

    .. math::

        \omega_{kl} &\leftarrow \omega_{kl}\, \operatorname{tr}(P_k P_l^{-1}) / n \\
        \omega_{kl} &\leftarrow \frac{\omega_{kl} \sqrt{\operatorname{tr}(P_k P_l^{-1} P_k)}}
            {\sum_j \omega_{kj} \sqrt{\operatorname{tr}(P_k P_j^{-1} P_k)}}

    Any omega in the simplex gives a consistent fusion, so stopping after ``iterations``
    steps costs optimality only, never consistency. The determinant is the default: it does
    not depend on the units of the state (the trace adds m^2 to m^2/s^2).
    """
    if criterion not in _CRITERIA:
        raise ValueError(f"criterion = {criterion!r}; expected one of {_CRITERIA}")
    if not (isinstance(iterations, int | np.integer) and iterations >= 0):
        raise ValueError(f"iterations = {iterations!r}; expected an integer >= 0")
    P = np.asarray(cov, dtype=float)
    omega = check_weights(weights)
    if P.ndim < 3 or P.shape[-3] != omega.shape[-1]:
        raise ValueError(f"cov has shape {P.shape}; the weights are {omega.shape[-2:]}, so "
                         f"expected (..., {omega.shape[-1]}, n, n)")
    n = P.shape[-1]
    Pinv = _inverse_pd(P, "ci_weights cov")
    flat = Pinv.reshape(Pinv.shape[:-2] + (n * n,))
    for _ in range(int(iterations)):
        # a convex combination of definite matrices is definite: no check in the loop
        Pk = np.linalg.inv(_mix(omega, Pinv, 2))
        if criterion == "trace":
            Pk = mm(Pk, Pk)
        # tr(A B) = sum_ij A_ij B_ij for symmetric B: all (k, l) pairs as one matmul
        d = Pk.reshape(Pk.shape[:-2] + (n * n,)) @ flat.mT
        omega = omega * (d / n if criterion == "det" else np.sqrt(d))
        omega = omega / omega.sum(-1, keepdims=True)
    return omega


def _intersect(x: Array, P: Array, omega: Array, where: str) -> tuple[Array, Array]:
    """``P_k = (sum_l w_kl P_l^-1)^-1`` and ``x_k = P_k sum_l w_kl P_l^-1 x_l``.

    Evaluated relative to agent k's own estimate (primes): ``P_k = (I + P_k' D_k)^-1 P_k'``
    with ``D_k = sum_l w_kl (P_l^-1 - P_k'^-1)``, and ``x_k = x_k' + P_k sum_l w_kl P_l^-1
    (x_l - x_k')``, so that identical inputs come out unchanged, bit for bit.
    """
    n = P.shape[-1]
    Pinv = _inverse_pd(P, where)
    D = _pull(omega, Pinv, 2)
    Pc = symmetrize(np.linalg.solve(np.eye(n) + mm(P, D), P))
    dx = x[..., None, :, :] - x[..., :, None, :]  # dx[..., k, l] = x_l - x_k
    y = (omega[..., :, None, :] @ (Pinv[..., None, :, :, :] @ dx[..., None])[..., 0])[..., 0, :]
    return x + np.einsum("...ij,...j->...i", Pc, y), Pc


def combine(belief: Gaussian, weights: ArrayLike, method: str = "information",
            criterion: str = "det", iterations: int = 50) -> Gaussian:
    r"""Diffusion combination of the agents' estimates, with ``weights[..., k, l] = a_lk``.

    ``method``:

    * ``"convex"`` (Cattivelli and Sayed 2010): :math:`\mathbf{x}_k = \sum_l a_{lk} \psi_l`
      and :math:`P_k` kept (the agent's own updated covariance);
    * ``"paper"`` (Jalalipoor and Kardehi Moghaddam 2021, eqs. 49-50 as printed):

      .. math::

          \mathbf{x}_k = \sum_l a_{lk} \psi_l, \qquad
          P_k = \Bigl(\sum_l a_{lk} P_l^{-1}\Bigr)^{-1}

      The covariance is a harmonic mean, the mean an arithmetic one: when the agents'
      covariances differ the pair can be badly overconfident (the mean keeps a share a_lk of
      the worst agent's error, the covariance hardly any), with or without correlation; with
      equal covariances it is consistent;
    * ``"information"``: the same covariance with the information-weighted mean,

      .. math::

          P_k = \Bigl(\sum_l a_{lk} P_l^{-1}\Bigr)^{-1}, \qquad
          \mathbf{x}_k = P_k \sum_l a_{lk} P_l^{-1} \psi_l

      covariance intersection with the weights fixed at ``a_lk``: consistent inputs give a
      consistent result whatever the correlation between the agents' errors (shared
      measurements, common priors);
    * ``"ci"``: the same with the weights chosen per agent by :func:`ci_weights`
      (``criterion`` ``"det"`` or ``"trace"``, ``iterations`` steps from ``a_lk``, over the
      agents with ``a_lk > 0``).

    Identical inputs come out unchanged, bit for bit (every rule weights deviations from the
    agent's own estimate). Memory grows as N^2 n^2 per batch row (the pairwise deviations).
    """
    if method not in COMBINATIONS:
        raise ValueError(f"method = {method!r}; expected one of {COMBINATIONS}")
    x, P = check_belief(belief, None, "combine belief")
    W = check_weights(weights)
    _agents(x, W, "weights", "combine belief")
    if method == "convex":
        return output(x + _pull(W, x, 1), P, symmetric=True)
    P = np.broadcast_to(P, x.shape + x.shape[-1:])
    if method == "paper":
        _, Pc = _intersect(x, P, W, "combine belief.cov")
        return output(x + _pull(W, x, 1), Pc, symmetric=True)
    omega = W if method == "information" else ci_weights(P, W, criterion, iterations)
    xc, Pc = _intersect(x, P, omega, "combine belief.cov")
    return output(xc, Pc, symmetric=True)


# -- the filter ------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class DiffusionKF:
    """Diffusion Kalman filter on a fixed network: a handle on the network and the rules.

    ``adjacency`` ``(N, N)`` (symmetric; self-loops implied); ``weights`` ``"metropolis"``
    (default), ``"uniform"`` or a matrix ``weights[k, l] = a_lk`` (validated against the
    graph); ``share[k, l] = c_lk`` (default: the neighbourhood, every neighbour's
    measurement with unit weight, as in the paper); ``order`` ``"atc"`` (the paper's) or
    ``"cta"``; ``combination`` one of :data:`COMBINATIONS` (default ``"information"``, the
    paper's covariance with its information-weighted mean; ``"paper"`` for eqs. 49-50 as
    printed), with ``criterion`` and ``iterations`` for ``"ci"``.

    ``f.predict(belief, motion, dt)`` then ``f.update(belief, z, R, H=None)`` per step; the
    belief is ``(..., N, n)``. The measurements are given as arrays rather than a sensor
    model because each agent's composite measurement carries its own ``R = J^-1``.
    """

    adjacency: ArrayLike
    weights: str | ArrayLike = "metropolis"
    share: ArrayLike | None = None
    order: str = "atc"
    combination: str = "information"
    criterion: str = "det"
    iterations: int = 50

    def __post_init__(self) -> None:
        Nk = neighbourhood(self.adjacency)
        if isinstance(self.weights, str):
            rules = {"metropolis": metropolis_weights, "uniform": uniform_weights}
            if self.weights not in rules:
                raise ValueError(f"DiffusionKF.weights = {self.weights!r}; expected "
                                 f"'metropolis', 'uniform' or an (N, N) matrix")
            W = rules[self.weights](Nk)
        else:
            W = check_weights(self.weights, Nk, "DiffusionKF.weights")
        if self.share is None:
            C = Nk.astype(float)
        else:
            C = np.asarray(self.share, dtype=float)
            if (C.shape[-2:] != Nk.shape[-2:] or not np.isfinite(C).all() or (C < 0).any()
                    or (np.broadcast_to(C, np.broadcast_shapes(C.shape, Nk.shape)) != 0)
                    [..., ~Nk].any()):
                raise ValueError(f"DiffusionKF.share has shape {C.shape}; expected a finite "
                                 f"non-negative {Nk.shape[-2:]} matrix, zero off the graph")
        if self.order not in _ORDERS:
            raise ValueError(f"DiffusionKF.order = {self.order!r}; expected one of {_ORDERS}")
        if self.combination not in COMBINATIONS:
            raise ValueError(f"DiffusionKF.combination = {self.combination!r}; expected one "
                             f"of {COMBINATIONS}")
        if self.criterion not in _CRITERIA:
            raise ValueError(f"DiffusionKF.criterion = {self.criterion!r}; expected one of "
                             f"{_CRITERIA}")
        if not (isinstance(self.iterations, int | np.integer) and self.iterations >= 0):
            raise ValueError(f"DiffusionKF.iterations = {self.iterations!r}; expected an "
                             "integer >= 0")
        object.__setattr__(self, "adjacency", Nk)
        object.__setattr__(self, "weights", W)
        object.__setattr__(self, "share", C)

    @property
    def n_agents(self) -> int:
        return int(self.adjacency.shape[-1])

    def predict(self, belief: Gaussian, motion: MotionModel, dt: ArrayLike) -> Gaussian:
        """``x_k- = F x_k``, ``P_k- = F P_k F^T + Q`` for every agent (eqs. 44-45; the
        printed ``G v(k)`` term is zero-mean and left out): the core KF prediction. The paper's
        ``G Q G^T`` is ``trackkit.models.LinearMotion(F, G Q G^T)``;
        ``trackkit.models.ConstantVelocity`` is its continuous-time counterpart."""
        x = np.asarray(belief.mean)
        check_dt(dt, "DiffusionKF.predict")
        _agents(x, self.weights, "the network", "DiffusionKF.predict belief")
        return KF().predict(belief, motion, dt)

    def combine(self, belief: Gaussian) -> Gaussian:
        """The combination step alone (:func:`combine` with this network's rule)."""
        return combine(belief, self.weights, self.combination, self.criterion,
                       self.iterations)

    def adapt(self, belief: Gaussian, z: ArrayLike, R: ArrayLike,
              H: ArrayLike | None = None) -> Gaussian:
        """The incremental update alone (:func:`adapt` with this network's sharing)."""
        return adapt(belief, z, R, self.share, H)

    def update(self, belief: Gaussian, z: ArrayLike, R: ArrayLike,
               H: ArrayLike | None = None) -> Gaussian:
        """ATC: ``combine(adapt(belief))``; CTA: ``adapt(combine(belief))``.

        ``z`` ``(..., N, m)`` with ``nan`` rows for agents without a measurement, ``R``
        ``(..., N, m, m)``, ``H`` ``(m, n)`` or ``(..., N, m, n)`` (default identity).
        """
        if self.order == "atc":
            return self.combine(self.adapt(belief, z, R, H))
        return self.adapt(self.combine(belief), z, R, H)
