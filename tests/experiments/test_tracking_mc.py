"""The multi-target Monte Carlo: the same numbers for any block size and executor, and
numbers that mean what they say."""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.experiments.tracking_mc import run_tracking
from trackkit.sim.scene import Radar, Scene, Target, radar_crossing
from trackkit.tracking import GNN, JPDA, HistoryLogic, SinglePoint, Tracker


def trackers(scene) -> dict[str, Tracker]:
    # a scene without clutter still needs a small density for the association's ratios
    sensor, lam = scene.sensors[0], max(scene.clutter_density[0], 1e-12)
    common = dict(pd=0.9, clutter_density=lam, logic=HistoryLogic(confirm=(2, 3), delete=(3, 3)),
                  initiator=SinglePoint(v_std=60.0))
    cv = tk.models.ConstantVelocity(dim=2, q=1.0)
    return {"GNN": Tracker(tk.filters.EKF(), cv, sensor, associator=GNN(), **common),
            "JPDA": Tracker(tk.filters.EKF(), cv, sensor, associator=JPDA(), **common)}


def _same(a, b):
    assert a.trackers.keys() == b.trackers.keys()
    for name in a.trackers:
        x, y = a.trackers[name], b.trackers[name]
        np.testing.assert_array_equal(x.gospa, y.gospa)
        np.testing.assert_array_equal(x.ospa, y.ospa)
        for k in x.gospa_parts:
            np.testing.assert_array_equal(x.gospa_parts[k], y.gospa_parts[k])
        assert x.summary == pytest.approx(y.summary, rel=0, abs=0, nan_ok=True)


@pytest.mark.portability
def test_same_numbers_for_any_block_size():
    scene = radar_crossing()
    one = run_tracking(scene, trackers(scene), runs=6, seed=3, block=6)
    _same(one, run_tracking(scene, trackers(scene), runs=6, seed=3, block=2))
    _same(one, run_tracking(scene, trackers(scene), runs=6, seed=3, block=4))


@pytest.mark.slow
@pytest.mark.portability
def test_same_numbers_on_a_local_dask_cluster():
    scene = radar_crossing()
    seen = []
    dask = run_tracking(scene, trackers(scene), runs=6, seed=3, block=2, workers=2,
                        progress=lambda d, t: seen.append((d, t)))
    _same(run_tracking(scene, trackers(scene), runs=6, seed=3, block=6), dask)
    assert seen[-1] == (6, 6)


def test_a_clean_scene_is_tracked_to_the_noise_level():
    # one target, no clutter, pd = 1, a position radar: after confirmation GOSPA is the
    # localisation error alone, near the filter's position accuracy, and nothing is false
    sensor = tk.models.Position(dim=2, sigma=10.0)
    scene = Scene([Target.moving(0.0, 0.0, course=1.0, speed=20.0)],
                  [Radar(sensor, fov=((-1e5, 1e5), (-1e5, 1e5)), pd=1.0, clutter=0.0,
                         period=2.0)], end=120.0)
    res = run_tracking(scene, trackers(scene), runs=4, seed=1)
    for r in res.trackers.values():
        late = r.gospa[10:]
        assert np.all(r.gospa_parts["missed"][10:] == 0)
        assert np.all(r.gospa_parts["false"] == 0)
        assert np.all((late > 1.0) & (late < 20.0)), late
        assert r.summary["false_tracks"] == 0 and r.summary["truths_confirmed"] == 4
        np.testing.assert_allclose(r.confirmed[10:], 1.0)
    assert res.times.shape == res.trackers["GNN"].gospa.shape


def test_bad_arguments():
    scene = radar_crossing()
    with pytest.raises(ValueError, match="trackers is empty"):
        run_tracking(scene, {}, runs=2, seed=0)
    with pytest.raises(ValueError, match="runs = 0"):
        run_tracking(scene, trackers(scene), runs=0, seed=0)
