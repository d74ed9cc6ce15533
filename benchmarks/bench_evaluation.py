"""Evaluation against filtering on a Monte Carlo comparison: what the metrics cost.

    python benchmarks/bench_evaluation.py [--scenario bo-cv] [--runs 1000] [--repeat 3]
                                          [--filters EKF,IEKF,UKF,CKF] [--before REF]
    python benchmarks/bench_evaluation.py --short-runs 20 [--scenario bo-cv]

In one process, block by block (the scenario's ``run.block`` runs each), the block is
simulated once and every filter is run over it, its estimates and innovations recorded; then
the two stages are timed apart, best of ``repeat``, interleaved:

* filtering: each filter's ``predict`` + ``update`` (what ``seconds_per_step`` counts) and its
  ``estimate`` (belief to mean and covariance), over the block;
* evaluation: what ``run_block`` does with those estimates (``MonteCarloMetrics.add`` per
  step with the innovation, the gap accumulator, the PCRLB's information and gradient sums)
  and, once for all blocks, ``combine`` (merging the blocks' accumulators, summaries, the
  bound series).

The evaluation is timed for the working tree's code ("after") and, with ``--before REF``
(default: the commit before the exact accumulation of the metrics), for that commit's
``eval/metrics.py`` and ``eval/montecarlo.py`` loaded from git, on the same recorded
estimates; both results are compared (largest relative difference of the per-step RMSE,
NEES and NIS). Prints the split and the ratio evaluation / filtering, for all the filters
and for each one.

``--short-runs N`` instead times a short comparison (``trackkit run NAME --runs N`` without
the CLI) against writing its report files.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np

import trackkit.experiments.montecarlo as after_mc
import trackkit.scenario as S
from trackkit.belief import Gaussian, Innovation
from trackkit.experiments.montecarlo import filter_rng, plan_of, with_run
from trackkit.scenario.simulate import simulate_block

ROOT = Path(__file__).resolve().parents[1]
#: the commit before the evaluation work (exact accumulation of every term)
BEFORE = "dd01dab"


def _load_before(ref: str) -> types.ModuleType | None:
    """HEAD-at-``ref`` ``montecarlo`` module, wired to that commit's ``metrics`` module."""
    try:
        src = {name: subprocess.run(
            ["git", "show", f"{ref}:src/trackkit/eval/{name}.py"], cwd=ROOT, check=True,
            capture_output=True, text=True).stdout for name in ("metrics", "montecarlo")}
    except (OSError, subprocess.CalledProcessError) as exc:
        print(f"(no 'before' code: git show {ref} failed: {exc})", file=sys.stderr)
        return None
    mods = {}
    for name in ("metrics", "montecarlo"):
        text = src[name].replace("from trackkit.eval.metrics import",
                                 "from _before_metrics import")
        mod = types.ModuleType(f"_before_{name}")
        mod.__file__ = f"<{ref}:eval/{name}.py>"
        sys.modules[mod.__name__] = mod
        exec(compile(text, mod.__file__, "exec"), mod.__dict__)
        mods[name] = mod
    return mods["montecarlo"]


def _pcrlb_ingredients_before(plan, data, groups):
    """``run_block``'s PCRLB sums as they were at the 'before' commit (a loop per step)."""
    T, n, d = plan.steps, plan.n, plan.dim
    B = data.truth.shape[1]
    info = np.empty((T, n, n))
    for k in range(T):
        sensor = plan.sensors[k]
        H = np.broadcast_to(sensor.jacobian(data.truth[k + 1]), (B, sensor.dim_z, n))
        RinvH = np.linalg.solve(sensor.noise, H)
        info[k] = plan.p_detect * np.einsum("bmi,bmj->ij", H, RinvH)
    grads = {g: np.stack([after_mc._derived_gradient(g, d, n, data.truth[k + 1],
                                                     plan.observer_states[0, k + 1, :2]).sum(0)
                          for k in range(T)])
             for g in groups if g in ("speed", "course", "bearing")}
    return info, grads


def record(plan, block: int, names: list[str]):
    """Simulate block ``block`` and run the filters ``names`` over it; returns the data,
    each filter's per-step (mean, cov, residual, innovation cov) and the filtering times."""
    s = plan.scenario
    r0, r1 = block * s.run.block, min(s.run.runs, (block + 1) * s.run.block)
    t0 = time.perf_counter()
    data = simulate_block(plan, r0, r1)
    if plan.gap_mask is not None:
        data.z[plan.gap_mask] = np.nan
    sim = time.perf_counter() - t0
    recs, secs = {}, {}
    for i, (name, f, motion, (mean0, P0)) in enumerate(zip(
            plan.filter_names, plan.filters, plan.filter_motions, plan.priors, strict=True)):
        if name not in names:
            continue
        n = plan.n
        L0 = np.linalg.cholesky(P0)
        m0 = (data.truth[0] + data.prior_offset @ L0.T) if mean0 is None else (
            np.broadcast_to(mean0, (r1 - r0, n)).copy())
        prior = Gaussian(m0, np.broadcast_to(P0, (r1 - r0, n, n)).copy())
        b = f.init(prior, rng=filter_rng(s.run.seed, block, i)) if getattr(
            f, "stochastic", False) else f.init(prior)
        steps, pu, est = [], 0.0, 0.0
        for k in range(plan.steps):
            sensor = plan.filter_sensor(i, k)
            t0 = time.perf_counter()
            b = f.predict(b, motion, plan.times[k + 1] - plan.times[k])
            b, innov = f.update(b, data.z[k], sensor)
            t1 = time.perf_counter()
            g = f.estimate(b)
            est += time.perf_counter() - t1
            pu += t1 - t0
            steps.append((np.array(g.mean), np.array(g.cov), np.array(innov.nu),
                          np.array(innov.cov)))
        recs[name] = steps
        secs[name] = (pu, est)
    return data, recs, secs, sim


def evaluate(mc, plan, block: int, data, recs, pcrlb) -> tuple[object, dict[str, float]]:
    """What ``run_block`` of module ``mc`` does with recorded estimates: a BlockResult and
    the seconds per part (each filter's metrics, the PCRLB sums)."""
    s = plan.scenario
    groups = mc.groups_for(plan)
    angular = None
    if s.report.angle_states:
        angular = tuple(j in s.report.angle_states for j in range(plan.n))
    windows = mc._gap_windows(plan)
    metrics, gaps, secs = {}, {}, {}
    B = data.truth.shape[1]
    for name, steps in recs.items():
        t0 = time.perf_counter()
        acc = mc.MonteCarloMetrics(groups=groups, angular=angular)
        gap = mc._GapAccumulator(groups, windows, B, plan.steps, False, angular)
        window = mc._StepWindow(acc, plan, data.truth, groups) if hasattr(
            mc, "_StepWindow") else None  # the engine's window of steps (after)
        for k, (mean, cov, res, S_) in enumerate(steps):
            g, innov = Gaussian._make((mean, cov)), Innovation(res, S_)
            if window is not None:
                window.add(k, g, innov)
            if "bearing" in groups:
                groups["bearing"].origin = plan.observer_states[0, k + 1, :2]
            if window is None:
                acc.add(k, data.truth[k + 1], g, innov)
            gap.add(k, data.truth[k + 1], mean, None)  # no gap handler: no belief used
        if window is not None:
            window.flush()
        metrics[name], gaps[name] = acc, gap.result(None)
        secs[name] = time.perf_counter() - t0
    t0 = time.perf_counter()
    info, grads = pcrlb(plan, data, groups)
    secs["PCRLB sums"] = time.perf_counter() - t0
    part = mc.BlockResult(block, B, metrics, {n: 0.0 for n in recs}, info, grads, None, None,
                          None, gaps, {})
    return part, secs


def short(name: str, runs: int, repeat: int) -> None:
    """A short run as ``trackkit run NAME --runs RUNS`` does it: the comparison, then every
    report file (results.json, metrics.parquet, plots, report.html); best of ``repeat``."""
    import tempfile

    from trackkit.experiments.compare import compare
    from trackkit.report.files import write_report

    sc = S.load(name)
    best = {"compute": np.inf, "report": np.inf}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeat):
            t0 = time.perf_counter()
            result = compare(sc, runs=runs)
            t1 = time.perf_counter()
            write_report(result, Path(tmp) / "out")
            t2 = time.perf_counter()
            best["compute"] = min(best["compute"], t1 - t0)
            best["report"] = min(best["report"], t2 - t1)
    total = best["compute"] + best["report"]
    print(f"{name} --runs {runs}, best of {repeat}, load average {os.getloadavg()[0]:.1f}: "
          f"comparison {best['compute']:.2f} s, report files {best['report']:.2f} s "
          f"({best['report'] / total:.0%} of the two)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="bo-cv")
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--filters", default=None, help="comma-separated (default: all)")
    ap.add_argument("--before", default=BEFORE, help="git ref of the 'before' code, or ''")
    ap.add_argument("--short-runs", type=int, default=0,
                    help="instead: time a short comparison of this many runs (compute, as "
                         "trackkit run does it) against writing its report files")
    a = ap.parse_args()
    if a.short_runs:
        short(a.scenario, a.short_runs, a.repeat)
        return

    sc = with_run(S.load(a.scenario), a.runs, None)
    names = [f.name for f in sc.filters]
    if a.filters:
        want = a.filters.split(",")
        unknown = set(want) - set(names)
        if unknown:
            raise SystemExit(f"unknown filters {sorted(unknown)}; the scenario has {names}")
        d = sc.model_dump()
        d["filters"] = [f for f in d["filters"] if f["name"] in want]
        sc = S.parse(d, a.scenario)
        names = want
    plan = plan_of(sc)
    impls = {"after": (after_mc, (lambda p, data, g: after_mc._pcrlb_ingredients(
        p, data.truth, g)) if hasattr(after_mc, "_pcrlb_ingredients")
        else _pcrlb_ingredients_before)}
    before = _load_before(a.before) if a.before else None
    if before is not None:
        impls = {"before": (before, _pcrlb_ingredients_before), **impls}

    nblocks = -(-sc.run.runs // sc.run.block)
    sim_total = 0.0
    filt = {n: np.zeros(2) for n in names}  # best predict+update, best estimate, summed
    ev = {k: {} for k in impls}  # impl -> part -> best seconds summed over blocks
    parts = {k: [] for k in impls}
    for blk in range(nblocks):
        best_f = {n: np.full(2, np.inf) for n in names}
        best_e = {k: {} for k in impls}
        sim_best = np.inf
        for rep in range(a.repeat):
            data, recs, secs, sim = record(plan, blk, names)
            sim_best = min(sim_best, sim)
            for n in names:
                best_f[n] = np.minimum(best_f[n], secs[n])
            for key, (mc, pcrlb) in impls.items():
                part, es = evaluate(mc, plan, blk, data, recs, pcrlb)
                for p, v in es.items():
                    best_e[key][p] = min(best_e[key].get(p, np.inf), v)
                if rep == 0:
                    parts[key].append(part)
            del recs
        sim_total += sim_best
        for n in names:
            filt[n] += best_f[n]
        for key in impls:
            for p, v in best_e[key].items():
                ev[key][p] = ev[key].get(p, 0.0) + v
        print(f"block {blk + 1}/{nblocks} done", file=sys.stderr)
    results = {}
    for key, (mc, _) in impls.items():
        best = np.inf
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            results[key] = mc.combine(sc, parts[key])
            best = min(best, time.perf_counter() - t0)
        ev[key]["combine"] = best

    filtering = sum(v.sum() for v in filt.values())
    print(f"machine: {platform.machine()} {platform.processor() or ''}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}; Python {platform.python_version()}, "
          f"numpy {np.__version__}")
    print(f"{sc.name}: {sc.run.runs} runs in blocks of {sc.run.block}, {plan.steps} steps, "
          f"filters {names}; best of {a.repeat} per block, summed over the blocks\n")
    print(f"simulation: {sim_total:.3f} s")
    print(f"filtering (predict + update + estimate): {filtering:.3f} s")
    cols = list(impls)
    print("\n| part | " + " | ".join(f"{c} (s)" for c in cols) + " |")
    print("|---|" + "---:|" * len(cols))
    print("| filtering, all filters | " + " | ".join(f"{filtering:.3f}" for _ in cols) + " |")
    rows = [*names, "PCRLB sums", "combine"]
    for r in rows:
        print(f"| evaluation: {r} | " + " | ".join(f"{ev[c].get(r, np.nan):.3f}" for c in cols)
              + " |")
    tot = {c: sum(ev[c].values()) for c in cols}
    print("| **evaluation, total** | " + " | ".join(f"**{tot[c]:.3f}**" for c in cols) + " |")
    print("| **evaluation / filtering** | "
          + " | ".join(f"**{tot[c] / filtering:.1%}**" for c in cols) + " |")
    print("\nper filter (its metrics / its filtering; the PCRLB sums and combine are shared):")
    print("| filter | filtering (s) | " + " | ".join(f"{c} metrics (s) | {c} ratio" for c in cols)
          + " |")
    print("|---|---:|" + "---:|---:|" * len(cols))
    for n in names:
        fs = filt[n].sum()
        print(f"| {n} | {fs:.3f} | " + " | ".join(
            f"{ev[c][n]:.3f} | {ev[c][n] / fs:.1%}" for c in cols) + " |")
    if len(cols) == 2:
        r0, r1 = (results[c] for c in cols)
        worst = 0.0
        for n in names:
            f0, f1 = r0.filters[n], r1.filters[n]
            pairs = [(f0.rmse[g], f1.rmse[g]) for g in f0.rmse]
            pairs += [(f0.nees, f1.nees), (f0.nis, f1.nis)]
            for x, y in pairs:
                ok = np.isfinite(x) & (x != 0)
                worst = max(worst, float(np.max(np.abs(x[ok] - y[ok]) / np.abs(x[ok]),
                                                initial=0.0)))
        print(f"\nlargest relative difference before/after (per-step RMSE, NEES, NIS): "
              f"{worst:.2e}")


if __name__ == "__main__":
    main()
