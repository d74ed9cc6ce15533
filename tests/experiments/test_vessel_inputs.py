"""A log of measured inputs at exactly a fifth of the grid step drives the identification
at its own samples (50 Euler sub-steps at the measured inputs), whatever the rounding of its
times: 0.2 s steps read from a file differ from 0.2 by an ulp or so."""

from __future__ import annotations

import numpy as np

from trackkit.experiments.vessel_mc import _inputs_resolve_substeps
from trackkit.io.navigation import MeasuredInputs


def inputs(t):
    n = t.size
    return MeasuredInputs(t, np.zeros(n), np.full(n, 20.0), np.arange(n) + 2, None)


def test_inputs_at_a_fifth_of_the_step_count_as_fine_with_rounded_times():
    t = np.cumsum(np.full(50, 0.2))  # 0.2 added up: 0.20000000000000107 apart
    assert float(np.median(np.diff(t))) > 0.2
    assert _inputs_resolve_substeps(inputs(t), 1.0)
    assert _inputs_resolve_substeps(inputs(np.arange(50) * 0.1), 1.0)


def test_coarser_inputs_do_not():
    assert not _inputs_resolve_substeps(inputs(np.arange(50) * 0.25), 1.0)
    assert not _inputs_resolve_substeps(inputs(np.arange(50) * 0.2001), 1.0)
