"""The common interface of trackkit's population optimisers (GA, PSO and ICA).

Every optimiser minimises B independent problems at once::

    result = GA(population=50, generations=200).minimize(cost, bounds, rngs)

- ``cost(X)`` takes candidates ``X`` of shape ``(B, n, d)`` (B problems, n candidates each,
  d decision variables) and returns costs ``(B, n)``; row b of X is only ever scored for
  problem b. Cost evaluation is one call per generation for all problems (so a filter-based
  cost can run all candidates of all Monte Carlo runs as one batch). ``n`` is not always the
  population size (elites are not re-scored), so a cost must accept any n. A ``nan`` cost is
  treated as ``+inf`` (the worst), so a candidate whose cost cannot be computed is never
  selected over one whose cost can.
- ``bounds`` is ``(d, 2)`` (shared) or ``(B, d, 2)`` (per problem): ``[lower, upper]`` with
  ``lower < upper``, both finite. Candidates never leave the box.
- ``rngs`` is a sequence of B ``numpy.random.Generator`` (ints and ``SeedSequence`` are
  accepted and passed to ``numpy.random.default_rng``). Problem b draws its random numbers
  only from ``rngs[b]``, in an order that does not depend on B, so a problem's result is
  identical whether it is solved alone or in a batch (for a cost whose rows are independent).

``repeat`` runs one problem several times with independent seeds and reports the best, mean
and worst final cost, as optimiser comparisons do (Naseri Solhdar, Table 3-2: 15 runs each).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Cost",
    "BOUNDARIES",
    "require",
    "is_integer",
    "is_real",
    "OptimizeResult",
    "Optimizer",
    "as_generators",
    "check_bounds",
    "evaluate",
    "enforce_bounds",
    "repeat",
]

Array = NDArray[np.float64]
Cost = Callable[[Array], ArrayLike]


class OptimizeResult(NamedTuple):
    """Result of a batched minimisation of B problems in d variables.

    ``best_x`` ``(B, d)`` and ``best_f`` ``(B,)``: the best candidate found and its cost.
    ``history`` ``(iterations + 1, B)``: the best cost after each generation or iteration
    (row 0: the initial population): the GA's best in the population (non-increasing with
    elitism), PSO's and ICA's best found so far; its last row equals ``best_f``.
    ``evaluations``: cost evaluations per problem.
    """

    best_x: Array
    best_f: Array
    history: Array
    evaluations: int

    def at(self, index: int | slice | Array) -> OptimizeResult:
        """The result of problem(s) ``index`` (e.g. ``res.at(3)`` or ``res.at(slice(0, 5))``)."""
        return OptimizeResult(self.best_x[index], self.best_f[index], self.history[:, index],
                              self.evaluations)


def require(ok: bool, owner: str, what: str, value: Any, want: str) -> None:
    """Raise ``ValueError("<owner> <what> = <value>; expected <want>")`` unless ``ok``: the
    optimisers' settings are checked with messages that name the field."""
    if not ok:
        raise ValueError(f"{owner} {what} = {value!r}; expected {want}")


def is_integer(v: Any) -> bool:
    """A Python or numpy integer (not a bool)."""
    return isinstance(v, int | np.integer) and not isinstance(v, bool)


def is_real(v: Any) -> bool:
    """A finite real number (not a bool)."""
    return (isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool)
            and bool(np.isfinite(v)))


def as_generators(rngs: Sequence[Any]) -> list[np.random.Generator]:
    """One ``Generator`` per problem; ints and ``SeedSequence`` go through ``default_rng``."""
    if isinstance(rngs, np.random.Generator | int | np.random.SeedSequence):
        raise TypeError(
            "rngs must be a sequence with one Generator per problem (e.g. "
            "[np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(B)]); "
            f"got a single {type(rngs).__name__}"
        )
    gens = [r if isinstance(r, np.random.Generator) else np.random.default_rng(r) for r in rngs]
    if not gens:
        raise ValueError("rngs is empty; expected one Generator per problem (B >= 1)")
    return gens


def check_bounds(bounds: ArrayLike, B: int) -> tuple[Array, Array]:
    """Validate ``bounds`` ``(d, 2)`` or ``(B, d, 2)``; return ``lower, upper`` of shape (B, d)."""
    b = np.asarray(bounds, dtype=float)
    if b.ndim == 2:
        b = np.broadcast_to(b, (B,) + b.shape)
    if b.ndim != 3 or b.shape[0] != B or b.shape[-1] != 2 or b.shape[1] < 1:
        raise ValueError(
            f"bounds has shape {np.shape(bounds)}; expected (d, 2) or ({B}, d, 2) for "
            f"{B} problems (one [lower, upper] row per variable)"
        )
    lo, hi = b[..., 0], b[..., 1]
    if not (np.all(np.isfinite(b)) and np.all(lo < hi)):
        raise ValueError("bounds must be finite with lower < upper in every row")
    return np.ascontiguousarray(lo), np.ascontiguousarray(hi)


def evaluate(cost: Cost, X: Array) -> Array:
    """``cost(X)`` for X ``(B, n, d)`` checked to be ``(B, n)``; ``nan`` becomes ``+inf``."""
    f = np.asarray(cost(X), dtype=float)
    if f.shape != X.shape[:2]:
        raise ValueError(
            f"cost returned shape {f.shape} for candidates of shape {X.shape}; "
            f"expected {X.shape[:2]} (one cost per problem and candidate)"
        )
    return np.where(np.isnan(f), np.inf, f)


#: the wall modes of :func:`enforce_bounds`, shared by every optimiser's ``boundary`` setting
BOUNDARIES = ("reflect", "clip")


def enforce_bounds(X: Array, lo: Array, hi: Array, mode: str = "reflect") -> Array:
    """Bring X ``(B, n, d)`` back into ``[lo, hi]`` (``lo, hi`` of shape (B, d)).

    ``"reflect"`` mirrors at the walls (periodic with period 2w, w = hi - lo, so any
    distance out comes back in): ``y = (x - lo) mod 2w``, ``x' = lo + w - |y - w|``. It keeps
    the spread of an operator that overshoots, where ``"clip"`` piles candidates onto the
    walls (useful when the optimum is expected on a wall).
    """
    lo, hi = lo[:, None, :], hi[:, None, :]
    if mode == "clip":
        return np.clip(X, lo, hi)
    w = hi - lo
    y = np.mod(X - lo, 2 * w)
    return np.clip(lo + w - np.abs(y - w), lo, hi)  # the clip only removes rounding


class Optimizer:
    """Base of the batched optimisers: ``minimize(cost, bounds, rngs) -> OptimizeResult``."""

    name: str = "Optimizer"

    def minimize(self, cost: Cost, bounds: ArrayLike,
                 rngs: Sequence[Any]) -> OptimizeResult:  # pragma: no cover - interface
        raise NotImplementedError

    def __repr__(self) -> str:
        fields = ", ".join(f"{k}={v!r}" for k, v in vars(self).items())
        return f"{type(self).__name__}({fields})"


def repeat(optimizer: Optimizer, cost: Cost, bounds: ArrayLike,
           seeds: Sequence[Any]) -> dict[str, Any]:
    """Independent runs of ``optimizer`` on ONE problem, one run per seed.

    The runs are solved as the rows of one batch (``cost`` sees ``(len(seeds), n, d)`` and
    must score every row as the same problem), which by batch invariance equals solving them
    one by one. ``bounds`` is ``(d, 2)``. Returns ``best``, ``mean`` and ``worst`` of the
    final costs over the runs, ``best_x`` (the best run's point) and ``results`` (the
    ``OptimizeResult`` whose row r is the run with ``seeds[r]``).
    """
    b = np.asarray(bounds, dtype=float)
    if b.ndim != 2:
        raise ValueError(f"repeat: bounds has shape {b.shape}; expected (d, 2) for one problem")
    res = optimizer.minimize(cost, b, as_generators(seeds))
    i = int(np.argmin(res.best_f))
    return {
        "best": float(res.best_f[i]),
        "mean": float(np.mean(res.best_f)),
        "worst": float(np.max(res.best_f)),
        "best_x": res.best_x[i],
        "results": res,
    }
