"""GOSPA speed against Stone Soup's GOSPAMetric, measured in one process.

Truths spread uniformly over a 10 km square; the estimates are 90% of the truths plus
N(0, 30 m) noise per axis, and 10% clutter, so n = m. Cases: 200 x 200 and 1000 x 1000 points
with a 100 m cut-off (the "within c" graph falls apart into small components) and with a
50 km cut-off (every pair within c: one dense assignment); and Monte Carlo-sized steps, about
10 truths and 14 estimates each, where trackkit does all steps in one call and Stone Soup one
step at a time. The two agree to 1e-9 on every case (checked here); the ratio is Stone Soup's
time over trackkit's (per step for the many-step case).

    python benchmarks/bench_metrics_multitarget.py [--repeat 5] [--no-large]
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import time

import numpy as np
from stonesoup.metricgenerator.ospametric import GOSPAMetric
from stonesoup.types.state import State

from trackkit.eval.track_metrics import frames, gospa, gospa_steps

T0 = datetime.datetime(2024, 1, 1)
SIDE = 10_000.0


def point_sets(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    x = rng.uniform(0, SIDE, (n, 2))
    kept = int(round(0.9 * n))
    y = np.vstack([x[:kept] + rng.normal(0, 30.0, (kept, 2)), rng.uniform(0, SIDE, (n - kept, 2))])
    return x, y


def states(pts: np.ndarray) -> list[State]:
    return [State(v.reshape(-1, 1), timestamp=T0) for v in pts]


def best_time(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bench_one(n: int, c: float, repeat: int, ss_repeat: int, rng) -> tuple[str, float, float]:
    x, y = point_sets(n, rng)
    sx, sy = states(x), states(y)
    metric = GOSPAMetric(c=c, p=2.0)
    ref = metric.compute_gospa_metric(sy, sx)[0].value["distance"]
    ours = gospa(x, y, c, 2.0).distance
    assert abs(ours - ref) <= 1e-9 * max(1.0, ref), (ours, ref)
    t_ss = best_time(lambda: metric.compute_gospa_metric(sy, sx), ss_repeat)
    t_tk = best_time(lambda: gospa(x, y, c, 2.0), repeat)
    return f"{n} x {n}, c = {c:g} m", t_ss, t_tk


def bench_steps(steps: int, ss_steps: int, c: float, repeat: int, rng) -> tuple[str, float, float]:
    n, m = rng.poisson(10, steps), rng.poisson(14, steps)
    xs = [rng.uniform(0, 3000.0, (k, 2)) for k in n]
    ys = [rng.uniform(0, 3000.0, (k, 2)) for k in m]
    X, Y = frames(xs, dim=2), frames(ys, dim=2)
    metric = GOSPAMetric(c=c, p=2.0)
    r = gospa_steps(X, Y, c, 2.0)
    pairs = [(states(xs[s]), states(ys[s])) for s in range(ss_steps)]
    for s in range(ss_steps):
        if n[s] + m[s]:
            ref = metric.compute_gospa_metric(pairs[s][1], pairs[s][0])[0].value["distance"]
            assert abs(r.distance[s] - ref) <= 1e-9 * max(1.0, ref)

    def run_ss():
        for sx, sy in pairs:
            if sx or sy:
                metric.compute_gospa_metric(sy, sx)

    t_ss = best_time(run_ss, 1) / ss_steps
    t_tk = best_time(lambda: gospa_steps(X, Y, c, 2.0), repeat) / steps
    return f"{steps} steps of ~10 x 14, c = {c:g} m (per step)", t_ss, t_tk


def fmt(t: float) -> str:
    if t >= 1.0:
        return f"{t:.3g} s"
    return f"{t * 1e3:.3g} ms" if t >= 1e-3 else f"{t * 1e6:.3g} us"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-large", action="store_true", help="skip 1000 x 1000 (Stone Soup ~15 s)")
    args = ap.parse_args()
    rng = np.random.default_rng(2026)

    rows = [bench_one(200, 100.0, args.repeat, 3, rng), bench_one(200, 5e4, args.repeat, 3, rng)]
    if not args.no_large:
        rows += [bench_one(1000, 100.0, args.repeat, 1, rng)]
        rows += [bench_one(1000, 5e4, args.repeat, 1, rng)]
    rows += [bench_steps(20_000, 300, 500.0, args.repeat, rng)]

    print(
        f"GOSPA (p = 2, alpha = 2): trackkit against Stone Soup GOSPAMetric; "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"Python {platform.python_version()}, numpy {np.__version__}\n"
    )
    print("| case | Stone Soup | trackkit | ratio |")
    print("|---|---:|---:|---:|")
    for name, t_ss, t_tk in rows:
        print(f"| {name} | {fmt(t_ss)} | {fmt(t_tk)} | {t_ss / t_tk:,.0f}x |")


if __name__ == "__main__":
    main()
