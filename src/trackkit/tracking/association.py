r"""Association: which gated detection updates which track (GNN), or how much (JPDA).

Everything starts from a :class:`~trackkit.tracking.gating.Gate`, the list of gated
(track i, detection j) pairs with their squared distances d2_ij, log-likelihoods
``log N_ij = log N(z_j; zhat_i, S_i)`` and innovations nu_ij.

* :func:`clusters`: connected components of the bipartite graph of gated pairs; tracks in
  different clusters share no detection, so association splits into independent problems.
* :func:`gnn_assign`: the global nearest neighbour, the one assignment (each track at most one
  detection, each detection at most one track) of least total cost, where a track may also
  take its miss alternative. Costs come from a cost function:

  - :func:`loglik_costs`: :math:`c_{ij} = -\log(P_D N_{ij} / \lambda)`,
    :math:`c_{i0} = -\log(1 - P_D P_G)`; the least-cost assignment is then the most probable
    joint event (the JPDA event below);
  - :func:`distance_costs`: ``c_ij = d_ij`` (Mahalanobis distance), ``c_i0`` a missed
    distance (Stone Soup's ``DistanceHypothesiser``);
  - :func:`pda_costs`: ``c_ij = -beta_ij`` with beta the single-track PDA probabilities
    (Stone Soup's ``GNNWith2DAssignment`` over a ``PDAHypothesiser``, which maximises
    their sum);
  - :func:`saturating_costs`: :math:`c_{ij} = K_1 (1 - e^{-K_2 \gamma_{ij}^2})`, the cost of
    Jalalipoor and Kardehi Moghaddam (2021).

* :func:`jpda_probabilities`: marginal association probabilities from the feasible joint
  events :math:`\theta` of each cluster (each detection to at most one track, each track at
  most one detection), weighted by

  .. math::

      w(\theta) = \prod_{(i,j) \in \theta} \frac{P_D N_{ij}}{\lambda}
          \prod_{i \text{ missed}} (1 - P_D P_G), \qquad
      \beta_{ij} = \frac{\sum_{\theta \ni (i,j)} w(\theta)}{\sum_\theta w(\theta)}

  (the tracker updates a track with each of its gated detections and moment-matches the
  mixture, :func:`trackkit.belief.moment_match`).
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import connected_components, min_weight_full_bipartite_matching
from scipy.special import chdtr

from trackkit.renamed import renamed_keywords
from trackkit.tracking.gating import Gate

__all__ = [
    "BATCH_MAX_EVENTS",
    "BATCH_MAX_TRACKS",
    "GNN_DENSE_MAX_CELLS",
    "JPDA_MAX_EVENTS",
    "Assignment",
    "Clusters",
    "Costs",
    "JPDAResult",
    "clusters",
    "distance_costs",
    "gnn_assign",
    "jpda_probabilities",

    "loglik_costs",
    "pda_costs",
    "saturating_costs",
]

Array = NDArray[np.float64]
Index = NDArray[np.intp]

#: a scan whose whole problem has at most this many cells, tracks x (detections + tracks), is
#: solved by ``gnn_assign`` as one dense ``linear_sum_assignment`` instead of cluster by cluster:
#: the cluster search (a sparse graph and its components) costs about 0.27 ms a scan even for one
#: track, the dense solve 26 us for 3 tracks and 0.18 ms for 150 (43 800 cells); at 300
#: tracks (178 500 cells) the clusters win, 0.46 against 0.62 ms (spread-out tracks, ~20
#: clutter plots; benchmarks/bench_association.py, "GNN: dense against per cluster")
GNN_DENSE_MAX_CELLS = 50_000

#: largest number of joint events enumerated exactly in one JPDA cluster; a cluster with
#: more falls back to loopy belief propagation (Williams and Lau 2014). 2e4 events of a
#: 10-track cluster take about 5 ms to enumerate
JPDA_MAX_EVENTS = 20_000

#: clusters of two or more and at most BATCH_MAX_TRACKS tracks whose joint events number at most
#: BATCH_MAX_EVENTS are enumerated together, every cluster's events in one array, track slot
#: by track slot (``_joint_events``); a larger cluster is solved on its own (GNN: one
#: ``linear_sum_assignment``; JPDA: ``_enumerate``, or loopy belief propagation past
#: ``max_events``). A scan of spread-out targets has thousands of clusters of 2 to 7 tracks
#: and a few dozen events each: one at a time, their Python loop was a third of a JPDA scan at
#: 10 000 targets (benchmarks/bench_scale.py)
BATCH_MAX_TRACKS = 8
BATCH_MAX_EVENTS = 2_000

#: loopy belief propagation stops when no message changes by more than this (relative), or
#: after LBP_MAX_ITER sweeps
LBP_TOL = 1e-13
LBP_MAX_ITER = 10_000


# -- clusters --------------------------------------------------------------------------------


class Clusters(NamedTuple):
    """``count`` clusters; ``track (T,)`` the cluster of each track (every track is in one,
    a track with an empty gate alone); ``det (D,)`` the cluster of each detection, -1 for a
    detection in no gate. Clusters are numbered in order of their first track."""

    count: int
    track: Index
    det: Index


def clusters(g: Gate) -> Clusters:
    """Connected components of the graph with an edge per gated pair (scipy's
    ``connected_components`` on the (T + D)-node adjacency)."""
    T, D = g.n_tracks, g.n_dets
    if T == 0:
        return Clusters(0, np.zeros(0, dtype=np.intp), np.full(D, -1, dtype=np.intp))
    A = sp.coo_matrix((np.ones(g.size, dtype=np.int8), (g.track, T + g.det)),
                      shape=(T + D, T + D))
    _, label = connected_components(A, directed=False)
    # renumber by first track, so the numbering does not depend on scipy's traversal
    comp, first, inverse = np.unique(label[:T], return_index=True, return_inverse=True)
    rank = np.empty(comp.size, dtype=np.intp)
    rank[np.argsort(first)] = np.arange(comp.size)
    lookup = np.full(label.max() + 1, -1, dtype=np.intp)
    lookup[comp] = rank
    return Clusters(int(comp.size), rank[inverse], lookup[label[T:]])


class _Layout(NamedTuple):
    """The pairs, tracks and detections of the clusters of two or more tracks, each grouped
    by cluster, with every index also local to its cluster (built once, vectorised, so that
    the per-cluster loop only slices)."""

    pairs: Index  # gated pairs, grouped by cluster (by track then detection inside)
    tracks: Index  # tracks, grouped by cluster, ascending inside
    dets: Index  # gated detections, grouped by cluster, ascending inside
    local_track: Index  # (P_multi,) each pair's track's position in its cluster
    local_det: Index  # (P_multi,) each pair's detection's position in its cluster
    p_bounds: Index  # (K + 1,) pair slice of each cluster
    t_bounds: Index  # (K + 1,) track slice
    d_bounds: Index  # (K + 1,) detection slice
    single: NDArray[np.bool_]  # (P,) pairs whose track is alone in its cluster


def _layout(g: Gate, cl: Clusters) -> _Layout:
    ntr = np.bincount(cl.track, minlength=cl.count)
    single = ntr[cl.track[g.track]] == 1
    multi = ntr > 1
    K = np.flatnonzero(multi)  # the clusters to loop over, in order
    pairs = np.flatnonzero(~single)
    pairs = pairs[np.argsort(cl.track[g.track[pairs]], kind="stable")]
    tracks = np.flatnonzero(multi[cl.track])
    tracks = tracks[np.argsort(cl.track[tracks], kind="stable")]
    dets = np.flatnonzero(cl.det >= 0)
    dets = dets[multi[cl.det[dets]]]
    dets = dets[np.argsort(cl.det[dets], kind="stable")]
    t_bounds = np.r_[0, np.cumsum(ntr[K])]
    d_bounds = np.r_[0, np.cumsum(np.bincount(cl.det[dets], minlength=cl.count)[K])]
    p_bounds = np.r_[0, np.cumsum(np.bincount(cl.track[g.track[pairs]],
                                              minlength=cl.count)[K])]
    # position of each track (detection) inside its cluster's slice
    slot = np.zeros(cl.count, dtype=np.intp)
    slot[K] = np.arange(K.size)
    pos_t = np.empty(g.n_tracks, dtype=np.intp)
    pos_t[tracks] = np.arange(tracks.size) - t_bounds[slot[cl.track[tracks]]]
    pos_d = np.empty(g.n_dets, dtype=np.intp)
    pos_d[dets] = np.arange(dets.size) - d_bounds[slot[cl.det[dets]]]
    return _Layout(pairs, tracks, dets, pos_t[g.track[pairs]], pos_d[g.det[pairs]],
                   p_bounds, t_bounds, d_bounds, single)


# -- costs -----------------------------------------------------------------------------------


class Costs(NamedTuple):
    """Assignment costs: ``pair (P,)`` per gated pair (``inf`` forbids the pair) and
    ``miss (T,)`` per track."""

    pair: Array
    miss: Array


def _p_gate(g: Gate, p_gate: float | None) -> float:
    """P_G given, or the one that produced the gate: chi2.cdf(gamma, m)."""
    return float(chdtr(g.nu.shape[1], g.threshold)) if p_gate is None else p_gate


def _log_ratio(g: Gate, pd: float, clutter_density: float, p_gate: float | None) -> Array:
    """``log(P_D N_ij / lambda) - log(1 - P_D P_G)``: a pair's weight over the miss's."""
    _check_pd(pd, clutter_density)
    pg = _p_gate(g, p_gate)
    return np.log(pd) + g.loglik - np.log(clutter_density) - np.log1p(-pd * pg)


def _check_pd(pd: float, clutter_density: float) -> None:
    if not 0.0 < pd <= 1.0:
        raise ValueError(f"pd = {pd!r}; expected 0 < pd <= 1 (the detection probability P_D)")
    if not clutter_density > 0:
        raise ValueError(f"clutter_density = {clutter_density!r}; expected lambda > 0")


@renamed_keywords(p_d="pd")
def loglik_costs(g: Gate, pd: float, clutter_density: float,
                 p_gate: float | None = None) -> Costs:
    """Negative log-likelihood-ratio costs: ``c_ij = -log(P_D N_ij / lambda)`` and
    ``c_i0 = -log(1 - P_D P_G)`` (``P_G`` defaults to the gate's, chi2.cdf(gamma, m)).

    Summed over an assignment this is minus the log of the joint event's weight (see
    :func:`jpda_probabilities`), so the GNN picks the most probable joint event.
    """
    _check_pd(pd, clutter_density)
    pg = _p_gate(g, p_gate)
    pair = -(np.log(pd) + g.loglik - np.log(clutter_density))
    return Costs(pair, np.full(g.n_tracks, -np.log1p(-pd * pg)))


def distance_costs(g: Gate, missed_distance: float | None = None) -> Costs:
    """``c_ij = d_ij`` (Mahalanobis distance), ``c_i0 = missed_distance`` (default the gate's
    edge, sqrt(gamma)); pairs with ``d_ij >= missed_distance`` are forbidden, as in Stone
    Soup's ``DistanceHypothesiser``."""
    md = float(np.sqrt(g.threshold)) if missed_distance is None else float(missed_distance)
    if not (md > 0 and np.isfinite(md)):
        raise ValueError(f"missed_distance = {missed_distance!r}; expected a finite value > 0")
    d = np.sqrt(g.d2)
    return Costs(np.where(d < md, d, np.inf), np.full(g.n_tracks, md))


@renamed_keywords(p_d="pd")
def pda_costs(g: Gate, pd: float, clutter_density: float,
              p_gate: float | None = None) -> Costs:
    """``c_ij = -beta_ij``, ``c_i0 = -beta_i0``, with the single-track PDA probabilities
    ``beta_ij = L_ij / (1 - P_D P_G + sum_j L_ij)``, ``L_ij = P_D N_ij / lambda``.

    The GNN then maximises the sum of the per-track probabilities, which is what Stone Soup's
    ``GNNWith2DAssignment`` does with a ``PDAHypothesiser``; kept for comparison with it.
    """
    beta, beta0 = _pda(g.track, _log_ratio(g, pd, clutter_density, p_gate), g.n_tracks)
    return Costs(-beta, -beta0)


def saturating_costs(g: Gate, k1: float = 1.0, k2: float = 0.5, miss_cost: float | None = None,
                  distance: Literal["mahalanobis", "residual"] = "mahalanobis") -> Costs:
    """The cost of Jalalipoor and Kardehi Moghaddam (2021), ``c_ij = K1 (1 - exp(-K2 gamma_ij^2))``.

    ``gamma_ij^2`` is the squared Mahalanobis distance d2_ij, or with ``distance="residual"``
    the squared innovation ``|nu_ij|^2`` (the paper's bearing difference, wrapped). The paper
    gives neither K1 nor K2: K1 = 1, K2 = 1/2 make ``1 - c`` the Gaussian likelihood
    shape ``exp(-d2 / 2)``. A missed track costs ``miss_cost``, by default K1, the cost of an
    infinitely distant detection: then every track that can be assigned is (the paper runs
    Munkres on the track x measurement matrix, which assigns min(T, D) pairs), and the gate
    is the only way to refuse a detection.
    """
    if not (k1 > 0 and k2 > 0):
        raise ValueError(f"k1 = {k1!r}, k2 = {k2!r}; expected K1 > 0 and K2 > 0")
    if distance == "mahalanobis":
        gamma2 = g.d2
    elif distance == "residual":
        gamma2 = np.einsum("pi,pi->p", g.nu, g.nu)
    else:
        raise ValueError(f"distance = {distance!r}; expected 'mahalanobis' or 'residual'")
    pair = k1 * -np.expm1(-k2 * gamma2)
    return Costs(pair, np.full(g.n_tracks, k1 if miss_cost is None else float(miss_cost)))


# -- GNN -------------------------------------------------------------------------------------


class Assignment(NamedTuple):
    """``det (T,)``: the detection assigned to each track, -1 for a miss; ``unassigned``:
    the detections no track took, sorted (for track initiation); ``cost``: the total."""

    det: Index
    unassigned: Index
    cost: float


def gnn_assign(g: Gate, costs: Costs,
        method: Literal["auto", "clusters", "sparse", "dense"] = "auto") -> Assignment:
    """Least-cost assignment of gated pairs, each track taking one detection or its miss.

    With rows = tracks and columns = detections plus one miss column per track (the miss
    block diagonal), minimise ``sum_i c_i,col(i)``. ``method="clusters"`` solves the tracks
    alone in their cluster by one vectorised argmin, the small clusters (``BATCH_MAX_TRACKS``,
    ``BATCH_MAX_EVENTS``) by their cheapest joint event, all at once, and each other cluster
    with a dense ``linear_sum_assignment`` (as it does a small cluster whose two cheapest
    events tie to within rounding, so the result is always the per-cluster solver's);
    ``"sparse"`` solves the whole scan as one sparse problem (scipy's LAPJVsp,
    ``min_weight_full_bipartite_matching``); ``"dense"`` solves the whole scan as one dense
    problem. All give the optimum. ``"auto"``, the
    default, takes "dense" up to ``GNN_DENSE_MAX_CELLS`` cells, where the cluster search's
    fixed cost dominates, and "clusters" above, where the per-cluster cost grows linearly with
    the clusters (benchmarks/bench_association.py).
    """
    T, D = g.n_tracks, g.n_dets
    pair, miss = np.asarray(costs.pair, dtype=float), np.asarray(costs.miss, dtype=float)
    if pair.shape != (g.size,) or miss.shape != (T,):
        raise ValueError(f"costs have shapes pair {pair.shape}, miss {miss.shape}; expected "
                         f"({g.size},) and ({T},)")
    if np.any(np.isnan(pair)) or not np.all(np.isfinite(miss)):
        raise ValueError("costs: nan pair costs or non-finite miss costs; expected a finite "
                         "miss cost for every track (inf pair costs forbid a pair)")
    ok = np.isfinite(pair)
    t, d, c = g.track[ok], g.det[ok], pair[ok]
    if method == "auto":
        method = "dense" if T * (D + T) <= GNN_DENSE_MAX_CELLS else "clusters"
    if method == "sparse":
        det = _gnn_sparse(t, d, c, miss, T, D)
    elif method == "dense":
        det = _gnn_dense(t, d, c, miss, T, D)
    elif method == "clusters":
        det = _gnn_clusters(g.take(ok), c, miss)
    else:
        raise ValueError(f"method = {method!r}; expected 'auto', 'dense', 'sparse' or "
                         "'clusters'")
    taken = np.zeros(D, dtype=bool)
    taken[det[det >= 0]] = True
    # total cost: the chosen pair costs, looked up by (track, det) key in the sorted pairs
    chosen = det >= 0
    key = t * D + d
    pos = np.searchsorted(key, np.flatnonzero(chosen) * D + det[chosen])
    total = float(c[pos].sum() + miss[~chosen].sum())
    return Assignment(det, np.flatnonzero(~taken), total)


def _gnn_sparse(t: Index, d: Index, c: Array, miss: Array, T: int, D: int) -> Index:
    """One LAPJVsp call on the T x (D + T) sparse matrix [pairs | diag(miss)].

    Every row is matched exactly once, so adding a constant to a row moves every solution's
    cost by the same amount: rows are shifted to costs >= 1, since the solver treats stored
    zeros as missing edges and wants no negative weights.
    """
    det = np.full(T, -1, dtype=np.intp)
    if t.size == 0:
        return det
    rows = np.unique(t)  # only tracks with some finite pair need solving
    local = np.searchsorted(rows, t)
    R = rows.size
    low = np.minimum(miss[rows], _segment_min(c, local, R))
    shift = 1.0 - low
    data = np.concatenate([c + shift[local], miss[rows] + shift])
    cols = np.concatenate([d, D + np.arange(R)])
    ri = np.concatenate([local, np.arange(R)])
    A = sp.csr_matrix((data, (ri, cols)), shape=(R, D + R))
    r, col = min_weight_full_bipartite_matching(A)
    hit = col < D
    det[rows[r[hit]]] = col[hit]
    return det


def _gnn_dense(t: Index, d: Index, c: Array, miss: Array, T: int, D: int) -> Index:
    """One ``linear_sum_assignment`` on the T x (D + T) matrix [pairs | diag(miss)] (inf
    where a pair is not gated; the miss diagonal keeps every row feasible)."""
    det = np.full(T, -1, dtype=np.intp)
    if t.size == 0:
        return det
    M = np.full((T, D + T), np.inf)
    M[t, d] = c
    M[np.arange(T), D + np.arange(T)] = miss
    r, col = linear_sum_assignment(M)
    hit = col < D
    det[r[hit]] = col[hit]
    return det


def _segment_min(values: Array, seg: Index, n: int) -> Array:
    out = np.full(n, np.inf)
    np.minimum.at(out, seg, values)
    return out


def _gnn_clusters(g: Gate, c: Array, miss: Array) -> Index:
    """Per-cluster least-cost assignment: one-track clusters by a vectorised argmin, the
    clusters within ``BATCH_MAX_TRACKS`` and ``BATCH_MAX_EVENTS`` by their cheapest joint
    event, all at once (``_gnn_batched``), and the rest one ``linear_sum_assignment`` each."""
    det = np.full(g.n_tracks, -1, dtype=np.intp)
    if g.size == 0:
        return det
    lay = _layout(g, clusters(g))
    # one track: the cheapest of its pairs, if cheaper than its miss
    ts, ds, cs = g.track[lay.single], g.det[lay.single], c[lay.single]
    order = np.lexsort((cs, ts))
    first = order[np.r_[True, ts[order][1:] != ts[order][:-1]]] if ts.size else order
    win = cs[first] < miss[ts[first]]
    det[ts[first][win]] = ds[first][win]
    cm = c[lay.pairs]
    solved = _gnn_batched(lay, cm, miss, det)
    for k in np.flatnonzero(~solved).tolist():
        _gnn_cluster(lay, k, cm, miss, det)
    return det


def _gnn_cluster(lay: _Layout, k: int, cm: Array, miss: Array, det: Index) -> None:
    """Cluster k by one dense ``linear_sum_assignment`` on [pair costs | diag(miss)],
    nt x (nd + nt); its tracks' detections written into ``det``."""
    p0, p1 = lay.p_bounds[k], lay.p_bounds[k + 1]
    t0, t1 = lay.t_bounds[k], lay.t_bounds[k + 1]
    nt, nd = t1 - t0, lay.d_bounds[k + 1] - lay.d_bounds[k]
    M = np.full((nt, nd + nt), np.inf)
    M[lay.local_track[p0:p1], lay.local_det[p0:p1]] = cm[p0:p1]
    tr = lay.tracks[t0:t1]
    M[np.arange(nt), nd + np.arange(nt)] = miss[tr]
    r, col = linear_sum_assignment(M)
    hit = col < nd
    det[tr[r[hit]]] = lay.dets[lay.d_bounds[k] + col[hit]]


#: the cheapest joint event of a cluster is taken only when the next cheapest costs more by
#: over this much per unit of the cluster's cost scale (sum over its tracks of the largest
#: |cost|); closer, the two differ by rounding and ``linear_sum_assignment`` decides, as on
#: the one-at-a-time path
GNN_TIE = 1e-9


def _gnn_batched(lay: _Layout, cm: Array, miss: Array, det: Index) -> NDArray[np.bool_]:
    """The batched clusters' least-cost assignments, written into ``det``; returns which
    clusters were solved (the others: too large, or a near tie).

    An assignment of a cluster is a joint event (each track its miss or one of its
    detections, no detection twice), costing ``sum_i miss_i + sum_(i,j) (c_ij - miss_i)``:
    the least-cost one is ``linear_sum_assignment``'s optimum."""
    K = lay.t_bounds.size - 1
    slot = _pair_slot(lay)
    pair_track = lay.tracks[slot]
    ev = _joint_events(lay, cm - miss[pair_track], BATCH_MAX_EVENTS)
    if ev.cluster.size == 0:
        return ev.batched
    start = np.searchsorted(ev.cluster, np.arange(K + 1))
    counts = np.diff(start)
    has = counts > 0
    order = np.lexsort((ev.logw, ev.cluster))  # by cluster, cheapest first
    best = order[start[:-1][has]]
    second = np.full(K, np.inf)
    many = has & (counts > 1)
    second[many] = ev.logw[order[start[:-1][many] + 1]]
    # every track of a cluster of two or more has a pair, and the pairs are grouped by track
    top = np.maximum(np.abs(miss[pair_track]), np.abs(cm))
    track_top = np.maximum.reduceat(top, np.flatnonzero(np.r_[True, slot[1:] != slot[:-1]]))
    scale = np.add.reduceat(track_top, lay.t_bounds[:-1])
    tie = np.zeros(K, dtype=bool)
    tie[has] = second[has] - ev.logw[best] <= GNN_TIE * (1.0 + scale[has])
    solved = ev.batched & ~tie
    win = best[solved[ev.cluster[best]]]
    k = ev.cluster[win]
    slots = ev.det[win]  # (n, W) local detections, -1 a miss or no such slot
    nt = np.diff(lay.t_bounds)[k]
    i = np.arange(slots.shape[1])
    sel = (i[None, :] < nt[:, None]) & (slots >= 0)
    rows, cols = np.nonzero(sel)
    det[lay.tracks[lay.t_bounds[k[rows]] + cols]] = lay.dets[lay.d_bounds[k[rows]]
                                                             + slots[rows, cols]]
    return solved


# -- joint events, every cluster at once -----------------------------------------------------


class _Events(NamedTuple):
    """The joint events of the clusters ``batched``, grouped by cluster, each cluster's
    in the order ``_enumerate`` builds them."""

    cluster: Index  # (E,) each event's cluster, ascending
    det: Index  # (E, W) each track slot's local detection, -1 a miss (and slots past nt)
    logw: Array  # (E,) the sum of w over the event's detected tracks, in track order
    batched: NDArray[np.bool_]  # (K,) the clusters enumerated here


def _pair_slot(lay: _Layout) -> Index:
    """Each layout pair's track's position in ``lay.tracks``."""
    k_pair = np.repeat(np.arange(lay.t_bounds.size - 1), np.diff(lay.p_bounds))
    return lay.t_bounds[k_pair] + lay.local_track


def _joint_events(lay: _Layout, w: Array, cap: int) -> _Events:
    """Every joint event of the clusters of at most ``BATCH_MAX_TRACKS`` tracks and ``cap``
    events, with its weight ``sum w`` (w per layout pair), built as ``_enumerate`` builds one
    cluster's: track slot by slot, each event so far kept (the slot's miss) and extended by
    each of the slot's detections it has not used, the extensions after the events, in
    (event, detection) order. The loop runs over the slots, vectorised over every event of
    every cluster; a cluster whose events pass ``cap`` is dropped (``batched`` False)."""
    nt = np.diff(lay.t_bounds)
    batched = nt <= BATCH_MAX_TRACKS
    slot = _pair_slot(lay)
    n_opt = np.bincount(slot, minlength=lay.tracks.size)
    first = np.cumsum(n_opt) - n_opt  # the layout pairs are grouped by track slot
    cl = np.flatnonzero(batched)
    W = int(nt[cl].max()) if cl.size else 0
    ev = np.full((cl.size, W), -1, dtype=np.intp)
    logw = np.zeros(cl.size)
    for i in range(W):
        act = np.flatnonzero(nt[cl] > i)
        tp = lay.t_bounds[cl[act]] + i
        cnt = n_opt[tp]
        e = np.repeat(act, cnt)
        o = np.arange(e.size) + np.repeat(first[tp] - (np.cumsum(cnt) - cnt), cnt)
        d = lay.local_det[o]
        free = ~np.any(ev[e, :i] == d[:, None], axis=1)
        e, o = e[free], o[free]
        ext = ev[e]
        ext[:, i] = lay.local_det[o]
        ext_cl = cl[e]
        ext_w = logw[e] + w[o]
        n = np.bincount(cl, minlength=nt.size) + np.bincount(ext_cl, minlength=nt.size)
        over = n > cap
        if over.any():
            batched &= ~over
            keep, keep_ext = ~over[cl], ~over[ext_cl]
            ev, cl, logw = ev[keep], cl[keep], logw[keep]
            ext, ext_cl, ext_w = ext[keep_ext], ext_cl[keep_ext], ext_w[keep_ext]
        # each cluster's events so far, then its extensions
        cl_all = np.concatenate([cl, ext_cl])
        order = np.argsort(cl_all, kind="stable")
        ev = np.concatenate([ev, ext])[order]
        logw = np.concatenate([logw, ext_w])[order]
        cl = cl_all[order]
    return _Events(cl, ev, logw, batched)


def _jpda_batched(lay: _Layout, lrm: Array, nd: Index, max_events: int, star: bool
                  ) -> tuple[NDArray[np.bool_], Array, Array]:
    """The exact marginals of the batched clusters, as ``_enumerate`` gives each: returns
    (batched (K,), beta over the layout pairs, beta0 over the layout tracks), the last two
    meaningful on the batched clusters only.

    Each cluster's normalisation is the sum of its events' probabilities in its events'
    order; clusters with equally many events are stacked and summed along rows (numpy sums a
    row of a C-ordered stack as it sums the row alone), so every number is ``_enumerate``'s,
    bit for bit."""
    nt = np.diff(lay.t_bounds)
    K = nt.size
    ev = _joint_events(lay, lrm, min(BATCH_MAX_EVENTS, max_events))
    cl, dets, logw = ev.cluster, ev.det, ev.logw
    if cl.size == 0:
        return ev.batched, np.zeros(lay.pairs.size), np.ones(lay.tracks.size)
    width = nd + 1
    boff = np.cumsum(nt * width) - nt * width  # each cluster's (nt, nd + 1) table in one array
    W = dets.shape[1]
    i = np.arange(W)
    live = i[None, :] < nt[cl][:, None]
    if star:
        keep = _star_keep_batched(lay, lrm, cl, dets, boff, width)
        cl, dets, logw, live = cl[keep], dets[keep], logw[keep], live[keep]
    start = np.searchsorted(cl, np.arange(K + 1))
    counts = np.diff(start)
    has = counts > 0
    mx = np.full(K, -np.inf)
    mx[has] = np.maximum.reduceat(logw, start[:-1][has])
    p = np.exp(logw - mx[cl])
    total = np.zeros(K)
    for E in np.unique(counts[has]).tolist():
        rows = np.flatnonzero(counts == E)
        total[rows] = p[start[rows][:, None] + np.arange(E)].sum(axis=1)
    p /= total[cl]
    flat = (boff[cl] + 1)[:, None] + i[None, :] * width[cl][:, None] + dets
    B = np.bincount(flat[live], np.broadcast_to(p[:, None], live.shape)[live],
                    minlength=int((nt * width).sum()))
    k_pair = np.repeat(np.arange(K), np.diff(lay.p_bounds))
    beta = B[boff[k_pair] + lay.local_track * width[k_pair] + lay.local_det + 1]
    k_track = np.repeat(np.arange(K), nt)
    local = np.arange(lay.tracks.size) - lay.t_bounds[k_track]
    beta0 = B[boff[k_track] + local * width[k_track]]
    return ev.batched, beta, beta0


def _star_keep_batched(lay: _Layout, lrm: Array, cl: Index, dets: Index, boff: Index,
                       width: Index) -> NDArray[np.bool_]:
    """``_star_keep`` of every batched cluster at once: the events in which no two detected
    tracks i < k (detections j, l) have a gated swap more likely,
    ``lr_il + lr_kj > lr_ij + lr_kl``; a cluster that would keep none keeps all."""
    nt = np.diff(lay.t_bounds)
    K = nt.size
    k_pair = np.repeat(np.arange(K), np.diff(lay.p_bounds))
    L = np.full(int((nt * width).sum()), -np.inf)  # column 0: the miss, never swapped
    L[boff[k_pair] + lay.local_track * width[k_pair] + lay.local_det + 1] = lrm
    W = dets.shape[1]
    a, b = np.triu_indices(W, 1)
    base = boff[cl][:, None]
    wd = width[cl][:, None]
    j, m = dets[:, a] + 1, dets[:, b] + 1
    both = (j > 0) & (m > 0)  # a slot past the cluster's tracks holds -1, a miss
    Lam, Lbj = L[np.where(both, base + a * wd + m, 0)], L[np.where(both, base + b * wd + j, 0)]
    Laj, Lbm = L[np.where(both, base + a * wd + j, 0)], L[np.where(both, base + b * wd + m, 0)]
    with np.errstate(invalid="ignore"):
        better = Lam + Lbj > Laj + Lbm
    keep = ~np.any(both & better, axis=1)
    # in exact arithmetic the most probable event has no better swap; guard against rounding
    kept = np.bincount(cl[keep], minlength=K)
    return keep | (kept[cl] == 0)


# -- JPDA ------------------------------------------------------------------------------------


class JPDAResult(NamedTuple):
    """``beta (P,)``: marginal probability that gated pair p's detection is the track's;
    ``beta0 (T,)``: probability that the track was not detected (sum_j beta_ij + beta_i0 = 1);
    ``clusters``; ``approximated (K,)``: the clusters whose marginals came from loopy belief
    propagation instead of exact enumeration."""

    beta: Array
    beta0: Array
    clusters: Clusters
    approximated: NDArray[np.bool_]


@renamed_keywords(p_d="pd")
def jpda_probabilities(g: Gate, pd: float, clutter_density: float, p_gate: float | None = None, *,
         max_events: int = JPDA_MAX_EVENTS, cl: Clusters | None = None,
         star: bool = False) -> JPDAResult:
    r"""Parametric JPDA marginals (Bar-Shalom): a feasible joint event :math:`\theta` (each
    detection to at most one track, each track at most one detection) has weight

    .. math::

        w(\theta) = \prod_{(i,j) \in \theta} \frac{P_D N_{ij}}{\lambda}
            \prod_{i \text{ missed}} (1 - P_D P_G)

    and the marginals are

    .. math::

        \beta_{ij} = \frac{\sum_{\theta \ni (i,j)} w(\theta)}{\sum_\theta w(\theta)}, \qquad
        \beta_{i0} = \frac{\sum_{\theta:\, i \text{ missed}} w(\theta)}{\sum_\theta w(\theta)}

    Events are enumerated exactly within each cluster (a track alone in its cluster in closed
    form, the PDA; the clusters within ``BATCH_MAX_TRACKS`` and ``BATCH_MAX_EVENTS`` all in one
    array, with the same numbers bit for bit); a cluster with more than ``max_events`` events
    falls back to loopy belief propagation (Williams and Lau 2014, exact on clusters without
    cycles), reported in ``approximated``.

    ``star=True`` is JPDA* (Blom and Bloem 2000), against track coalescence: the exact
    enumeration drops every event theta in which two tracks i, k take detections j, l while
    the swapped pairs (i, l), (k, j) are both gated and more likely,
    ``r_il r_kj > r_ij r_kl``, and normalises over the events kept (the most probable event is
    always kept). Single-track clusters are unchanged, and the loopy-BP fallback stays plain
    JPDA (still reported in ``approximated``).
    """
    T = g.n_tracks
    lr = _log_ratio(g, pd, clutter_density, p_gate)
    cl = clusters(g) if cl is None else cl
    beta = np.zeros(g.size)
    beta0 = np.ones(T)
    approx = np.zeros(cl.count, dtype=bool)
    if g.size == 0:
        return JPDAResult(beta, beta0, cl, approx)
    lay = _layout(g, cl)
    single = lay.single
    # one-track clusters: the PDA, beta_ij = r_ij / (1 + sum_j r_ij), all at once
    b, b0 = _pda(g.track[single], lr[single], T)
    beta[single] = b
    has = np.bincount(g.track[single], minlength=T) > 0
    beta0[has] = b0[has]
    lrm, lt, ld = lr[lay.pairs], lay.local_track, lay.local_det
    pb, tb, db = lay.p_bounds.tolist(), lay.t_bounds.tolist(), lay.d_bounds.tolist()
    done, bb, bb0 = _jpda_batched(lay, lrm, np.diff(lay.d_bounds), max_events, star)
    on_pair = np.repeat(done, np.diff(lay.p_bounds))
    beta[lay.pairs[on_pair]] = bb[on_pair]
    on_track = np.repeat(done, np.diff(lay.t_bounds))
    beta0[lay.tracks[on_track]] = bb0[on_track]
    lbp_pairs = []
    for k in np.flatnonzero(~done).tolist():
        p0, p1, t0, t1 = pb[k], pb[k + 1], tb[k], tb[k + 1]
        B = _enumerate(lt[p0:p1], ld[p0:p1], lrm[p0:p1], t1 - t0, db[k + 1] - db[k],
                       max_events, star)
        if B is None:
            lbp_pairs.append(lay.pairs[p0:p1])
            continue
        beta[lay.pairs[p0:p1]] = B[lt[p0:p1], ld[p0:p1] + 1]
        beta0[lay.tracks[t0:t1]] = B[:, 0]
    if lbp_pairs:
        idx = np.concatenate(lbp_pairs)
        beta[idx], b0 = _lbp(g.track[idx], g.det[idx], lr[idx], T, g.n_dets)
        tr = np.unique(g.track[idx])
        beta0[tr] = b0[tr]
        approx[cl.track[tr]] = True
    return JPDAResult(beta, beta0, cl, approx)


def _pda(track: Index, lr: Array, T: int) -> tuple[Array, Array]:
    """Single-track PDA over pairs (track, log ratio r): ``beta_ij = r_ij / (1 + sum r)``,
    ``beta_i0 = 1 / (1 + sum r)``, in log space (a tight gate makes r overflow)."""
    mx = np.zeros(T)
    np.maximum.at(mx, track, lr)
    s = np.exp(-mx) + np.bincount(track, np.exp(lr - mx[track]), minlength=T)
    lse = mx + np.log(s)
    return np.exp(lr - lse[track]), np.exp(-lse)


def _enumerate(lt: Index, ld: Index, lr: Array, nt: int, nd: int, max_events: int,
               star: bool = False) -> Array | None:
    """Exact marginals of one cluster: ``B (nt, nd + 1)`` with ``B[i, 0] = beta_i0`` and
    ``B[i, j + 1] = beta_ij``, or None past ``max_events`` events.

    Events are built track by track; each step extends every event so far by the track's
    miss and by each of its detections that the event has not used (vectorised over events
    and options). ``star``: JPDA* pruning (see :func:`jpda_probabilities`), vectorised over
    events and track pairs.
    """
    ev = np.full((1, nt), -1, dtype=np.intp)  # each track's detection, -1 = miss (so far)
    used = np.zeros((1, nd), dtype=bool)
    logw = np.zeros(1)
    bounds = np.searchsorted(lt, np.arange(nt + 1)).tolist()  # lt is sorted
    for i in range(nt):
        dets, w = ld[bounds[i]:bounds[i + 1]], lr[bounds[i]:bounds[i + 1]]
        e, o = np.nonzero(~used[:, dets])  # event e can add option o
        if logw.size + e.size > max_events:
            return None
        # the events so far already carry the miss (-1) of track i: append the extensions
        ext = ev[e]
        ext[:, i] = dets[o]
        ext_used = used[e]
        ext_used[np.arange(e.size), dets[o]] = True
        ev = np.concatenate([ev, ext])
        used = np.concatenate([used, ext_used])
        logw = np.concatenate([logw, logw[e] + w[o]])
    if star and nt > 1:
        keep = _star_keep(ev, lt, ld, lr, nt, nd)
        ev, logw = ev[keep], logw[keep]
    p = np.exp(logw - logw.max())
    p /= p.sum()
    flat = (np.arange(nt) * (nd + 1))[None, :] + ev + 1
    B = np.bincount(flat.ravel(), np.repeat(p, nt), minlength=nt * (nd + 1))
    return B.reshape(nt, nd + 1)


def _star_keep(ev: Index, lt: Index, ld: Index, lr: Array, nt: int, nd: int
               ) -> NDArray[np.bool_]:
    """JPDA* (Blom and Bloem 2000): the events ``ev (E, nt)`` to keep, those in which no two
    detected tracks i < k (detections j, l) have a gated swap more likely,
    ``lr_il + lr_kj > lr_ij + lr_kl``."""
    L = np.full((nt, nd + 1), -np.inf)  # column 0: the miss, never swapped
    L[lt, ld + 1] = lr
    i, k = np.triu_indices(nt, 1)
    j, m = ev[:, i] + 1, ev[:, k] + 1  # (E, pairs), 0 = miss
    both = (j > 0) & (m > 0)
    with np.errstate(invalid="ignore"):
        better = L[i, m] + L[k, j] > L[i, j] + L[k, m]
    keep = ~np.any(both & better, axis=1)
    # in exact arithmetic the most probable event has no better swap; guard against rounding
    if not keep.any():
        keep[:] = True
    return keep


def _lbp(track: Index, det: Index, lr: Array, T: int, D: int) -> tuple[Array, Array]:
    """Loopy belief propagation for the marginals (Williams and Lau 2014), over pairs.

    With ``r_ij`` the pair's weight over the miss's, messages
    ``mu_ij = r_ij / (1 + sum_{j' != j} r_ij' nu_ij')`` (track to detection) and
    ``nu_ij = 1 / (1 + sum_{i' != i} mu_i'j)`` (detection to track) are iterated from
    nu = 1; then ``beta_ij = r_ij nu_ij / (1 + sum_j' r_ij' nu_ij')``, ``beta_i0 = 1 / (...)``.
    """
    # e^500 ~ 1e217: a few such weights still sum without overflow
    r = np.exp(np.clip(lr, -500.0, 500.0))
    nu = np.ones_like(r)
    for _ in range(LBP_MAX_ITER):
        mu = r / _one_plus_others(r * nu, track, T)
        new = 1.0 / _one_plus_others(mu, det, D)
        done = np.max(np.abs(new - nu) / new) <= LBP_TOL
        nu = new
        if done:
            break
    val = r * nu
    s = 1.0 + np.bincount(track, val, minlength=T)
    return val / s[track], 1.0 / s


def _one_plus_others(v: Array, seg: Index, n: int) -> Array:
    """``1 + sum_{k != p, seg_k = seg_p} v_k`` for every element p, without cancellation.

    ``1 + total - v_p`` loses everything when v_p dominates its segment (a detection far
    likelier than the miss makes total - v_p round to 0, and the message divides by 0), so
    the largest element of each segment gets the direct sum of the others; for the rest,
    ``total - v_p`` keeps the maximum in, and is accurate to a few ulps of it.
    """
    top = np.full(n, -np.inf)
    np.maximum.at(top, seg, v)
    is_top = v == top[seg]
    # one element per segment plays the maximum (ties: the first)
    cand = np.flatnonzero(is_top)
    _, keep = np.unique(seg[cand], return_index=True)
    is_top[:] = False
    is_top[cand[keep]] = True
    total = np.bincount(seg, v, minlength=n)
    rest = np.bincount(seg, np.where(is_top, 0.0, v), minlength=n)
    return 1.0 + np.where(is_top, rest[seg], total[seg] - v)
