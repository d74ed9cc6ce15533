"""trackkit: target tracking and state estimation on one batched core.

    import trackkit as tk
    b = tk.Gaussian(mean, cov)
    b = tk.filters.EKF().predict(b, tk.models.ConstantVelocity(dim=2, q=0.01), dt)
    tk.tracking.gate(zhat, S, z)       # the multi-target front end
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

__all__ = ["Gaussian", "Particles", "Innovation", "check_gaussian", "angles", "linalg", "models",
           "filters", "optimize", "tracking", "network", "belief", "eval", "io", "sim",
           "identify", "scenario", "experiments", "report"]

# Submodules load on first use (PEP 562): the command line starts, and answers Ctrl-C, before
# numpy and scipy are imported, and tk.tracking's scipy.stats and KD-tree cost nothing until
# they are used.
_SUBMODULES = {"angles", "linalg", "models", "filters", "optimize", "tracking", "network",
               "belief", "eval", "io", "sim", "identify", "scenario", "experiments", "report"}
_FROM_BELIEF = {"Gaussian", "Particles", "Innovation", "check_gaussian"}

if TYPE_CHECKING:  # the layers above experiments stay out: they import trackkit themselves
    from trackkit import (
        angles,
        belief,
        eval,
        filters,
        identify,
        io,
        linalg,
        models,
        network,
        optimize,
        sim,
        tracking,
    )
    from trackkit.belief import Gaussian, Innovation, Particles, check_gaussian


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"trackkit.{name}")
    if name in _FROM_BELIEF:
        return getattr(importlib.import_module("trackkit.belief"), name)
    raise AttributeError(f"module 'trackkit' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
