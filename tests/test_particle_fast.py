"""The particle filters' compiled draws (``trackkit.filters.particle_fast``): numpy's standard
normals bit for bit, the generator left where numpy leaves it, the threshold where the kernel
takes over, and the same bits when numba compiles for another CPU."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import trackkit as tk
from trackkit.filters import particle_fast as pf
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


_CHILD = """
import numpy as np
from trackkit.filters import particle_fast as pf
np.save({path!r}, pf.standard_normals(np.random.default_rng(5), (400_000,)))
"""


@pytest.mark.parametrize("cpu", ["generic", "haswell"])
def test_the_same_bits_when_compiled_for_another_cpu(cpu, tmp_path):
    # compiled for plain x86-64 (no FMA) and for AVX2 the ziggurat's arithmetic (its tail's
    # log and exp included: 400 000 draws reach |e| > 4 about 25 times) gives the same bits
    path = tmp_path / "out.npy"
    env = dict(os.environ, NUMBA_CPU_NAME=cpu, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    subprocess.run([sys.executable, "-c", _CHILD.format(path=str(path))], env=env, check=True,
                   timeout=300)
    np.testing.assert_array_equal(np.load(path),
                                  np.random.default_rng(5).standard_normal(400_000))
