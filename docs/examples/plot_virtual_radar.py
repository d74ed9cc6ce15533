"""
A virtual radar over recorded AIS traffic
=========================================

AIS reports give every vessel's position, not radar plots. The virtual radar of
:mod:`trackkit.sim.virtual_radar` puts a radar at a site, interpolates each vessel's
reports to the scan times, and makes the plots that radar would have made: range and bearing
noise, missed detections and Poisson clutter, seeded per scan. Here on the AIS sample that
ships with trackkit (:mod:`trackkit.io.samples`: the first 10 minutes of a Solent recording
of 12 January 2016, from Stone Soup's demonstration data). ``trackkit track solent-ais
--as-radar`` makes the same plots and tracks them.

.. budget: 7 s
"""

# %%
# Reports and radar
# -----------------
# :func:`trackkit.io.read_ais_csv` recognises the Solent layout and converts the positions
# to a local east-north-up frame at the reports' median position, which is where the radar
# stands here. The radar turns every 3 s, measures range to 20 m and bearing to 0.5 deg,
# detects a vessel with probability 0.9 and adds 10 false plots per scan.
import matplotlib.pyplot as plt
import numpy as np

from trackkit.io import read_ais_csv, samples
from trackkit.sim.virtual_radar import VirtualRadar, virtual_radar

reports, report = read_ais_csv(samples.path("solent-ais"))
print(f"{report.rows_read} reports read, {report.rows_kept} kept, of {len(reports.ids)} "
      f"vessels over {reports.time[-1] - reports.time[0]:.0f} s")
radar = VirtualRadar(site=(0.0, 0.0), period=3.0, sigma_range=20.0,
                     sigma_bearing=np.deg2rad(0.5), pd=0.9, clutter=10.0, max_range=40e3)
run = virtual_radar(reports, radar, seed=1)

# %%
# The plots
# ---------
# ``run.scans`` holds every scan's plots as ``[range (m), bearing (rad)]``;
# ``run.origin`` says which vessel made each plot (-1 for clutter), and ``run.truth`` the
# interpolated positions of the vessels in range at each scan, to score a tracker against.
scan = np.repeat(np.arange(len(run.scans.times)), run.scans.counts)
r, b = run.scans.z.T
east, north = radar.site[0] + r * np.sin(b), radar.site[1] + r * np.cos(b)
clutter = run.origin < 0
in_range = run.truth.sizes.sum()
print(f"{len(run.scans.times)} scans, {run.scans.z.shape[0]} plots: {(~clutter).sum()} of "
      f"vessels ({(~clutter).sum() / in_range:.1%} of the {in_range} vessel-scans in range), "
      f"{clutter.sum()} clutter; {run.objects_seen} of {len(reports.ids)} vessels seen")

# %%
# Reports against plots
# ---------------------
# Left, the whole sample: each vessel's reports (lines) and the plots the radar made of it
# (dots, a colour per vessel), clutter in grey. Right, the busiest 1.2 km square, about a
# kilometre from the radar: a moored vessel's plots form a cluster stretched along the line
# of sight by the range noise (20 m) and across it by the bearing noise (0.5 deg, about 9 m
# per kilometre of range); a vessel under way leaves a trail along its reports.
fig, axes = plt.subplots(1, 2, figsize=(11, 5))
for ax, half in zip(axes, (None, 600.0), strict=True):
    ax.plot(east[clutter] / 1e3, north[clutter] / 1e3, ".", ms=1, color="0.75")
    ax.scatter(east[~clutter] / 1e3, north[~clutter] / 1e3, s=1,
               c=run.origin[~clutter] % 10, cmap="tab10", vmin=0, vmax=10)
    for code in np.unique(reports.code):
        mine = reports.code == code
        ax.plot(reports.x[mine] / 1e3, reports.y[mine] / 1e3, "k", lw=0.4, alpha=0.6)
    ax.plot(*radar.site, "r^", ms=8, label="radar")
    ax.set_aspect("equal")
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")
    if half is None:
        ax.set_xlim(reports.x.min() / 1e3 - 1, reports.x.max() / 1e3 + 1)
        ax.set_ylim(reports.y.min() / 1e3 - 1, reports.y.max() / 1e3 + 1)
        ax.plot([], [], "k", lw=0.6, label="AIS reports")
        ax.plot([], [], "o", ms=3, color="C0", label="plots of a vessel")
        ax.plot([], [], "o", ms=3, color="0.75", label="clutter")
        ax.legend(fontsize="small", loc="lower left")
        ax.set_title(f"solent-ais, {len(run.scans.times)} scans of {radar.period:.0f} s")
    else:
        h, xe, ye = np.histogram2d(east[~clutter], north[~clutter], bins=40)
        i, j = np.unravel_index(h.argmax(), h.shape)
        cx, cy = (xe[i] + xe[i + 1]) / 2, (ye[j] + ye[j + 1]) / 2
        ax.set_xlim((cx - half) / 1e3, (cx + half) / 1e3)
        ax.set_ylim((cy - half) / 1e3, (cy + half) / 1e3)
        ax.set_title("the busiest area")
fig.tight_layout()
plt.show()
