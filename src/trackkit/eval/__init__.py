"""Evaluation metrics: Monte Carlo statistics (RMSE, NEES, NIS, divergence), the posterior
CRLB, multi-target metrics (OSPA, GOSPA, track counts), innovation covariance matching and the
IMO manoeuvring criteria. Pure functions of estimates and truths; the experiments that produce
them live in :mod:`trackkit.experiments`.

    from trackkit.eval import PCRLB, MonteCarloMetrics
    bound = PCRLB(P0).predict(motion, truths_k, dt).update(sensor, truths_k1).bound
    acc = MonteCarloMetrics(groups={"position": [0, 1], "velocity": [2, 3]})
    acc.add(k, truth, estimate, innovation); acc.merge(other_chunk).summary(start=20)
"""

from trackkit.eval.crlb import PCRLB, pcrlb, rmse_bound
from trackkit.eval.metrics import MonteCarloMetrics, chi2_bounds, merge_all

__all__ = ["PCRLB", "pcrlb", "rmse_bound", "MonteCarloMetrics", "chi2_bounds", "merge_all"]
