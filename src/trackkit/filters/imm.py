r"""Interacting multiple model filter (IMM; Blom and Bar-Shalom 1988; Bar-Shalom, Li and
Kirubarajan 2001, section 11.6.6).

r motion models :math:`M_1, \dots, M_r`, each with its own inner filter (KF, EKF, IEKF, UKF or
CKF); the mode is a Markov chain with transition probabilities
:math:`p_{ij} = P(M_j \text{ at } k \mid M_i \text{ at } k-1)`. One cycle, per batch row:

**Mixing**: the predicted mode probabilities :math:`c_j`, the mixing probabilities
:math:`\mu_{i|j}` and each model's mixed initial condition,

.. math::

    c_j &= \sum_i p_{ij} \mu_i, \qquad \mu_{i|j} = \frac{p_{ij} \mu_i}{c_j}, \\
    \mathbf{x}^0_j &= \sum_i \mu_{i|j} \mathbf{x}_i, \qquad
    P^0_j = \sum_i \mu_{i|j} \bigl(P_i + (\mathbf{x}_i - \mathbf{x}^0_j)
        (\mathbf{x}_i - \mathbf{x}^0_j)^\top\bigr)

**Prediction**: ``x_j-, P_j- = filter_j.predict(N(x0_j, P0_j), M_j, dt)``.

**Update**: ``x_j, P_j`` and ``nu_j, S_j = filter_j.update(N(x_j-, P_j-), z, sensor)``; the
mode probabilities from each filter's own innovation (computed in log space):

.. math::

    \Lambda_j = \mathcal{N}(\nu_j; 0, S_j), \qquad
    \mu_j = \frac{\Lambda_j c_j}{\sum_l \Lambda_l c_l}

**Combination**:

.. math::

    \mathbf{x} = \sum_j \mu_j \mathbf{x}_j, \qquad
    P = \sum_j \mu_j \bigl(P_j + (\mathbf{x}_j - \mathbf{x})(\mathbf{x}_j - \mathbf{x})^\top\bigr)

The belief (:class:`IMMBelief`) holds the mode probabilities and every model's mean and
covariance, the batch axes leading; after ``predict`` its ``mu`` is c_j, after ``update`` the
posterior mu_j. ``estimate`` is the combination above, the moment-matched Gaussian.

**Models of different state sizes.** The IMM's state is the union of the models' states:
``state_maps[j]`` lists, for each component of model j's state, its index in the union (by
default model j's state is the first ``dim_x`` components of the union, which with the state
trackkit's state ordering puts CV ``[x, y, vx, vy]`` inside CT ``[x, y, vx, vy, omega]`` and CA
``[x, y, vx, vy, ax, ay]``). A model that does not carry a component (CV and the turn rate)
still enters every sum above; what it is taken to say about that component is ``fill``:

* ``"others"`` (default): nothing. Model i's density of a component it lacks is that of the
  models that carry it, independent of model i's own components. In mixing into model j that
  is model j's own estimate (mean and covariance of those components), so mixing leaves the
  receiving model's estimate of them unchanged (and scales their correlation with the
  common components by :math:`\mu_{j|j}`); in the combination it is the carriers' moment
  match, with :math:`C_k` the models carrying component k and
  :math:`\mathbf{d}_j = \mathbf{x}_j - \mathbf{x}`:

  .. math::

      x_k = \frac{\sum_{j \in C_k} \mu_j x_{jk}}{\sum_{j \in C_k} \mu_j}, \qquad
      P_{kl} = \frac{\sum_{j \in C_k \cap C_l} \mu_j (P_j + \mathbf{d}_j \mathbf{d}_j^\top)_{kl}}
          {\sum_{j \in C_k \cup C_l} \mu_j}

  Both are the moments of a true mixture when the models' component sets are nested (CV in CT,
  CV in CA), hence symmetric PSD. It is the augmentation of the smaller state from the larger
  model's own estimate, one of the options Granstrom, Willett and Bar-Shalom (2015) compare with
  zero padding. When the carriers' weights underflow (a mode probability of exactly 0 after a
  plot tens of sigma from that model) the ratios are taken in the limit: one carrier gives its
  own moments, several whose weights are all 0 are weighted equally (:func:`combine`).
* ``"zero"``: the component is exactly zero under that model (mean 0, variance 0: a CV
  target is a CT target with omega = 0). Mixing pulls the CT model's turn rate toward 0 by
  the CV model's weight at every step and shrinks its variance, which biases it toward
  straight motion. The EKF/UKF toolbox (``eimm_predict``) also pads with zero means, but
  adds to the covariance only each model's own block, leaving out the spread of the means
  in the missing components; here the exact mixture moments are used.

On the missing-measurements thesis's section 4-5 scenario (CV + CT, 200 runs) "others" gives the
lower position RMSE, 0.178 against 0.186, and is better in 84% of runs (``tests/test_imm.py``).

Missing measurements (nan in z) keep every model's prediction and leave mu at c_j. The
returned :class:`~trackkit.belief.Innovation` is that of the moment-matched predicted
measurement (:math:`\hat{\mathbf{z}}_j - \hat{\mathbf{z}} = \nu - \nu_j`),

.. math::

    \nu = \sum_j c_j \nu_j = \mathbf{z} - \hat{\mathbf{z}}, \qquad
    S = \sum_j c_j \bigl(S_j + (\nu_j - \nu)(\nu_j - \nu)^\top\bigr)

so that gating and the multi-target tracker's association use the mixture's first two
moments. ``log_likelihood`` gives the mixture's exact
:math:`\log \sum_j c_j \mathcal{N}(\nu_j; 0, S_j)`,
``measurement_prediction`` that innovation's predicted measurement and covariance without the
update (for the tracker's gate), and ``merge_hypotheses`` the JPDA combination per model.

When every model is linear with a ``KF`` inside and all share one state, the same equations
run on a fast path for large batches (the end of this module); the general path above takes
each model through its own filter object.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian, Innovation, moment_match
from trackkit.filters import imm_fast
from trackkit.filters.base import (
    Filter,
    check_belief,
    check_dt,
    check_measurement,
    output,
    produced,
    register,
)
from trackkit.filters.kalman import EKF, KF, condition, jacobian_predict, linearize
from trackkit.filters.kalman_fast import dot_rows, innovation_cov, predict_matrices
from trackkit.linalg import (
    check_covariance,
    gaussian_loglik,
    mirror,
    symmetrize,
    triu,
)
from trackkit.models.protocols import SensorModel

__all__ = [
    "IMM",
    "IMMBelief",
    "mixing_probabilities",
    "mix",
    "combine",
    "mode_probabilities",
    "mixture_innovation",
    "gaussian_loglik",
]

Array = NDArray[np.float64]
_PROB_TOL = 1e-9  # how far a probability vector's sum may be from 1 (rounding of a user's)
#: carriers' total weight below which :func:`combine` rescales the weights first: above it,
#: a product ``mu_j v`` of a weight and an entry |v| >= eps^2 is a normal float
_SMALL_WEIGHT = float(np.finfo(float).tiny / np.finfo(float).eps ** 2)


class IMMBelief(NamedTuple):
    """Belief of the IMM: ``mu (..., r)`` the mode probabilities (c_j after ``predict``, the
    posterior after ``update``); ``mean (..., r, n)`` and ``cov (..., r, n, n)`` each model's
    mean and covariance in the union state. Components a model does not carry hold 0 (in the
    mean and in the covariance's rows and columns) and are not used."""

    mu: Array
    mean: Array
    cov: Array

    def at(self, index) -> IMMBelief:
        """The belief at a batch index (every field indexed alike)."""
        return IMMBelief(*(np.asarray(a)[index] for a in self))


# --------------------------------------------------------------------------------------------
# Kernels: pure functions over leading batch axes
# --------------------------------------------------------------------------------------------


def mixing_probabilities(mu: Array, p: Array) -> tuple[Array, Array]:
    """``c_j = sum_i p_ij mu_i`` ``(..., r)`` and ``mu_{i|j} = p_ij mu_i / c_j``
    ``(..., r, r)`` (axis -2 is i, axis -1 is j). A mode no row can reach (c_j = 0) gets
    mixing weights 0."""
    num = mu[..., :, None] * p
    c = num.sum(-2)
    with np.errstate(divide="ignore", invalid="ignore"):
        W = num / c[..., None, :]
    if not (c > 0).all():
        W = np.where(c[..., None, :] > 0, W, 0.0)
    return c, W


def _augmented(X: Array, P: Array, carry: Array, j: int, fill: str) -> tuple[Array, Array]:
    """Every model's mean ``(..., r, n)`` and covariance ``(..., r, n, n)`` with the
    components it does not carry filled as ``fill`` says, for mixing into model j."""
    if fill == "zero" or carry.all():
        return X, P  # (padding holds zeros)
    c2 = carry[:, :, None] & carry[:, None, :]
    miss = ~carry
    m2 = miss[:, :, None] & miss[:, None, :]
    Xa = np.where(carry, X, X[..., j:j + 1, :])
    Pa = np.where(c2, P, np.where(m2, P[..., j:j + 1, :, :], 0.0))
    return Xa, Pa


def mix(mu: Array, X: Array, P: Array, p: Array, carry: Array | None = None,
        fill: str = "others") -> tuple[Array, Array, Array]:
    """IMM mixing: ``(c, X0, P0)`` with ``x0_j = sum_i mu_{i|j} x_i`` and
    ``P0_j = sum_i mu_{i|j} (P_i + (x_i - x0_j)(x_i - x0_j)^T)``.

    ``X (..., r, n)``, ``P (..., r, n, n)`` are the models' estimates in the union state;
    ``carry (r, n)`` marks the components each model carries (None: all), the others filled
    as ``fill`` says (module docstring). Components model j does not carry are 0 in
    ``X0[..., j, :]`` and ``P0[..., j, :, :]``.
    """
    r = X.shape[-2]
    c, W = mixing_probabilities(mu, p)
    if carry is None:
        carry = np.ones(X.shape[-2:], dtype=bool)
    X0 = np.empty(np.broadcast_shapes(W.shape[:-2], X.shape[:-2]) + X.shape[-2:])
    P0 = np.empty(X0.shape + X.shape[-1:])
    for j in range(r):
        Xa, Pa = _augmented(X, P, carry, j, fill)
        x0, Pj = moment_match(W[..., :, j], Xa, Pa)
        if not carry[j].all():
            x0 = np.where(carry[j], x0, 0.0)
            Pj = np.where(carry[j][:, None] & carry[j][None, :], Pj, 0.0)
        X0[..., j, :] = x0
        P0[..., j, :, :] = Pj
    return c, X0, P0


def combine(mu: Array, X: Array, P: Array, carry: Array | None = None,
            fill: str = "others") -> tuple[Array, Array]:
    """The moment-matched Gaussian of the models' mixture: ``x = sum_j mu_j x_j`` and
    ``P = sum_j mu_j (P_j + (x_j - x)(x_j - x)^T)``, with the components a model lacks
    filled as ``fill`` says (module docstring).

    With ``fill="others"`` a component's moments are ratios of sums over its carriers'
    weights. Rows where some carriers' total weight is below ``_SMALL_WEIGHT`` (a mode
    probability that underflowed, possibly to exactly 0) take the limit instead of 0/0
    (``_combine_limit``)."""
    if carry is None or carry.all() or fill == "zero":
        return moment_match(mu, X, P)
    x = np.einsum("...j,...jn->...n", mu, X)
    cf = carry.astype(float)
    total = np.einsum("...j,jn->...n", mu, cf)  # each component's carriers' weight
    with np.errstate(divide="ignore", invalid="ignore"):
        x = x / total  # the carriers' weights, renormalised
        d = np.where(carry, X - x[..., None, :], 0.0)
        num = np.einsum("...j,...jab->...ab", mu, P + d[..., :, None] * d[..., None, :])
        either = np.maximum(cf[:, :, None], cf[:, None, :])
        den = np.einsum("...j,jab->...ab", mu, either)
        Pm = symmetrize(num / den)
    small = (total < _SMALL_WEIGHT).any(-1)
    if small.any():
        batch = small.shape
        x, Pm = np.array(np.broadcast_to(x, batch + x.shape[-1:])), np.array(Pm)
        mu, X, P = (np.broadcast_to(a, batch + a.shape[a.ndim - k:])
                    for a, k in ((mu, 1), (X, 2), (P, 3)))
        x[small], Pm[small] = _combine_limit(mu[small], X[small], P[small], carry)
    return x, Pm


def _carrier_weights(mu: Array, sets: Array) -> Array:
    """Weights ``(N, r, ...)`` of the models in each set ``sets (r, ...)`` (one per component
    or pair of components) for the rows ``mu (N, r)``: ``mu_j / max_{i in set} mu_i``, or 1
    for every member of a set whose weights are all 0; 0 outside the set."""
    m = np.where(sets, mu.reshape(mu.shape + (1,) * (sets.ndim - 1)), 0.0)
    top = m.max(axis=1, keepdims=True)
    return np.where(sets, np.where(top > 0, m / np.where(top > 0, top, 1.0), 1.0), 0.0)


def _combine_limit(mu: Array, X: Array, P: Array, carry: Array) -> tuple[Array, Array]:
    """:func:`combine` with ``fill="others"`` (``mu (N, r)``) as the limit where carriers'
    weights underflow. Each component's (and pair's) moments are ratios of sums over its
    carriers, so dividing their weights by the largest changes nothing in exact arithmetic
    and keeps the products normal floats; a carrier whose weight is 0 while another's is not
    drops out. When every carrier of a component has weight 0 the limit depends on how the
    weights went to 0, which ``mu`` no longer holds: those carriers are weighted equally
    (the limit of weights that fall to 0 together, each infinitely below any positive one).
    Then component k alone: ``x_k`` is its carriers' mean, uncorrelated with the components
    of positive weight; one carrier gives its own moments."""
    w = _carrier_weights(mu, carry)  # (N, r, n)
    x = (w * X).sum(1) / w.sum(1)
    d = np.where(carry, X - x[:, None, :], 0.0)
    either = carry[:, :, None] | carry[:, None, :]
    W = _carrier_weights(mu, either)  # (N, r, n, n)
    num = (W * (P + d[..., :, None] * d[..., None, :])).sum(1)
    return x, symmetrize(num / W.sum(1))


def mode_probabilities(c: Array, loglik: Array) -> Array:
    """``mu_j = Lambda_j c_j / sum_l Lambda_l c_l`` from ``log Lambda_j`` ``(..., r)``,
    in log space (shifted by the row's largest term), so that likelihoods far below the
    float range still give the right ratios."""
    with np.errstate(divide="ignore"):
        a = np.log(c) + loglik
    a = a - a.max(axis=-1, keepdims=True)
    w = np.exp(a)
    return w / w.sum(axis=-1, keepdims=True)


def mixture_innovation(c: Array, nu: Array, S: Array) -> tuple[Array, Array]:
    """The moment-matched innovation of the predicted measurement mixture
    ``sum_j c_j N(zhat_j, S_j)``: ``nu = sum_j c_j nu_j`` and
    ``S = sum_j c_j (S_j + (nu_j - nu)(nu_j - nu)^T)`` (``nu (..., r, m)``,
    ``S (..., r, m, m)``)."""
    return moment_match(c, nu, S)


# --------------------------------------------------------------------------------------------
# The filter
# --------------------------------------------------------------------------------------------


def _probabilities(value: ArrayLike, shape: tuple[int, ...], name: str) -> Array:
    """A probability vector or row-stochastic matrix, checked."""
    a = np.asarray(value, dtype=float)
    if a.shape != shape:
        raise ValueError(f"IMM {name} has shape {a.shape}; expected {shape}")
    if not np.isfinite(a).all() or (a < 0).any() or (a > 1).any():
        bad = float(a[~(np.isfinite(a) & (a >= 0) & (a <= 1))][0])
        raise ValueError(f"IMM {name} has an entry {bad!r}; expected probabilities in [0, 1]")
    s = a.sum(-1)
    off = np.abs(s - 1.0) > _PROB_TOL
    if off.any():
        if a.ndim == 1:
            raise ValueError(f"IMM {name} = {a.tolist()} sums to {float(s)!r}; expected "
                             "mode probabilities summing to 1")
        i = int(np.flatnonzero(off)[0])
        raise ValueError(f"IMM {name} row {i} = {a[i].tolist()} sums to {float(s[i])!r}; "
                         "expected each row of p_ij to sum to 1")
    a = a.copy()
    a.flags.writeable = False
    return a


def _memoryless(f: Any) -> bool:
    """Whether ``f`` is a filter of plain Gaussian beliefs (KF, EKF, IEKF, UKF, CKF)."""
    return (callable(getattr(f, "predict", None)) and callable(getattr(f, "update", None))
            and getattr(type(f), "init", Filter.init) is Filter.init
            and getattr(type(f), "estimate", Filter.estimate) is Filter.estimate)


class IMM(Filter):
    """Interacting multiple model filter: ``IMM(models, filters, transition, mu0=None,
    state_maps=None, fill="others")``.

    ``models``: the r motion models; ``filters``: one inner filter per model (KF, EKF,
    IEKF, UKF or CKF), or one filter for all; ``transition``: p_ij (r x r, rows sum to 1);
    ``mu0``: the initial mode probabilities (default uniform); ``state_maps``: per model,
    the union-state index of each of its components (default: the first ``dim_x``); ``fill``:
    how a model's missing components enter mixing and combination (module docstring).

    ``init(gaussian)`` gives every model the union Gaussian's marginal over its components
    and mu0; ``predict(belief, motion, dt)`` mixes then predicts each model, with ``motion``
    None (the IMM's own models) or a sequence of r models (e.g. the same models with other
    noise); ``update(belief, z, sensor)`` updates each model with the one ``sensor`` (which
    reads the position from the first components of every model's state) and the mode
    probabilities; ``estimate`` is the moment-matched Gaussian of the union state.
    """

    name = "IMM"

    def __init__(self, models: Sequence[Any], filters: Any, transition: ArrayLike,
                 mu0: ArrayLike | None = None, state_maps: Sequence[ArrayLike] | None = None,
                 fill: Literal["others", "zero"] = "others") -> None:
        models = tuple(models)
        r = len(models)
        if r < 1:
            raise ValueError("IMM models is empty; expected at least one motion model")
        if isinstance(filters, Sequence):
            filters = tuple(filters)
            if len(filters) != r:
                raise ValueError(f"IMM has {r} models and {len(filters)} filters; expected one "
                                 "filter per model (or a single filter for all)")
        else:
            filters = (filters,) * r
        for j, f in enumerate(filters):
            if not _memoryless(f):
                raise ValueError(f"IMM filters[{j}] is {type(f).__name__}; expected a filter of "
                                 "Gaussian beliefs (KF, EKF, IEKF, UKF or CKF)")
        if fill not in ("others", "zero"):
            raise ValueError(f"IMM fill = {fill!r}; expected 'others' or 'zero'")
        dims = [getattr(m, "dim_x", None) for m in models]
        if state_maps is None:
            if any(d is None for d in dims):
                raise ValueError("IMM: a model has no dim_x; give state_maps")
            maps = [np.arange(d) for d in dims]
        else:
            if len(state_maps) != r:
                raise ValueError(f"IMM has {r} models and {len(state_maps)} state_maps; "
                                 "expected one index vector per model")
            maps = []
            for j, s in enumerate(state_maps):
                a = np.asarray(s)
                if (a.ndim != 1 or a.size == 0 or not np.issubdtype(a.dtype, np.integer)
                        or (a < 0).any() or np.unique(a).size != a.size):
                    raise ValueError(f"IMM state_maps[{j}] = {np.asarray(s).tolist()!r}; "
                                     "expected distinct non-negative integer indices")
                if dims[j] is not None and a.size != dims[j]:
                    raise ValueError(f"IMM state_maps[{j}] has {a.size} indices but "
                                     f"models[{j}] has {dims[j]} states; expected one each")
                maps.append(a.astype(np.intp))
        n = int(max(int(a.max()) for a in maps)) + 1
        carry = np.zeros((r, n), dtype=bool)
        for j, a in enumerate(maps):
            carry[j, a] = True
        if not carry.any(0).all():
            k = int(np.flatnonzero(~carry.any(0))[0])
            raise ValueError(f"IMM state component {k} is carried by no model; expected "
                             "state_maps that cover 0 .. n-1")
        for a in maps:
            a.flags.writeable = False
        carry.flags.writeable = False
        self.models = models
        self.filters = filters
        self.transition = _probabilities(transition, (r, r), "transition")
        self.mu0 = _probabilities(np.full(r, 1.0 / r) if mu0 is None else mu0, (r,), "mu0")
        self.state_maps = tuple(maps)
        self.fill = fill
        self._carry = carry
        # a model whose components are the union's first n_j, in order: plain slices
        self._prefix = tuple(bool(np.array_equal(a, np.arange(a.size))) for a in maps)
        # every model a KF on the whole state: the fast path (end of the module) may apply
        self._kf_only = all(type(f) is KF for f in filters) and bool(carry.all())
        # CV nested in CT with first-order EKFs: the compiled kernels (imm_fast)
        self._compiled = imm_fast.configuration(self)
        self._ct_noise: dict[float, Array] = {}

    # -- shapes ---------------------------------------------------------------------------

    @property
    def r(self) -> int:
        return len(self.models)

    @property
    def dim_x(self) -> int:
        """The size of the union state."""
        return self._carry.shape[1]

    def _part(self, X: Array, P: Array, j: int) -> tuple[Array, Array]:
        """Model j's own mean ``(..., n_j)`` and covariance from the union arrays."""
        a = self.state_maps[j]
        if self._prefix[j]:
            k = a.size
            return X[..., j, :k], P[..., j, :k, :k]
        return X[..., j, a], P[..., j, :, :][..., a[:, None], a]

    def _place(self, X: Array, P: Array, j: int, x: Array, Pj: Array) -> None:
        a = self.state_maps[j]
        if self._prefix[j]:
            k = a.size
            X[..., j, :k] = x
            P[..., j, :k, :k] = Pj
        else:
            X[..., j, a] = x
            P[..., j, a[:, None], a] = Pj

    def model_estimates(self, belief: IMMBelief) -> list[Gaussian]:
        """Each model's Gaussian in its own state (``[x, y, vx, vy]`` for CV...)."""
        b = self._belief(belief, "IMM.model_estimates")
        return [Gaussian._make(self._part(b.mean, b.cov, j)) for j in range(self.r)]

    # -- the interface ----------------------------------------------------------------------

    def init(self, prior: Gaussian) -> IMMBelief:
        """Every model starts from the prior's marginal over its components, mu = mu0."""
        x, P = check_belief(prior, self.dim_x, "IMM.init prior")
        batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2])
        r, n = self._carry.shape
        X = np.zeros(batch + (r, n))
        C = np.zeros(batch + (r, n, n))
        X[...] = np.where(self._carry, x[..., None, :], 0.0)
        c2 = self._carry[:, :, None] & self._carry[:, None, :]
        C[...] = np.where(c2, P[..., None, :, :], 0.0)
        mu = np.array(np.broadcast_to(self.mu0, batch + (r,)))
        return IMMBelief(mu, X, register(C))

    def estimate(self, belief: IMMBelief) -> Gaussian:
        """The moment-matched Gaussian of the union state (module docstring)."""
        b = self._belief(belief, "IMM.estimate")
        if self._compiled:
            x, P = self._rows(imm_fast.estimate_kernel, b)
            return output(x, P, symmetric=True)
        if self._carry.all():  # one state for all: the same sums on the upper triangles
            batch = b.mu.shape[:-1]
            r, n = self._carry.shape
            N = int(np.prod(batch))
            x, P = _fast_combine(b.mu.reshape(N, r), b.mean.reshape(N, r, n),
                                 b.cov.reshape(N, r, n, n))
            return output(x.reshape(batch + (n,)), P.reshape(batch + (n, n)), symmetric=True)
        x, P = combine(b.mu, b.mean, b.cov, self._carry, self.fill)
        return output(x, P, symmetric=True)

    def predict(self, belief: IMMBelief | Gaussian, motion: Sequence[Any] | None,
                dt: ArrayLike) -> IMMBelief:
        """Mixing (``c_j``, ``mu_{i|j}``, ``x0_j``, ``P0_j``), then each model's prediction by
        its filter. ``motion``: None for the IMM's own models, or a sequence of r models
        used instead of them for this step."""
        b = self._belief(belief, "IMM.predict")
        if self._compiled and motion is None and type(dt) in (float, int):
            check_dt(dt, "IMM.predict")
            return self._compiled_predict(b, float(dt))
        motions = self._motions(motion)
        if self._kf_only and all(getattr(m, "linear", False) for m in motions):
            check_dt(dt, "IMM.predict")
            batch = b.mu.shape[:-1]
            N = int(np.prod(batch))
            r, n = self._carry.shape
            fast = _fast_predict(b.mu.reshape(N, r), b.mean.reshape(N, r, n),
                                 b.cov.reshape(N, r, n, n), self.transition, motions, dt)
            if fast is not None:
                mu, X, P = (a.reshape(batch + a.shape[1:]) for a in fast)
                return IMMBelief(mu, X, register(P))
        c, X0, P0 = mix(b.mu, b.mean, b.cov, self.transition, self._carry, self.fill)
        preds = []
        for j in range(self.r):
            x0, P0j = self._part(X0, P0, j)
            f, motion = self.filters[j], motions[j]
            if type(f) is EKF and getattr(motion, "dim_x", None) == x0.shape[-1]:
                # EKF.predict without re-checking the mixture of a belief checked above
                check_dt(dt, "IMM.predict")
                preds.append(jacobian_predict(x0, P0j, motion, dt))
                continue
            preds.append(f.predict(Gaussian._make((x0, register(P0j))), motion, dt))
        return self._assemble(c, preds)

    def update(self, belief: IMMBelief | Gaussian, z: ArrayLike,
               sensor: Any) -> tuple[IMMBelief, Innovation]:
        """Each model's update, the mode probabilities ``mu_j ~ Lambda_j c_j`` and the
        mixture's innovation (module docstring); rows with nan in z keep the prediction
        and ``mu = c``, and their residual is nan."""
        b = self._belief(belief, "IMM.update")
        params = imm_fast.sensor_params(sensor) if self._compiled else None
        fast = self._compiled_update(b, z, params) if params is not None else None
        if fast is not None:
            return fast
        post, nu, S, loglik, miss = self._update_models(b, z, sensor)
        c = b.mu
        mu = mode_probabilities(c, loglik)
        v, Sm = mixture_innovation(c, nu, S)
        if miss is not None:
            mu = np.where(miss[..., None], c, mu)
            v = np.where(miss[..., None], np.nan, v)
            m3 = miss[..., None, None]
            post = IMMBelief(mu, np.where(m3, b.mean, post.mean),
                             register(np.where(m3[..., None], b.cov, post.cov)))
        else:
            post = IMMBelief(mu, post.mean, post.cov)
        return post, Innovation(v, Sm)

    def measurement_prediction(self, belief: IMMBelief | Gaussian,
                               sensor: Any) -> tuple[Array, Array] | None:
        """The predicted measurement ``zhat (..., m)`` and its covariance ``S (..., m, m)``:
        the mixture's moments that :meth:`update` returns as its innovation, without the
        update. For models with first-order inner filters (KF, EKF), per model j

            zhat_j = h(x_j-),   S_j = H_j P_j- H_j^T + R,   nu_j = z0 - zhat_j

        at ``z0 = h(x-)``, x- the combined prediction (angles wrapped in nu_j); then
        ``nu = sum_j c_j nu_j``, ``S = sum_j c_j (S_j + (nu_j - nu)(nu_j - nu)^T)`` and
        ``zhat = z0 - nu`` (angles wrapped): the update's ``z - innov.nu`` and
        ``innov.cov`` at ``z = z0``, the same arithmetic to the last bit. None for other
        inner filters or shapes (the caller takes the update at z0 instead)."""
        b = self._belief(belief, "IMM.measurement_prediction")
        params = imm_fast.sensor_params(sensor) if self._compiled else None
        if params is not None:
            return self._rows(imm_fast.prediction_kernel, b, params.R, params.kind,
                              params.origin, params.nautical)
        R = sensor.noise
        if not (all(type(f) is EKF and f.order == 1 or type(f) is KF for f in self.filters)
                and (getattr(sensor, "linear", False) or not any(type(f) is KF
                                                                 for f in self.filters))
                and not (self._kf_only and getattr(sensor, "linear", False))
                and type(R) is np.ndarray and R.dtype == np.float64):
            return None
        z0 = np.asarray(sensor.h(self._combined_mean(b)), dtype=float)
        nus, Ss = [], []
        for j in range(self.r):
            x, Pj = self._part(b.mean, b.cov, j)
            zhat, H = linearize(sensor, x)
            S = innovation_cov(Pj, np.asarray(H, dtype=float), R)
            if S is None:
                return None
            nus.append(sensor.residual(z0, zhat))
            Ss.append(S)
        m = z0.shape[-1]
        batch = np.broadcast_shapes(*(np.shape(v)[:-1] for v in nus),
                                    *(np.shape(s)[:-2] for s in Ss))
        nu = np.stack([np.broadcast_to(v, batch + (m,)) for v in nus], -2)
        S = np.stack([np.broadcast_to(s, batch + (m, m)) for s in Ss], -3)
        v, Sm = mixture_innovation(b.mu, nu, S)
        zhat = z0 - v
        ang = np.asarray(getattr(sensor, "angular", (False,) * m))
        if ang.any():
            zhat[..., ang] = wrap(zhat[..., ang])
        return zhat, Sm

    def _combined_mean(self, b: IMMBelief) -> Array:
        """``estimate(b).mean`` without the covariance (the same sums as :func:`combine`)."""
        if self._carry.all() or self.fill == "zero":
            return self.estimate(b).mean
        x = np.einsum("...j,...jn->...n", b.mu, b.mean)
        total = np.einsum("...j,jn->...n", b.mu, self._carry.astype(float))
        if (total < _SMALL_WEIGHT).any():  # the limit of underflowed weights: combine's own
            return self.estimate(b).mean
        return x / total

    def log_likelihood(self, belief: IMMBelief | Gaussian, z: ArrayLike, sensor: Any) -> Array:
        """``log p(z) = log sum_j c_j N(nu_j; 0, S_j)``, the predicted measurement mixture's
        exact log-likelihood of z per batch row (nan where z is missing)."""
        b = self._belief(belief, "IMM.log_likelihood")
        _, _, _, loglik, miss = self._update_models(b, z, sensor)
        with np.errstate(divide="ignore"):
            a = np.log(b.mu) + loglik
        top = a.max(axis=-1)
        out = top + np.log(np.exp(a - top[..., None]).sum(-1))
        return out if miss is None else np.where(miss, np.nan, out)

    def merge_hypotheses(self, prior: IMMBelief, post: IMMBelief, track: ArrayLike,
                         beta0: ArrayLike, beta: ArrayLike) -> IMMBelief:
        """The JPDA (PDA) combination of IMM beliefs, per model (IMM-JPDA).

        Track t's predicted belief ``prior`` (rows t, mode probabilities c_j) and the
        beliefs ``post`` updated with each of its gated detections h (rows h,
        ``track[h] = t``, mode probabilities mu_{j|h}), with association probabilities
        ``beta0[t]`` (no detection) and ``beta[h]``: the posterior is the mixture over
        (hypothesis, model) with weights ``beta_h mu_{j|h}``; grouped by model and
        moment-matched within each model it is

            mu_j = beta_0 c_j + sum_h beta_h mu_{j|h}
            x_j = (beta_0 c_j x_j- + sum_h beta_h mu_{j|h} x_{j|h}) / mu_j
            P_j = (beta_0 c_j (P_j- + d d^T) + sum_h beta_h mu_{j|h} (P_{j|h} + d d^T)) / mu_j

        with d the deviation from x_j (:func:`~trackkit.belief.moment_match` per model). A
        model whose mu_j underflows to 0 keeps its prediction.
        """
        track = np.asarray(track, dtype=np.intp)
        b0 = np.asarray(beta0, dtype=float)
        bh = np.asarray(beta, dtype=float)
        w0 = b0[:, None] * prior.mu  # (T, r)
        wh = bh[:, None] * post.mu  # (H, r)
        mu = w0.copy()
        np.add.at(mu, track, wh)
        ok = mu > 0
        safe = np.where(ok, mu, 1.0)
        T = prior.mu.shape[0]
        # per model, the prediction and the hypotheses with weights summing to 1
        x, P = moment_match(np.concatenate([w0 / safe, wh / safe[track]]),
                            np.concatenate([prior.mean, post.mean]),
                            np.concatenate([prior.cov, post.cov]),
                            np.concatenate([np.arange(T), track]), T)
        x = np.where(ok[..., None], x, prior.mean)
        P = np.where(ok[..., None, None], P, prior.cov)
        # mu sums to beta_0 + sum_h beta_h = 1 up to rounding; make it exact
        return IMMBelief(mu / mu.sum(-1, keepdims=True), x, register(P))

    # -- internals ----------------------------------------------------------------------------

    def _motions(self, motion: Any) -> tuple[Any, ...]:
        if motion is None:
            return self.models
        if not isinstance(motion, Sequence) or len(motion) != self.r:
            raise ValueError(f"IMM.predict motion = {motion!r}; expected None (the IMM's own "
                             f"models) or a sequence of {self.r} motion models")
        return tuple(motion)

    def _belief(self, belief: Any, where: str) -> IMMBelief:
        """The belief as an IMMBelief (a plain Gaussian is initialised), checked: shapes,
        finite values, mode probabilities, and (for covariances not produced here) each
        model's covariance symmetric PSD; the padding of a belief from outside is zeroed."""
        if isinstance(belief, Gaussian):
            return self.init(belief)
        if not isinstance(belief, IMMBelief):
            if not all(hasattr(belief, f) for f in IMMBelief._fields):
                raise ValueError(f"{where}: belief is a {type(belief).__name__}; expected an "
                                 "IMMBelief (mu, mean, cov) or a Gaussian of the union state")
            belief = IMMBelief(belief.mu, belief.mean, belief.cov)
        mu, X, P = (np.asarray(a, dtype=float) for a in belief)
        r, n = self._carry.shape
        if mu.ndim < 1 or mu.shape[-1] != r:
            raise ValueError(f"{where}: belief.mu has shape {mu.shape}; the IMM has {r} models, "
                             f"so expected (..., {r})")
        batch = mu.shape[:-1]
        if X.shape != batch + (r, n):
            raise ValueError(f"{where}: belief.mean has shape {X.shape}; expected "
                             f"{batch + (r, n)} (batch, model, union state)")
        if P.shape != batch + (r, n, n):
            raise ValueError(f"{where}: belief.cov has shape {P.shape}; expected "
                             f"{batch + (r, n, n)}")
        if not (np.isfinite(mu).all() and (mu >= 0).all()):
            raise ValueError(f"{where}: belief.mu has entries outside [0, 1] or non-finite; "
                             "expected mode probabilities")
        s = mu.sum(-1)
        if (np.abs(s - 1.0) > 1e-6).any():
            bad = float(s.ravel()[np.argmax(np.abs(s - 1.0).ravel())])
            raise ValueError(f"{where}: belief.mu sums to {bad!r} in some row; expected mode "
                             "probabilities summing to 1")
        if not np.isfinite(X).all():
            raise ValueError(f"{where}: belief.mean has non-finite entries; expected finite")
        if produced(belief.cov):
            return IMMBelief(mu, X, belief.cov)
        for j in range(r):
            Pj = self._part(X, P, j)[1]
            check_covariance(Pj, f"{where} belief.cov of model {j}", n=self.state_maps[j].size)
        if not self._carry.all():
            c2 = self._carry[:, :, None] & self._carry[:, None, :]
            X = np.where(self._carry, X, 0.0)
            P = np.where(c2, P, 0.0)
        return IMMBelief(mu, X, register(np.array(P)))

    def _assemble(self, mu: Array, parts: list[Gaussian]) -> IMMBelief:
        """An IMMBelief from each model's Gaussian (batch shapes broadcast together)."""
        r, n = self._carry.shape
        batch = np.broadcast_shapes(mu.shape[:-1], *(g.mean.shape[:-1] for g in parts))
        X = np.zeros(batch + (r, n))
        P = np.zeros(batch + (r, n, n))
        for j, g in enumerate(parts):
            self._place(X, P, j, g.mean, g.cov)
        mu = np.array(np.broadcast_to(mu, batch + (r,)))
        return IMMBelief(mu, X, register(P))

    def _rows(self, kernel: Any, b: IMMBelief, *args: Any) -> tuple[Array, ...]:
        """A compiled kernel (``imm_fast``) on the belief's batch flattened to rows; every
        output reshaped back to the batch."""
        batch = b.mu.shape[:-1]
        r, n = self._carry.shape
        N = int(np.prod(batch))
        out = kernel(np.ascontiguousarray(b.mu.reshape(N, r)),
                     np.ascontiguousarray(b.mean.reshape(N, r, n)),
                     np.ascontiguousarray(b.cov.reshape(N, r, n, n)), *args)
        return tuple(a.reshape(batch + a.shape[1:]) if isinstance(a, np.ndarray) else a
                     for a in out)

    def _compiled_predict(self, b: IMMBelief, dt: float) -> IMMBelief:
        """Mixing and both EKF predictions by ``imm_fast.predict_kernel``."""
        cv, ct = self.models
        Qct = self._ct_noise.get(dt)
        if Qct is None:
            if len(self._ct_noise) > 64:
                self._ct_noise.clear()
            Qct = self._ct_noise[dt] = np.asarray(ct.noise(None, dt), dtype=float)
        Fcv = np.asarray(cv.jacobian(None, dt), dtype=float)
        Qcv = np.asarray(cv.noise(None, dt), dtype=float)
        c, X, P = self._rows(imm_fast.predict_kernel, b, self.transition, dt, Fcv, Qcv, Qct)
        return IMMBelief(c, X, register(P))

    def _compiled_update(self, b: IMMBelief, z: ArrayLike, params: Any
                         ) -> tuple[IMMBelief, Innovation] | None:
        """:meth:`update` by ``imm_fast.update_kernel`` (nan rows of z: missed); None when
        z has more batch rows than the belief."""
        batch = b.mu.shape[:-1]
        z = check_measurement(z, 2, "IMM.update", batch)
        if np.broadcast_shapes(z.shape[:-1], batch) != batch:
            return None
        N = int(np.prod(batch))
        zf = np.ascontiguousarray(np.broadcast_to(z, batch + (2,)).reshape(N, 2))
        mu, X, P, v, Sm, bad = self._rows(imm_fast.update_kernel, b, zf, params.R,
                                          params.kind, params.origin, params.nautical)
        if bad >= 0:
            raise ValueError(f"IMM.update: innovation covariance is not positive definite in "
                             f"row {bad}")
        return IMMBelief(mu, X, register(P)), Innovation(v, Sm)

    def _fast_update(self, b: IMMBelief, z: Array, sensor: Any, batch: tuple[int, ...]):
        """The fast path's update (every model a KF); None when the sensor's H or R is not
        one unbatched matrix."""
        r, n = self._carry.shape
        N = int(np.prod(batch))
        X = b.mean.reshape(N, r, n)
        zhat, H = linearize(sensor, X)
        R = sensor.noise
        m = z.shape[-1]
        if not (type(R) is np.ndarray and H.shape == (m, n) and R.shape == (m, m)
                and np.shape(zhat) == (N, r, m)):
            return None
        zf = np.broadcast_to(z, batch + (m,)).reshape(N, m)
        xn, Pn, nu, S, loglik = _fast_update_models(
            X, b.cov.reshape(N, r, n, n), zf, np.asarray(zhat, dtype=float), sensor,
            np.asarray(H, dtype=float), np.asarray(R, dtype=float))
        post = IMMBelief(b.mu, xn.reshape(batch + (r, n)),
                         register(Pn.reshape(batch + (r, n, n))))
        return (post, nu.reshape(batch + (r, m)), S.reshape(batch + (r, m, m)),
                loglik.reshape(batch + (r,)))

    def _update_models(self, b: IMMBelief, z: ArrayLike, sensor: Any):
        """Every model's update: ``(post, nu (..., r, m), S (..., r, m, m),
        log Lambda (..., r), missing rows or None)``. Missing rows are updated with a
        stand-in measurement (model 0's predicted one) so that every S_j and nu_j - nu is
        defined; the caller restores their prediction."""
        m = sensor.dim_z
        z = check_measurement(z, m, "IMM.update", b.mu.shape[:-1])
        miss = None
        if np.isnan(z).any():
            miss = np.isnan(z).any(-1)
            x0 = self._part(b.mean, b.cov, 0)[0]
            z = np.where(miss[..., None], np.asarray(sensor.h(x0), dtype=float), z)
        batch = b.mu.shape[:-1]
        if (self._kf_only and getattr(sensor, "linear", False)
                and np.broadcast_shapes(z.shape[:-1], batch) == batch):
            fast = self._fast_update(b, z, sensor, batch)
            if fast is not None:
                post, nu, S, loglik = fast
                if miss is not None:
                    miss = np.broadcast_to(miss, batch)
                return post, nu, S, loglik, miss
        parts, nus, Ss = [], [], []
        for j in range(self.r):
            x, Pj = self._part(b.mean, b.cov, j)
            f = self.filters[j]
            if type(f) is EKF and f.order == 1:
                # EKF.update without its checks of a belief and z checked above (z has no
                # nan left): the residual at h(x-) and the Kalman update of kalman.condition
                zhat, H = linearize(sensor, x)
                nu = sensor.residual(z, zhat)
                xn, Pn, S = condition(x, Pj, nu, H, sensor.noise)
                parts.append(Gaussian._make((xn, Pn)))
                nus.append(nu)
                Ss.append(S)
                continue
            g, innov = f.update(Gaussian._make((x, register(Pj))), z, sensor)
            parts.append(g)
            nus.append(innov.nu)
            Ss.append(innov.cov)
        batch = np.broadcast_shapes(*(np.shape(v)[:-1] for v in nus),
                                    *(np.shape(s)[:-2] for s in Ss))
        nu = np.stack([np.broadcast_to(v, batch + (m,)) for v in nus], -2)
        S = np.stack([np.broadcast_to(s, batch + (m, m)) for s in Ss], -3)
        post = self._assemble(b.mu, parts)
        if miss is not None:
            miss = np.broadcast_to(miss, post.mu.shape[:-1])
        return post, nu, S, gaussian_loglik(nu, S), miss


# --------------------------------------------------------------------------------------------
# Fast path: every model linear with a KF inside, one state for all (the same equations as
# the cycle above, ordered for large batches; tests/test_imm.py pins it against them)
# --------------------------------------------------------------------------------------------
#
# Covariances are handled as their upper triangles (T = n (n + 1) / 2 entries, row-major as
# ``triu(n).flat``) until they are stored. Mixing is the formula of :func:`mix` on the
# triangles, with the spread of the means as pairwise differences (one outer product per pair
# of models, shared by every j; :func:`_weighted_upper`). The prediction
# ``P- = F P0 F^T + Q`` is one GEMM per model on the triangles,
# ``vec_u(P-) = vec_u(P0) K_uu^T + vec_u(Q)``, with ``K_uu`` the rows of ``F kron F`` for the
# upper triangle (``kalman_fast.predict_matrices``) with the columns of each mirrored pair of
# entries added. The update of every model and row at once is the Kalman filters' own
# (``kalman.condition`` on the N r rows: the general path's arithmetic). The combined estimate
# of models of one state is the same weighted sum on the triangles (:func:`_fast_combine`).

_UPPER_PREDICT: dict[tuple[bytes, bytes], tuple[Array, Array]] = {}

def _upper_predict_matrices(F: Array, Q: Array) -> tuple[Array, Array]:
    """``(K_uu^T (T, T), vec_u(Q) (T,))`` for an unbatched F and Q, remembered by value."""
    key = (F.tobytes(), Q.tobytes())
    hit = _UPPER_PREDICT.get(key)
    if hit is None:
        n = F.shape[0]
        K_u, _, Q_u = predict_matrices(F, Q)  # (T, n^2): vec_u(F P F^T) = K_u vec(P)
        T = K_u.shape[0]
        fold = np.zeros((n * n, T))
        fold[np.arange(n * n), triu(n).twin] = 1.0  # vec(P) = fold vec_u(P)
        hit = (np.ascontiguousarray((K_u @ fold).T), np.array(Q_u))
        for a in hit:
            a.flags.writeable = False
        if len(_UPPER_PREDICT) > 64:
            _UPPER_PREDICT.clear()
        _UPPER_PREDICT[key] = hit
    return hit


def _fast_predict(mu: Array, X: Array, P: Array, p: Array, motions, dt) -> IMMBelief | None:
    """Mixing and the KF prediction of every model (``mu (N, r)``, ``X (N, r, n)``,
    ``P (N, r, n, n)``); None when a model's F or Q is not one unbatched n x n matrix."""
    N, r, n = X.shape
    mats = []
    for j, m in enumerate(motions):
        F = m.jacobian(X[:, j], dt)
        Q = m.noise(X[:, j], dt)
        if not (type(F) is np.ndarray and type(Q) is np.ndarray and F.shape == (n, n)
                and Q.shape == (n, n) and F.dtype == Q.dtype == np.float64):
            return None
        mats.append((F, _upper_predict_matrices(F, Q)))
    tri = triu(n)
    c, W = mixing_probabilities(mu, p)
    Pu = P.reshape(N, r, n * n)[:, :, tri.flat]
    spreads = _pair_spreads(X, tri)
    Xp = np.empty((N, r, n))
    Ppu = np.empty((N, r, tri.flat.size))
    for j, (F, (K_uuT, Q_u)) in enumerate(mats):
        w = W[:, :, j]
        x0 = np.einsum("ni,nia->na", w, X)
        P0u = _weighted_upper(w, Pu, spreads)
        Ppu[:, j] = dot_rows(P0u, K_uuT) + Q_u
        Xp[:, j] = dot_rows(x0, F.T)
    return IMMBelief(c, Xp, register(mirror(Ppu, n)))


def _fast_update_models(X: Array, P: Array, z: Array, zhat: Array, sensor: SensorModel, H: Array,
                        R: Array):
    """Every model's KF update at once (``X (N, r, n)``, ``P (N, r, n, n)``, ``z (N, m)``,
    ``zhat = h(X) (N, r, m)``, H and R unbatched): ``(x+, P+, nu (N, r, m), S (N, r, m, m),
    log Lambda (N, r))``. The N r rows go through the Kalman filters' own update
    (:func:`~trackkit.filters.kalman.condition`) and ``log N(nu; 0, S)``, as each model's
    filter on the general path."""
    N, r, n = X.shape
    m, Nr = H.shape[0], N * r
    nu = sensor.residual(z[:, None, :], zhat)
    xn, Pn, S = condition(X.reshape(Nr, n), P.reshape(Nr, n, n), nu.reshape(Nr, m), H, R)
    loglik = gaussian_loglik(nu.reshape(Nr, m), S)
    return (xn.reshape(N, r, n), Pn.reshape(N, r, n, n), nu, S.reshape(N, r, m, m),
            loglik.reshape(N, r))


def _pair_spreads(X: Array, tri) -> list[tuple[int, int, Array]]:
    """The upper triangles of ``(x_i - x_k)(x_i - x_k)^T`` for every pair i < k of models
    (``X (N, r, n)``), shared by every weighting of the models."""
    r = X.shape[1]
    out = []
    for i in range(r):
        for k in range(i + 1, r):
            D = X[:, i] - X[:, k]
            out.append((i, k, D[:, tri.i] * D[:, tri.j]))
    return out


def _weighted_upper(w: Array, Pu: Array, spreads) -> Array:
    """Upper triangle of ``sum_i w_i (P_i + (x_i - xbar)(x_i - xbar)^T)``, ``xbar = sum_i
    w_i x_i``, for weights ``w (N, r)`` summing to 1: the spread of the means written as
    ``sum_{i<k} w_i w_k (x_i - x_k)(x_i - x_k)^T`` (equal when the weights sum to 1), one
    outer product per pair of models whatever the weighting."""
    acc = w[:, 0, None] * Pu[:, 0]
    for i in range(1, Pu.shape[1]):
        acc += w[:, i, None] * Pu[:, i]
    for i, k, O in spreads:
        acc += (w[:, i] * w[:, k])[:, None] * O
    return acc


def _fast_combine(mu: Array, X: Array, P: Array) -> tuple[Array, Array]:
    """:func:`combine` for models of one state, on the upper triangles (``mu (N, r)``,
    ``X (N, r, n)``, ``P (N, r, n, n)``): ``x = sum_j mu_j x_j``,
    ``P = sum_j mu_j (P_j + d_j d_j^T)`` (the spread as pairwise differences, see
    :func:`_weighted_upper`), mirrored (exactly symmetric)."""
    N, r, n = X.shape
    tri = triu(n)
    x = np.einsum("nj,nja->na", mu, X)
    Pu = P.reshape(N, r, n * n)[:, :, tri.flat]
    return x, mirror(_weighted_upper(mu, Pu, _pair_spreads(X, tri)), n)
