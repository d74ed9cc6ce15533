"""Tracking recorded data, from Python as ``trackkit track`` does it from the command line.

AIS or ADS-B position reports are tracked through a virtual radar (plots of the reported
positions, the reports kept as the truth to score against); a detections file's plots are
tracked as they are::

    from trackkit.io import samples
    from trackkit.tracking.recorded import TrackOptions, track_recording

    result = track_recording(samples.path("solent-ais"),
                             TrackOptions(as_radar=True, max_scans=20))
    result.history  # the tracker's history, as trackkit track writes it to tracks.parquet
    result.smoothed  # the tracks RTS-smoothed (tracking.smoothing), written beside them

The tracker of AIS and ADS-B plots is an IMM (nearly constant velocity and coordinated turn,
Blom and Bar-Shalom 1988) of EKFs or UKFs with GNN or JPDA association, two-point initiation
and a track score (Blackman and Popoli 1999) whose deletion allows for a few missed scans;
a detections file gets a constant-velocity filter, single-point initiation and Wald's SPRT
thresholds. The numbers are per input kind (``TRACK_PROFILES``, where each is justified).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from trackkit.io import read_header

if TYPE_CHECKING:
    from trackkit.sim.virtual_radar import VirtualRadar

__all__ = ["DEFAULT_SAMPLE", "SINGLE_MODEL_Q", "TRACKER_REASONS", "TRACK_PROFILES", "Recording",
           "TrackOptions", "TrackProfile", "TrackingResult", "build_tracker", "open_recording",
           "profile_radar", "sample_sentence", "track_recording"]

Kind = Literal["ais", "opensky", "detections"]
#: scans of plots after each estimate that smooth it: an IMM's estimates smoothed with one of
#: its models (``smoothing_model``) let the backward pass drift over the thousands of scans
#: of a moored vessel (on the whole Solent file, fixed-interval: 46 km RMSE; a lag of 20: the
#: smoothed tracks closer to the reports than the filtered)
SMOOTHING_LAG = 20
#: ``progress(stage, done, total)``: stage "reading" (bytes) or "tracking" (scans)
Progress = Callable[[str, float, float], None]


@dataclass(frozen=True)
class TrackProfile:
    """The radar, tracker and scoring numbers of one kind of input (None: not used by it).

    ``turn_q`` None gives a constant-velocity filter, else an IMM of nearly constant velocity
    and coordinated turn (the CT model's acceleration noise is ``manoeuvre_q``, by default
    ``q``); ``misses`` None
    deletes a track at Wald's SPRT threshold (alpha 0.01, beta 0.001: three missed scans at
    pd 0.9), else after ``misses + 1`` consecutive missed scans, or with ``hold`` (s) holds
    it there, unseen, for a new track within ``rejoin`` (m) to continue (and while its
    position std is within ``regain`` (m) lets it take plots no other track gates);
    ``v_max`` None starts a track at every unassigned plot (single point, velocity std
    ``v_std``), else from two plots of consecutive scans closer than ``v_max dt`` plus three
    standard deviations of the plots' separation at the edge of the radar's range (two-point
    differencing)."""

    period: float | None = None  # scan period of the virtual radar (s)
    sigma_range: float | None = None  # range noise std (m)
    sigma_bearing_deg: float | None = None  # bearing noise std (deg)
    sigma_pos: float | None = None  # position noise std of x, y detections (m)
    pd: float | None = None  # detection probability
    clutter: float | None = None  # false plots per scan
    max_range: float | None = None  # instrumented range (m)
    min_range: float | None = None  # blind range (m)
    q: float | None = None  # process noise of the constant-velocity model (m^2/s^3)
    v_std: float | None = None  # velocity std of a new track, single-point initiation (m/s)
    gospa_c: float | None = None  # GOSPA cut-off (m)
    turn_q: float | None = None  # turn-rate noise of the coordinated-turn model (rad^2/s^3)
    turn_std_deg: float | None = None  # turn-rate std of a new track (deg/s)
    manoeuvre_q: float | None = None  # acceleration noise of the CT model (m^2/s^3; None: q)
    misses: float | None = None  # consecutive missed scans a track coasts through
    v_max: float | None = None  # top speed for two-point initiation (m/s)
    hold: float | None = None  # time a lost track is held, unseen, for a new one to continue
    rejoin: float | None = None  # how near a new track must be to a held one to continue it (m)
    regain: float | None = None  # position std up to which a held track takes plots (m)


#: defaults per input: a coastal marine radar over AIS traffic, an en-route air surveillance
#: radar over ADS-B, a generic tracker for a detections file (the plots are as recorded).
#: Why the tracker's numbers (checked on the Solent AIS and OpenSky recordings over ten radar
#: seeds, benchmarks/recorded_defaults.py):
#:
#: - ``q``, ``manoeuvre_q``: the IMM has a quiet mode and a manoeuvring one. A vessel on a
#:   steady course or moored changes its speed by a few tenths of a m/s over a minute (the
#:   CV model's q 0.0025 m^2/s^3: 0.39 m/s of velocity std per minute, so a moored vessel's
#:   track settles on it rather than wandering among its neighbours); one stopping, going
#:   astern or turning hard changes it by a m/s within a scan or two (the CT model's
#:   acceleration noise 0.5 m^2/s^3: 1.2 m/s per 3 s scan). With one q for both (0.05, the
#:   single-model compromise, ``SINGLE_MODEL_Q``) tracks lagged behind decelerating vessels,
#:   lost them and broke: half of the Solent breaks (17 of 34, seed 0) came a scan or two
#:   after the vessel's last scan on its old track, six of them traced to lag behind a stop
#:   or a turn. An airliner's speed changes by a few m/s in either mode
#:   (100 m^2/s^3).
#: - ``turn_q``, ``turn_std_deg``: turns are the CT model's. A ship's rate of turn is at
#:   most a few deg/s (a new track's std 2 deg/s) and builds up over tens of seconds after a
#:   rudder order (1e-5 rad^2/s^3: 0.3 deg/s per 3 s scan); an airliner turns at up to the
#:   standard rate of 3 deg/s (std 1.5 deg/s), rolling in within a few seconds (1e-4
#:   rad^2/s^3: 1.8 deg/s per 10 s scan).
#: - ``misses``: a track is shown coasting while its object is more likely missed than gone.
#:   At pd 0.9 an object still there misses k scans in a row with probability 0.1^k; an
#:   object's reports end about once in a thousand scans (some 120 ends in the Solent hour's
#:   10^5 vessel-scans), so after k misses it is still there with probability 0.1^k /
#:   (0.1^k + k 1e-3): 0.99, 0.81, 0.22 for k = 1, 2, 3. Shown through 2 missed scans (6 s
#:   for a vessel; 20 s, 5 km at 250 m/s, for an aircraft), then held.
#: - ``regain``: a held vessel track whose position is still known to within 100 m (its
#:   first scans unseen) takes a plot no other track gates and is shown again once
#:   its score recovers: a vessel missed three scans in a row (once in a thousand scans) is
#:   not lost for the scans a new track would take to confirm. An aircraft's position is
#:   known no better than a few km after two missed 10 s scans: no regain, only rejoin.
#: - ``hold``, ``rejoin``: a vessel's AIS reports stop for minutes (a receiver's shadow, a
#:   transponder off at a berth: gaps of 10 to 40 min in the Solent hour, an aircraft's for up
#:   to a few minutes), and the radar, made from the reports, loses it. Its lost track is held
#:   1 h, longer than those gaps (30 min: 24.5 breaks in the Solent file per radar seed
#:   against 22.1; 5 min for an aircraft), and a new track confirmed within 500 m of its
#:   prediction (10 km: 40 s of flight) and agreeing in position and velocity continues it
#:   under its ID.
#:   Held tracks are not shown (and past ``regain`` take no plot), so holding longer costs
#:   no false track.
#: - ``v_max``: two plots of consecutive scans start a track only if they are no farther
#:   apart than the fastest traffic moves (20 m/s, 39 kn: fast ferries and small craft; 350
#:   m/s for aircraft): among closely packed slow vessels and 10 false plots a scan, this is
#:   what keeps clutter from starting tracks. Confirmation waits one scan longer.
TRACK_PROFILES: dict[str, TrackProfile] = {
    "ais": TrackProfile(period=3.0, sigma_range=20.0, sigma_bearing_deg=0.5, pd=0.9,
                        clutter=10.0, max_range=40e3, min_range=50.0, q=0.0025, v_std=10.0,
                        gospa_c=500.0, turn_q=1e-5, turn_std_deg=2.0, manoeuvre_q=0.5,
                        misses=2.0, v_max=20.0, hold=3600.0, rejoin=500.0, regain=100.0),
    "opensky": TrackProfile(period=10.0, sigma_range=50.0, sigma_bearing_deg=0.1, pd=0.9,
                            clutter=10.0, max_range=400e3, min_range=500.0, q=100.0,
                            v_std=150.0, gospa_c=2000.0, turn_q=1e-4, turn_std_deg=1.5,
                            misses=2.0, v_max=350.0, hold=300.0, rejoin=10e3),
    "detections": TrackProfile(sigma_range=20.0, sigma_bearing_deg=0.5, sigma_pos=20.0, pd=0.9,
                               clutter=10.0, q=1.0, v_std=50.0, gospa_c=1000.0),
}

#: the process noise (m^2/s^3) of one constant-velocity model that must cover quiet and
#: manoeuvring motion alike, the single-model compromise: both of the AIS IMM's models had
#: it before the quiet and the manoeuvring modes, and a single-model tracker compared with
#: the IMM takes it (benchmarks/)
SINGLE_MODEL_Q: dict[str, float] = {"ais": 0.05, "opensky": 100.0}


#: the reasons for each kind's tracker, in words, for the report (the comment above in full)
TRACKER_REASONS: dict[str, str] = {
    "ais": "Vessels turn, stop and lie moored in clusters: the IMM's quiet constant-velocity "
           "model keeps a moored or steady vessel's track still, and its manoeuvring "
           "coordinated-turn model follows a turn or a stop that the quiet model would lose; "
           "two plots of "
           "consecutive scans no farther apart than 20 m/s (39 kn) allows start a track, so "
           "the false plots seldom do; a track is shown coasting through 2 missed scans (6 "
           "s): after a third in a row its vessel is more likely gone than missed at pd 0.9. "
           "It is then held unseen for an hour, since AIS reports stop for minutes: a "
           "plot near it takes it up again while its position is known to within 100 m, "
           "and later a new track within 500 m of it continues it under its ID.",
    "opensky": "Aircraft fly straight legs and standard-rate turns (3 deg/s): the IMM's "
               "coordinated-turn model follows the turns; two plots no farther apart than "
               "350 m/s allows start a track; a track coasts through 2 missed scans (20 s, "
               "5 km at 250 m/s), beyond which the prediction leaves the gate; a lost track "
               "is held unseen for 5 minutes, and a new track within 10 km of it continues it "
               "under its ID.",
    "detections": "Nothing is known of the objects: a constant-velocity filter, a track at "
                  "every unassigned plot and Wald's SPRT thresholds.",
}


@dataclass(frozen=True)
class TrackOptions:
    """What ``trackkit track`` takes besides the file (its options, same names and meaning;
    ``profile`` holds the numbers given, the rest from the input kind's ``TRACK_PROFILES``)."""

    fmt: Kind | None = None  # None: guessed from the columns
    as_radar: bool = False
    columns: str | None = None  # KEY=NAME,... (--columns)
    units: str | None = None  # KEY=VALUE,... (--units)
    site_lat: float | None = None
    site_lon: float | None = None
    profile: TrackProfile = field(default_factory=TrackProfile)
    max_gap: float | None = None
    seed: int = 0
    associator: Literal["gnn", "jpda"] = "gnn"
    filter: Literal["ekf", "ukf"] = "ekf"
    on_bad: Literal["skip", "stop"] = "skip"
    until: float | None = None
    max_scans: int | None = None

    def settings(self, kind: str) -> TrackProfile:
        """The numbers given, else the input kind's defaults."""
        given = {f.name: float(v) for f in fields(TrackProfile)
                 if (v := getattr(self.profile, f.name)) is not None}
        return replace(TRACK_PROFILES[kind], **given)


@dataclass(frozen=True)
class Recording:
    """A recorded file checked against the options, before any data is read."""

    path: Path
    kind: Kind
    header: list[str]
    options: TrackOptions
    settings: TrackProfile
    layout: str = ""  # the recognised layout (trackkit.io.LAYOUTS), "" for --columns


@dataclass
class TrackingResult:
    """The tracks of a recording and what the report is made of."""

    recording: Recording
    history: Any  # tracking.history.TrackHistory
    read: Any  # the reader's ReadReport
    scans: Any  # the tracked Scans
    sensor: Any
    frame: Any  # io.EnuFrame or None (x, y as in a detections file)
    truth: Any  # the reported positions at the scan times, or None
    site: tuple[float, float] | None
    max_range: float | None
    background: Any  # the positions or plots drawn behind the tracks
    background_label: str
    config: dict[str, Any]
    notes: list[str]
    plots: int
    objects: int | None = None
    seen: int | None = None
    smoothed: Any = None  # tracking.smoothing.SmoothedTracks, row for row with the history
    object_ids: Any = None  # the MMSI or icao24 of each object code of truth.ids


#: what ``trackkit track`` tracks when given no file (as radar plots)
DEFAULT_SAMPLE = "solent-ais"


def sample_sentence(name: str) -> str:
    """What ``trackkit track`` says first when it runs on a bundled sample by default."""
    from trackkit.io import samples

    return (f"No file given: tracking the sample shipped with trackkit, {name}: "
            f"{samples.SAMPLES[name][1]}. Its positions go through a virtual radar, as with "
            f"trackkit track {name} --as-radar.")


def resolve_input(file: Path) -> Path:
    """The file, else the bundled sample of that name (a file of that name comes first)."""
    from trackkit.io import samples

    if not file.exists() and str(file) in samples.SAMPLES:
        return samples.path(str(file))
    if not file.is_file():
        what = "is not a file" if file.exists() else "no such file"
        raise ValueError(f"{file}: {what}; expected a detections, AIS or OpenSky file, or a "
                         f"bundled sample ({', '.join(samples.SAMPLES)})")
    return file


def guess_format(path: Path, header: list[str], columns: bool = True) -> Kind:
    """The input's kind from its columns: AIS (MMSI), OpenSky (icao24) or detections; an AIS
    or OpenSky file in no known layout only with a column mapping (``columns``)."""
    from trackkit.io.layouts import expected_layouts

    names = {h.strip().lower() for h in header}
    if columns and "mmsi" in names:
        return "ais"
    if columns and "icao24" in names:
        return "opensky"
    if "time" in names and ({"x", "y"} <= names or {"range", "bearing"} <= names):
        return "detections"
    raise ValueError(f"{path}: not a layout trackkit knows (first line: columns "
                     f"{', '.join(map(repr, header[:12]))}); expected {expected_layouts()}; or "
                     "detections (time with x, y or range, bearing); for other columns pass "
                     "--format ais|opensky|detections with --columns")


def open_recording(path: Path | str, options: TrackOptions) -> Recording:
    """``path`` (or a bundled sample's name) with its kind, checked against the options."""
    from trackkit.io import recognise

    file = resolve_input(Path(path))
    parquet = file.suffix.lower() in (".parquet", ".pq")
    layout = None if options.columns or parquet else recognise(file)
    # NMEA and SBS-1 lines have no header
    header = [] if layout is not None and not layout.columns else read_header(file)
    if layout is not None and options.fmt not in (None, layout.kind):
        layout = None  # the kind the user names wins; read as that kind with --columns
    kind = options.fmt or (layout.kind if layout is not None else
                           guess_format(file, header, columns=bool(options.columns)))
    if kind != "detections" and not options.as_radar:
        raise ValueError(f"{file}: {kind} position reports are tracked through a "
                         "virtual radar; add --as-radar (trackkit track --help lists the "
                         "radar options)")
    if kind == "detections" and options.as_radar:
        raise ValueError(f"{file}: --as-radar makes plots of AIS or ADS-B reports; a "
                         "detections file holds plots already, tracked as they are (drop "
                         "--as-radar)")
    if (options.site_lat is None) != (options.site_lon is None):
        raise ValueError("--site-lat and --site-lon: give both or neither")
    if options.units and kind != "detections":
        raise ValueError(f"--units is for detections files; {file} is {kind}")
    return Recording(file, kind, header, options, options.settings(kind),
                     layout.name if layout is not None else "")


def track_recording(source: Path | str | Recording, options: TrackOptions | None = None,
                    progress: Progress | None = None) -> TrackingResult:
    """Read a recording, make the virtual radar's plots (AIS, ADS-B) or take its detections,
    and track them: what ``trackkit track`` writes and scores."""
    rec = source if isinstance(source, Recording) else open_recording(
        source, options or TrackOptions())
    report = progress or (lambda stage, done, total: None)
    report("reading", 0, max(rec.path.stat().st_size, 1))
    data, read, polar = _read_input(rec, lambda done, total: report("reading", done, total))
    job = (_detections_job(rec, data, read, polar) if rec.kind == "detections"
           else _radar_job(rec, data, read))
    s = rec.settings
    tracker, desc = build_tracker(job["sensor"], s, job.pop("clutter_density"),
                             rec.options.associator, rec.options.filter)
    desc["gospa_c_m"] = s.gospa_c
    desc["why"] = TRACKER_REASONS[rec.kind]
    job["config"]["tracker"] = desc
    from trackkit.tracking.history import run_tracker

    n = len(job["scans"])
    report("tracking", 0, n)
    history, _ = run_tracker(tracker, job["scans"],
                             progress=lambda done: report("tracking", done, n))
    smoothed = _smooth(tracker, history, desc)
    return TrackingResult(recording=rec, history=history, read=read, smoothed=smoothed, **job)


def _smooth(tracker: Any, history: Any, desc: dict[str, Any]) -> Any:
    """The tracks RTS-smoothed (``tracking.smoothing``), the smoother described in ``desc``."""
    import numpy as np

    from trackkit.tracking.smoothing import smooth_tracks, smoothing_model

    period = float(np.median(np.diff(history.times))) if history.times.size > 1 else 1.0
    motion, filt, dims = smoothing_model(tracker, period)
    desc["smoother"] = (f"Rauch-Tung-Striebel with a fixed lag of {SMOOTHING_LAG} scans, "
                        f"{type(motion).__name__} model")
    return smooth_tracks(history, motion, filt, dims, lag=SMOOTHING_LAG)


def _mapping(text: str | None, option: str, allowed: tuple[str, ...]) -> dict[str, str | None]:
    """``KEY=VALUE,KEY=VALUE`` (a value ``none`` is None), keys checked against ``allowed``."""
    out: dict[str, str | None] = {}
    if not text:
        return out
    for item in text.split(","):
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise ValueError(f"{option} {text!r}: {item!r} is not KEY=VALUE; expected e.g. "
                             f"{option} {allowed[0]}=NAME,{allowed[1]}=NAME")
        if key not in allowed:
            raise ValueError(f"{option}: {key!r} is not a known key; expected one of "
                             f"{', '.join(allowed)}")
        out[key] = None if value.lower() == "none" else value
    return out


def _read_input(rec: Recording, progress: Callable[[float, float], None]
                ) -> tuple[Any, Any, bool]:
    """(Reports or Scans, ReadReport, whether the detections are range-bearing plots)."""
    from trackkit import io as tio

    path, columns, o = rec.path, rec.options.columns, rec.options
    kw = dict(on_bad=o.on_bad, progress=progress, max_listed=100_000)
    if rec.layout:
        return (*tio.read_recording(path, rec.layout, **kw), False)
    if rec.kind == "ais":
        keys = tuple(f.name for f in fields(tio.AisColumns))
        cols = tio.AisColumns(**_mapping(columns, "--columns", keys))
        return (*tio.read_ais_csv(path, cols, **kw), False)
    if rec.kind == "opensky":
        if columns:
            raise ValueError("--columns: the OpenSky reader uses OpenSky's own column names "
                             "(time, icao24, lat, lon, ...); use --format ais with --columns "
                             "for another layout of position reports")
        return (*tio.read_opensky_csv(path, **kw), False)
    given = _mapping(columns, "--columns",
                     ("time", "sensor", "x", "y", "z", "range", "bearing"))
    names = {h.strip().lower(): h.strip() for h in rec.header}
    if not given and "range" in names and "bearing" in names and "x" not in names:
        given = {"range": names["range"], "bearing": names["bearing"]}
    if "sensor" not in given and "sensor" not in names:
        given["sensor"] = None  # every plot from one sensor
    un = tio.DetectionUnits(**_mapping(o.units, "--units", ("distance", "angle", "bearing",
                                                            "time")))
    dc = tio.DetectionColumns(**given)
    return (*tio.read_detections(path, dc, un, **kw), dc.polar)


#: the IMM's probability of switching between its models from one scan to the next: a mean
#: 20 scans in a mode (a minute for a vessel, three for an aircraft: a turn, or a leg)
IMM_SWITCH = 0.05
#: the IMM's mode probabilities of a new track (most traffic is going straight)
IMM_MU0 = (0.95, 0.05)


def build_tracker(sensor: Any, s: TrackProfile, clutter_density: float, associator: str,
             filt: str) -> tuple[Any, dict[str, Any]]:
    """The tracker of ``trackkit track`` for the settings ``s``, and its description for the
    report."""
    from trackkit.filters import EKF, UKF
    from trackkit.tracking import GNN, JPDA, Tracker

    f = EKF() if filt == "ekf" else UKF()
    filt_, motion, extra, motion_desc = _motion(f, s)
    logic, logic_desc = _logic(s, clutter_density)
    initiator, init_desc = _initiator(sensor, s)
    tracker = Tracker(filt_, motion, sensor, pd=s.pd, clutter_density=clutter_density,
                      associator=GNN() if associator == "gnn" else JPDA(),
                      logic=logic, initiator=initiator, **extra,
                      rejoin_within=math.inf if s.rejoin is None else float(s.rejoin),
                      regain_within=float(s.regain or 0.0))
    unit = "per_m_rad" if hasattr(sensor, "sigma_bearing") else "per_m2"
    desc = {"filter": filt.upper(), **motion_desc, "associator": associator.upper(),
            "gate": "the filter's own innovation covariance (the IMM's: its models' mixture)",
            **logic_desc, **init_desc, "pd_assumed": s.pd,
            f"clutter_density_{unit}": clutter_density,
            "new_target_density": logic.new_target_density}
    return tracker, desc


def _motion(f: Any, s: TrackProfile) -> tuple[Any, Any, dict[str, Any], dict[str, Any]]:
    """The filter and motion model: CV, or the IMM of CV and CT (``s.turn_q``; the CT
    model's acceleration noise ``s.manoeuvre_q``, by default ``s.q``)."""
    from trackkit.filters import IMM
    from trackkit.models import ConstantVelocity, CoordinatedTurn

    if s.turn_q is None:
        return f, ConstantVelocity(dim=2, q=s.q), {}, {"motion": "constant velocity",
                                                        "q_m2_s3": s.q}
    p = IMM_SWITCH
    q_turn = s.q if s.manoeuvre_q is None else s.manoeuvre_q
    imm = IMM([ConstantVelocity(dim=2, q=s.q), CoordinatedTurn(q=q_turn, q_omega=s.turn_q)],
              f, [[1 - p, p], [p, 1 - p]], mu0=IMM_MU0)
    omega_std = math.radians(s.turn_std_deg if s.turn_std_deg is not None else 1.0)
    desc = {"motion": "IMM of nearly constant velocity and coordinated turn",
            "q_m2_s3": s.q, "turn_model_q_m2_s3": q_turn,
            "turn_rate_noise_rad2_s3": s.turn_q,
            "initial_turn_rate_std_deg_s": math.degrees(omega_std),
            "model_switch_probability_per_scan": p}
    return imm, None, {"extra_mean": (0.0,), "extra_std": (omega_std,)}, desc


def _logic(s: TrackProfile, clutter_density: float) -> tuple[Any, dict[str, Any]]:
    """The track score: confirmed at Wald's SPRT threshold (alpha 0.01, beta 0.001), deleted
    at it too, or after ``s.misses + 1`` consecutive missed scans:

        T_delete = (misses + 1/2) ln(1 - pd)

    below the score's maximum (each miss adds ln(1 - P_D)); with ``s.hold`` a confirmed track
    is held (not shown) rather than deleted there, until ``hold / period`` more misses:

        T_hold = T_delete + (hold / period) ln(1 - pd)."""
    from trackkit.tracking import ScoreLogic

    # one new object per hundred false plots: a track is confirmed after two or three hits
    birth = clutter_density / 100
    logic = ScoreLogic.from_sprt(alpha=1e-2, beta=1e-3, pd=s.pd,
                                 clutter_density=clutter_density, new_target_density=birth)
    if s.misses is None:
        rule = "SPRT track score, alpha 0.01, beta 0.001"
    else:
        logic = replace(logic, delete_threshold=(float(s.misses) + 0.5) * math.log1p(-s.pd))
        rule = (f"track score, confirmed at the SPRT threshold (alpha 0.01), deleted after "
                f"{int(s.misses) + 1} consecutive missed scans")
    text = (f"{rule}: confirmed at a score of {logic.confirm_threshold:.3g}, deleted at a drop "
            f"of {-logic.delete_threshold:.3g} below its maximum")
    if s.hold and s.period and s.misses is not None:
        scans = round(s.hold / s.period)
        logic = replace(logic, hold_threshold=logic.delete_threshold
                        + scans * math.log1p(-s.pd))
        near = "" if s.rejoin is None else f" within {s.rejoin:g} m"
        text += (f"; a confirmed track is not deleted there but held, unseen, for {scans} "
                 f"more missed scans ({s.hold:g} s), and a new track confirmed{near} of it "
                 "and agreeing with it in position and velocity continues it under its ID")
        if s.regain:
            text += (f"; while its position std is within {s.regain:g} m a held track takes "
                     "plots no other track gates, shown again once its score recovers")
    return logic, {"logic": text}


def _initiator(sensor: Any, s: TrackProfile) -> tuple[Any, dict[str, Any]]:
    """Single-point initiation, or two-point (``s.v_max``) allowing each pair of plots three
    standard deviations of their separation (range-bearing plots: their converted
    covariances, so the allowance grows with range)."""
    from trackkit.tracking import SinglePoint, TwoPoint

    if s.v_max is None:
        return SinglePoint(v_std=s.v_std), {"initiator": "single point, velocity 0",
                                            "initial_velocity_std_m_s": s.v_std}
    return TwoPoint(v_max=s.v_max, sigmas=3.0, both_plots=True), {
        "initiator": "two-point differencing of consecutive scans, the plots no farther "
                     "apart than v_max dt plus three standard deviations of their "
                     "separation", "v_max_m_s": s.v_max}


def _notes(read: Any) -> list[str]:
    notes = []
    if read.out_of_order:
        notes.append(f"{read.out_of_order} records were out of time order in the file and "
                     "were sorted by time before tracking")
    if read.duplicates:
        notes.append(f"{read.duplicates} exact duplicate records were dropped (the first "
                     "of each kept)")
    return notes


def _limit_scans(scans: Any, until: float | None, max_scans: int | None) -> Any:
    """The first scans: up to ``until`` s after the first, at most ``max_scans``."""
    import numpy as np

    from trackkit.io.scans import Scans

    n = len(scans)
    if until is not None and n:
        n = int(np.searchsorted(scans.times, scans.times[0] + until, side="right"))
    if max_scans is not None:
        n = min(n, max_scans)
    if n == len(scans):
        return scans
    off = scans.offsets[:n + 1]
    return Scans(scans.z[:off[-1]], off, scans.times[:n], scans.sensor[:n])


def profile_radar(profile: TrackProfile, site: tuple[float, float] = (0.0, 0.0),
                  max_gap: float | None = None) -> VirtualRadar:
    """The virtual radar of an AIS or ADS-B ``profile`` at ``site`` (x east, y north in the
    reports' frame, m), bridging reporting gaps up to ``max_gap`` (s; None: its default)."""
    from trackkit.sim.virtual_radar import VirtualRadar

    s = profile
    return VirtualRadar(site=site, period=s.period, sigma_range=s.sigma_range,
                        sigma_bearing=math.radians(s.sigma_bearing_deg), pd=s.pd,
                        clutter=s.clutter, max_range=s.max_range,
                        min_range=s.min_range, max_gap=max_gap)


def _radar_job(rec: Recording, reports: Any, read: Any) -> dict[str, Any]:
    """The virtual radar's plots of AIS or ADS-B reports, and the truth to score against."""
    import numpy as np

    from trackkit.io.frames import ground_geodetic
    from trackkit.sim.virtual_radar import virtual_radar

    s, o = rec.settings, rec.options
    if len(reports) == 0:
        raise ValueError(f"{rec.path}: no usable position reports ({read.n_skipped} skipped); "
                         "nothing to track")
    frame = reports.frame  # at the data's median position
    if o.site_lat is None:
        site = (0.0, 0.0)
    else:
        x, y, _ = frame.to_enu(o.site_lat, o.site_lon, 0.0)
        site = (float(x), float(y))
    radar = profile_radar(s, site, o.max_gap)
    until = None if o.until is None else float(reports.time[0]) + o.until
    run = virtual_radar(reports, radar, o.seed, until=until, max_scans=o.max_scans)
    lat, lon = ground_geodetic(frame, np.array([site[0]]), np.array([site[1]]))
    # the reported positions the radar could see, for the picture
    t_end = float(run.scans.times[-1])
    near = (np.hypot(reports.x - site[0], reports.y - site[1]) <= radar.max_range) & (
        reports.time <= t_end)
    n_plots = int(run.scans.z.shape[0])
    config = {"virtual radar": {
        "site_lat_deg": round(float(lat[0]), 6), "site_lon_deg": round(float(lon[0]), 6),
        "site_x_m": site[0], "site_y_m": site[1], "period_s": radar.period,
        "sigma_range_m": radar.sigma_range, "sigma_bearing_deg": s.sigma_bearing_deg,
        "pd": radar.pd, "clutter_per_scan": radar.clutter, "min_range_m": radar.min_range,
        "max_range_m": radar.max_range, "max_gap_s": radar.gap,
        "still_distance_m": radar.still_distance, "still_gap_s": radar.still_gap,
        "seed": o.seed, "scans": len(run.scans), "plots": n_plots,
        "plots_of_objects": int(np.sum(run.origin >= 0)),
        "objects_in_file": int(len(reports.ids)), "objects_in_range": run.objects_seen}}
    notes = _notes(read) + [
        "The truth is the reported positions (AIS or ADS-B), interpolated linearly to the "
        "scan times; they carry their own errors (GNSS, tens of metres), so GOSPA has a "
        "floor of that size. The radar is 2-D: range is horizontal distance in the local "
        "frame, and every plot of a scan carries the scan's time.",
        f"Objects in range: {run.objects_seen} of {len(reports.ids)} in the file (an object "
        "outside the range, or with a single report, is not seen)."]
    if o.until is not None or o.max_scans is not None:
        notes.append(f"Limited to {len(run.scans)} scans (--until / --max-scans).")
    return dict(
        scans=run.scans, sensor=run.sensor, clutter_density=max(radar.clutter, 0.1)
        / radar.volume, truth=run.truth, frame=frame, site=site, max_range=radar.max_range,
        background=reports.position[near], background_label="reported positions",
        config=config, notes=notes, objects=len(reports.ids), seen=run.objects_seen,
        plots=n_plots, object_ids=run.ids)


def _detections_job(rec: Recording, scans: Any, read: Any, polar: bool) -> dict[str, Any]:
    """A detections file's plots, tracked as they are (no truth)."""
    import numpy as np

    from trackkit.io import EnuFrame
    from trackkit.models import Position, RangeBearing

    s, o = rec.settings, rec.options
    if len(scans) == 0:
        raise ValueError(f"{rec.path}: no usable detections ({read.n_skipped} skipped); "
                         "nothing to track")
    if scans.dim_z != 2:
        raise ValueError(f"{rec.path}: detections with {scans.dim_z} coordinates; the tracker "
                         "takes 2-D plots (x, y or range, bearing)")
    scans = _limit_scans(scans, o.until, o.max_scans)
    z = scans.z
    if polar:  # range, bearing (rad, nautical, as the reader gives them) from x, y = 0, 0
        sensor = RangeBearing(origin=(0.0, 0.0), sigma_range=s.sigma_range,
                                        sigma_bearing=math.radians(s.sigma_bearing_deg))
        volume = max(float(z[:, 0].max()), 1.0) * 2 * math.pi if len(z) else 2 * math.pi
        points = np.stack([z[:, 0] * np.sin(z[:, 1]), z[:, 0] * np.cos(z[:, 1])], axis=-1)
        site: tuple[float, float] | None = (0.0, 0.0)
    else:
        sensor = Position(dim=2, sigma=s.sigma_pos)
        volume = float(max(np.ptp(z[:, 0]), 1.0) * max(np.ptp(z[:, 1]), 1.0)) if len(z) else 1.0
        points = z
        site = None
    frame = EnuFrame(o.site_lat, o.site_lon) if o.site_lat is not None else None
    plots: dict[str, Any] = {"scans": len(scans), "plots": int(z.shape[0]),
                             "kind": "range, bearing" if polar else "x, y"}
    if polar:
        plots.update(sigma_range_m=s.sigma_range, sigma_bearing_deg=s.sigma_bearing_deg)
    else:
        plots["sigma_pos_m"] = s.sigma_pos
    plots.update(clutter_per_scan_assumed=s.clutter, measurement_volume=volume)
    notes = _notes(read)
    if frame is None:
        notes.append("No --site-lat/--site-lon: positions stay in the file's x, y (no "
                     "lat/lon columns, no GeoJSON).")
    return dict(
        scans=scans, sensor=sensor, clutter_density=max(s.clutter, 0.1) / volume, truth=None,
        frame=frame, site=site, max_range=None, background=points, background_label="plots",
        config={"plots": plots}, notes=notes, objects=None, seen=None, plots=int(z.shape[0]))
