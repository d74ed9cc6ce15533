"""Real-coded genetic algorithm (Holland 1975; real-valued operators after Eshelman and
Schaffer 1993), batched over independent problems.

One generation, for each problem, with population N and e elites:

1. **Elitism.** The e best members are copied unchanged into the next generation.
2. **Tournament selection.** Each of the ``2 ceil((N - e)/2)`` parent slots takes the best of
   ``tournament`` members drawn uniformly with replacement.
3. **Crossover** of consecutive parent pairs ``(p1, p2)``, with probability ``crossover``
   (otherwise the children are copies of the parents):

   - ``"blend"`` (BLX-alpha): per gene, ``c = p1 + g (p2 - p1)``, ``g ~ U(-alpha, 1 + alpha)``
     drawn independently for each child and gene: a child lies anywhere in the parents' box
     widened by ``alpha`` times its width on each side;
   - ``"arithmetic"`` (whole arithmetic): ``c1 = g p1 + (1 - g) p2``,
     ``c2 = (1 - g) p1 + g p2`` with one ``g ~ U(0, 1)`` per pair;
   - ``"single_point"`` (the textbook binary-GA operator of Naseri Solhdar, swap tails): the genes
     after a cut ``j ~ U{1, ..., d-1}`` are exchanged (``d = 1``: no change).

4. **Mutation**, independently per gene with probability ``mutation``:
   ``"gaussian"``: ``x += s (hi - lo) n``, ``n ~ N(0, 1)``, ``s = mutation_scale``;
   ``"uniform"``: ``x ~ U(lo, hi)`` (a fresh value anywhere in the bounds).
5. **Bounds** (``boundary``): ``"reflect"`` mirrors a gene that left ``[lo, hi]`` back in
   (default: it keeps the spread of the blend and Gaussian steps), ``"clip"`` sets it onto the
   wall.
6. The ``N - e`` children are scored in one batched ``cost`` call.

The run lasts exactly ``generations`` generations (no early stop, so every problem draws the
same amount of randomness and results do not depend on the batch). Evaluations per problem:
``N + generations (N - e)``.
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
    require,
)

__all__ = ["GA"]

Array = NDArray[np.float64]

_CROSSOVERS = ("blend", "arithmetic", "single_point")
_MUTATIONS = ("gaussian", "uniform")


@dataclass(frozen=True, repr=True)
class GA(Optimizer):
    """Real-coded GA: tournament selection, crossover, per-gene mutation, elitism.

    ``GA(population=50, generations=200, crossover=0.8, mutation=0.05)`` are the settings of
    Hashemi and Alfi (2019). See the module docstring for the operators.
    """

    population: int = 50
    generations: int = 200
    crossover: float = 0.8
    mutation: float = 0.05
    elite: int = 1
    tournament: int = 2
    crossover_kind: str = "blend"
    alpha: float = 0.5
    mutation_kind: str = "gaussian"
    mutation_scale: float = 0.1
    boundary: str = "reflect"

    name = "GA"

    def __post_init__(self) -> None:
        def need(ok: bool, what: str, value: Any, want: str) -> None:
            require(ok, "GA", what, value, want)

        need(is_integer(self.population) and self.population >= 2, "population",
             self.population, "an integer >= 2")
        need(is_integer(self.generations) and self.generations >= 0, "generations",
             self.generations, "an integer >= 0")
        need(is_integer(self.elite) and 0 <= self.elite < self.population, "elite", self.elite,
             f"an integer in [0, population) = [0, {self.population})")
        need(is_integer(self.tournament) and self.tournament >= 1, "tournament", self.tournament,
             "an integer >= 1")
        for what in ("crossover", "mutation"):
            v = getattr(self, what)
            need(np.isfinite(v) and 0 <= v <= 1, what, v, "a probability in [0, 1]")
        need(np.isfinite(self.alpha) and self.alpha >= 0, "alpha", self.alpha, "a value >= 0")
        need(np.isfinite(self.mutation_scale) and self.mutation_scale > 0, "mutation_scale",
             self.mutation_scale, "a value > 0")
        need(self.crossover_kind in _CROSSOVERS, "crossover_kind", self.crossover_kind,
             f"one of {_CROSSOVERS}")
        need(self.mutation_kind in _MUTATIONS, "mutation_kind", self.mutation_kind,
             f"one of {_MUTATIONS}")
        need(self.boundary in BOUNDARIES, "boundary", self.boundary, f"one of {BOUNDARIES}")

    @property
    def iterations(self) -> int:
        """The generations, under the name the other optimisers use."""
        return self.generations

    # --- random numbers: a fixed amount per problem and generation -----------------------

    def _layout(self, d: int) -> tuple[int, int, list[int]]:
        """(pairs M, children C, lengths of the uniform blocks) for d variables.

        Per problem and generation: ``rng.random(sum(lengths))`` split into tournament picks
        ``2 M k``, crossover flags ``M``, crossover parameters, mutation masks ``2 M d`` and
        (uniform mutation) new values ``2 M d``; then ``standard_normal((2 M, d))`` for the
        Gaussian mutation.
        """
        C = self.population - self.elite
        M = (C + 1) // 2
        gamma = 2 * M * d if self.crossover_kind == "blend" else M
        blocks = [2 * M * self.tournament, M, gamma, 2 * M * d]
        if self.mutation_kind == "uniform":
            blocks.append(2 * M * d)
        return M, C, blocks

    def _draw(self, gens: list[np.random.Generator], d: int) -> tuple[Array, Array | None]:
        """The uniforms ``(B, sum(blocks))`` and normals ``(B, 2 M, d)`` of one generation."""
        M, _, blocks = self._layout(d)
        U = np.empty((len(gens), sum(blocks)))
        Z = np.empty((len(gens), 2 * M, d)) if self.mutation_kind == "gaussian" else None
        for b, g in enumerate(gens):
            U[b] = g.random(U.shape[1])
            if Z is not None:
                Z[b] = g.standard_normal((2 * M, d))
        return U, Z

    # --- one generation ------------------------------------------------------------------

    def _offspring(self, X: Array, F: Array, lo: Array, hi: Array, U: Array,
                   Z: Array | None) -> Array:
        """Children ``(B, N - e, d)`` of population X ``(B, N, d)`` with costs F ``(B, N)``."""
        B, N, d = X.shape
        M, C, blocks = self._layout(d)
        k = self.tournament
        rows = np.arange(B)[:, None]
        u_tour, u_flag, u_gam, u_mask, *u_val = np.split(U, np.cumsum(blocks)[:-1], axis=1)
        # tournament selection: winner = lowest cost among k uniform picks
        picks = np.minimum((u_tour.reshape(B, 2 * M, k) * N).astype(np.intp), N - 1)
        fp = F[rows[..., None], picks]
        winners = np.take_along_axis(picks, np.argmin(fp, axis=-1)[..., None], -1)[..., 0]
        P = X[rows, winners].reshape(B, M, 2, d)
        p1, p2 = P[:, :, 0], P[:, :, 1]
        # crossover
        if self.crossover_kind == "blend":
            g = u_gam.reshape(B, M, 2, d) * (1 + 2 * self.alpha) - self.alpha
            c1 = p1 + g[:, :, 0] * (p2 - p1)
            c2 = p2 + g[:, :, 1] * (p1 - p2)
        elif self.crossover_kind == "arithmetic":
            g = u_gam[..., None]
            c1 = g * p1 + (1 - g) * p2
            c2 = (1 - g) * p1 + g * p2
        else:  # single point: exchange the genes j >= cut, cut in 1..d-1 (d = 1: none)
            cut_at = 1 + np.minimum((u_gam * (d - 1)).astype(np.intp), max(d - 2, 0))
            tail = np.arange(d) >= cut_at[..., None]
            c1 = np.where(tail, p2, p1)
            c2 = np.where(tail, p1, p2)
        cross = (u_flag < self.crossover)[..., None]
        children = np.stack([np.where(cross, c1, p1), np.where(cross, c2, p2)], 2)
        children = children.reshape(B, 2 * M, d)
        # mutation per gene
        mask = u_mask.reshape(B, 2 * M, d) < self.mutation
        width = (hi - lo)[:, None, :]
        if self.mutation_kind == "gaussian":
            mutated = children + self.mutation_scale * width * Z
        else:
            mutated = lo[:, None, :] + u_val[0].reshape(B, 2 * M, d) * width
        children = np.where(mask, mutated, children)[:, :C]
        return enforce_bounds(children, lo, hi, self.boundary)

    def minimize(self, cost: Cost, bounds: ArrayLike, rngs: Sequence[Any]) -> OptimizeResult:
        """Minimise ``cost`` over the box ``bounds`` for ``len(rngs)`` problems at once."""
        gens = as_generators(rngs)
        B = len(gens)
        lo, hi = check_bounds(bounds, B)
        d = lo.shape[1]
        N, e = self.population, self.elite
        X = np.empty((B, N, d))
        for b, g in enumerate(gens):
            X[b] = g.random((N, d))
        X = lo[:, None, :] + X * (hi - lo)[:, None, :]
        F = evaluate(cost, X)
        rows = np.arange(B)[:, None]
        history = np.empty((self.generations + 1, B))
        history[0] = F.min(1)
        i = np.argmin(F, 1)
        best_x, best_f = X[rows[:, 0], i].copy(), F[rows[:, 0], i].copy()
        for gen in range(1, self.generations + 1):
            U, Z = self._draw(gens, d)
            children = self._offspring(X, F, lo, hi, U, Z)
            Fc = evaluate(cost, children)
            if e:
                keep = np.argsort(F, axis=1, kind="stable")[:, :e]
                X = np.concatenate([X[rows, keep], children], 1)
                F = np.concatenate([F[rows, keep], Fc], 1)
            else:
                X, F = children, Fc
            i = np.argmin(F, 1)
            f_gen = F[rows[:, 0], i]
            history[gen] = f_gen
            better = f_gen < best_f
            best_f = np.where(better, f_gen, best_f)
            best_x = np.where(better[:, None], X[rows[:, 0], i], best_x)
        return OptimizeResult(best_x, best_f, history, N + self.generations * (N - e))
