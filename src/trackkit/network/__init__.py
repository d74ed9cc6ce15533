"""Decentralised cooperative tracking (seed 004): composite measurements from asynchronous
bearings (:mod:`~trackkit.network.composite`) and diffusion Kalman filtering over a network
of agents (:mod:`~trackkit.network.diffusion`)."""

from trackkit.network.composite import (
    CONVERGED,
    NOT_CONVERGED,
    SINGULAR,
    Composite,
    composite_measurement,
    fisher_information,
)
from trackkit.network.diffusion import (
    COMBINATIONS,
    DiffusionKF,
    adapt,
    check_weights,
    ci_weights,
    combine,
    metropolis_weights,
    neighbourhood,
    uniform_weights,
)

__all__ = [
    "COMBINATIONS",
    "CONVERGED",
    "NOT_CONVERGED",
    "SINGULAR",
    "Composite",
    "DiffusionKF",
    "adapt",
    "check_weights",
    "ci_weights",
    "combine",
    "composite_measurement",
    "fisher_information",
    "metropolis_weights",
    "neighbourhood",
    "uniform_weights",
]
