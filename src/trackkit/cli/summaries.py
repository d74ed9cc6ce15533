"""The summaries the commands print when they have written their reports (from the results
they wrote, so that what is printed is what is in the files)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table
from rich.text import Text


def number_table(headers: list[str], rows: list[list[str]], title: str, console: Console
                  ) -> Any:
    """A summary table whose numbers are never cut at the console's width (folded instead;
    ``report.tables.summary_rich_table``)."""
    from trackkit.report.tables import Summary, summary_rich_table

    return summary_rich_table(Summary(headers, rows, "", title=title), console.width)


def print_network_summary(paths: dict[str, Path]) -> None:
    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    w = doc["windows"]["last"]
    mode = "steering" if doc["steering"] else "straight courses"
    headers = ["agent", "all held at the end", "GOSPA [m]",
               f"pos. RMSE {w[0]:g}-{w[1]:g} s [m]", "centralised [m]", "PCRLB [m]",
               "ratio to centralised", "ratio to PCRLB"]

    def per_target(v: list, spec: str) -> str:
        return " / ".join("-" if x is None else format(x, spec) for x in v)

    rows = [[str(e["agent"]), f"{100 * e['all_held_final_fraction']:.0f}%",
             "-" if e["gospa_mean"] is None else f"{e['gospa_mean']:.0f}",
             per_target(e["rmse_pos_last"], ".0f"),
             per_target(e["central_rmse_pos_last"], ".0f"),
             per_target(e["pcrlb_pos_last"], ".0f"),
             per_target(e["ratio_to_central_pos_last"], ".2f"),
             per_target(e["ratio_to_pcrlb_pos_last"], ".2f")] for e in doc["per_agent"]]
    console = Console()
    console.print(number_table(headers, rows, f"{doc['scenario']}: {doc['runs']} runs, "
                                f"seed {doc['seed']}, {mode} (per target: 1 / 2 / ...)",
                                console))
    m = doc["messages"]
    console.print(Text(f"messages: {m['sent']} sent, {m['delivered']} delivered, "
                       f"{m['lost']} lost, {m['late']} late"))
    for o in doc["channel"]["outages"]:
        back = [x for x in o["recovered_after_s"] if x is not None]
        console.print(Text(
            f"agent {o['agent']} killed at {o['kill_at_s']:g} s, "
            + ("not restarted" if o["restart_at_s"] is None
               else f"restarted at {o['restart_at_s']:g} s")
            + ": held its tracks again after "
            + (f"{min(back):.0f}-{max(back):.0f} s" if back else "never")
            + f" ({len(back)} of {len(o['recovered_after_s'])} runs)"), soft_wrap=True)
    if doc["channel"].get("curve"):
        console.print(Text(f"CURVE: agents authenticated and encrypted; "
                           f"{doc['channel']['peers_refused']} peers refused"))
    c = doc.get("courses")
    if c is not None:
        console.print(Text(
            f"steering pays: {c['steering_pays']} (position RMSE {w[0]:g}-{w[1]:g} s "
            f"{c['rmse_steered_m']:.0f} m steered, {c['rmse_straight_m']:.0f} m straight, "
            f"ratio {c['ratio']:.2f}; steered lower in {100 * c['steered_lower_share']:.0f}% "
            f"of runs, paired t = {c['t']:.2f}, p = {c['p']:.2g})"), soft_wrap=True)
    html = paths.get("html")
    where = html.parent if html is not None else paths["results"].parent
    console.print(Text(f"wrote {len(paths)} files to {where}", style="green"), soft_wrap=True)
    if html is not None:
        console.print(Text(f"report: {html}", style="green"), soft_wrap=True)


def print_summary(result: Any, paths: dict[str, Path]) -> None:
    from trackkit.report.tables import matching_rich_tables, rich_table

    console = Console()
    console.print(rich_table(result, width=console.width))
    # the error windows, the matching tables (J1-J4), the gap table: if present
    for table in matching_rich_tables(result, width=console.width):
        console.print(table)
    for note in getattr(result, "notes", []) or []:
        console.print(Text(f"note: {note}", style="yellow"))
    html = paths.get("html")
    where = html.parent if html is not None else next(iter(paths.values())).parent
    console.print(Text(f"wrote {len(paths)} files to {where}", style="green"))
    if html is not None:
        console.print(Text(f"report: {html}", style="green"))


def print_sweep_summary(campaign: Any, docs: list[dict], paths: dict[str, Path]) -> None:
    from trackkit.report.tables import Summary, display_unit, summary_rich_table

    console = Console()
    g = campaign.base.report.groups[0]
    unit, factor = display_unit(docs[0]["units"].get(g, "") if docs else "")
    paths_ = [p.path for p in campaign.params]
    # each swept value under its field's last name (the full paths in the caption)
    short = [q.rsplit(".", 1)[-1] for q in paths_]
    names = short if len(set(short)) == len(short) else paths_

    def num(v: Any, scale: float = 1.0) -> str:
        return "n/a" if v is None else f"{v * scale:.4g}"

    cells: list[list[str]] = []
    shown, limit = 0, 40
    for d in docs:
        for name, f in d["filters"].items():
            if shown == limit:
                break
            shown += 1
            cells.append([*(str(d["values"][q]) for q in paths_), name,
                         num(f["rmse"].get(g), factor), num(f["rmse_pcrlb"].get(g)),
                         num(f["anees"]), f"{f['diverged'] / d['runs']:.1%}"])
    caption = ", ".join(f"{n} = {q}" for n, q in zip(names, paths_, strict=True)
                        if n != q)
    table = Summary([*names, "filter", f"{g} RMSE [{unit}]", "RMSE / PCRLB", "ANEES",
                     "diverged"], cells, caption,
                    title=f"{campaign.base.name}: {len(campaign.points)} points x "
                    f"{campaign.runs} runs, seed {campaign.seed}")
    console.print(summary_rich_table(table, console.width))
    rows = sum(len(d["filters"]) for d in docs)
    if rows > shown:
        console.print(Text(f"... {rows - shown} more rows in {paths['csv']}", style="dim"))
    for note in campaign.notes:
        console.print(Text(f"note: {note}", style="yellow"), soft_wrap=True)
    console.print(Text(f"wrote {len(paths)} files to {paths['html'].parent}", style="green"),
                  soft_wrap=True)
    console.print(Text(f"report: {paths['html']}", style="green"), soft_wrap=True)


def print_track_summary(read: Any, job: Any, paths: dict[str, Path]) -> None:
    console = Console()
    console.print(Text(read.summary()), soft_wrap=True)
    if "skipped" in paths:
        console.print(Text(f"  the skipped records are listed in {paths['skipped']}"),
                      soft_wrap=True)
    elif not read.n_skipped:
        console.print(Text("  no records skipped"))
    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    res = doc["results"]
    radar = doc["config"].get("virtual radar")
    if radar is not None:
        console.print(Text(
            f"virtual radar at {radar['site_lat_deg']:.5f}, {radar['site_lon_deg']:.5f}: "
            f"{radar['scans']} scans of {radar['period_s']:g} s, {radar['plots']} plots "
            f"({radar['plots_of_objects']} of objects, the rest clutter); "
            f"{radar['objects_in_range']} of {radar['objects_in_file']} objects in range"),
            soft_wrap=True)
    else:
        console.print(Text(f"{job.plots} plots in {len(job.scans)} scans"))
    console.print(Text(f"tracks: {res['tracks_confirmed']} confirmed of "
                       f"{res['tracks_started']} started"), soft_wrap=True)
    if res["tracks_confirmed"] == 0:
        from trackkit.report.track_pages import NO_TRACK_CONFIRMED

        console.print(Text(NO_TRACK_CONFIRMED, style="yellow"), soft_wrap=True)
    g = res.get("gospa")
    if g is not None:
        t = res["tracks"]
        rmse = "n/a" if t["rmse"] is None else f"{t['rmse']:.3g} m"
        console.print(Text(
            f"mean GOSPA {g['mean']:.4g} m (c = {g['c']:g} m; per scan on average "
            f"{g['objects_per_scan']:.1f} objects, {g['missed_per_scan']:.2f} missed, "
            f"{g['false_per_scan']:.2f} false tracks; localisation part "
            f"{g['localisation']:.4g} m^2); {t['truths_confirmed']} of {t['truths']} objects "
            f"tracked, {t['breaks']} track breaks, position RMSE {rmse}"),
            soft_wrap=True)
    i = res.get("identity")
    if i is not None:
        def num(v: float | None, fmt: str) -> str:  # nan (no object, no match) is null
            return "n/a" if v is None else format(v, fmt)

        console.print(Text(
            f"MOTA {num(i['mota'], '.3f')}, MOTP {num(i['motp_m'], '.3g')} m, IDF1 "
            f"{num(i['idf1'], '.3f')}; {i['id_switches']} ID switches ("
            f"{num(i['id_switches_resolvable'], 'd')} between objects the radar resolves), "
            f"{i['fragmentations']} fragmentations; mean GOSPA with switching "
            f"{num(i['gospa_switching_mean'], '.4g')} m"), soft_wrap=True)
    html = paths.get("html")
    console.print(Text(f"wrote {len(paths)} files to {html.parent if html else ''}",
                       style="green"), soft_wrap=True)
    if html is not None:
        console.print(Text(f"report: {html}", style="green"), soft_wrap=True)


def print_recorded_summary(paths: dict[str, Path], log: Path, notes: list[str]) -> None:
    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    console = Console()
    limit = 100 * doc["rel_sd_limit"]
    table = Table("coefficient", "value", "std", "relative std", "identified",
                  title=f"{log.name}: {doc['filter']}, {doc['samples']} samples of "
                  f"{doc['period_s']:g} s (prime units: L = 19.6 m, U0 = 18 kn, n0 = 2000 rpm)",
                  title_justify="left")
    for name, c in doc["coefficients"].items():
        rel = "-" if c["rel_std"] is None else f"{100 * c['rel_std']:.0f}%"
        flag = (Text("yes") if c["identified"]
                else Text(f"no: std > {limit:.0f}% of the value", style="yellow"))
        table.add_row(name, _signed4(c["value"]), _signed4(c["std"]).lstrip("+"), rel, flag)
    console.print(table)
    n_id = doc["identified_count"]
    console.print(Text(f"{16 - n_id} of 16 coefficients are not identified by this log "
                       f"(standard deviation above {limit:.0f}% of the value)",
                       style="yellow" if n_id < 16 else ""), soft_wrap=True)
    _print_closing(console, doc["model_trials"], notes, paths)


def _signed4(v: float | None) -> str:
    return "-" if v is None else f"{v:+.4f}"


def _print_trials(mt: dict) -> None:
    """The standard trials' metrics and the IMO table of results.json's ``model_trials``."""
    from rich.markup import escape

    from trackkit.report.vessel_report import imo_rows

    truth = "truth" in mt
    console = Console()
    kn = mt["speed_mps"] * 3600.0 / 1852.0
    turn, z10, z20 = (mt["identified_run0"][k] for k in ("turn", "zigzag10", "zigzag20"))

    def f(v: float | None, spec: str, scale: float = 1.0) -> str:
        return "-" if v is None else format(v * scale, spec)

    deg = 180.0 / math.pi
    console.print(Text(
        f"identified model at {kn:.1f} kn, {mt['rpm']:.0f} rpm: 20 deg turn D/L "
        f"{f(turn['diameter_to_length'], '.2f')} (steady diameter "
        f"{f(turn['steady_diameter_m'], '.0f')} m, advance {f(turn['advance_m'], '.0f')} m, "
        f"tactical diameter {f(turn['tactical_diameter_m'], '.0f')} m); 10/10 overshoots "
        f"{f(z10['first_overshoot_rad'], '.1f', deg)} and "
        f"{f(z10['second_overshoot_rad'], '.1f', deg)} deg; 20/20 first overshoot "
        f"{f(z20['first_overshoot_rad'], '.1f', deg)} deg"), soft_wrap=True)
    head = ["criterion", "identified" + (" (run 0)" if truth else "")]
    head += (["truth", "runs passing"] if truth else []) + ["limit", "source"]
    table = Table(*(escape(h) for h in head), title="IMO MSC.137(76) (for reference only "
                  "below 100 m) and the paper's 2 <= D/L <= 7", title_justify="left")
    for row in imo_rows(mt["imo"], truth):
        table.add_row(*(escape(c) for c in row))
    console.print(table)


def _print_closing(console: Console, trials: dict, notes: list[str],
                   paths: dict[str, Path]) -> None:
    """The end of both vessel summaries: the model's trials, the notes, where the files went."""
    _print_trials(trials)
    for note in notes:
        console.print(Text(f"note: {note}", style="yellow"), soft_wrap=True)
    console.print(Text(f"wrote {len(paths)} files to {paths['results'].parent}",
                       style="green"), soft_wrap=True)
    console.print(Text(f"report: {paths['html']}", style="green"), soft_wrap=True)


def print_vessel_summary(paths: dict[str, Path], notes: list[str]) -> None:
    from rich.markup import escape

    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    console = Console()
    shown = doc["shown_filter"]
    names = list(doc["filters"])
    truth = doc["truth"]["coefficients"]
    f0 = doc["filters"][shown]["coefficients_run0"]
    head = ["coefficient", "truth", f"{shown} run 0", "std"]
    head += [f"{n} median error" for n in names]
    table = Table(*head, title=f"{doc['scenario']}: {doc['runs']} runs, seed {doc['seed']}, "
                  f"identified from the {doc['data']} ({doc['samples']} samples of "
                  f"{doc['period_s']:g} s)", title_justify="left")
    for k, t in truth.items():
        errs = [doc["filters"][n]["rel_error_median"][k] for n in names]
        table.add_row(k, f"{t:+.3f}", f"{f0[k]['value']:+.4f}", f"{f0[k]['std']:.4f}",
                      *("-" if e is None else f"{100 * e:.1f}%" for e in errs))
    console.print(table)
    lo, hi = doc["nees_band"]
    per = Table("filter", "NEES median", escape(f"NEES in [{lo:.1f}, {hi:.1f}]"),
                "filtered u / v / r RMSE over the measurement's",
                title="per filter (medians over runs)", title_justify="left")
    for n, f in doc["filters"].items():
        r = f["body_rmse_over_noise_median"]
        per.add_row(n, f"{f['nees_median']:.1f}", f"{100 * f['nees_inside_fraction']:.0f}%",
                    "-" if r[0] is None else f"{r[0]:.2f} / {r[1]:.2f} / {r[2]:.2f}")
    console.print(per)
    tr = doc["trial"]
    if tr is not None:
        def m(v: float | None) -> str:
            return "-" if v is None else f"{v:.2f} m"

        console.print(Text(
            f"{tr['kind']} trial, {tr['duration_s']:g} s (medians over runs): raw GPS "
            f"{m(tr['gps_rmse_median_m'])} RMS from the truth, filtered track "
            f"{m(tr['filtered_rmse_median_m'])}; the identified model driven by the inputs "
            f"{m(tr['model_rmse_median_m'])} (largest {m(tr['model_max_error_median_m'])})"),
            soft_wrap=True)
    _print_closing(console, doc["model_trials"], notes, paths)
