"""The particle filters' compiled kernels (``trackkit.filters.particle_fast``): numpy's standard
normals bit for bit, the generator left where numpy leaves it; systematic resampling's
ancestors equal to its numpy passes; the thresholds where the kernels take over; and the same
bits when numba compiles for another CPU."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import trackkit as tk
from trackkit.filters import particle_fast as pf
from trackkit.filters import resample as rs
from trackkit.filters.particle import propagate


@pytest.mark.parametrize("shape", [(pf.COMPILED_DRAWS,), (3, 7, 500, 4), (1_000_003,)])
def test_the_compiled_draws_are_numpys_bit_for_bit(shape):
    ours, theirs = np.random.default_rng(42), np.random.default_rng(42)
    np.testing.assert_array_equal(pf.standard_normals(ours, shape), theirs.standard_normal(shape))
    # the generator is left where numpy leaves it: the rest of the stream is the same too
    assert ours.bit_generator.state == theirs.bit_generator.state
    assert ours.standard_normal() == theirs.standard_normal()


def test_the_kernel_takes_over_at_the_threshold(monkeypatch):
    calls = []
    kernel = pf._fill_standard_normal
    monkeypatch.setattr(pf, "_fill_standard_normal", lambda rng, out: calls.append(out.size)
                        or kernel(rng, out))
    below, at = (pf.COMPILED_DRAWS - 1,), (pf.COMPILED_DRAWS,)
    for shape in (below, at):
        a, b = np.random.default_rng(3), np.random.default_rng(3)
        np.testing.assert_array_equal(pf.standard_normals(a, shape), b.standard_normal(shape))
    assert calls == [pf.COMPILED_DRAWS]


def test_a_prediction_is_the_textbook_one_bit_for_bit():
    # x_i <- f(x_i) + e_i L^T with e drawn by numpy: the PF's prediction, by hand
    motion = tk.models.ConstantVelocity(dim=2, q=0.5)
    X = np.random.default_rng(0).normal(size=(20, 300, 4)) * [100.0, 100.0, 5.0, 5.0]
    rng, ref = np.random.default_rng(7), np.random.default_rng(7)
    L = np.linalg.cholesky(motion.noise(X, 2.0))
    expected = motion.f(X, 2.0) + ref.standard_normal(X.shape) @ L.T
    np.testing.assert_array_equal(propagate(X, motion, 2.0, rng), expected)


def _weights(rows: int, N: int, seed: int, power: float = 8.0) -> np.ndarray:
    # skewed weights (a few heavy particles, many near zero), some exactly zero
    w = np.random.default_rng(seed).random((rows, N)) ** power
    w[:, 1::7] = 0.0
    return w / w.sum(-1, keepdims=True)


@pytest.mark.parametrize("N, n", [(5000, 5000), (300, 1000), (1000, 300), (1, 8), (8, 1)])
def test_systematic_ancestors_are_the_numpy_passes_bit_for_bit(N, n):
    w = _weights(40, N, seed=N + n)
    U = np.random.default_rng(1).random(40)
    U[0] = 0.0  # the points' extremes: k / n exactly
    np.testing.assert_array_equal(pf.systematic_ancestors(w, U, n),
                                  rs._systematic_numpy(w, U, n))


def test_the_resampler_takes_the_kernel_from_its_threshold(monkeypatch):
    calls = []
    kernel = pf.systematic_ancestors
    monkeypatch.setattr(pf, "systematic_ancestors", lambda w, U, n: calls.append(w.size)
                        or kernel(w, U, n))
    for rows in (1, 2):  # 512 weights (numpy) and 1 024 (compiled)
        w = _weights(rows, pf.COMPILED_WEIGHTS // 2, seed=rows)
        a = rs.systematic(w, np.random.default_rng(4))
        np.testing.assert_array_equal(
            a, rs._systematic_numpy(w, np.random.default_rng(4).random(rows), w.shape[-1]))
    assert calls == [pf.COMPILED_WEIGHTS]


_CHILD = """
import numpy as np
from trackkit.filters import particle_fast as pf
w = np.random.default_rng(6).random((50, 4000)) ** 8
w /= w.sum(-1, keepdims=True)
np.savez({path!r}, e=pf.standard_normals(np.random.default_rng(5), (400_000,)),
         a=pf.systematic_ancestors(w, np.random.default_rng(7).random(50), 4000))
"""


@pytest.mark.parametrize("cpu", ["generic", "haswell"])
def test_the_same_bits_when_compiled_for_another_cpu(cpu, tmp_path):
    # compiled for plain x86-64 (no FMA) and for AVX2 the ziggurat's arithmetic (its tail's
    # log and exp included: 400 000 draws reach |e| > 4 about 25 times) and the resampling's
    # cumulative sums give the same bits
    path = tmp_path / "out.npz"
    env = dict(os.environ, NUMBA_CPU_NAME=cpu, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    subprocess.run([sys.executable, "-c", _CHILD.format(path=str(path))], env=env, check=True,
                   timeout=300)
    theirs = np.load(path)
    np.testing.assert_array_equal(theirs["e"], np.random.default_rng(5).standard_normal(400_000))
    w = np.random.default_rng(6).random((50, 4000)) ** 8
    w /= w.sum(-1, keepdims=True)
    np.testing.assert_array_equal(
        theirs["a"], rs._systematic_numpy(w, np.random.default_rng(7).random(50), 4000))
