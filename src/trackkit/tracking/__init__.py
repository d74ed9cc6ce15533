"""Multi-target tracking front end: scans, gating, association, track logic, initiation.

Typical use::

    from trackkit import tracking as tt
    g = tt.gate(zhat, S, z, p_gate=0.99)                 # KD-tree pre-gate, batched fine test
    a = tt.gnn_assign(g, tt.loglik_costs(g, pd=0.9, clutter_density=1e-6))
    # or r = tt.jpda_probabilities(g, pd=0.9, clutter_density=1e-6): the marginals beta_ij
    logic = tt.HistoryLogic(confirm=(2, 3), delete=(3, 3))   # M-of-N, or tt.ScoreLogic
    new = tt.single_point(z[a.unassigned], R, v_max=30.0)     # or two_point, converted plots

    tracker = tt.Tracker(tk.filters.EKF(), motion, radar, pd=0.9, clutter_density=lam,
                         associator=tt.JPDA(), logic=logic, initiator=tt.TwoPoint(v_max=40))
    tracks = tracker.init()
    for scan in scans:                   # all live tracks are one batched belief
        tracks = tracker.step(tracks, scan)
"""

from trackkit.tracking.association import (
    BATCH_MAX_EVENTS,
    BATCH_MAX_TRACKS,
    GNN_DENSE_MAX_CELLS,
    JPDA_MAX_EVENTS,
    Assignment,
    Clusters,
    Costs,
    JPDAResult,
    clusters,
    distance_costs,
    gnn_assign,
    jpda_probabilities,
    loglik_costs,
    pda_costs,
    saturating_costs,
)
from trackkit.tracking.gating import (
    GATE_PROBABILITY,
    KDTREE_MIN_PAIRS,
    Gate,
    MeasurementPrediction,
    gate,
    gate_pairs,
    gate_threshold,
    predict_measurement,
)
from trackkit.tracking.initiate import (
    convert_range_bearing,
    converted_cov_given_truth,
    pair_plots,
    single_point,
    two_point,
)
from trackkit.tracking.logic import (
    HistoryLogic,
    HistoryState,
    IdCounter,
    ScoreLogic,
    ScoreState,
    TimerLogic,
    TimerState,
    TrackStatus,
    concatenate,
    confirmed,
    lost,
    select,
    sprt_thresholds,
    tentative,
    to_delete,
)
from trackkit.tracking.tracker import (
    GNN,
    JPDA,
    SinglePoint,
    StepInfo,
    Tracker,
    Tracks,
    TwoPoint,
)

__all__ = [
    "BATCH_MAX_EVENTS", "BATCH_MAX_TRACKS",
    "GNN_DENSE_MAX_CELLS", "JPDA_MAX_EVENTS", "Assignment", "Clusters", "Costs", "JPDAResult",
    "clusters",
    "distance_costs", "gnn_assign", "jpda_probabilities", "loglik_costs",
    "pda_costs", "saturating_costs",
    "GATE_PROBABILITY", "KDTREE_MIN_PAIRS", "Gate", "MeasurementPrediction", "gate", "gate_pairs",
    "gate_threshold", "predict_measurement",
    "convert_range_bearing", "converted_cov_given_truth", "pair_plots", "single_point",
    "two_point",
    "HistoryLogic", "HistoryState", "IdCounter", "ScoreLogic", "ScoreState", "TimerLogic",
    "TimerState", "TrackStatus", "lost",
    "concatenate", "confirmed", "select", "sprt_thresholds",
    "tentative", "to_delete",
    "GNN", "JPDA", "SinglePoint", "StepInfo", "Tracker", "Tracks", "TwoPoint",
]

#: functions renamed to say what they do (not only the case tells them from GNN and JPDA)
_RENAMED = {"gnn": "gnn_assign", "jpda": "jpda_probabilities", "seed004_costs": "saturating_costs"}


def __getattr__(name: str):
    if name in _RENAMED:
        raise AttributeError(f"trackkit.tracking.{name} is now spelled {_RENAMED[name]}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
