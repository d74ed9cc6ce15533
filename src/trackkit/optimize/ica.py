"""Imperialist competitive algorithm (Atashpaz-Gargari and Lucas 2007), batched over
independent problems.

Each problem has N countries ``x_i`` in the box ``[lo, hi]`` (width ``w = hi - lo``) with
costs ``c_i``. The bookkeeping is two integer arrays per batch: ``owner`` ``(B, N)``, the
empire of each country, and ``imp`` ``(B, K)``, the country ruling each empire (its
imperialist; the other members are its colonies), with a mask ``alive`` ``(B, K)``.

**Start.** ``x_i ~ U(lo, hi)``; the ``K = imperialists`` cheapest countries rule empires
``n = 1..K``. Normalised cost and power of imperialist n::

    C_n = c_n - max_i c_i,        p_n = |C_n / sum_i C_i|    (p_n = 1/K if all C_n = 0)

Empire n receives ``NC_n = 1 + a_n`` colonies, where ``a_n`` apportions the ``N - 2K``
colonies left after one each in proportion to ``p_n`` (``floor(p_n (N - 2K))`` plus one more
for the largest remainders). The guaranteed colony is a deviation from the paper: there the
weakest imperialist has ``p = 0``, gets no colony and its empire would die at once. The
colonies are dealt to the empires in a random order (a random permutation per problem).

**One iteration** (a "decade"), for every problem:

1. **Assimilation.** A colony ``x`` of imperialist ``m`` moves towards it, with ``D = m - x``,
   ``u ~ U(0, 1)``, ``theta ~ U(-gamma, gamma)`` and ``z ~ N(0, I_d)``::

       s = beta u D                                  (the paper's move x ~ U(0, beta |D|))
       e = z_perp / |z_perp|,  z_perp = z - (z . D^) D^,  D^ = D / |D|
       x <- x + s + |s| tan(theta) e

   ``e`` is a uniformly random unit vector orthogonal to D, so the step keeps the paper's
   progress ``|s|`` along D and deviates from D by the angle ``|theta|`` (length
   ``|s| / cos(theta)``, hence ``gamma < pi/2``). In d = 2 this is the paper's direction
   turned by theta; in d = 1 there is no orthogonal direction and ``e = 0``. ``beta > 1``
   lets a colony overshoot and search both sides of its imperialist.
2. **Revolution.** Each colony, with probability ``revolution``, is replaced by a fresh
   ``x ~ U(lo, hi)`` (the original code's revolution, a new random country, applied per
   colony with that probability rather than to exactly ``round(revolution NC_n)`` of them).
3. **Bounds** (``boundary``): ``"reflect"`` mirrors a colony that left the box back in,
   ``"clip"`` sets it onto the wall.
4. **Scoring.** The cost is called on all N countries ``(B, N, d)``: the number of colonies
   differs between problems (empires die at different times), and one fixed shape keeps a
   problem's result independent of the batch. The imperialists did not move; their
   returned costs are discarded (K of the N evaluations per iteration are this overhead).
5. **Exchange of positions.** If an empire's best colony is cheaper than its imperialist,
   they swap roles.
6. **Total cost** of empire n: ``TC_n = c(imperialist_n) + zeta mean(c(colonies of n))``.
7. **Imperialistic competition** (when at least two empires are left). The weakest empire
   ``w = argmax_n TC_n`` loses its weakest (costliest) colony to empire ``k`` drawn by a
   roulette with the possession probabilities::

       NTC_n = TC_n - max_i TC_i,      P_n = |NTC_n / sum_i NTC_i|

   (``P_w = 0``; if all other ``TC`` are equal, ``k`` is uniform over them). A roulette
   gives exactly these probabilities with one uniform, where the paper's ``D = P - U``
   argmax only approximates them. If w has no colony left it is eliminated and its
   imperialist becomes a colony of k.

A non-finite cost (``nan`` counts as ``+inf``) has zero power: it is normalised as the worst
finite cost. The run lasts exactly ``iterations`` iterations (also when one empire is left:
then only steps 1-6 act), with the randomness of an iteration drawn as one fixed-size block per
problem, ``random(N (3 + d) + 1)`` (step ``u``, ``theta``, revolution flags, revolution
positions, roulette) and ``standard_normal((N, d))`` (``z``), whether used or not; the start
draws ``random((N, d))`` and ``random(N - K)``. The reference code's uniting of nearby
empires is not implemented.

Defaults: ``beta = 2`` and ``gamma = pi/4`` (the paper's suggested values), ``zeta = 0.1``
(the paper's), ``revolution = 0.3`` (the reference implementation's rate), 5 imperialists
(10 % of the countries), population 50 and 30 iterations (Naseri Solhdar's settings).

``history[t]`` is the best cost over all countries evaluated up to iteration t (row 0: the
initial countries): non-increasing, last row equal to ``best_f``. (An imperialist of an
eliminated empire may be better than its new imperialist and then moves on assimilation, so
the best of the current countries alone could increase.) Evaluations per problem:
``N (iterations + 1)``. ``minimize(..., diagnostics={})`` fills the dict with ``"empires"``,
the number of empires per problem after each iteration, shape ``(iterations + 1, B)``.
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

__all__ = ["ICA"]

Array = NDArray[np.float64]



def _power(c: Array, alive: NDArray[np.bool_]) -> Array:
    """Normalised power ``p_n = |C_n / sum C_i|``, ``C_n = c_n - max_i c_i``, of costs c (B, K)
    among the alive entries (dead: 0). Uniform over the alive ones when all ``C_n = 0``; a
    non-finite cost is taken as the worst finite one (power 0)."""
    finite = alive & np.isfinite(c)
    worst = np.max(np.where(finite, c, -np.inf), axis=1, keepdims=True)
    worst = np.where(np.isfinite(worst), worst, 0.0)  # no finite cost at all: all equal
    C = np.where(finite, worst - np.where(finite, c, 0.0), 0.0)  # = |c - max c| >= 0
    S = C.sum(1, keepdims=True)
    uniform = alive / alive.sum(1, keepdims=True)
    return np.where(S > 0, C / np.where(S > 0, S, 1.0), uniform)


def _apportion(p: Array, total: int) -> NDArray[np.intp]:
    """Integers ``a`` (B, K) with ``sum_n a_n = total``, ``a_n ~ p_n total`` (largest remainder:
    ``floor(p_n total)`` plus one for the ``total - sum floor`` largest fractional parts)."""
    share = p * total
    base = np.floor(share)
    left = total - base.sum(1, keepdims=True)
    rank = np.argsort(np.argsort(base - share, axis=1, kind="stable"), axis=1, kind="stable")
    return (base + (rank < left)).astype(np.intp)


def _orthogonal_unit(z: Array, D: Array) -> Array:
    """``z`` with its component along D removed, normalised (B, n, d); 0 where undefined."""
    nD = np.sqrt((D * D).sum(-1, keepdims=True))
    Dh = np.divide(D, nD, out=np.zeros_like(D), where=nD > 0)
    zp = z - (z * Dh).sum(-1, keepdims=True) * Dh
    nz = np.sqrt((zp * zp).sum(-1, keepdims=True))
    return np.divide(zp, nz, out=np.zeros_like(zp), where=nz > 0)


@dataclass(frozen=True, repr=True)
class ICA(Optimizer):
    """Imperialist competitive algorithm: assimilation with angular deviation, revolution,
    exchange of positions, imperialistic competition, elimination of empty empires.

    ``ICA(population=50, iterations=30)`` are Naseri Solhdar's settings; the other defaults are the
    paper's (see the module docstring for the steps and the choices).
    """

    population: int = 50
    iterations: int = 30
    imperialists: int = 5
    beta: float = 2.0
    gamma: float = np.pi / 4
    revolution: float = 0.3
    zeta: float = 0.1
    boundary: str = "reflect"

    name = "ICA"

    def __post_init__(self) -> None:
        def need(ok: bool, what: str, value: Any, want: str) -> None:
            require(ok, "ICA", what, value, want)

        need(is_integer(self.population) and self.population >= 2, "population",
             self.population, "an integer >= 2")
        need(is_integer(self.iterations) and self.iterations >= 0, "iterations",
             self.iterations, "an integer >= 0")
        need(is_integer(self.imperialists) and 1 <= self.imperialists <= self.population // 2,
             "imperialists", self.imperialists,
             f"an integer in [1, population // 2] = [1, {self.population // 2}] (every "
             "empire starts with at least one colony)")
        need(is_real(self.beta) and self.beta > 0, "beta", self.beta, "a finite value > 0")
        need(is_real(self.gamma) and 0 <= self.gamma < np.pi / 2, "gamma", self.gamma,
             "an angle in [0, pi/2) radians")
        need(is_real(self.revolution) and 0 <= self.revolution <= 1, "revolution",
             self.revolution, "a probability in [0, 1]")
        need(is_real(self.zeta) and self.zeta >= 0, "zeta", self.zeta, "a finite value >= 0")
        need(self.boundary in BOUNDARIES, "boundary", self.boundary, f"one of {BOUNDARIES}")

    def _draw(self, gens: list[np.random.Generator], N: int, d: int) -> tuple[Array, Array]:
        """The uniforms ``(B, N (3 + d) + 1)`` and normals ``(B, N, d)`` of one iteration."""
        U = np.empty((len(gens), N * (3 + d) + 1))
        Z = np.empty((len(gens), N, d))
        for b, g in enumerate(gens):
            U[b] = g.random(U.shape[1])
            Z[b] = g.standard_normal((N, d))
        return U, Z

    def minimize(self, cost: Cost, bounds: ArrayLike, rngs: Sequence[Any], *,
                 diagnostics: dict[str, Any] | None = None) -> OptimizeResult:
        """Minimise ``cost`` over the box ``bounds`` for ``len(rngs)`` problems at once.

        Pass a dict as ``diagnostics`` to receive ``"empires"`` ``(iterations + 1, B)``.
        """
        gens = as_generators(rngs)
        B = len(gens)
        lo, hi = check_bounds(bounds, B)
        d = lo.shape[1]
        N, K, T = self.population, self.imperialists, self.iterations
        r, rows = np.arange(B), np.arange(B)[:, None]
        lo3, width = lo[:, None, :], (hi - lo)[:, None, :]
        empire, country = np.arange(K), np.arange(N)

        X = np.empty((B, N, d))
        deal = np.empty((B, N - K))
        for b, g in enumerate(gens):
            X[b] = g.random((N, d))
            deal[b] = g.random(N - K)
        X = lo3 + X * width
        F = evaluate(cost, X)

        # --- empires: the K cheapest rule, the colonies are dealt in proportion to power ---
        order = np.argsort(F, axis=1, kind="stable")
        imp = order[:, :K].copy()  # imp[b, n]: the country ruling empire n
        alive = np.ones((B, K), dtype=bool)
        counts = 1 + _apportion(_power(F[rows, imp], alive), N - 2 * K)
        # colony slot j (in a random order) goes to the first empire whose running count > j
        slot_empire = (np.arange(N - K)[None, :, None] >= np.cumsum(counts, 1)[:, None, :]).sum(-1)
        dealt = np.take_along_axis(order[:, K:], np.argsort(deal, axis=1, kind="stable"), 1)
        owner = np.empty((B, N), dtype=np.intp)
        owner[rows, imp] = empire
        owner[rows, dealt] = slot_empire

        def colonies_of(owner: NDArray[np.intp], imp: NDArray[np.intp],
                        alive: NDArray[np.bool_]) -> NDArray[np.bool_]:
            """member[b, n, i]: country i is a colony of empire n (B, K, N)."""
            ruler = (country[None, None, :] == imp[:, :, None]) & alive[:, :, None]
            return (owner[:, None, :] == empire[None, :, None]) & ~ruler.any(1)[:, None, :]

        i = np.argmin(F, 1)
        best_x, best_f = X[r, i].copy(), F[r, i].copy()
        history = np.empty((T + 1, B))
        history[0] = best_f
        n_empires = np.empty((T + 1, B), dtype=np.intp)
        n_empires[0] = K
        splits = np.cumsum([N, N, N, N * d])
        for t in range(1, T + 1):
            U, Z = self._draw(gens, N, d)
            u_step, u_turn, u_rev, u_new, u_win = np.split(U, splits, axis=1)
            member = colonies_of(owner, imp, alive)
            colony = member.any(1)
            # 1. assimilation: towards the own imperialist, turned by theta
            D = X[rows, imp[rows, owner]] - X  # 0 for the imperialists
            s = self.beta * u_step[..., None] * D
            step = np.sqrt((s * s).sum(-1))
            theta = self.gamma * (2 * u_turn - 1)
            e = _orthogonal_unit(Z, D) if d > 1 else np.zeros_like(D)
            moved = X + s + (step * np.tan(theta))[..., None] * e
            # 2. revolution: a fresh random country
            fresh = lo3 + u_new.reshape(B, N, d) * width
            moved = np.where((u_rev < self.revolution)[..., None], fresh, moved)
            # 3.-4. bounds and scoring (imperialists unchanged: their old cost stands)
            X = np.where(colony[..., None], enforce_bounds(moved, lo, hi, self.boundary), X)
            F = np.where(colony, evaluate(cost, X), F)
            # 5. exchange: an empire's best colony cheaper than its imperialist takes over
            Fm = np.where(member, F[:, None, :], np.inf)
            j = np.argmin(Fm, -1)
            swap = alive & (np.take_along_axis(Fm, j[..., None], -1)[..., 0] < F[rows, imp])
            imp = np.where(swap, j, imp)
            member = colonies_of(owner, imp, alive)
            # 6. total cost (zeta = 0: no 0 * inf)
            n_col = member.sum(-1)
            TC = F[rows, imp]
            if self.zeta > 0:
                TC = TC + self.zeta * np.where(member, F[:, None, :], 0.0).sum(-1) / np.maximum(
                    n_col, 1)
            # 7. competition: the weakest colony of the weakest empire w goes to a roulette
            # winner k; w dies when it has no colony left
            compete = alive.sum(1) >= 2
            w = np.argmax(np.where(alive, TC, -np.inf), 1)
            c = np.argmax(np.where(member[r, w], F, -np.inf), 1)
            others = alive & (empire != w[:, None])
            P = np.where(others, _power(TC, alive), 0.0)
            S = P.sum(1, keepdims=True)
            P = np.where(S > 0, P / np.where(S > 0, S, 1.0),
                         others / np.maximum(others.sum(1, keepdims=True), 1))
            cum = np.cumsum(P, 1)
            hit = cum > u_win * cum[:, -1:]
            last = K - 1 - np.argmax(P[:, ::-1] > 0, 1)  # if u * total rounded up to total
            k = np.where(hit.any(1), np.argmax(hit, 1), last)
            owner = np.where(compete[:, None] & (country == c[:, None]), k[:, None], owner)
            dies = compete & (n_col[r, w] == 1)
            owner = np.where(dies[:, None] & (country == imp[r, w][:, None]), k[:, None], owner)
            alive = alive & ~(dies[:, None] & (empire == w[:, None]))
            # best over every country evaluated so far
            i = np.argmin(F, 1)
            better = F[r, i] < best_f
            best_f = np.where(better, F[r, i], best_f)
            best_x = np.where(better[:, None], X[r, i], best_x)
            history[t] = best_f
            n_empires[t] = alive.sum(1)
        if diagnostics is not None:
            diagnostics["empires"] = n_empires
        return OptimizeResult(best_x, best_f, history, N * (T + 1))
