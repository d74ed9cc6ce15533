"""Turn a validated scenario into models, legs and filters in SI units (the one conversion)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from trackkit import filters as tkf
from trackkit import models
from trackkit.belief import Gaussian
from trackkit.filters.gaps import WithGaps
from trackkit.scenario.options import make_filter
from trackkit.scenario.schema import (
    CHANNELS,
    KNOT,
    FilterSpec,
    Kinematics,
    Leg,
    MotionSpec,
    PriorSpec,
    Scenario,
    SensorSpec,
    channels,
)
from trackkit.sim.kinematics import LegPlan, propagate

Array = NDArray[np.float64]

__all__ = ["Plan", "compile_scenario", "build_motion", "build_filter", "build_imm",
           "WiderState", "build_sensor", "numeric_problems", "COV_LIMIT", "PRECISION_LIMIT"]


def build_motion(spec: MotionSpec, dim: int, extras: int = 0, dt: float = 1.0):
    """The motion model named by ``spec`` over ``[pos, vel]`` (+ constant extras); a
    ``Linear`` model, or a constant velocity with an additive ``q_diag``, is built for the
    scenario's step ``dt``; a ``ContinuousLinear`` one is discretised for each step."""
    if spec.model == "Linear":
        return models.LinearMotion(np.asarray(spec.F, dtype=float), np.diag(spec.q_diag))
    if spec.model == "ContinuousLinear":
        return models.ContinuousLinear(np.asarray(spec.A, dtype=float),
                                       np.asarray(spec.L, dtype=float),
                                       np.asarray(spec.Qc, dtype=float))
    if spec.q_diag is not None:
        n = 2 * dim + extras
        if len(spec.q_diag) != n:
            raise ValueError(f"motion q_diag has {len(spec.q_diag)} values; expected {n} "
                             "(the state length)")
        cv = models.ConstantVelocity(dim=dim, q=0.0)
        F = np.eye(n)
        F[: 2 * dim, : 2 * dim] = cv.jacobian(np.zeros(2 * dim), dt)
        return models.LinearMotion(F, np.diag(spec.q_diag))
    if spec.model == "ConstantVelocity":
        base = models.ConstantVelocity(dim=dim, q=spec.q)
    elif spec.model == "ConstantAcceleration":
        base = models.ConstantAcceleration(dim=dim, q=spec.q)
    elif spec.model == "Singer":
        base = models.Singer(dim=dim, tau=spec.tau, sigma=spec.sigma)
    else:
        if dim != 2:
            raise ValueError(f"CoordinatedTurn is 2-D; the scenario has dim = {dim}")
        base = models.CoordinatedTurn(q=spec.q, q_omega=spec.q_omega)
    return models.Augmented(base, extras, spec.q_extra) if extras else base


class WiderState:
    """A filter whose state is the scenario's n components followed by extra ones the truth
    does not carry (an IMM's union state [x, y, vx, vy, omega] over a CV truth).

    ``init`` appends the extras' prior to the scenario's prior, independent of it:
    ``x0 = [x0_n, m_e]``, ``P0 = blockdiag(P0_n, P_e)``; ``estimate`` is the marginal of the
    first n components (mean and covariance), which is what the metrics score. ``predict``
    ignores the scenario's motion: the filter has its own models.
    """

    def __init__(self, f: Any, n: int, extra_mean: Array, extra_cov: Array) -> None:
        self.f, self.n = f, n
        self.extra_mean = np.asarray(extra_mean, dtype=float)
        self.extra_cov = np.asarray(extra_cov, dtype=float)

    @property
    def stochastic(self) -> bool:
        """Whether the inner filter draws random numbers (then ``init`` takes its ``rng``)."""
        return getattr(self.f, "stochastic", False)

    def init(self, prior: Gaussian, rng: np.random.Generator | None = None):
        x, P = np.asarray(prior.mean, dtype=float), np.asarray(prior.cov, dtype=float)
        if x.shape[-1] != self.n:
            raise ValueError(f"WiderState.init: prior.mean has {x.shape[-1]} components; "
                             f"expected {self.n} (the scenario's state)")
        batch, e = x.shape[:-1], self.extra_mean.size
        X = np.concatenate([x, np.broadcast_to(self.extra_mean, batch + (e,))], -1)
        PX = np.zeros(batch + (self.n + e, self.n + e))
        PX[..., : self.n, : self.n] = P
        PX[..., self.n:, self.n:] = self.extra_cov
        wide = Gaussian(X, PX)
        return self.f.init(wide, rng=rng) if self.stochastic else self.f.init(wide)

    def predict(self, belief: Any, motion: Any, dt: float):
        return self.f.predict(belief, None, dt)

    def update(self, belief: Any, z: Any, sensor: Any):
        return self.f.update(belief, z, sensor)

    def estimate(self, belief: Any) -> Gaussian:
        g = self.f.estimate(belief)
        return Gaussian(g.mean[..., : self.n], g.cov[..., : self.n, : self.n])


def build_imm(spec: FilterSpec, dim: int, dt: float) -> tkf.IMM:
    """The IMM of a filter's ``imm`` table: each model's motion (over ``dim`` positions, for
    the step ``dt``) with its inner filter, the transition and mu0 (default equal); each
    model's state is the first components of the union (imm.py's default state maps)."""
    imm = spec.imm
    motions = [build_motion(m.motion, dim, 0, dt) for m in imm.models]
    inner = [make_filter(m.filter, m.options) for m in imm.models]
    r = len(motions)
    mu0 = np.full(r, 1.0 / r) if imm.mu0 is None else np.asarray(imm.mu0, dtype=float)
    return tkf.IMM(motions, inner, np.asarray(imm.transition, dtype=float), mu0=mu0,
                   fill=make_filter(spec.type, spec.options).fill)


def build_filter(spec: FilterSpec, dim: int = 2, dt: float = 1.0, n: int | None = None):
    """The filter named by ``spec.type`` with ``spec.options``, as the table of
    ``trackkit.scenario.options`` says (the options were validated with the scenario).

    A fuzzy-adaptive type (OFKF, OFEKF, OFUKF) wraps a KF, EKF or UKF; ``q_inputs`` is given
    flat, ``[i1, l1, i2, l2, ...]``. Without ``params`` (a filter still to be tuned) it gets
    the untuned default system. An IMM (``spec.imm``) is built for ``dim`` positions and
    the step ``dt``; when its union state is longer than the scenario's ``n`` components it
    is wrapped in :class:`WiderState` with the prior of the extras (``imm.extra_std``).
    """
    if spec.imm is None:
        return make_filter(spec.type, spec.options)
    f = build_imm(spec, dim, dt)
    extra = len(spec.imm.extra_std)
    if n is None:
        return f
    mean = np.zeros(extra) if spec.imm.extra_mean is None else spec.imm.extra_mean
    return WiderState(f, n, np.asarray(mean, dtype=float),
                      np.diag(np.square(np.asarray(spec.imm.extra_std, dtype=float))))


def build_sensor(spec: SensorSpec, position: Array, velocity: Array, sigma: list[float]):
    """The sensor at an observer pose; ``sigma`` holds the SI noise standard deviation of
    each measurement channel (from units, ``r_diag_si`` or the SNR)."""
    m = spec.model
    if m == "Bearing":
        return models.Bearing(position[:2], sigma[0], convention=spec.convention,
                              velocity=velocity[:2])
    if m == "RangeBearing":
        return models.RangeBearing(position[:2], sigma[0], sigma[1],
                                   convention=spec.convention)
    if m == "Position":
        return models.Position(dim=len(sigma), sigma=sigma)
    if m == "AzimuthElevation":
        return models.AzimuthElevation(position, sigma[0], sigma[1],
                                       convention=spec.convention)
    if m == "BearingFrequency":
        return models.BearingFrequency(position[:2], velocity[:2], sigma[0], sigma[1],
                                       c=spec.c_mps)
    if m == "Sine":
        return models.Sine(sigma=sigma[0], amplitude=spec.amplitude)
    return models.MultipathDelay(position, spec.h_surface_m, spec.h_bottom_m,
                                 sigma=sigma, c=spec.c_mps)


def _channel_field(spec: SensorSpec, dim: int) -> list[str]:
    """The scenario field that sets each channel's noise."""
    if spec.r_diag_si is not None:
        return ["r_diag_si"] * channels(spec, dim)
    if spec.snr_db is not None:
        return ["snr_db"] * channels(spec, dim)
    if spec.model == "Position":
        return ["sigma_m"] * channels(spec, dim)
    by_kind = {"bearing": "sigma_deg", "elevation": "sigma_deg", "range": "sigma_m",
               "frequency": "sigma_hz", "delay": "sigma_s"}
    return [by_kind[c] for c in CHANNELS[spec.model]]


def _unit_sigma(spec: SensorSpec, dim: int) -> list[float] | None:
    """Per-channel noise std from the fields with units (None when the SNR sets it)."""
    m = channels(spec, dim)
    if spec.r_diag_si is not None:
        if len(spec.r_diag_si) != m:
            raise ValueError(f"sensor {spec.model}: r_diag_si has {len(spec.r_diag_si)} values;"
                             f" expected {m} (one per measurement channel)")
        return [math.sqrt(v) for v in spec.r_diag_si]
    if spec.snr_db is not None:
        return None
    if spec.model == "Position":
        return [spec.sigma_m] * m
    by_kind = {"bearing": spec.sigma_deg and math.radians(spec.sigma_deg),
               "elevation": spec.sigma_deg and math.radians(spec.sigma_deg),
               "range": spec.sigma_m, "frequency": spec.sigma_hz, "delay": spec.sigma_s}
    return [by_kind[c] for c in CHANNELS[spec.model]]


def legs_si(legs: list[Leg]) -> list[LegPlan]:
    out = []
    for leg in legs:
        if leg.turn_rate_deg_s is not None:
            out.append(LegPlan("turn", leg.start_s, leg.end_s, rate=math.radians(
                leg.turn_rate_deg_s)))
        elif leg.velocity_mps is not None:
            out.append(LegPlan("velocity", leg.start_s, velocity=tuple(leg.velocity_mps)))
        elif leg.acceleration_mps2 is not None:
            out.append(LegPlan("accel", leg.start_s, leg.end_s, accel=leg.acceleration_mps2))
        else:
            out.append(LegPlan(
                "set", leg.start_s,
                course=None if leg.course_deg is None else math.radians(leg.course_deg),
                speed=None if leg.speed_kn is None else leg.speed_kn * KNOT))
    return out


def kinematic_state(k: Kinematics, dim: int) -> Array:
    vx, vy = k.velocity()
    if dim == 2:
        return np.array([k.x_m, k.y_m, vx, vy])
    return np.array([k.x_m, k.y_m, k.z_m or 0.0, vx, vy, k.vz_mps or 0.0])


@dataclass
class Plan:
    """A scenario compiled for simulation and estimation (everything SI)."""

    scenario: Scenario
    dim: int
    n: int
    times: Array  # (T + 1,) from 0
    x0: Array  # (n,) initial true state
    truth_motion: object  # model whose Q drives the truth's process noise (and the PCRLB)
    target_legs: list[LegPlan]
    observer_states: Array  # (O, T + 1, 2 dim)
    sensor_specs: list[SensorSpec]
    sigmas: list[list[float]]  # per observer, SI noise std per channel
    sensors: list  # per step k = 1..T: the (stacked) sensor at the observers' poses
    filter_names: list[str]
    filters: list
    filter_motions: list
    priors: list[tuple[Array | None, Array]]  # per filter (mean or None, P0)
    prior_cov: Array  # the scenario prior's P0 (for the PCRLB)
    p_detect: float
    filter_r0: list[Array | None]  # per filter: the R it believes, or None for the true R
    nominal: Array  # (T + 1, n) the noise-free truth
    gap_mask: Array | None = None  # (T,) True where [gaps] hides the measurement
    gap_handlers: list[str | None] | None = None  # per filter: its handler's label, or None

    def filter_sensor(self, i: int, k: int):
        """The sensor of step k (0-based) as filter i sees it (its own R0 if it has one)."""
        R0 = self.filter_r0[i]
        return self.sensors[k] if R0 is None else models.with_noise(self.sensors[k], R0)

    @property
    def steps(self) -> int:
        return len(self.times) - 1

    @property
    def dt(self) -> float:
        return float(self.times[1] - self.times[0])


def _prior(p: PriorSpec) -> tuple[Array | None, Array]:
    mean = None if p.mean is None else np.asarray(p.mean, dtype=float)
    if p.cov is not None:
        return mean, np.asarray(p.cov, dtype=float)
    return mean, np.diag(np.asarray(p.std, dtype=float) ** 2)


def _stack(sensors: list):
    return sensors[0] if len(sensors) == 1 else models.Stack(tuple(sensors))


def _tracks(s: Scenario, T: int) -> tuple[Array, Array, Any, Array, Array]:
    """Times, initial true state, truth's motion model, observers' tracks and the
    noise-free truth over the first T steps."""
    dim = s.dim
    extras = len(s.target.extras)
    times = np.arange(T + 1) * s.time.step_s
    if s.target.state is not None:
        x0 = np.asarray(s.target.state, dtype=float)
    else:
        x0 = np.concatenate([kinematic_state(s.target.initial, dim), s.target.extras])
    dt = s.time.step_s
    truth_motion = build_motion(s.target.motion, dim, extras, dt)
    obs = np.stack([
        propagate(kinematic_state(o.initial, dim), times, legs_si(o.legs), dim)
        for o in s.observers
    ])
    if s.linear_system:
        nominal = np.empty((T + 1, len(x0)))
        nominal[0] = x0
        for k in range(T):
            nominal[k + 1] = truth_motion.f(nominal[k], dt)
    else:
        nominal = np.concatenate(
            [propagate(x0[: 2 * dim], times, legs_si(s.target.legs), dim),
             np.broadcast_to(x0[2 * dim:], (T + 1, extras))], -1)
    return times, x0, truth_motion, obs, nominal


def _sigmas(s: Scenario, obs: Array, nominal: Array) -> list[list[float]]:
    """Per observer, the SI noise standard deviation of each channel (an SNR averages the
    measurement's power over all the steps of ``nominal``)."""
    dim, T = s.dim, len(nominal) - 1
    sigmas = []
    for i, o in enumerate(s.observers):
        sig = _unit_sigma(o.sensor, dim)
        if sig is None:
            # noise variance = mean square of the noise-free measurement / 10^(SNR/10)
            probe = [1.0] * channels(o.sensor, dim)
            z = np.stack([
                build_sensor(o.sensor, obs[i, k, :dim], obs[i, k, dim:], probe).h(nominal[k])
                for k in range(1, T + 1)
            ])
            power = np.mean(z**2, axis=0)
            sig = [float(np.sqrt(pw / np.power(10.0, o.sensor.snr_db / 10)))
                   for pw in power]
        sigmas.append(sig)
    return sigmas


def compile_scenario(s: Scenario) -> Plan:
    """Convert units once, build models, observers' tracks and the per-step sensors."""
    dim, T = s.dim, s.time.steps
    extras = len(s.target.extras)
    dt = s.time.step_s
    times, x0, truth_motion, obs, nominal = _tracks(s, T)
    sigmas = _sigmas(s, obs, nominal)
    sensors = [
        _stack([build_sensor(o.sensor, obs[i, k, :dim], obs[i, k, dim:], sigmas[i])
                for i, o in enumerate(s.observers)])
        for k in range(1, T + 1)
    ]
    fmotions, filters, priors, r0 = [], [], [], []
    m = sensors[0].dim_z
    handlers = []
    for f in s.filters:
        flt = build_filter(f, dim, dt, s.state_dim)
        if f.gaps is not None:
            handler = f.gaps.build()
            detector = None if f.gaps.detector is None else f.gaps.detector.build(m)
            flt = WithGaps(flt, handler, detector)
            handlers.append(handler.label)
        else:
            handlers.append(None)
        filters.append(flt)
        fmotions.append(build_motion(f.motion or s.target.motion, dim, extras, dt))
        priors.append(_prior(f.prior or s.prior))
        if f.r0_diag_si is not None and len(f.r0_diag_si) != m:
            raise ValueError(f"filter {f.name!r}: r0_diag_si has {len(f.r0_diag_si)} values; "
                             f"expected {m} (the measurement's channels)")
        r0.append(None if f.r0_diag_si is None else np.diag(f.r0_diag_si))
    pds = {o.sensor.p_detect for o in s.observers}
    return Plan(
        scenario=s, dim=dim, n=s.state_dim, times=times, x0=x0, truth_motion=truth_motion,
        target_legs=legs_si(s.target.legs), observer_states=obs,
        sensor_specs=[o.sensor for o in s.observers], sigmas=sigmas, sensors=sensors,
        filter_names=[f.name for f in s.filters], filters=filters, filter_motions=fmotions,
        priors=priors, prior_cov=_prior(s.prior)[1], p_detect=min(pds), filter_r0=r0,
        nominal=nominal, gap_mask=None if s.gaps is None else s.gaps.mask(T, dt),
        gap_handlers=handlers,
    )


# --- numbers a run cannot carry, found when the scenario is read --------------------------

#: Largest covariance entry (SI units squared) that P0, Q, R and the first prediction may
#: have. The filters multiply two covariance-sized quantities (``A A^T`` in the Joseph form,
#: ``a d - b b`` in a 2 x 2 inverse), so each must stay below sqrt(1.8e308) = 1.3e154, the
#: square root of the largest double; 1e150 leaves a factor 1e4 for the growth of P over a
#: run. No physical covariance comes near it (1e150 m^2 is a spread of 1e75 m).
COV_LIMIT = 1e150

#: Largest ratio of a channel's predicted measurement variance ``(H P- H^T)_jj`` at the
#: first step to its noise variance ``R_jj``. The update leaves about ``R_jj`` of that
#: variance, computed as a difference of numbers of size ``(H P- H^T)_jj``, so its relative
#: rounding error is about eps * ratio (eps = 2.2e-16): 2e-4 at 1e12. Filters fail near a
#: ratio of 1/eps = 4.5e15 (the bo-cv UKF at sigma_deg = 1e-8, cv-position at sigma_m =
#: 1e-6, where the posterior covariance stops being positive definite); the factor 1e4 of
#: margin covers later steps, whose geometry or process noise can make the ratio larger.
#: In standard deviations: the noise may be up to 1e6 times smaller than the prior spread.
PRECISION_LIMIT = 1e12

_CHANNEL_UNITS = {"bearing": "rad", "elevation": "rad", "range": "m", "frequency": "Hz",
                  "delay": "s", "position": "m", "signal": "(SI)"}


def _channel_kinds(spec: SensorSpec, dim: int) -> list[str]:
    if spec.model == "Position":
        return ["position"] * channels(spec, dim)
    return CHANNELS[spec.model]


def _motion_field(spec: MotionSpec) -> str:
    """The field that scales a motion model's process noise."""
    if spec.q_diag is not None:
        return "q_diag"
    if spec.model == "ContinuousLinear":
        return "Qc"
    return "sigma" if spec.model == "Singer" else "q"


def _g(v: float) -> str:
    return f"{v:.3g}"


def numeric_problems(s: Scenario) -> list[tuple[str, Any, str]]:
    """Values that pass the schema but that a run in double precision cannot carry, as
    ``(field, value, message)``: covariances beyond :data:`COV_LIMIT`, a first update sharper
    than :data:`PRECISION_LIMIT`, and the sizes only the built models can check (``q_diag``,
    ``r_diag_si`` and ``r0_diag_si`` against the state and the channels). Only the first
    step is built (all steps with an ``snr_db``, whose noise averages over them), and no
    floating-point warning escapes: overflow shows as a value out of range."""
    problems: dict[str, tuple[Any, str]] = {}  # by field: each named once

    def add(loc: str, value: Any, message: str) -> None:
        problems.setdefault(loc, (value, message))

    with np.errstate(all="ignore"):
        _check(s, add)
    return [(loc, value, message) for loc, (value, message) in problems.items()]


def _too_big(M: Any) -> float | None:
    """The largest magnitude of M when it is not finite or beyond COV_LIMIT."""
    M = np.asarray(M, dtype=float)
    top = float(np.max(np.abs(M))) if M.size else 0.0
    return top if not (top <= COV_LIMIT) else None


def _check(s: Scenario, add: Callable[[str, Any, str], None]) -> None:
    dim, dt = s.dim, s.time.step_s
    extras = len(s.target.extras)
    snr = any(o.sensor.snr_db is not None for o in s.observers)
    try:
        _, x0, truth_motion, obs, nominal = _tracks(s, s.time.steps if snr else 1)
    except ValueError as err:
        add("target.motion", _motion_value(s.target.motion), str(err))
        return

    def motion_noise(spec: MotionSpec, where: str, motion: Any, x: Array) -> Array | None:
        """Q, or None (and the problem named) when it is out of range."""
        Q = np.asarray(motion.noise(x, dt), dtype=float)
        top = _too_big(Q)
        if top is not None:
            field = _motion_field(spec)
            value = getattr(spec, field)
            hint = f"entries up to {COV_LIMIT:.0e}"
            if field in ("q", "sigma") and math.isfinite(top):
                scale = COV_LIMIT / top
                hint = (f"{field} <= about "
                        f"{_g(value * (scale if field == 'q' else math.sqrt(scale)))}")
            add(f"{where}.{field}", value,
                f"the process noise covariance over one step ({_g(dt)} s) reaches {_g(top)} "
                f"(SI units squared); expected {hint}, so that products of two covariances "
                "stay below the largest double (1.8e308)")
            return None
        return Q

    motion_noise(s.target.motion, "target.motion", truth_motion, x0)
    for i, o in enumerate(s.observers):
        try:
            _unit_sigma(o.sensor, dim)
        except ValueError as err:  # r_diag_si of the wrong length
            add(f"observers.{i}.sensor.r_diag_si", o.sensor.r_diag_si, str(err))
            return
    sigmas = _sigmas(s, obs, nominal)
    fields, kinds = [], []
    noise_ok = True
    for i, (o, sig) in enumerate(zip(s.observers, sigmas, strict=True)):
        names = _channel_field(o.sensor, dim)
        for j, var in enumerate(np.square(np.asarray(sig, dtype=float))):
            if not (1 / COV_LIMIT <= var <= COV_LIMIT):
                noise_ok = False
                add(f"observers.{i}.sensor.{names[j]}", getattr(o.sensor, names[j]),
                    f"the noise variance of the {_channel_kinds(o.sensor, dim)[j]} is "
                    f"{_g(var)} (SI units squared); expected {1 / COV_LIMIT:.0e} to "
                    f"{COV_LIMIT:.0e}, what products of two variances can carry in double "
                    "precision")
        fields += [f"observers.{i}.sensor.{n}" for n in names]
        kinds += _channel_kinds(o.sensor, dim)
    if not noise_ok:
        return  # the sensors cannot even be built
    sensor = _stack([build_sensor(o.sensor, obs[i, 1, :dim], obs[i, 1, dim:], sigmas[i])
                     for i, o in enumerate(s.observers)])
    for i, f in enumerate(s.filters):
        spec, where = (f.motion, f"filters.{i}.motion") if f.motion else (
            s.target.motion, "target.motion")
        try:
            motion = build_motion(spec, dim, extras, dt)
        except ValueError as err:
            add(where, _motion_value(spec), str(err))
            continue
        prior = f.prior or s.prior
        ploc = f"filters.{i}.prior" if f.prior else "prior"
        ploc += ".std" if prior.std is not None else ".cov"
        mean, P0 = _prior(prior)
        variances = np.diagonal(P0)
        if not np.all((variances >= 1 / COV_LIMIT) & (variances <= COV_LIMIT)):
            add(ploc, prior.std if prior.std is not None else prior.cov,
                f"the prior variances reach {_g(variances.min())} to {_g(variances.max())} "
                f"(SI units squared); expected {1 / COV_LIMIT:.0e} to {COV_LIMIT:.0e}, what "
                "products of two variances can carry in double precision")
            continue
        x = x0 if mean is None else mean
        Q = motion_noise(spec, where, motion, x)
        if Q is None:
            continue
        R = np.asarray(sensor.noise, dtype=float)
        chan_fields = fields
        if f.r0_diag_si is not None:
            if len(f.r0_diag_si) != R.shape[-1]:
                add(f"filters.{i}.r0_diag_si", f.r0_diag_si,
                    f"filter {f.name!r}: r0_diag_si has {len(f.r0_diag_si)} values; expected "
                    f"{R.shape[-1]} (the measurement's channels)")
                continue
            R = np.diag(np.asarray(f.r0_diag_si, dtype=float))
            chan_fields = [f"filters.{i}.r0_diag_si"] * R.shape[-1]
            if _too_big(R) is not None:
                add(chan_fields[0], f.r0_diag_si, f"filter {f.name!r}: r0_diag_si reaches "
                    f"{_g(R.max())}; expected values up to {COV_LIMIT:.0e}")
                continue
        F = np.asarray(motion.jacobian(x, dt), dtype=float)
        H = np.asarray(sensor.jacobian(motion.f(x, dt)), dtype=float)
        Pp = F @ P0 @ F.T + Q
        hph = np.diagonal(H @ Pp @ H.T)
        hqh = np.diagonal(H @ Q @ H.T)
        r = np.diagonal(R)
        if _too_big(Pp) is not None:
            add(ploc, prior.std if prior.std is not None else prior.cov,
                f"the first predicted covariance of filter {f.name!r} reaches "
                f"{_g(np.abs(Pp).max())}; expected entries up to {COV_LIMIT:.0e}")
            continue
        if not (np.all(np.isfinite(hph)) and np.all(np.isfinite(r))):
            continue  # a degenerate geometry (target on the sensor): not a number's fault
        for j in np.flatnonzero(hph > PRECISION_LIMIT * r):
            _too_sharp(s, f, add, kinds[j], chan_fields[j], where, spec, float(hph[j]),
                       float(hqh[j]), float(r[j]))


def _motion_value(spec: MotionSpec) -> Any:
    return getattr(spec, _motion_field(spec))


def _too_sharp(s: Scenario, f: FilterSpec, add: Callable[[str, Any, str], None], kind: str,
               field: str, where: str, spec: MotionSpec, hph: float, hqh: float,
               r: float) -> None:
    """Name the field behind a first update sharper than PRECISION_LIMIT: the process noise
    when it makes most of the predicted spread, else the measurement noise."""
    unit = _CHANNEL_UNITS[kind]
    ratio = math.sqrt(hph / r)
    spread = (f"the first predicted {kind} of filter {f.name!r} spreads {_g(math.sqrt(hph))} "
              f"{unit}, {_g(ratio)} times the noise's {_g(math.sqrt(r))} {unit}")
    why = (f"beyond {math.sqrt(PRECISION_LIMIT):.0e} times the update's covariance loses its "
           "precision in double arithmetic")
    if hqh > hph / 2:
        mfield = _motion_field(spec)
        value = getattr(spec, mfield)
        hint = "smaller values"
        if mfield in ("q", "sigma"):
            scale = PRECISION_LIMIT * r / hqh
            top = value * (scale if mfield == "q" else math.sqrt(scale))
            hint = f"{mfield} <= about {_g(top)}"
        add(f"{where}.{mfield}", value, f"{spread}, mostly from this process noise; {why}; "
            f"expected {hint}")
        return
    name = field.rsplit(".", 1)[1]
    value = _field_value(s, field)
    need = math.sqrt(hph / PRECISION_LIMIT)  # the smallest noise std, SI
    if name == "sigma_deg":
        hint = f"sigma_deg >= {_g(math.degrees(need))}"
    elif name in ("sigma_m", "sigma_hz", "sigma_s"):
        hint = f"{name} >= {_g(need)}"
    elif name == "snr_db":
        hint = f"snr_db <= {_g(value + 10 * math.log10(r * PRECISION_LIMIT / hph))}"
    else:
        hint = f"{kind} variances >= {_g(need ** 2)}"
    prior = f"filters.{s.filters.index(f)}.prior" if f.prior else "prior"
    add(field, value, f"{spread}; {why}; expected {hint} (or a tighter {prior})")


def _field_value(s: Scenario, loc: str) -> Any:
    obj: Any = s
    for part in loc.split("."):
        obj = obj[int(part)] if part.isdigit() else getattr(obj, part)
    return obj
