"""Filters: stateless strategies with ``predict(belief, motion, dt)`` and
``update(belief, z, sensor) -> (belief, innovation)``."""

from trackkit.filters.adaptive import AEKF, AMCEKF, MCEKF, AdaptiveBelief, SageHusaBelief
from trackkit.filters.alphabeta import AlphaBeta, AlphaBetaBelief, AlphaBetaGamma
from trackkit.filters.bearings_only import (
    MPEKF,
    RPEKF,
    MPBelief,
    PendingParticles,
    RangeBankBelief,
    RangePF,
)
from trackkit.filters.fuzzy import FuzzyAdaptive, FuzzyBelief
from trackkit.filters.imm import IMM, IMMBelief
from trackkit.filters.initialise import dbt_prior_cov, ga_initial_position, ga_prior
from trackkit.filters.jtc import JTC, JTCBelief, MultiFilterBelief, MultiFilterJTC
from trackkit.filters.kalman import EKF, IEKF, KF
from trackkit.filters.particle import PF
from trackkit.filters.run import run_filter
from trackkit.filters.sigma import CKF, SRCKF, UKF, SigmaPoints
from trackkit.filters.smoothers import smooth

__all__ = [
    "KF",
    "EKF",
    "IEKF",
    "UKF",
    "CKF",
    "SRCKF",
    "PF",
    "JTC",
    "JTCBelief",
    "MultiFilterJTC",
    "MultiFilterBelief",
    "RPEKF",
    "RangeBankBelief",
    "MPEKF",
    "MPBelief",
    "RangePF",
    "PendingParticles",
    "AlphaBeta",
    "AlphaBetaGamma",
    "AlphaBetaBelief",
    "IMM",
    "IMMBelief",
    "MCEKF",
    "AMCEKF",
    "AEKF",
    "AdaptiveBelief",
    "SageHusaBelief",
    "FuzzyAdaptive",
    "FuzzyBelief",
    "SigmaPoints",
    "smooth",
    "run_filter",
    "ga_initial_position",
    "ga_prior",
    "dbt_prior_cov",
]
