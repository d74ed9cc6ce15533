r"""Gating: which detections may have come from which track.

A detection :math:`\mathbf{z}_j` falls in track i's gate when its squared Mahalanobis
distance is within the threshold,

.. math::

    d^2_{ij} = \nu_{ij}^\top S_i^{-1} \nu_{ij} \le \gamma, \qquad
    \nu_{ij} = \mathbf{z}_j - \hat{\mathbf{z}}_i \quad \text{(angles wrapped)}

with :math:`S_i` the innovation covariance and :math:`\gamma = F^{-1}_{\chi^2_m}(P_G)`
(``chi2.ppf(P_G, m)``), so that a detection of the target falls in the gate with probability
:math:`P_G`. Each gated pair also gets the Gaussian log-likelihood

.. math::

    \log \mathcal{N}(\mathbf{z}_j; \hat{\mathbf{z}}_i, S_i)
        = -\tfrac12 \bigl(d^2_{ij} + \log\det(2 \pi S_i)\bigr)

Two paths give the same pairs, bit for bit:

* brute force, every (track, detection) pair through the fine test: cost T x D;
* a coarse pre-gate first: a ``cKDTree`` over the detections, queried with each track's
  bounding radius :math:`\sqrt{\gamma\, \lambda_{\max}(S_i)}` (the smallest ball that holds the gate
  ellipsoid; tracks of similar radius are queried together, one dual-tree search per
  group), then the fine test on the candidates only: cost ~ (T + D) log D when the
  targets are spread out. The tree works in coordinates divided by one per-axis scale
  (the median innovation standard deviation), so that a range in metres and a bearing in
  radians do not make every ball cover every bearing. An angle lives on a circle and the
  tree does not know it: a detection near the +-pi cut is added again shifted by -+2 pi
  (periodic images) wherever some gate could reach across the cut, and pairs found twice
  are merged.

``gate`` takes the brute-force path below ``KDTREE_MIN_PAIRS`` pairs and the tree above.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Literal, NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from trackkit.angles import wrap
from trackkit.belief import Gaussian
from trackkit.eval.metrics import chi2_ppf
from trackkit.filters.imm_fast import wrap_angle
from trackkit.filters.kalman import kalman_gain
from trackkit.linalg import cholesky
from trackkit.models.protocols import SensorModel
from trackkit.renamed import renamed_attribute

__all__ = [
    "GATE_PROBABILITY",
    "KDTREE_MIN_PAIRS",
    "Gate",
    "MeasurementPrediction",
    "gate",
    "gate_pairs",
    "gate_threshold",
    "predict_measurement",
]

Array = NDArray[np.float64]
Index = NDArray[np.intp]

#: default gate probability P_G
GATE_PROBABILITY = 0.99

#: tracks x detections above which ``gate`` pre-gates with a KD-tree. Below it the tree's
#: set-up and the per-track query lists cost more than testing every pair (measured with
#: benchmarks/bench_association.py: about equal near 7e3 pairs for spread-out 2-D scenes)
KDTREE_MIN_PAIRS = 8_000


class Gate(NamedTuple):
    """Gated pairs, sorted by track then detection (``P`` pairs).

    ``track``, ``det`` (P,) indices; ``d2`` (P,) squared Mahalanobis distances; ``loglik``
    (P,) ``log N(z_j; zhat_i, S_i)``; ``nu`` (P, m) the innovations ``nu_ij`` (angles
    wrapped); ``n_tracks``, ``n_dets`` the sizes of the problem; ``threshold`` gamma.
    """

    track: Index
    det: Index
    d2: Array
    loglik: Array
    nu: Array
    n_tracks: int
    n_dets: int
    threshold: float

    residual = renamed_attribute("Gate", "residual", "nu")

    @property
    def size(self) -> int:
        return int(self.track.shape[0])

    def take(self, pairs: NDArray[np.bool_] | Index) -> Gate:
        """The gate with only ``pairs`` (a mask or indices over the pairs, in order), the
        problem's sizes and threshold unchanged."""
        return self._replace(track=self.track[pairs], det=self.det[pairs], d2=self.d2[pairs],
                             loglik=self.loglik[pairs], nu=self.nu[pairs])


class MeasurementPrediction(NamedTuple):
    """Predicted measurement ``zhat (T, m)``, innovation covariance ``S (T, m, m)`` and
    Kalman gain ``K (T, n, m)`` of a batch of tracks."""

    zhat: Array
    S: Array
    K: Array


@lru_cache(maxsize=64)  # chi2.ppf costs more than a small scan's gate
def gate_threshold(p_gate: float, m: int) -> float:
    """gamma = chi2.ppf(P_G, m): the squared distance that holds a fraction P_G of the
    target's detections."""
    if not 0.0 < p_gate < 1.0:
        raise ValueError(f"p_gate = {p_gate!r}; expected 0 < P_G < 1")
    return float(chi2_ppf(p_gate, m))


def predict_measurement(belief: Gaussian, sensor: SensorModel) -> MeasurementPrediction:
    """First-order (EKF) measurement prediction of every track in ``belief`` (axis 0 = track):
    ``zhat = h(x)``, ``S = H P H^T + R``, ``K = P H^T S^{-1}`` with ``H`` the Jacobian at x."""
    x, P = np.asarray(belief.mean, dtype=float), np.asarray(belief.cov, dtype=float)
    zhat, H = sensor.linearize(x)
    H = np.broadcast_to(H, x.shape[:-1] + np.shape(H)[-2:])
    _, S, K = kalman_gain(P, H, np.asarray(sensor.noise, dtype=float))
    return MeasurementPrediction(np.asarray(zhat, dtype=float), S, K)


def gate(
    zhat: ArrayLike,
    S: ArrayLike,
    z: ArrayLike,
    p_gate: float = GATE_PROBABILITY,
    *,
    angular: ArrayLike | None = None,
    threshold: float | None = None,
    method: Literal["auto", "brute", "kdtree"] = "auto",
) -> Gate:
    """Ellipsoidal gate of detections ``z (D, m)`` against tracks ``zhat (T, m)``,
    ``S (T, m, m)``: the pairs with ``d2_ij <= gamma`` (see the module docstring).

    ``angular`` (m,) marks angle components (a sensor's ``angular``), whose residuals are
    wrapped; ``threshold`` gives gamma directly instead of ``p_gate``. ``method`` picks the
    path ("auto": brute force up to ``KDTREE_MIN_PAIRS`` pairs); the result is the same.
    """
    zhat, S, z, ang = _check(zhat, S, z, angular)
    T, m = zhat.shape
    D = z.shape[0]
    gamma = gate_threshold(p_gate, m) if threshold is None else float(threshold)
    if not gamma > 0:
        raise ValueError(f"threshold = {threshold!r}; expected gamma > 0")
    if method not in ("auto", "brute", "kdtree"):
        raise ValueError(f"method = {method!r}; expected 'auto', 'brute' or 'kdtree'")
    L = cholesky(S, "innovation covariance S")
    if T == 0 or D == 0:
        t = d = np.zeros(0, dtype=np.intp)
    elif method == "brute" or (method == "auto" and T * D <= KDTREE_MIN_PAIRS):
        t, d = np.divmod(np.arange(T * D, dtype=np.intp), D)
    else:
        t, d = _candidates_kdtree(zhat, S, z, ang, gamma)
    return _fine(zhat, L, z, t, d, ang, gamma)


def gate_pairs(zhat: ArrayLike, S: ArrayLike, L: ArrayLike, z: ArrayLike,
               track: ArrayLike, det: ArrayLike, gamma: float, *,
               angular: ArrayLike | None = None) -> Gate:
    """The fine test of :func:`gate` on the candidate pairs ``(track[p], det[p])`` alone,
    sorted by (track, detection), with ``L`` the lower Cholesky factor of each ``S`` and
    ``gamma`` the threshold: for several scans stacked into one (each track's candidates
    among its own scan's detections). Each pair's numbers are those ``gate`` gives it."""
    zhat, S, z, ang = _check(zhat, S, z, angular)
    t = np.asarray(track, dtype=np.intp)
    d = np.asarray(det, dtype=np.intp)
    return _fine(zhat, np.asarray(L, dtype=float), z, t, d, ang, float(gamma))


def _check(zhat, S, z, angular):
    zhat = np.asarray(zhat, dtype=float)
    if zhat.ndim != 2:
        raise ValueError(f"zhat has shape {zhat.shape}; expected (T, m)")
    T, m = zhat.shape
    S = np.asarray(S, dtype=float)
    if S.shape != (T, m, m):
        raise ValueError(f"S has shape {S.shape}; expected {(T, m, m)} to match zhat {zhat.shape}")
    z = np.asarray(z, dtype=float)
    if z.ndim == 1 and z.size == 0:
        z = z.reshape(0, m)
    if z.ndim != 2 or z.shape[1] != m:
        raise ValueError(f"z has shape {z.shape}; expected (D, {m})")
    for name, a in (("zhat", zhat), ("S", S), ("z", z)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} has non-finite entries; expected finite values")
    ang = np.zeros(m, dtype=bool) if angular is None else np.asarray(angular, dtype=bool)
    if ang.shape != (m,):
        raise ValueError(f"angular has shape {ang.shape}; expected ({m},)")
    return zhat, S, z, ang


def _fine(zhat: Array, L: Array, z: Array, t: Index, d: Index, ang, gamma: float) -> Gate:
    """The fine test on candidate pairs ``(t, d)``: ``w = L_t^{-1} nu`` by forward
    substitution, ``d2 = |w|^2``; keeps ``d2 <= gamma``.

    Pair by pair (:func:`_whitened`), so a pair's numbers do not depend on which other pairs
    are in the batch (the brute-force and tree paths agree bit for bit).
    """
    T, m = zhat.shape
    keep, d2, nu = _whitened(np.ascontiguousarray(zhat), np.ascontiguousarray(L),
                             np.ascontiguousarray(z), t, d, ang, gamma)
    t, d, d2, nu = t[keep], d[keep], d2[keep], nu[keep]
    # log det(2 pi S) = m log(2 pi) + 2 sum log L_kk, once per track
    logdet = m * np.log(2.0 * np.pi) + 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(-1)
    loglik = -0.5 * (d2 + logdet[t])
    return Gate(t, d, d2, loglik, nu, T, z.shape[0], gamma)


@numba.njit(cache=True, error_model="numpy")
def _whitened(zhat, L, z, t, d, ang, gamma):  # pragma: no cover
    """Per pair p: ``nu = z[d_p] - zhat[t_p]`` (angles wrapped), ``w = L^{-1} nu`` by forward
    substitution, ``d2 = |w|^2`` summed in component order; ``(d2 <= gamma, d2, nu)``.
    Compiled: a loop over the pairs instead of a dozen numpy passes per component."""
    P, m = t.size, zhat.shape[1]
    keep = np.zeros(P, dtype=np.bool_)
    d2 = np.zeros(P)
    nu = np.empty((P, m))
    w = np.empty(m)
    for p in range(P):
        i, k0 = t[p], d[p]
        s = 0.0
        for k in range(m):
            v = z[k0, k] - zhat[i, k]
            nu[p, k] = wrap_angle(v) if ang[k] else v
        for k in range(m):
            acc = nu[p, k]
            for j in range(k):
                acc -= L[i, k, j] * w[j]
            w[k] = acc / L[i, k, k]
            s += w[k] * w[k]
        d2[p] = s
        keep[p] = s <= gamma
    return keep, d2, nu


def _lambda_max(S: Array) -> Array:
    """Largest eigenvalue of each symmetric ``S (T, m, m)``; closed form for m <= 2."""
    m = S.shape[-1]
    if m == 1:
        return S[:, 0, 0].copy()
    if m == 2:
        a, b, c = S[:, 0, 0], 0.5 * (S[:, 0, 1] + S[:, 1, 0]), S[:, 1, 1]
        return 0.5 * (a + c) + np.hypot(0.5 * (a - c), b)
    return np.linalg.eigvalsh(S)[:, -1]


def _candidates_kdtree(zhat: Array, S: Array, z: Array, ang, gamma: float
                       ) -> tuple[Index, Index]:
    """Coarse pre-gate: pairs whose scaled, wrapped distance is within the track's bounding
    radius; a superset of the gated pairs, sorted by (track, detection), no duplicates."""
    T, m = zhat.shape
    D = z.shape[0]
    scale = np.sqrt(np.median(np.diagonal(S, axis1=-2, axis2=-1), axis=0))
    c = zhat.copy()
    y = z.copy()
    if ang.any():
        c[:, ang] = wrap(c[:, ang])
        y[:, ang] = wrap(y[:, ang])
    c /= scale
    y /= scale
    lam = _lambda_max(S / (scale[:, None] * scale[None, :]))
    # inflate so that rounding in the tree's distances can never drop a pair on the boundary
    r = np.sqrt(gamma * lam) * (1.0 + 1e-9) + 1e-300
    idx = np.arange(D, dtype=np.intp)
    W = float(r.max())
    for a in np.flatnonzero(ang):
        # angles are in (-half, half]; a gate reaching across +half finds detections near
        # -half at +2 half, and the other way round
        half = np.pi / scale[a]
        lo = y[:, a] <= W - half
        hi = y[:, a] >= half - W
        up, down = y[lo], y[hi]
        up[:, a] += 2.0 * half
        down[:, a] -= 2.0 * half
        y = np.concatenate([y, up, down])
        idx = np.concatenate([idx, idx[lo], idx[hi]])
    # Tracks in groups of similar radius (within a factor sqrt 2), each group one tree
    # query against the detection tree at the group's largest radius, then each pair held
    # to its own track's radius: a few dual-tree traversals instead of T single queries
    # (scipy's ``query_ball_point`` with per-point radii builds one Python list per track,
    # about twice as slow at 1e4 tracks), and one uncertain track's large gate does not
    # widen the query of every other track.
    tree = cKDTree(y, balanced_tree=False)  # the unbalanced build is 2x faster, queries equal
    group = np.floor(2.0 * np.log2(r)).astype(np.intp)
    keys = []
    for v in np.unique(group):
        members = np.flatnonzero(group == v)
        hits = cKDTree(c[members], balanced_tree=False).sparse_distance_matrix(
            tree, float(r[members].max()), output_type="ndarray")
        i = members[hits["i"]]
        ok = hits["v"] <= r[i]
        keys.append(i[ok] * D + idx[hits["j"][ok]])
    key = np.concatenate(keys)
    # images can find a detection twice; unique also sorts by (track, detection)
    return np.divmod(np.unique(key), D)
