"""Batched population optimisers with one interface: GA, PSO and ICA.

    from trackkit.optimize import GA, ICA, PSO, repeat
    res = GA(population=50, generations=200).minimize(cost, bounds, rngs)
    res = PSO(population=50, iterations=30).minimize(cost, bounds, rngs)
    res = ICA(population=50, iterations=30, imperialists=5).minimize(cost, bounds, rngs)
    res.best_x  # (B, d);  cost(X): (B, n, d) -> (B, n);  rngs: one Generator per problem
    stats = repeat(PSO(), cost, bounds, seeds=range(15))  # best / mean / worst over runs

``GA``: real-coded genetic algorithm (tournament, crossover, mutation, elitism). ``PSO``:
particle swarm with linearly decreasing inertia (Kennedy and Eberhart; Shi and Eberhart).
``ICA``: imperialist competitive algorithm (Atashpaz-Gargari and Lucas). Each module's
docstring states its update equations and default hyper-parameters.
"""

from trackkit.optimize.base import Optimizer, OptimizeResult, enforce_bounds, repeat
from trackkit.optimize.ga import GA
from trackkit.optimize.ica import ICA
from trackkit.optimize.pso import PSO

__all__ = ["Optimizer", "OptimizeResult", "GA", "PSO", "ICA", "repeat", "enforce_bounds"]
