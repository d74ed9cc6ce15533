"""
Multi-target tracking in clutter, scored by GOSPA
=================================================

The bundled ``radar-clutter`` scene: ten aircraft crossing the coverage of an air surveillance
radar with 20 false plots per scan, tracked by :class:`trackkit.tracking.Tracker` with GNN and
with JPDA association, as the scenario file sets them up. The score is GOSPA (Rahmathullah,
García-Fernández and Svensson 2017) at every scan: localisation error of the assigned tracks
plus a cost for each missed aircraft and each false track. ``trackkit run radar-clutter``
runs the same comparison over the file's 100 runs
(:func:`trackkit.experiments.tracking_run.run_multitarget`) and writes a report; here, three
runs, through the library's pieces.

.. budget: 10 s
"""

# %%
# The scene and the trackers
# --------------------------
# :func:`trackkit.scenario.multitarget.load_multitarget` reads the bundled file and
# :func:`trackkit.scenario.multitarget.build` makes its scene (targets, radar, clutter) and
# one tracker per ``[[trackers]]`` table; :func:`trackkit.sim.scene.simulate_scene` draws
# each run's plots, run r from the scenario's seed and r alone.
import matplotlib.pyplot as plt
import numpy as np

from trackkit.eval.track_metrics import gospa_steps
from trackkit.scenario.multitarget import build, load_multitarget
from trackkit.sim.scene import simulate_scene
from trackkit.tracking.history import run_tracker

scenario = load_multitarget("radar-clutter")
scene, trackers = build(scenario)
runs = simulate_scene(scene, [0, 1, 2], scenario.run.seed)
c = scenario.report.c_m  # GOSPA cut-off (m): a miss or a false track costs c / sqrt(2)
print(f"{len(runs)} runs of {runs[0].scans}; trackers {list(trackers)}; c = {c:.0f} m")

# %%
# Track and score
# ---------------
# :func:`trackkit.tracking.history.run_tracker` steps a tracker through a run's scans and
# keeps every track at every scan; its confirmed tracks against the truth's positions give
# :func:`trackkit.eval.track_metrics.gospa_steps`, one GOSPA (and its three parts) per scan.
scores, histories = {}, {}
for name, tracker in trackers.items():
    parts = []
    for run in runs:
        history, _ = run_tracker(tracker, run.scans)
        parts.append(gospa_steps(run.truth_positions, history.confirmed(), c))
        histories.setdefault(name, history)  # run 0's, for the picture
    scores[name] = parts
    d = np.stack([g.distance for g in parts])
    missed = np.stack([g.missed for g in parts]).sum() / (c**2 / 2)
    false = np.stack([g.false for g in parts]).sum() / (c**2 / 2)
    print(f"{name}: mean GOSPA {d.mean():5.1f} m; over {len(runs)} runs "
          f"{missed:.0f} missed and {false:.0f} false target-scans")

# %%
# The picture
# -----------
# Left, run 0: the aircraft's paths and the GNN tracker's confirmed tracks (the clutter
# plots of every scan in grey). Right, GOSPA against time, the mean of the three runs. An
# aircraft is born every 20 s for the first 200 s, and each costs a missed target until its
# track is confirmed; the highest peak follows the two 90 deg turns at 200 s, where the
# constant-velocity tracks lose their aircraft and new tracks start. With every aircraft
# held, what remains is the localisation error, summed over the aircraft in view.
run0, h = runs[0], histories["GNN"]
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.5), width_ratios=(1, 1.3))
clutter = run0.origin < 0
r, brg = run0.scans.z[clutter].T
ax0.plot(r * np.sin(brg) / 1e3, r * np.cos(brg) / 1e3, ".", ms=1, color="0.8")
for i in np.unique(run0.truth.ids):
    xy = run0.truth.x[run0.truth.ids == i, :2] / 1e3
    ax0.plot(*xy.T, "k", lw=3, alpha=0.25)
tracks = h.confirmed()
for i in np.unique(tracks.ids):
    ax0.plot(*(tracks.x[tracks.ids == i] / 1e3).T, lw=1)
ax0.plot([], [], "k", lw=3, alpha=0.25, label="aircraft")
ax0.plot([], [], "C0", lw=1, label="confirmed tracks (GNN)")
ax0.set_xlabel("east (km)")
ax0.set_ylabel("north (km)")
ax0.set_aspect("equal")
ax0.legend(fontsize="small", loc="lower left")

t = run0.scans.times
for name, parts in scores.items():
    ax1.plot(t, np.mean([g.distance for g in parts], axis=0), label=name)
ax1.axhline(c / np.sqrt(2), color="k", ls=":", lw=1, label="one missed or false target alone")
ax1.set_xlabel("time (s)")
ax1.set_ylabel("GOSPA (m)")
ax1.set_title(f"mean of {len(runs)} runs, c = {c:.0f} m")
ax1.legend(fontsize="small")
fig.tight_layout()
plt.show()
