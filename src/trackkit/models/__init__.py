"""Motion and sensor models."""

from trackkit.models import classes
from trackkit.models.discretize import discretize
from trackkit.models.motion import (
    Augmented,
    ConstantAcceleration,
    ConstantVelocity,
    ContinuousLinear,
    CoordinatedTurn,
    KnownTurnRate,
    LinearMotion,
    MotionBase,
    MotionModel,
    RandomSine,
    Singer,
)
from trackkit.models.noise import with_noise
from trackkit.models.sensors import (
    AzimuthElevation,
    Bearing,
    BearingFrequency,
    MultipathDelay,
    Position,
    RangeBearing,
    SensorBase,
    SensorModel,
    Sine,
    Stack,
)

__all__ = [
    "classes",
    "discretize",
    "MotionModel",
    "MotionBase",
    "LinearMotion",
    "ContinuousLinear",
    "ConstantVelocity",
    "ConstantAcceleration",
    "Singer",
    "KnownTurnRate",
    "CoordinatedTurn",
    "RandomSine",
    "Augmented",
    "SensorModel",
    "SensorBase",
    "Position",
    "Bearing",
    "RangeBearing",
    "AzimuthElevation",
    "BearingFrequency",
    "MultipathDelay",
    "Sine",
    "Stack",
    "with_noise",
]
