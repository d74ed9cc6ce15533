"""The report of a vessel identification (Zolfagharnasab and Seif 2025): a scenario's Monte Carlo
(``experiments.vessel_mc.run_vessel``) or a recorded log
(``experiments.vessel_mc.identify_recorded``),
written atomically into one directory with ``report.files.write_atomically``:

* ``results.json``: the identified coefficients with their standard deviations; per filter
  the relative errors, settling steps, NEES and the filtered u, v, r against the noise
  (scenarios); the demonstrated trial's position errors and metrics; the standard trials of
  the identified model (and of the truth) with the IMO MSC.137(76) criteria, their limits,
  pass or fail, and the paper's 2 <= D/L <= 7 band. SI throughout (angles in rad, speeds in
  m/s), each quantity's unit under ``units``; only numbers that depend on the inputs and the
  seed, so equal seeds give byte-identical files; wall-clock times go to ``timings.json``.
* ``convergence.png``: every coefficient's estimate against time with its +-2 sigma band
  (the paper's Figs. 5-7 show a1, b2 and c1), the truth dashed when known.
* ``track.png``: plan view, without filtering (raw GPS; Fig. 10) and with filtering (the
  filtered track, Fig. 11) beside the identified model driven by the trial's inputs (Figs. 8
  and 9) and the truth when known.
* ``heading.png``: heading and nozzle angle against time, measured (and true) against the
  identified model (Fig. 9).
* ``trials.png``: the identified model's standard trials (20 deg turn, 10/10 and 20/20
  zig-zags) beside the truth's when known.
* ``errors.png`` (scenarios with more than one run): each coefficient's relative error per
  filter, median and 10-90% range over the runs.
* ``report.html``: one self-contained page (inline CSS, PNGs as data URIs, no scripts).

Degrees and knots appear only in the figures and the page.
"""

from __future__ import annotations

import html
import math
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from trackkit import __version__
from trackkit.eval.manoeuvres import IMO_NOTE, Criterion, TurningMetrics, ZigZagMetrics
from trackkit.experiments.vessel_mc import (
    REL_SD_LIMIT,
    ModelTrials,
    RecordedIdentification,
    VesselResult,
    nees_band,
)
from trackkit.models.manoeuvring import COEFFICIENT_NAMES, KNOT, Normalisation
from trackkit.report.files import (
    REPORT_HTML,
    RESULTS_JSON,
    TIMINGS_JSON,
    write_atomically,
    write_json,
)
from trackkit.report.html import CSS, notes_and_figures
from trackkit.report.plots import save_figure

__all__ = [
    "VESSEL_FILES", "convergence_figure", "track_figure", "heading_figure", "trials_figure",
    "errors_figure", "vessel_results_document", "recorded_results_document",
    "render_vessel_html", "write_vessel_report", "write_recorded_report",
]

CONVERGENCE_PNG = "convergence.png"
TRACK_PNG = "track.png"
HEADING_PNG = "heading.png"
TRIALS_PNG = "trials.png"
ERRORS_PNG = "errors.png"
#: The files the vessel report owns (an earlier run's not written again are removed).
VESSEL_FILES = (CONVERGENCE_PNG, TRACK_PNG, HEADING_PNG, TRIALS_PNG, ERRORS_PNG, REPORT_HTML,
                TIMINGS_JSON, RESULTS_JSON)
PAPER_BAND = (2.0, 7.0)

#: units of the entries of results.json
METRIC_UNITS = {
    "turn": "advance_m, transfer_m, tactical_diameter_m, steady_diameter_m: m; "
            "diameter_to_length: 1 (steady diameter / L)",
    "zigzag": "initial_turning_time_s, time_to_check_yaw_s, period_s: s; "
              "initial_turning_distance_m: m; first_overshoot_rad, second_overshoot_rad: rad",
}
UNITS: dict[str, Any] = {
    "coefficients": "prime units of the normalisation (u' = u/U0, v' = v/U0, r' = r L/U0, "
                    "t' = t U0/L, n' = n/n0, nozzle angle in rad)",
    "normalisation": "length_m: m; speed_mps: m/s; rpm: rpm",
    "sigma_z": "the identifier's measurement standard deviations: u, v m/s; r rad/s",
    "period_s": "s", "samples": "grid samples",
    "rel_error": "1: |theta_hat - theta| / |theta|",
    "settling_step": "samples: the first from which the estimate stays within settle_tol of "
                     "the truth (samples = never at the end)",
    "nees": "1: coefficients' NEES, chi-square(16) when consistent; band: two-sided 95%",
    "body_rmse": "[u m/s, v m/s, r rad/s], filtered against the truth (median over runs)",
    "measurement_rmse": "[u m/s, v m/s, r rad/s], measured against the truth (median over "
                        "runs)",
    "trial": "positions m; params: delta_rad, alpha_rad rad, rpm, speed_mps m/s, side +1 "
             "starboard / -1 port",
    "metrics": METRIC_UNITS,
    "imo": "value, lower, upper in the criterion's unit: m (advance, tactical diameter, "
           "initial turning distance), rad (overshoots), 1 (paper_band: D/L); null: "
           "unbounded or not reached",
}

_CAPTIONS = {
    "convergence": "Every coefficient's estimate against time with its +-2 sigma band (the "
                   "paper's Figs. 5-7 show a1, b2 and c1); dashed: the truth.",
    "track": "Plan view. Left, without filtering: the raw GPS fixes (Fig. 10). Right, with "
             "filtering: the filtered velocities integrated with the measured heading and "
             "placed on the GPS fixes (Fig. 11), and the identified model driven by the "
             "trial's inputs alone from the first sample (Figs. 8-9).",
    "heading": "Heading and nozzle angle against time: measured against the identified "
               "model driven by the same inputs (Fig. 9).",
    "trials": "The identified model's standard trials: a 20 deg turning circle and 10/10 and "
              "20/20 zig-zags (dashed: the truth's).",
    "errors": "Relative error of each coefficient per filter: median over the runs with the "
              "10-90% range (log scale).",
}


# ---------------------------------------------------------------------------------------------
# numbers
# ---------------------------------------------------------------------------------------------


def _num(x: Any) -> float | None:
    """A float, or None where it is missing or not finite (JSON null)."""
    if x is None:
        return None
    v = float(x)
    return v if math.isfinite(v) else None


def _median(a: Any, axis: int = 0) -> np.ndarray:
    """Median over ``axis`` of the finite entries (nan where there are none)."""
    a = np.asarray(a, dtype=float)
    if a.ndim == 0:  # one model (a recorded log)
        return a
    with warnings.catch_warnings():  # an all-nan slice is a nan, said so by the value itself
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(np.where(np.isfinite(a), a, np.nan), axis=axis)


def _coefficients(values: Any) -> dict[str, float | None]:
    return {k: _num(v) for k, v in zip(COEFFICIENT_NAMES, np.asarray(values), strict=True)}


def _norm(norm: Normalisation) -> dict[str, float]:
    return {"length_m": norm.length, "speed_mps": norm.speed, "rpm": norm.rpm}


def _turn_doc(m: TurningMetrics, pick: Any) -> dict[str, float | None]:
    return {f"{k}_m" if k != "diameter_to_length" else k: _num(pick(v))
            for k, v in m._asdict().items()}


_ZZ_KEYS = {"initial_turning_time": "initial_turning_time_s",
            "initial_turning_distance": "initial_turning_distance_m",
            "time_to_check_yaw": "time_to_check_yaw_s", "first_overshoot": "first_overshoot_rad",
            "second_overshoot": "second_overshoot_rad", "period": "period_s"}


def _zz_doc(m: ZigZagMetrics, pick: Any) -> dict[str, float | None]:
    return {_ZZ_KEYS[k]: _num(pick(v)) for k, v in m._asdict().items()}


def _metrics_doc(m: TurningMetrics | ZigZagMetrics, pick: Any) -> dict[str, float | None]:
    return _turn_doc(m, pick) if isinstance(m, TurningMetrics) else _zz_doc(m, pick)


def _run0(a: Any) -> Any:
    a = np.asarray(a)
    return a if a.ndim == 0 else a.reshape(-1)[0]


def _trials_doc(mt: ModelTrials, pick: Any) -> dict[str, Any]:
    return {"turn": _turn_doc(mt.turning, pick), "zigzag10": _zz_doc(mt.zz10, pick),
            "zigzag20": _zz_doc(mt.zz20, pick)}


def _bound(x: Any) -> float | None:
    v = float(np.asarray(x).reshape(-1)[0])
    return v if math.isfinite(v) else None


def _imo_doc(crit: Mapping[str, Criterion], truth: Mapping[str, Criterion] | None
             ) -> list[dict[str, Any]]:
    """One entry per criterion: limits, and value and pass of the identified model (run 0,
    and the fraction of runs that pass) and of the truth."""
    out = []
    for name, c in crit.items():
        passed = np.asarray(c.passed, dtype=bool)
        e: dict[str, Any] = {"name": name, "source": c.source, "lower": _bound(c.lower),
                             "upper": _bound(c.upper), "value": _num(_run0(c.value)),
                             "passed": bool(_run0(passed)),
                             "passed_fraction": float(passed.mean())}
        if truth is not None:
            t = truth[name]
            e["truth_value"] = _num(_run0(t.value))
            e["truth_passed"] = bool(_run0(t.passed))
        out.append(e)
    return out


def _model_trials_doc(mt: ModelTrials, truth: ModelTrials | None) -> dict[str, Any]:
    doc: dict[str, Any] = {
        "speed_mps": mt.speed, "rpm": mt.rpm, "length_m": mt.length,
        "stable_fraction": float(np.mean(mt.stable)),
        "identified_run0": _trials_doc(mt, _run0),
        "imo": _imo_doc(mt.criteria, None if truth is None else truth.criteria),
        "imo_note": IMO_NOTE, "paper_band": list(PAPER_BAND),
    }
    if np.ndim(mt.stable):  # several runs' models: their medians too
        doc["identified_median"] = _trials_doc(mt, _median)
    if truth is not None:
        doc["truth"] = _trials_doc(truth, _run0)
    return doc


def vessel_results_document(res: VesselResult) -> dict[str, Any]:
    """The ``results.json`` document of a scenario's Monte Carlo (module docstring)."""
    K = res.t.size
    band = nees_band()
    filters = {}
    for name, f in res.filters.items():
        sd = np.asarray(f.theta_std)
        entry: dict[str, Any] = {
            "coefficients_run0": {k: {"value": _num(v), "std": _num(s)} for k, v, s in zip(
                COEFFICIENT_NAMES, f.theta[0], sd[0], strict=True)},
            "coefficients_median": _coefficients(_median(f.theta)),
            "rel_error_median": _coefficients(_median(f.rel_error)),
            "rel_error_p90": _coefficients(np.percentile(f.rel_error, 90, axis=0)),
            "settling_step_median": (None if f.settling is None
                                     else _coefficients(np.median(f.settling, 0))),
            "settled_fraction": (None if f.settling is None
                                 else _coefficients((f.settling < K).mean(0))),
            "nees_mean": _num(np.mean(f.nees)), "nees_median": _num(np.median(f.nees)),
            "nees_inside_fraction": float(np.mean((f.nees >= band[0]) & (f.nees <= band[1]))),
            "body_rmse_median": [_num(v) for v in _median(f.body_rmse)],
            "body_rmse_over_noise_median": [_num(v) for v in
                                            _median(f.body_rmse / res.noise_rmse)],
        }
        filters[name] = entry
    doc: dict[str, Any] = {
        "scenario": res.scenario, "kind": "vessel", "runs": res.runs, "seed": res.seed,
        "period_s": res.dt, "data": res.data, "samples": K,
        "data_trials": [s.name for s in res.segments],
        "units": UNITS,
        "truth": {"coefficients": _coefficients(res.truth.theta),
                  "normalisation": _norm(res.truth.norm)},
        "sigma_z": [float(v) for v in res.sigma_z],
        "measurement_rmse_median": [_num(v) for v in _median(res.noise_rmse)],
        "shown_filter": res.shown, "settle_tol": res.settle_tol,
        "nees_band": list(band),
        "filters": filters,
        "trial": None if res.trial is None else _trial_doc(res),
        "model_trials": _model_trials_doc(res.model, res.model_truth),
    }
    return doc


def _trial_doc(res: VesselResult) -> dict[str, Any]:
    d = res.trial
    p = {"delta_rad": d.params["delta"], "rpm": d.params["rpm"],
         "speed_mps": d.params["speed"], "side": d.params["side"]}
    if d.kind == "zigzag":
        p.update(alpha_rad=d.params["alpha"], commands=d.params["commands"])
    return {
        "kind": d.kind, "params": p, "samples": int(d.t.size), "duration_s": float(d.t[-1]),
        "gps_rmse_median_m": _num(_median(d.gps_rmse)),
        "filtered_rmse_median_m": None if d.filtered_rmse is None
        else _num(_median(d.filtered_rmse)),
        "model_rmse_median_m": _num(_median(d.model_rmse)),
        "model_max_error_median_m": _num(_median(d.model_max)),
        "metrics": {"truth": _metrics_doc(d.metrics["truth"], _run0),
                    "measured_median": _metrics_doc(d.metrics["measured"], _median),
                    "model_median": _metrics_doc(d.metrics["model"], _median)},
    }


def vessel_timings_document(res: VesselResult) -> dict[str, Any]:
    """``timings.json``: wall-clock seconds of each identifier (all runs) and the stages."""
    return {"scenario": res.scenario, "runs": res.runs, "seed": res.seed,
            "units": {"identify_s": "s of wall-clock time, all runs", "stages_s": "s"},
            "identify_s": {n: float(f.seconds) for n, f in res.filters.items()},
            "identify_s_per_run_step": {n: float(f.seconds) / (res.runs * max(res.t.size, 1))
                                        for n, f in res.filters.items()},
            "stages_s": {k: float(v) for k, v in res.seconds.items()}}


def _read_doc(report: Any) -> dict[str, Any]:
    return {"path": report.path, "records_read": report.rows_read,
            "records_kept": report.rows_kept, "skipped": dict(report.skipped),
            "skipped_lines": [int(x) for x in report.skipped_lines[:1000]],
            "duplicates": report.duplicates, "out_of_order": report.out_of_order,
            "epoch_utc": None if report.epoch is None else str(report.epoch)}


def recorded_results_document(rec: RecordedIdentification, log_read: Any = None,
                              inputs_read: Any = None) -> dict[str, Any]:
    """The ``results.json`` document of a recorded log's identification."""
    coeffs = {k: {"value": _num(v), "std": _num(s), "rel_std": _num(r),
                  "identified": bool(r <= REL_SD_LIMIT)}
              for k, v, s, r in zip(COEFFICIENT_NAMES, rec.theta, rec.theta_std, rec.rel_std,
                                    strict=True)}
    doc: dict[str, Any] = {
        "kind": "vessel-log", "filter": rec.filter, "period_s": rec.dt,
        "samples": int(rec.t.size), "start_s": float(rec.t[0]), "end_s": float(rec.t[-1]),
        "dropped_leading_samples": rec.dropped, "missing_samples": rec.missing,
        "substeps": rec.substeps,
        "units": {**UNITS, "rel_std": "1: std / |value|; identified: rel_std <= "
                  f"{REL_SD_LIMIT:g}", "start_s": "s from the log's epoch",
                  "model_rmse_m": "m, RMS distance of the model's track from the GPS fixes "
                  "(null: diverged)", "filtered_rmse_m": "m, likewise of the filtered track",
                  "speed_mps": "m/s, the log's median surge", "rpm": "the log's median"},
        "normalisation": _norm(rec.norm), "sigma_z": [float(v) for v in rec.sigma_z],
        "rel_sd_limit": REL_SD_LIMIT, "coefficients": coeffs,
        "identified_count": int(sum(c["identified"] for c in coeffs.values())),
        "speed_mps": rec.speed, "rpm": rec.rpm, "stable": rec.stable,
        "model_rmse_m": _num(rec.model_rmse), "filtered_rmse_m": _num(rec.filtered_rmse),
        "model_trials": _model_trials_doc(rec.trials, None),
    }
    if log_read is not None:
        doc["log"] = _read_doc(log_read)
    if inputs_read is not None:
        doc["inputs"] = _read_doc(inputs_read)
    return doc


# ---------------------------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------------------------


def convergence_figure(t: np.ndarray, history: np.ndarray, std: np.ndarray,
                       truth: np.ndarray | None, title: str) -> Figure:
    """A 4 x 4 grid: each coefficient's estimate ``history (K, 16)`` against ``t`` with the
    band ``+-2 std``, the truth dashed when given."""
    fig = Figure(figsize=(12.0, 9.0), layout="constrained")
    axes = fig.subplots(4, 4, sharex=True).ravel()
    for j, (ax, name) in enumerate(zip(axes, COEFFICIENT_NAMES, strict=True)):
        h, s = history[:, j], std[:, j]
        ax.fill_between(t, h - 2 * s, h + 2 * s, color="C0", alpha=0.2, lw=0)
        ax.plot(t, h, color="C0", lw=1.2)
        if truth is not None:
            ax.axhline(truth[j], color="black", ls="--", lw=1.0)
            span = max(abs(truth[j]), 0.05)
            ax.set_ylim(truth[j] - 3 * span, truth[j] + 3 * span)  # the band starts wide
        else:
            fin = h[np.isfinite(h)]
            if fin.size:
                mid, span = float(fin[-1]), max(float(np.ptp(fin[fin.size // 2:])), 0.05)
                ax.set_ylim(mid - 4 * span, mid + 4 * span)
        ax.set_title(name, fontsize="medium")
        ax.grid(True, alpha=0.3)
    for ax in axes[-4:]:
        ax.set_xlabel("time [s]")
    fig.suptitle(title, fontsize="medium")
    return fig


def _plan(ax, lines: Sequence[tuple[np.ndarray, np.ndarray, dict]]) -> None:
    for east, north, kw in lines:
        ax.plot(east, north, **kw)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")


def track_figure(gps: np.ndarray, filtered: np.ndarray | None, model: np.ndarray,
                 truth: np.ndarray | None, title: str) -> Figure:
    """Plan view in two panels: raw GPS ``(K, 2)`` (left) and the filtered and model tracks
    ``(K, >=2)`` (right), each beside the truth ``(K, >=2)`` when given."""
    fig = Figure(figsize=(12.0, 6.0), layout="constrained")
    left, right = fig.subplots(1, 2)
    ref = [] if truth is None else [(truth[:, 0], truth[:, 1],
                                     dict(color="black", lw=1.2, label="truth"))]
    _plan(left, ref + [(gps[:, 0], gps[:, 1], dict(color="C3", marker=".", ms=3, lw=0.5,
                                                   alpha=0.7, label="GPS fixes (raw)"))])
    left.set_title("without filtering", fontsize="medium")
    lines = list(ref)
    if truth is None:
        lines.append((gps[:, 0], gps[:, 1], dict(color="0.6", marker=".", ms=2, lw=0,
                                                 label="GPS fixes")))
    if filtered is not None:
        lines.append((filtered[:, 0], filtered[:, 1], dict(color="C0", lw=1.4,
                                                           label="filtered")))
    ok = np.isfinite(model[:, :2]).all(-1)
    lines.append((np.where(ok, model[:, 0], np.nan), np.where(ok, model[:, 1], np.nan),
                  dict(color="C2", lw=1.4, ls="--", label="identified model")))
    _plan(right, lines)
    right.set_title("with filtering, and the identified model", fontsize="medium")
    fig.suptitle(title, fontsize="medium")
    return fig


def heading_figure(t: np.ndarray, heading: np.ndarray, model: np.ndarray, nozzle: np.ndarray,
                   truth: np.ndarray | None, title: str) -> Figure:
    """Heading (measured, model, truth; deg, unwrapped from the first value) and nozzle
    angle (deg) against time."""
    fig = Figure(figsize=(9.0, 6.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1.3))
    h0 = float(heading[np.isfinite(heading)][0]) if np.isfinite(heading).any() else 0.0

    def deg(psi: np.ndarray) -> np.ndarray:
        p = np.asarray(psi, dtype=float)
        ok = np.isfinite(p)
        out = np.full(p.shape, np.nan)
        out[ok] = np.degrees(np.unwrap(p[ok]) - h0)
        return out

    if truth is not None:
        top.plot(t, deg(truth), color="black", lw=1.2, label="truth")
    top.plot(t, deg(heading), color="C3", lw=0.8, label="measured (INS)")
    top.plot(t, deg(model), color="C2", lw=1.4, ls="--", label="identified model")
    top.set_ylabel("heading change [deg]")
    top.grid(True, alpha=0.3)
    top.legend(fontsize="small")
    bottom.plot(t, np.degrees(nozzle), color="C1", lw=1.2)
    bottom.set_ylabel("nozzle [deg]")
    bottom.set_xlabel("time [s]")
    bottom.grid(True, alpha=0.3)
    fig.suptitle(title, fontsize="medium")
    return fig


def trials_figure(mt: ModelTrials, truth: ModelTrials | None, title: str) -> Figure:
    """The standard trials of run 0's model: the turn in plan view, the zig-zags' heading
    against time (dashed: the truth's)."""
    fig = Figure(figsize=(12.0, 4.5), layout="constrained")
    ax_turn, ax10, ax20 = fig.subplots(1, 3)

    def first(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a)
        return a.reshape(-1, a.shape[-1])[0]

    for m, style, label in ((mt, dict(color="C0", lw=1.3), "identified"),
                            (truth, dict(color="black", lw=1.0, ls="--"), "truth")):
        if m is None:
            continue
        e, n = first(m.turn.east), first(m.turn.north)
        ok = np.isfinite(e) & np.isfinite(n) & (np.abs(e) < 1e5) & (np.abs(n) < 1e5)
        ax_turn.plot(e[ok], n[ok], label=label, **style)
        for ax, tr in ((ax10, m.zigzag10), (ax20, m.zigzag20)):
            psi = first(tr.psi)
            ok = np.isfinite(psi) & (np.abs(psi) < 1e3)
            ax.plot(tr.t[ok], np.degrees(psi[ok]), label=f"{label}: heading", **style)
            ax.plot(tr.t, np.degrees(first(tr.delta)), color=style["color"], lw=0.7,
                    ls=":", label=f"{label}: nozzle")
    ax_turn.set_aspect("equal", adjustable="datalim")
    ax_turn.set_xlabel("east [m]")
    ax_turn.set_ylabel("north [m]")
    ax_turn.set_title("20 deg turning circle", fontsize="medium")
    for ax, name in ((ax10, "10/10 zig-zag"), (ax20, "20/20 zig-zag")):
        ax.set_xlabel("time [s]")
        ax.set_ylabel("[deg]")
        ax.set_title(name, fontsize="medium")
    for ax in (ax_turn, ax10, ax20):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="x-small")
    fig.suptitle(title, fontsize="medium")
    return fig


def errors_figure(res: VesselResult) -> Figure:
    """Median relative error per coefficient and filter with the 10-90% range."""
    fig = Figure(figsize=(11.0, 4.5), layout="constrained")
    ax = fig.add_subplot()
    x = np.arange(len(COEFFICIENT_NAMES))
    n = len(res.filters)
    for i, (name, f) in enumerate(res.filters.items()):
        e = np.maximum(f.rel_error, 1e-6)
        med = np.median(e, 0)
        lo, hi = np.percentile(e, 10, 0), np.percentile(e, 90, 0)
        off = (i - (n - 1) / 2) * 0.8 / max(n, 1)
        ax.errorbar(x + off, med, yerr=[med - lo, hi - med], fmt="o", ms=4, capsize=2,
                    color=f"C{i}", label=name)
    ax.axhline(res.settle_tol, color="black", ls=":", lw=1.0,
               label=f"{100 * res.settle_tol:g}%")
    ax.set_yscale("log")
    ax.set_xticks(x, COEFFICIENT_NAMES)
    ax.set_ylabel("relative error")
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(fontsize="small")
    ax.set_title(f"{res.scenario}: {res.runs} runs", fontsize="medium")
    return fig


# ---------------------------------------------------------------------------------------------
# page
# ---------------------------------------------------------------------------------------------


def _fmt(v: Any, spec: str = ".4g") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, spec)


def _deg(v: float | None, spec: str = ".2f") -> str:
    return "-" if v is None else format(math.degrees(v), spec)


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]], caption: str = "") -> str:
    esc = html.escape
    cap = f"<caption>{esc(caption)}</caption>" if caption else ""
    head = "".join(f"<th>{esc(h)}</th>" for h in headers)
    body = "\n".join("<tr>" + "".join(
        f"<th>{esc(c)}</th>" if i == 0 else f"<td>{esc(c)}</td>" for i, c in enumerate(r))
        + "</tr>" for r in rows)
    return (f'<table class="summary">{cap}<thead><tr>{head}</tr></thead>\n<tbody>\n{body}'
            "\n</tbody></table>")


def imo_rows(imo: Sequence[Mapping[str, Any]], with_truth: bool) -> list[list[str]]:
    """Rows of the IMO table (criterion, identified, truth, limit, source), in the report's
    units: m, deg, D/L."""
    rows = []
    for e in imo:
        angle = "overshoot" in e["name"]
        conv = (lambda v: _deg(v, ".1f")) if angle else (lambda v: _fmt(v, ".3g"))
        unit = " deg" if angle else ("" if e["name"] == "paper_band" else " m")
        lo = e["lower"]
        limit = (f"<= {conv(e['upper'])}{unit}" if lo is None
                 else f"{conv(lo)} to {conv(e['upper'])}{unit}")
        verdict = "pass" if e["passed"] else "fail"
        row = [e["name"], f"{conv(e['value'])}{unit} ({verdict})"]
        if with_truth:
            tv = "pass" if e.get("truth_passed") else "fail"
            row.append(f"{conv(e.get('truth_value'))}{unit} ({tv})")
            row.append(f"{100 * e['passed_fraction']:.0f}%")
        rows += [row + [limit, e["source"]]]
    return rows


_UNIT_LABEL = {"rad": "deg", "m": "m", "s": "s"}


def _metric_rows(cols: Sequence[tuple[str, Mapping[str, Any]]]) -> list[list[str]]:
    keys = list(cols[0][1])
    rows = []
    for k in keys:
        angle = k.endswith("_rad")
        stem, _, unit = k.rpartition("_")
        label = f"{stem} [{_UNIT_LABEL[unit]}]" if unit in _UNIT_LABEL else k
        rows.append([label] + [_deg(c.get(k)) if angle else _fmt(c.get(k), ".4g")
                               for _, c in cols])
    return rows


def render_vessel_html(doc: Mapping[str, Any], title: str, description: str,
                       notes: Sequence[str], images: Mapping[str, str | Path | bytes]) -> str:
    """The report page from a ``results.json`` document (scenario or log) and the figures:
    self-contained, no scripts, no links."""
    esc = html.escape
    parts = ["<!DOCTYPE html>", '<html lang="en">', '<head><meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             f"<title>trackkit: {esc(title)}</title>", f"<style>{CSS}</style></head>",
             "<body>", f"<h1>{esc(title)}</h1>"]
    if description:
        parts.append(f"<p>{esc(description)}</p>")
    if doc["kind"] == "vessel":
        parts += _scenario_sections(doc)
    else:
        parts += _log_sections(doc)
    mt = doc["model_trials"]
    parts.append("<h2>Standard trials of the identified model</h2>")
    many = "identified_median" in mt
    stable = (f"{100 * mt['stable_fraction']:.0f}% of the identified models" if many
              else ("yes" if mt["stable_fraction"] == 1.0 else "no: its trials diverge"))
    text = (f"At {mt['speed_mps'] / KNOT:.1f} kn and {mt['rpm']:.0f} rpm; L = "
            f"{mt['length_m']:g} m. Stable in a straight line: {stable}. {IMO_NOTE}; the "
            "paper asks 2 <= D/L <= 7.")
    parts.append(f"<p>{esc(text)}</p>")
    truth = "truth" in mt
    for trial in ("turn", "zigzag10", "zigzag20"):
        cols = [("identified (run 0)" if truth else "identified",
                 mt["identified_run0"][trial])]
        if "identified_median" in mt:
            cols.append(("identified (median)", mt["identified_median"][trial]))
        if truth:
            cols.append(("truth", mt["truth"][trial]))
        parts.append(_table([trial] + [c[0] for c in cols], _metric_rows(cols)))
    head = ["criterion", "identified (run 0)"] + (["truth", "runs passing"] if truth else [])
    parts.append(_table(head + ["limit", "source"], imo_rows(mt["imo"], truth),
                        "IMO MSC.137(76) section 5.3 and the paper's band (for reference "
                        "only below 100 m)"))
    captions = _CAPTIONS if doc["kind"] == "vessel" else {
        **_CAPTIONS, "convergence": _CAPTIONS["convergence"].replace("; dashed: the truth", ""),
        "trials": _CAPTIONS["trials"].replace(" (dashed: the truth's)", "")}
    parts += notes_and_figures(list(notes), images, captions)
    parts += [f'<p class="meta">Generated by trackkit {esc(__version__)}.</p>', "</body>",
              "</html>", ""]
    return "\n".join(parts)


def _scenario_sections(doc: Mapping[str, Any]) -> list[str]:
    esc = html.escape
    sz = doc["sigma_z"]
    meta = (f"{doc['runs']} Monte Carlo runs, seed {doc['seed']}; identification data: "
            f"{doc['data']} ({doc['samples']} samples of {doc['period_s']:g} s: "
            f"{', '.join(doc['data_trials'])}); measurement noise assumed by the identifier "
            f"u {sz[0]:.3g} m/s, v {sz[1]:.3g} m/s, r {math.degrees(sz[2]):.3g} deg/s.")
    parts = [f'<p class="meta">{esc(meta)}</p>', "<h2>Identified coefficients</h2>"]
    shown = doc["shown_filter"]
    names = list(doc["filters"])
    rows = []
    truth = doc["truth"]["coefficients"]
    f0 = doc["filters"][shown]["coefficients_run0"]
    for k in COEFFICIENT_NAMES:
        row = [k, _fmt(truth[k]), f"{_fmt(f0[k]['value'])} +- {_fmt(f0[k]['std'], '.2g')}"]
        row += [_fmt(100 * v if (v := doc["filters"][n]["rel_error_median"][k]) is not None
                     else None, ".1f") for n in names]
        rows.append(row)
    parts.append(_table(["coefficient", "truth", f"{shown} run 0 (+- 1 sd)"]
                        + [f"{n}: median error [%]" for n in names], rows,
                        "Prime units (L = 19.6 m, U0 = 18 kn, n0 = 2000 rpm)."))
    rows = []
    lo, hi = doc["nees_band"]
    for n, f in doc["filters"].items():
        br, bn = f["body_rmse_median"], f["body_rmse_over_noise_median"]
        rows.append([n, _fmt(f["nees_median"], ".3g"),
                     _fmt(100 * f["nees_inside_fraction"], ".0f"),
                     "-" if br[0] is None else
                     f"{br[0]:.3f} / {br[1]:.3f} / {math.degrees(br[2]):.3f}",
                     "-" if bn[0] is None else f"{bn[0]:.2f} / {bn[1]:.2f} / {bn[2]:.2f}"])
    parts.append(_table(["filter", "NEES (median)", f"NEES in [{lo:.1f}, {hi:.1f}] [% of runs]",
                         "filtered u / v / r RMSE [m/s, m/s, deg/s]",
                         "filtered RMSE / measurement RMSE"], rows,
                        "Medians over the runs; the coefficients' NEES is chi-square(16) when "
                        "the stated covariance is right."))
    tr = doc["trial"]
    if tr is not None:
        parts.append(f"<h2>The {esc(tr['kind'])} trial</h2>")
        text = (f"Position RMSE against the truth (median over runs): raw GPS "
                f"{_fmt(tr['gps_rmse_median_m'], '.3g')} m, filtered track "
                f"{_fmt(tr['filtered_rmse_median_m'], '.3g')} m, identified model driven by "
                f"the inputs {_fmt(tr['model_rmse_median_m'], '.3g')} m (largest "
                f"{_fmt(tr['model_max_error_median_m'], '.3g')} m) over "
                f"{tr['duration_s']:g} s.")
        parts.append(f"<p>{esc(text)}</p>")
        m = tr["metrics"]
        parts.append(_table(["metric", "truth", "measured (median)", "model (median)"],
                            _metric_rows([("truth", m["truth"]),
                                               ("measured", m["measured_median"]),
                                               ("model", m["model_median"])])))
    return parts


def _log_sections(doc: Mapping[str, Any]) -> list[str]:
    esc = html.escape
    meta = (f"{doc['samples']} samples of {doc['period_s']:g} s "
            f"({doc['end_s'] - doc['start_s']:g} s) identified with {doc['filter']}; "
            f"{doc['identified_count']} of 16 coefficients with a standard deviation within "
            f"{100 * doc['rel_sd_limit']:.0f}% of their value.")
    parts = [f'<p class="meta">{esc(meta)}</p>', "<h2>Identified coefficients</h2>"]
    rows = [[k, _fmt(c["value"]), _fmt(c["std"], ".3g"),
             _fmt(None if c["rel_std"] is None else 100 * c["rel_std"], ".0f"),
             "yes" if c["identified"] else "no"] for k, c in doc["coefficients"].items()]
    parts.append(_table(["coefficient", "value", "std", "relative std [%]", "identified"],
                        rows, "Prime units of L = 19.6 m, U0 = 18 kn, n0 = 2000 rpm."))
    text = (f"The identified model driven by the log's inputs from the first sample stays "
            f"{_fmt(doc['model_rmse_m'], '.3g')} m (RMS) from the GPS fixes; the filtered "
            f"track {_fmt(doc['filtered_rmse_m'], '.3g')} m. Straight-line stable at the "
            f"log's speed: {'yes' if doc['stable'] else 'no'}.")
    parts.append(f"<p>{esc(text)}</p>")
    return parts


# ---------------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------------


def _scenario_images(res: VesselResult, folder: Path) -> dict[str, Path]:
    images: dict[str, Path] = {}
    f = res.filters[res.shown]
    if f.history is not None:
        images["convergence"] = save_figure(convergence_figure(
            res.t, f.history, f.history_std, res.truth.theta,
            f"{res.scenario}: {f.name} run 0, coefficients with +-2 sigma"),
            folder / CONVERGENCE_PNG)
    d = res.trial
    if d is not None:
        images["track"] = save_figure(track_figure(
            d.gps[0], None if d.filtered_pose is None else d.filtered_pose[0],
            d.model_pose[0], d.truth_pose, f"{res.scenario}: the {d.kind} trial, run 0"),
            folder / TRACK_PNG)
        images["heading"] = save_figure(heading_figure(
            d.t, d.heading[0], d.model_pose[0, :, 2], d.inputs[:, 0], d.truth_pose[:, 2],
            f"{res.scenario}: heading and nozzle, run 0"), folder / HEADING_PNG)
    images["trials"] = save_figure(trials_figure(res.model, res.model_truth,
                                           f"{res.scenario}: {res.shown} run 0's model"),
                             folder / TRIALS_PNG)
    if res.runs > 1:
        images["errors"] = save_figure(errors_figure(res), folder / ERRORS_PNG)
    return images


def _write_scenario(res: VesselResult, scenario, folder: Path) -> dict[str, Path]:
    images = _scenario_images(res, folder)
    doc = vessel_results_document(res)
    written: dict[str, Path] = dict(images)
    written["html"] = folder / REPORT_HTML
    written["html"].write_text(render_vessel_html(doc, scenario.name, scenario.description,
                                                  scenario.notes, images), encoding="utf-8")
    written["timings"] = write_json(vessel_timings_document(res), folder / TIMINGS_JSON)
    written["results"] = write_json(doc, folder / RESULTS_JSON)
    return written


def write_vessel_report(res: VesselResult, scenario, out: str | Path) -> dict[str, Path]:
    """Write a scenario's report files into ``out`` atomically (a temporary directory inside
    ``out``, ``results.json`` moved into place last, nothing left behind on failure).
    Returns name -> path."""
    return write_atomically(out, lambda folder: _write_scenario(res, scenario, folder),
                            VESSEL_FILES)


def _write_recorded(rec: RecordedIdentification, title: str, notes: Sequence[str],
                    log_read: Any, inputs_read: Any, folder: Path) -> dict[str, Path]:
    images: dict[str, Path] = {}
    if rec.history is not None:
        images["convergence"] = save_figure(convergence_figure(
            rec.t - rec.t[0], rec.history, rec.history_std, None,
            f"{title}: {rec.filter}, coefficients with +-2 sigma"), folder / CONVERGENCE_PNG)
    filtered = None if rec.filter == "ls" else rec.filtered_pose
    images["track"] = save_figure(track_figure(rec.pose[:, :2], filtered, rec.model_pose, None,
                                         f"{title}: measured against the identified model"),
                            folder / TRACK_PNG)
    images["heading"] = save_figure(heading_figure(rec.t - rec.t[0], rec.pose[:, 2],
                                             rec.model_pose[:, 2], rec.s[:, 0], None,
                                             f"{title}: heading and nozzle"),
                              folder / HEADING_PNG)
    images["trials"] = save_figure(
        trials_figure(rec.trials, None, f"{title}: the identified model"), folder / TRIALS_PNG)
    doc = recorded_results_document(rec, log_read, inputs_read)
    written: dict[str, Path] = dict(images)
    written["html"] = folder / REPORT_HTML
    written["html"].write_text(render_vessel_html(doc, title, "", notes, images),
                               encoding="utf-8")
    written["results"] = write_json(doc, folder / RESULTS_JSON)
    return written


def write_recorded_report(rec: RecordedIdentification, out: str | Path, *, title: str,
                          notes: Sequence[str] = (), log_read: Any = None,
                          inputs_read: Any = None) -> dict[str, Path]:
    """Write a recorded log's report files into ``out`` atomically. ``log_read`` and
    ``inputs_read``: the readers' ``ReadReport`` (their counts go into results.json)."""
    return write_atomically(out, lambda folder: _write_recorded(
        rec, title, notes, log_read, inputs_read, folder), VESSEL_FILES)
