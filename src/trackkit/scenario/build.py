"""Turn a validated scenario into models, legs and filters in SI units (the one conversion)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from trackkit import filters as tkf
from trackkit import models
from trackkit.scenario.schema import (
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


def build_motion(spec: MotionSpec, dim: int, extras: int = 0):
    """The motion model named by ``spec`` over ``[pos, vel]`` (+ constant extras)."""
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


def build_filter(spec: FilterSpec):
    """The filter named by ``spec.type`` with ``spec.options`` (names as the constructors')."""
    cls = {"KF": tkf.KF, "EKF": tkf.EKF, "IEKF": tkf.IEKF, "UKF": tkf.UKF, "CKF": tkf.CKF,
           "EKF2": tkf.EKF, "MCEKF": tkf.MCEKF, "AMCEKF": tkf.AMCEKF, "AEKF": tkf.AEKF}[spec.type]
    options = {k: tuple(v) if isinstance(v, list) else v for k, v in spec.options.items()}
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


def build_sensor(spec: SensorSpec, position: Array, velocity: Array, sigma: dict[str, float]):
    """The sensor at an observer pose; ``sigma`` holds the SI noise (from units or SNR)."""
    m = spec.model
    if m == "Bearing":
        return models.Bearing(position[:2], sigma["bearing"], convention=spec.convention)
    if m == "RangeBearing":
        return models.RangeBearing(position[:2], sigma["range"], sigma["bearing"],
                                   convention=spec.convention)
    if m == "Position":
        return models.Position(dim=len(position), sigma=sigma["position"])
    if m == "AzimuthElevation":
        return models.AzimuthElevation(position, sigma["bearing"], sigma["elevation"],
                                       convention=spec.convention)
    if m == "BearingFrequency":
        return models.BearingFrequency(position[:2], velocity[:2], sigma["bearing"],
                                       sigma["frequency"], c=spec.c_mps)
    return models.MultipathDelay(position, spec.h_surface_m, spec.h_bottom_m,
                                 sigma=[sigma["delay"], sigma["delay"]], c=spec.c_mps)


def _unit_sigma(spec: SensorSpec) -> dict[str, float]:
    out = {}
    if spec.sigma_deg is not None:
        out["bearing"] = out["elevation"] = math.radians(spec.sigma_deg)
    if spec.sigma_m is not None:
        out["range"] = out["position"] = spec.sigma_m
    if spec.sigma_hz is not None:
        out["frequency"] = spec.sigma_hz
    if spec.sigma_s is not None:
        out["delay"] = spec.sigma_s
    return out


_CHANNELS = {
    "Bearing": ["bearing"],
    "RangeBearing": ["range", "bearing"],
    "Position": ["position"],
    "AzimuthElevation": ["bearing", "elevation"],
    "BearingFrequency": ["bearing", "frequency"],
    "MultipathDelay": ["delay", "delay"],
}


def legs_si(legs: list[Leg]) -> list[LegPlan]:
    out = []
    for leg in legs:
        if leg.turn_rate_deg_s is not None:
            out.append(LegPlan("turn", leg.start_s, leg.end_s, rate=math.radians(
                leg.turn_rate_deg_s)))
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
    sigmas: list[dict[str, float]]  # per observer, SI noise per channel
    sensors: list  # per step k = 1..T: the (stacked) sensor at the observers' poses
    filter_names: list[str]
    filters: list
    filter_motions: list
    priors: list[tuple[Array | None, Array]]  # per filter (mean or None, P0)
    prior_cov: Array  # the scenario prior's P0 (for the PCRLB)
    p_detect: float

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
    truth_motion = build_motion(s.target.motion, dim, extras)
    obs = np.stack([
        propagate(kinematic_state(o.initial, dim), times, legs_si(o.legs), dim)
        for o in s.observers
    ])
    nominal = np.concatenate(
        [propagate(x0[: 2 * dim], times, legs_si(s.target.legs), dim),
         np.broadcast_to(x0[2 * dim:], (T + 1, extras))], -1)
    sigmas = []
    for i, o in enumerate(s.observers):
        sig = _unit_sigma(o.sensor)
        if o.sensor.snr_db is not None:
            # noise variance = mean square of the noise-free measurement / 10^(SNR/10)
            probe = {c: 1.0 for c in _CHANNELS[o.sensor.model]}
            z = np.stack([
                build_sensor(o.sensor, obs[i, k, :dim], obs[i, k, dim:], probe).h(nominal[k])
                for k in range(1, T + 1)
            ])
            power = np.mean(z**2, axis=0)
            for c, pw in zip(_CHANNELS[o.sensor.model], power, strict=True):
                sig[c] = float(np.sqrt(pw / 10 ** (o.sensor.snr_db / 10)))
        sigmas.append(sig)
    sensors = [
        _stack([build_sensor(o.sensor, obs[i, k, :dim], obs[i, k, dim:], sigmas[i])
                for i, o in enumerate(s.observers)])
        for k in range(1, T + 1)
    ]
    fmotions, filters, priors = [], [], []
    for f in s.filters:
        filters.append(build_filter(f))
        fmotions.append(build_motion(f.motion or s.target.motion, dim, extras))
        priors.append(_prior(f.prior or s.prior))
    pds = {o.sensor.p_detect for o in s.observers}
    return Plan(
        scenario=s, dim=dim, n=s.state_dim, times=times, x0=x0, truth_motion=truth_motion,
        target_legs=legs_si(s.target.legs), observer_states=obs,
        sensor_specs=[o.sensor for o in s.observers], sigmas=sigmas, sensors=sensors,
        filter_names=[f.name for f in s.filters], filters=filters, filter_motions=fmotions,
        priors=priors, prior_cov=_prior(s.prior)[1], p_detect=min(pds),
    )
