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
from trackkit.filters.gaps import (
    HANDLER_NAMES,
    Coast,
    GapHandler,
    GapMemory,
    GapRun,
    HoldLast,
    MeanOfLast,
    PolynomialFit,
    SineFit,
    gap_and_after,
    make_handler,
    mask_by_count,
    mask_by_samples,
    mask_by_time,
    measurement_times,
    run_with_gaps,
    union,
)
from trackkit.filters.imm import IMM, IMMBelief
from trackkit.filters.initialise import dbt_prior_cov, ga_initial_position, ga_prior
from trackkit.filters.jtc import JTC, JTCBelief, MultiFilterBelief, MultiFilterJTC
from trackkit.filters.kalman import EKF, IEKF, KF
from trackkit.filters.maneuver import (
    DetectorRun,
    DetectorState,
    FadingMemoryDetector,
    NISDetector,
    PInflation,
    QInflation,
    ScaledNoise,
    VariableOrderRun,
    WindowDetector,
    WindowState,
    chi2_threshold,
    fading_memory,
    fading_threshold,
    inflate_p,
    inflate_q,
    run_variable_order,
    run_with_detector,
    weighted_chi2_sf,
)
from trackkit.filters.particle import PF
from trackkit.filters.run import run_filter
from trackkit.filters.sigma import CKF, SRCKF, UKF, SigmaPoints
from trackkit.filters.smoothers import smooth

__all__ = [
    "KF", "EKF", "IEKF", "UKF", "CKF", "SRCKF", "PF", "JTC", "JTCBelief", "MultiFilterJTC",
    "MultiFilterBelief", "RPEKF", "RangeBankBelief", "MPEKF", "MPBelief", "RangePF",
    "PendingParticles", "AlphaBeta", "AlphaBetaGamma", "AlphaBetaBelief", "IMM", "IMMBelief",
    "MCEKF", "AMCEKF", "AEKF", "AdaptiveBelief", "SageHusaBelief", "FuzzyAdaptive",
    "FuzzyBelief", "SigmaPoints", "smooth", "run_filter", "ga_initial_position", "ga_prior",
    "dbt_prior_cov", "HANDLER_NAMES", "Coast", "GapHandler", "GapMemory", "GapRun", "HoldLast",
    "MeanOfLast", "PolynomialFit", "SineFit", "gap_and_after", "make_handler", "mask_by_count",
    "mask_by_samples", "mask_by_time", "measurement_times", "run_with_gaps", "union",
    "DetectorRun", "DetectorState", "FadingMemoryDetector", "NISDetector", "PInflation",
    "QInflation", "ScaledNoise", "VariableOrderRun", "WindowDetector", "WindowState",
    "chi2_threshold", "fading_memory", "fading_threshold", "inflate_p", "inflate_q",
    "run_variable_order", "run_with_detector", "weighted_chi2_sf",
]
