"""
Campaigns on a Dask cluster: sweeps, checkpoints, resume
========================================================

A campaign runs the full Monte Carlo comparison at every point of a sweep, and can take hours:
it must survive a Ctrl-C, a killed job or a lost machine without losing or changing a result.
Here you run a small campaign over the bearing noise of ``bo-cv`` on a local Dask cluster of
two workers, interrupt it after a few blocks, look at its checkpoint store, resume it so that
only the missing blocks run, and check that the result is, bit for bit, the one an
uninterrupted campaign gives. The same machinery draws the mis-specification plane of Hashemi
and Alfi (2019), every filter's process and measurement noise scaled together, on
:doc:`/dbt-comparison`.

.. budget: 30 s
"""

# %%
# The command
# -----------
#
# .. code-block:: bash
#
#     trackkit sweep bo-cv --param sensor.sigma_deg=0.5,1,2 --runs 200 --block 50 \
#         --workers 2 --out my-sweep/
#     # ... Ctrl-C, a killed job, a lost machine ...
#     trackkit sweep bo-cv --param sensor.sigma_deg=0.5,1,2 --runs 200 --block 50 \
#         --workers 2 --out my-sweep/       # the same command again: it resumes
#
# ``--workers 2`` starts a local cluster of two single-threaded worker processes;
# ``--scheduler tcp://HOST:8786`` sends the blocks to a cluster that is already running. The
# unit of work and of checkpoints is the *block* (``--block`` runs of one point): every
# finished block is stored at once, with an atomic write. The command calls
# :func:`trackkit.experiments.sweep.plan_campaign`,
# :meth:`trackkit.experiments.checkpoint.CampaignStore.open` and
# :func:`trackkit.experiments.sweep.run_campaign`; the same from Python follows, on a
# shorter ``bo-cv`` (two filters, the EKF and the UKF) and 120 runs per point in blocks of 40,
# so the numbers are from that reduced campaign.

import json
import logging
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
from dask.distributed import LocalCluster

from trackkit.experiments.checkpoint import CampaignMismatch, CampaignStore
from trackkit.experiments.sweep import Listener, parse_param, plan_campaign, run_campaign
from trackkit.scenario import load, parse

d = load("bo-cv").model_dump()
d["filters"] = [f for f in d["filters"] if f["name"] in ("EKF", "UKF")]
d["notes"] = []
base = parse(d)

param = parse_param("sensor.sigma_deg=0.5,1,2")
campaign = plan_campaign(base, [param], runs=120, seed=11, block=40)
print(f"{len(campaign.points)} points x {campaign.blocks_per_point} blocks of "
      f"{campaign.block} runs")
for p in campaign.points:
    print(f"  point {p.id}: {p.label()}, seed {p.seed}")

# %%
# A point's seed is a hash of the campaign seed and the point's values, never its place in the
# list, so adding a point later leaves the others' runs as they were.
#
# The cluster, and an interruption
# --------------------------------
#
# Two workers in this process (threads: they start in a fraction of a second; ``processes=True``
# gives each its own process, as ``--workers`` does). ``run_campaign`` takes the scheduler's
# address. A :class:`trackkit.experiments.sweep.Listener` is told of every stored block; this
# one stops the campaign after four, as a Ctrl-C would.

cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                       dashboard_address=None, silence_logs=logging.ERROR)


class Interrupted(Exception):
    """Stands for a Ctrl-C."""

class StopAfter(Listener):
    def __init__(self, blocks: int) -> None:
        self.left = blocks

    def stored(self, i: int, block: int) -> None:
        self.left -= 1
        if self.left == 0:
            raise Interrupted


root = Path(tempfile.mkdtemp())
store = CampaignStore(root / "my-sweep")
store.open(campaign.identity())
try:
    run_campaign(campaign, store, scheduler=cluster.scheduler_address, listener=StopAfter(4))
except Interrupted:
    print("interrupted")

# %%
# The checkpoint store
# --------------------
#
# :class:`trackkit.experiments.checkpoint.CampaignStore` keeps, in the campaign directory,
# ``campaign.json`` (what the blocks were computed from: a hash of the scenario, the swept
# parameters, the seed, the runs, the block size and the code version), and under
# ``points/<id>/`` each point's values, seed and key (``point.json``), its finished blocks
# (``block-NNNNNN.tkb``: a JSON header and an ``.npz`` of arrays, read without pickle) and,
# once every block is there, its combined ``result.json``.

for f in sorted(store.root.rglob("*")):
    if f.is_file():
        print(f"{str(f.relative_to(store.root)):45s} {f.stat().st_size:>8,d} bytes")
identity = json.loads((store.root / "campaign.json").read_text(encoding="utf-8"))["identity"]
print({k: identity[k] for k in ("parameters", "seed", "runs", "block")})
print("code:", identity["code"])

# %%
# A store opened for another campaign (here: other runs per point) refuses, naming what
# changed, rather than mix blocks of two campaigns; ``--fresh`` on the command line (``fresh=
# True``) discards the stored blocks instead.

other = plan_campaign(base, [param], runs=80, seed=11, block=40)
try:
    CampaignStore(store.root, "--out my-sweep/").open(other.identity())
except CampaignMismatch as err:
    print(err)

# %%
# Resume
# ------
#
# The same call again. ``run_campaign`` reads what is stored, runs only the blocks that are
# missing and combines each point once all its blocks are there. The listener counts what is
# computed now.


class Count(Listener):
    def start(self, campaign, stored_runs, stored_blocks, finished) -> None:
        self.before = sum(stored_blocks)
        self.now = 0

    def stored(self, i: int, block: int) -> None:
        self.now += 1


count = Count()
resumed = run_campaign(campaign, store, scheduler=cluster.scheduler_address, listener=count)
total = len(campaign.points) * campaign.blocks_per_point
print(f"{count.before} of {total} blocks were stored; {count.now} computed on resuming")
cluster.close()

# %%
# The same result as an uninterrupted campaign
# --------------------------------------------
#
# The reference: the whole campaign, uninterrupted, in this process (no cluster) and in a
# fresh directory. Each run draws from its own generator, a block's sums depend on that block
# alone and blocks combine exactly in any order, so the two must agree to the last bit: the
# result documents are equal, and so are the ``result.json`` files byte for byte.

fresh = CampaignStore(root / "reference")
fresh.open(campaign.identity())
reference = run_campaign(campaign, fresh)
same_files = all((store.point_dir(p.id) / "result.json").read_bytes()
                 == (fresh.point_dir(p.id) / "result.json").read_bytes()
                 for p in campaign.points)
print("documents equal:", resumed == reference, "  result.json files identical:", same_files)

# %%
# The swept metric
# ----------------
#
# Each point's document holds, per filter, the RMSE of each error group averaged after
# convergence, its ratio to the PCRLB, ANEES and the runs that diverged (``trackkit sweep``
# also writes them as ``sweep.csv`` and ``sweep.parquet``, with line plots and a report). The
# bound grows with the bearing noise, and so does every filter's error.

sigmas = [doc["values"][campaign.params[0].path] for doc in resumed]
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
for f in base.filters:
    ax1.plot(sigmas, [doc["filters"][f.name]["rmse"]["position"] for doc in resumed], "o-",
             label=f.name)
    ax2.plot(sigmas, [doc["filters"][f.name]["rmse_pcrlb"]["position"] for doc in resumed],
             "o-", label=f.name)
ax1.plot(sigmas, [doc["pcrlb"]["position"] for doc in resumed], "k--", lw=2,
         label=r"$\sqrt{\mathrm{PCRLB}}$")
ax2.axhline(1.0, color="k", lw=0.8)
ax1.set_ylabel(f"position RMSE, t >= {base.report.average_from_s:g} s [m]")
ax2.set_ylabel(r"RMSE / $\sqrt{\mathrm{PCRLB}}$ [-]")
for ax in (ax1, ax2):
    ax.set_xlabel("bearing noise sigma [deg]")
    ax.legend()
ax1.set_title(f"{campaign.runs} runs per point, interrupted and resumed")
fig.tight_layout()
plt.show()
