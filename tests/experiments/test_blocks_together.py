"""``run_blocks(..., together=True)``: small blocks filtered as one batch of their runs, each
block simulated and evaluated on its own, so that the blocks a batch-means or jackknife error
needs cost what one large block costs.

What it promises: every block's truths, measurements, priors and PCRLB ingredients are the
bits of ``run_block``. Its per-step statistics agree with ``run_block``'s to 1e-8 of the
value plus the series' median (one run's squared error may pass through 0), and run 0's
estimates to 1e-8 of each component's largest value: a run's place in a batch only moves
where numpy's SIMD loops round, and the filters' recursions carry that on. Measured on the
2000-step DBT scenarios: four of the five filters bit for bit, the UKF's per-step MSE within
3e-10; on the GA-started runs below within 1.3e-7 of the value. What depends on a block's own
generator (a stochastic filter) or on its runs as a whole (``report.matching``) is refused.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.experiments.montecarlo import combine, run_block, run_blocks

RTOL = 1e-8


def _scenario(name: str, runs: int, block: int, duration: float | None = None, **prior):
    d = S.load(name).model_dump()
    d["run"].update(runs=runs, block=block)
    if duration is not None:  # a shortened DBT run: its report's windows within it
        d["time"]["duration_s"] = duration
        d["report"].update(average_from_s=duration / 3, windows={})
    d["prior"].update(prior)
    return S.parse(d, name)


def _series(m, g: str):
    return getattr(m, g)() if g in ("nees", "nis") else m.mse(g)


def _assert_same_block(a, b):
    assert (a.block, a.runs) == (b.block, b.runs)
    np.testing.assert_array_equal(a.info, b.info)  # the PCRLB's sums: the same truths
    for g in a.grads:
        np.testing.assert_array_equal(a.grads[g], b.grads[g])
    assert list(a.metrics) == list(b.metrics)
    for name, ma in a.metrics.items():
        mb = b.metrics[name]
        for g in ma.names:
            want, got = (_series(x, g) for x in (ma, mb))
            np.testing.assert_array_equal(np.isnan(got), np.isnan(want))  # the steps unseen
            seen = ~np.isnan(want)
            want, got = want[seen], got[seen]
            # relative to the value, and to the series' median where a run's error crosses 0
            tol = RTOL * (np.abs(want) + np.median(np.abs(want)))
            assert np.all(np.abs(got - want) <= tol), (name, g, np.max(np.abs(got - want)
                                                                        / tol) * RTOL)
        np.testing.assert_array_equal(ma.count(ma.names[0]), mb.count(ma.names[0]))
        np.testing.assert_array_equal(ma.diverged(), mb.diverged())
        assert b.seconds[name] > 0
    for name, ga in (a.gaps or {}).items():
        gb = b.gaps[name]
        assert ga.keys() == gb.keys() and ga["handler"] == gb["handler"]
        for key in ("gap_sse", "after_sse"):
            for g in ga.get(key, {}):
                np.testing.assert_allclose(gb[key][g], ga[key][g], rtol=RTOL, atol=0)
        if "pseudo_steps" in ga:
            np.testing.assert_array_equal(ga["pseudo_steps"], gb["pseudo_steps"])


def test_dbt_blocks_together_are_the_blocks_one_by_one():
    # five filters (EKF, UKF, Sage-Husa, correntropy and the adaptive correntropy EKF with its
    # second-order term) over 600 s, four blocks of three runs
    s = _scenario("dbt-approaching", runs=12, block=3, duration=600.0)
    alone = [run_block(s, b) for b in range(4)]
    together = run_blocks(s, [0, 1, 2, 3], together=True)
    for a, b in zip(alone, together, strict=True):
        _assert_same_block(a, b)
    assert together[0].example is not None and all(p.example is None for p in together[1:])
    for name, (m, P) in alone[0].example.estimates.items():
        for want, got in ((m, together[0].example.estimates[name][0]),
                          (P, together[0].example.estimates[name][1])):
            scale = np.max(np.abs(want), axis=0)  # each component's largest value
            assert np.all(np.abs(got - want) <= RTOL * scale), name
    ra, rb = combine(s, alone), combine(s, together)
    for name, f in ra.filters.items():
        assert rb.filters[name].anees == pytest.approx(f.anees, rel=RTOL)
        for g, v in f.rmse_mean.items():
            assert rb.filters[name].rmse_mean[g] == pytest.approx(v, rel=RTOL)


def test_blocks_that_do_not_start_at_run_0_and_a_short_last_block():
    s = _scenario("dbt-receding", runs=8, block=3, duration=300.0)
    alone = [run_block(s, b) for b in (1, 2)]
    together = run_blocks(s, [1, 2], together=True)
    assert [p.runs for p in together] == [3, 2]
    for a, b in zip(alone, together, strict=True):
        _assert_same_block(a, b)
    assert all(p.example is None for p in together)


def test_gap_handlers_score_each_blocks_runs():
    # three KFs through the radar's gap with coasting, the mean of the last measurements and
    # a fitted line: each block's gap and after-gap errors, and its pseudo-measurement counts
    s = _scenario("gaps-cv", runs=40, block=10)
    alone = [run_block(s, b) for b in range(4)]
    together = run_blocks(s, [0, 1, 2, 3], together=True)
    assert all("gap_sse" in g for g in together[0].gaps.values())
    for a, b in zip(alone, together, strict=True):
        _assert_same_block(a, b)
    np.testing.assert_array_equal(together[0].example.pseudo["B2"],
                                  alone[0].example.pseudo["B2"])


def test_the_ga_start_is_each_blocks_own():
    # the GA searches all the runs at once, each with its own generator: each block gets the
    # start it gets alone
    s = _scenario("dbt-approaching", runs=2, block=1, duration=900.0, initialiser="ga")
    alone = [run_block(s, b) for b in range(2)]
    together = run_blocks(s, [0, 1], together=True)
    for a, b in zip(alone, together, strict=True):
        _assert_same_block(a, b)


def test_a_stochastic_filter_or_covariance_matching_is_refused():
    s = _scenario("bo-cv", runs=20, block=10)
    with pytest.raises(ValueError, match="'PF' draws from its block's own generator"):
        run_blocks(s, [0, 1], together=True)
    d = S.load("dbt-approaching").model_dump()
    d["report"]["matching"] = True
    d["run"]["block"] = 50
    with pytest.raises(ValueError, match="report.matching"):
        run_blocks(S.parse(d), [0, 1], together=True)


def test_progress_counts_the_batchs_runs():
    s = _scenario("dbt-approaching", runs=6, block=3, duration=200.0)
    seen: list[float] = []
    run_blocks(s, [0, 1], seen.append, together=True)
    assert seen[-1] == pytest.approx(6.0) and seen == sorted(seen)
