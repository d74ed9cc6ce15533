r"""Compiled kernels of the particle filters: the generator's standard normals, the same
numbers in the same order as ``Generator.standard_normal`` at a third of its cost; and
systematic resampling's ancestors in one pass per row.

A particle filter's floor under numpy is its random numbers: ``Generator.standard_normal``
fills an array at about 10 ns a draw (on a 2-core Intel Xeon and a 2-core AMD EPYC alike),
and a 4-state prediction draws four per particle (38 of a position step's 101 ns per particle
on the EPYC, ``benchmarks/RESULTS.md``). numba compiles NumPy's own ziggurat against the same
bit generator (it reads and advances the generator's state through its C interface) at 3.2-3.5
ns a draw on the Xeon. The numbers are numpy's,
bit for bit, and the generator is left where numpy would leave it, so a run's random stream
and every result drawn from it are unchanged. The textbook form is ``rng.standard_normal``
itself; :func:`standard_normals` takes over from :data:`COMPILED_DRAWS` draws, below which
numba's call (about 8 us, most of it handing over the generator) costs more than it saves.

Systematic resampling (``trackkit.filters.resample``) computes its ancestors in numpy as a
cumulative sum, ``ceil``, one ``bincount`` over all rows and a cumulative histogram: four
passes and their temporaries. :func:`systematic_ancestors` does the same arithmetic in the
same order, one row at a time, so the ancestors are the same integers, four times faster; it
takes over from :data:`COMPILED_WEIGHTS` weights.

No fastmath, so no FMA contraction and no sum reordered by the vector width: the bits do not
depend on the CPU (``tests/test_particle_fast.py`` compiles them for plain x86-64 and for
AVX2 too). numba compiles the kernels on first use (about a second) and caches the machine
code beside this module (``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["COMPILED_DRAWS", "COMPILED_WEIGHTS", "standard_normals", "systematic_ancestors"]

Array = NDArray[np.float64]

#: the number of draws from which the compiled kernel takes over from numpy
COMPILED_DRAWS = 2048


@numba.njit(cache=True, error_model="numpy")
def _fill_standard_normal(rng: np.random.Generator, out: Array) -> None:
    flat = out.reshape(-1)
    for i in range(flat.size):
        flat[i] = rng.standard_normal()


def standard_normals(rng: np.random.Generator, shape: tuple[int, ...]) -> Array:
    """``rng.standard_normal(shape)``: the same numbers, compiled from
    :data:`COMPILED_DRAWS` draws."""
    shape = tuple(int(s) for s in shape)
    if math.prod(shape) < COMPILED_DRAWS:
        return rng.standard_normal(shape)
    out = np.empty(shape)
    _fill_standard_normal(rng, out)
    return out


# --------------------------------------------------------------------------------------------
# Systematic resampling's ancestors
# --------------------------------------------------------------------------------------------

#: the number of weights (rows x N) from which the compiled resampling takes over
COMPILED_WEIGHTS = 1024


@numba.njit(cache=True, error_model="numpy")
def _systematic_ancestors(w: Array, U: Array, n: int, out: NDArray[np.intp]) -> None:
    """Per row of ``w (R, N)``: with ``c`` the cumulative weights (ending at 1) and ``K_i =
    ceil(n c_i - U)`` clipped to [0, n], point k goes to particle ``a_k = #{i : K_i <= k}``
    (at most N - 1), a cumulative histogram of K: no branch per point."""
    R, N = w.shape
    c = np.empty(N)
    h = np.empty(n + 1, dtype=np.intp)
    for r in range(R):
        acc = 0.0
        for i in range(N):
            acc += w[r, i]
            c[i] = acc
        last = c[N - 1]
        h[:] = 0
        for i in range(N):
            h[min(max(math.ceil((c[i] / last) * n - U[r]), 0), n)] += 1
        a = 0
        for k in range(n):
            a += h[k]
            out[r, k] = min(a, N - 1)


def systematic_ancestors(w: Array, U: Array, n: int) -> NDArray[np.intp]:
    """Sorted ancestors ``(..., n)`` of systematic resampling of the weights ``w (..., N)``
    with one uniform per row ``U (...)``: ``resample.systematic``'s numpy passes (a
    cumulative sum, ``ceil``, one ``bincount`` and a cumulative histogram) bit for bit, in
    one compiled pass per row."""
    batch, N = w.shape[:-1], w.shape[-1]
    rows = math.prod(batch)
    out = np.empty((rows, n), dtype=np.intp)
    _systematic_ancestors(np.ascontiguousarray(w, dtype=float).reshape(rows, N),
                          np.ascontiguousarray(U, dtype=float).reshape(rows), int(n), out)
    return out.reshape(batch + (n,))
