"""``belief.moment_match``, the one moment match of a Gaussian mixture, and its users: IMM
mixing, combination and mixture innovation, ``IMM.merge_hypotheses`` and the tracker's JPDA.

Tolerance: the sums are the same as the hand-written loop's in another order, so they agree
to a few ulps of the largest term (``1e-12`` of ``max |P_k + d_k d_k^T|`` leaves a wide margin
and still catches a wrong weight, index or sign, which is wrong at the 1e-3 .. 1 level).
"""

from __future__ import annotations

import numpy as np

import trackkit as tk
from trackkit import belief
from trackkit.filters import imm as imm_module
from trackkit.filters.imm import IMM
from trackkit.io.scans import Scan
from trackkit.tracking import tracker as tracker_module
from trackkit.tracking.tracker import JPDA, Tracker

TOL = 1e-12


def _mixture(rng, K, n):
    w = rng.uniform(0.1, 1.0, K)
    X = rng.normal(0, 10, (K, n))
    A = rng.normal(0, 1, (K, n, n))
    P = A @ np.swapaxes(A, -1, -2) + np.eye(n)
    return w / w.sum(), X, P


def _by_hand(w, X, P):
    x = sum(wk * xk for wk, xk in zip(w, X, strict=True))
    C = sum(wk * (Pk + np.outer(xk - x, xk - x)) for wk, xk, Pk in zip(w, X, P, strict=True))
    return x, C


def _close(a, b, scale):
    assert np.abs(a - b).max() <= TOL * scale, np.abs(a - b).max() / scale


def test_dense_form_is_the_mixture_moments_per_row():
    rng = np.random.default_rng(1)
    rows = [_mixture(rng, 3, 4) for _ in range(5)]
    w, X, P = (np.stack(a) for a in zip(*rows, strict=True))
    x, C = belief.moment_match(w, X, P)
    assert x.shape == (5, 4) and C.shape == (5, 4, 4)
    assert np.array_equal(C, np.swapaxes(C, -1, -2))
    for i, (wi, Xi, Pi) in enumerate(rows):
        xr, Cr = _by_hand(wi, Xi, Pi)
        scale = np.abs(Pi).max() + np.abs(Xi).max() ** 2
        _close(x[i], xr, np.abs(Xi).max())
        _close(C[i], Cr, scale)


def test_grouped_form_is_the_dense_form_of_each_group():
    # five mixtures of 1 .. 4 components scattered in any order along axis 0, one with none
    rng = np.random.default_rng(2)
    sizes = [3, 1, 4, 0, 2]
    parts = [_mixture(rng, k, 3) if k else None for k in sizes]
    group = np.concatenate([np.full(k, g) for g, k in enumerate(sizes)])
    order = rng.permutation(group.size)
    w = np.concatenate([p[0] for p in parts if p])[order]
    X = np.concatenate([p[1] for p in parts if p])[order]
    P = np.concatenate([p[2] for p in parts if p])[order]
    x, C = belief.moment_match(w, X, P, group[order], len(sizes))
    assert x.shape == (5, 3) and C.shape == (5, 3, 3)
    assert np.array_equal(C, np.swapaxes(C, -1, -2))
    for g, p in enumerate(parts):
        if p is None:
            assert not x[g].any() and not C[g].any()
            continue
        xd, Cd = belief.moment_match(*p)
        _close(x[g], xd, np.abs(p[1]).max())
        _close(C[g], Cd, np.abs(p[2]).max() + np.abs(p[1]).max() ** 2)


def test_one_component_is_itself():
    rng = np.random.default_rng(3)
    _, X, P = _mixture(rng, 1, 4)
    x, C = belief.moment_match(np.ones(1), X, P)
    np.testing.assert_array_equal(x, X[0])
    np.testing.assert_array_equal(C, P[0])
    x, C = belief.moment_match(np.ones(1), X, P, np.zeros(1, np.intp), 1)
    np.testing.assert_array_equal(x[0], X[0])
    np.testing.assert_array_equal(C[0], P[0])


class _Spy:
    def __init__(self, fun):
        self.fun, self.calls = fun, 0

    def __call__(self, *a, **k):
        self.calls += 1
        return self.fun(*a, **k)


def test_the_imm_and_the_tracker_moment_match_through_it(monkeypatch):
    # IMM mixing (general path), combination, mixture innovation and merge_hypotheses, and
    # the tracker's JPDA of a plain filter: every moment match goes through the one function
    spies = {}
    for mod in (imm_module, tracker_module):
        spies[mod.__name__] = spy = _Spy(belief.moment_match)
        monkeypatch.setattr(mod, "moment_match", spy)
    cv = tk.models.ConstantVelocity(dim=2, q=0.5)
    ct = tk.models.CoordinatedTurn(q=0.5, q_omega=0.01)
    pos = tk.models.Position(dim=2, sigma=5.0)
    f = IMM([cv, ct], [tk.filters.KF(), tk.filters.EKF()], [[0.9, 0.1], [0.1, 0.9]],
            fill="zero")
    b = f.init(tk.Gaussian(np.array([[0.0, 0, 10, 0, 0.01]] * 3), np.eye(5)))
    b = f.predict(b, None, 1.0)  # mixing: one match per model
    assert spies[imm_module.__name__].calls == 2
    post, _ = f.update(b, np.array([[10.0, 0.5]] * 3), pos)  # the mixture innovation
    f.estimate(post)  # (fill="zero": the combination of the dense form)
    f.merge_hypotheses(b, post.at([0, 0, 2]), np.array([0, 0, 2]), np.array([0.2, 1.0, 0.5]),
                       np.array([0.5, 0.3, 0.5]))
    assert spies[imm_module.__name__].calls == 5
    trk = Tracker(tk.filters.KF(), cv, pos, associator=JPDA())
    tracks = trk.step(trk.init(), Scan(0.0, 0, np.array([[0.0, 0.0], [500.0, 0.0]])))
    trk.step(tracks, Scan(1.0, 0, np.array([[3.0, 1.0], [2.0, -4.0], [502.0, 3.0]])))
    assert spies[tracker_module.__name__].calls == 1
