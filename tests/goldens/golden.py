"""Golden runs: a small fixed-seed run of every bundled scenario, with its numbers checked in.

Regenerate (after a deliberate change of numbers, with the reason in the commit message):

    python tests/goldens/golden.py
"""

from __future__ import annotations

import json
from pathlib import Path

import trackkit.scenario as S
from trackkit.eval.montecarlo import run_scenario

HERE = Path(__file__).parent
RUNS = 20


def golden_numbers(name: str) -> dict:
    """The key numbers of a 20-run, block-10 run of a bundled scenario (timings left out)."""
    d = S.load(name).model_dump()
    d["run"].update(runs=RUNS, block=10)
    for f in d["filters"]:
        if f.get("tune") and not f["tune"].get("on"):
            # a short tuning: the golden checks the pipeline's numbers, not the optimiser
            f["tune"].update(runs=2, iterations=3, population=10)
    result = run_scenario(S.parse(d, name))
    doc = result.to_json_dict()
    for f in doc["filters"].values():
        f.pop("seconds_per_step")
    for t in doc.get("tuning", {}).values():
        t.pop("seconds")
    doc["final_rmse"] = {n: {g: float(v[-1]) for g, v in f.rmse.items()}
                         for n, f in result.filters.items()}
    return doc


def main() -> None:
    for name in S.bundled():
        path = HERE / f"{name}.json"
        path.write_text(json.dumps(golden_numbers(name), indent=1, sort_keys=True) + "\n")
        print("wrote", path)


if __name__ == "__main__":
    main()
