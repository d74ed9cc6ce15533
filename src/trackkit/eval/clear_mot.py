r"""Identity-aware tracking scores: CLEAR-MOT, the ID measures, GOSPA with its switching
penalty and a classification of ID switches by whether a radar could resolve the objects.

Input: the truth and the confirmed tracks as ``Frames`` with integer IDs, one step per scan
(``trackkit.eval.track_metrics``). A truth and a track can be matched at a step only if
``|x_track - x_truth| < c``.

* CLEAR-MOT (Bernardin & Stiefelhagen 2008), as py-motmetrics' ``MOTAccumulator`` computes
  it: at step k, every truth o keeps the track h it was last matched to (at any earlier step)
  if h is present and within c (when two truths claim one track, the lower truth ID keeps
  it); the rest are matched by the maximum-cardinality assignment of least total distance.
  A match of o to a track other than its last one is an ID switch (IDSW); unmatched truths
  are misses (FN), unmatched tracks false positives (FP). With GT the number of truth-steps,
  and MOTP in metres:

  .. math::

      \mathrm{MOTA} = 1 - \frac{\mathrm{FN} + \mathrm{FP} + \mathrm{IDSW}}{\mathrm{GT}},
      \qquad
      \mathrm{MOTP} = \frac{\sum_{\text{matches}} \lVert \mathbf{x}_{\text{track}}
          - \mathbf{x}_{\text{truth}} \rVert}{\text{number of matches}}

  A fragmentation is a truth going from matched to missed and being matched again later.
* ID measures (Ristani, Solera, Zou, Cucchiara & Tomasi 2016): truths and tracks are paired
  one-to-one over the whole run so that IDTP, the number of steps at which paired truth and
  track are within c, is largest; with P the number of track-steps:

  .. math::

      \mathrm{IDP} = \frac{\mathrm{IDTP}}{P}, \qquad
      \mathrm{IDR} = \frac{\mathrm{IDTP}}{\mathrm{GT}}, \qquad
      \mathrm{IDF1} = \frac{2\, \mathrm{IDTP}}{\mathrm{GT} + P}

* GOSPA with switching (Stone Soup's ``GOSPAMetric(c, p, switching_penalty=gamma)``): per
  step, the GOSPA assignment (``track_metrics.assign``); a truth's assignment changing from
  one track to another is a full switch, to or from no track a half switch (a truth counts
  only from its first assignment on). With :math:`s_k` the full switches plus half the half
  switches at step k:

  .. math::

      \mathrm{switching}_k = \gamma\, s_k^{1/p}, \qquad
      \mathrm{distance}_k = \bigl(\mathrm{GOSPA}_k^2 + \mathrm{switching}_k^2\bigr)^{1/2}

  (Stone Soup's combination; for p = 2 it is the trajectory GOSPA's switching cost of
  Garcia-Fernandez, Rahmathullah & Svensson 2020, gamma^2 per full switch inside GOSPA^2).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.eval.track_metrics import (
    Frames,
    assign,
    checked_assignment,
    checked_frames,
    pairs_within,
    solve_partial,
    track_counts,
    track_summary,
)

__all__ = [
    "ClearMot",
    "IdScores",
    "SwitchingGospa",
    "SwitchClasses",
    "clear_mot",
    "clear_mot_summary",
    "mota_steps",
    "id_scores",
    "gospa_switching",
    "classify_switches",
    "score_run",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]


class ClearMot(NamedTuple):
    """CLEAR-MOT counts per step, ``(S,)`` each, and the ID switch events (``clear_mot``)."""

    objects: IntArray  #: truths present (GT)
    predictions: IntArray  #: tracks present
    matches: IntArray  #: matched pairs, switches included
    misses: IntArray  #: FN
    false_positives: IntArray  #: FP
    switches: IntArray  #: IDSW
    transfers: IntArray  #: a track matched to another truth than before (py-motmetrics)
    fragmentations: IntArray  #: at the step a fragment's miss starts
    distance: Array  #: sum over the matches of ``|x_track - x_truth|`` (m)
    switch_step: IntArray  #: step of each ID switch, by step, then truth ID
    switch_truth: IntArray  #: truth ID of each ID switch
    transfer_step: IntArray  #: step of each transfer, by step, then truth ID
    transfer_truth: IntArray  #: the truth ID each transfer moves its track to


class IdScores(NamedTuple):
    """The ID measures of Ristani et al. (2016) over a run (``id_scores``)."""

    idtp: int
    idfp: int
    idfn: int
    idf1: float
    idp: float
    idr: float
    idtp_steps: IntArray  #: (S,) the IDTP of each step (paired truth and track within c)


class SwitchingGospa(NamedTuple):
    """GOSPA per step with Stone Soup's switching term, ``(S,)`` each (``gospa_switching``)."""

    distance: Array  #: (GOSPA^2 + switching^2)^(1/2)
    gospa: Array  #: GOSPA without the switching term
    localisation: Array  #: GOSPA's parts, p-th powers as in ``track_metrics.gospa_steps``
    missed: Array
    false: Array
    switches: Array  #: full switches plus half the half switches
    switching: Array  #: gamma switches^(1/p)


class SwitchClasses(NamedTuple):
    """ID switches by whether the radar can resolve the objects (``classify_switches``)."""

    total: int
    resolvable: int
    mask: NDArray[np.bool_]  #: per switch event: resolvable


def _keys(ids: IntArray) -> tuple[IntArray, int]:
    """Dense keys 0..n-1 in ascending ID order, and n. By sorting: numpy's hashed unique
    is slow on some integer patterns (steps x n + key among them)."""
    o = np.argsort(ids, kind="stable")
    new = np.r_[True, ids[o][1:] != ids[o][:-1]] if ids.size else np.zeros(0, bool)
    k = np.empty(ids.size, np.int64)
    k[o] = np.cumsum(new) - 1
    return k, int(new.sum())


def _checked(truth: Frames, tracks: Frames, c: float) -> tuple[Frames, Frames]:
    truth = checked_frames("truth", truth, need_ids=True)
    tracks = checked_frames("tracks", tracks, need_ids=True)
    if not (float(c) > 0 and math.isfinite(c)):
        raise ValueError(f"c = {c!r}; expected a finite distance threshold c > 0")
    if truth.n_steps != tracks.n_steps:
        raise ValueError(f"truth has {truth.n_steps} steps and tracks {tracks.n_steps}; "
                         "expected the same number")
    return truth, tracks


def _unique_per_step(name: str, keys: IntArray, steps: IntArray, n: int) -> None:
    k = np.sort(steps * max(n, 1) + keys)
    if np.any(k[1:] == k[:-1]):
        raise ValueError(f"{name}.ids repeat an ID within a step; expected unique IDs")


class _Run(NamedTuple):
    """A checked truth and tracks: each row's step, the dense ID keys and their counts."""

    X: Frames
    Y: Frames
    xs: IntArray
    tk: IntArray
    jk: IntArray
    nT: int
    nJ: int


def _run(truth: Frames, tracks: Frames, c: float) -> _Run:
    X, Y = _checked(truth, tracks, c)
    S = X.n_steps
    xs = np.repeat(np.arange(S), np.diff(X.offsets))
    ys = np.repeat(np.arange(S), np.diff(Y.offsets))
    tk, nT = _keys(np.asarray(X.ids, np.int64))
    jk, nJ = _keys(np.asarray(Y.ids, np.int64))
    _unique_per_step("truth", tk, xs, nT)
    _unique_per_step("tracks", jk, ys, nJ)
    return _Run(X, Y, xs, tk, jk, nT, nJ)


# --- CLEAR-MOT --------------------------------------------------------------------------------


def clear_mot(truth: Frames, tracks: Frames, c: float) -> ClearMot:
    """CLEAR-MOT counts of every step (module docstring), with distance threshold ``c``:
    truth and track are matched only if ``|x_track - x_truth| < c``."""
    r = _run(truth, tracks, c)
    return _clear_mot(r, pairs_within(r.X, r.Y, c), c)


def _clear_mot(r: _Run, pairs: tuple[IntArray, IntArray, Array], c: float) -> ClearMot:
    X, Y, xs, tk = r.X, r.Y, r.xs, r.tk
    S = X.n_steps
    I, J, d2 = pairs
    n, m = np.diff(X.offsets), np.diff(Y.offsets)
    # a cost above min(a, b) c makes the least-cost assignment one of maximum cardinality
    big = c * (1.0 + float(np.minimum(n, m).max(initial=0)))
    mi, md, sw, tr = _match(I, J, tk, r.jk, np.sqrt(d2), xs[I], S, r.nT, r.nJ, big)
    o = np.lexsort((tk[mi], xs[mi]))  # events by step, then truth ID
    mi, md, sw, tr = mi[o], md[o], sw[o], tr[o]
    ms, mt = xs[mi], tk[mi]
    matches = np.bincount(ms, minlength=S)
    matched = np.zeros(X.x.shape[0], bool)  # per truth row
    matched[mi] = True
    tid = np.zeros(r.nT, np.int64)
    tid[tk] = X.ids  # truth ID of each key
    return ClearMot(
        objects=n, predictions=m, matches=matches, misses=n - matches,
        false_positives=m - matches, switches=np.bincount(ms[sw], minlength=S),
        transfers=np.bincount(ms[tr], minlength=S),
        fragmentations=_fragmentations(tk, xs, matched, r.nT, S),
        distance=np.bincount(ms, weights=md, minlength=S).astype(float),
        switch_step=ms[sw], switch_truth=tid[mt[sw]], transfer_step=ms[tr],
        transfer_truth=tid[mt[tr]])


def _match(I: IntArray, J: IntArray, tk: IntArray, jk: IntArray, d: Array, es: IntArray,
           S: int, nT: int, nJ: int, big: float) -> tuple[IntArray, Array, NDArray[np.bool_],
                                                           NDArray[np.bool_]]:
    """The CLEAR-MOT matches, step by step (each step needs the last one's), from the edges
    (truth row ``I``, track row ``J``, distance ``d``, step ``es``, in step order) of the
    pairs within the threshold; ``tk``, ``jk`` are the rows' ID keys. Returns the matched
    truth rows, in step order, the distances, and whether each match is an ID switch (the
    truth's last track was another) and a transfer (the track's last truth matched by
    assignment rather than carried over was another: py-motmetrics' rule)."""
    eo = np.searchsorted(es, np.arange(S + 1))
    last = np.full(nT, -1, np.int64)  # the track each truth was last matched to
    owner = np.full(nJ, -1, np.int64)  # the truth each track was last given by assignment
    held_t, held_j = np.zeros(nT, bool), np.zeros(nJ, bool)
    out: list[tuple[NDArray, ...]] = []
    for s in np.flatnonzero(eo[1:] > eo[:-1]).tolist():
        a, b = eo[s], eo[s + 1]
        ts, js = tk[I[a:b]], jk[J[a:b]]
        keep = np.flatnonzero(last[ts] == js)
        if keep.size > 1:  # two truths last matched to one track: the lower truth ID keeps it
            o = keep[np.lexsort((ts[keep], js[keep]))]
            keep = o[np.r_[True, js[o[1:]] != js[o[:-1]]]]
        held_t[ts[keep]], held_j[js[keep]] = True, True
        rest = a + np.flatnonzero(~(held_t[ts] | held_j[js]))
        held_t[ts[keep]], held_j[js[keep]] = False, False
        no = np.zeros(keep.size, bool)
        out.append((I[a + keep], d[a + keep], no, no))
        if rest.size:  # rows are unique labels within a step
            ni, nj, nd = solve_partial(I[rest], J[rest], d[rest], big)
            nt, nj = tk[ni], jk[nj]
            sw = (last[nt] >= 0) & (last[nt] != nj)
            tr = (owner[nj] >= 0) & (owner[nj] != nt)
            out.append((ni, nd, sw, tr))
            last[nt], owner[nj] = nj, nt
    if not out:
        f = np.empty(0, bool)
        return np.empty(0, np.int64), np.empty(0), f, f
    mi, md, sw, tr = (np.concatenate(x) for x in zip(*out, strict=True))
    return mi.astype(np.int64), md, sw, tr


def _fragmentations(tk: IntArray, xs: IntArray, matched: NDArray[np.bool_], nT: int,
                    S: int) -> IntArray:
    """Per step: truths going from matched to missed there and matched again later."""
    o = np.argsort(tk, kind="stable")  # each truth's rows in step order
    t, m = tk[o], matched[o]
    last = np.full(nT, -1, np.int64)
    np.maximum.at(last, t[m], np.flatnonzero(m))
    q = np.arange(1, t.size)
    frag = (t[q] == t[q - 1]) & m[q - 1] & ~m[q] & (q < last[t[q]])
    return np.bincount(xs[o][q][frag], minlength=S)


def _ratio(a: float, b: float) -> float:
    return a / b if b else math.nan


def clear_mot_summary(cm: ClearMot) -> dict[str, float]:
    """Totals of ``clear_mot`` and ``mota``, ``motp`` (m); nan with no truth or no match."""
    tot = {k: int(np.sum(v)) for k, v in cm._asdict().items()
           if k not in ("distance", "switch_step", "switch_truth", "transfer_step",
                     "transfer_truth")}
    tot["mota"] = 1.0 - _ratio(tot["misses"] + tot["false_positives"] + tot["switches"],
                               tot["objects"])
    tot["motp"] = _ratio(math.fsum(cm.distance.tolist()), tot["matches"])
    return tot


def mota_steps(cm: ClearMot) -> Array:
    """MOTA of every step alone, ``(S,)``; nan at a step with no truth."""
    gt = cm.objects.astype(float)
    bad = (cm.misses + cm.false_positives + cm.switches).astype(float)
    return np.where(gt > 0, 1.0 - bad / np.maximum(gt, 1.0), np.nan)


# --- the ID measures --------------------------------------------------------------------------


def id_scores(truth: Frames, tracks: Frames, c: float) -> IdScores:
    """IDTP, IDFP, IDFN, IDF1, IDP and IDR (module docstring), threshold ``c``; the
    truth-to-track pairing maximises IDTP by one assignment over all pairs that meet."""
    r = _run(truth, tracks, c)
    return _id_scores(r, pairs_within(r.X, r.Y, c))


def _id_scores(r: _Run, pairs: tuple[IntArray, IntArray, Array]) -> IdScores:
    X, Y, xs, tk, jk, nJ = r.X, r.Y, r.xs, r.tk, r.jk, r.nJ
    I, J, _ = pairs
    combo = tk[I] * nJ + jk[J]
    o = np.argsort(combo, kind="stable")
    new = np.r_[True, combo[o][1:] != combo[o][:-1]] if combo.size else np.zeros(0, bool)
    u, n = combo[o][new], np.diff(np.r_[np.flatnonzero(new), combo.size])
    at, aj, cost = solve_partial(u // nJ, u % nJ, -n.astype(float), 0.0)
    pick = np.zeros(u.size, bool)
    pick[np.searchsorted(u, at * nJ + aj)] = True
    chosen = np.empty(combo.size, bool)
    chosen[o] = np.repeat(pick, n)
    idtp = int(round(-math.fsum(cost.tolist())))
    gt, pr = int(X.x.shape[0]), int(Y.x.shape[0])
    return IdScores(idtp=idtp, idfp=pr - idtp, idfn=gt - idtp,
                    idf1=_ratio(2 * idtp, gt + pr), idp=_ratio(idtp, pr), idr=_ratio(idtp, gt),
                    idtp_steps=np.bincount(xs[I][chosen], minlength=X.n_steps))


# --- GOSPA with switching ---------------------------------------------------------------------


def gospa_switching(truth: Frames, tracks: Frames, c: float, p: float = 2.0,
                    switching_penalty: float | None = None, *,
                    assignment: tuple[ArrayLike, ArrayLike] | None = None) -> SwitchingGospa:
    """GOSPA (alpha = 2, cut-off ``c``, order ``p``) of every step with Stone Soup's switching
    term (module docstring), penalty gamma = ``switching_penalty``, by default ``c``: at
    p = 2 a full switch then adds c^2 to GOSPA^2, as a missed object plus a false track do,
    and a half switch c^2/2, as either does.

    ``assignment``: the rows ``(i, j)`` that ``track_metrics.assign(truth, tracks, c, p)``
    returned, when the caller has them (saves solving it again; the result is the same to
    the bit)."""
    gamma = _penalty(c, switching_penalty)
    if not (p >= 1 and math.isfinite(p)):  # assign checks it too, but may not be called
        raise ValueError(f"p = {p!r}; expected an order 1 <= p < inf")
    r = _run(truth, tracks, c)
    ab = (assign(r.X, r.Y, c, p) if assignment is None
          else checked_assignment(assignment, r.X, r.Y))
    return _gospa_switching(r, ab, c, p, gamma)


def _gospa_switching(r: _Run, assignment: tuple[IntArray, IntArray], c: float, p: float,
                     gamma: float) -> SwitchingGospa:
    X, Y, xs = r.X, r.Y, r.xs
    S = X.n_steps
    I, J = assignment
    diff = X.x[I] - Y.x[J]
    d2 = (diff * diff).sum(axis=1)
    dp = d2 if p == 2 else np.sqrt(d2) if p == 1 else d2 ** (p / 2)
    loc = np.bincount(xs[I], weights=dp, minlength=S).astype(float)
    k = np.bincount(xs[I], minlength=S)
    half = c**p / 2
    missed, false = half * (np.diff(X.offsets) - k), half * (np.diff(Y.offsets) - k)
    g = (loc + missed + false) ** (1 / p)
    a = np.full(X.x.shape[0], -1, np.int64)
    a[I] = r.jk[J]
    sw = _switch_counts(r.tk, xs, a, S)
    switching = gamma * sw ** (1 / p)
    return SwitchingGospa(np.sqrt(g * g + switching * switching), g, loc, missed, false, sw,
                          switching)


def _penalty(c: float, switching_penalty: float | None) -> float:
    gamma = float(c if switching_penalty is None else switching_penalty)
    if not (gamma >= 0 and math.isfinite(gamma)):
        raise ValueError(f"switching_penalty = {switching_penalty!r}; expected a finite "
                         "penalty >= 0")
    return gamma


def _switch_counts(tk: IntArray, xs: IntArray, a: IntArray, S: int) -> Array:
    """Per step: full switches plus half the half switches of the truths' assigned tracks
    ``a`` (-1: none), each truth counted from its first assignment on."""
    if tk.size == 0:
        return np.zeros(S)
    o = np.argsort(tk, kind="stable")  # each truth's rows in step order
    t, a = tk[o], a[o]
    on = a >= 0
    first = np.r_[True, t[1:] != t[:-1]]
    group = np.cumsum(first) - 1
    ca = np.cumsum(on)
    base = (ca - on)[first]  # assignments before each truth's rows
    q = np.arange(1, t.size)
    seen = ca[q - 1] - base[group[q]] > 0  # the previous row is at or after the first one
    change = ~first[q] & seen & (a[q] != a[q - 1])
    cost = 0.5 * on[q - 1] + 0.5 * on[q]
    return np.bincount(xs[o][q][change], weights=cost[change], minlength=S).astype(float)


# --- switches the radar could resolve ---------------------------------------------------------


def classify_switches(step: ArrayLike, truth_id: ArrayLike, truth: Frames,
                      site: tuple[float, float], sigma_bearing: float) -> SwitchClasses:
    """ID switch events (``step (E,)``, ``truth_id (E,)``: truth object a switches at step k)
    split by whether the radar can resolve a from its neighbours.

    A switch is *resolvable* when every other truth object at step k is farther from a than
    three cross-range sigmas at a's range, ``|x_b - x_a| > 3 r_a sigma_bearing`` for all
    b != a, with ``r_a = |x_a - site|`` (first two coordinates) and ``sigma_bearing`` the
    bearing noise std (rad); a switch of an object alone at its step is resolvable. A
    switch between objects closer than that (moored together, moving in company) is one
    the radar's plots cannot tell apart, not the tracker's fault."""
    step = np.asarray(step, np.int64).reshape(-1)
    tid = np.asarray(truth_id, np.int64).reshape(-1)
    sb = float(sigma_bearing)
    if step.shape != tid.shape:
        raise ValueError(f"step has shape {step.shape} and truth_id {tid.shape}; expected one "
                         "(E,) shape")
    if not (sb >= 0 and math.isfinite(sb)):
        raise ValueError(f"sigma_bearing = {sigma_bearing!r}; expected a finite std >= 0 (rad)")
    truth = checked_frames("truth", truth, need_ids=True)
    site_xy = np.asarray(site, float).reshape(-1)
    if site_xy.shape != (2,) or not np.all(np.isfinite(site_xy)):
        raise ValueError(f"site = {site!r}; expected a finite (x, y) in metres")
    if step.size and (step.min() < 0 or step.max() >= truth.n_steps):
        raise ValueError(f"step has values outside 0..{truth.n_steps - 1}, the truth's steps")
    row = _rows_of(truth, step, tid)
    off = np.asarray(truth.offsets, np.int64)
    n = off[step + 1] - off[step]  # truths at each event's step
    ev = np.repeat(np.arange(step.size), n)
    other = np.repeat(off[step], n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    x = np.asarray(truth.x, float)[:, :2]
    gap = np.hypot(*(x[other] - x[row[ev]]).T)
    nearest = np.full(step.size, np.inf)
    np.minimum.at(nearest, ev[other != row[ev]], gap[other != row[ev]])
    r = np.hypot(*(x[row] - site_xy).T)
    mask = nearest > 3.0 * r * sb
    return SwitchClasses(total=int(step.size), resolvable=int(mask.sum()), mask=mask)


def _rows_of(truth: Frames, step: IntArray, tid: IntArray) -> IntArray:
    """The row of ``truth.x`` of truth ``tid`` at ``step``, per event."""
    ids = np.asarray(truth.ids, np.int64)
    xs = np.repeat(np.arange(truth.n_steps), np.diff(np.asarray(truth.offsets)))
    u = np.unique(ids)
    n = max(u.size, 1)
    kt = np.minimum(np.searchsorted(u, tid), n - 1)
    key = xs * n + np.searchsorted(u, ids)  # unique per row: IDs are unique within a step
    o = np.argsort(key, kind="stable")
    pos = np.minimum(np.searchsorted(key[o], step * n + kt), max(o.size - 1, 0))
    ok = np.zeros(step.size, bool)
    if o.size:
        ok = (u[kt] == tid) & (key[o][pos] == step * n + kt)
    if not np.all(ok):
        e = int(np.flatnonzero(~ok)[0])
        raise ValueError(f"switch {e}: truth {int(tid[e])} is not in the truth at step "
                         f"{int(step[e])}; expected a truth present at its switch")
    return o[pos]


# --- one run's scores -------------------------------------------------------------------------


def score_run(tracks: Frames, truth: Frames, site: tuple[float, float] | None,
              sigma_bearing: float | None, c: float, *, p: float = 2.0,
              switching_penalty: float | None = None) -> dict[str, float]:
    """Every figure of one run, flat, from the confirmed tracks and the truth (``Frames``
    with IDs, one step per scan), threshold and GOSPA cut-off ``c`` (m), the radar ``site``
    (x, y) and its bearing noise ``sigma_bearing`` (rad; both None: no resolvable count).

    ``tracks_per_object`` = confirmed tracks / objects ever tracked; ``breaks``,
    ``completeness``, ``false_tracks``, ``rmse``, ``mean_purity`` as in
    ``track_metrics.track_counts``; ``id_switches`` (CLEAR-MOT IDSW) and
    ``id_switches_resolvable`` (``classify_switches``), ``fragmentations``, ``mota``,
    ``motp``, ``idf1``, ``idp``, ``idr``; ``gospa`` and ``gospa_switching``, the means over
    scans of GOSPA without and with the switching term (penalty ``switching_penalty``,
    default ``c``); ``false_track_scans``, the confirmed tracks assigned to no object summed
    over scans."""
    r = _run(truth, tracks, c)
    pairs = pairs_within(r.X, r.Y, c)
    cm = _clear_mot(r, pairs, c)
    cms = clear_mot_summary(cm)
    ids = _id_scores(r, pairs)
    ab = assign(r.X, r.Y, c, p)
    gs = _gospa_switching(r, ab, c, p, _penalty(c, switching_penalty))
    tc = track_summary(track_counts(r.X, r.Y, c, p=p, assignment=ab))
    if site is None or sigma_bearing is None:
        resolvable = math.nan
    else:
        resolvable = classify_switches(cm.switch_step, cm.switch_truth, truth, site,
                                       sigma_bearing).resolvable
    half = c**p / 2
    return {
        "scans": truth.n_steps, "objects": tc["truths"],
        "objects_tracked": tc["truths_confirmed"], "tracks": tc["tracks"],
        "tracks_per_object": _ratio(tc["tracks"], tc["truths_confirmed"]),
        "breaks": tc["breaks"], "id_switches": cms["switches"],
        "id_switches_resolvable": resolvable, "fragmentations": cms["fragmentations"],
        "idf1": ids.idf1, "idp": ids.idp, "idr": ids.idr,
        "mota": cms["mota"], "motp": cms["motp"],
        "gospa": float(np.mean(gs.gospa)) if gs.gospa.size else math.nan,
        "gospa_switching": float(np.mean(gs.distance)) if gs.distance.size else math.nan,
        "completeness": tc["completeness"], "false_tracks": tc["false_tracks"],
        "false_track_scans": int(round(math.fsum(gs.false.tolist()) / half)),
        "rmse": tc["rmse"], "mean_purity": tc["mean_purity"],
    }
