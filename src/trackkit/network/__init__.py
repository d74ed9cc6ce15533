"""Decentralised cooperative tracking (Jalalipoor and Kardehi Moghaddam 2021).

The agents' program and an in-process network run (:mod:`~trackkit.network.agents`,
:mod:`~trackkit.network.inprocess`), built on composite measurements from asynchronous bearings
(:mod:`~trackkit.network.composite`), diffusion Kalman filtering over a network of agents
(:mod:`~trackkit.network.diffusion`), randomised initiation from bearings
(:mod:`~trackkit.tracking.initiate`), the agents' course control
(:mod:`~trackkit.network.steering`), and tracks across agents: similarity, matching,
duplicate pruning and the memory of neighbours' messages (:mod:`~trackkit.network.tracks`).
"""

from trackkit.network.agents import (
    PAYLOAD_VERSION,
    Agent,
    AgentSettings,
    BearingSet,
    Payload,
)
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
from trackkit.network.inprocess import NetworkResult, Trace, run_network
from trackkit.network.steering import (
    TURN_RATE,
    CourseCommand,
    Steering,
    admissible_courses,
    blend_courses,
    move,
    steer,
    swarm_neighbours,
)
from trackkit.network.tracks import (
    DEFAULT_GATE,
    Matches,
    Message,
    MessageMemory,
    duplicates,
    match_tracks,
    similarity,
    uncertainty,
)

__all__ = [
    "PAYLOAD_VERSION",
    "Agent",
    "AgentSettings",
    "BearingSet",
    "Payload",
    "NetworkResult",
    "Trace",
    "run_network",
    "COMBINATIONS",
    "CONVERGED",
    "DEFAULT_GATE",
    "TURN_RATE",
    "CourseCommand",
    "Steering",
    "admissible_courses",
    "blend_courses",
    "move",
    "steer",
    "swarm_neighbours",
    "Matches",
    "Message",
    "MessageMemory",
    "duplicates",
    "match_tracks",
    "similarity",
    "uncertainty",
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
