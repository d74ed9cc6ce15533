"""Write a comparison's report files into an output directory, all or nothing.

Files: ``results.json`` (the summary document: numbers that depend only on the scenario and
the seed, so equal seeds give byte-identical files), ``timings.json`` (wall-clock times, which
do not), ``metrics.parquet`` (per-step metrics of every filter), the PNG figures and
``report.html``. Everything is written into a temporary directory inside ``out_dir`` first (so
nothing is ever written outside it); only when every file is complete are they moved into
place, ``results.json`` last, under an ``INCOMPLETE`` marker that is removed at the end. A
failure leaves ``out_dir`` as it was (and removes it again if this call created it).

A command (``trackkit run``, ``sweep``, ``network``, ``identify``, ``track``) declares itself
with :func:`command_output` while it holds its output directory: the directory is checked
before anything is computed (another command's output, or files no manifest lists that the
command would overwrite, are refused), and every write also writes ``manifest.json``: the
command, its arguments, the trackkit version, the time and each file written with its size
and sha256. Files the same command wrote last time (its manifest lists them) and did not
write again are removed, so the directory holds one command's files and says which.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import uuid
from collections.abc import Callable, Collection, Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from trackkit.experiments.results import MonteCarloResult
from trackkit.report import plots
from trackkit.report.html import render_html
from trackkit.report.tables import averaging_window

__all__ = [
    "RESULTS_JSON", "TIMINGS_JSON", "METRICS_PARQUET", "REPORT_HTML", "INCOMPLETE",
    "TRACKKIT_FILES", "results_document", "timings_document", "write_results_json",
    "write_timings_json", "metrics_table", "write_metrics_parquet", "write_report",
    "MANIFEST_JSON", "CommandRun", "command_output", "read_manifest", "write_atomically",
]

#: The results document of a run (written last).
RESULTS_JSON = "results.json"
#: The wall-clock times of a run (not deterministic, so kept out of ``results.json``).
TIMINGS_JSON = "timings.json"
#: The per-step metrics table.
METRICS_PARQUET = "metrics.parquet"
#: The self-contained HTML report.
REPORT_HTML = "report.html"
#: The marker present in an output directory while its files are being moved into place.
INCOMPLETE = "INCOMPLETE"
#: The record of the command that wrote an output directory and of the files it wrote.
MANIFEST_JSON = "manifest.json"
#: The files ``write_report`` owns: an earlier run's that this run did not write are removed.
TRACKKIT_FILES = (METRICS_PARQUET, *plots.PLOT_FILES.values(), REPORT_HTML, TIMINGS_JSON,
                  RESULTS_JSON)
#: the units of the quantities that are the same for every scenario (the error groups' units
#: come from the result)
_FIXED_UNITS = {
    "dt": "s",
    "window": "s (from_s, to_s); steps (first_step, steps)",
    "anees": "1 (dimensionless; about the state dimension n when consistent)",
    "anis": "1 (dimensionless; about the measurement dimension m when consistent)",
    "nees_in_bounds": "fraction of the window's steps, 0 to 1",
    "diverged": "runs",
}
_MATCHING_UNITS = {
    "J1": "SI unit of each measurement channel (rad for angles)",
    "J2": "SI unit of each measurement channel (rad for angles)",
    "J3": "SI unit of each state component (m, m/s, ...)",
    "J4": "dom_alpha times the RMS of the DOM diagonal (SI measurement variance)",
    "tuning": "best, mean and worst: the J4 cost of the tuning realisation; params: the "
              "fuzzy system's parameters (normalised, dimensionless)",
}


_CLASSIFICATION_UNITS = (
    "final_mean, final_true_mean, final_true_p10: probabilities, 0 to 1 (the last step's; "
    "mean and 10th percentile over runs); above: fraction of runs whose last probability of "
    "the true class exceeds threshold; decided_s: s, the median over runs of the time from "
    "which it stays above threshold")


def finite_or_none(obj: Any) -> Any:
    """JSON has no NaN/Infinity: non-finite floats become null, anywhere in nested dicts,
    lists and tuples (tuples become lists, as JSON writes them); numpy scalars become
    Python numbers first."""
    if isinstance(obj, dict):
        return {k: finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite_or_none(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _units(result: MonteCarloResult, doc: dict) -> dict:
    units: dict[str, Any] = {
        "rmse": dict(result.groups),
        "pcrlb": {g: result.groups.get(g, "") for g in doc.get("pcrlb", {})},
        **_FIXED_UNITS,
    }
    present = {"J1", "tuning"} & set(doc)
    for per_filter in doc.get("J", {}).values():
        present |= set(per_filter)
    units.update({k: v for k, v in _MATCHING_UNITS.items() if k in present})
    if "classification" in doc:
        units["classification"] = _CLASSIFICATION_UNITS
    return units


def results_document(result: MonteCarloResult) -> dict:
    """The ``results.json`` document: ``result.to_json_dict()`` without the wall-clock
    timings (they go to ``timings.json``), with the averaging ``window`` and the ``units`` of
    every quantity added, and non-finite numbers (no bound, no NIS) as null.

    Values are SI (angles in radians, as ``units`` says); the tables show degrees."""
    doc = result.to_json_dict()
    for entry in doc.get("filters", {}).values():
        entry.pop("seconds_per_step", None)
    for entry in doc.get("tuning", {}).values():
        entry.pop("seconds", None)
    head = {k: doc.pop(k) for k in ("scenario", "runs", "seed", "steps", "dt") if k in doc}
    ordered = {**head, "window": averaging_window(result), "units": _units(result, doc), **doc}
    return finite_or_none(ordered)


def timings_document(result: MonteCarloResult) -> dict:
    """The ``timings.json`` document: wall-clock time per run-step of each filter and the
    seconds each fuzzy system took to tune (they vary from run to run, unlike results.json)."""
    doc: dict[str, Any] = {
        "scenario": result.scenario, "runs": result.runs, "seed": result.seed,
        "units": {"seconds_per_step": "s of filter time (predict and update) per run and step",
                  "tuning_seconds": "s of wall-clock time to tune the filter's fuzzy system"},
        "seconds_per_step": {name: float(f.seconds_per_step)
                             for name, f in result.filters.items()},
    }
    if result.tuning:
        doc["tuning_seconds"] = {name: float(getattr(t, "seconds", math.nan))
                                 for name, t in result.tuning.items()}
    return finite_or_none(doc)


def write_json(doc: dict, path: str | Path) -> Path:
    path = Path(path)
    text = json.dumps(doc, indent=2, allow_nan=False)
    path.write_text(text + "\n", encoding="utf-8")
    return path


def write_results_json(result: MonteCarloResult, path: str | Path) -> Path:
    """Write ``results.json`` (strict JSON, UTF-8, indented; see :func:`results_document`)."""
    return write_json(results_document(result), path)


def write_timings_json(result: MonteCarloResult, path: str | Path) -> Path:
    """Write ``timings.json`` (see :func:`timings_document`)."""
    return write_json(timings_document(result), path)


def _column(values: Any, steps: int, name: str) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64).reshape(-1)
    if a.shape != (steps,):
        raise ValueError(f"{name}: {a.size} values for {steps} steps")
    return a


def metrics_table(result: MonteCarloResult) -> pa.Table:
    """Per-step metrics, one row per (filter, step), SI units (radians for angle groups).

    Columns: ``filter, step, time, rmse_<group>..., nees, nis, nees_lo, nees_hi, nis_lo,
    nis_hi, pcrlb_<group>...`` and, when a filter classifies, ``class_prob_<class>...`` and
    ``p_true_p10, p_true_p50, p_true_p90`` (nan where a value does not exist). The units of
    each group are in the field metadata (``unit``) and the run settings in the schema
    metadata (``trackkit``, JSON)."""
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
    cols.update(_class_columns(result, stack))

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


def _class_columns(result: MonteCarloResult, stack: Any) -> dict[str, np.ndarray]:
    """With a filter that classifies: ``class_prob_<class>``, each class's probability per
    step averaged over runs, and (with a true class) ``p_true_p10``, ``p_true_p50`` and
    ``p_true_p90``, its percentiles over runs; nan for the other filters."""
    classifiers = result.classifiers()
    if not classifiers:
        return {}
    nan = np.full(result.steps, np.nan)
    classes = list(dict.fromkeys(k for n in classifiers
                                 for k in result.filters[n].classes["names"]))

    def mean_of(f: Any, k: str) -> np.ndarray:
        c = f.classes
        if not c or k not in c["names"]:
            return nan
        return np.asarray(c["mean"])[:, list(c["names"]).index(k)]

    cols = {f"class_prob_{k}": stack(lambda f, k=k: mean_of(f, k), f"class {k}")
            for k in classes}
    if any(result.filters[n].classes.get("true") is not None for n in classifiers):
        def pct(f: Any, i: int) -> np.ndarray:
            if not f.classes or f.classes.get("true") is None:
                return nan
            return result.true_class_percentiles(f.name)[i]

        for i, q in enumerate((10, 50, 90)):
            cols[f"p_true_p{q}"] = stack(lambda f, i=i: pct(f, i), f"P(true) p{q}")
    return cols


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
    written["timings"] = write_timings_json(result, folder / TIMINGS_JSON)
    written["results"] = write_results_json(result, folder / RESULTS_JSON)
    return written


# --- which command wrote a directory: manifest.json ------------------------------------------


@dataclass(frozen=True)
class CommandRun:
    """The command writing an output directory: its name (``run``), its arguments as given
    (JSON values) and the file names it may write there (for the check before computing)."""

    command: str
    arguments: dict[str, Any] = field(default_factory=dict)
    may_write: Collection[str] = ()


_RUN: ContextVar[tuple[Path, CommandRun] | None] = ContextVar("trackkit_command_run",
                                                               default=None)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("trackkit")
    except PackageNotFoundError:  # a source tree that is not installed
        from trackkit import __version__

        return __version__


def read_manifest(out_dir: str | Path, label: str | None = None) -> dict | None:
    """The ``manifest.json`` of ``out_dir`` (None without one); a ValueError in words when it
    cannot be read."""
    path = Path(out_dir) / MANIFEST_JSON
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        names = [f["name"] for f in doc["files"]]
        if not isinstance(doc["command"], str) or not all(isinstance(n, str) for n in names):
            raise TypeError("command or file names are not text")
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ValueError(f"{label or out_dir}: {path} cannot be read ({err}); it is not a "
                         "trackkit manifest: choose another --out, or delete it") from None
    return doc


def _listed(doc: dict | None) -> set[str]:
    """The plain file names a manifest lists (never a path out of the directory)."""
    names = {f["name"] for f in doc["files"]} if doc else set()
    return {n for n in names if n and Path(n).name == n and not n.startswith(".")}


def _check_directory(out: Path, label: str, run: CommandRun, writes: Iterable[str]) -> set[str]:
    """Refuse (ValueError) a directory holding another command's output, or files no
    manifest lists that ``writes`` would replace; returns the names the same command's
    manifest lists."""
    doc = read_manifest(out, label)
    again = f"trackkit {run.command}"
    if doc is not None and doc["command"] != run.command:
        raise ValueError(
            f"{label} holds the output of `trackkit {doc['command']}` (its {MANIFEST_JSON}, "
            f"written {doc.get('time', 'at an unknown time')}); `{again}` does not write "
            "into another command's directory: choose another --out")
    listed = _listed(doc)
    clash = sorted(n for n in set(writes) - listed if (out / n).exists())
    if clash:
        shown = ", ".join(clash[:5]) + (f" and {len(clash) - 5} more" if len(clash) > 5 else "")
        raise ValueError(
            f"{label} holds {shown}, which no trackkit {MANIFEST_JSON} there lists (files of "
            f"an earlier trackkit version, or not trackkit's); `{again}` would overwrite them: "
            "choose another --out, or move them away")
    return listed


@contextmanager
def command_output(out_dir: str | Path, label: str, run: CommandRun) -> Iterator[None]:
    """While inside, ``run`` is the command writing ``out_dir``: checked now (before any
    computing; see ``_check_directory``), and every :func:`write_atomically` into it
    writes ``manifest.json`` and removes the files of the command's previous manifest that
    it did not write again."""
    out = Path(out_dir).resolve()
    _check_directory(out, label, run, run.may_write)
    token = _RUN.set((out, run))
    try:
        yield
    finally:
        _RUN.reset(token)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _write_manifest(folder: Path, run: CommandRun, written: dict[str, Path],
                    kept: Iterable[str]) -> Path:
    """``manifest.json``: the files of this write, and (``kept``) the other entries the
    directory keeps beside them (a campaign's stored blocks, a user's own files)."""
    files = [{"name": p.name, "bytes": p.stat().st_size, "sha256": _sha256(p)}
             for p in sorted(written.values(), key=lambda p: p.name)]
    doc = {"command": run.command, "arguments": run.arguments, "trackkit": _version(),
           "time": datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
           "files": files, "kept": sorted(kept)}
    return write_json(doc, folder / MANIFEST_JSON)


def _kept(out: Path, written: Iterable[str], removed: Iterable[str]) -> list[str]:
    """The entries of ``out`` a write leaves beside its files (directories end in /)."""
    gone = {*written, *removed, MANIFEST_JSON, INCOMPLETE, RESULTS_JSON}
    return [p.name + ("/" if p.is_dir() else "") for p in out.iterdir()
            if p.name not in gone and not p.name.startswith(".")]


def _move_into_place(tmp: Path, out: Path, written: dict[str, Path],
                     owned: Iterable[str]) -> dict[str, Path]:
    marker = out / INCOMPLETE
    marker.write_text("trackkit is replacing the report files in this directory; if this file "
                      "remains, the write was interrupted and the files here are not one "
                      "consistent result.\n", encoding="utf-8")
    (out / RESULTS_JSON).unlink(missing_ok=True)
    final: dict[str, Path] = {}
    last = {RESULTS_JSON: 1, MANIFEST_JSON: 2}  # the manifest only once all files are there
    for key, p in sorted(written.items(), key=lambda kv: last.get(kv[1].name, 0)):
        final[key] = out / p.name
        os.replace(p, final[key])
    new = {p.name for p in final.values()}
    for stale in owned:
        if stale not in new:
            (out / stale).unlink(missing_ok=True)
    marker.unlink()
    tmp.rmdir()
    return final


def _make_dirs(out: Path) -> list[Path]:
    """``mkdir -p out``; returns the directories it created, outermost first."""
    missing = []
    p = out
    while not p.exists():
        missing.append(p)
        p = p.parent
    out.mkdir(parents=True, exist_ok=True)
    return missing[::-1]


def _remove_if_empty(created: list[Path]) -> None:
    for d in reversed(created):
        try:
            d.rmdir()
        except OSError:  # not empty (someone else's files) or already gone: leave it
            return


def write_atomically(out_dir: str | Path, write_all: Callable[[Path], dict[str, Path]],
                     owned: Iterable[str]) -> dict[str, Path]:
    """All or nothing: ``write_all(folder)`` writes the files into a temporary folder inside
    ``out_dir`` (never beside it: a run writes nowhere but the directory it was given); they
    are moved into place under an ``INCOMPLETE`` marker, ``results.json`` last, and the files
    of ``owned`` that this run did not write are removed (an earlier run's); other files are
    left alone. On failure nothing is left behind, not even the directories it created.
    Returns name -> path."""
    out = Path(out_dir).resolve()
    if out.exists() and not out.is_dir():
        raise ValueError(f"output directory {str(out_dir)!r} exists and is not a directory")
    created = _make_dirs(out)
    tmp = out / f".trackkit-tmp.{uuid.uuid4().hex[:12]}"
    held = _RUN.get()
    try:
        tmp.mkdir()
        written = write_all(tmp)
        if held is not None and held[0] == out:  # a command's directory: checked, listed
            run = held[1]
            names = {p.name for p in written.values()}
            owned = {*owned, *_check_directory(out, str(out_dir), run, names)}
            written["manifest"] = _write_manifest(tmp, run, written,
                                                  _kept(out, names, set(owned) - names))
        return _move_into_place(tmp, out, written, owned)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        _remove_if_empty(created)
        raise


def write_report(result: MonteCarloResult, out_dir: str | Path) -> dict[str, Path]:
    """Write all report files of ``result`` into ``out_dir`` atomically (see module doc).

    Other files in an existing ``out_dir`` are left alone; trackkit files of an earlier run
    are replaced (or removed when this run does not produce them). Returns name -> path."""
    return write_atomically(out_dir, lambda folder: _write_all(result, folder), TRACKKIT_FILES)
