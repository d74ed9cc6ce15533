"""A recorded GPS/INS log and its measured inputs, identified (Zolfagharnasab and Seif 2025):
read, check, pre-process to the body velocities on a grid, identify the 16 coefficients and
simulate the standard trials, what ``trackkit identify LOG --inputs CSV`` does, from Python.

    from trackkit.experiments.vessel_log import LogOptions, identify_log
    ident = identify_log(LogOptions(Path("trial.nmea"), Path("inputs.csv")))
    ident.result.theta, ident.result.trials, ident.notes

Every fact the run learns on the way that a user should read beside the numbers (no rate of
turn in the log, gaps, a short log, an unstable model, dropped samples) is a note in words.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from trackkit.experiments.vessel_mc import RecordedIdentification, identify_recorded
from trackkit.io.navigation import INPUT_COLUMNS, preprocess, read_inputs_csv
from trackkit.io.nmea import NAV_CSV_COLUMNS, read_nav_csv, read_nmea
from trackkit.io.records import ReadReport

__all__ = ["CONVERGED_AFTER_S", "NMEA_TYPES", "LogIdentification", "LogOptions", "identify_log"]

#: the NMEA sentences the identifier reads
NMEA_TYPES = "GGA RMC VTG HDT THS ROT"
#: a log shorter than this cannot show converged coefficients (the paper: 500 s)
CONVERGED_AFTER_S = 500.0


@dataclass(frozen=True)
class LogOptions:
    """A log (NMEA 0183, or the CSV form when it ends in ``.csv``), its inputs CSV (time,
    nozzle_deg, rpm), the identifier (``"ekf"``, ``"ukf"``, ``"ckf"``, ``"srckf"``, ``"ls"``),
    the grid period ``dt`` (s) and what a bad line does."""

    log: Path
    inputs: Path
    filter: str = "ekf"
    dt: float = 1.0
    on_bad: Literal["skip", "stop"] = "skip"


@dataclass
class LogIdentification:
    """The identification, the two reads' accounts, the NMEA sentence types read but not
    used, and the notes in words."""

    result: RecordedIdentification
    log_read: ReadReport
    inputs_read: ReadReport
    unsupported: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def _quiet(what: str) -> AbstractContextManager:
    return nullcontext()


def identify_log(options: LogOptions, *,
                 stage: Callable[[str], AbstractContextManager] = _quiet,
                 say: Callable[[str], None] = lambda text: None) -> LogIdentification:
    """Read, pre-process and identify a recorded log. ``stage(what)`` wraps each long step
    (reading, identifying) and ``say(text)`` hears the reads' accounts as soon as they are
    known, for a caller that shows progress."""
    o = options
    with stage(f"reading {o.log} and {o.inputs}"):
        nav, read, ins, iread = _read(o)
    say(read.summary())
    say(iread.summary())
    if nav.unsupported:
        say("  sentence types not used: " + ", ".join(
            f"{k} {v}" for k, v in sorted(nav.unsupported.items())))
    if ins.t.size < 2:
        raise ValueError(f"--inputs {o.inputs}: {ins.t.size} usable records "
                         f"({iread.n_skipped} skipped); expected nozzle angle and rpm over "
                         "the log's time span")
    notes: list[str] = []
    m = _body_velocities(o, nav, notes)
    doing = f"identifying the 16 coefficients with {o.filter} ({m.t.size} samples)"
    if not _compiled(o.filter):
        doing = (f"compiling the {o.filter} filter (the first run only: about half a minute; "
                 f"later runs reuse it), then {doing}")
    with stage(doing):
        rec = identify_recorded(m, ins, filter=o.filter, inputs_name=f"--inputs {o.inputs}")
    notes += _result_notes(rec)
    return LogIdentification(rec, read, iread, dict(nav.unsupported), notes)


def _read(o: LogOptions) -> tuple[Any, ReadReport, Any, ReadReport]:
    """The log's navigation records and the inputs, each with its read's account."""
    csv = o.log.suffix.lower() == ".csv"
    try:
        nav, read = read_nav_csv(o.log, o.on_bad) if csv else read_nmea(o.log, o.on_bad)
    except ValueError as err:
        raise _expected_columns(err, NAV_CSV_COLUMNS) from None
    _check_log_usable(o.log, nav, read, (
        f"the columns {', '.join(NAV_CSV_COLUMNS)}" if csv else
        f"NMEA 0183 sentences ({NMEA_TYPES}) with valid checksums"))
    fmt = "iso" if nav.epoch is not None else "seconds"  # a log without a date: both
    try:
        ins, iread = read_inputs_csv(o.inputs, o.on_bad, epoch=nav.epoch, time_format=fmt)
    except ValueError as err:
        raise _expected_columns(err, INPUT_COLUMNS) from None
    return nav, read, ins, iread


def _expected_columns(err: ValueError, columns: tuple[str, ...]) -> ValueError:
    return ValueError(str(err).replace(" (pass a column mapping)",
                                       f"; expected the columns {', '.join(columns)}"))


def _check_log_usable(log: Path, nav: Any, read: ReadReport, expected: str) -> None:
    """A log with no usable position is named as the culprit (before its inputs, which
    cannot be read against the times of a log without any)."""
    if read.rows_kept and nav.t_pos.size:
        return
    why = ", ".join(f"{n} {r}" for r, n in sorted(read.skipped.items(), key=lambda kv: -kv[1]))
    first = f"; first: {read.bad[0]}" if read.bad else ""
    kept = (f"{read.rows_kept} kept but none gives a position (GGA or RMC)" if read.rows_kept
            else f"none usable ({why or 'empty'}){first}")
    raise ValueError(f"{log}: no usable GPS/INS record: {read.rows_read} lines read, {kept}; "
                     f"expected {expected}")


def _body_velocities(o: LogOptions, nav: Any, notes: list[str]) -> Any:
    """The log pre-processed to u, v, r on the grid, with a note for each choice made."""
    rate_source = "gyro"
    if nav.t_rate.size < 2 and nav.t_heading.size >= 2:  # no ROT: differentiate the heading
        rate_source = "heading"
        notes.append("the log has no rate of turn (ROT); the yaw rate is the differenced INS "
                     "heading")
    try:
        m = preprocess(nav, dt=o.dt, rate_source=rate_source)
    except ValueError as err:
        raise ValueError(f"{o.log}: {err}") from None
    if m.gaps:
        notes.append(f"{len(m.gaps)} gap(s) in the log's streams ("
                     + ", ".join(f"{g.stream} {g.start:.1f}-{g.end:.1f} s" for g in m.gaps[:5])
                     + ("..." if len(m.gaps) > 5 else "") + "): no measurement there, the "
                     "filter predicts across")
    return m


def _compiled(filt: str) -> bool:
    """Whether the identifier is ready to run at once (the EKF's fused step is compiled on
    its first run and cached beside its module)."""
    if filt != "ekf":
        return True
    from trackkit.identify import fused

    return fused.step_is_compiled()


def _result_notes(rec: RecordedIdentification) -> list[str]:
    notes = []
    span = rec.t[-1] - rec.t[0]
    if span < CONVERGED_AFTER_S:
        notes.append(f"the log is {span:.0f} s long; the paper's coefficients converged only "
                     f"after {CONVERGED_AFTER_S:.0f} s: expect wide standard deviations")
    if not rec.stable:
        notes.append(f"the identified model is unstable in a straight line at the log's "
                     f"{rec.speed / 1852.0 * 3600.0:.1f} kn and {rec.rpm:.0f} rpm (an eigenvalue "
                     "of df/dx with a positive real part): its simulated trials diverge and "
                     "their metrics are not meaningful")
    if rec.dropped:
        notes.append(f"the first {rec.dropped} grid sample(s) lack a measurement and were "
                     "left out")
    return notes
