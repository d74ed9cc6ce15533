"""The glossary of report.html and docs/glossary.md: one text, and it states the rules the
code applies."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from scipy.stats import chi2

from trackkit.eval import metrics
from trackkit.report.glossary import GLOSSARY, glossary_html, glossary_markdown

DOCS = Path(__file__).resolve().parents[2] / "docs" / "glossary.md"


def test_docs_glossary_is_the_report_glossary():
    assert DOCS.read_text(encoding="utf-8") == glossary_markdown(), (
        "docs/glossary.md differs from trackkit.report.glossary; regenerate it with\n"
        "python -c 'from trackkit.report.glossary import glossary_markdown as g; "
        "print(g(), end=\"\")' > docs/glossary.md")


def test_glossary_covers_the_reported_quantities():
    terms = {term for term, _ in GLOSSARY}
    assert {"ANEES", "ANIS", "NEES in 95% bounds", "Diverged", "Time per run-step",
            "Averaging window", "RMSE", "PCRLB"} <= terms
    page = glossary_html()
    for term in terms:
        assert f"<dt>{term}</dt>" in page
    assert "<code>window.from_s</code>" in page  # code spans rendered, text escaped
    assert "`" not in page


def test_divergence_rule_is_the_one_in_metrics():
    """The numbers the glossary states are the defaults the engine's accumulator uses."""
    text = dict(GLOSSARY)["Diverged"]
    defaults = {f.name: f.default for f in dataclasses.fields(metrics.MonteCarloMetrics)}
    assert defaults["nees_threshold"] is None and defaults["distance"] is None
    assert f"{defaults['max_bad_fraction']:.0%}" in text  # "25%"
    for n in (1, 4, 6):
        assert metrics._default_nees_threshold(n) == 100 * chi2.ppf(1 - 1e-6, n)
    assert "100 chi2.ppf(1 - 1e-6, n)" in text
