"""``trackkit track``: recorded data tracked through ``trackkit.tracking.recorded`` (the
options become a ``TrackOptions``; ``track_recording`` does the work)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.text import Text

from trackkit.cli.entry import app
from trackkit.cli.option_types import OnBad, at_least, number
from trackkit.cli.output import (
    OutputDir,
    output_dir,
    progress_bar,
    say_note,
    stderr,
    user_errors,
)
from trackkit.cli.summaries import print_track_summary
from trackkit.tracking.recorded import (
    DEFAULT_SAMPLE,
    TRACK_PROFILES,
    TrackingResult,
    TrackOptions,
    TrackProfile,
    open_recording,
    sample_sentence,
    track_recording,
)


class TrackFormat(StrEnum):
    ais = "ais"
    opensky = "opensky"
    detections = "detections"


class AssociatorName(StrEnum):
    gnn = "gnn"
    jpda = "jpda"


class FilterName(StrEnum):
    ekf = "ekf"
    ukf = "ukf"


_PROFILE_HELP = "ais {ais}, opensky {opensky}, detections {detections}"


def _profile_default(key: str, unit: str = "") -> str:
    vals = {f: "-" if (v := getattr(p, key)) is None else f"{v:g}{unit}"
            for f, p in TRACK_PROFILES.items()}
    return _PROFILE_HELP.format(**vals)


#: the profile's options, the radar's then the tracker's (module-level, to keep ``track``
#: short)
PeriodOption = Annotated[float | None, typer.Option(
    "--period", callback=number(0), help="Scan period (s).",
    show_default=_profile_default("period"))]
SigmaRangeOption = Annotated[float | None, typer.Option(
    "--sigma-range", callback=number(0), help="Range noise std (m).",
    show_default=_profile_default("sigma_range"))]
SigmaBearingOption = Annotated[float | None, typer.Option(
    "--sigma-bearing-deg", callback=number(0), help="Bearing noise std (deg).",
    show_default=_profile_default("sigma_bearing_deg"))]
SigmaPosOption = Annotated[float | None, typer.Option(
    "--sigma-pos", callback=number(0), help="Position noise std of x, y detections (m).",
    show_default=_profile_default("sigma_pos"))]
PdOption = Annotated[float | None, typer.Option(
    "--pd", callback=number(0, 1), help="Detection probability.",
    show_default=_profile_default("pd"))]
ClutterOption = Annotated[float | None, typer.Option(
    "--clutter", callback=number(0, open_lo=False), help="False plots per scan.",
    show_default=_profile_default("clutter"))]
MaxRangeOption = Annotated[float | None, typer.Option(
    "--max-range", callback=number(0), help="Instrumented range (m).",
    show_default=_profile_default("max_range"))]
MinRangeOption = Annotated[float | None, typer.Option(
    "--min-range", callback=number(0, open_lo=False), help="Blind range (m).",
    show_default=_profile_default("min_range"))]
GospaCOption = Annotated[float | None, typer.Option(
    "--gospa-c", callback=number(0), help="GOSPA cut-off (m).",
    show_default=_profile_default("gospa_c"))]
QOption = Annotated[float | None, typer.Option(
    "--q", callback=number(0), help="Process noise of the constant-velocity model "
    "(m^2/s^3).", show_default=_profile_default("q"))]
VStdOption = Annotated[float | None, typer.Option(
    "--v-std", callback=number(0), help="Velocity std of a track started from a single "
    "plot (m/s): single-point initiation, a detections file's. Two-point initiation (AIS, "
    "ADS-B, or --v-max) takes the velocity from the two plots and does not use it.",
    show_default=_profile_default("v_std"))]
VMaxOption = Annotated[float | None, typer.Option(
    "--v-max", callback=number(0), help="Top speed of the traffic (m/s): a track starts "
    "from two plots of consecutive scans no farther apart than v_max times the scan "
    "interval plus three standard deviations of their separation (two-point "
    "initiation). Given for a detections file, it replaces single-point initiation.",
    show_default=_profile_default("v_max"))]
MissesOption = Annotated[int | None, typer.Option(
    "--misses", callback=at_least(0), help="Consecutive missed scans a track coasts "
    "through (count); it is deleted at the next. Without it a detections file's track is "
    "deleted at Wald's SPRT threshold (the third miss at pd 0.9).",
    show_default=_profile_default("misses"))]
HoldOption = Annotated[float | None, typer.Option(
    "--hold", callback=number(0, open_lo=False), help="Time a lost track is held, unseen "
    "(s): a track that missed more scans than --misses is no longer shown but kept, and a "
    "new track within --rejoin of it continues it under its ID. 0: deleted when lost.",
    show_default=_profile_default("hold"))]
RejoinOption = Annotated[float | None, typer.Option(
    "--rejoin", callback=number(0), help="How near a new track must be to a held one to "
    "continue it (m), besides agreeing with it in position and velocity within their "
    "covariances.", show_default=_profile_default("rejoin"))]
RegainOption = Annotated[float | None, typer.Option(
    "--regain", callback=number(0, open_lo=False), help="Position std (m) up to which a held "
    "track takes plots no other track gates, shown again once its score recovers. 0: a held "
    "track takes no plot (only --rejoin continues it).",
    show_default=_profile_default("regain"))]
TurnQOption = Annotated[float | None, typer.Option(
    "--turn-q", callback=number(0, open_lo=False), help="Turn-rate noise of the "
    "coordinated-turn model (rad^2/s^3; the turn rate's variance grows by turn_q dt): the "
    "filter is an IMM of constant velocity and coordinated turn. Given for a detections "
    "file, it replaces the constant-velocity filter.",
    show_default=_profile_default("turn_q"))]
ManoeuvreQOption = Annotated[float | None, typer.Option(
    "--manoeuvre-q", callback=number(0, open_lo=False), help="Acceleration noise of the "
    "IMM's coordinated-turn model, its manoeuvring mode (m^2/s^3; --q is the quiet "
    "constant-velocity model's). Default: --q.", show_default=_profile_default("manoeuvre_q"))]
TurnStdOption = Annotated[float | None, typer.Option(
    "--turn-std-deg", callback=number(0), help="Turn-rate std of a new track (deg/s), in "
    "the IMM's coordinated-turn model.",
    show_default=_profile_default("turn_std_deg"))]


@app.command()
def track(
    file: Annotated[Path | None, typer.Argument(
        help="AIS (Solent, NOAA MarineCadastre, Danish Maritime Authority CSV or NMEA "
        "!AIVDM), ADS-B (OpenSky state vectors or SBS-1), detections (CSV or Parquet), or a "
        "bundled sample: solent-ais, opensky-adsb (see trackkit list).",
        show_default=f"the bundled sample {DEFAULT_SAMPLE}, as radar plots")] = None,
    fmt: Annotated[TrackFormat | None, typer.Option(
        "--format", "-f", help="What the file holds.",
        show_default="guessed from the columns")] = None,
    as_radar: Annotated[bool, typer.Option(
        "--as-radar", help="Make radar plots of the AIS/ADS-B positions (a virtual radar), "
        "track them and score the tracks against the reported positions (GOSPA). Required "
        "for AIS and OpenSky.")] = False,
    columns: Annotated[str | None, typer.Option(
        "--columns", help="Column mapping KEY=NAME,...: AIS keys time, id, lat, lon, course, "
        "speed, time_format, course_unit, speed_unit; detections keys time, sensor, x, y, "
        "range, bearing (NAME none: no such column).",
        show_default="the standard layout")] = None,
    units: Annotated[str | None, typer.Option(
        "--units", help="Units of a detections file KEY=VALUE,...: distance m|km|nmi, angle "
        "deg|rad, bearing nautical|math, time s|iso|unix|unix_ms.",
        show_default="distance=m,angle=deg,bearing=nautical,time=s")] = None,
    site_lat: Annotated[float | None, typer.Option(
        "--site-lat", callback=number(-90, 90, open_lo=False), help="Radar site latitude "
        "(deg); for detections, the latitude of the origin of x, y (gives lat/lon columns "
        "and GeoJSON).", show_default="the data's median")] = None,
    site_lon: Annotated[float | None, typer.Option(
        "--site-lon", callback=number(-180, 180, open_lo=False),
        help="Radar site longitude (deg).", show_default="the data's median")] = None,
    period: PeriodOption = None,
    sigma_range: SigmaRangeOption = None,
    sigma_bearing_deg: SigmaBearingOption = None,
    sigma_pos: SigmaPosOption = None,
    pd: PdOption = None,
    clutter: ClutterOption = None,
    max_range: MaxRangeOption = None,
    min_range: MinRangeOption = None,
    max_gap: Annotated[float | None, typer.Option(
        "--max-gap", callback=number(0), help="Longest gap between an object's reports "
        "bridged by interpolation (s).", show_default="max(3 periods, 120 s)")] = None,
    seed: Annotated[int, typer.Option(
        "--seed", "-s", callback=at_least(0), help="Seed of the virtual radar.")] = 0,
    associator: Annotated[AssociatorName, typer.Option(
        "--associator", help="Data association.")] = AssociatorName.gnn,
    filt: Annotated[FilterName, typer.Option("--filter", help="Track filter.")] = FilterName.ekf,
    q: QOption = None,
    v_std: VStdOption = None,
    v_max: VMaxOption = None,
    misses: MissesOption = None,
    hold: HoldOption = None,
    rejoin: RejoinOption = None,
    regain: RegainOption = None,
    turn_q: TurnQOption = None,
    turn_std_deg: TurnStdOption = None,
    manoeuvre_q: ManoeuvreQOption = None,
    gospa_c: GospaCOption = None,
    on_bad: Annotated[OnBad, typer.Option(
        "--on-bad", help="Skip bad records (counted, and listed in skipped.csv) or stop at "
        "the first.")] = OnBad.skip,
    until: Annotated[float | None, typer.Option(
        "--until", callback=number(0, open_lo=False), help="Track only the first SECONDS "
        "of the data.", show_default="all")] = None,
    max_scans: Annotated[int | None, typer.Option(
        "--max-scans", callback=at_least(1), help="Track at most N scans.",
        show_default="all")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", "-o", help="Output directory (created if missing).",
        show_default="trackkit-out/track-STEM")] = None,
) -> None:
    """Track recorded data; write tracks (Parquet, CSV, GeoJSON), pictures, results.json and
    report.html. AIS and ADS-B need --as-radar: a virtual radar makes plots of the reported
    positions, and the tracks are scored against those positions with GOSPA. Try it on a
    bundled sample: trackkit track solent-ais --as-radar (what trackkit track with no file
    does)."""
    with user_errors() as state:
        if file is None:
            file, as_radar = Path(DEFAULT_SAMPLE), True
            Console().print(Text(sample_sentence(DEFAULT_SAMPLE)), soft_wrap=True)
        profile = TrackProfile(period=period, sigma_range=sigma_range,
                               sigma_bearing_deg=sigma_bearing_deg, sigma_pos=sigma_pos, pd=pd,
                               clutter=clutter, max_range=max_range, min_range=min_range, q=q,
                               v_std=v_std, gospa_c=gospa_c, turn_q=turn_q,
                               turn_std_deg=turn_std_deg, manoeuvre_q=manoeuvre_q,
                               misses=misses, v_max=v_max,
                               hold=hold, rejoin=rejoin, regain=regain)
        options = TrackOptions(
            fmt=fmt.value if fmt else None, as_radar=as_radar, columns=columns, units=units,
            site_lat=site_lat, site_lon=site_lon, profile=profile,
            max_gap=max_gap, seed=seed, associator=associator.value, filter=filt.value,
            on_bad=on_bad.value, until=until, max_scans=max_scans)
        recording = open_recording(file, options)
        _check_used(profile, recording.settings)
        target, label = output_dir(out, f"track-{recording.path.stem}")
        with OutputDir(target, label) as where:
            state.interrupted = f"interrupted; nothing was written to {target}"
            say_note(where)
            with progress_bar(stderr()) as bar:
                try:
                    result = track_recording(recording, progress=_bars(bar))
                except ValueError as err:  # the reader's advice in the command's words
                    raise ValueError(str(err).replace(
                        "[on_bad='stop'; pass on_bad='skip' to skip bad records]",
                        "[--on-bad stop; pass --on-bad skip to skip bad records]")) from None
            paths = _write(result, where.path)
            state.interrupted = "interrupted"
            print_track_summary(result.read, result, paths)


def _check_used(given: TrackProfile, used: TrackProfile) -> None:
    """A tracker option the chosen tracker would ignore is a mistake: say which and why."""
    if given.v_std is not None and used.v_max is not None:
        raise ValueError(f"--v-std {given.v_std:g}: tracks here start by two-point "
                         "initiation, which takes the velocity from the two plots and does not "
                         f"use --v-std; its speed limit is --v-max ({used.v_max:g} m/s)")
    for flag, value in (("--turn-std-deg", given.turn_std_deg),
                        ("--manoeuvre-q", given.manoeuvre_q)):
        if value is not None and used.turn_q is None:
            raise ValueError(f"{flag} {value:g}: the filter here is constant-velocity, with "
                             "no coordinated-turn model; give --turn-q for the IMM of "
                             "constant velocity and coordinated turn")
    if given.hold and (used.period is None or used.misses is None):
        raise ValueError(f"--hold {given.hold:g}: a detections file's tracks are deleted at "
                         "Wald's SPRT threshold, with no scan period to hold them by; give "
                         "--misses, or track AIS or ADS-B with --as-radar")


def _bars(bar: Any) -> Any:
    """``track_recording``'s progress on ``bar``: a bar per stage, as it starts."""
    tasks: dict[str, Any] = {}
    units = {"reading": "bytes", "tracking": "scans"}

    def progress(stage: str, done: float, total: float) -> None:
        if stage not in tasks:
            tasks[stage] = bar.add_task(stage, total=total, unit=units[stage])
        bar.update(tasks[stage], completed=done, total=total)

    return progress


def _write(result: TrackingResult, out: Path) -> dict[str, Path]:
    """The tracks and the report of ``result`` written into ``out``."""
    from trackkit.report.track_pages import track_report, write_track_report

    with stderr().status("writing the tracks and the report"):
        return write_track_report(track_report(result), out)
