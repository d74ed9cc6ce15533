"""What the track report says first, in words: the five headline figures of a run and its
radar and tracker settings as sentences with units (the raw keys stay in ``results.json``)::

    figures = headline_figures(metrics, history.times, kind="ais")
    # [("vessels held", "73 of 73", "..."), ("tracks per vessel", "1.37", "..."), ...]
    settings = settings_in_words(config)   # [("Virtual radar", "Virtual radar at ..."), ...]

ID switches per vessel-hour are the CLEAR-MOT ID switches (an object matched to another track
than before, ``eval.clear_mot``; Bernardin and Stiefelhagen 2008) when the metrics have them,
else the track-level ID switches of ``track_counts``, over the object-hours in range,
``sum over scans of the objects in range x scan period / 3600 s``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["headline_figures", "object_noun", "settings_in_words"]

#: unit suffixes of the configuration's keys, longest first
_UNITS = (("_per_m_rad", "per m per rad"), ("_per_m2", "per m^2"), ("_m2_s3", "m^2/s^3"),
          ("_m_s", "m/s"), ("_deg", "deg"), ("_m", "m"), ("_s", "s"))


def object_noun(kind: str) -> tuple[str, str]:
    """Singular and plural of what a recording holds: vessels (AIS), aircraft (ADS-B)."""
    return {"ais": ("vessel", "vessels"), "opensky": ("aircraft", "aircraft")}.get(
        kind, ("object", "objects"))


def _num(v: float, digits: int = 3) -> str:
    if v is None or not math.isfinite(v):
        return "n/a"
    return f"{v:,.{digits}g}" if abs(v) < 10**digits else f"{v:,.0f}"


def headline_figures(metrics: Mapping[str, Any], times: Sequence[float] | np.ndarray,
                     kind: str = "") -> list[tuple[str, str, str]]:
    """The five figures a person looks for first, as (label, value, what it means); with no
    truth, the counts the run has."""
    one, many = object_noun(kind)
    tr, g = metrics.get("tracks"), metrics.get("gospa")
    if tr is None or g is None:
        return [("confirmed tracks", f"{metrics['tracks_confirmed']:,}",
                 f"of {metrics['tracks_started']:,} started"),
                ("tracks per scan", _num(metrics["mean_confirmed_per_scan"]),
                 f"mean over {metrics['scans']:,} scans")]
    t = np.asarray(times, float)
    period = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    hours = tr["truth_steps"] * period / 3600.0
    held = tr["truths_confirmed"]
    ident = metrics.get("identity") or {}
    switches = ident.get("id_switches", tr["id_switches"])
    per_hour = switches / hours if hours > 0 else math.nan
    return [
        (f"{many} held", f"{held:,} of {tr['truths']:,}",
         f"{many} in range that had a confirmed track at some scan"),
        (f"tracks per {one}", _num(tr["tracks"] / held) if held else "n/a",
         f"{tr['tracks']:,} confirmed tracks for {held:,} {many}; 1 is one track each"),
        (f"ID switches per {one}-hour", _num(per_hour),
         f"{switches:,} times a {one} was matched to another track than before"
         f"{' (CLEAR-MOT)' if 'id_switches' in ident else ''}, over "
         f"{_num(hours)} {one}-hours in range"),
        ("mean GOSPA", f"{_num(g['mean'])} m",
         f"per scan, cut-off {g['c']:g} m: position error, missed {many} and false tracks"),
        ("position RMSE", "n/a" if tr.get("rmse") is None else f"{_num(tr['rmse'])} m",
         f"of the tracks paired with {many} (within {g['c']:g} m)"),
    ]


def _plain(key: str, value: Any) -> str:
    """``q_m2_s3: 0.05`` as ``q 0.05 m^2/s^3``."""
    unit = ""
    for suffix, name in _UNITS:
        if key.endswith(suffix):
            key, unit = key[: -len(suffix)], name
            break
    text = f"{value:.4g}" if isinstance(value, float) else str(value)
    return f"{key.replace('_', ' ')} {text}{' ' + unit if unit else ''}"


def _latlon(lat: float, lon: float) -> str:
    return f"{abs(lat):.5f} {'N' if lat >= 0 else 'S'}, {abs(lon):.5f} {'E' if lon >= 0 else 'W'}"


def _distance(m: float) -> str:
    return f"{m / 1000:g} km" if m >= 1000 else f"{m:g} m"


def _radar(c: Mapping[str, Any]) -> tuple[str, set[str]]:
    """The virtual radar in words, and the keys said."""
    said = {"site_lat_deg", "site_lon_deg", "site_x_m", "site_y_m", "period_s", "sigma_range_m",
            "sigma_bearing_deg", "pd", "clutter_per_scan", "min_range_m", "max_range_m",
            "max_gap_s", "still_distance_m", "still_gap_s", "seed", "scans", "plots",
            "plots_of_objects", "objects_in_file", "objects_in_range"}
    if not said <= set(c):
        return "", set()
    text = (
        f"Virtual radar at {_latlon(c['site_lat_deg'], c['site_lon_deg'])}, a scan every "
        f"{c['period_s']:g} s, range noise {c['sigma_range_m']:g} m, bearing noise "
        f"{c['sigma_bearing_deg']:g} deg, detection probability {c['pd']:g}, "
        f"{c['clutter_per_scan']:g} false plots a scan on average, seeing from "
        f"{_distance(c['min_range_m'])} to {_distance(c['max_range_m'])}. An object's "
        f"position at a scan is interpolated between its reports across gaps of up to "
        f"{c['max_gap_s']:g} s (up to {c['still_gap_s']:g} s when it moved less than "
        f"{c['still_distance_m']:g} m). Random seed {c['seed']}: {c['scans']:,} scans, "
        f"{c['plots']:,} plots ({c['plots_of_objects']:,} of objects, the rest false); "
        f"{c['objects_in_range']:,} of the {c['objects_in_file']:,} objects in the file came "
        f"into range.")
    return text, said


def _tracker(c: Mapping[str, Any]) -> tuple[str, set[str]]:
    """The tracker in words (the keys it knows), and the keys said."""
    parts, said = [], set()

    def take(*keys: str) -> bool:
        if all(k in c for k in keys):
            said.update(keys)
            return True
        return False

    if take("filter", "motion"):
        q = f" (process noise q {c['q_m2_s3']:g} m^2/s^3)" if take("q_m2_s3") else ""
        parts.append(f"{c['filter']} on a {c['motion']} model{q}")
    if take("associator"):
        parts.append(f"{c['associator']} association")
    if take("initiator"):
        v = (f", initial velocity std {c['initial_velocity_std_m_s']:g} m/s"
             if take("initial_velocity_std_m_s") else "")
        parts.append(f"tracks started from a {c['initiator']}{v}")
    if take("pd_assumed"):
        parts.append(f"detection probability assumed {c['pd_assumed']:g}")
    text = "; ".join(parts)
    text = text[:1].upper() + text[1:] + "." if text else ""
    if take("logic"):
        text += f" Track logic: {c['logic']}."
    if take("gospa_c_m"):
        text += f" Scored with GOSPA, cut-off {c['gospa_c_m']:g} m."
    return text.strip(), said


def settings_in_words(config: Mapping[str, Mapping[str, Any]]) -> list[tuple[str, str]]:
    """Each configuration section (title, sentences); what a section holds beyond the known
    keys is added as "key value unit" phrases."""
    out = []
    for section, values in config.items():
        if section == "virtual radar":
            text, said = _radar(values)
        elif section == "tracker":
            text, said = _tracker(values)
        else:
            text, said = "", set()
        rest = [_plain(k, v) for k, v in values.items() if k not in said]
        if rest:
            text = (text + " Also: " if text else "") + "; ".join(rest) + "."
        out.append((section[:1].upper() + section[1:], text))
    return out
