"""What a Monte Carlo comparison produces: the data contract between evaluate and report.

Everything here is plain arrays and floats in SI units, so that the report stage (tables,
plots, JSON, Parquet, HTML) never reaches back into filters or scenarios.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

__all__ = ["FilterResult", "Example", "MonteCarloResult"]


@dataclass
class FilterResult:
    """One filter's Monte Carlo statistics (per-step arrays have length ``steps``)."""

    name: str
    rmse: dict[str, Array]  # group -> RMSE per step (SI units; radians for angle groups)
    rmse_mean: dict[str, float]  # group -> RMSE averaged over the steps from ``start``
    nees: Array  # average NEES per step
    nis: Array  # average NIS per step (nan where no measurement)
    nees_bounds: tuple[Array, Array]  # two-sided 95% chi-square bounds of the average NEES
    nis_bounds: tuple[Array, Array]
    anees: float  # average NEES over the steps from ``start``
    anis: float
    nees_in_bounds: float  # fraction of steps from ``start`` inside the NEES bounds
    nis_in_bounds: float
    diverged: int  # runs diverged (rule: trackkit.eval.metrics docstring)
    seconds_per_step: float  # wall time per run-step (filter only, not simulation)
    #: Naseri Solhdar's per-run metrics (trackkit.eval.covariance_matching): "J2" (runs, m),
    #: "J3" (runs, n), "J4" (runs,)
    matching: dict[str, Array] = field(default_factory=dict)
    #: missing measurements (scenario [gaps], filter gaps handlers): "handler" (label or
    #: None), per-run sums of squared errors per group over the gap steps "gap_sse" and the
    #: steps after them "after_sse" ({group: (runs,)}), "pseudo_steps" (steps,) the runs fed
    #: a pseudo-measurement at each step; see :func:`~trackkit.report.tables.gap_summary`
    gaps: dict = field(default_factory=dict)
    #: a filter that classifies (JTC, MultiFilterJTC): "names" its classes, "mean" (steps, C)
    #: each class's probability per step averaged over runs, "final" (runs, C) each run's last
    #: probabilities, "true_class" (a name or None) and "true" (runs, steps) each run's
    #: probability of the true class per step (None without a true class); empty otherwise
    classes: dict = field(default_factory=dict)
    #: the scenario's error windows (report.windows): window -> {"rmse": {group: RMSE over
    #: the window's steps}, "anees", "anis", "nees_in_bounds"}, each from the per-step sums
    #: as ``rmse_mean`` and ``anees`` are; empty without windows
    windows: dict[str, dict] = field(default_factory=dict)


#: a run counts as classified when its last probability of the true class exceeds this
DECIDED = 0.9


@dataclass
class Example:
    """One run, for the geometry plot: truth, observer track and each filter's estimates."""

    times: Array  # (steps,)
    truth: Array  # (steps, n)
    observer: Array  # (steps, d) observer position (d = 2 or 3); first observer if several
    estimates: dict[str, tuple[Array, Array]]  # filter -> (means (steps, n), covs (steps, n, n))
    measurements: Array | None = None  # (steps, m), nan where missing
    #: filter -> {"R", "S", "C", "DOM"}: diagonals per step (steps, m) of the innovation
    #: covariance matching (trackkit.eval.covariance_matching)
    logs: dict[str, dict[str, Array]] = field(default_factory=dict)
    #: filter -> the pseudo-measurements it was fed (steps, m), nan elsewhere (gap handlers)
    pseudo: dict[str, Array] = field(default_factory=dict)


@dataclass
class MonteCarloResult:
    """A whole comparison on one scenario."""

    scenario: str
    description: str
    runs: int
    seed: int
    steps: int
    dt: float
    times: Array  # (steps,) seconds from the scenario start
    start: int  # first step index of the time averages ("after convergence")
    groups: dict[str, str]  # group -> unit label for reports ("m", "m/s", "rad", "Hz")
    filters: dict[str, FilterResult]
    pcrlb: dict[str, Array]  # group -> RMSE lower bound per step (same units as rmse)
    pcrlb_mean: dict[str, float]  # group -> bound averaged over the same steps as rmse_mean
    example: Example | None = None
    notes: list[str] = field(default_factory=list)  # assumptions and skipped items to report
    j1: Array | None = None  # (runs, m) raw measurement noise RMS of each run (J1)
    dom_alpha: float = 1000.0  # the alpha of J4
    #: filter -> tuning summary of its fuzzy system (trackkit.experiments.tuning.TuningResult)
    tuning: dict[str, object] = field(default_factory=dict)
    #: the step indices [gaps] hides, and the ones after them (``after_gap_s``) where the
    #: recovery is scored; None without [gaps]
    gap_steps: NDArray[np.int64] | None = None
    after_steps: NDArray[np.int64] | None = None
    after_gap_s: float = 0.0
    #: the state is [positions, velocities, ...] (an X-Y picture means something)
    kinematic: bool = True
    #: the error windows (report.windows): name -> (start_s, end_s) as the scenario gives
    #: them, their steps name -> (k0, k1) (steps k0 .. k1 - 1), and the PCRLB over each:
    #: name -> {group: sqrt(mean_k bound_k^2)}, as ``pcrlb_mean``
    windows: dict[str, tuple[float, float]] = field(default_factory=dict)
    window_steps: dict[str, tuple[int, int]] = field(default_factory=dict)
    pcrlb_windows: dict[str, dict[str, float]] = field(default_factory=dict)

    def gap_rmse(self, name: str, group: str, window: str = "gap") -> float:
        """RMSE over all runs and the steps of ``window`` ("gap", "after" or "both")."""
        g = self.filters[name].gaps
        if self.gap_steps is None or "gap_sse" not in g:
            return float("nan")
        sse, steps = self._window_sse(g, group, window)
        return float(np.sqrt(np.sum(sse) / (steps * self.runs))) if steps else float("nan")

    def gap_rmse_per_run(self, name: str, group: str, window: str = "both") -> Array:
        """Each run's RMSE over the steps of ``window`` ("gap", "after" or "both")."""
        g = self.filters[name].gaps
        if self.gap_steps is None or "gap_sse" not in g:
            raise ValueError(f"scenario {self.scenario!r} has no [gaps]; no gap RMSE")
        sse, steps = self._window_sse(g, group, window)
        return np.sqrt(sse / steps)

    def _window_sse(self, g: dict, group: str, window: str) -> tuple[Array, int]:
        nga, naf = len(self.gap_steps), len(self.after_steps)
        if window == "gap":
            return g["gap_sse"][group], nga
        if window == "after":
            return g["after_sse"][group], naf
        if window == "both":
            return g["gap_sse"][group] + g["after_sse"][group], nga + naf
        raise ValueError(f"window = {window!r}; expected 'gap', 'after' or 'both'")

    def pseudo_fraction(self, name: str) -> float:
        """The fraction of (run, step) pairs at which filter ``name`` was fed a
        pseudo-measurement."""
        g = self.filters[name].gaps
        if "pseudo_steps" not in g:
            return 0.0
        return float(np.sum(g["pseudo_steps"]) / (self.runs * self.steps))

    def classifiers(self) -> list[str]:
        """The filters that classify (their results carry class probabilities)."""
        return [name for name, f in self.filters.items() if f.classes]

    def true_class_percentiles(self, name: str, q: tuple[float, ...] = (10.0, 50.0, 90.0)
                               ) -> Array:
        """Percentiles ``q`` over runs of filter ``name``'s probability of the true class at
        each step, ``(len(q), steps)``."""
        c = self.filters[name].classes
        if not c or c.get("true") is None:
            raise ValueError(f"filter {name!r} has no probability of a true class (it does not "
                             "classify, or the scenario has no report.true_class)")
        return np.percentile(c["true"], q, axis=0)

    def classification(self, name: str) -> dict:
        """Filter ``name``'s classification summary (empty when it does not classify):
        ``classes``, ``final_mean`` (each class's last probability averaged over runs) and,
        with a true class, ``true_class``, ``final_true_mean``, ``final_true_p10`` (the 10th
        percentile over runs), ``above`` (the fraction of runs whose last probability of it
        exceeds ``DECIDED``) and ``decided_s`` (the median over runs of the time from which
        that probability stays above ``DECIDED``; nan when most runs never get there)."""
        c = self.filters[name].classes
        if not c:
            return {}
        final = np.asarray(c["final"], dtype=float)
        out: dict = {"classes": list(c["names"]), "final_mean": final.mean(0).tolist()}
        if c.get("true") is None:
            return out
        t = list(c["names"]).index(c["true_class"])
        p = final[:, t]
        hist = np.asarray(c["true"], dtype=float)
        below = hist <= DECIDED
        # the step after the last one at or below the threshold (steps: never decided)
        last = np.where(below.any(1), hist.shape[1] - np.argmax(below[:, ::-1], 1), 0)
        times = np.append(np.asarray(self.times, dtype=float), np.inf)[last]
        median = float(np.median(times))
        out.update(true_class=c["true_class"], final_true_mean=float(p.mean()),
                   final_true_p10=float(np.percentile(p, 10.0)),
                   above=float(np.mean(p > DECIDED)),
                   decided_s=median if np.isfinite(median) else float("nan"))
        return out

    def efficiency(self, name: str, group: str, window: str | None = None) -> float:
        """RMSE / PCRLB (time averaged from ``start``, or over the error window ``window``):
        1 is efficient, larger is further from the bound."""
        if window is None:
            bound = self.pcrlb_mean.get(group, float("nan"))
            rmse = self.filters[name].rmse_mean[group]
        else:
            if window not in self.windows:
                raise KeyError(f"window = {window!r}; the result has windows "
                               f"{list(self.windows)}")
            bound = self.pcrlb_windows[window].get(group, float("nan"))
            rmse = self.filters[name].windows[window]["rmse"][group]
        return rmse / bound if bound > 0 else float("nan")

    def to_json_dict(self) -> dict:
        """The ``results.json`` document."""
        return {
            "scenario": self.scenario,
            "runs": self.runs,
            "seed": self.seed,
            "steps": self.steps,
            "dt": self.dt,
            "filters": {
                name: {
                    "rmse": {g: float(v) for g, v in f.rmse_mean.items()},
                    "anees": float(f.anees),
                    "anis": float(f.anis),
                    "nees_in_bounds": float(f.nees_in_bounds),
                    "diverged": int(f.diverged),
                    "seconds_per_step": float(f.seconds_per_step),
                }
                for name, f in self.filters.items()
            },
            "pcrlb": {g: float(v) for g, v in self.pcrlb_mean.items()},
            **self._windows_json(),
            **self._matching_json(),
            **self._gaps_json(),
            **self._classification_json(),
        }

    def _windows_json(self) -> dict:
        """The error windows block, when the scenario names windows."""
        if not self.windows:
            return {}
        out = {}
        for w, (a, b) in self.windows.items():
            k0, k1 = self.window_steps[w]
            out[w] = {
                "start_s": float(a), "end_s": float(b), "steps": int(k1 - k0),
                "pcrlb": {g: float(v) for g, v in self.pcrlb_windows[w].items()},
                "filters": {name: {
                    "rmse": {g: float(v) for g, v in f.windows[w]["rmse"].items()},
                    "rmse_over_pcrlb": {g: float(self.efficiency(name, g, w))
                                        for g in f.windows[w]["rmse"]
                                        if g in self.pcrlb_windows[w]},
                    "anees": float(f.windows[w]["anees"]),
                    "anis": float(f.windows[w]["anis"]),
                    "nees_in_bounds": float(f.windows[w]["nees_in_bounds"]),
                } for name, f in self.filters.items()},
            }
        return {"windows": out}

    def _classification_json(self) -> dict:
        """The classification block, when a filter classifies."""
        names = self.classifiers()
        if not names:
            return {}
        return {"classification": {"threshold": DECIDED,
                                   "filters": {n: self.classification(n) for n in names}}}

    def _gaps_json(self) -> dict:
        """The missing-measurement block, when the scenario has [gaps] or handlers."""
        handlers = {n: f.gaps.get("handler") for n, f in self.filters.items()}
        if self.gap_steps is None and not any(handlers.values()):
            return {}
        out: dict = {}
        if self.gap_steps is not None:
            out = {"steps": self.gap_steps.tolist(), "after_steps": self.after_steps.tolist(),
                   "after_gap_s": self.after_gap_s}
        out["filters"] = {
            name: {"handler": handlers[name] or "B0",
                   "pseudo_fraction": self.pseudo_fraction(name),
                   **({} if self.gap_steps is None else {
                       f"rmse_{w}": {g: self.gap_rmse(name, g, w) for g in self.groups}
                       for w in ("gap", "after", "both")})}
            for name in self.filters}
        return {"gaps": out}

    def _matching_json(self) -> dict:
        """J1-J4 (mean over runs and run 0) and the tuning summaries, when present."""
        out: dict = {}
        if self.j1 is not None:
            out["J1"] = {"mean": self.j1.mean(0).tolist(), "run0": self.j1[0].tolist()}
        js = {name: {k: {"mean": np.mean(v, 0).tolist(), "run0": np.asarray(v[0]).tolist()}
                     for k, v in f.matching.items()}
              for name, f in self.filters.items() if f.matching}
        if js:
            out["J"] = js
            out["dom_alpha"] = self.dom_alpha
        if self.tuning:
            out["tuning"] = {name: t.summary() for name, t in self.tuning.items()}
        return out
