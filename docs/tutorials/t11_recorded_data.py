"""
Recorded AIS and ADS-B to tracks: ``trackkit track``
====================================================

AIS and ADS-B receivers log where ships and aircraft say they are, not what a radar sees.
``trackkit track FILE --as-radar`` puts a virtual radar at the site, makes the plots it would
have produced of the reported positions (noise, missed detections, clutter), tracks them,
and scores the confirmed tracks against the reports. This tutorial takes the two
recordings that ship with trackkit (:mod:`trackkit.io.samples`) through that path: reading,
the virtual radar, the tracker, GOSPA, the CLEAR-MOT and identity scores, and the track
table. It follows no one source document: the tracker is an IMM (Blom and Bar-Shalom
1988) with a track score after Blackman and Popoli (1999), scored by GOSPA (Rahmathullah,
García-Fernández and Svensson 2017); :doc:`/recorded-data` describes every step and sets
it against a Stone Soup tracker fed the same plots.

.. budget: 20 s
"""

# %%
# Reading a recording
# -------------------
#
# ``solent-ais`` is the first 10 minutes of a Solent AIS recording (12 January 2016). The
# layout is recognised from the file's first lines (:data:`trackkit.io.layouts.LAYOUTS`);
# every report goes into a local east-north frame at the data's median position, sorted by
# time, with bad records named and counted, not fatal
# (:func:`trackkit.io.layouts.read_recording`):

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from trackkit.io import samples
from trackkit.io.layouts import read_recording
from trackkit.report.track_pages import track_metrics, track_report, write_track_report
from trackkit.report.track_table import track_table
from trackkit.sim.virtual_radar import virtual_radar
from trackkit.tracking.recorded import (
    TRACK_PROFILES,
    TrackOptions,
    profile_radar,
    track_recording,
)

reports, read = read_recording(samples.path("solent-ais"))
print(read.summary())
print(f"{len(reports)} reports of {len(reports.ids)} vessels; frame {reports.frame}")

# %%
# The virtual radar
# -----------------
#
# The AIS profile (``TRACK_PROFILES["ais"]``, each number argued in
# :mod:`trackkit.tracking.recorded`) is a coastal marine radar: a scan every 3 s, 20 m and
# 0.5 deg of noise, detection probability 0.9, 10 false plots a scan, 40 km of range. At
# each scan every vessel is placed by interpolation between its reports around the scan
# time; those interpolated positions are the truth the tracks are scored against, errors of
# the reports (tens of metres) included. ``as_radar=True`` below does this inside
# :func:`trackkit.tracking.recorded.track_recording`; here it is by hand, for a look at the
# plots (:func:`trackkit.sim.virtual_radar.virtual_radar`):

SCANS = 150
radar = profile_radar(TRACK_PROFILES["ais"])
run = virtual_radar(reports, radar, seed=0, max_scans=SCANS)
n_plots = run.scans.z.shape[0]
print(f"{len(run.scans)} scans, {n_plots} plots: {np.sum(run.origin >= 0)} of vessels, "
      f"{np.sum(run.origin < 0)} clutter; {run.objects_seen} vessels in range")

# %%
# Tracking: ``trackkit track solent-ais --as-radar``
# --------------------------------------------------
#
# .. code-block:: bash
#
#    trackkit track solent-ais --as-radar --max-scans 150
#
# The command builds a :class:`trackkit.tracking.recorded.TrackOptions` from its options and
# calls :func:`trackkit.tracking.recorded.track_recording`, then writes the track files
# (Parquet, CSV, GeoJSON) and the report. Without ``--max-scans`` it tracks the whole
# sample, 200 scans; the numbers here are from the first 150. A radar's scan k depends on
# the seed and k alone, so these plots are the start of the full run's, and the ones made
# by hand above:

result = track_recording(samples.path("solent-ais"),
                         TrackOptions(as_radar=True, max_scans=SCANS, seed=0))
same = np.array_equal(result.scans.z, run.scans.z)
print(f"{len(result.scans)} scans tracked; the same plots as above: {same}")
desc = result.config["tracker"]
print(f"tracker: {desc['motion']}, {desc['filter']} updates, {desc['associator']}; "
      f"initiation by {desc['initiator'].split(',')[0]}")

# %%
# Scores
# ------
#
# :func:`trackkit.report.track_pages.track_metrics` scores as the report does: at every
# scan the confirmed tracks are assigned one-to-one to the vessels in range by the optimal
# GOSPA assignment (cut-off c = 500 m, p = 2, alpha = 2), and the same assignment feeds
# the track counts and the CLEAR-MOT and IDF1 scores of :mod:`trackkit.eval.clear_mot`:

ais = TRACK_PROFILES["ais"]
m = track_metrics(result.history, result.truth, ais.gospa_c, site=result.site,
                  sigma_bearing=np.deg2rad(ais.sigma_bearing_deg))
g, ident, counts = m["gospa"], m["identity"], m["tracks"]
print(f"mean GOSPA {g['mean']:.0f} m (c = {g['c']:.0f} m): per scan {g['missed_per_scan']:.2f} "
      f"vessels missed and {g['false_per_scan']:.2f} false tracks, of "
      f"{g['objects_per_scan']:.1f} vessels in range")
print(f"position RMSE over assigned pairs {counts['rmse']:.1f} m; "
      f"{counts['truths_confirmed']} of {counts['truths']} vessels tracked, "
      f"{counts['breaks']} breaks, {counts['false_tracks']} false tracks")
print(f"MOTA {ident['mota']:.3f}, MOTP {ident['motp_m']:.1f} m, IDF1 {ident['idf1']:.3f}, "
      f"{ident['id_switches']} ID switches ({ident['id_switches_resolvable']} resolvable)")
total = g["localisation"] + g["missed"] + g["false"]  # the mean of GOSPA^2 over scans
print(f"GOSPA^2 by part: localisation {g['localisation'] / total:.0%}, missed "
      f"{g['missed'] / total:.0%}, false {g['false'] / total:.0%}")

# %%
# GOSPA is dominated by its missed part: each vessel without a confirmed track within c
# costs the full ``c^2 / 2``, and every vessel does at first (a track needs two plots to
# start and a few more to confirm), as does each that comes into range, starts reporting
# or goes unseen for three scans. The localisation part sums the squared position errors
# of the assigned pairs, each a few tens of metres (the RMSE above), near the floor the
# reports' own GNSS errors set.
#
# The track table
# ---------------
#
# One row per confirmed track (:func:`trackkit.report.track_table.track_table`, the
# report's table and ``tracks_summary.csv``): the MMSI it followed most, on which share of
# its scans, its life, distance, speeds, longest coast and its status at the end:

table = track_table(result.history, truth=result.truth, c=ais.gospa_c,
                    object_ids=result.object_ids, epoch=read.epoch,
                    assignment=m["_assignment"])
print(f"{table.num_rows} confirmed tracks; the six that went farthest:")
rows = sorted(table.to_pylist(), key=lambda r: -r["distance_m"])[:6]
print("  id  MMSI       share  start (UTC)            min   km  mean kn  status")
for r in rows:
    print(f"{r['id']:4d}  {r['identity']:9s} {r['identity_share']:6.2f}  {r['start_utc']}  "
          f"{r['duration_s'] / 60:5.1f} {r['distance_m'] / 1e3:5.2f} "
          f"{r['mean_speed_m_s'] * 3600 / 1852:7.1f}  {r['status']}")

# %%
# The files the command writes
# ----------------------------
#
# :func:`trackkit.report.track_pages.write_track_report` writes what ``trackkit track``
# leaves in its output folder: the tracks per scan (filtered and RTS-smoothed, with their
# variances and latitude and longitude) as Parquet and CSV, the track table, one GeoJSON
# line per track, the pictures, ``results.json`` and ``report.html``. Here into a
# temporary folder:

out = Path(tempfile.mkdtemp())
paths = write_track_report(track_report(result), out)
for key, path in paths.items():
    print(f"{key:10s} {path.name:20s} {path.stat().st_size / 1e3:8.1f} kB")

# %%
# ADS-B: the en-route profile
# ---------------------------
#
# ``opensky-adsb`` is 5 minutes of OpenSky state vectors over England and Wales. The same
# call recognises the layout and takes the ADS-B profile: an en-route surveillance radar
# (10 s scans, 50 m and 0.1 deg, 400 km) and GOSPA's cut-off at 2 km. Over only 30 scans
# the start-up, while each aircraft's track is still confirming, weighs heavily in the
# mean, as the missed count shows.
#
# .. code-block:: bash
#
#    trackkit track opensky-adsb --as-radar

air = track_recording(samples.path("opensky-adsb"), TrackOptions(as_radar=True, seed=0))
ma = track_metrics(air.history, air.truth, air.recording.settings.gospa_c)
ga = ma["gospa"]
print(f"{len(air.scans)} scans: {ma['tracks']['truths_confirmed']} of "
      f"{ma['tracks']['truths']} aircraft tracked, mean GOSPA {ga['mean']:.0f} m "
      f"(c = {ga['c']:.0f} m; {ga['missed_per_scan']:.1f} of {ga['objects_per_scan']:.1f} "
      f"aircraft missed per scan), position RMSE {ma['tracks']['rmse']:.0f} m")

# %%
# The figure: the Solent tracks on the map, over the reported AIS positions of the same
# minutes, and GOSPA against time with the counts behind it.

frame, h = result.frame, result.history
conf = h.confirmed()
scan_of = np.repeat(np.arange(h.times.size), conf.sizes)
lat_r, lon_r, _ = frame.to_geodetic(result.background[:, 0], result.background[:, 1])
lat_t, lon_t, _ = frame.to_geodetic(conf.x[:, 0], conf.x[:, 1])

fig = plt.figure(figsize=(13, 6.2))
grid = fig.add_gridspec(2, 2, width_ratios=[1.25, 1])
ax_map = fig.add_subplot(grid[:, 0])
ax_g = fig.add_subplot(grid[0, 1])
ax_n = fig.add_subplot(grid[1, 1], sharex=ax_g)

ax_map.plot(lon_r, lat_r, "o", color="0.6", ms=4, mew=0, label="AIS reported positions")
for k, tid in enumerate(np.unique(conf.ids)):
    mine = conf.ids == tid
    order = np.argsort(scan_of[mine])
    ax_map.plot(lon_t[mine][order], lat_t[mine][order], lw=0.9, color=f"C{k % 10}",
                label="confirmed tracks" if k == 0 else None)
lat_s, lon_s, _ = frame.to_geodetic(*result.site)
ax_map.plot(lon_s, lat_s, "k^", ms=8, label="virtual radar")
ax_map.set_aspect(1.0 / np.cos(np.deg2rad(frame.lat0)))  # metres alike east and north
ax_map.set(xlabel="longitude (deg)", ylabel="latitude (deg)",
           title=f"Solent, {len(result.scans)} scans of 3 s: {table.num_rows} tracks")
ax_map.legend(fontsize=8, loc="lower left")

t_min = (h.times - h.times[0]) / 60.0
steps = m["_gospa_steps"]
ax_g.plot(t_min, steps.distance, color="C0", label="GOSPA")
ax_g.plot(t_min, np.sqrt(steps.localisation), color="C2",
          label="localisation part, sqrt(L)")
ax_g.axhline(g["mean"], color="C0", ls="--", lw=0.8, label=f"mean {g['mean']:.0f} m")
ax_g.set(ylabel="GOSPA (m)", title="GOSPA against the AIS reports (c = 500 m, p = 2)")
ax_g.legend(fontsize=8)
ax_n.plot(t_min, result.truth.sizes, "k", label="vessels in range")
ax_n.plot(t_min, conf.sizes, color="C1", label="confirmed tracks")
ax_n.plot(t_min, steps.assigned, color="C2", ls="--", label="assigned within c")
ax_n.set(xlabel="time from the first scan (min)", ylabel="count")
ax_n.legend(fontsize=8)
fig.tight_layout()
plt.show()
