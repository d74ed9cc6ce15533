"""
A decentralised bearings-only network: ``trackkit network``
===========================================================

Jalalipoor and Kardehi Moghaddam (2021) let a team of moving agents with passive bearing
sensors track several targets without a fusion centre: each agent turns batches of its own
and its neighbours' asynchronous bearings into composite maximum-likelihood measurements,
fuses them by a diffusion Kalman filter with its neighbours' tracks, and steers. This
tutorial runs the bundled three-agent, three-target scenario in one process for a few Monte
Carlo runs, shows how to run the same agents as separate operating-system processes
talking over ZeroMQ, and sets the agents' errors beside a centralised filter and the
network's posterior Cramér-Rao bound. :doc:`/network-comparison` sets the method against
the paper.

.. budget: 40 s
"""

# %%
# The bundled scenario: ``trackkit network net-baseline``
# -------------------------------------------------------
#
# ``net-baseline``: three agents 15-18 km apart heading north at 8 m/s, bearings every 5 s
# (each execution delayed at random by up to 5 s) with 2 deg noise, unlimited ranges, and
# three constant-velocity targets, two of which pass 300 m apart at 600 s:
#
# .. code-block:: bash
#
#    trackkit network net-baseline --runs 20
#    trackkit network net-baseline --runs 100 --workers 2   # blocks of 25 runs on Dask
#
# The command calls :func:`trackkit.experiments.network_mc.run_network_mc`, which runs
# :func:`trackkit.network.inprocess.run_network` for each run (each run is one multi-target
# problem whose agents execute one at a time), up to 25 runs stepped together
# (:func:`~trackkit.network.inprocess.run_network_block`: the agents' array work of all 25
# runs at one execution goes through :mod:`trackkit.network.lockstep` as one batched call,
# with the same numbers bit for bit as one run at a time), beside the centralised reference
# (:mod:`trackkit.network.central`: one EKF per target fed every bearing, with ideal
# association) and the centralised PCRLB on the agents' actual, steered paths. The
# scenario's default is 100 runs; here 2 runs, so the numbers below are noisy. With
# ``--workers`` or ``--scheduler`` (``workers=``, ``scheduler=``) each block of runs is one
# task on a Dask cluster (:func:`trackkit.experiments.executors.execute`), the blocks gathered
# in run order: the same bits as in this process.

import matplotlib.pyplot as plt
import numpy as np

from trackkit.experiments.network_mc import run_network_mc
from trackkit.network.bound import network_pcrlb
from trackkit.scenario.network import load_network

sc = load_network("net-baseline")
mc = run_network_mc(sc, runs=2)
print(f"{mc.runs} runs of {mc.duration:.0f} s, {mc.n_agents} agents, {mc.n_targets} targets; "
      f"{mc.seconds.mean():.1f} s per run")
print(f"every agent holds all targets at the end in {mc.held_final.mean():.0%} of "
      "(agent, run) cases")

# %%
# Position RMSE over the last 20% of the run, per agent and target, beside the centralised
# filter and the PCRLB (the mean over runs of each run's bound, which
# :doc:`/network-comparison` explains is the one to report when the geometry varies):

rmse = mc.window_rmse("pos", "last")
central = mc.window_rmse("pos", "last", central=True)
bound = mc.window_bound("pos", "last")
print("agent  target  RMSE (m)  centralised (m)  PCRLB (m)  agent/centralised")
for a in range(mc.n_agents):
    for j in range(mc.n_targets):
        print(f"{a + 1:5d} {j + 1:7d} {rmse[a, j]:9.0f} {central[a, j]:16.0f} "
              f"{bound[a, j]:10.0f} {rmse[a, j] / central[a, j]:18.2f}")

# %%
# After the combination step the agents share one estimate, so their rows agree to a few
# metres. The centralised filter knows which target each bearing came from; the agents
# have to associate, and fuse composites of batches of bearings rather than single ones.
# Two runs make each RMSE uncertain by some tens of per cent, enough for a ratio to fall
# below 1 or an RMSE below the bound; at 100 runs (:doc:`/network-comparison`) every
# (agent, target) pair comes within 1.5 times the centralised filter.
#
# The bound itself: :func:`trackkit.network.bound.network_pcrlb`
# ----------------------------------------------------------------
#
# The bound takes one event per agent execution: its time, the agent's position, the true
# target states and the bearing standard deviation. Fed every agent's executions it is the
# centralised bound the Monte Carlo reports; fed one agent's it is what that agent could
# reach alone on the same path, without its neighbours. Run 0's traces
# (:class:`trackkit.network.inprocess.Trace`) hold all of it:

ex = mc.example
t = np.stack([tr.time for tr in ex.agents])          # (A, E)
pos = np.stack([tr.position for tr in ex.agents])    # (A, E, 2)
truth = np.stack([tr.truth for tr in ex.agents])     # (A, E, Nt, 4)
sigma = np.broadcast_to(sc.sigma_rad()[:, None], t.shape)
prior = np.diag([sc.report.prior_pos_std_m**2] * 2 + [sc.report.prior_vel_std_mps**2] * 2)
A, E, Nt = truth.shape[:3]

together = network_pcrlb(prior, t.ravel(), pos.reshape(-1, 2), truth.reshape(-1, Nt, 4),
                         sigma.ravel(), q=sc.network.q)
alone = network_pcrlb(prior, t[0], pos[0], truth[0], sigma[0], q=sc.network.q)
print("position PCRLB at the end of run 0, per target (m)")
print("  all agents' bearings:", np.round(together.position_rmse[-1]).tolist())
print("  agent 1's alone:     ", np.round(alone.position_rmse[-1]).tolist())

# %%
# Agents as processes over ZeroMQ
# -------------------------------
#
# .. code-block:: bash
#
#    trackkit network net-baseline --agents processes
#    trackkit network net-baseline --agents processes --loss 0.1 --delay 2 --kill 2@400:500
#
# With ``agents="processes"`` every agent is its own interpreter
# (:func:`trackkit.network.processes.run_network_processes`) that talks only over ZeroMQ
# to an environment owning the truth, the schedule and the channel; simulated time travels
# in every message, so without loss the tracks are the in-process run's bit for bit
# (``tests/network/test_processes.py`` checks it). From Python it is the same call with
# ``agents="processes"``; a first look can cut the run short, here to 100 s (the first
# tracks confirm after about a minute), and compare the two modes:
#
# .. code-block:: python
#
#    short = sc.model_copy(
#        update={"network": sc.network.model_copy(update={"duration_s": 100.0})})
#    inproc = run_network_mc(short, runs=1)
#    procs = run_network_mc(short, runs=1, agents="processes")
#    same = all(np.array_equal(p.ids, q.ids) and np.array_equal(p.mean, q.mean)
#               and np.array_equal(p.cov, q.cov)
#               for p, q in zip(inproc.example.agents, procs.example.agents, strict=True))
#    print(same, procs.sent[0], procs.delivered[0])
#
# The channel and the deployment are arguments of the call: ``loss``, ``delay`` and
# ``outages`` (``[(1, 400.0, 500.0)]`` kills the second agent at 400 s and restarts it at
# 500 s), and ``deployment=Deployment(host="0.0.0.0", ...)``
# (:class:`trackkit.network.processes.Deployment`) for agents on other machines, their
# connections then authenticated and encrypted with ZeroMQ's CURVE.
#
# The block is shown, not run, on this page: each agent's process starts its own Python and
# imports trackkit before the first execution, and those three start-ups beside the Monte
# Carlo above do not fit this page's time budget on a build machine shared with other work.
# Run it yourself: it takes seconds, most of them the start-ups.

# %%
# The figure: run 0's agents (steered) and targets, with agent 1's confirmed tracks; then
# the position error pooled over the targets, against time, of agent 1 and of the
# centralised filter (RMSE over the 2 runs) beside the centralised PCRLB and what agent 1
# alone could reach.

fig, ax = plt.subplots(1, 2, figsize=(13, 5.2))
for a in range(A):
    ax[0].plot(pos[a, :, 0] / 1e3, pos[a, :, 1] / 1e3, lw=2, label=f"agent {a + 1}")
    ax[0].plot(*pos[a, 0] / 1e3, "k^", ms=6)
for j in range(Nt):
    ax[0].plot(truth[0, :, j, 0] / 1e3, truth[0, :, j, 1] / 1e3, "k--", lw=1, zorder=3,
               label="targets (truth)" if j == 0 else None)
    ax[0].plot(*truth[0, 0, j, :2] / 1e3, "ko", ms=4)
tr0 = ex.agents[0]
ax[0].plot(tr0.mean[:, 0] / 1e3, tr0.mean[:, 1] / 1e3, ".", color="C3", ms=2, alpha=0.5,
           label="agent 1's confirmed tracks")
ax[0].set(xlabel="east (km)", ylabel="north (km)", aspect="equal",
          title="run 0: agents and targets (start: markers)")
ax[0].legend(fontsize=8, loc="lower right")

mine = mc.rmse_over_time("pos", pooled=True)[0]
cen = mc.rmse_over_time("pos", central=True, pooled=True)[0]
pcrlb = mc.bound_over_time("pos", pooled=True)[0]
back = np.empty(alone.order.size, np.intp)
back[alone.order] = np.arange(alone.order.size)   # the bound after each of agent 1's events
solo = np.sqrt(np.mean(alone.position_rmse[back] ** 2, -1))
ax[1].semilogy(mc.time, mine, color="C0", label=f"agent 1 (RMSE, {mc.runs} runs)")
ax[1].semilogy(mc.time, cen, color="C2", label="centralised filter (RMSE)")
ax[1].semilogy(mc.time, pcrlb, "k-", lw=1.5, label="centralised PCRLB")
ax[1].semilogy(mc.time, solo, "k:", lw=1.5, label="PCRLB, agent 1 alone (run 0)")
ax[1].axvspan(*mc.window_s("last"), color="0.9", zorder=0)
ax[1].set(xlabel="time (s)", ylabel="position error, RMS over targets (m)",
          title="error against the bound (grey: last 20%)")
ax[1].legend(fontsize=8)
fig.tight_layout()
plt.show()
