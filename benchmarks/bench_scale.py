"""The tracker from 1 000 to 100 000 spread-out targets: one scan, GNN and JPDA, and the
share of it the Python interpreter takes.

Scenes are those of ``bench_tracker.py`` (one target per 300 m x 300 m, a position radar of
sigma 20 m, 2 s scans, 20 clutter plots, P_G 0.99; every track confirmed and 8 scans old, so
its covariance and gate are the filter's own; every target detected in the timed scan). One
scan is ``Tracker.step`` (predict, measurement prediction, KD-tree gate, association,
update, logic, initiation); ``assoc`` is the association alone on that scan's gate
(``loglik_costs`` + ``gnn_assign``, or ``jpda_probabilities``).

Python share: the fraction of the scan's CPU samples (``perf record -F 1999`` attached to this
process while the scan runs in a loop) whose innermost frame is in the interpreter,
``libpython``: bytecode evaluation, calls, attribute look-ups, object allocation and reference
counting, rather than numpy, scipy, numba-compiled code, BLAS, libc or the kernel. It leaves
out the part of a numpy call's own overhead (argument parsing, array creation) spent inside
numpy, so the script also counts the Python-level and C-level calls of one scan (cProfile):
a loop over clusters shows as calls growing with the targets. Without ``perf`` the share is
not measured.

Timings are the best of ``--repeat`` rounds, GNN and JPDA in turn within each round.

    python benchmarks/bench_scale.py [--sizes 1000 3000 10000 30000 100000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))

from bench_tracker import DT, Scene, best_of, machine  # noqa: E402

from trackkit.tracking import gate, gnn_assign  # noqa: E402
from trackkit.tracking.association import jpda_probabilities, loglik_costs  # noqa: E402
from trackkit.tracking.tracker import GNN, JPDA  # noqa: E402

INTERPRETER = ("libpython", "python3")  # the shared objects of the interpreter


def python_share(fn, seconds: float) -> float:
    """Fraction of perf's samples of ``fn`` (looped for ``seconds``) in the interpreter."""
    perf = shutil.which("perf")
    if perf is None:
        return float("nan")
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        rec = subprocess.Popen([perf, "record", "-q", "-F", "1999", "-p", str(os.getpid()),
                                "-o", data], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
        time.sleep(0.5)  # perf attaches
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            fn()
        rec.send_signal(signal.SIGINT)
        rec.wait()
        out = subprocess.run([perf, "report", "-i", data, "--sort", "dso", "--stdio", "-q",
                              "--no-children", "-g", "none"], capture_output=True, text=True,
                             check=False).stdout
    share = total = 0.0
    for line in out.splitlines():
        parts = line.split()
        if len(parts) < 2 or not parts[0].endswith("%"):
            continue
        pct = float(parts[0].rstrip("%"))
        total += pct
        if any(parts[1].startswith(name) for name in INTERPRETER):
            share += pct
    return share / total if total else float("nan")


def calls(fn) -> int:
    """Function calls (Python and C) of one ``fn()``, by cProfile."""
    pr = cProfile.Profile()
    pr.enable()
    fn()
    pr.disable()
    return pstats.Stats(pr).total_calls


def row(n: int, repeat: int, perf_seconds: float) -> str:
    sc = Scene(n)
    trk = {"GNN": sc.tracker(GNN()), "JPDA": sc.tracker(JPDA())}
    b = trk["GNN"].filter.predict(sc.tracks.belief, sc.motion, DT)
    zhat, S = trk["GNN"].measurement_prediction(b, sc.sensor)
    g = gate(zhat, S, sc.z, trk["GNN"].p_gate)
    pd, cd = trk["GNN"].pd, trk["GNN"].clutter_density
    step = {k: (lambda t=t: t.step(sc.tracks, sc.scan)) for k, t in trk.items()}
    assoc = {"GNN": lambda: gnn_assign(g, loglik_costs(g, pd, cd)),
             "JPDA": lambda: jpda_probabilities(g, pd, cd)}
    t_step = dict.fromkeys(trk, np.inf)
    t_assoc = dict.fromkeys(trk, np.inf)
    for _ in range(repeat):  # interleaved: a change of load hits both alike
        for k in trk:
            t_step[k] = min(t_step[k], best_of(step[k], 1))
            t_assoc[k] = min(t_assoc[k], best_of(assoc[k], 1))
    cells = [f"{n:,}".replace(",", " "), str(g.size)]
    for k in trk:
        share = python_share(step[k], perf_seconds)
        cells += [f"{1e3 * t_step[k]:.1f}", f"{1e6 * t_step[k] / n:.2f}",
                  f"{1e3 * t_assoc[k]:.1f}", f"{100 * share:.1f}%", str(calls(step[k]))]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 3000, 10000, 30000, 100000])
    ap.add_argument("--repeat", type=int, default=5, help="best of this many rounds")
    ap.add_argument("--perf-seconds", type=float, default=3.0,
                    help="seconds of scans sampled by perf per size and associator")
    a = ap.parse_args()
    print(f"Machine: {machine()}; load average {os.getloadavg()[0]:.2f} at the start")
    print("\n| targets | gated pairs | GNN ms/scan | GNN us/target | GNN assoc ms | GNN Python "
          "| GNN calls | JPDA ms/scan | JPDA us/target | JPDA assoc ms | JPDA Python "
          "| JPDA calls |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in a.sizes:
        print(row(n, a.repeat, a.perf_seconds), flush=True)
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
