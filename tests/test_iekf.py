"""The IEKF's iterations converge to the MAP point of the update."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

import trackkit as tk


@pytest.mark.parametrize("line_search", [False, True])
def test_iekf_converges_to_the_map_of_a_bearing_update(line_search):
    sensor = tk.models.Bearing([0.0, 0.0], np.deg2rad(1.0))
    P = np.diag([4e6, 4e6, 16.0, 16.0])
    x0 = np.array([1000.0, 12000.0, 0.0, 0.0])
    z = np.array([np.deg2rad(20.0)])

    def cost(x):
        d, r = x - x0, sensor.residual(z, sensor.h(x))
        return d @ np.linalg.solve(P, d) + (r @ r) / sensor.sigma**2

    best = minimize(cost, x0, method="Nelder-Mead",
                    options={"xatol": 1e-8, "fatol": 1e-12, "maxiter": 40000})
    b, innov = tk.filters.IEKF(20, line_search=line_search).update(tk.Gaussian(x0, P), z, sensor)
    np.testing.assert_allclose(b.mean, best.x, atol=1e-3)
    assert cost(b.mean) <= best.fun + 1e-9
    # one iteration is the EKF, which stops short of the MAP on this strongly nonlinear update
    e, _ = tk.filters.EKF().update(tk.Gaussian(x0, P), z, sensor)
    one, _ = tk.filters.IEKF(1).update(tk.Gaussian(x0, P), z, sensor)
    np.testing.assert_allclose(one.mean, e.mean, rtol=1e-12)
    assert cost(e.mean) > cost(b.mean) + 0.1
    # the innovation is the one at the prediction
    np.testing.assert_allclose(innov.nu, z - sensor.h(x0), rtol=1e-12)


def test_iekf_line_search_never_increases_the_cost_batched():
    rng = np.random.default_rng(3)
    sensor = tk.models.RangeBearing([0.0, 0.0], 50.0, np.deg2rad(2.0))
    runs = 200
    x0 = np.column_stack([rng.uniform(-5e3, 5e3, runs), rng.uniform(2e3, 9e3, runs),
                          np.zeros(runs), np.zeros(runs)])
    P = np.tile(np.diag([9e6, 9e6, 25.0, 25.0]), (runs, 1, 1))
    z = sensor.h(x0 + rng.normal(0, 1500, (runs, 4)) * [1, 1, 0, 0])

    def cost(x):
        d, r = x - x0, sensor.residual(z, sensor.h(x))
        return (tk.linalg.quadratic_form(P, d)
                + tk.linalg.quadratic_form(np.broadcast_to(sensor.noise, (runs, 2, 2)), r))

    b, _ = tk.filters.IEKF(8, line_search=True).update(tk.Gaussian(x0, P), z, sensor)
    assert np.all(cost(b.mean) <= cost(x0) + 1e-9)
