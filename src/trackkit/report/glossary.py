"""What the numbers of a report mean: one glossary, rendered into ``report.html`` and into
``docs/glossary.md`` (a test keeps the two identical, so the page and the docs cannot drift).

The divergence rule is the one of :mod:`trackkit.eval.metrics` with the defaults the Monte
Carlo engine uses (no distance threshold, ``max_bad_fraction = 0.25``).
"""

from __future__ import annotations

import html
import re

__all__ = ["GLOSSARY", "glossary_markdown", "glossary_html"]

#: (term, definition); definitions use `code` spans and nothing else of markdown
GLOSSARY: tuple[tuple[str, str], ...] = (
    ("Averaging window",
     "The time-averaged numbers (the summary tables and `results.json`) use the steps from "
     "the scenario's `report.average_from_s` to the last step, so that the first steps, while "
     "the filters converge from the prior, do not dominate. `results.json` states the window "
     "as `window.from_s` and `window.to_s` (seconds from the scenario start) and "
     "`window.steps`."),
    ("Units",
     "SI inside: metres, seconds, radians, hertz. `results.json` and `metrics.parquet` hold SI "
     "values and name the unit of each quantity (`units` in `results.json`, the `unit` field "
     "metadata in `metrics.parquet`). Tables and plots show angles in degrees and say so in "
     "their headers."),
    ("RMSE",
     "Root-mean-square error of an error group (position, velocity, speed, course, ...). Per "
     "step: the square root of the mean over the Monte Carlo runs of the squared error norm "
     "(truth minus estimate; angles wrapped to (-pi, pi]). Time-averaged: the square root of "
     "the mean of those per-step mean squares over the averaging window, i.e. the RMS error "
     "over all runs and steps of the window."),
    ("PCRLB",
     "Posterior Cramer-Rao lower bound: the smallest RMSE an unbiased estimator can reach "
     "with the scenario's motion model, sensors and prior. Time-averaged like the RMSE. "
     "`RMSE/PCRLB` is the efficiency: 1 is as good as any estimator can be."),
    ("NEES",
     "Normalised estimation error squared `e' P^-1 e` of one run at one step: `e` is truth "
     "minus estimate, `P` the covariance the filter claims. If the filter is consistent "
     "(its covariance describes its error) its mean is `n`, the state dimension."),
    ("ANEES",
     "Average NEES: the NEES averaged over the runs and over the steps of the averaging "
     "window (dimensionless). About `n` for a consistent filter; above `n` the filter is "
     "overconfident (its covariance is too small for its error), below `n` pessimistic."),
    ("ANIS",
     "Average normalised innovation squared `nu' S^-1 nu` (`nu = z - zhat` the innovation, "
     "`S` its predicted covariance), over the runs that had a measurement and the steps of the "
     "averaging window (dimensionless). About `m`, the measurement dimension, for a "
     "consistent filter. It needs no truth, so it is the check that also works on recorded "
     "data."),
    ("NEES in 95% bounds",
     "The fraction of the averaging window's steps at which the average NEES over the `N` "
     "runs lies inside its two-sided 95% chi-square interval "
     "`[chi2.ppf(0.025, N n) / N, chi2.ppf(0.975, N n) / N]`. About 95% for a consistent "
     "filter; far less means the covariance does not describe the error. A percentage in the "
     "tables, a fraction from 0 to 1 in `results.json`."),
    ("Diverged",
     "A run is bad at a step when its estimate (mean or covariance) is not finite or its "
     "NEES exceeds `100 chi2.ppf(1 - 1e-6, n)`: a consistent filter exceeds "
     "`chi2.ppf(1 - 1e-6, n)` once in a million steps, and the further factor 100 means the "
     "covariance understates the error by two orders of magnitude, so the track is lost, "
     "not merely overconfident. A run has diverged when it is bad at its last step or on more "
     "than 25% of its steps. Tables show diverged runs out of all runs. Runs with a "
     "non-finite estimate are left out of that step's RMSE and NEES."),
    ("Time per run-step",
     "Wall-clock time of one filter's predict and update for one run at one step: the "
     "filter's time over the whole comparison divided by runs x steps (simulation, metrics "
     "and reports not included). Runs are computed as one batch, so this is the batched cost "
     "per run. It changes from machine to machine and from run to run, so it is kept out of "
     "`results.json` and written to `timings.json` (seconds), with the tuning times."),
)

_INTRO = ("What the numbers in a trackkit report mean (`report.html`, `results.json`, "
          "`metrics.parquet`, the tables `trackkit run` prints).")


def glossary_markdown() -> str:
    """The glossary as a markdown document (the text of ``docs/glossary.md``)."""
    lines = ["# Glossary", "", _INTRO, ""]
    for term, text in GLOSSARY:
        lines += [f"**{term}**: {text}", ""]
    return "\n".join(lines)


def code_spans(text: str) -> str:
    # escape first, then turn the (already escaped) backtick spans into <code>
    return re.sub(r"`([^`]*)`", r"<code>\1</code>", html.escape(text))


def glossary_html() -> str:
    """The glossary as an HTML definition list."""
    items = [f"<dt>{html.escape(term)}</dt><dd>{code_spans(text)}</dd>"
             for term, text in GLOSSARY]
    return '<dl class="glossary">\n' + "\n".join(items) + "\n</dl>"
