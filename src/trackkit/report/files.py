"""Write a comparison's report files into an output directory, all or nothing.

Files: ``results.json`` (the summary document), ``metrics.parquet`` (per-step metrics of every
filter), the PNG figures and ``report.html``. Everything is written into a sibling temporary
directory first; only when every file is complete does it move into place (a directory rename
when ``out_dir`` is new; otherwise file by file with ``results.json`` last, under an
``INCOMPLETE`` marker that is removed at the end). A failure leaves ``out_dir`` as it was.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from trackkit.eval.results import MonteCarloResult
from trackkit.report import plots
from trackkit.report.html import render_html

__all__ = [
    "RESULTS_JSON", "METRICS_PARQUET", "REPORT_HTML", "INCOMPLETE", "TRACKKIT_FILES",
    "results_document", "write_results_json", "metrics_table", "write_metrics_parquet",
    "write_report",
]

RESULTS_JSON = "results.json"
METRICS_PARQUET = "metrics.parquet"
REPORT_HTML = "report.html"
INCOMPLETE = "INCOMPLETE"
TRACKKIT_FILES = (METRICS_PARQUET, *plots.PLOT_FILES.values(), REPORT_HTML, RESULTS_JSON)


def _finite_or_none(obj: Any) -> Any:
    """JSON has no NaN/Infinity: non-finite floats become null."""
    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def results_document(result: MonteCarloResult) -> dict:
    """``result.to_json_dict()`` with non-finite numbers (no bound, no NIS) as null."""
    return _finite_or_none(result.to_json_dict())


def write_results_json(result: MonteCarloResult, path: str | Path) -> Path:
    """Write ``results.json`` (strict JSON, UTF-8, indented)."""
    path = Path(path)
    text = json.dumps(results_document(result), indent=2, allow_nan=False)
    path.write_text(text + "\n", encoding="utf-8")
    return path


def _column(values: Any, steps: int, name: str) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64).reshape(-1)
    if a.shape != (steps,):
        raise ValueError(f"{name}: {a.size} values for {steps} steps")
    return a


def metrics_table(result: MonteCarloResult) -> pa.Table:
    """Per-step metrics, one row per (filter, step), SI units (radians for angle groups).

    Columns: ``filter, step, time, rmse_<group>..., nees, nis, nees_lo, nees_hi, nis_lo,
    nis_hi, pcrlb_<group>...`` (nan where a value does not exist). The units of each group
    are in the field metadata (``unit``) and the run settings in the schema metadata
    (``trackkit``, JSON)."""
    steps = result.steps
    nan = np.full(steps, np.nan)
    names = list(result.filters)
    cols: dict[str, Any] = {
        "filter": pa.array(np.repeat(names, steps).tolist(), pa.string()),
        "step": np.tile(np.arange(steps, dtype=np.int64), len(names)),
        "time": np.tile(_column(result.times, steps, "times"), len(names)),
    }

    def stack(get: Any, what: str) -> np.ndarray:
        parts = [_column(get(f), steps, f"{f.name} {what}") for f in result.filters.values()]
        return np.concatenate(parts) if parts else np.empty(0)

    for g in result.groups:
        cols[f"rmse_{g}"] = stack(lambda f, g=g: f.rmse.get(g, nan), f"rmse {g}")
    cols["nees"] = stack(lambda f: f.nees, "nees")
    cols["nis"] = stack(lambda f: f.nis, "nis")
    cols["nees_lo"] = stack(lambda f: f.nees_bounds[0], "nees lower bound")
    cols["nees_hi"] = stack(lambda f: f.nees_bounds[1], "nees upper bound")
    cols["nis_lo"] = stack(lambda f: f.nis_bounds[0], "nis lower bound")
    cols["nis_hi"] = stack(lambda f: f.nis_bounds[1], "nis upper bound")
    for g in result.groups:
        bound = _column(result.pcrlb.get(g, nan), steps, f"pcrlb {g}")
        cols[f"pcrlb_{g}"] = np.tile(bound, len(names))

    fields = []
    for name, values in cols.items():
        unit = {"time": "s"}.get(name)
        for prefix in ("rmse_", "pcrlb_"):
            if name.startswith(prefix) and name[len(prefix):] in result.groups:
                unit = result.groups[name[len(prefix):]]
        dtype = values.type if isinstance(values, pa.Array) else pa.from_numpy_dtype(values.dtype)
        fields.append(pa.field(name, dtype, metadata={"unit": unit} if unit else None))
    meta = {"scenario": result.scenario, "runs": result.runs, "seed": result.seed,
            "steps": steps, "dt": result.dt, "start": result.start, "groups": result.groups}
    schema = pa.schema(fields, metadata={"trackkit": json.dumps(meta)})
    return pa.Table.from_arrays([pa.array(v) for v in cols.values()], schema=schema)


def write_metrics_parquet(result: MonteCarloResult, path: str | Path) -> Path:
    """Write ``metrics.parquet`` (see :func:`metrics_table`)."""
    path = Path(path)
    pq.write_table(metrics_table(result), path)
    return path


def _write_all(result: MonteCarloResult, folder: Path) -> dict[str, Path]:
    """Every report file into ``folder``; ``results.json`` last. Returns name -> path."""
    written = {"metrics": write_metrics_parquet(result, folder / METRICS_PARQUET)}
    figures = plots.make_plots(result, folder)
    written.update(figures)
    page = render_html(result, figures)
    written["html"] = folder / REPORT_HTML
    written["html"].write_text(page, encoding="utf-8")
    written["results"] = write_results_json(result, folder / RESULTS_JSON)
    return written


def _move_into_place(tmp: Path, out: Path, written: dict[str, Path]) -> dict[str, Path]:
    if not out.exists():
        os.rename(tmp, out)
        return {k: out / p.name for k, p in written.items()}
    marker = out / INCOMPLETE
    marker.write_text("trackkit is replacing the report files in this directory; if this file "
                      "remains, the write was interrupted and the files here are not one "
                      "consistent result.\n", encoding="utf-8")
    (out / RESULTS_JSON).unlink(missing_ok=True)
    final: dict[str, Path] = {}
    for key, p in sorted(written.items(), key=lambda kv: kv[1].name == RESULTS_JSON):
        final[key] = out / p.name
        os.replace(p, final[key])
    new = {p.name for p in final.values()}
    for stale in TRACKKIT_FILES:
        if stale not in new:
            (out / stale).unlink(missing_ok=True)
    marker.unlink()
    tmp.rmdir()
    return final


def write_report(result: MonteCarloResult, out_dir: str | Path) -> dict[str, Path]:
    """Write all report files of ``result`` into ``out_dir`` atomically (see module doc).

    Other files in an existing ``out_dir`` are left alone; trackkit files of an earlier run
    are replaced (or removed when this run does not produce them). Returns name -> path."""
    out = Path(out_dir).resolve()
    if out.exists() and not out.is_dir():
        raise ValueError(f"output directory {str(out)!r} exists and is not a directory")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.{uuid.uuid4().hex[:12]}.tmp"
    tmp.mkdir()  # not mkdtemp: the directory renamed into place keeps the usual permissions
    try:
        written = _write_all(result, tmp)
        return _move_into_place(tmp, out, written)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
