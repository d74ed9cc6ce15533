"""
A vessel's manoeuvring model from GPS/INS and NMEA: ``trackkit identify``
=========================================================================

Zolfagharnasab and Seif (2025) identify the 16 coefficients of a search-and-rescue boat's
surge, sway and yaw model with an extended Kalman filter on the state augmented with the
coefficients, from sea-trial GPS/INS data. This tutorial simulates such trials under GPS/INS
noise, identifies the model over several runs at once, sets the identified turning circle and
zig-zag beside the true ones, then writes one trial as an NMEA 0183 log with its inputs and
identifies the model from that log, as ``trackkit identify LOG --inputs CSV`` does.
:doc:`/vessel-comparison` sets the method against the paper.

.. budget: 30 s
"""

# %%
# Simulated sea trials: ``trackkit identify vessel-zigzag-20``
# ------------------------------------------------------------
#
# The paper publishes no data, and its own coefficients (Tables 3-5) give an unstable
# model, so the bundled vessel scenarios sail trackkit's stable reference vessel
# (:func:`trackkit.models.manoeuvring.reference_vessel`: 19.6 m, 18 kn at 2 000 rpm). The
# identification data are a 657 s trial programme (:mod:`trackkit.identify.programme`:
# an acceleration, 20/20 and 10/10 zig-zags, turns both ways and a deceleration), sensed by
# simulated GPS at 2 Hz and INS at 10 Hz (:mod:`trackkit.sim.gnss`) and turned into
# body-frame surge, sway and yaw rate on a 1 s grid:
#
# .. code-block:: bash
#
#    trackkit identify vessel-zigzag-20 --runs 20
#
# The command calls :func:`trackkit.experiments.vessel_mc.run_vessel` and writes the report;
# here the same call runs 4 runs (the scenario's default is 10), batched: the runs are the
# leading axis of one filter pass.

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from trackkit.experiments.vessel_log import LogOptions, identify_log
from trackkit.experiments.vessel_mc import REL_SD_LIMIT, nees_band, run_vessel
from trackkit.io.nmea import read_nmea, write_nmea
from trackkit.models.manoeuvring import COEFFICIENT_NAMES, reference_vessel
from trackkit.scenario.vessel import load_vessel
from trackkit.sim import gnss, seatrials

scenario = load_vessel("vessel-zigzag-20")
res = run_vessel(scenario, runs=4)
ekf = res.filters["ekf"]
truth = res.truth.theta

print(f"{res.runs} runs of {res.t.size} samples; EKF {ekf.seconds:.2f} s for all runs")
print("coef   truth   median est.  median |error|  median sd/|truth|")
for i, name in enumerate(COEFFICIENT_NAMES):
    print(f"{name:4s} {truth[i]:7.3f} {np.median(ekf.theta[:, i]):11.3f} "
          f"{100 * np.median(ekf.rel_error[:, i]):12.1f} % "
          f"{100 * np.median(ekf.theta_std[:, i]) / abs(truth[i]):14.1f} %")

# %%
# The sway and yaw coefficients (b1-b4, c1-c3) and the surge terms in ``u^2`` and ``n^2``
# (a1, a9) come out within a few per cent, with reported standard deviations to match. The
# surge terms in ``v^2``, ``r^2``, ``v r``, ``v delta`` and ``r delta`` (a2, a3, a5-a7) are
# poorly determined, and their reported standard deviations, comparable to the values, say
# so: their regressors are small beside ``u^2``, ``u n`` and ``n^2`` and move with them in
# every manoeuvre a boat can sail.
# Whether the stated covariance is honest is the coefficient NEES, chi-square with 16
# degrees of freedom:

lo, hi = nees_band()
print(f"coefficient NEES per run: {np.round(ekf.nees, 1)}; 95% band [{lo:.1f}, {hi:.1f}], "
      f"{np.mean((ekf.nees >= lo) & (ekf.nees <= hi)):.0%} of runs inside")

# %%
# The identified model's trials
# -----------------------------
#
# What matters to a navigator is the motion the model predicts. ``run_vessel`` sails each
# run's identified model through a 20 deg turning circle and 10/10 and 20/20 zig-zags at
# 18 kn (:func:`trackkit.experiments.vessel_mc.model_trials`, metrics by
# :mod:`trackkit.eval.manoeuvres`), beside the true vessel's:

D_L = res.model.turning.diameter_to_length
ov = np.rad2deg(res.model.zz20.first_overshoot)
print(f"turning D/L: true {float(res.model_truth.turning.diameter_to_length):.3f}, "
      f"identified {D_L.min():.3f}-{D_L.max():.3f}")
print(f"20/20 first overshoot: true {np.rad2deg(float(res.model_truth.zz20.first_overshoot)):.2f}"
      f" deg, identified {ov.min():.2f}-{ov.max():.2f} deg")

# %%
# A recorded log: NMEA 0183 and the inputs CSV
# --------------------------------------------
#
# On a real boat the data are a GPS/INS log and the logged nozzle angle and engine speed.
# To show that path end to end we make one: a 160 s 20/20 zig-zag of the reference
# vessel (:func:`trackkit.sim.seatrials.zigzag`, integrated at 0.05 s), sensed by
# :func:`trackkit.sim.gnss.simulate_gnss` (GPS fixes at 2 Hz, 1.5 m; INS heading and rate of
# turn at 10 Hz), written by :func:`trackkit.io.nmea.write_nmea` as GGA, RMC, HDT and ROT
# sentences, and the inputs logged every 0.1 s. Inputs logged finer than a fifth of the
# grid period let the identifier take them at the ends of its 50 Euler sub-steps, where a
# nozzle that moves at 15 deg/s starts and stops between samples.

ref = reference_vessel()
trial = seatrials.zigzag(ref.theta, ref.norm, delta=np.deg2rad(20.0), alpha=np.deg2rad(20.0),
                         rpm=2000.0, commands=13, dt=0.1, substeps=2, duration=160.0)
fixes, ins = gnss.simulate_gnss(trial.t, trial.east, trial.north, trial.psi, trial.u,
                                trial.v, trial.r, rng=np.random.default_rng(2025))

out = Path(tempfile.mkdtemp())
start = np.datetime64("2025-03-03T08:00:00", "ms")
n_lines = write_nmea(out / "trial.nmea", fixes, ins, str(start),
                     sentences=("GGA", "RMC", "HDT", "ROT"))
stamps = start + np.round(trial.t * 1000).astype("timedelta64[ms]")
rows = [f"{w}Z,{d:.2f},{n:.1f}" for w, d, n in zip(stamps, np.rad2deg(trial.delta), trial.n,
                                                    strict=True)]
(out / "trial_inputs.csv").write_text("time,nozzle_deg,rpm\n" + "\n".join(rows) + "\n")

print(f"{n_lines} NMEA lines, for example:")
print("\n".join((out / "trial.nmea").read_text().splitlines()[:4]))
nav, read = read_nmea(out / "trial.nmea")  # the reader names and counts any bad line
print(read.summary())

# %%
# Identifying the log
# -------------------
#
# .. code-block:: bash
#
#    trackkit identify trial.nmea --inputs trial_inputs.csv
#
# reads the log (:func:`trackkit.io.nmea.read_nmea`), turns the fixes, speed and course,
# heading and rate of turn into ``u, v, r`` on a 1 s grid (:mod:`trackkit.io.navigation`),
# identifies the coefficients and simulates the standard trials at the log's speed. It
# calls :func:`trackkit.experiments.vessel_log.identify_log`:

ident = identify_log(LogOptions(out / "trial.nmea", out / "trial_inputs.csv"))
rec = ident.result
for note in ident.notes:
    print("note:", note)
print(f"{rec.t.size} grid samples, {rec.substeps} Euler sub-steps per sample")
print("coef   truth  estimate     sd   sd/|est|  error/sd")
for i, name in enumerate(COEFFICIENT_NAMES):
    flag = "" if rec.rel_std[i] <= REL_SD_LIMIT else "  not identified by the log"
    print(f"{name:4s} {truth[i]:7.3f} {rec.theta[i]:9.3f} {rec.theta_std[i]:6.3f} "
          f"{rec.rel_std[i]:8.2f} {(rec.theta[i] - truth[i]) / rec.theta_std[i]:9.2f}{flag}")
print(f"identified {np.sum(rec.rel_std <= REL_SD_LIMIT)} of 16 (sd within "
      f"{REL_SD_LIMIT:.0%} of the value)")
print(f"filtered track {rec.filtered_rmse:.2f} m and the model driven by the inputs "
      f"{rec.model_rmse:.1f} m RMS from the GPS fixes")

# %%
# One zig-zag at one engine speed identifies the sway and yaw coefficients and leaves most
# surge terms poorly determined: for those the log needs speed changes, as the programme
# above has. The flag is the command's screen (a standard deviation above half the
# estimate): it says how closely the log pins a coefficient down, not whether the estimate
# is right. The last column, which no real log can show, is the error in reported
# standard deviations.
#
# The standard trials of the log's model, against the true vessel's from the same speed
# (the log's median, ``rec.speed``):

turn_true = seatrials.turning_circle(truth, ref.norm, delta=np.deg2rad(20.0), rpm=rec.rpm,
                                     speed=rec.speed, duration=120.0)
zz_true = seatrials.zigzag(truth, ref.norm, delta=np.deg2rad(20.0), alpha=np.deg2rad(20.0),
                           rpm=rec.rpm, speed=rec.speed)
print(f"log's model: D/L {float(rec.trials.turning.diameter_to_length):.3f}, "
      f"20/20 overshoots {np.rad2deg(float(rec.trials.zz20.first_overshoot)):.2f} / "
      f"{np.rad2deg(float(rec.trials.zz20.second_overshoot)):.2f} deg")

# %%
# The figure: the turning circle and the 20/20 zig-zag of the true vessel, of the models
# identified from the programme (one line per run) and of the model identified from the
# log; then every coefficient over its true value with two reported standard deviations.

fig, ax = plt.subplots(1, 3, figsize=(14, 4.6), gridspec_kw={"width_ratios": [1, 1.3, 1.4]})
tc, zz = res.model.turn, res.model.zigzag20
for r in range(res.runs):
    label = "identified, programme (per run)" if r == 0 else None
    ax[0].plot(tc.east[r], tc.north[r], color="C0", lw=0.8, alpha=0.7, label=label)
    ax[1].plot(zz.t, np.rad2deg(zz.psi[r]), color="C0", lw=0.8, alpha=0.7, label=label)
ax[0].plot(res.model_truth.turn.east, res.model_truth.turn.north, "k--", lw=1.2,
           label="true vessel, 18 kn")
ax[0].plot(rec.trials.turn.east, rec.trials.turn.north, color="C3", lw=1.2,
           label="identified, NMEA log")
ax[0].plot(turn_true.east, turn_true.north, "k:", lw=1.2, label="true vessel, log's speed")
ax[0].set(xlabel="east (m)", ylabel="north (m)", title="20 deg turning circle", aspect="equal")
ax[0].legend(fontsize=7, loc="center")

ax[1].plot(res.model_truth.zigzag20.t, np.rad2deg(res.model_truth.zigzag20.psi), "k--",
           lw=1.2, label="true vessel, 18 kn")
ax[1].plot(rec.trials.zigzag20.t, np.rad2deg(rec.trials.zigzag20.psi), color="C3", lw=1.2,
           label="identified, NMEA log")
ax[1].plot(zz_true.t, np.rad2deg(zz_true.psi), "k:", lw=1.2, label="true vessel, log's speed")
ax[1].set(xlabel="time (s)", ylabel="heading (deg)", title="20/20 zig-zag", ylim=(-45, 60))
ax[1].legend(fontsize=7, loc="upper center", ncol=2)

idx = np.arange(16)
ax[2].axhline(1.0, color="k", lw=0.8)
ax[2].errorbar(idx - 0.15, ekf.theta[0] / truth, 2 * ekf.theta_std[0] / np.abs(truth),
               fmt="o", ms=4, capsize=2, color="C0",
               label=f"programme, run 0 ({res.t.size} samples)")
ax[2].errorbar(idx + 0.15, rec.theta / truth, 2 * rec.theta_std / np.abs(truth),
               fmt="s", ms=4, capsize=2, color="C3", label=f"NMEA log ({rec.t.size} samples)")
ax[2].set_xticks(idx, COEFFICIENT_NAMES, fontsize=8)
ax[2].set(ylim=(-1.5, 3.5), ylabel="estimate / true value (1)",
          title="coefficients, +-2 reported sd")
ax[2].legend(fontsize=7, loc="upper left")
fig.tight_layout()
plt.show()
