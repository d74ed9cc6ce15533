"""Identification of the vessel model of Zolfagharnasab and Seif (2025): the 16
coefficients of ``trackkit.models.manoeuvring`` from sea-trial data.

* ``programme``: the trial programme that generates identification data (batched, seeded
  per run), with the discrete (``substeps=1``) or near-continuous truth;
* ``identify``: EKF, UKF, CKF or square-root CKF on the augmented state ``[u, v, r, theta]``
  over a record, with the per-sample history of every coefficient and its standard deviation;
* ``least_squares``: the batch equation-error baseline (linear in theta);
* ``predict``, ``dead_reckon``, ``position_error``: open-loop prediction with an identified
  model and tracks from filtered body states.
"""

from trackkit.identify.augmented import (
    DEFAULT_Q_BODY,
    DEFAULT_SUBSTEPS,
    METHODS,
    Q_BODY_SAMPLED_INPUTS,
    SUBSTEPS_SAMPLED_INPUTS,
    Identification,
    SampledVessel,
    coefficient_nees,
    identify,
    initial_guess,
    relative_error,
    settling_step,
)
from trackkit.identify.least_squares import EQUATIONS, LeastSquaresFit, least_squares
from trackkit.identify.prediction import Prediction, dead_reckon, position_error, predict, rmse
from trackkit.identify.programme import (
    DEFAULT_NOISE,
    DEFAULT_PROGRAMME,
    NoiseLevels,
    Record,
    Segment,
    TrialSpec,
    programme,
    run_seed,
)

__all__ = [
    "DEFAULT_NOISE",
    "DEFAULT_PROGRAMME",
    "DEFAULT_Q_BODY",
    "DEFAULT_SUBSTEPS",
    "METHODS",
    "EQUATIONS",
    "Identification",
    "LeastSquaresFit",
    "NoiseLevels",
    "Q_BODY_SAMPLED_INPUTS",
    "SUBSTEPS_SAMPLED_INPUTS",
    "Prediction",
    "Record",
    "SampledVessel",
    "Segment",
    "TrialSpec",
    "coefficient_nees",
    "dead_reckon",
    "identify",
    "initial_guess",
    "least_squares",
    "position_error",
    "predict",
    "programme",
    "relative_error",
    "rmse",
    "run_seed",
    "settling_step",
]
