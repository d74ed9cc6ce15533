"""Per-execution scoring of an agent's confirmed tracks (trackkit.eval.network_score)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackkit.eval.network_score import position_rmse, score_trace

TRUTH = np.array([[[0.0, 0.0, 1.0, 0.0], [10000.0, 0.0, 0.0, 1.0]],
                  [[5.0, 0.0, 1.0, 0.0], [10000.0, 5.0, 0.0, 1.0]],
                  [[10.0, 0.0, 1.0, 0.0], [10000.0, 10.0, 0.0, 1.0]]])


def test_counts_gospa_and_errors_by_hand():
    """Execution 0: no track (2 missed); 1: a track 30-40-50 m from target 0 and a false
    one far away; 2: both targets held, 100 m and 200 m off. c = 1000, p = 2."""
    mean = np.array([[35.0, 40.0, 0.0, 0.0], [-50000.0, 0.0, 0.0, 0.0],
                     [10100.0, 10.0, 0.0, 0.0], [10.0, -200.0, 0.0, 0.0]])
    s = score_trace([0.0, 5.0, 10.0], [0, 0, 2, 4], mean, TRUTH, c=1000.0)
    assert s.count.tolist() == [0, 2, 2]
    half = 1000.0**2 / 2
    np.testing.assert_allclose(s.gospa, [math.sqrt(2 * half), math.sqrt(50.0**2 + 2 * half),
                                         math.sqrt(100.0**2 + 200.0**2)], rtol=1e-12)
    assert np.isnan(s.error[0]).all()
    assert s.error[1, 0] == pytest.approx(50.0) and np.isnan(s.error[1, 1])
    np.testing.assert_allclose(s.error[2], [200.0, 100.0])
    np.testing.assert_allclose(position_rmse(s), [math.sqrt((50.0**2 + 200.0**2) / 2), 100.0])
    np.testing.assert_allclose(position_rmse(s, 6.0), [200.0, 100.0])
    assert np.isnan(position_rmse(s, 0.0, 1.0)).all()


def test_bad_offsets_are_refused():
    with pytest.raises(ValueError, match="offsets"):
        score_trace([0.0, 5.0, 10.0], [0, 1, 0, 0], np.zeros((0, 4)), TRUTH)
    with pytest.raises(ValueError, match="truth"):
        score_trace([0.0, 5.0], [0, 0, 0], np.zeros((0, 4)), TRUTH)
