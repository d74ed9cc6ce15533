"""Particle swarm optimisation (Kennedy and Eberhart 1995) with linearly decreasing inertia
(Shi and Eberhart 1998), batched over independent problems.

Each problem has a swarm of N particles with positions ``X_i`` and velocities ``V_i`` in the
box ``[lo, hi]`` (width ``w = hi - lo`` per variable), personal bests ``P_i`` (the best
position particle i has visited, cost ``f(P_i)``) and the global best ``G = P_g``,
``g = argmin_i f(P_i)``. Iteration ``t = 0, ..., T - 1`` (``T = iterations``):

1. **Inertia**: ``w(t) = w_start + (w_end - w_start) t / (T - 1)`` (``w_start`` for the first
   step, ``w_end`` for the last; ``w_start`` when ``T = 1``).
2. **Velocity**, per particle i and variable j, with ``r1, r2 ~ U(0, 1)`` drawn independently
   for each particle and variable::

       V_i(t+1) = w(t) V_i(t) + c1 r1 (P_i - X_i(t)) + c2 r2 (G - X_i(t))

   then clamped per variable: ``V_ij <- clip(V_ij, -v_max w_j, v_max w_j)``.
3. **Position**: ``X_i(t+1) = X_i(t) + V_i(t+1)``, brought back into the box (``boundary``):

   - ``"reflect"`` (default): the position is mirrored at the walls (``enforce_bounds``) and
     each velocity component whose position bounced an odd number of times,
     ``floor((x - lo_j) / w_j)`` odd, has its sign flipped, so the particle keeps moving
     away from the wall it hit;
   - ``"clip"``: the position is set onto the wall and the velocity component that left
     the box is set to 0 (an absorbing wall; Robinson and Rahmat-Samii 2004).

4. The N new positions are scored in one batched ``cost`` call;
   ``P_i <- X_i(t+1)`` where ``f(X_i(t+1)) < f(P_i)``; then ``G`` is recomputed.

Initial state: ``X_i(0) ~ U(lo, hi)``, ``V_i(0) = 0`` (zero initial velocities, as
Engelbrecht 2012 recommends: large random ones send particles out of the box in the first
steps; it also needs no extra randomness), ``P_i = X_i(0)``.

Defaults: ``c1 = c2 = 2`` (Kennedy and Eberhart's acceleration constants) with the inertia
going from 0.9 to 0.4 (Shi and Eberhart 1999), ``v_max = 0.2`` of the box width per variable
(the usual 10-20 %), population 50 and 30 iterations (Naseri Solhdar's settings).

``history[t]`` is the global best cost ``f(G)`` after iteration t (row 0: the initial
swarm), i.e. the best cost seen so far: non-increasing, last row equal to ``best_f``.
Per problem and iteration the generator draws ``random((2, N, d))`` (``r1``, ``r2``); the
initial positions are ``random((N, d))``. The run lasts exactly ``iterations`` iterations.
Evaluations per problem: ``N (iterations + 1)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.optimize.base import (
    BOUNDARIES,
    Cost,
    Optimizer,
    OptimizeResult,
    as_generators,
    check_bounds,
    enforce_bounds,
    evaluate,
    is_integer,
    is_real,
    require,
)

__all__ = ["PSO"]

Array = NDArray[np.float64]



@dataclass(frozen=True, repr=True)
class PSO(Optimizer):
    """Particle swarm with linearly decreasing inertia, velocity clamping and walls.

    ``PSO(population=50, iterations=30)`` are Naseri Solhdar's settings; the other defaults are the
    standard ones (see the module docstring for the update and the choices).
    """

    population: int = 50
    iterations: int = 30
    c1: float = 2.0
    c2: float = 2.0
    w_start: float = 0.9
    w_end: float = 0.4
    v_max: float = 0.2
    boundary: str = "reflect"

    name = "PSO"

    def __post_init__(self) -> None:
        def need(ok: bool, what: str, value: Any, want: str) -> None:
            require(ok, "PSO", what, value, want)

        need(is_integer(self.population) and self.population >= 2, "population",
             self.population, "an integer >= 2")
        need(is_integer(self.iterations) and self.iterations >= 0, "iterations",
             self.iterations, "an integer >= 0")
        for what in ("c1", "c2", "w_start", "w_end"):
            v = getattr(self, what)
            need(is_real(v) and v >= 0, what, v, "a finite value >= 0")
        need(is_real(self.v_max) and self.v_max > 0, "v_max", self.v_max,
             "a finite value > 0 (a fraction of the box width)")
        need(self.boundary in BOUNDARIES, "boundary", self.boundary, f"one of {BOUNDARIES}")

    def inertia(self, t: int) -> float:
        """``w(t)`` of the step from iterate t to t + 1, ``t = 0, ..., iterations - 1``."""
        T = self.iterations
        return self.w_start + (self.w_end - self.w_start) * (t / (T - 1) if T > 1 else 0.0)

    def minimize(self, cost: Cost, bounds: ArrayLike, rngs: Sequence[Any]) -> OptimizeResult:
        """Minimise ``cost`` over the box ``bounds`` for ``len(rngs)`` problems at once."""
        gens = as_generators(rngs)
        B = len(gens)
        lo, hi = check_bounds(bounds, B)
        d = lo.shape[1]
        N = self.population
        rows = np.arange(B)
        lo3, hi3, width = lo[:, None, :], hi[:, None, :], (hi - lo)[:, None, :]
        v_lim = self.v_max * width

        X = np.empty((B, N, d))
        for b, g in enumerate(gens):
            X[b] = g.random((N, d))
        X = lo3 + X * width
        V = np.zeros_like(X)
        F = evaluate(cost, X)
        P, FP = X.copy(), F.copy()
        gi = np.argmin(FP, 1)
        G = P[rows, gi]
        history = np.empty((self.iterations + 1, B))
        history[0] = FP[rows, gi]

        R = np.empty((B, 2, N, d))
        for t in range(self.iterations):
            for b, g in enumerate(gens):  # fixed draws per problem: batch invariant
                R[b] = g.random((2, N, d))
            r1, r2 = R[:, 0], R[:, 1]
            V = self.inertia(t) * V + self.c1 * r1 * (P - X) + self.c2 * r2 * (G[:, None] - X)
            V = np.clip(V, -v_lim, v_lim)
            X_new = X + V
            if self.boundary == "reflect":
                # an odd number of bounces (floor((x - lo)/w) odd) leaves the particle moving
                # the other way: flip that velocity component
                bounces = np.floor((X_new - lo3) / width)
                V = np.where(np.mod(bounces, 2) == 1, -V, V)
            else:  # absorbing wall: stop the component that left the box
                V = np.where((X_new < lo3) | (X_new > hi3), 0.0, V)
            X = enforce_bounds(X_new, lo, hi, self.boundary)
            F = evaluate(cost, X)
            better = F < FP
            P = np.where(better[..., None], X, P)
            FP = np.where(better, F, FP)
            gi = np.argmin(FP, 1)
            G = P[rows, gi]
            history[t + 1] = FP[rows, gi]
        return OptimizeResult(G.copy(), FP[rows, gi].copy(), history,
                              N * (self.iterations + 1))
