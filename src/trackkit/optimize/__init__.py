"""Batched population optimisers with one interface (GA; PSO and ICA to follow).

    from trackkit.optimize import GA, repeat
    res = GA(population=50, generations=200).minimize(cost, bounds, rngs)
    res.best_x  # (B, d);  cost(X): (B, n, d) -> (B, n);  rngs: one Generator per problem
    stats = repeat(GA(), cost, bounds, seeds=range(15))  # best / mean / worst over runs
"""

from trackkit.optimize.base import Optimizer, OptimizeResult, enforce_bounds, repeat
from trackkit.optimize.ga import GA

__all__ = ["Optimizer", "OptimizeResult", "GA", "repeat", "enforce_bounds"]
