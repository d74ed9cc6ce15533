"""trackkit: target tracking and state estimation on one batched core.

    import trackkit as tk
    b = tk.Gaussian(mean, cov)
    b = tk.filters.EKF().predict(b, tk.models.ConstantVelocity(dim=2, q=0.01), dt)
"""

from trackkit import angles, filters, linalg, models, optimize
from trackkit.belief import Gaussian, Innovation, check_gaussian

__version__ = "0.1.0"

__all__ = [
    "Gaussian",
    "Innovation",
    "check_gaussian",
    "angles",
    "linalg",
    "models",
    "filters",
    "optimize",
]
