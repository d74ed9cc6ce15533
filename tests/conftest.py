"""Shared helpers for the core tests: finite differences, random SPD matrices, tolerances; and
how many processes run the suite.

The helpers are handed to tests through the session fixture ``num`` (not imported by module
name, so that another ``conftest.py`` under ``tests/`` can never shadow them); session scope
keeps them usable inside hypothesis tests.

``pytest`` runs the files on pytest-xdist workers (``-n auto --dist loadfile`` in
pyproject.toml): one worker per CPU this process may really use, none (in-process) on one CPU.
Each worker's BLAS gets its share of the CPUs, so that two workers do not each start a thread
per core and fight over them: on a busy two-core machine a tall product such as
``(500 000, 4) @ (4, 4)`` (particles through a transition) took 7 to 10 times longer with two
OpenBLAS threads than with one.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

# --- parallel runs (pytest-xdist) -----------------------------------------------------------

BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _cgroup_cpus() -> int | None:
    """Whole CPUs allowed by a cgroup CPU quota (v2, then v1), or None without a quota: a
    container on a large host sees every host core in ``os.cpu_count()``."""
    try:
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()
    except (OSError, ValueError):
        try:
            quota = Path("/sys/fs/cgroup/cpu/cpu.cfs_quota_us").read_text().strip()
            period = Path("/sys/fs/cgroup/cpu/cpu.cfs_period_us").read_text().strip()
        except OSError:
            return None
    if quota in ("max", "-1"):
        return None
    return max(1, int(quota) // int(period))


def usable_cpus(logical: bool = False) -> int:
    """CPUs this process may use: the least of the (physical, unless ``logical``) core count,
    the affinity mask and the cgroup quota."""
    counts = [os.cpu_count() or 1]
    try:
        import psutil  # a dask.distributed dependency
    except ImportError:  # pragma: no cover
        pass
    else:
        counts.append(psutil.cpu_count(logical=logical) or counts[0])
    if hasattr(os, "sched_getaffinity"):
        counts.append(len(os.sched_getaffinity(0)))
    counts.append(_cgroup_cpus() or counts[0])
    return max(1, min(counts))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: one worker per usable CPU; 0 (run in this process) on one CPU, where a
    lone worker would only add its start-up. ``PYTEST_XDIST_AUTO_NUM_WORKERS`` still wins."""
    forced = os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS", "")
    if forced.isdigit():
        return int(forced)
    n = usable_cpus(logical=config.option.numprocesses == "logical")
    return n if n > 1 else 0


# Scheduling units other than the file, by node-id prefix (the first match wins); None makes
# each test a unit of its own.
SCHEDULING_UNITS = {
    # the uw-* scenarios' tunings (Naseri Solhdar), cached per scenario per process
    # (experiments.tuning), take about 5 min of CPU: the tests that use them share a worker, or the
    # tunings run twice
    "tests/report/test_show_roundtrip.py::test_show_then_compare_gives_the_same_results_tuned":
        "uw tunings",
    "tests/statistical/test_underwater_claims.py::": "uw tunings",
    # the uw-ch5 goldens share uw-ch5-fixed's (short) tuning through tune.on: about 30 s
    "tests/goldens/test_goldens.py::test_bundled_scenario_matches_golden[uw-ch5-":
        "uw-ch5 goldens",
    # minutes of independent tests (no fixture or cache between them): spread one by one
    "tests/report/test_show_roundtrip.py::": None,
    "tests/goldens/test_goldens.py::": None,
}


def scheduling_unit(nodeid: str) -> str:
    """The unit a test is scheduled with: its ``SCHEDULING_UNITS`` entry, else its file."""
    for prefix, unit in SCHEDULING_UNITS.items():
        if nodeid.startswith(prefix):
            return nodeid if unit is None else unit
    return nodeid.split("::", 1)[0]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The units holding a ``slow`` test first, each kept in collection order: the workers
    start on the long Monte Carlo and command-line files and end on the many short unit-test
    files, which even out their ends (a long file collected late, as ``test_readme.py``'s
    two minutes of commands were, leaves one worker running it alone)."""
    slow = {scheduling_unit(i.nodeid) for i in items if i.get_closest_marker("slow")}
    items.sort(key=lambda i: scheduling_unit(i.nodeid) not in slow)


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """``--dist loadfile`` with the units of ``SCHEDULING_UNITS``: a file's tests stay on one
    worker (its module fixtures, Monte Carlo runs, are computed once), and so do the tests
    that fill one cache from several files."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    # units go out in collection order, the slow ones first (pytest_collection_modifyitems);
    # xdist's default order (most tests first) would leave the long few-test files to the
    # end, one worker running alone
    config.option.loadscopereorder = False

    class UnitScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return scheduling_unit(nodeid)

    return UnitScheduling(config, log)


def pytest_configure(config: pytest.Config) -> None:
    # the controller sets this before it starts the workers, which inherit it (as do the Dask
    # and CLI processes they start); a value the user exported is kept
    workers = getattr(config.option, "numprocesses", None)
    if isinstance(workers, int) and workers > 1 and "PYTEST_XDIST_WORKER" not in os.environ:
        share = str(max(1, usable_cpus() // workers))
        for var in BLAS_THREADS:
            os.environ.setdefault(var, share)


def fd_jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float = 1e-6,
                diff: Callable | None = None, floor: float = 1.0):
    """Central finite-difference Jacobian of ``fun`` at the single point ``x`` (shape (n,)).

    The step is relative, ``h * max(floor, |x_i|)``; all 2n perturbed points are evaluated in one
    vectorised call, shape ``(2n, n)``. ``diff(a, b)`` forms ``a - b`` (pass a sensor's
    ``residual`` so that an angle crossing the +-pi cut is differenced on the circle).
    ``floor`` sets the smallest step scale (a sensor's geometry scale, so that a small
    component such as a depth offset is not differenced with a step far below rounding).
    Returns ``(m, n)``.
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    step = h * np.maximum(floor, np.abs(x))
    E = np.eye(n) * step
    pts = np.concatenate([x + E, x - E], axis=0)
    vals = np.asarray(fun(pts))
    d = (vals[:n] - vals[n:]) if diff is None else np.asarray(diff(vals[:n], vals[n:]))
    return (d / (2 * step[:, None])).T


def fd_hessian_from_jacobian(jac: Callable[[np.ndarray], np.ndarray], x: np.ndarray,
                             h: float = 1e-6, floor: float = 1.0):
    """Central differences of an analytic Jacobian ``jac`` (``(n,) -> (m, n)``) at ``x``:
    returns ``(m, n, n)`` with ``out[i, j, k] = d^2 h_i / dx_j dx_k``."""
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    step = h * np.maximum(floor, np.abs(x))
    cols = []
    for k in range(n):
        e = np.zeros(n)
        e[k] = step[k]
        Jp = np.asarray(jac(x + e))
        Jm = np.asarray(jac(x - e))
        Jp = np.broadcast_to(Jp, Jp.shape[-2:])
        Jm = np.broadcast_to(Jm, Jm.shape[-2:])
        cols.append((Jp - Jm) / (2 * step[k]))
    return np.stack(cols, axis=-1)  # (m, n, n) with last index k


def fd_hessian_direct(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float = 1e-4,
                      diff: Callable | None = None, floor: float = 1.0):
    """Second-order central differences of ``fun`` itself (no Jacobian used): ``(m, n, n)``;
    ``diff`` as for :func:`fd_jacobian`."""
    diff = (lambda a, b: a - b) if diff is None else diff
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    step = h * np.maximum(floor, np.abs(x))
    m = np.asarray(fun(x[None]))[0].shape[-1]
    H = np.zeros((m, n, n))
    for j in range(n):
        for k in range(n):
            ej = np.zeros(n)
            ek = np.zeros(n)
            ej[j] = step[j]
            ek[k] = step[k]
            pts = np.stack([x + ej + ek, x + ej - ek, x - ej + ek, x - ej - ek])
            v = np.asarray(fun(pts))
            H[:, j, k] = (diff(v[0], v[1]) - diff(v[2], v[3])) / (4 * step[j] * step[k])
    return H


def assert_close_scaled(actual, expected, rtol: float, atol: float = 0.0, what: str = "",
                        per_row: bool = False):
    """``|actual - expected| <= atol + rtol * scale`` elementwise, with a readable message.

    ``scale`` is ``max|expected|`` over the whole array, or, with ``per_row``, over each slice
    along the first axis (one measurement component of a Jacobian ``(m, n)`` or Hessian
    ``(m, n, n)``), so that a row of small entries (a bearing at long range next to a range)
    is held to its own magnitude. Zero entries of a Jacobian are compared against the scale.
    """
    actual = np.asarray(actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    if per_row and expected.ndim >= 2:
        axes = tuple(range(1, expected.ndim))
        scale = np.max(np.abs(expected), axis=axes, keepdims=True)
    else:
        scale = np.max(np.abs(expected)) if expected.size else 0.0
    err = np.abs(actual - expected)
    tol = atol + rtol * scale
    bad = ~(err <= tol)  # nan anywhere is a failure too
    assert not np.any(bad), (
        f"{what}: {int(bad.sum())} entries off, max abs error {float(np.max(err)):.3e}"
        f"\nactual=\n{actual}\nexpected=\n{expected}"
    )


def random_spd(rng: np.random.Generator, shape: tuple[int, ...], n: int, cond: float = 1e3):
    """Random symmetric positive-definite matrices of shape ``shape + (n, n)``.

    Eigenvalues log-uniform in [1, cond] times a random orthogonal basis; exactly symmetric.
    """
    A = rng.standard_normal(shape + (n, n))
    Qm, _ = np.linalg.qr(A)
    ev = np.exp(rng.uniform(0.0, np.log(cond), size=shape + (n,)))
    P = (Qm * ev[..., None, :]) @ np.swapaxes(Qm, -1, -2)
    return 0.5 * (P + np.swapaxes(P, -1, -2))


@pytest.fixture(scope="session")
def num() -> SimpleNamespace:
    """Numerical helpers: ``num.jac``, ``num.hess``, ``num.hess2``, ``num.close``, ``num.spd``."""
    return SimpleNamespace(
        jac=fd_jacobian,
        hess=fd_hessian_from_jacobian,
        hess2=fd_hessian_direct,
        close=assert_close_scaled,
        spd=random_spd,
    )
