"""Report figures, one PNG each: geometry, RMSE against time with the PCRLB, NEES with bounds;
and, for Naseri Solhdar's scenarios when the result has the data, the covariance matching of run 0
(R, S, C and DOM per channel), the tuned fuzzy systems' membership functions and the
optimisers' convergence.

Figures are ``matplotlib.figure.Figure`` objects rendered by the Agg canvas: no display, no
pyplot state and no global backend switch (safe in worker threads, CI and notebooks).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse
from matplotlib.ticker import LogFormatter, MaxNLocator

from trackkit.experiments.results import MonteCarloResult
from trackkit.filters.fuzzy import INPUT_SETS, OUTPUT_SETS, fis
from trackkit.report.tables import channel_labels, display_unit

__all__ = [
    "geometry_figure", "rmse_figure", "nees_figure", "plot_geometry", "plot_rmse", "plot_nees",
    "matching_figure", "membership_figure", "convergence_figure", "plot_matching",
    "plot_membership", "plot_convergence", "make_plots", "PLOT_FILES", "time_figure",
    "plot_time", "classes_figure", "plot_classes",
]

#: The file name of each report figure, by figure.
PLOT_FILES = {"geometry": "geometry.png", "rmse": "rmse.png", "nees": "nees.png",
              "matching": "matching.png", "membership": "membership.png",
              "convergence": "convergence.png", "time": "time.png", "classes": "classes.png"}
_DPI = 110


def save_figure(fig: Figure, path: str | Path, *, dpi: int = _DPI,
                metadata: dict[str, Any] | None = None) -> Path:
    """Write ``fig`` as a PNG at ``dpi``, rendered with Agg whatever the session's backend;
    ``metadata`` goes to the PNG's text chunks (``{"Software": None}`` leaves out the
    matplotlib version, for files that must not change with it)."""
    path = Path(path)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=dpi, format="png", metadata=metadata)
    return path


def distance_scale(extent: float) -> tuple[str, float]:
    return ("km", 1e-3) if extent > 5e3 else ("m", 1.0)


def _ellipse(mean: np.ndarray, cov: np.ndarray, nsigma: float, **kw) -> Ellipse | None:
    """The ``nsigma`` ellipse of a 2x2 covariance (None if not finite or not PSD)."""
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
        return None
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    if w[0] < 0:
        return None
    angle = np.degrees(np.arctan2(v[1, 1], v[0, 1]))
    width, height = 2 * nsigma * np.sqrt(w[1]), 2 * nsigma * np.sqrt(w[0])
    return Ellipse(tuple(mean), width, height, angle=angle, fill=False, **kw)


def _frame(ax, scene: np.ndarray, tracks: list[np.ndarray]) -> None:
    """Square limits around truth and observer, widened for estimates and ellipses up to one
    scene size away (a diverged track running off must not shrink the scene to a dot)."""
    if not len(scene):
        return
    lo, hi = scene.min(axis=0), scene.max(axis=0)
    span = max(float((hi - lo).max()), 1e-9)
    est = np.concatenate(tracks) if tracks else np.empty((0, 2))
    near = est[np.all(np.abs(est - np.clip(est, lo, hi)) <= span, axis=1)]  # nan: not near
    if len(near):
        lo, hi = np.minimum(lo, near.min(axis=0)), np.maximum(hi, near.max(axis=0))
    half = 0.55 * max(float((hi - lo).max()), 1e-9)  # square frame, 5% margin
    mid = 0.5 * (lo + hi)
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)


def geometry_figure(result: MonteCarloResult, every: int | None = None,
                    nsigma: float = 2.0) -> Figure | None:
    """Plan view (east, north) of one run: truth, observer and each filter's estimates, with
    ``nsigma`` covariance ellipses every ``every`` steps (about 10 per track by default).
    None when the result carries no example run."""
    ex = result.example
    if ex is None:
        return None
    truth = np.asarray(ex.truth)[:, :2]
    obs = np.asarray(ex.observer)[:, :2]
    steps = truth.shape[0]
    every = every or max(1, steps // 10)
    pts = np.concatenate([truth, obs])
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    extent = float(np.ptp(pts, axis=0).max()) if len(pts) else 1.0
    unit, s = distance_scale(extent)

    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(truth[:, 0] * s, truth[:, 1] * s, color="black", lw=2, label="truth")
    ax.plot(truth[0, 0] * s, truth[0, 1] * s, "o", color="black", ms=6)
    ax.plot(obs[:, 0] * s, obs[:, 1] * s, color="grey", lw=1.5, ls="--", label="observer")
    ax.plot(obs[0, 0] * s, obs[0, 1] * s, "s", color="grey", ms=6)
    near = [np.asarray(m)[:, :2] * s for m, _ in ex.estimates.values()]
    for i, (name, (means, covs)) in enumerate(ex.estimates.items()):
        color = f"C{i}"
        means = np.asarray(means)[:, :2]
        covs = np.asarray(covs)[:, :2, :2]
        ax.plot(means[:, 0] * s, means[:, 1] * s, color=color, lw=1.2, label=name)
        for k in range(0, steps, every):
            e = _ellipse(means[k] * s, covs[k] * s * s, nsigma, color=color, lw=0.8, alpha=0.8)
            if e is not None:
                ax.add_patch(e)
                r = nsigma * np.sqrt(np.diag(covs[k])) * s
                near.append(np.stack([means[k] * s - r, means[k] * s + r]))
    ax.plot([], [], color="0.4", lw=0.8, label=f"{nsigma:g}-sigma ellipses (every {every} steps)")
    _frame(ax, pts * s, near)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel(f"east [{unit}]")
    ax.set_ylabel(f"north [{unit}]")
    ax.set_title(f"{result.scenario}: geometry of one run (circle: target start, "
                 "square: observer start)", fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncols=3, fontsize="small",
              frameon=False)
    return fig


def plot_geometry(result: MonteCarloResult, path: str | Path, every: int | None = None,
                  nsigma: float = 2.0) -> Path | None:
    """Write :func:`~trackkit.report.plots.geometry_figure` as a PNG;
    None (nothing written) without an example run."""
    fig = geometry_figure(result, every, nsigma)
    return None if fig is None else save_figure(fig, path)


class _PlainLog(LogFormatter):
    """Log-axis labels as plain numbers (0.6, 6, 1e+04) on the ticks LogFormatter labels."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        return f"{x:g}" if super().__call__(x, pos) else ""


def _log_scale(ax) -> None:
    """Log y axis with plain-number tick labels (6, 0.6, 1e+04)."""
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(_PlainLog(labelOnlyBase=False))
    ax.yaxis.set_minor_formatter(_PlainLog(labelOnlyBase=False, minor_thresholds=(2, 0.5)))


def _log_if_wide(ax, values: list[np.ndarray]) -> None:
    v = np.concatenate([np.ravel(a) for a in values]) if values else np.array([])
    v = v[np.isfinite(v) & (v > 0)]
    if v.size and v.max() / v.min() > 30:
        _log_scale(ax)


def _mark_start(ax, result: MonteCarloResult) -> None:
    if 0 < result.start < len(result.times):
        ax.axvline(result.times[result.start], color="0.5", lw=0.8, ls=":",
                   label="averages start")


def rmse_figure(result: MonteCarloResult) -> Figure:
    """RMSE against time, one panel per error group, each filter solid and the PCRLB dashed
    (angle groups in degrees). A dotted vertical line marks the start of the time averages."""
    groups = list(result.groups)
    fig = Figure(figsize=(8, 2.6 * len(groups) + 0.6), layout="constrained")
    axes = fig.subplots(len(groups), 1, sharex=True, squeeze=False)[:, 0]
    t = np.asarray(result.times)
    for ax, g in zip(axes, groups, strict=True):
        label, factor = display_unit(result.groups[g])
        series = []
        for i, (name, f) in enumerate(result.filters.items()):
            if g in f.rmse:
                y = np.asarray(f.rmse[g]) * factor
                ax.plot(t, y, color=f"C{i}", lw=1.3, label=name)
                series.append(y)
        if g in result.pcrlb:
            y = np.asarray(result.pcrlb[g]) * factor
            ax.plot(t, y, color="black", lw=1.3, ls="--", label="PCRLB")
            series.append(y)
        _log_if_wide(ax, series)
        _mark_start(ax, result)
        ax.set_ylabel(f"{g} RMSE [{label}]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{result.scenario}: RMSE over {result.runs} runs", fontsize="medium")
    return fig


def plot_rmse(result: MonteCarloResult, path: str | Path) -> Path:
    """Write :func:`~trackkit.report.plots.rmse_figure` as a PNG."""
    return save_figure(rmse_figure(result), path)


def _same(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> bool:
    return all(np.allclose(x, y, equal_nan=True) for x, y in zip(a, b, strict=True))


def nees_figure(result: MonteCarloResult) -> Figure:
    """Average NEES (and NIS, when measured) against time with the two-sided 95% chi-square
    bounds dashed (black when all filters share them, else in each filter's colour); log
    scale."""
    has_nis = any(np.isfinite(np.asarray(f.nis)).any() for f in result.filters.values())
    panels = [("NEES", "nees", "nees_bounds")] + ([("NIS", "nis", "nis_bounds")] if has_nis else [])
    fig = Figure(figsize=(8, 3.2 * len(panels) + 0.6), layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    t = np.asarray(result.times)
    for ax, (title, attr, battr) in zip(axes, panels, strict=True):
        filters = list(result.filters.values())
        shared = all(_same(getattr(f, battr), getattr(filters[0], battr)) for f in filters)
        for i, f in enumerate(filters):
            ax.plot(t, getattr(f, attr), color=f"C{i}", lw=1.3, label=f.name)
        for i, f in enumerate(filters):
            if not shared or i == 0:
                color = "black" if shared else f"C{i}"
                lo, hi = getattr(f, battr)
                ax.plot(t, lo, color=color, lw=0.9, ls="--",
                        label="95% chi-square bounds" if i == 0 else None)
                ax.plot(t, hi, color=color, lw=0.9, ls="--")
        _log_scale(ax)
        _mark_start(ax, result)
        ax.set_ylabel(f"average {title} [-]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{result.scenario}: consistency over {result.runs} runs", fontsize="medium")
    return fig


def plot_nees(result: MonteCarloResult, path: str | Path) -> Path:
    """Write :func:`~trackkit.report.plots.nees_figure` as a PNG."""
    return save_figure(nees_figure(result), path)


# --- Naseri Solhdar's thesis: covariance matching, fuzzy membership functions, optimiser
# convergence ---------


def _color(result: MonteCarloResult, name: str) -> str:
    """A filter's colour, the same as in the RMSE and NEES figures."""
    names = list(result.filters)
    return f"C{names.index(name) if name in names else len(names)}"


_MATCHING_PANELS = (("R", "R(i,i) in use"), ("S", "S(i,i) innovation covariance"),
                    ("C", "C(i,i) windowed innovation cov."), ("DOM", "DOM(i,i) = S - C"))


def matching_figure(result: MonteCarloResult) -> Figure | None:
    """The covariance matching of run 0: one row per measurement channel, columns R, S, C
    (sharing one y axis per row, log when wide) and DOM (linear, it changes sign; zero
    dotted), one line per filter. None when the result carries no matching logs."""
    ex = result.example
    logs = {} if ex is None else {k: v for k, v in ex.logs.items() if v}
    if not logs:
        return None
    t = np.asarray(ex.times)
    m = np.shape(next(iter(logs.values()))["R"])[-1]
    fig = Figure(figsize=(14, 2.3 * m + 1.2), layout="constrained")
    axes = fig.subplots(m, 4, sharex=True, squeeze=False)
    for i, channel in enumerate(channel_labels(m)):
        row = axes[i]
        for ax in row[1:3]:
            ax.sharey(row[0])
        series = []
        for j, (key, title) in enumerate(_MATCHING_PANELS):
            ax = row[j]
            for name, log in logs.items():
                if key in log:
                    y = np.asarray(log[key], dtype=float)[:, i]
                    ax.plot(t, y, color=_color(result, name), lw=1.0, label=name)
                    if key != "DOM":
                        series.append(y)
            if i == 0:
                ax.set_title(title, fontsize="medium")
            ax.grid(True, which="both", alpha=0.3)
        row[3].axhline(0.0, color="black", lw=0.8, ls=":")
        _log_if_wide(row[0], series)
        row[0].set_ylabel(f"{channel} [SI units squared]")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=max(1, len(labels)),
               fontsize="small", frameon=False)
    fig.suptitle(f"{result.scenario}: covariance matching in run 0 (diagonals per "
                 "measurement channel)", fontsize="medium")
    return fig


def plot_matching(result: MonteCarloResult, path: str | Path) -> Path | None:
    """Write :func:`~trackkit.report.plots.matching_figure` as a PNG;
    None (nothing written) without logs."""
    fig = matching_figure(result)
    return None if fig is None else save_figure(fig, path)


def _levels(x: np.ndarray, span: float, near: float = 0.07, depth: int = 3) -> np.ndarray:
    """Label levels 0, 1, 2, ... for points ``x`` so that neighbours closer than ``near``
    of the axis ``span`` get different heights (labels that would overlap are staggered)."""
    x = np.asarray(x, dtype=float)
    out = np.zeros(x.size, dtype=int)
    order = np.argsort(x, kind="stable")
    for a, b in zip(order[:-1], order[1:], strict=True):
        if x[b] - x[a] < near * span:
            out[b] = (out[a] + 1) % depth
    return out


def membership_figure(result: MonteCarloResult, points: int = 600) -> Figure | None:
    """The tuned fuzzy system of each tuned filter (one row each): the Gaussian input sets
    NM..PM over the normalised DOM, the output centres IL..DL as stems (singletons of the
    centre-average defuzzifier) and the input-output curve y(x) with the rule points
    (c_l, ybar_l). None when nothing was tuned."""
    if not result.tuning:
        return None
    rows = len(result.tuning)
    fig = Figure(figsize=(14, 3.1 * rows + 0.6), layout="constrained")
    axes = fig.subplots(rows, 3, squeeze=False)
    for (name, t), (a_in, a_out, a_xy) in zip(result.tuning.items(), axes, strict=True):
        p = np.asarray(t.params, dtype=float)
        c, w, ybar = p[0:5], p[5:10], p[10:15]
        x = np.linspace(float(np.min(c - 2.5 * w)), float(np.max(c + 2.5 * w)), points)
        up = _levels(c, x[-1] - x[0])
        for ell, label in enumerate(INPUT_SETS):
            mu = np.exp(-(((x - c[ell]) / w[ell]) ** 2))
            a_in.plot(x, mu, color=f"C{ell}", lw=1.4, label=label)
            a_in.annotate(label, (c[ell], 1.0), xytext=(0, 3 + 11 * up[ell]),
                          textcoords="offset points", ha="center", va="bottom",
                          fontsize="small", color=f"C{ell}")
        a_in.set_ylim(0, 1.3)
        a_in.set_xlabel("DOM(i,i), normalised")
        a_in.set_ylabel("membership")
        a_in.set_title(f"{name} ({t.optimizer}): input sets", fontsize="medium")

        up = _levels(ybar, max(float(np.ptp(ybar)), 1e-12))
        for ell, label in enumerate(OUTPUT_SETS):
            a_out.vlines(ybar[ell], 0, 1, color=f"C{ell}", lw=1.6)
            a_out.plot(ybar[ell], 1, "o", color=f"C{ell}", ms=5)
            a_out.annotate(label, (ybar[ell], 1.0), xytext=(0, 4 + 11 * up[ell]),
                           textcoords="offset points", ha="center", va="bottom",
                           fontsize="small", color=f"C{ell}")
        a_out.axvline(0.0, color="0.5", lw=0.8, ls=":")
        a_out.set_ylim(0, 1.35)
        a_out.set_xlabel("adjustment (output centre), normalised")
        a_out.set_title(f"{name}: output centres", fontsize="medium")

        a_xy.plot(x, fis(p, x), color="black", lw=1.4, label="y(x)")
        for ell, (src, dst) in enumerate(zip(INPUT_SETS, OUTPUT_SETS, strict=True)):
            a_xy.plot(c[ell], ybar[ell], "o", color=f"C{ell}", ms=5, label=f"{src} -> {dst}")
        a_xy.axhline(0.0, color="0.5", lw=0.8, ls=":")
        a_xy.legend(loc="best", fontsize="x-small", title="rule (c, ybar)",
                    title_fontsize="x-small")
        a_xy.set_xlabel("DOM(i,i), normalised")
        a_xy.set_ylabel("adjustment y(x)")
        a_xy.set_title(f"{name}: input-output curve", fontsize="medium")
        for ax in (a_in, a_out, a_xy):
            ax.grid(True, alpha=0.3)
    fig.suptitle(f"{result.scenario}: tuned fuzzy systems (rules NM->IL, NS->I, ZE->M, PS->D, "
                 "PM->DL)", fontsize="medium")
    return fig


def plot_membership(result: MonteCarloResult, path: str | Path) -> Path | None:
    """Write :func:`~trackkit.report.plots.membership_figure` as a PNG;
    None (nothing written) without tuning."""
    fig = membership_figure(result)
    return None if fig is None else save_figure(fig, path)


def _band(history: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Median, min and max over runs (axis 1) of the finite values; nan where none."""
    h = np.asarray(history, dtype=float)
    h = np.where(np.isfinite(h), h, np.nan).reshape(h.shape[0], -1)
    med, lo, hi = (np.full(h.shape[0], np.nan) for _ in range(3))
    ok = np.isfinite(h).any(axis=1)
    if ok.any():
        med[ok] = np.nanmedian(h[ok], axis=1)
        lo[ok] = np.nanmin(h[ok], axis=1)
        hi[ok] = np.nanmax(h[ok], axis=1)
    return med, lo, hi


def convergence_figure(result: MonteCarloResult) -> Figure | None:
    """Best-so-far DOM cost against iteration of each tuned filter's optimiser: the median
    over the independent runs, the min-max band shaded (log scale when wide). None when
    nothing was tuned."""
    if not result.tuning:
        return None
    fig = Figure(figsize=(8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    series = []
    for name, t in result.tuning.items():
        med, lo, hi = _band(t.history)
        it = np.arange(len(med))
        color = _color(result, name)
        ax.plot(it, med, color=color, lw=1.5, label=f"{name} ({t.optimizer}, {t.runs} runs, "
                f"population {t.population})")
        ax.fill_between(it, lo, hi, color=color, alpha=0.2, lw=0)
        series += [lo, hi]
    _log_if_wide(ax, series)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("iteration")
    ax.set_ylabel(f"best-so-far cost (alpha {result.dom_alpha:g})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper right", fontsize="small", title="median, min-max band",
              title_fontsize="small")
    fig.suptitle(f"{result.scenario}: optimiser convergence (cost alpha sum_i RMS DOM(i,i))",
                 fontsize="medium")
    return fig


def plot_convergence(result: MonteCarloResult, path: str | Path) -> Path | None:
    """Write :func:`~trackkit.report.plots.convergence_figure` as a PNG;
    None (nothing written) without tuning."""
    fig = convergence_figure(result)
    return None if fig is None else save_figure(fig, path)


def _shade_gaps(ax, result: MonteCarloResult) -> None:
    if result.gap_steps is None or not len(result.gap_steps):
        return
    t = np.asarray(result.times, dtype=float)
    steps = np.asarray(result.gap_steps)
    for part in np.split(steps, np.flatnonzero(np.diff(steps) > 1) + 1):
        # a measurement's gap runs from the last real one before it to the first after it
        lo = t[part[0] - 1] if part[0] > 0 else t[0] - result.dt
        hi = t[part[-1] + 1] if part[-1] + 1 < len(t) else t[-1]
        ax.axvspan(lo, hi, color="0.85", lw=0)


def time_figure(result: MonteCarloResult) -> Figure | None:
    """Run 0 against time (the missing-measurements thesis's figures 4-4 .. 4-15): the first state
    component, true and estimated by each filter, and the first measurement channel, measured and
    fed as a pseudo-measurement by each filter; gaps shaded. None without an example run."""
    ex = result.example
    if ex is None:
        return None
    t = np.asarray(ex.times, dtype=float)
    fig = Figure(figsize=(8.0, 6.5), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    for ax in (top, bottom):
        _shade_gaps(ax, result)
        ax.grid(True, alpha=0.3)
    top.plot(t, np.asarray(ex.truth)[:, 0], color="black", lw=2, label="truth")
    for i, (name, (means, _)) in enumerate(ex.estimates.items()):
        top.plot(t, np.asarray(means)[:, 0], color=f"C{i}", lw=1.2, label=name)
    top.set_ylabel("x (east) [m]" if result.kinematic else "state component 1")
    top.legend(fontsize="small", ncols=3)
    if ex.measurements is not None:
        z = np.asarray(ex.measurements, dtype=float).reshape(len(t), -1)[:, 0]
        bottom.plot(t, z, ".", color="0.3", ms=4, label="measurements")
    for i, name in enumerate(ex.estimates):
        zp = ex.pseudo.get(name)
        if zp is not None and np.isfinite(zp).any():
            bottom.plot(t, np.asarray(zp).reshape(len(t), -1)[:, 0], "x", color=f"C{i}",
                        ms=4, label=f"{name}: pseudo")
    bottom.set_ylabel("measurement, channel 1")
    bottom.set_xlabel("time [s]")
    bottom.legend(fontsize="small", ncols=3)
    fig.suptitle(f"{result.scenario}: run 0 against time (gaps shaded)", fontsize="medium")
    return fig


def plot_time(result: MonteCarloResult, path: str | Path) -> Path | None:
    """Write :func:`~trackkit.report.plots.time_figure` as a PNG;
    None (nothing written) without an example run."""
    fig = time_figure(result)
    return None if fig is None else save_figure(fig, path)


def classes_figure(result: MonteCarloResult) -> Figure | None:
    """Class probability against time (Hosseini, Haeri and Khaloozadeh 2019, Fig. 4): for each
    filter that classifies, its probability of the true class, mean over runs with the 10-90th
    percentile band shaded; without a true class, the mean probability of each of its classes (one
    line style per class). None when no filter classifies."""
    names = result.classifiers()
    if not names:
        return None
    t = np.asarray(result.times, dtype=float)
    fig = Figure(figsize=(8, 4.2), layout="constrained")
    ax = fig.add_subplot()
    true = None
    for name in names:
        c = result.filters[name].classes
        color = _color(result, name)
        if c.get("true") is not None:
            true = c["true_class"]
            mean = np.asarray(c["mean"])[:, list(c["names"]).index(true)]
            lo, hi = result.true_class_percentiles(name, (10.0, 90.0))
            ax.fill_between(t, lo, hi, color=color, alpha=0.2, lw=0)
            ax.plot(t, mean, color=color, lw=1.5, label=f"{name}: P({true}), mean")
            continue
        for j, k in enumerate(c["names"]):
            ax.plot(t, np.asarray(c["mean"])[:, j], color=color, lw=1.3,
                    ls=("-", "--", ":", "-.")[j % 4], label=f"{name}: P({k}), mean")
    ax.axhline(0.9, color="0.4", lw=0.8, ls=":")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("class probability [-]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize="small",
              title=None if true is None else "shaded: 10-90th percentile over runs",
              title_fontsize="small")
    what = f"the true class ({true})" if true is not None else "each class"
    fig.suptitle(f"{result.scenario}: probability of {what} over {result.runs} runs",
                 fontsize="medium")
    return fig


def plot_classes(result: MonteCarloResult, path: str | Path) -> Path | None:
    """Write :func:`~trackkit.report.plots.classes_figure` as a PNG;
    None (nothing written) when no filter classifies."""
    fig = classes_figure(result)
    return None if fig is None else save_figure(fig, path)


def _wants_time_plot(result: MonteCarloResult) -> bool:
    return (result.gap_steps is not None or not result.kinematic
            or any(f.gaps.get("handler") for f in result.filters.values()))


def make_plots(result: MonteCarloResult, out_dir: str | Path) -> dict[str, Path]:
    """Write every figure into ``out_dir``; returns ``{figure: path}`` for those written
    (geometry only with an example run of a kinematic state; the time plot with an example
    run of a scenario with gaps, handlers or a given, non-kinematic state; matching,
    membership and convergence only when the result has those data)."""
    out = Path(out_dir)
    written: dict[str, Path] = {}
    # a given state that is not [positions, velocities] has no plan view: the time plot
    geometry = plot_geometry(result, out / PLOT_FILES["geometry"]) if result.kinematic else None
    if geometry is not None:
        written["geometry"] = geometry
    if _wants_time_plot(result):
        path = plot_time(result, out / PLOT_FILES["time"])
        if path is not None:
            written["time"] = path
    written["rmse"] = plot_rmse(result, out / PLOT_FILES["rmse"])
    written["nees"] = plot_nees(result, out / PLOT_FILES["nees"])
    for name, plot in (("matching", plot_matching), ("membership", plot_membership),
                       ("convergence", plot_convergence), ("classes", plot_classes)):
        path = plot(result, out / PLOT_FILES[name])
        if path is not None:
            written[name] = path
    return written


def gospa_panels(title: str) -> tuple[Figure, Any, Any]:
    """The GOSPA figure of the tracking and network reports: GOSPA against time (top, with
    ``title``) over the number of confirmed tracks (bottom). Draw, then
    :func:`finish_gospa_panels`."""
    fig = Figure(figsize=(8.0, 6.5), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    top.set_title(title, fontsize="medium")
    return fig, top, bottom


def finish_gospa_panels(top: Any, bottom: Any) -> None:
    top.set_ylabel("GOSPA [m]")
    top.set_ylim(bottom=0)
    bottom.set_ylabel("confirmed tracks")
    bottom.set_xlabel("time [s]")
    bottom.set_ylim(bottom=0)
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="small")

