"""The JPDA (PDAF) state update in closed form, the reference the tests hold the tracker's JPDA
to.

The tracker updates a track with each of its gated detections through its own filter and
moment-matches the mixture (``Tracker._jpda``, :func:`trackkit.belief.moment_match`), which
serves any filter (an IEKF's gain depends on the detection, an IMM merges per model). For a
Kalman filter that mixture is, in exact arithmetic, the combined-innovation update below
(Bar-Shalom, Daum and Huang 2009), which Stone Soup's ``PDAUpdater`` computes too.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from trackkit.belief import Gaussian
from trackkit.linalg import symmetrize

Array = NDArray[np.float64]
Index = NDArray[np.intp]


def jpda_update(prior: Gaussian, K: Array, S: Array, track: Index, residual: Array,
                beta: Array, beta0: Array, P_upd: Array | None = None) -> Gaussian:
    """JPDA (PDAF) state update of every track at once (Bar-Shalom):

        nu_i = sum_j beta_ij nu_ij                                  (combined innovation)
        x_i+ = x_i + K_i nu_i
        P_i+ = beta_i0 P_i + (1 - beta_i0) P_i^c
               + K_i [sum_j beta_ij nu_ij nu_ij^T - nu_i nu_i^T] K_i^T

    with ``P^c = P - K S K^T`` the covariance after a certain detection (pass ``P_upd`` to
    use the filter's own, e.g. Joseph form). ``prior`` is the predicted belief ``(T, n)``;
    ``K (T, n, m)``, ``S (T, m, m)``; pairs given by ``track (P,)``, ``residual (P, m)``,
    ``beta (P,)``; ``beta0 (T,)``. A track with no gated detection (beta_i0 = 1) keeps its
    prediction.
    """
    x, P = np.asarray(prior.mean, dtype=float), np.asarray(prior.cov, dtype=float)
    T, m = x.shape[0], S.shape[-1]
    nP = track.shape[0]
    # one sparse (T x P) matrix of the betas sums every track's pairs in one product
    Bm = sp.csr_matrix((beta, (track, np.arange(nP))), shape=(T, nP))
    nu = np.asarray(Bm @ residual).reshape(T, m)
    outer = (residual[:, :, None] * residual[:, None, :]).reshape(nP, m * m)
    spread = np.asarray(Bm @ outer).reshape(T, m, m) - nu[:, :, None] * nu[:, None, :]
    x_new = x + (K @ nu[:, :, None])[:, :, 0]
    if P_upd is None:
        P_upd = P - K @ S @ K.mT
    b0 = np.asarray(beta0, dtype=float)[:, None, None]
    P_new = b0 * P + (1.0 - b0) * P_upd + K @ spread @ K.mT
    return Gaussian(x_new, symmetrize(P_new))
