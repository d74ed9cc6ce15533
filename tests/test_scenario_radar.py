"""The bundled scenarios of the missing-measurements thesis's chapter 2: S2, ``kf-cwpa`` (the
toolbox's ``kf_cwpa_demo``, a 2-D continuous Wiener-process acceleration target tracked by a KF) and
S3, ``sine-ekf-ukf`` (``ekf_sine_demo``, Table 2-1's random sine). Their models are the thesis's
equations written out here; S2's KF beats the raw measurements and its RTS smoother beats the
KF; both scenarios go through ``trackkit show`` and ``trackkit run`` unchanged; and the schema
fields they added (the ContinuousLinear motion model, the Sine sensor) refuse bad input by
name. Table 2-1's statistics are in tests/statistical/test_sine_ekf_ukf.py."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import trackkit as tk
import trackkit.scenario as S
from trackkit import cli
from trackkit.experiments.montecarlo import plan_of, run_scenario
from trackkit.scenario.simulate import simulate_block

RTOL = 1e-12  # deterministic maths


def load(name: str, runs: int | None = None):
    """A bundled scenario, with ``runs`` Monte Carlo runs instead of its own."""
    s = S.load(name)
    if runs is None:
        return s
    d = s.model_dump()
    d["run"]["runs"] = runs
    return S.parse(d)


def filtered(plan, data, i: int) -> tk.Gaussian:
    """Filter ``i`` of the plan over every simulated run as the Monte Carlo engine runs it
    (its prior: the fixed mean, or the truth plus the run's draw from N(0, P0)), with the
    estimates of every step: mean ``(T, runs, n)``, cov ``(T, runs, n, n)``."""
    mean0, P0 = plan.priors[i]
    runs, n = data.prior_offset.shape
    m0 = (data.truth[0] + data.prior_offset @ np.linalg.cholesky(P0).T if mean0 is None
          else np.tile(mean0, (runs, 1)))
    f = plan.filters[i]
    prior = f.init(tk.Gaussian(m0, np.broadcast_to(P0, (runs, n, n)).copy()))
    sensors = [plan.filter_sensor(i, k) for k in range(plan.steps)]
    _, history = tk.filters.run_filter(f, prior, plan.filter_motions[i], sensors, data.z,
                                       np.diff(plan.times), history=True)
    return history


def mse_per_run(mean, truth, idx) -> np.ndarray:
    """Per run, the squared error of the components ``idx`` (summed) averaged over the
    steps: ``(runs,)``. ``truth`` is ``(T, runs, n)``, the states at the estimates' times."""
    return np.sum((mean[..., idx] - truth[..., idx]) ** 2, axis=-1).mean(axis=0)


def assert_close(actual, expected, what: str) -> None:
    """Equal to RTOL relative to the largest entry of ``expected`` (its zeros included)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = np.abs(expected).max()
    err = np.abs(actual - expected).max()
    assert err <= RTOL * scale, f"{what}: off by {err:.3g} (scale {scale:.3g})"


# --------------------------------------------------------------------------------------------
# The models are the thesis's equations
# --------------------------------------------------------------------------------------------


def test_kf_cwpa_is_the_thesis_model_with_the_corrected_q():
    """Eqs. 2-65 and 2-66 (with dt^3/3, not the printed dt^3/6, and q = 0.2), H = [I 0]
    (2-64) and R = diag(10, 10) (2-67), in the state order (x, y, vx, vy, ax, ay)."""
    plan = plan_of(S.load("kf-cwpa"))
    dt, q = 0.5, 0.2
    assert plan.dt == dt and plan.steps == 50
    Fa = np.array([[1, dt, dt**2 / 2], [0, 1, dt], [0, 0, 1]])
    Qa = q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6],
                       [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                       [dt**3 / 6, dt**2 / 2, dt]])
    F, Q = np.kron(Fa, np.eye(2)), np.kron(Qa, np.eye(2))  # per-axis blocks interleaved
    for motion in (plan.truth_motion, plan.filter_motions[0]):
        assert_close(motion.jacobian(None, dt), F, "A (2-65)")
        assert_close(motion.noise(None, dt), Q, "Q (2-66, corrected)")
    assert Q[2, 2] == pytest.approx(q * dt**3 / 3, rel=RTOL)  # the printed dt^3/6 is wrong
    sensor = plan.sensors[0]
    assert_close(sensor.jacobian(np.zeros(6)), np.eye(2, 6), "H (2-64)")
    assert_close(sensor.noise, np.diag([10.0, 10.0]), "R (2-67)")
    assert_close(plan.priors[0][1], np.diag([0.1, 0.1, 0.1, 0.1, 0.5, 0.5]), "P0")
    assert plan.priors[0][0] is None  # drawn from N(truth, P0)
    assert type(plan.filters[0]) is tk.filters.KF


def test_sine_ekf_ukf_is_the_thesis_model():
    """Eqs. 2-94 and 2-95 with q1 = 0.2, q2 = 0.1, dt = 0.01 (also trackkit's RandomSine),
    y = a sin(theta) with R = 1 (2-96, 2-97), its Jacobian (2-99) and Hessian (2-100); the
    filters EKF, EKF2 and the UKF with alpha = 1, beta = 0, kappa = 0; the fixed prior."""
    plan = plan_of(S.load("sine-ekf-ukf"))
    dt, q1, q2 = 0.01, 0.2, 0.1
    assert plan.dt == pytest.approx(dt, rel=RTOL) and plan.steps == 500
    F = np.array([[1, dt, 0], [0, 1, 0], [0, 0, 1]])
    Q = np.array([[q1 * dt**3 / 3, q1 * dt**2 / 2, 0],
                  [q1 * dt**2 / 2, q1 * dt, 0],
                  [0, 0, q2 * dt]])
    sine = tk.models.RandomSine(q1=q1, q2=q2)
    for motion in (plan.truth_motion, *plan.filter_motions):
        assert_close(motion.jacobian(None, plan.dt), F, "A (2-94)")
        assert_close(motion.noise(None, plan.dt), Q, "Q (2-95)")
        assert_close(motion.noise(None, plan.dt), sine.noise(None, plan.dt), "RandomSine Q")
    x = np.random.default_rng(1).normal(size=(20, 3)) * [3.0, 10.0, 2.0]
    th, a = x[:, 0], x[:, 2]
    sensor = plan.sensors[0]
    assert_close(sensor.noise, [[1.0]], "R (2-97)")
    assert_close(sensor.h(x)[:, 0], a * np.sin(th), "h (2-96)")
    H = np.zeros((20, 1, 3))
    H[:, 0, 0], H[:, 0, 2] = a * np.cos(th), np.sin(th)
    assert_close(sensor.jacobian(x), H, "Jacobian (2-99)")
    Hs = np.zeros((20, 1, 3, 3))
    Hs[:, 0, 0, 0] = -a * np.sin(th)
    Hs[:, 0, 0, 2] = Hs[:, 0, 2, 0] = np.cos(th)
    assert_close(sensor.hessian(x), Hs, "Hessian (2-100)")
    ekf, ekf2, ukf = plan.filters
    assert (ekf.order, ekf2.order) == (1, 2)
    assert (ukf.alpha, ukf.beta, ukf.kappa) == (1.0, 0.0, 0.0)
    for mean, P0 in plan.priors:
        assert_close(mean, [0.0, 10.0, 1.0], "x0")
        assert_close(P0, 3.0 * np.eye(3), "P0")
    assert_close(plan.x0, [0.0, 10.0, 1.0], "true x0")


def test_the_squared_rmse_of_the_report_is_the_mean_per_run_mse_of_table_2_1():
    """results.json's time-averaged RMSE of x1, x2, x3, squared, is the Monte Carlo mean of
    each run's MSE of theta, omega and a (Table 2-1's quantity): the filters run here as the
    engine runs them. Rounding: the two sum in different orders, so 1e-12 relative."""
    s = load("sine-ekf-ukf", runs=40)
    result = run_scenario(s)
    plan = plan_of(s)
    data = simulate_block(plan, 0, 40)
    for i, name in enumerate(plan.filter_names):
        mean = filtered(plan, data, i).mean
        for j, g in enumerate(("x1", "x2", "x3")):
            mse = mse_per_run(mean, data.truth[1:], [j])
            assert result.filters[name].rmse_mean[g] ** 2 == pytest.approx(mse.mean(),
                                                                           rel=RTOL), (name, g)


# --------------------------------------------------------------------------------------------
# S2: the KF reduces the measurement error, the smoother reduces it further
# --------------------------------------------------------------------------------------------


def test_kf_cwpa_kf_beats_the_measurements_and_the_smoother_beats_the_kf():
    """Figs. 2-8 and 2-9: over the bundled 1 000 runs, the median per-run position MSE of the
    KF is below that of the raw measurements (2 R = 20 m^2 per run in expectation) and the
    RTS smoother's is at most the KF's. Measured: medians 19.9 (measurements), 7.9 (KF) and
    1.9 (smoother) m^2; the KF's 97.5 % quantile over runs (12.9) lies below the
    measurements' 2.5 % quantile (14.3), so the order is not an accident of the seed. The KF's
    mean equals the engine's squared position RMSE (the test filters as the engine does)."""
    s = S.load("kf-cwpa")
    runs = s.run.runs
    plan = plan_of(s)
    data = simulate_block(plan, 0, runs)
    truth = data.truth[1:]
    mse_raw = np.sum((data.z - truth[..., :2]) ** 2, axis=-1).mean(axis=0)
    kf = filtered(plan, data, 0)
    rts = tk.filters.smooth(plan.filters[0], kf, plan.filter_motions[0], plan.dt)
    mse_kf = mse_per_run(kf.mean, truth, [0, 1])
    mse_rts = mse_per_run(rts.mean, truth, [0, 1])
    print(f"\nS2 position MSE per run (m^2), median [2.5%, 97.5%] over {runs} runs:")
    for name, v in (("measurements", mse_raw), ("KF", mse_kf), ("RTS", mse_rts)):
        lo, hi = np.percentile(v, [2.5, 97.5])
        print(f"  {name:12s} {np.median(v):7.3f} [{lo:.3f}, {hi:.3f}] mean {v.mean():.3f}")
    assert np.median(mse_kf) < np.median(mse_raw)
    assert np.median(mse_rts) <= np.median(mse_kf)
    assert np.percentile(mse_kf, 97.5) < np.percentile(mse_raw, 2.5)
    engine = run_scenario(s).filters["KF"].rmse_mean["position"]
    assert engine**2 == pytest.approx(mse_kf.mean(), rel=RTOL)


def test_kf_cwpa_kf_is_consistent_and_at_the_bound():
    """The KF on its own linear-Gaussian model with a prior drawn from N(truth, P0) is the
    optimal filter: its MSE of position and velocity is the PCRLB (its own covariance) and its
    NEES averages n = 6. Each Monte Carlo mean over the 1 000 independent runs is within 4 of
    its standard errors (from the spread of the per-run values) of the theory: a false alarm
    once in 15 000 for each of the three checks. Measured: MSE / bound 1.0007 (position) and
    1.0002 (velocity), average NEES 5.98."""
    s = S.load("kf-cwpa")
    plan = plan_of(s)
    data = simulate_block(plan, 0, s.run.runs)
    truth = data.truth[1:]
    kf = filtered(plan, data, 0)
    result = run_scenario(s)
    e = kf.mean - truth
    nees = np.einsum("...i,...i->...", e, np.linalg.solve(kf.cov, e[..., None])[..., 0])
    checks = [(mse_per_run(kf.mean, truth, idx), result.pcrlb_mean[g] ** 2, g)
              for g, idx in (("position", [0, 1]), ("velocity", [2, 3]))]
    checks.append((nees.mean(axis=0), 6.0, "NEES"))
    for per_run, theory, what in checks:
        se = per_run.std(ddof=1) / np.sqrt(len(per_run))
        print(f"\n{what}: mean {per_run.mean():.4f}, theory {theory:.4f}, standard error "
              f"{se:.4f}")
        assert abs(per_run.mean() - theory) < 4 * se, what


# --------------------------------------------------------------------------------------------
# Load, show and run round trip
# --------------------------------------------------------------------------------------------

runner = CliRunner()


@pytest.mark.slow  # 5 s (kf-cwpa) and 9 s (sine-ekf-ukf): two runs and their reports
@pytest.mark.parametrize("name", ["kf-cwpa", "sine-ekf-ukf"])
def test_show_then_run_gives_the_bundled_results(name, tmp_path: Path):
    """``trackkit show NAME > x.toml`` loads to the same scenario, and ``trackkit run x.toml``
    writes the same results.json, byte for byte, as ``trackkit run NAME`` (3 runs)."""
    shown = runner.invoke(cli.app, ["show", name])
    assert shown.exit_code == 0, shown.output
    path = tmp_path / "x.toml"
    path.write_text(shown.stdout, encoding="utf-8")
    assert S.load(str(path)) == S.load(name)
    for source, out in ((str(path), "from-file"), (name, "bundled")):
        ran = runner.invoke(cli.app, ["run", source, "--runs", "3", "--out",
                                      str(tmp_path / out)], env={"COLUMNS": "200"})
        assert ran.exit_code == 0, ran.output
    a, b = ((tmp_path / out / "results.json").read_bytes() for out in ("from-file", "bundled"))
    assert a == b


# --------------------------------------------------------------------------------------------
# The schema fields S2 and S3 added refuse bad input by name
# --------------------------------------------------------------------------------------------


def _dump(name: str) -> dict:
    return copy.deepcopy(S.load(name).model_dump())


def rejects(d: dict, *words: str) -> None:
    with pytest.raises(S.ScenarioError) as err:
        S.parse(d)
    msg = str(err.value)
    for w in words:
        assert w in msg, (w, msg)


@pytest.mark.parametrize("field, value, words", [
    ("A", [[0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], ["A has rows of lengths [2, 3, 3]",
                                                            "square"]),
    ("L", [[0.0, 0.0], [1.0, 0.0]], ["L has rows of lengths [2, 2]", "expected 3 rows"]),
    ("L", [[0.0], [1.0, 0.0], [0.0, 1.0]], ["L has rows of lengths [1, 2, 2]"]),
    ("Qc", [[0.2, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 1.0]], ["Qc has rows of lengths",
                                                                  "expected 2 x 2"]),
    ("Qc", [[0.2, 0.1], [0.0, 0.1]], ["Qc is not symmetric"]),
    ("Qc", [[0.2, 0.0], [0.0, -0.1]], ["Qc is not positive semi-definite", "-0.1"]),
    ("Qc", None, ["ContinuousLinear needs A (n x n), L (n x s) and Qc (s x s)"]),
    ("F", [[1.0]], ["F is only for motion model Linear"]),
])
def test_bad_continuous_linear_motion_is_named(field, value, words):
    d = _dump("sine-ekf-ukf")
    d["target"]["motion"][field] = value
    rejects(d, "target.motion", *words)


def test_continuous_linear_needs_a_state_and_sized_filter_motions():
    d = _dump("sine-ekf-ukf")
    d["target"]["state"] = None
    rejects(d, "a target with motion model ContinuousLinear needs target.state")
    d = _dump("sine-ekf-ukf")
    d["filters"][0]["motion"] = {"model": "ContinuousLinear", "A": [[0.0]], "L": [[1.0]],
                                 "Qc": [[1.0]]}
    rejects(d, "filters[0].motion.A is 1 x 1; expected 3 x 3")
    d = _dump("bo-cv")
    d["target"]["motion"]["A"] = [[0.0]]
    rejects(d, "target.motion", "A, L and Qc are only for motion model ContinuousLinear, not "
            "ConstantVelocity")


def test_a_continuous_linear_noise_a_run_cannot_carry_names_qc():
    d = _dump("sine-ekf-ukf")
    d["target"]["motion"]["Qc"] = [[1e300, 0.0], [0.0, 0.1]]
    rejects(d, "target.motion.Qc", "process noise covariance over one step")


def test_sine_sensor_needs_its_noise_and_the_random_sine_state():
    d = _dump("sine-ekf-ukf")
    d["observers"][0]["sensor"]["r_diag_si"] = None
    rejects(d, "observers.0.sensor", "sensor Sine needs r_diag_si (its R, one value) or "
            "snr_db")
    d = _dump("bo-cv")
    d["observers"][0]["sensor"] = {"model": "Sine", "r_diag_si": [1.0]}
    rejects(d, "observers[0].sensor is Sine", "[theta, omega, a]",
            "not ConstantVelocity with 4 components")


def test_kinematic_groups_need_positions_and_velocities_in_the_state():
    d = _dump("sine-ekf-ukf")
    d["report"]["groups"] = ["x1", "position"]
    rejects(d, "report.groups has ['position']", "ContinuousLinear target's state of 3 "
            "components", "at least 2 dim = 4")
    d = _dump("kf-cwpa")  # (x, y, vx, vy, ax, ay): positions and velocities lead
    d["report"]["groups"] = ["position", "velocity", "x", "vy", "speed", "x3"]
    S.parse(d)
    d["report"]["groups"] = ["frequency"]
    rejects(d, "report.groups has ['frequency']")
