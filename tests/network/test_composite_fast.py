"""The compiled composite fit (``network.composite_fast``) against its numpy form
(``composite._fit_numpy``): the same iteration, the same decisions, the same numbers to
rounding; a row's bits independent of its batch and of the CPU the kernel is compiled for.

Problems: a constant-velocity target seen by two sensors (one heading north, one west),
bearings at random times with 2 degree noise, a fifth of them missing, starts up to 2 km
and 5 m/s off, reference times anywhere in the window; rows with fewer than 4 bearings, a
single static sensor (unobservable), a target on a sensor and the "math" convention among them.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from trackkit.models.sensors import Bearing
from trackkit.network import composite
from trackkit.network.composite import NOT_CONVERGED, SINGULAR, composite_measurement

SIGMA = np.deg2rad(2.0)
X_TRUE = np.array([5000.0, 12000.0, -4.0, 6.0])


def _problems(seed: int, n: int = 600, m: int = 16, convention: str = "nautical") -> dict:
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.0, 300.0, (n, m))
    east = np.arange(m) % 2 == 1
    S = np.zeros((n, m, 2))
    S[..., 0] = np.where(east, 15000.0 - 4.0 * t, 0.0)
    S[..., 1] = np.where(east, 0.0, 5.0 * t)
    S[: n // 10] = 0.0  # one static sensor: the state is not observed
    x = X_TRUE[:2] + t[..., None] * X_TRUE[2:]
    z = Bearing(origin=S, convention=convention).h(x)[..., 0]
    z = z + SIGMA * rng.standard_normal(z.shape)
    z[rng.random(z.shape) < 0.2] = np.nan
    z[n // 10: n // 10 + 20, 3:] = np.nan  # at most 3 bearings
    x0 = X_TRUE + rng.normal(0.0, [2000.0, 2000.0, 5.0, 5.0], (n, 4))
    tf = rng.uniform(0.0, 300.0, n)
    k = n // 10 + 30  # a start on a sensor at the reference time
    S[k] = x0[k, :2] + (t[k] - tf[k])[:, None] * x0[k, 2:]
    return dict(z=z, t=t, sensor_pos=S, sigma=SIGMA, t_f=tf, x0=x0, convention=convention)


def _numpy_form(pr: dict, max_iter: int = 50, tol: float = 1e-8, rcond: float = 1e-10):
    _, X, p, count = composite._prepare(pr["x0"], pr["t"], pr["sensor_pos"], pr["sigma"],
                                        pr["t_f"], pr["z"], None, pr["convention"], "x0")
    return composite.Composite(*composite._fit_numpy(X, p, count, max_iter, tol, rcond))


@pytest.mark.parametrize("convention", ["nautical", "math"])
@pytest.mark.parametrize("seed", [1, 2])
def test_the_compiled_fit_equals_the_numpy_form(seed, convention):
    pr = _problems(seed, convention=convention)
    fast, slow = composite_measurement(**pr), _numpy_form(pr)
    # the same decisions: every row takes the same steps to the same status
    np.testing.assert_array_equal(fast.status, slow.status)
    np.testing.assert_array_equal(fast.iterations, slow.iterations)
    assert (slow.status == SINGULAR).sum() >= 60 and (slow.status == 0).sum() >= 400
    # the same numbers to rounding, each on its own scale: the estimate in its standard
    # deviations, J and J^-1 relative to their diagonals, lambda relative to itself
    well = slow.status != SINGULAR
    sd = np.sqrt(np.einsum("nii->ni", slow.cov[well]))
    assert np.all(np.abs(fast.mean - slow.mean)[well] <= 1e-13 * sd)
    np.testing.assert_array_equal(np.isnan(fast.cov), np.isnan(slow.cov))
    assert np.all(np.abs(fast.cov - slow.cov)[well] <= 1e-12 * sd[:, :, None] * sd[:, None, :])
    d = np.sqrt(np.einsum("nii->ni", slow.information[well]))
    assert np.all(np.abs(fast.information - slow.information)[well] <= 1e-12 * d[:, :, None]
                  * d[:, None, :])
    np.testing.assert_allclose(fast.cost[well], slow.cost[well], rtol=1e-12, atol=1e-20)
    # a singular row's iterate wanders along what the bearings do not observe, and the two
    # forms' rounding takes it to different points there (3e-4 relative after 50 steps):
    # only its status is promised


def test_a_budget_of_steps_ends_not_converged_in_both_forms():
    pr = _problems(3, n=200)
    fast, slow = composite_measurement(**pr, max_iter=2), _numpy_form(pr, max_iter=2)
    np.testing.assert_array_equal(fast.status, slow.status)
    np.testing.assert_array_equal(fast.iterations, slow.iterations)
    assert (fast.status == NOT_CONVERGED).sum() >= 50
    well = slow.status != SINGULAR
    np.testing.assert_allclose(fast.mean[well], slow.mean[well], rtol=1e-12)


def test_a_rows_bits_do_not_depend_on_its_batch_or_its_empty_slots():
    pr = _problems(4, n=40)
    together = composite_measurement(**pr)
    wider = dict(pr, z=np.pad(pr["z"], ((0, 0), (0, 5)), constant_values=np.nan),
                 t=np.pad(pr["t"], ((0, 0), (0, 5))),
                 sensor_pos=np.pad(pr["sensor_pos"], ((0, 0), (0, 5), (0, 0))))
    padded = composite_measurement(**wider)
    for i in (0, 7, 25, 39):
        alone = composite_measurement(**{k: v[i] if k in ("z", "t", "sensor_pos", "t_f", "x0")
                                         else v for k, v in pr.items()})
        for a, b, c in zip(alone, together, padded, strict=True):
            np.testing.assert_array_equal(a, b[i])
            np.testing.assert_array_equal(a, c[i])


_CHILD = """
import numpy as np
from tests.network.test_composite_fast import _problems
from trackkit.network.composite import composite_measurement
np.savez({path!r}, *composite_measurement(**_problems(5)))
"""


@pytest.mark.parametrize("cpu", ["generic", "haswell"])
def test_the_same_bits_when_compiled_for_another_cpu(cpu, tmp_path):
    # compiled for plain x86-64 (no FMA) and for AVX2, atan2 and the sums give the same bits
    path = tmp_path / "out.npz"
    env = dict(os.environ, NUMBA_CPU_NAME=cpu, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    subprocess.run([sys.executable, "-c", _CHILD.format(path=str(path))], env=env, check=True,
                   timeout=300, cwd=root)
    theirs = np.load(path)
    for i, ours in enumerate(composite_measurement(**_problems(5))):
        np.testing.assert_array_equal(theirs[f"arr_{i}"], ours)

