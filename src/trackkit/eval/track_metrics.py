r"""Multi-target metrics: OSPA, GOSPA and track-level counts, over ragged per-step point sets.

Input format (``Frames``): the point sets of S steps are stacked as one ragged array, step s
holding rows ``offsets[s]:offsets[s + 1]`` of ``x (N, d)`` (and of ``ids (N,)``, the integer
truth or track IDs, for the track-level counts). The steps may be the K steps of one run, or
the R K steps of R runs laid one run after another; the distances are computed per step, and
the track counts per run (``run_offsets``), each independently of what else is in the batch,
so a result is bit-identical however runs are chunked.

Distances between a truth set :math:`X = \{\mathbf{x}_1, \dots, \mathbf{x}_n\}` and an
estimate set :math:`Y = \{\mathbf{y}_1, \dots, \mathbf{y}_m\}`, cut-off :math:`c > 0`, order
:math:`1 \le p < \infty`, :math:`d(\mathbf{x}, \mathbf{y}) = \lVert \mathbf{x} - \mathbf{y}
\rVert` (Euclidean), :math:`d_c = \min(d, c)`. Both share one assignment problem, over the
one-to-one partial assignments :math:`\gamma` of truths to estimates,

.. math::

    A = \min_\gamma \sum_{(i,j) \in \gamma} d_c(\mathbf{x}_i, \mathbf{y}_j)^p
        + c^p \bigl(\min(n, m) - |\gamma|\bigr)

(a pair at distance >= c costs the same as leaving both points unassigned, so only pairs
within c are ever assigned; ``assigned`` = k is the number of those). With
:math:`L = \sum d(\mathbf{x}_i, \mathbf{y}_j)^p` over the k assigned pairs:

* GOSPA, :math:`\alpha = 2` (Rahmathullah, Garcia-Fernandez & Svensson 2017), localisation
  plus missed plus false (the parts are in units of :math:`d^p`):

  .. math::

      \mathrm{GOSPA}^p = L + \frac{c^p}{2} (n - k) + \frac{c^p}{2} (m - k)

* OSPA (Schuhmacher, Vo & Vo 2008), n or m > 0, again localisation plus missed plus false:

  .. math::

      \mathrm{OSPA}^p = \frac{A + c^p\, |m - n|}{\max(n, m)}
          = \frac{A}{\max(n, m)} + \frac{c^p \max(n - m, 0)}{\max(n, m)}
          + \frac{c^p \max(m - n, 0)}{\max(n, m)}

  (the paper's components are ``localisation^(1/p)`` and ``(missed + false)^(1/p)``);
  :math:`\mathrm{OSPA}(\emptyset, \emptyset) = 0`.

p = inf is not supported. The parts are p-th powers so that they add up (and sum exactly
over Monte Carlo runs). Stone Soup's ``GOSPAMetric`` reports the same parts (its
``distance`` is GOSPA). Its ``OSPAMetric`` assigns by min(d, c) rather than min(d, c)^p, so
it is the textbook OSPA only at p = 1 (at p = 2 it is never low, and can be far too high).

How it is fast: the pairs within c of many small steps are found in one vectorised pass (a
large step, n m >= 4096, gets its own broadcast pass); the bipartite "within c" graph is split
into connected components (pairs in different components are never assigned); a component
with one truth or one estimate takes its nearest pair, small components of one shape are
solved together by enumerating every assignment, and only the rest go one by one to
``scipy.optimize.linear_sum_assignment`` (a large step whose edges are dense goes there
whole). Every step is solved by the same arithmetic whatever else is in the batch.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from functools import cache
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

__all__ = [
    "Frames",
    "SetDistance",
    "TrackCounts",
    "assign",
    "checked_assignment",
    "checked_frames",
    "dominant_truths",
    "frames",
    "gospa",
    "gospa_steps",
    "ospa",
    "ospa_steps",
    "pairs_within",
    "solve_partial",
    "track_counts",
    "track_summary",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

_PAIR_CHUNK = 1 << 22  # candidate pairs per vectorised pass (about 100 MB of temporaries at d=2)


class Frames(NamedTuple):
    """Ragged per-step point sets: step s is ``x[offsets[s]:offsets[s + 1]]``.

    ``offsets (S + 1,)`` non-decreasing from 0 to N, ``x (N, d)``, ``ids (N,)`` integer
    IDs (truth or track; needed by ``track_counts`` only, unique within a step).
    """

    offsets: IntArray
    x: Array
    ids: IntArray | None = None

    @property
    def n_steps(self) -> int:
        return len(self.offsets) - 1

    @property
    def sizes(self) -> IntArray:
        """Points per step, ``(S,)``."""
        return np.diff(self.offsets)


class SetDistance(NamedTuple):
    """A distance between point sets and its additive parts (p-th powers):
    ``distance^p = localisation + missed + false``; ``assigned`` is the number of pairs within
    the cut-off. Floats for one step; ``(S,)`` arrays from the ``*_steps`` functions."""

    distance: Array
    localisation: Array
    missed: Array
    false: Array
    assigned: IntArray


class TrackCounts(NamedTuple):
    """Track-level counts and sums per run, each ``(R,)``; see ``track_counts``.

    Every field is a sum over the run's truths, tracks, steps or pairs, so Monte Carlo totals
    are exact sums over runs (``track_summary`` turns them into rates and means).
    """

    truths: IntArray  #: distinct truth IDs
    truths_confirmed: IntArray  #: truths assigned to a track at some step
    confirmed_within: IntArray  #: truths confirmed no later than ``within`` after birth
    confirm_delay: Array  #: sum over confirmed truths of t(first assigned) - t(birth)
    truth_steps: IntArray  #: sum over steps of the number of truths present
    assigned_steps: IntArray  #: assigned (truth, track) pairs over all steps
    tracks: IntArray  #: distinct confirmed track IDs
    false_tracks: IntArray  #: tracks assigned on less than ``min_assigned`` of their life
    track_steps: IntArray  #: sum over steps of the number of confirmed tracks
    purity: Array  #: sum over the non-false tracks of their purity
    breaks: IntArray  #: a truth's track ends, and the truth is later assigned another track
    truth_switches: IntArray  #: changes of a truth's assigned track ID (breaks included)
    id_switches: IntArray  #: changes of a track's assigned truth ID
    sq_error: Array  #: sum over assigned pairs of ``|x_track - x_truth|^2``


# ---------------------------------------------------------------------------------------------
# input
# ---------------------------------------------------------------------------------------------


def frames(
    points: Sequence[ArrayLike], ids: Sequence[ArrayLike] | None = None, dim: int | None = None
) -> Frames:
    """``Frames`` from per-step lists: ``points[s]`` is ``(n_s, d)`` (an empty step may be
    ``[]``), ``ids[s]`` is ``(n_s,)``. ``dim`` is needed only if every step is empty."""
    arrs = [np.asarray(p, dtype=float) for p in points]
    if dim is None:
        dims = {a.shape[-1] for a in arrs if a.size}
        if len(dims) > 1:
            raise ValueError(f"points: steps have dimensions {sorted(dims)}; expected one")
        dim = dims.pop() if dims else 1
    arrs = [a.reshape(0, dim) if a.size == 0 else a for a in arrs]
    for s, a in enumerate(arrs):
        if a.ndim != 2 or a.shape[1] != dim:
            raise ValueError(f"points[{s}] has shape {a.shape}; expected (n, {dim})")
    offsets = np.concatenate([[0], np.cumsum([len(a) for a in arrs], dtype=np.int64)])
    x = np.concatenate(arrs) if arrs else np.empty((0, dim))
    idv = None
    if ids is not None:
        if len(ids) != len(arrs):
            raise ValueError(f"ids has {len(ids)} steps; expected {len(arrs)} like points")
        idl = [np.asarray(i, dtype=np.int64).reshape(-1) for i in ids]
        idv = np.concatenate(idl) if idl else np.empty(0, np.int64)
    return _check_frames("frames", Frames(offsets, x, idv))


def _check_frames(name: str, f: Frames, need_ids: bool = False) -> Frames:
    offsets = np.asarray(f.offsets)
    x = np.asarray(f.x, dtype=float)
    if offsets.ndim != 1 or offsets.size < 1 or not np.issubdtype(offsets.dtype, np.integer):
        raise ValueError(
            f"{name}.offsets has shape {offsets.shape} and dtype {offsets.dtype}; "
            "expected an integer array (S + 1,)"
        )
    offsets = offsets.astype(np.int64)
    if x.ndim != 2:
        raise ValueError(f"{name}.x has shape {x.shape}; expected (N, d)")
    if offsets[0] != 0 or offsets[-1] != len(x) or np.any(np.diff(offsets) < 0):
        raise ValueError(
            f"{name}.offsets runs {offsets[0]}..{offsets[-1]}; expected non-decreasing "
            f"from 0 to len(x) = {len(x)}"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}.x has non-finite values; expected finite points")
    ids = f.ids
    if ids is not None:
        ids = np.asarray(ids)
        if ids.shape != (len(x),) or not np.issubdtype(ids.dtype, np.integer):
            raise ValueError(
                f"{name}.ids has shape {ids.shape} and dtype {ids.dtype}; "
                f"expected integers ({len(x)},)"
            )
        ids = ids.astype(np.int64)
    elif need_ids:
        raise ValueError(f"{name}.ids is None; expected integer IDs ({len(x)},)")
    return Frames(offsets, x, ids)


def checked_frames(name: str, f: Frames, need_ids: bool = False) -> Frames:
    """``f`` with int64 offsets and IDs, float points, after checking its shape (errors name
    the argument ``name``); ``need_ids``: IDs are required."""
    return _check_frames(name, f, need_ids)


def _check_params(c: float, p: float) -> tuple[float, float]:
    c, p = float(c), float(p)
    if not (c > 0 and math.isfinite(c)):
        raise ValueError(f"c = {c!r}; expected a finite cut-off c > 0")
    if not (p >= 1 and math.isfinite(p)):
        raise ValueError(f"p = {p!r}; expected an order 1 <= p < inf")
    return c, p


def _check_pair(X: Frames, Y: Frames, nx: str, ny: str) -> None:
    if X.n_steps != Y.n_steps:
        raise ValueError(
            f"{nx} has {X.n_steps} steps and {ny} {Y.n_steps}; expected the same number"
        )
    if X.x.shape[1] != Y.x.shape[1]:
        raise ValueError(
            f"{nx}.x has dimension {X.x.shape[1]} and {ny}.x {Y.x.shape[1]}; expected the same"
        )


def _pow(d2: Array, p: float) -> Array:
    """d^p from d^2; p = 1 and 2 take correctly rounded paths (sqrt, identity)."""
    if p == 2.0:
        return d2
    if p == 1.0:
        return np.sqrt(d2)
    return d2 ** (p / 2)


# ---------------------------------------------------------------------------------------------
# the assignment kernel
# ---------------------------------------------------------------------------------------------


def _cum0(a: IntArray) -> IntArray:
    """Exclusive cumulative sum: where each block starts."""
    return np.cumsum(a) - a


def _sqdist(xc: Array, yc: Array, I: IntArray | slice, J: IntArray | slice) -> Array:
    """|x_i - y_j|^2 coordinate by coordinate, added left to right: the same rounding for a
    pair whichever pass (broadcast or gathered) computes it."""
    d2 = None
    for k in range(xc.shape[0]):
        t = xc[k][I] - yc[k][J]
        t = t * t
        d2 = t if d2 is None else d2 + t
    return d2


def _pairs_small(
    X: Frames, Y: Frames, xc: Array, yc: Array, steps: IntArray, c2: float
) -> tuple[IntArray, IntArray, Array]:
    """All (i, j, d^2) with d^2 < c^2, i a row of X and j of Y in the same step, over the
    given steps, gathered in one vectorised pass; rows are global."""
    n, m = X.sizes[steps], Y.sizes[steps]
    xrow = np.repeat(X.offsets[steps] - _cum0(n), n) + np.arange(n.sum())
    cnt = np.repeat(m, n)  # candidates per X row
    I = np.repeat(xrow, cnt)
    J = np.repeat(np.repeat(Y.offsets[steps], n), cnt) + (
        np.arange(cnt.sum()) - np.repeat(_cum0(cnt), cnt)
    )
    d2 = _sqdist(xc, yc, I, J)
    keep = d2 < c2
    return I[keep], J[keep], d2[keep]


def _step_big(
    X: Frames, Y: Frames, xc: Array, yc: Array, s: int, c: float, p: float
) -> tuple[IntArray, IntArray, Array]:
    """Assigned pairs (rows, rows, d^p) of one large step, from its broadcast distance
    matrix: one linear_sum_assignment on the rows and columns that have an edge when the
    edges are dense among them, else component by component (``_solve``)."""
    i0, i1, j0, j1 = X.offsets[s], X.offsets[s + 1], Y.offsets[s], Y.offsets[s + 1]
    d2 = _sqdist(xc[:, i0:i1, None], yc[:, None, j0:j1], slice(None), slice(None))
    edge = d2 < c * c
    ri, rj = np.flatnonzero(edge.any(axis=1)), np.flatnonzero(edge.any(axis=0))
    E = edge[np.ix_(ri, rj)]
    n_edges = int(E.sum())
    if n_edges < _DENSE * E.size:
        li, lj = np.nonzero(edge)
        return _solve(i0 + li, j0 + lj, _pow(d2[li, lj], p), c**p)
    M = np.where(E, _pow(d2[np.ix_(ri, rj)], p), c**p)
    r, k = linear_sum_assignment(M)
    ok = E[r, k]
    r, k = r[ok], k[ok]
    return i0 + ri[r], j0 + rj[k], M[r, k]


def _components(u: IntArray, v: IntArray, n: int) -> tuple[int, IntArray]:
    """Connected components of the graph with edges (u, v) on n nodes: (count, labels).

    Union by the smaller root and full path compression, in whole-array passes: cheaper than
    building a scipy.sparse graph when the problem is small (one step), and no slower when
    large. Pathological graphs (many rounds) go to scipy's connected_components."""
    lab = np.arange(n)
    for _ in range(64):
        lu, lv = lab[u], lab[v]
        if np.array_equal(lu, lv):
            roots, lab = np.unique(lab, return_inverse=True)
            return roots.size, lab
        m = np.minimum(lu, lv)
        np.minimum.at(lab, lu, m)  # hook each root under the smaller root it touches
        np.minimum.at(lab, lv, m)
        while True:
            nxt = lab[lab]
            if np.array_equal(nxt, lab):
                break
            lab = nxt
    g = coo_matrix((np.ones(u.size, np.int8), (u, v)), shape=(n, n))
    return connected_components(g, directed=False)


def _ranks(lab: IntArray, counts: IntArray) -> tuple[IntArray, IntArray]:
    """Rank of each node within its component, and the nodes ordered by component."""
    o = np.argsort(lab, kind="stable")
    rank = np.empty(lab.size, np.int64)
    rank[o] = np.arange(lab.size) - _cum0(counts)[lab[o]]
    return rank, o


def _solve(
    I: IntArray, J: IntArray, cost: Array, cp: float
) -> tuple[IntArray, IntArray, Array]:
    """Optimal partial assignment on the edges (I, J, cost < cp) of one or more steps.

    Minimises the sum over assigned edges of (cost - cp), i.e. the GOSPA/OSPA problem,
    component by component of the bipartite edge graph."""
    if I.size == 0:
        return I, J, cost
    ui, li = np.unique(I, return_inverse=True)
    uj, lj = np.unique(J, return_inverse=True)
    a, b = ui.size, uj.size
    ncomp, lab = _components(li, a + lj, a + b)
    la, lb = lab[:a], lab[a:]
    na = np.bincount(la, minlength=ncomp)
    nb = np.bincount(lb, minlength=ncomp)
    comp = la[li]
    star = (na[comp] == 1) | (nb[comp] == 1)

    out_i, out_j, out_c = [], [], []
    # one truth or one estimate in the component: its cheapest edge (lowest index on ties)
    e = np.flatnonzero(star)
    if e.size:
        o = e[np.lexsort((cost[e], comp[e]))]
        o = o[np.r_[True, comp[o[1:]] != comp[o[:-1]]]]
        out_i.append(I[o])
        out_j.append(J[o])
        out_c.append(cost[o])
    # the rest, grouped by shape (a, b): small shapes by enumerating every assignment of the
    # smaller side at once for the whole group, larger ones by linear_sum_assignment on each
    # component's dense matrix (non-edges at c^p in both)
    e = np.flatnonzero(~star)
    if e.size:
        ra, oa = _ranks(la, na)
        rb, ob = _ranks(lb, nb)
        sa, sb = _cum0(na), _cum0(nb)
        shape = na.astype(np.int64) * (nb.max() + 1) + nb
        e = e[np.lexsort((comp[e], shape[comp[e]]))]  # by shape, then component
        ce = comp[e]
        bounds = np.flatnonzero(np.r_[True, ce[1:] != ce[:-1], True])
        qs = ce[bounds[:-1]]  # components in this order
        sq = shape[qs]
        gb = np.flatnonzero(np.r_[True, sq[1:] != sq[:-1], True])
        for g0, g1 in zip(gb[:-1].tolist(), gb[1:].tolist(), strict=True):
            q = qs[g0:g1]
            A, B = int(na[q[0]]), int(nb[q[0]])
            el = e[bounds[g0] : bounds[g1]]  # this group's edges, by component
            g = np.repeat(np.arange(q.size), np.diff(bounds[g0 : g1 + 1]))
            T = np.full((q.size, A, B), cp)
            T[g, ra[li[el]], rb[lj[el]]] = cost[el]
            E = np.zeros(T.shape, bool)
            E[g, ra[li[el]], rb[lj[el]]] = True
            P = _perms(min(A, B), max(A, B))
            if P is not None:
                if A <= B:
                    tot = T[:, np.arange(A), P].sum(axis=-1)  # (G, n_perms)
                    r = np.broadcast_to(np.arange(A), (q.size, A))
                    k = P[np.argmin(tot, axis=1)]
                else:
                    tot = T[:, P, np.arange(B)].sum(axis=-1)
                    k = np.broadcast_to(np.arange(B), (q.size, B))
                    r = P[np.argmin(tot, axis=1)]
                gg = np.broadcast_to(np.arange(q.size)[:, None], r.shape)
                ok = E[gg, r, k]
                gg, r, k = gg[ok], r[ok], k[ok]
                out_i.append(ui[oa[sa[q[gg]] + r]])
                out_j.append(uj[ob[sb[q[gg]] + k]])
                out_c.append(T[gg, r, k])
                continue
            for t in range(q.size):
                r, k = linear_sum_assignment(T[t])
                ok = E[t, r, k]
                r, k = r[ok], k[ok]
                out_i.append(ui[oa[sa[q[t]] + r]])
                out_j.append(uj[ob[sb[q[t]] + k]])
                out_c.append(T[t, r, k])
    return np.concatenate(out_i), np.concatenate(out_j), np.concatenate(out_c)


_MAX_PERMS = 720  # enumerate assignments up to 6!/0! (6 x 6, 3 x 10, ...)


@cache
def _perms(a: int, b: int) -> IntArray | None:
    """All injective maps of a rows into b >= a columns, ``(b!/(b-a)!, a)``; None if many."""
    count = math.perm(b, a)
    if count > _MAX_PERMS:
        return None
    P = np.array(list(itertools.permutations(range(b), a)), np.int64).reshape(count, a)
    P.flags.writeable = False
    return P


_BIG = 4096  # a step with at least this many candidate pairs gets its own broadcast pass
_DENSE = 0.05  # above this fraction of edges, one assignment beats splitting components


def _assign(X: Frames, Y: Frames, c: float, p: float) -> tuple[IntArray, IntArray, Array]:
    """Assigned pairs (rows of X, rows of Y, d^p) over all steps, sorted by X row.

    Each step's pairs and costs are computed by the same arithmetic whichever other steps
    are in the batch, so each step's result is independent of the batch."""
    cp, c2 = c**p, c * c
    xc, yc = np.ascontiguousarray(X.x.T), np.ascontiguousarray(Y.x.T)
    work = X.sizes * Y.sizes
    Is, Js, Cs = [], [], []

    def solve(I: IntArray, J: IntArray, d2: Array) -> None:
        I, J, cost = _solve(I, J, _pow(d2, p), cp)
        Is.append(I)
        Js.append(J)
        Cs.append(cost)

    small = np.flatnonzero((work > 0) & (work < _BIG))
    if small.size:
        # chunks of small steps with about _PAIR_CHUNK candidate pairs each
        chunk = np.cumsum(work[small]) // _PAIR_CHUNK
        cuts = np.flatnonzero(np.r_[True, chunk[1:] != chunk[:-1], True])
        for lo, hi in zip(cuts[:-1].tolist(), cuts[1:].tolist(), strict=True):
            solve(*_pairs_small(X, Y, xc, yc, small[lo:hi], c2))
    for s in np.flatnonzero(work >= _BIG).tolist():
        I, J, cost = _step_big(X, Y, xc, yc, s, c, p)
        Is.append(I)
        Js.append(J)
        Cs.append(cost)
    if not Is:
        return np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)
    I, J, C = np.concatenate(Is), np.concatenate(Js), np.concatenate(Cs)
    o = np.argsort(I, kind="stable")  # per-step sums then add in a fixed (row) order
    return I[o], J[o], C[o]


def assign(
    truth: Frames, estimates: Frames, c: float, p: float = 2.0
) -> tuple[IntArray, IntArray]:
    """The optimal GOSPA/OSPA assignment of every step: rows ``(i, j)`` of ``truth.x`` and
    ``estimates.x`` paired (same step, ``|x_i - y_j| < c``), minimising
    ``sum d(x_i, y_j)^p + c^p/2 (unassigned points)``; sorted by ``i``."""
    c, p = _check_params(c, p)
    X = _check_frames("truth", truth)
    Y = _check_frames("estimates", estimates)
    _check_pair(X, Y, "truth", "estimates")
    I, J, _ = _assign(X, Y, c, p)
    return I, J


def checked_assignment(
    assignment: tuple[ArrayLike, ArrayLike], truth: Frames, estimates: Frames
) -> tuple[IntArray, IntArray]:
    """The rows ``(i, j)`` of an assignment of ``truth`` to ``estimates`` (as ``assign``
    returns it) as int64 arrays sorted by ``i``, after checking that they are rows of the two
    in the same step (the sort makes the per-step sums that use them add in ``assign``'s
    order, so that a result is the same to the bit)."""
    if len(assignment) != 2:
        raise ValueError(f"assignment has {len(assignment)} parts; expected the rows (i, j)")
    I, J = (np.asarray(a) for a in assignment)
    if I.ndim != 1 or I.shape != J.shape or not all(
            np.issubdtype(a.dtype, np.integer) or a.size == 0 for a in (I, J)):
        raise ValueError(f"assignment rows have shapes {I.shape} and {J.shape}; expected "
                         "integers (K,) each")
    I, J = I.astype(np.int64), J.astype(np.int64)
    xo, yo = np.asarray(truth.offsets), np.asarray(estimates.offsets)
    if I.size and (I.min() < 0 or I.max() >= xo[-1] or J.min() < 0 or J.max() >= yo[-1]):
        raise ValueError(f"assignment rows run outside the truth's {xo[-1]} and the "
                         f"estimates' {yo[-1]} rows; expected rows of both")
    if np.any(np.searchsorted(xo, I, "right") != np.searchsorted(yo, J, "right")):
        raise ValueError("assignment pairs rows of different steps; expected the rows that "
                         "assign(truth, estimates, c, p) returned")
    o = np.argsort(I, kind="stable")
    return I[o], J[o]


def pairs_within(truth: Frames, estimates: Frames, c: float) -> tuple[IntArray, IntArray, Array]:
    """Every pair of rows ``(i, j)`` of ``truth.x`` and ``estimates.x`` in the same step with
    ``|x_i - y_j| < c``, and ``|x_i - y_j|^2``; sorted by ``i``, then ``j``. Small steps in
    vectorised passes of about ``_PAIR_CHUNK`` candidate pairs, a large one by broadcasting
    (as ``assign``)."""
    c, _ = _check_params(c, 1.0)
    X = _check_frames("truth", truth)
    Y = _check_frames("estimates", estimates)
    _check_pair(X, Y, "truth", "estimates")
    xc, yc = np.ascontiguousarray(X.x.T), np.ascontiguousarray(Y.x.T)
    work = X.sizes * Y.sizes
    small = np.flatnonzero((work > 0) & (work < _BIG))
    chunk = np.cumsum(work[small]) // _PAIR_CHUNK
    cuts = np.flatnonzero(np.r_[True, chunk[1:] != chunk[:-1], True]) if small.size else []
    parts = [_pairs_small(X, Y, xc, yc, small[lo:hi], c * c)
             for lo, hi in zip(cuts[:-1], cuts[1:], strict=True)]
    big = np.flatnonzero(work >= _BIG)
    for s in big.tolist():
        i0, j0 = X.offsets[s], Y.offsets[s]
        d2 = _sqdist(xc[:, i0:X.offsets[s + 1], None], yc[:, None, j0:Y.offsets[s + 1]],
                     slice(None), slice(None))
        li, lj = np.nonzero(d2 < c * c)
        parts.append((i0 + li, j0 + lj, d2[li, lj]))
    if not parts:
        return np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)
    I, J, D = (np.concatenate(a) for a in zip(*parts, strict=True))
    if small.size and big.size:  # large steps' pairs go after the small ones'
        o = np.argsort(I, kind="stable")  # each part is sorted by (i, j) already
        I, J, D = I[o], J[o], D[o]
    return I, J, D


def solve_partial(
    I: ArrayLike, J: ArrayLike, cost: ArrayLike, cp: float
) -> tuple[IntArray, IntArray, Array]:
    """Optimal one-to-one partial assignment on the edges ``(I[e], J[e])`` (integer labels of
    the two sides; any values) with ``cost[e] < cp``: minimises ``sum (cost - cp)`` over the
    assigned edges, component by component of the edge graph (as ``assign`` does). With
    ``cp`` above ``min(a, b) max(cost)`` in every component of a rows and b columns it is the
    maximum-cardinality assignment of least total cost. Returns the assigned edges' labels
    and costs."""
    I, J = np.asarray(I, np.int64), np.asarray(J, np.int64)
    cost = np.asarray(cost, float)
    if not (I.shape == J.shape == cost.shape and I.ndim == 1):
        raise ValueError(f"I, J and cost have shapes {I.shape}, {J.shape}, {cost.shape}; "
                         "expected one (E,)")
    if cost.size and not np.all(cost < cp):
        raise ValueError(f"cost has values >= cp = {cp!r}; expected every edge below cp")
    return _solve(I, J, cost, float(cp))


def _core(
    truth: Frames, estimates: Frames, c: float, p: float,
    assignment: tuple[ArrayLike, ArrayLike] | None = None,
) -> tuple[IntArray, IntArray, Array, IntArray, float, float]:
    c, p = _check_params(c, p)
    X = _check_frames("truth", truth)
    Y = _check_frames("estimates", estimates)
    _check_pair(X, Y, "truth", "estimates")
    if assignment is None:
        I, J, C = _assign(X, Y, c, p)
    else:  # d^p by the kernel's own arithmetic: the same bits as the costs it returns
        I, J = checked_assignment(assignment, X, Y)
        C = _pow(_sqdist(np.ascontiguousarray(X.x.T), np.ascontiguousarray(Y.x.T), I, J), p)
    S = X.n_steps
    step = np.repeat(np.arange(S), X.sizes)[I]
    L = np.bincount(step, weights=C, minlength=S).astype(float)  # float even when empty
    k = np.bincount(step, minlength=S).astype(np.int64)
    return X.sizes, Y.sizes, L, k, c, p


def gospa_steps(truth: Frames, estimates: Frames, c: float, p: float = 2.0, *,
                assignment: tuple[ArrayLike, ArrayLike] | None = None) -> SetDistance:
    """GOSPA (alpha = 2) of every step, ``(S,)`` arrays:
    ``GOSPA^p = L + c^p/2 (n - k) + c^p/2 (m - k)`` (localisation, missed, false).

    ``assignment``: the rows ``(i, j)`` that ``assign(truth, estimates, c, p)`` returned,
    when the caller has them (saves solving it again; the result is the same to the bit)."""
    n, m, L, k, c, p = _core(truth, estimates, c, p, assignment)
    half = c**p / 2
    missed = half * (n - k)
    false = half * (m - k)
    return SetDistance((L + missed + false) ** (1 / p), L, missed, false, k)


def ospa_steps(truth: Frames, estimates: Frames, c: float, p: float = 1.0) -> SetDistance:
    """OSPA of every step, ``(S,)`` arrays: with A the optimal sum of min(d, c)^p,
    ``OSPA^p = (A + c^p |m - n|) / max(n, m)``; 0 when both sets are empty."""
    n, m, L, k, c, p = _core(truth, estimates, c, p)
    cp = c**p
    big = np.maximum(n, m)
    den = np.maximum(big, 1)  # both empty: every part is 0
    loc = (L + cp * (np.minimum(n, m) - k)) / den
    missed = cp * np.maximum(n - m, 0) / den
    false = cp * np.maximum(m - n, 0) / den
    return SetDistance((loc + missed + false) ** (1 / p), loc, missed, false, k)


def _one(x: ArrayLike, y: ArrayLike) -> tuple[Frames, Frames]:
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    dim = x.shape[-1] if x.size else (y.shape[-1] if y.size else 1)
    x = x.reshape(-1, dim) if x.size == 0 else x
    y = y.reshape(-1, dim) if y.size == 0 else y
    for name, a in (("x", x), ("y", y)):
        if a.ndim != 2:
            raise ValueError(f"{name} has shape {a.shape}; expected (n, d)")
    return (
        Frames(np.array([0, len(x)]), x),
        Frames(np.array([0, len(y)]), y),
    )


def _scalar(r: SetDistance) -> SetDistance:
    return SetDistance(*(float(v[0]) for v in r[:4]), int(r.assigned[0]))


def gospa(x: ArrayLike, y: ArrayLike, c: float, p: float = 2.0) -> SetDistance:
    """GOSPA (alpha = 2) between truth points ``x (n, d)`` and estimates ``y (m, d)``."""
    X, Y = _one(x, y)
    return _scalar(gospa_steps(X, Y, c, p))


def ospa(x: ArrayLike, y: ArrayLike, c: float, p: float = 1.0) -> SetDistance:
    """OSPA between point sets ``x (n, d)`` and ``y (m, d)`` (symmetric; ``missed`` counts
    the points of x left over, ``false`` those of y)."""
    X, Y = _one(x, y)
    return _scalar(ospa_steps(X, Y, c, p))


# ---------------------------------------------------------------------------------------------
# track-level counts
# ---------------------------------------------------------------------------------------------


def _keys(run: IntArray, ids: IntArray) -> tuple[IntArray, IntArray]:
    """Index of (run, id) among the sorted distinct pairs, and the run of each distinct key."""
    if run.size == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    o = np.lexsort((ids, run))
    r, i = run[o], ids[o]
    new = np.r_[True, (r[1:] != r[:-1]) | (i[1:] != i[:-1])]
    key = np.empty(run.size, np.int64)
    key[o] = np.cumsum(new) - 1
    return key, r[new]


def _changes(owner: IntArray, partner: IntArray, step: IntArray) -> tuple[IntArray, IntArray]:
    """Positions (in a (owner, step) ordering) where an owner's partner differs from its
    previous one: returns (order, mask of changes over order[1:])."""
    o = np.lexsort((step, owner))
    same = owner[o[1:]] == owner[o[:-1]]
    return o, same & (partner[o[1:]] != partner[o[:-1]])


def track_counts(
    truth: Frames,
    tracks: Frames,
    c: float,
    *,
    p: float = 2.0,
    run_offsets: ArrayLike | None = None,
    times: ArrayLike | None = None,
    min_assigned: float = 0.5,
    within: float = math.inf,
    assignment: tuple[ArrayLike, ArrayLike] | None = None,
) -> TrackCounts:
    """Track-level counts per run, from truth and confirmed tracks with integer IDs.

    Per step s, truths (IDs, positions ``truth.x``) are assigned one-to-one to confirmed
    tracks (IDs, positions ``tracks.x``) by the optimal GOSPA assignment with cut-off ``c``
    and order ``p`` (``assign``): a pair is assigned only if ``|x_track - x_truth| < c``.
    Steps ``run_offsets[r]:run_offsets[r + 1]`` form run r (default: one run); IDs are local
    to a run. ``times (S,)`` gives each step's time (default: its step index). Then, per run:

    * a truth's *birth* is the first step it is present; it is *confirmed* if it is assigned
      at some step, and its confirmation delay is t(first assigned step) - t(birth)
      (MATLAB ``trackAssignmentMetrics``: establishment length, but in time);
      ``confirmed_within`` counts the truths whose delay is at most ``within``;
    * a track's *life* is the number of steps it is present; it is *false* if it is assigned
      on fewer than ``min_assigned`` (default 1/2) of them, i.e. unassigned for most of its
      life; its *purity* is the number of steps assigned to its dominant truth (the truth it
      is assigned to most often) over its life, summed over the tracks that are not false;
    * along each truth's assigned steps, a *truth switch* is a change of its track ID from one
      assigned step to the next (the CLEAR-MOT mismatch); it is a *break* when the previous
      track is no longer present at the step of the change (the track was lost and the truth
      picked up again under a new ID; MATLAB's break count also counts a truth merely losing
      its track); Stone Soup's SIAP ID changes are the analogue of truth switches (SIAP
      associates by distance, several tracks per truth; here one-to-one per step);
    * along each track's assigned steps, an *ID switch* is a change of its truth ID (the track
      ID moving from one truth to another; MATLAB's swap count);
    * ``sq_error`` sums ``|x_track - x_truth|^2`` over assigned pairs (RMSE = sqrt(sq_error /
      assigned_steps)), and ``assigned_steps / truth_steps`` is SIAP's completeness.

    ``assignment``: the rows ``(i, j)`` that ``assign(truth, tracks, c, p)`` returned, when the
    caller has them (saves solving it again).
    """
    X, Y, c, p = _check_counts(truth, tracks, c, p, min_assigned, within)
    S = X.n_steps
    ro = _run_offsets(run_offsets, S)
    R = ro.size - 1
    t = _step_times(times, ro, S)
    run_of_step = np.repeat(np.arange(R), np.diff(ro))
    xs = np.repeat(np.arange(S), X.sizes)  # step of each truth row
    ys = np.repeat(np.arange(S), Y.sizes)
    _check_unique_ids("truth", X, xs)
    _check_unique_ids("tracks", Y, ys)
    tk_, truth_run = _keys(run_of_step[xs], X.ids)  # truth key of each truth row
    jk_, track_run = _keys(run_of_step[ys], Y.ids)

    I, J = (_assign(X, Y, c, p)[:2] if assignment is None
            else checked_assignment(assignment, X, Y))
    pstep, pt, pj = xs[I], tk_[I], jk_[J]
    prun = run_of_step[pstep]

    def per_run(idx: IntArray, w: Array | None = None) -> NDArray:
        out = np.bincount(idx, weights=w, minlength=R)
        return out.astype(np.int64 if w is None else float)  # (bincount of nothing is int)

    conf, delay = _confirmation(tk_, xs, pt, pstep, truth_run.size, S, t)
    life, last, false_, purity = _track_lives(jk_, ys, pt, pj, track_run.size, min_assigned)
    good = ~false_
    new, brk, id_new = _switches(pt, pj, pstep, last)
    diff = X.x[I] - Y.x[J]
    return TrackCounts(
        truths=per_run(truth_run),
        truths_confirmed=per_run(truth_run[conf]),
        confirmed_within=per_run(truth_run[conf][delay <= within]),
        confirm_delay=per_run(truth_run[conf], delay),
        truth_steps=per_run(run_of_step[xs]),
        assigned_steps=per_run(prun),
        tracks=per_run(track_run),
        false_tracks=per_run(track_run[false_]),
        track_steps=per_run(run_of_step[ys]),
        purity=per_run(track_run[good], purity[good]),
        breaks=per_run(prun[new][brk]),
        truth_switches=per_run(prun[new]),
        id_switches=per_run(prun[id_new]),
        sq_error=per_run(prun, (diff * diff).sum(axis=1)),
    )


def _check_counts(truth: Frames, tracks: Frames, c: float, p: float, min_assigned: float,
                  within: float) -> tuple[Frames, Frames, float, float]:
    """``track_counts``' arguments checked: the frames, ``c`` and ``p``."""
    c, p = _check_params(c, p)
    if not 0 < min_assigned <= 1:
        raise ValueError(f"min_assigned = {min_assigned!r}; expected a fraction in (0, 1]")
    if not within >= 0:
        raise ValueError(f"within = {within!r}; expected a delay >= 0")
    X = _check_frames("truth", truth, need_ids=True)
    Y = _check_frames("tracks", tracks, need_ids=True)
    _check_pair(X, Y, "truth", "tracks")
    return X, Y, c, p


def _check_unique_ids(name: str, f: Frames, steps: IntArray) -> None:
    k, _ = _keys(steps, f.ids)
    if k.size and k.max() + 1 != k.size:
        raise ValueError(f"{name}.ids repeat an ID within a step; expected unique IDs")


def _switches(pt: IntArray, pj: IntArray, pstep: IntArray,
              last: IntArray) -> tuple[IntArray, NDArray, IntArray]:
    """Along each truth's assigned pairs (truth keys ``pt``, track keys ``pj`` at steps
    ``pstep``): the pairs where its track changes (truth switches) and, of those, the breaks
    (the previous track's ``last`` step is before the change); along each track's: the
    pairs where its truth changes (ID switches)."""
    o, ch = _changes(pt, pj, pstep)
    new = o[1:][ch]
    prev = o[:-1][ch]
    brk = last[pj[prev]] < pstep[new]
    o2, ch2 = _changes(pj, pt, pstep)
    return new, brk, o2[1:][ch2]


def _run_offsets(run_offsets: ArrayLike | None, S: int) -> IntArray:
    """``track_counts``' ``run_offsets`` checked (default: one run of the ``S`` steps)."""
    if run_offsets is None:
        return np.array([0, S], np.int64)
    ro = np.asarray(run_offsets)
    if (
        ro.ndim != 1
        or ro.size < 2
        or not np.issubdtype(ro.dtype, np.integer)
        or ro[0] != 0
        or ro[-1] != S
        or np.any(np.diff(ro) < 0)
    ):
        raise ValueError(
            f"run_offsets = {ro!r}; expected integers (R + 1,) non-decreasing from 0 to "
            f"the number of steps {S}"
        )
    return ro.astype(np.int64)


def _step_times(times: ArrayLike | None, ro: IntArray, S: int) -> Array:
    """``track_counts``' ``times`` checked (default: each step's index within its run)."""
    if times is None:
        return (np.arange(S) - np.repeat(ro[:-1], np.diff(ro))).astype(float)
    t = np.asarray(times, dtype=float)
    if t.shape != (S,):
        raise ValueError(f"times has shape {t.shape}; expected ({S},), one per step")
    return t


def _confirmation(tk_: IntArray, xs: IntArray, pt: IntArray, pstep: IntArray, nT: int,
                  S: int, t: Array) -> tuple[NDArray, Array]:
    """Per truth key: confirmed (assigned at some step) and, for those, the delay from its
    birth (its first row; rows are in step order) to its first assigned step."""
    birth = np.full(nT, S, np.int64)
    np.minimum.at(birth, tk_, xs)
    first = np.full(nT, S, np.int64)
    np.minimum.at(first, pt, pstep)
    conf = first < S
    return conf, t[first[conf]] - t[birth[conf]]


def _track_lives(jk_: IntArray, ys: IntArray, pt: IntArray, pj: IntArray, nJ: int,
                 min_assigned: float) -> tuple[IntArray, IntArray, NDArray, Array]:
    """Per track key: life (steps present), last step, false (assigned on fewer than
    ``min_assigned`` of its life) and purity (steps on its dominant truth over its life)."""
    life = np.bincount(jk_, minlength=nJ)
    last = np.full(nJ, -1, np.int64)
    np.maximum.at(last, jk_, ys)
    on = np.bincount(pj, minlength=nJ)
    false_ = on < min_assigned * life
    tracks, _, n = dominant_truths(pj, pt)
    dom = np.zeros(nJ, np.int64)
    dom[tracks] = n
    return life, last, false_, dom / np.maximum(life, 1)


def dominant_truths(track: ArrayLike, truth: ArrayLike) -> tuple[IntArray, IntArray, IntArray]:
    """Each track's dominant truth over assigned pairs: pair e is track ``track[e]`` assigned
    to truth ``truth[e]`` at one step (IDs or keys, integers), and a track's dominant truth
    is the one it was assigned to most often, the lowest on a tie. Returns the tracks that
    have a pair (ascending), their dominant truths and the number of pairs with it (a
    track's purity is that number over its life)."""
    trk, tru = np.asarray(track), np.asarray(truth)
    if trk.ndim != 1 or trk.shape != tru.shape or not all(
            np.issubdtype(a.dtype, np.integer) or a.size == 0 for a in (trk, tru)):
        raise ValueError(f"track and truth have shapes {trk.shape} and {tru.shape}; expected "
                         "integers (E,) each")
    if trk.size == 0:
        return (np.empty(0, np.int64),) * 3
    o = np.lexsort((tru, trk))
    a, b = trk[o].astype(np.int64), tru[o].astype(np.int64)
    start = np.flatnonzero(np.r_[True, (a[1:] != a[:-1]) | (b[1:] != b[:-1])])
    n = np.diff(np.r_[start, a.size])
    a, b = a[start], b[start]  # the (track, truth) combinations, by track then truth
    q = np.lexsort((-n, a))  # stable: among equal counts the lower truth stays first
    first = q[np.r_[True, a[q[1:]] != a[q[:-1]]]]
    return a[first], b[first], n[first]


def track_summary(counts: TrackCounts) -> dict[str, float]:
    """Totals over runs (integers exactly, floats by ``math.fsum``, correctly rounded) and
    the rates built from them: ``completeness`` = assigned_steps / truth_steps,
    ``confirmed_fraction`` = truths_confirmed / truths, ``confirmed_within_fraction`` =
    confirmed_within / truths, ``mean_confirm_delay``,
    ``false_track_fraction`` = false_tracks / tracks, ``mean_purity`` (over non-false tracks),
    ``rmse`` = sqrt(sq_error / assigned_steps). A rate with a zero denominator is nan."""
    tot: dict[str, float] = {}
    for name, v in counts._asdict().items():
        v = np.asarray(v)
        tot[name] = math.fsum(v.tolist()) if v.dtype.kind == "f" else int(v.sum())

    def ratio(a: float, b: float) -> float:
        return a / b if b else math.nan

    tot["completeness"] = ratio(tot["assigned_steps"], tot["truth_steps"])
    tot["confirmed_fraction"] = ratio(tot["truths_confirmed"], tot["truths"])
    tot["confirmed_within_fraction"] = ratio(tot["confirmed_within"], tot["truths"])
    tot["mean_confirm_delay"] = ratio(tot["confirm_delay"], tot["truths_confirmed"])
    tot["false_track_fraction"] = ratio(tot["false_tracks"], tot["tracks"])
    tot["mean_purity"] = ratio(tot["purity"], tot["tracks"] - tot["false_tracks"])
    tot["rmse"] = math.sqrt(ratio(tot["sq_error"], tot["assigned_steps"]))
    return tot
