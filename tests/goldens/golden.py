"""Golden runs: a small fixed-seed run of every bundled scenario, with its numbers checked in.

Each number is promised to a stated relative tolerance, the same on every CPU
(docs/architecture.md, Determinism): 1e-12, or, for a quantity whose own conditioning amplifies
rounding beyond that, 100 times its sensitivity to a one-ulp change of every input. The sensitivity
is measured when the goldens are made: the same run again with the simulated truth, the
measurements and the prior draws each multiplied by (1 + 2^-52), and by (1 - 2^-52), the
larger of the two (the goldens made before 2026-11-26 tried the first only, and pass on
AVX2 and AVX-512 CPUs as they are; a mis-specified Doppler-bearing scenario made that day
did not, until both signs were tried). Another CPU rounds
differently (numpy's SIMD loops and the BLAS kernels differ between AVX2 and AVX-512), which
is a rounding-level change of the same kind; a bearings-only filter whose runs diverge, or a
Doppler-bearing UKF with a poorly scaled covariance, turns it into 1e-10 or more, and no
tolerance of 1e-12 can hold there. The file lists every such quantity with its tolerance.
Particle filters run with at most ``PARTICLE_CAPS`` particles (per class for a classifier):
their goldens check the pipeline's numbers, the draws included, not the accuracy at full size.

Regenerate (after a deliberate change of numbers, with the reason in the commit message):

    python tests/goldens/golden.py

A change that must not move any number (a refactoring) is checked bit for bit, on one machine,
by dumping every golden's numbers with all their digits before and after it and comparing the
two files byte for byte:

    python tests/goldens/golden.py --dump before.json     # on the old commit
    python tests/goldens/golden.py --dump after.json      # on the new one
    cmp before.json after.json
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import trackkit.experiments.montecarlo as montecarlo
import trackkit.scenario as S
from trackkit.experiments.compare import compare

HERE = Path(__file__).parent
RUNS = 20
RTOL = 1e-12  # the promise for a well-conditioned quantity
MARGIN = 100.0  # times the measured one-ulp sensitivity, for an ill-conditioned one
ULP = 2.0**-52


#: particle counts in a golden run (per class for the classifying filters)
PARTICLE_CAPS = {"n_particles": 500, "particles_per_class": 250}


def _option_names(filter_type: str) -> set[str]:
    from trackkit.scenario.options import FILTER_TYPES

    return {o.name for o in FILTER_TYPES[filter_type].options}


def golden_numbers(name: str) -> dict:
    """The key numbers of a 20-run, block-10 run of a bundled scenario (timings left out)."""
    d = S.load(name).model_dump()
    d["run"].update(runs=RUNS, block=10)
    for f in d["filters"]:
        opts = f.setdefault("options", {})
        for key, cap in PARTICLE_CAPS.items():
            if key in _option_names(f["type"]):
                # a particle filter's golden checks its numbers, not its accuracy at full size
                opts[key] = min(opts.get(key, cap), cap)
        if f.get("tune") and not f["tune"].get("on"):
            # a short tuning: the golden checks the pipeline's numbers, not the optimiser
            f["tune"].update(runs=2, iterations=3, population=10)
    result = compare(S.parse(d, name))
    doc = result.to_json_dict()
    for f in doc["filters"].values():
        f.pop("seconds_per_step", None)
    for t in doc.get("tuning", {}).values():
        t.pop("seconds", None)
    doc["final_rmse"] = {n: {g: float(v[-1]) for g, v in f.rmse.items()}
                         for n, f in result.filters.items()}
    return doc


@contextmanager
def one_ulp_inputs(sign: float = 1.0) -> Iterator[None]:
    """Every simulated input of the Monte Carlo engine times (1 + sign 2^-52), while
    inside."""
    simulate = montecarlo.simulate_block

    def perturbed(*args: Any, **kwargs: Any):
        data = simulate(*args, **kwargs)
        for field in ("truth", "z", "prior_offset"):
            setattr(data, field, getattr(data, field) * (1.0 + sign * ULP))
        return data

    montecarlo.simulate_block = perturbed
    try:
        yield
    finally:
        montecarlo.simulate_block = simulate


def leaves(doc: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    """``(path, value)`` of every number, string and boolean in a JSON document."""
    if isinstance(doc, dict):
        for k in sorted(doc):
            yield from leaves(doc[k], f"{path}.{k}" if path else k)
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from leaves(v, f"{path}[{i}]")
    else:
        yield path, doc


def relative(a: float, b: float) -> float:
    if a == b or (math.isnan(a) and math.isnan(b)):
        return 0.0
    return abs(a - b) / max(abs(a), abs(b))


def tolerances(numbers: dict, *perturbed: dict) -> dict[str, float]:
    """The quantities that need more than ``RTOL``, with ``MARGIN`` x their sensitivity (the
    largest over the perturbed runs)."""
    others = [dict(leaves(p)) for p in perturbed]
    out = {}
    for path, value in leaves(numbers):
        if isinstance(value, float):
            sens = max(relative(value, o[path]) for o in others)
            tol = float(f"{MARGIN * sens:.1e}")  # two digits
            if tol > RTOL:
                out[path] = tol
    return out


def make(name: str) -> dict:
    """One direction of the perturbation can leave a quantity nearly unmoved by chance (a
    Doppler-bearing AMCEKF speed moved 3e-15 one way and 1.5e-12 on an AVX2 CPU), so both
    signs are tried."""
    numbers = golden_numbers(name)
    perturbed = []
    for sign in (1.0, -1.0):
        with one_ulp_inputs(sign):
            perturbed.append(golden_numbers(name))
    return {"numbers": numbers, "rtol": RTOL, "tolerance": tolerances(numbers, *perturbed)}


def dump(path: str) -> None:
    """Every golden's numbers with all their digits (``repr`` of each float), sorted, into
    ``path``: two dumps of one machine are byte-identical exactly when no number moved."""
    doc = {name: golden_numbers(name) for name in sorted(S.bundled())}
    Path(path).write_text(json.dumps(doc, sort_keys=True) + "\n")
    print(f"wrote {path} ({len(doc)} goldens)")


def main() -> None:
    import sys

    if sys.argv[1:2] == ["--dump"] and len(sys.argv) == 3:
        dump(sys.argv[2])
        return
    for name in S.bundled():
        path = HERE / f"{name}.json"
        doc = make(name)
        path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        print(f"wrote {path} ({len(doc['tolerance'])} quantities above rtol {RTOL})")


if __name__ == "__main__":
    main()
