"""Tests of the report stage and the CLI; ``fake_result`` builds a MonteCarloResult by hand."""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from trackkit.experiments.results import Example, FilterResult, MonteCarloResult

FILTERS = ("EKF", "UKF")
GROUPS = {"position": "m", "velocity": "m/s", "course": "rad"}


def _bounds(runs: int, dof: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    lo = chi2.ppf(0.025, runs * dof) / runs
    hi = chi2.ppf(0.975, runs * dof) / runs
    return np.full(steps, lo), np.full(steps, hi)


def fake_result(steps: int = 50, runs: int = 20, example: bool = True,
                seed: int = 7) -> MonteCarloResult:
    """A 2-filter comparison on a 2-D constant-velocity target seen from a zig-zag observer."""
    rng = np.random.default_rng(seed)
    dt = 2.0
    t = np.arange(steps) * dt
    decay = np.exp(-t / 30.0)
    bound = {"position": 40 + 400 * decay, "velocity": 0.5 + 5 * decay,
             "course": np.deg2rad(1 + 10 * decay)}
    filters = {}
    for i, name in enumerate(FILTERS):
        scale = 1.1 + 0.3 * i
        rmse = {g: b * scale * (1 + 0.05 * rng.standard_normal(steps)) for g, b in bound.items()}
        nees = 4 * (1 + 0.3 * i) * (1 + 0.1 * rng.standard_normal(steps))
        nis = 1 + 0.1 * rng.standard_normal(steps)
        nis[::10] = np.nan  # missing measurements
        filters[name] = FilterResult(
            name=name, rmse=rmse, rmse_mean={g: float(v[10:].mean()) for g, v in rmse.items()},
            nees=nees, nis=nis, nees_bounds=_bounds(runs, 4, steps),
            nis_bounds=_bounds(runs, 1, steps), anees=float(nees[10:].mean()),
            anis=float(np.nanmean(nis[10:])), nees_in_bounds=0.9 - 0.4 * i,
            nis_in_bounds=0.95, diverged=i, seconds_per_step=3e-6 * (1 + 4 * i))
    ex = None
    if example:
        truth = np.column_stack([3000 + 5 * t, 8000 - 3 * t, np.full(steps, 5.0),
                                 np.full(steps, -3.0)])
        observer = np.column_stack([4 * t, 1000 * np.abs(np.sin(t / 40))])
        estimates = {}
        for i, name in enumerate(FILTERS):
            sd = bound["position"] * (1 + 0.3 * i) / np.sqrt(2)
            means = truth + np.column_stack([sd * rng.standard_normal(steps),
                                             sd * rng.standard_normal(steps),
                                             np.zeros(steps), np.zeros(steps)])
            covs = np.zeros((steps, 4, 4))
            covs[:, 0, 0] = (2 * sd) ** 2
            covs[:, 1, 1] = (0.5 * sd) ** 2
            covs[:, 0, 1] = covs[:, 1, 0] = 0.5 * (2 * sd) * (0.5 * sd)
            covs[:, 2, 2] = covs[:, 3, 3] = 1.0
            estimates[name] = (means, covs)
        ex = Example(times=t, truth=truth, observer=observer, estimates=estimates)
    return MonteCarloResult(
        scenario="fake_bot", description="A hand-made bearings-only comparison for tests.",
        runs=runs, seed=seed, steps=steps, dt=dt, times=t, start=10, groups=dict(GROUPS),
        filters=filters, pcrlb=bound,
        pcrlb_mean={g: float(b[10:].mean()) for g, b in bound.items()},
        example=ex, notes=["PCRLB assumes the prior covariance of the scenario.",
                           "<script>alert(1)</script> notes are escaped"])
