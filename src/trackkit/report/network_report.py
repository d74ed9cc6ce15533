"""The report of a network Monte Carlo (Jalalipoor and Kardehi Moghaddam 2021), written atomically
into one
directory with ``report.files.write_atomically``:

* ``results.json``: per agent (numbered from 1) the fraction of runs ending with every target
  held, the mean number of confirmed tracks and mean GOSPA, and per target the position RMSE
  over the first and the last window, the velocity and range RMSE over the last window, the
  centralised reference's and the PCRLB's values over the same windows and the ratios to
  them, and the fraction of executions with the target held; the centralised reference's
  own numbers; message counts; the series against time (``series``). SI units, listed under
  ``units``; only numbers that depend on the scenario and the seed, so equal seeds give
  byte-identical files; wall-clock times go to ``timings.json``.
* ``paths.png``: run 0 in plan view: the agents' paths, the targets' paths and one agent's
  confirmed tracks (the paper's Figs. 7-12).
* ``errors.png``: position, velocity and range RMSE against time per agent (pooled over the
  targets), beside the centralised reference and the PCRLB.
* ``gospa.png``: mean GOSPA against time per agent and the centralised reference, and the
  mean number of confirmed tracks against the number of targets.
* ``courses.png`` and a ``courses`` entry in ``results.json``, when the same runs on
  straight courses are given (``straight=``): position RMSE against time, steered and
  straight, and the paired comparison over the last window (``experiments.network_compare``) with
  the verdict whether steering pays.
* ``report.html``: one self-contained page (inline CSS, PNGs as data URIs, no scripts).

    mc = run_network_mc(scenario)                     # trackkit.experiments.network_mc
    paths = write_network_report(mc, scenario, "trackkit-out/net-baseline")
    flat = run_network_mc(scenario, steering=False)   # the same runs on straight courses
    paths = write_network_report(mc, scenario, "trackkit-out/net-baseline", straight=flat)
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from trackkit import __version__
from trackkit.experiments.network_compare import PairedComparison, compare_networks
from trackkit.experiments.network_mc import NetworkMonteCarlo
from trackkit.report.files import (
    REPORT_HTML,
    RESULTS_JSON,
    TIMINGS_JSON,
    finite_or_none,
    write_atomically,
    write_json,
)
from trackkit.report.html import CSS, notes_and_figures
from trackkit.report.plots import distance_scale, finish_gospa_panels, gospa_panels, save_figure

__all__ = ["NETWORK_FILES", "network_results_document", "network_timings_document",
           "paths_figure", "errors_figure", "gospa_figure", "courses_figure",
           "render_network_html", "write_network_report"]

PATHS_PNG = "paths.png"
ERRORS_PNG = "errors.png"
GOSPA_PNG = "gospa.png"
COURSES_PNG = "courses.png"
#: The files the network report owns (an earlier run's not written again are removed).
NETWORK_FILES = (PATHS_PNG, ERRORS_PNG, GOSPA_PNG, COURSES_PNG, REPORT_HTML, TIMINGS_JSON,
                 RESULTS_JSON)

#: per-agent entries of results.json with their units
AGENT_UNITS: dict[str, str] = {
    "agent": "agent number (1 = the scenario's first agent)",
    "all_held_final_fraction": "fraction 0 to 1 of runs ending with exactly one confirmed "
                               "track per target, each within c_m of its target",
    "confirmed_tracks_mean": "tracks (mean over runs and executions)",
    "gospa_mean": "m (mean over runs and executions; p = 2, alpha = 2, cut-off c_m)",
    "held_fraction": "per target: fraction 0 to 1 of (run, execution) with a track assigned",
    "rmse_pos_first": "m, per target, over the first window (runs and executions where held)",
    "rmse_pos_last": "m, per target, over the last window",
    "rmse_vel_last": "m/s, per target, over the last window",
    "rmse_range_last": "m, per target, over the last window (range from this agent)",
    "rmse_pos_first_all": "m, pooled over targets, first window",
    "rmse_pos_last_all": "m, pooled over targets, last window",
    "central_rmse_pos_last": "m, per target: the centralised reference at this agent's "
                             "executions, last window",
    "central_rmse_vel_last": "m/s, per target, likewise",
    "central_rmse_range_last": "m, per target, likewise (range from this agent)",
    "pcrlb_pos_last": "m, per target: sqrt(mean over runs and the last window's executions of "
                      "the centralised PCRLB^2)",
    "pcrlb_vel_last": "m/s, per target, likewise",
    "pcrlb_range_last": "m, per target, likewise, on the range from this agent "
                        "(sqrt(e^T J^-1 e), e the unit line of sight)",
    "ratio_to_central_pos_last": "1, per target: rmse_pos_last / central_rmse_pos_last",
    "ratio_to_pcrlb_pos_last": "1, per target: rmse_pos_last / pcrlb_pos_last",
}
CENTRAL_UNITS: dict[str, str] = {
    "all_held_final_fraction": "fraction 0 to 1 of runs",
    "gospa_mean": "m (mean over runs and its executions)",
}
TOP_UNITS: dict[str, Any] = {
    "runs": "Monte Carlo runs", "agents": "agents", "targets": "targets",
    "duration_s": "s", "period_s": "s", "jitter_s": "s (executions delayed U[0, jitter_s))",
    "windows": "s ([from, to] of the first and the last window)",
    "metrics": {"c_m": "m (GOSPA cut-off and target-track assignment distance)",
                "gospa_p": "1", "gospa_alpha": "1"},
    "messages": "messages (totals over all runs: sent, delivered, lost, late; per run: "
                "means)",
    "channel": "loss: probability that one delivery is lost; delay_s: s; outages: agent "
               "(from 1), kill_at_s, restart_at_s (s), recovered_after_s per run (s from the "
               "restart until the agent held its tracks again; null if never); with CURVE "
               "(agents authenticated and encrypted): curve, peers_refused (connections "
               "refused for want of a key of the run, over all runs)",
    "courses": "steered against straight courses over the last window, per agent (numbered "
               "from 1): rmse_steered_m, rmse_straight_m (pooled position RMSE), ratio "
               "(steered / straight), steered_lower_share (fraction of runs), t and p (paired "
               "t test on the per-run MSE, two-sided), verdict; the same pooled over agents; "
               "whole_run: the pooled comparison over the whole run",
    "series": "time_s: s (slot times e P + jitter / 2); per agent over executions: "
              "confirmed_mean tracks, gospa_mean m, rmse_pos m, rmse_vel m/s, rmse_range m "
              "(pooled over targets), central_* likewise, pcrlb_pos m, pcrlb_vel m/s, "
              "pcrlb_range m",
}


# ---------------------------------------------------------------------------------------------
# numbers
# ---------------------------------------------------------------------------------------------


def _list(x: Any) -> Any:
    """Nested lists of floats, None where a value is missing or not finite (JSON null;
    ``finite_or_none`` does not look inside numpy arrays)."""
    if np.ndim(x) == 1:
        return [float(v) if math.isfinite(v) else None for v in np.asarray(x, dtype=float)]
    return [_list(v) for v in x]


def _curve_note(doc: dict) -> str:
    """The agents' CURVE, when the run had it: how many peers it refused."""
    ch = doc["channel"]
    if not ch.get("curve"):
        return ""
    return (" The agents were authenticated and encrypted with CURVE; "
            f"{ch['peers_refused']} other peers were refused.")


def _ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where((b > 0) & np.isfinite(b), a / np.where(b > 0, b, 1.0), np.nan)


def _agent_entries(mc: NetworkMonteCarlo) -> list[dict[str, Any]]:
    out = []
    first_pos = mc.window_rmse("pos", "first")
    last = {k: mc.window_rmse(k, "last") for k in ("pos", "vel", "rng")}
    held = (~np.isnan(mc.err["pos"])).mean(axis=(0, 2))  # (A, Nt)
    first_all = mc.window_rmse("pos", "first", pooled=True)
    last_all = mc.window_rmse("pos", "last", pooled=True)
    bound = {k: mc.window_bound(k, "last") for k in ("pos", "vel", "rng")}
    nan = np.full(last["pos"].shape, np.nan)
    central = ({k: mc.window_rmse(k, "last", central=True) for k in ("pos", "vel", "rng")}
               if mc.has_central else {"pos": nan, "vel": nan, "rng": nan})
    for a in range(mc.n_agents):
        out.append({
            "agent": a + 1,
            "all_held_final_fraction": float(mc.held_final[:, a].mean()),
            "confirmed_tracks_mean": float(mc.count[:, a].mean()),
            "gospa_mean": float(mc.gospa[:, a].mean()),
            "held_fraction": _list(held[a]),
            "rmse_pos_first": _list(first_pos[a]),
            "rmse_pos_last": _list(last["pos"][a]),
            "rmse_vel_last": _list(last["vel"][a]),
            "rmse_range_last": _list(last["rng"][a]),
            "rmse_pos_first_all": float(first_all[a]),
            "rmse_pos_last_all": float(last_all[a]),
            "central_rmse_pos_last": _list(central["pos"][a]),
            "central_rmse_vel_last": _list(central["vel"][a]),
            "central_rmse_range_last": _list(central["rng"][a]),
            "pcrlb_pos_last": _list(bound["pos"][a]),
            "pcrlb_vel_last": _list(bound["vel"][a]),
            "pcrlb_range_last": _list(bound["rng"][a]),
            "ratio_to_central_pos_last": _list(_ratio(last["pos"][a], central["pos"][a])),
            "ratio_to_pcrlb_pos_last": _list(_ratio(last["pos"][a], bound["pos"][a])),
        })
    return out


def _series(mc: NetworkMonteCarlo) -> dict[str, Any]:
    pooled = {k: mc.rmse_over_time(k, pooled=True) for k in ("pos", "vel", "rng")}
    per_agent = []
    for a in range(mc.n_agents):
        s: dict[str, Any] = {
            "confirmed_mean": _list(mc.count[:, a].mean(0)),
            "gospa_mean": _list(mc.gospa[:, a].mean(0)),
            "rmse_pos": _list(pooled["pos"][a]),
            "rmse_vel": _list(pooled["vel"][a]),
            "rmse_range": _list(pooled["rng"][a]),
            "pcrlb_pos": _list(mc.bound_over_time("pos", pooled=True)[a]),
            "pcrlb_vel": _list(mc.bound_over_time("vel", pooled=True)[a]),
            "pcrlb_range": _list(mc.bound_over_time("rng", pooled=True)[a]),
        }
        if mc.has_central:
            s["central_confirmed_mean"] = _list(mc.central_count[:, a].mean(0))
            s["central_gospa_mean"] = _list(mc.central_gospa[:, a].mean(0))
            for k, name in (("pos", "pos"), ("vel", "vel"), ("rng", "range")):
                s[f"central_rmse_{name}"] = _list(mc.rmse_over_time(k, central=True,
                                                                    pooled=True)[a])
        per_agent.append(s)
    return {"time_s": _list(mc.time), "agents": per_agent}


def _courses_entry(c: PairedComparison, whole: PairedComparison) -> dict[str, Any]:
    per_agent = [{
        "agent": i + 1, "rmse_steered_m": float(c.rmse_a[i]),
        "rmse_straight_m": float(c.rmse_b[i]), "ratio": float(c.ratio[i]),
        "steered_lower_share": float(c.lower_share[i]), "t": float(c.t[i]),
        "p": float(c.p[i]), "paired_runs": int(c.runs[i]), "verdict": c.verdict[i],
        "all_held_final_steered": float(c.held_a[i]),
        "all_held_final_straight": float(c.held_b[i]),
    } for i in range(c.rmse_a.size)]
    return {"window_s": list(c.window), "confidence": c.confidence, "per_agent": per_agent,
            "rmse_steered_m": c.rmse_a_all, "rmse_straight_m": c.rmse_b_all,
            "ratio": c.ratio_all, "steered_lower_share": c.lower_share_all, "t": c.t_all,
            "p": c.p_all, "verdict": c.verdict_all, "steering_pays": steering_pays(c),
            "whole_run": {"rmse_steered_m": whole.rmse_a_all,
                          "rmse_straight_m": whole.rmse_b_all, "ratio": whole.ratio_all,
                          "steered_lower_share": whole.lower_share_all, "t": whole.t_all,
                          "p": whole.p_all, "verdict": whole.verdict_all,
                          "steering_pays": steering_pays(whole)}}


def steering_pays(c: PairedComparison) -> str:
    """The report's one-line answer: "yes", "no" (it costs accuracy) or "not measurably"."""
    return {"lower": "yes", "higher": "no"}.get(c.verdict_all, "not measurably")


def network_results_document(mc: NetworkMonteCarlo, scenario,
                             courses: tuple[PairedComparison, PairedComparison] | None = None
                             ) -> dict[str, Any]:
    """The ``results.json`` document (module docstring); non-finite numbers as null."""
    doc: dict[str, Any] = {
        "scenario": scenario.name,
        "kind": "network",
        "runs": int(mc.runs),
        "seed": int(mc.seed),
        "steering": bool(mc.steering),
        "central": bool(mc.has_central),
        "agents": mc.n_agents,
        "targets": mc.n_targets,
        "duration_s": float(mc.duration),
        "period_s": float(mc.period),
        "jitter_s": float(mc.jitter),
        "windows": {"first": list(mc.window_s("first")), "last": list(mc.window_s("last"))},
        "metrics": {"c_m": float(mc.c), "gospa_p": 2.0, "gospa_alpha": 2.0},
        "units": {**TOP_UNITS, "per_agent": dict(AGENT_UNITS),
                  "central_reference": dict(CENTRAL_UNITS)},
        "per_agent": _agent_entries(mc),
        "central_reference": ({
            "all_held_final_fraction": float(mc.central_held_final.mean()),
            "gospa_mean": float(mc.central_gospa.mean()),
        } if mc.has_central else None),
        "messages": {
            "sent": int(mc.sent.sum()), "delivered": int(mc.delivered.sum()),
            "lost": int(mc.lost.sum()), "late": int(mc.late.sum()),
            "sent_per_run": float(mc.sent.mean()), "lost_per_run": float(mc.lost.mean()),
            "late_per_run": float(mc.late.mean()),
        },
        "channel": {
            "loss": float(mc.loss), "delay_s": float(mc.delay),
            "outages": [{"agent": int(a) + 1, "kill_at_s": float(k),
                         "restart_at_s": None if r is None else float(r),
                         "recovered_after_s": _list(mc.recovered[:, i])}
                        for i, (a, k, r) in enumerate(mc.outages)],
            **({"curve": True, "peers_refused": int(mc.refused.sum())} if mc.curve else {}),
        },
        "series": _series(mc),
    }
    if courses is not None:
        doc["courses"] = _courses_entry(*courses)
    return finite_or_none(doc)


def network_timings_document(mc: NetworkMonteCarlo, scenario) -> dict[str, Any]:
    """The ``timings.json`` document: wall-clock seconds per run (they vary between
    machines and runs, so they are kept out of results.json)."""
    return finite_or_none({
        "scenario": scenario.name, "runs": int(mc.runs), "seed": int(mc.seed),
        "units": {"network_s_per_run": "s (run_network: every agent's program and the "
                                       "centralised reference)",
                  "total_s_per_run": "s (run_network, scoring and the PCRLB)"},
        "network_s_per_run": float(mc.seconds.mean()),
        "total_s_per_run": float(mc.wall.mean()),
    })


# ---------------------------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------------------------


def paths_figure(mc: NetworkMonteCarlo, scenario) -> Figure:
    """Run 0 in plan view: agents' paths (coloured, triangle at the start, numbers at the
    end), targets' paths (black, circle at the start, numbers) and the example agent's
    confirmed track positions (small dots, one colour per track ID)."""
    ex = mc.example
    fig = Figure(figsize=(7.5, 7.0), layout="constrained")
    ax = fig.add_subplot()
    if ex is None:
        ax.text(0.5, 0.5, "no example run", ha="center", va="center")
        return fig
    k = scenario.report.example_agent - 1
    agent_xy = [tr.position for tr in ex.agents]
    truth = ex.agents[k].truth  # (E, Nt, 4): the targets at that agent's executions
    pts = np.concatenate([*agent_xy, truth[:, :, :2].reshape(-1, 2)])
    lo, hi = pts.min(0), pts.max(0)
    unit, s = distance_scale(float((hi - lo).max()) or 1000.0)
    for a, xy in enumerate(agent_xy):
        ax.plot(xy[:, 0] * s, xy[:, 1] * s, color=f"C{a}", lw=1.8, label=f"agent {a + 1}")
        ax.plot(xy[0, 0] * s, xy[0, 1] * s, "^", color=f"C{a}", ms=7)
        ax.annotate(str(a + 1), xy[-1] * s, color=f"C{a}", xytext=(3, 3),
                    textcoords="offset points")
    for j in range(truth.shape[1]):
        ax.plot(truth[:, j, 0] * s, truth[:, j, 1] * s, color="black", lw=1.2,
                label="targets" if j == 0 else None)
        ax.plot(truth[0, j, 0] * s, truth[0, j, 1] * s, "o", color="black", ms=4)
        ax.annotate(f"T{j + 1}", truth[-1, j, :2] * s, xytext=(3, -10),
                    textcoords="offset points")
    tr = ex.agents[k]
    if tr.ids.size:
        ax.scatter(tr.mean[:, 0] * s, tr.mean[:, 1] * s, s=3, c=[f"C{i % 10}" for i in tr.ids],
                   alpha=0.6, linewidths=0, label=f"agent {k + 1}'s confirmed tracks")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"east [{unit}]")
    ax.set_ylabel(f"north [{unit}]")
    mode = "steering" if mc.steering else "straight courses"
    ax.set_title(f"{scenario.name}: run 0 ({mode})", fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    return fig


def errors_figure(mc: NetworkMonteCarlo, scenario) -> Figure:
    """One row per agent, columns position, velocity and range RMSE (pooled over targets)
    against time, with the centralised reference (dashed) and the PCRLB (dotted)."""
    A = mc.n_agents
    fig = Figure(figsize=(11.0, 2.6 * A + 0.6), layout="constrained")
    axes = np.atleast_2d(fig.subplots(A, 3, sharex=True))
    t = mc.time
    cols = (("pos", "position RMSE [m]"), ("vel", "velocity RMSE [m/s]"),
            ("rng", "range RMSE [m]"))
    for a in range(A):
        for i, (kind, label) in enumerate(cols):
            ax = axes[a, i]
            ax.plot(t, mc.rmse_over_time(kind, pooled=True)[a], color=f"C{a}", lw=1.3,
                    label=f"agent {a + 1}")
            if mc.has_central:
                ax.plot(t, mc.rmse_over_time(kind, central=True, pooled=True)[a], color="0.3",
                        ls="--", lw=1.1, label="centralised")
            ax.plot(t, mc.bound_over_time(kind, pooled=True)[a], color="black", ls=":",
                    lw=1.1, label="PCRLB (centralised)")
            ax.set_yscale("log")
            ax.set_ylabel(label)
            ax.grid(True, alpha=0.3, which="both")
            if i == 0:
                ax.legend(fontsize="x-small")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(f"{scenario.name}: RMSE over {mc.runs} runs (targets held, pooled over "
                 "targets)", fontsize="medium")
    return fig


def gospa_figure(mc: NetworkMonteCarlo, scenario) -> Figure:
    """Mean GOSPA against time per agent (and the centralised reference), and the mean
    number of confirmed tracks against the number of targets."""
    fig, top, bottom = gospa_panels(f"{scenario.name}: GOSPA (c = {mc.c:g} m, p = 2, "
                                    f"alpha = 2), mean of {mc.runs} runs")
    t = mc.time
    for a in range(mc.n_agents):
        top.plot(t, mc.gospa[:, a].mean(0), color=f"C{a}", lw=1.2, label=f"agent {a + 1}")
        bottom.plot(t, mc.count[:, a].mean(0), color=f"C{a}", lw=1.2, label=f"agent {a + 1}")
    if mc.has_central:
        top.plot(t, mc.central_gospa.mean(axis=(0, 1)), color="0.3", ls="--", lw=1.1,
                 label="centralised")
    bottom.axhline(mc.n_targets, color="black", ls="--", lw=1.0, label="targets")
    finish_gospa_panels(top, bottom)
    return fig


def courses_figure(mc: NetworkMonteCarlo, straight: NetworkMonteCarlo, scenario) -> Figure:
    """Position RMSE against time per agent (pooled over targets), steered (solid) and on
    straight courses (dashed), the same runs, beside the centralised PCRLB of each."""
    A = mc.n_agents
    fig = Figure(figsize=(8.0, 2.4 * A + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(A, 1, sharex=True))
    t = mc.time
    for a, ax in enumerate(axes):
        ax.plot(t, mc.rmse_over_time("pos", pooled=True)[a], color=f"C{a}", lw=1.3,
                label=f"agent {a + 1}, steered")
        ax.plot(t, straight.rmse_over_time("pos", pooled=True)[a], color=f"C{a}", ls="--",
                lw=1.1, label="straight courses")
        ax.plot(t, mc.bound_over_time("pos", pooled=True)[a], color="black", ls=":", lw=1.0,
                label="PCRLB, steered")
        ax.plot(t, straight.bound_over_time("pos", pooled=True)[a], color="0.5", ls=":",
                lw=1.0, label="PCRLB, straight")
        ax.set_yscale("log")
        ax.set_ylabel("position RMSE [m]")
        ax.grid(True, alpha=0.3, which="both")
        ax.legend(fontsize="x-small")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{scenario.name}: steered against straight courses, the same {mc.runs} "
                 "runs", fontsize="medium")
    return fig


# ---------------------------------------------------------------------------------------------
# page
# ---------------------------------------------------------------------------------------------

_CAPTIONS = {
    "paths": "Monte Carlo run 0: the agents' paths (triangle at the start), the targets "
             "(black, circle at the start) and the example agent's confirmed tracks (dots, "
             "one colour per track ID), east-north frame.",
    "errors": "RMSE against time per agent (over the runs where a target is held, pooled over "
              "the targets), beside the centralised reference at the same times (dashed) and "
              "the centralised PCRLB on the run's actual paths (dotted; RMS over runs).",
    "courses": "Position RMSE against time per agent, steered (solid) and on straight "
               "courses (dashed), the same runs (targets and bearing noise), with each one's "
               "centralised PCRLB (dotted).",
    "gospa": "GOSPA against time, mean over the runs, per agent and for the centralised "
             "reference (top); mean number of confirmed tracks against the number of "
             "targets (bottom).",
}


def _num(v: Any, spec: str = ".0f") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, spec)


def _per_target(values: list, spec: str = ".0f") -> str:
    return " / ".join(_num(v, spec) for v in values)


def _summary_table(doc: Mapping[str, Any]) -> str:
    esc = html.escape
    rows = (("all_held_final_fraction", "runs ending with every target held [%]", None),
            ("confirmed_tracks_mean", "confirmed tracks (mean)", ".2f"),
            ("gospa_mean", "GOSPA mean [m]", ".0f"),
            ("held_fraction", "held, per target [%]", "%"),
            ("rmse_pos_first", "position RMSE, first window [m]", ".0f"),
            ("rmse_pos_last", "position RMSE, last window [m]", ".0f"),
            ("central_rmse_pos_last", "centralised, last window [m]", ".0f"),
            ("pcrlb_pos_last", "PCRLB, last window [m]", ".0f"),
            ("ratio_to_central_pos_last", "ratio to centralised", ".2f"),
            ("ratio_to_pcrlb_pos_last", "ratio to PCRLB", ".2f"),
            ("rmse_vel_last", "velocity RMSE, last window [m/s]", ".2f"),
            ("rmse_range_last", "range RMSE, last window [m]", ".0f"),
            ("pcrlb_range_last", "range PCRLB, last window [m]", ".0f"))
    agents = doc["per_agent"]
    head = "".join(f"<th>agent {e['agent']}</th>" for e in agents)
    body = []
    for key, label, spec in rows:
        cells = []
        for e in agents:
            v = e[key]
            if isinstance(v, list):
                vals = [None if x is None else (100 * x if spec == "%" else x) for x in v]
                cells.append(_per_target(vals, ".0f" if spec == "%" else spec))
            elif spec is None:
                cells.append(_num(None if v is None else 100 * v, ".0f"))
            else:
                cells.append(_num(v, spec))
        body.append(f"<tr><th>{esc(label)}</th>"
                    + "".join(f"<td>{esc(c)}</td>" for c in cells) + "</tr>")
    w = doc["windows"]
    caption = (f"{doc['runs']} runs; per-target values separated by '/', targets 1 to "
               f"{doc['targets']}; first window {w['first'][0]:g}-{w['first'][1]:g} s, last "
               f"window {w['last'][0]:g}-{w['last'][1]:g} s; errors over the (run, execution) "
               "pairs where the target is held.")
    return (f'<table class="summary"><caption>{esc(caption)}</caption>'
            f"<thead><tr><th></th>{head}</tr></thead>\n<tbody>\n" + "\n".join(body)
            + "\n</tbody></table>")


def _courses_section(c: Mapping[str, Any]) -> list[str]:
    esc = html.escape
    w = c["window_s"]
    conf = 100 * c["confidence"]
    answer = {"yes": "Steering pays", "no": "Steering costs accuracy",
              "not measurably": "Steering makes no difference measurable"}[c["steering_pays"]]
    text = (f"{answer} here: over {w[0]:g}-{w[1]:g} s the agents' position RMSE is "
            f"{_num(c['rmse_steered_m'])} m steered against {_num(c['rmse_straight_m'])} m on "
            f"straight courses (ratio {_num(c['ratio'], '.2f')}); the steered error is lower "
            f"in {_num(100 * c['steered_lower_share'])}% of the runs (paired t = "
            f"{_num(c['t'], '.2f')}, p = {_num(c['p'], '.2g')}, at {conf:g}% confidence; "
            "the same runs, targets and bearing noise).")
    w2 = c["whole_run"]
    text += (f" Over the whole run: {_num(w2['rmse_steered_m'])} m against "
             f"{_num(w2['rmse_straight_m'])} m (ratio {_num(w2['ratio'], '.3f')}, steered lower "
             f"in {_num(100 * w2['steered_lower_share'])}% of runs, t = {_num(w2['t'], '.2f')}, "
             f"p = {_num(w2['p'], '.2g')}: steering pays {w2['steering_pays']}).")
    rows = []
    for e in c["per_agent"]:
        rows.append("<tr>" + "".join(f"<td>{esc(x)}</td>" for x in (
            str(e["agent"]), _num(e["rmse_steered_m"]), _num(e["rmse_straight_m"]),
            _num(e["ratio"], ".2f"), _num(100 * e["steered_lower_share"]),
            _num(e["t"], ".2f"), _num(e["p"], ".2g"), e["verdict"],
            _num(100 * e["all_held_final_steered"]),
            _num(100 * e["all_held_final_straight"]))) + "</tr>")
    head = ("<tr><th>agent</th><th>steered RMSE [m]</th><th>straight RMSE [m]</th>"
            "<th>ratio</th><th>steered lower [% of runs]</th><th>t</th><th>p</th>"
            "<th>steered error</th><th>all held at end, steered [%]</th>"
            "<th>straight [%]</th></tr>")
    return ["<h2>Steering against straight courses</h2>", f"<p>{esc(text)}</p>",
            f'<table class="summary"><thead>{head}</thead><tbody>\n' + "\n".join(rows)
            + "\n</tbody></table>"]


def render_network_html(doc: Mapping[str, Any], scenario,
                        images: Mapping[str, str | Path | bytes]) -> str:
    """The report page from the ``results.json`` document and the figures (name -> PNG
    path or bytes): self-contained, no scripts, no links."""
    esc = html.escape
    m = doc["messages"]
    mode = "steering" if doc["steering"] else "straight courses"
    c = doc["central_reference"]
    central = ("" if c is None else
               f" The centralised reference ends with every target held in "
               f"{100 * c['all_held_final_fraction']:.0f}% of the runs; its mean GOSPA is "
               f"{_num(c['gospa_mean'])} m.")
    meta = (f"{doc['runs']} Monte Carlo runs, seed {doc['seed']}; {doc['agents']} agents "
            f"({mode}), {doc['targets']} targets, {doc['duration_s']:g} s, executions every "
            f"{doc['period_s']:g} s delayed U[0, {doc['jitter_s']:g}) s. Messages: "
            f"{m['sent']} sent, {m['lost']} lost, {m['late']} late.{_curve_note(doc)}{central} "
            "Generated by "
            "trackkit "
            f"{__version__}.")
    parts = [
        "<!DOCTYPE html>", '<html lang="en">', '<head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>trackkit: {esc(scenario.name)}</title>", f"<style>{CSS}</style></head>",
        "<body>", f"<h1>{esc(scenario.name)}</h1>",
    ]
    if scenario.description:
        parts.append(f"<p>{esc(scenario.description)}</p>")
    parts += [f'<p class="meta">{esc(meta)}</p>', "<h2>Summary</h2>", _summary_table(doc)]
    if "courses" in doc:
        parts += _courses_section(doc["courses"])
    parts += notes_and_figures(scenario.notes, images, _CAPTIONS)
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


# ---------------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------------


def _write_all(mc: NetworkMonteCarlo, scenario, folder: Path,
               straight: NetworkMonteCarlo | None) -> dict[str, Path]:
    images: dict[str, Path] = {}
    if mc.example is not None:
        images["paths"] = save_figure(paths_figure(mc, scenario), folder / PATHS_PNG)
    images["errors"] = save_figure(errors_figure(mc, scenario), folder / ERRORS_PNG)
    images["gospa"] = save_figure(gospa_figure(mc, scenario), folder / GOSPA_PNG)
    courses = None
    if straight is not None:
        images["courses"] = save_figure(courses_figure(mc, straight, scenario),
                                        folder / COURSES_PNG)
        courses = tuple(compare_networks(mc, straight, label_a="steered", label_b="straight",
                                         which=w) for w in ("last", "all"))
    written: dict[str, Path] = dict(images)
    doc = network_results_document(mc, scenario, courses)
    written["html"] = folder / REPORT_HTML
    written["html"].write_text(render_network_html(doc, scenario, images), encoding="utf-8")
    written["timings"] = write_json(network_timings_document(mc, scenario),
                                     folder / TIMINGS_JSON)
    written["results"] = write_json(doc, folder / RESULTS_JSON)
    return written


def write_network_report(mc: NetworkMonteCarlo, scenario, out: str | Path,
                         straight: NetworkMonteCarlo | None = None) -> dict[str, Path]:
    """Write the report files into ``out`` atomically (``report.files.write_atomically``:
    a temporary directory inside ``out``, ``results.json`` moved into place last, nothing
    left behind on failure). ``straight``: the same runs on straight courses, for the
    steering comparison (``mc`` must then be steered). Returns name -> path (``paths``,
    ``errors``, ``gospa``, ``courses`` with ``straight``, ``html``, ``timings``,
    ``results``)."""
    if straight is not None and not (mc.steering and not straight.steering):
        raise ValueError(f"write_network_report: steering = {mc.steering} and straight's "
                         f"steering = {straight.steering}; expected a steered Monte Carlo "
                         "and the same runs on straight courses")
    return write_atomically(out, lambda folder: _write_all(mc, scenario, folder, straight),
                            NETWORK_FILES)
