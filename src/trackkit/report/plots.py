"""Report figures, one PNG each: geometry, RMSE against time with the PCRLB, NEES with bounds.

Figures are ``matplotlib.figure.Figure`` objects rendered by the Agg canvas: no display, no
pyplot state and no global backend switch (safe in worker threads, CI and notebooks).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse
from matplotlib.ticker import LogFormatter

from trackkit.eval.results import MonteCarloResult
from trackkit.report.tables import display_unit

__all__ = [
    "geometry_figure", "rmse_figure", "nees_figure", "plot_geometry", "plot_rmse", "plot_nees",
    "make_plots", "PLOT_FILES",
]

PLOT_FILES = {"geometry": "geometry.png", "rmse": "rmse.png", "nees": "nees.png"}
_DPI = 110


def _save(fig: Figure, path: str | Path) -> Path:
    path = Path(path)
    FigureCanvasAgg(fig)  # render with Agg whatever the session's backend
    fig.savefig(path, dpi=_DPI, format="png")
    return path


def _distance_scale(extent: float) -> tuple[str, float]:
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
    unit, s = _distance_scale(extent)

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
    """Write :func:`geometry_figure` as a PNG; None (nothing written) without an example run."""
    fig = geometry_figure(result, every, nsigma)
    return None if fig is None else _save(fig, path)


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
    """Write :func:`rmse_figure` as a PNG."""
    return _save(rmse_figure(result), path)


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
    """Write :func:`nees_figure` as a PNG."""
    return _save(nees_figure(result), path)


def make_plots(result: MonteCarloResult, out_dir: str | Path) -> dict[str, Path]:
    """Write every figure into ``out_dir``; returns ``{figure: path}`` for those written."""
    out = Path(out_dir)
    written: dict[str, Path] = {}
    geometry = plot_geometry(result, out / PLOT_FILES["geometry"])
    if geometry is not None:
        written["geometry"] = geometry
    written["rmse"] = plot_rmse(result, out / PLOT_FILES["rmse"])
    written["nees"] = plot_nees(result, out / PLOT_FILES["nees"])
    return written
