"""Joint tracking and classification: speed against Stone Soup's multi-model particle filter,
and the single filter against the multi-filter baseline, measured in one process.

The problem is jtc-fighter's (Hosseini, Haeri and Khaloozadeh 2019): a target at 340 m/s with two 3
deg/s turns, a range-bearing radar at the origin (20 m, 0.2 deg), 1 s scans. Stone Soup runs one
problem with ``MultiModelPredictor`` and ``MultiModelParticleUpdater`` (systematic resampling every
step) at 5 000 particles over five linear models (a constant velocity and four known turn
rates, +-0.5 and +-1 deg/s: Stone Soup has no acceleration input for a CA mode; the models
cost the same, one matrix product each) with the paper's 0.6/0.1 transition; per step
``predict``, ``update`` and the particles' mean. trackkit runs ``JTC`` and
``MultiFilterJTC`` at 5 000 particles per class (two classes: 10 000 particles per run)
batched over ``--runs`` runs, ``predict``, ``update`` and ``estimate`` per step, and reports
the time per run-step; also ``JTC`` at half the particles per class, where it matches the
baseline's accuracy on the bundled scenarios (docs/jtc-comparison.md), and trackkit's
bootstrap ``PF`` at 5 000 particles with one constant-velocity model of the same noise
(q = 100 m^2/s^3) and systematic resampling at every step, as Stone Soup's. Timings are the
best of ``--repeat`` interleaved repetitions.

    python benchmarks/bench_jtc.py [--runs 100] [--steps 30] [--repeat 3]
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import time

import numpy as np

import trackkit as tk
from trackkit.filters.jtc import JTC, MultiFilterJTC
from trackkit.filters.particle import PF
from trackkit.models.classes import mode_step

DT = 1.0
SIGMA_R, SIGMA_B = 20.0, math.radians(0.2)
X0 = np.array([-20000.0, 30000.0, 340.0, 0.0])
P0 = np.diag([100.0, 100.0, 30.0, 30.0]) ** 2
P = np.full((5, 5), 0.1) + 0.5 * np.eye(5)


def truth(steps: int) -> np.ndarray:
    """``(steps + 1, 4)`` jtc-fighter's path: right turn at 3 deg/s from 25 to 40 s, left
    from 60 to 75 s (nautical turns are clockwise: omega = -3 deg/s counter-clockwise)."""
    x = [X0]
    for k in range(steps):
        omega = -math.radians(3.0) if 25 <= k < 40 else math.radians(3.0) if 60 <= k < 75 else 0
        x.append(mode_step(x[-1], omega, 0.0, DT))
    return np.array(x)


def plots(x: np.ndarray, runs: int, rng: np.random.Generator) -> np.ndarray:
    """``(steps, runs, 2)`` range and nautical bearing plots of the true path."""
    r = np.hypot(x[1:, 0], x[1:, 1])
    b = np.arctan2(x[1:, 0], x[1:, 1])
    z = np.stack([r, b], -1)[:, None, :] + rng.standard_normal((len(r), runs, 2)) * [
        SIGMA_R, SIGMA_B]
    return z


def trackkit_run(f, z: np.ndarray, rng: np.random.Generator,
                 motion=None) -> tuple[float, np.ndarray]:
    """Seconds per step (predict, update, estimate) over all steps, and the estimates
    (``motion``: the PF's model; the JTC filters carry their classes' modes)."""
    runs = z.shape[1]
    m0 = X0 + rng.standard_normal((runs, 4)) @ np.sqrt(P0)
    b = f.init(tk.Gaussian(m0, np.broadcast_to(P0, (runs, 4, 4))),
               rng=np.random.default_rng(1))
    sensor = tk.models.RangeBearing(origin=[0.0, 0.0], sigma_range=SIGMA_R,
                                    sigma_bearing=SIGMA_B)
    est = np.empty((len(z), runs, 4))
    t0 = time.perf_counter()
    for k in range(len(z)):
        b = f.predict(b, motion, DT)
        b, _ = f.update(b, z[k], sensor)
        est[k] = f.estimate(b).mean
    return (time.perf_counter() - t0) / len(z), est


def stonesoup_run(z: np.ndarray, n: int, rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """Seconds per step of Stone Soup's multi-model PF on the plots of run 0 (its bearing is
    counter-clockwise from east, its state [x, vx, y, vy]), and its estimates."""
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
        KnownTurnRate,
    )
    from stonesoup.predictor.particle import MultiModelPredictor
    from stonesoup.resampler.particle import SystematicResampler
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import MultiModelParticleState, StateVectors
    from stonesoup.updater.particle import MultiModelParticleUpdater

    q = 100.0  # (10 m/s^2)^2, the JTC's sigma = 10 m/s^2 as a white-acceleration density
    cv = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    models = [cv] + [KnownTurnRate([q, q], math.radians(w)) for w in (0.5, -0.5, 1.0, -1.0)]
    predictor = MultiModelPredictor(transition_models=models, transition_matrix=P,
                                    model_mappings=[[0, 1, 2, 3]] * 5)
    meas = CartesianToBearingRange(ndim_state=4, mapping=(0, 2),
                                   noise_covar=np.diag([SIGMA_B**2, SIGMA_R**2]))
    updater = MultiModelParticleUpdater(measurement_model=meas, predictor=predictor,
                                        resampler=SystematicResampler())
    t0 = datetime.datetime(2026, 1, 1)
    m0 = X0 + rng.standard_normal(4) @ np.sqrt(P0)
    x = m0[:, None] + np.sqrt(np.diag(P0))[:, None] * rng.standard_normal((4, n))
    state = MultiModelParticleState(StateVectors(x[[0, 2, 1, 3]]),
                                    log_weight=np.full(n, -math.log(n)),
                                    dynamic_model=np.zeros(n, dtype=int), timestamp=t0)
    est = np.empty((len(z), 4))
    start = time.perf_counter()
    for k in range(len(z)):
        r, b = z[k, 0]
        bearing = math.remainder(math.pi / 2 - b, 2 * math.pi)  # to (-pi, pi]
        det = Detection(np.array([[bearing], [r]]), measurement_model=meas,
                        timestamp=t0 + datetime.timedelta(seconds=(k + 1) * DT))
        prediction = predictor.predict(state, timestamp=det.timestamp)
        state = updater.update(SingleHypothesis(prediction, det))
        est[k] = np.asarray(state.mean, dtype=float).ravel()[[0, 2, 1, 3]]
    return (time.perf_counter() - start) / len(z), est


def _rmse(est: np.ndarray, x: np.ndarray) -> float:
    d = est[..., :2] - (x[1:, None, :2] if est.ndim == 3 else x[1:, :2])
    return float(np.sqrt(np.mean(np.sum(d * d, -1))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--particles", type=int, default=5000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores")
    x = truth(args.steps)
    z = plots(x, args.runs, np.random.default_rng(0))
    half = args.particles // 2
    variants = (("JTC", JTC(particles_per_class=args.particles)),
                ("MultiFilterJTC", MultiFilterJTC(particles_per_class=args.particles)),
                (f"JTC at {half}", JTC(particles_per_class=half)),
                (f"PF at {args.particles}", PF(args.particles, ess_threshold=1.0)))
    cv = tk.models.ConstantVelocity(dim=2, q=100.0)
    best = {"Stone Soup MMPF": math.inf} | {name: math.inf for name, _ in variants}
    errors = {}
    for _ in range(args.repeat):
        t, est = stonesoup_run(z, args.particles, np.random.default_rng(2))
        best["Stone Soup MMPF"] = min(best["Stone Soup MMPF"], t)
        errors["Stone Soup MMPF"] = _rmse(est, x)
        for name, f in variants:
            t, est = trackkit_run(f, z, np.random.default_rng(3),
                                  cv if isinstance(f, PF) else None)
            best[name] = min(best[name], t / args.runs)
            errors[name] = _rmse(est, x)
    ss = best["Stone Soup MMPF"]
    print(f"{args.steps} steps; Stone Soup: one run of {args.particles} particles; trackkit: "
          f"{args.runs} runs of {args.particles} particles per class (2 classes)")
    print(f"{'filter':<18}{'ms per run-step':>17}{'vs Stone Soup':>15}{'position RMSE':>15}")
    for name, t in best.items():
        print(f"{name:<18}{1e3 * t:>17.3f}{ss / t:>14.1f}x{errors[name]:>13.1f} m")
    print(f"single filter against the multi-filter baseline (equal particles per class): "
          f"{best['MultiFilterJTC'] / best['JTC']:.2f}x (the paper's Table 2: 113x); at half "
          f"the particles per class (equal accuracy on jtc-fighter and jtc-airliner): "
          f"{best['MultiFilterJTC'] / best[f'JTC at {half}']:.2f}x")


if __name__ == "__main__":
    main()
