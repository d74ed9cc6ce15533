"""Turn a validated scenario into models, legs and filters in SI units (the one conversion)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from trackkit import filters as tkf
from trackkit import models
from trackkit.scenario.schema import (
    FUZZY_TYPES,
    KNOT,
    FilterSpec,
    Kinematics,
    Leg,
    MotionSpec,
    PriorSpec,
    Scenario,
    SensorSpec,
)
from trackkit.sim.kinematics import LegPlan, propagate

Array = NDArray[np.float64]

__all__ = ["Plan", "compile_scenario", "build_motion", "build_filter", "build_sensor"]


def build_motion(spec: MotionSpec, dim: int, extras: int = 0, dt: float = 1.0):
    """The motion model named by ``spec`` over ``[pos, vel]`` (+ constant extras); a
    ``Linear`` model, or a constant velocity with an additive ``q_diag``, is built for the
    scenario's step ``dt``."""
    if spec.model == "Linear":
        return models.LinearMotion(np.asarray(spec.F, dtype=float), np.diag(spec.q_diag))
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


_FILTERS = {"KF": tkf.KF, "EKF": tkf.EKF, "IEKF": tkf.IEKF, "UKF": tkf.UKF, "CKF": tkf.CKF,
            "EKF2": tkf.EKF, "MCEKF": tkf.MCEKF, "AMCEKF": tkf.AMCEKF, "AEKF": tkf.AEKF}


def build_filter(spec: FilterSpec):
    """The filter named by ``spec.type`` with ``spec.options`` (names as the constructors').

    A fuzzy-adaptive type (OFKF, OFEKF, OFUKF) wraps a KF, EKF or UKF; ``q_inputs`` is given
    flat, ``[i1, l1, i2, l2, ...]``. Without ``params`` (a filter still to be tuned) it gets
    the untuned default system.
    """
    fuzzy = spec.type in FUZZY_TYPES
    cls = tkf.FuzzyAdaptive if fuzzy else _FILTERS[spec.type]
    options = {k: tuple(v) if isinstance(v, list) else v for k, v in spec.options.items()}
    if fuzzy:
        options["base"] = _FILTERS[FUZZY_TYPES[spec.type]]()
        pairs = options.get("q_inputs")
        if pairs is not None:
            if len(pairs) % 2:
                raise ValueError(f"filter {spec.name!r}: q_inputs has {len(pairs)} values; "
                                 "expected pairs [i1, l1, i2, l2, ...]")
            options["q_inputs"] = tuple((int(pairs[j]), int(pairs[j + 1]))
                                        for j in range(0, len(pairs), 2))
    if spec.type == "EKF2":
        options.setdefault("order", 2)
    for name in ("iterations", "order", "window", "max_halvings"):
        if options.get(name) is not None:
            options[name] = int(options[name])
    try:
        return cls(**options)
    except TypeError:
        import inspect

        allowed = [p for p in inspect.signature(cls).parameters if p != "self"]
        raise ValueError(
            f"filter {spec.name!r} ({spec.type}): options {sorted(options)} not accepted; "
            f"allowed: {allowed or 'none'}"
        ) from None


def build_sensor(spec: SensorSpec, position: Array, velocity: Array, sigma: list[float]):
    """The sensor at an observer pose; ``sigma`` holds the SI noise standard deviation of
    each measurement channel (from units, ``r_diag_si`` or the SNR)."""
    m = spec.model
    if m == "Bearing":
        return models.Bearing(position[:2], sigma[0], convention=spec.convention)
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
    return models.MultipathDelay(position, spec.h_surface_m, spec.h_bottom_m,
                                 sigma=sigma, c=spec.c_mps)


_CHANNELS = {
    "Bearing": ["bearing"],
    "RangeBearing": ["range", "bearing"],
    "AzimuthElevation": ["bearing", "elevation"],
    "BearingFrequency": ["bearing", "frequency"],
    "MultipathDelay": ["delay", "delay"],
}


def channels(spec: SensorSpec, dim: int) -> int:
    """Number of measurement channels of the sensor."""
    if spec.model == "Position":
        return len(spec.r_diag_si) if spec.r_diag_si is not None else dim
    return len(_CHANNELS[spec.model])


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
    return [by_kind[c] for c in _CHANNELS[spec.model]]


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


def compile_scenario(s: Scenario) -> Plan:
    """Convert units once, build models, observers' tracks and the per-step sensors."""
    dim, T = s.dim, s.time.steps
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
            sig = [float(np.sqrt(pw / 10 ** (o.sensor.snr_db / 10))) for pw in power]
        sigmas.append(sig)
    sensors = [
        _stack([build_sensor(o.sensor, obs[i, k, :dim], obs[i, k, dim:], sigmas[i])
                for i, o in enumerate(s.observers)])
        for k in range(1, T + 1)
    ]
    fmotions, filters, priors, r0 = [], [], [], []
    m = sensors[0].dim_z
    for f in s.filters:
        filters.append(build_filter(f))
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
        nominal=nominal,
    )
