"""
A vessel model's turning circles and zig-zags
=============================================

The manoeuvring model of a 19.6 m waterjet search-and-rescue boat (Zolfagharnasab and Seif
2025; trackkit's stable reference coefficients,
:func:`trackkit.models.manoeuvring.reference_vessel`) sailed through the standard sea trials
by :mod:`trackkit.sim.seatrials`: turning circles at three nozzle angles and the 10/10 and
20/20 zig-zags, each family one batched call, and scored by :mod:`trackkit.eval.manoeuvres`
(advance, tactical diameter, D/L, overshoots) with the IMO MSC.137(76) criteria beside them
(IMO 2002).

.. budget: 6 s
"""

# %%
# Trials
# ------
# At the model's design speed (18 kn) and 2000 rpm. The nozzle follows its command at
# 15 deg/s; a turning circle runs until the heading has turned 540 deg, a zig-zag reverses
# the nozzle each time the heading deviation reaches alpha. Leading axes are trials: three
# turning circles, two zig-zags.
import matplotlib.pyplot as plt
import numpy as np

from trackkit.eval.manoeuvres import IMO_NOTE, imo_criteria, turning_metrics, zigzag_metrics
from trackkit.models.manoeuvring import KNOT, naji7, reference_vessel
from trackkit.sim.seatrials import turning_circle, zigzag

vessel = reference_vessel()
L = naji7().length_overall  # m
speed = vessel.design["speed"]  # m/s
deg = np.pi / 180

nozzle = np.array([10.0, 20.0, 30.0]) * deg
turns = turning_circle(vessel.theta, vessel.norm, delta=nozzle, rpm=2000.0, speed=speed)
zz_angle = np.array([10.0, 20.0]) * deg
zigs = zigzag(vessel.theta, vessel.norm, delta=zz_angle, alpha=zz_angle, rpm=2000.0,
              speed=speed)
print(f"turning circles {turns.east.shape}, zig-zags {zigs.psi.shape} (trials, samples)")

# %%
# Trial metrics and the IMO criteria
# ----------------------------------
tm = turning_metrics(turns.t, turns.east, turns.north, turns.psi, L)
zm = zigzag_metrics(zigs.t, zigs.psi, zz_angle, zigs.east, zigs.north)
for i, d in enumerate(nozzle / deg):
    print(f"nozzle {d:2.0f} deg: advance {tm.advance[i]:5.1f} m, tactical diameter "
          f"{tm.tactical_diameter[i]:5.1f} m, D/L {tm.diameter_to_length[i]:4.1f}")
for i, a in enumerate(zz_angle / deg):
    print(f"{a:.0f}/{a:.0f} zig-zag: first overshoot {zm.first_overshoot[i] / deg:4.1f} deg, "
          f"second {zm.second_overshoot[i] / deg:4.1f} deg, period {zm.period[i]:4.1f} s")

# the standard takes the turning circle at the largest nozzle angle; one trial of each family
largest = type(tm)(*(a[-1] for a in tm))
zz10, zz20 = (type(zm)(*(a[i] for a in zm)) for i in (0, 1))
print(IMO_NOTE)
for c in imo_criteria(L, speed, turning=largest, zigzag10=zz10, zigzag20=zz20).values():
    scale, unit = (1 / deg, " deg") if "overshoot" in c.name else (1.0, " m")
    unit = "" if c.name == "paper_band" else unit  # D/L
    lower = "" if np.isinf(c.lower) else f"{c.lower * scale:.1f} <= "
    print(f"  {c.name}: {lower}{c.value * scale:.1f}{unit} <= {c.upper * scale:.1f}{unit}: "
          f"{'pass' if c.passed else 'fail'}")

# %%
# Tracks and headings
# -------------------
# Left, the turning circles from the execute point (north is the approach course): the
# harder the nozzle, the tighter the circle. Right, the zig-zags' heading and nozzle angle
# against time: the heading overshoots each reversal by the first and second overshoots
# printed above.
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.5), width_ratios=(1, 1.4))
for i, d in enumerate(nozzle / deg):
    ax0.plot(turns.east[i], turns.north[i], label=f"nozzle {d:.0f} deg")
ax0.set_aspect("equal")
ax0.set_xlabel("east (m)")
ax0.set_ylabel("north (m)")
ax0.set_title(f"turning circles, {speed / KNOT:.0f} kn")
ax0.legend(fontsize="small")

for i, a in enumerate(zz_angle / deg):
    line, = ax1.plot(zigs.t, zigs.psi[i] / deg, label=f"{a:.0f}/{a:.0f}: heading")
    ax1.plot(zigs.t, zigs.delta[i] / deg, ls="--", color=line.get_color(),
             label=f"{a:.0f}/{a:.0f}: nozzle")
ax1.axhline(0.0, color="k", lw=0.5)
ax1.set_xlabel("time (s)")
ax1.set_ylabel("angle (deg, starboard positive)")
ax1.set_title("zig-zags")
ax1.legend(fontsize="small", ncol=2)
fig.tight_layout()
plt.show()
