"""Campaigns (``trackkit.experiments.sweep``): parameters, designs, point seeds, and the same bits
in this process and on a Dask cluster one of whose workers is killed mid-campaign.

The campaign is a 3 x 3 grid over the full ``bo-cv`` (its seven filters, the particle filter
among them, over 1 800 s), 6 runs per point in blocks of 2: 27 blocks. The checks of
parameters and designs use a short ``bo-cv`` (EKF and UKF, 900 s), which costs less to plan."""

from __future__ import annotations

import json
import os
import signal
import time

import numpy as np
import psutil
import pytest

from trackkit.experiments.checkpoint import CampaignStore
from trackkit.experiments.sweep import (
    Listener,
    canonical,
    parse_param,
    plan_campaign,
    point_id,
    point_seed,
    run_campaign,
)
from trackkit.report.sweep_report import sweep_table, write_sweep_csv
from trackkit.scenario import dumps, load, parse

PARAMS = ("filters.EKF.motion.q=1e-5,1e-4,1e-3", "sensor.sigma_deg=0.5,1,2")
RUNS, BLOCK, SEED = 6, 2, 11
#: the campaign's blocks: 9 points of RUNS / BLOCK blocks
BLOCKS = 9 * -(-RUNS // BLOCK)


def full_bo_cv():
    """bo-cv as bundled, its runs, seed and block those of the campaign."""
    d = load("bo-cv").model_dump()
    d["notes"] = []
    d["run"] = {"runs": RUNS, "seed": SEED, "block": BLOCK}
    return parse(d)


def full_bo_cv_toml(path):
    path.write_text(dumps(full_bo_cv()), encoding="utf-8")
    return path


def short_bo_cv():
    """bo-cv with two filters over its first 900 s (the manoeuvre at 600-690 s)."""
    d = load("bo-cv").model_dump()
    d["filters"] = [f for f in d["filters"] if f["name"] in ("EKF", "UKF")]
    d["time"]["duration_s"] = 900.0
    d["report"]["average_from_s"] = 700.0
    d["notes"] = []
    d["run"] = {"runs": RUNS, "seed": SEED, "block": BLOCK}
    return parse(d)


def short_bo_cv_toml(path):
    path.write_text(dumps(short_bo_cv()), encoding="utf-8")
    return path


def campaign_3x3(**kw):
    return plan_campaign(full_bo_cv(), [parse_param(p) for p in PARAMS], **kw)


def outputs(campaign, store: CampaignStore, docs) -> dict[str, bytes]:
    """The deterministic outputs: every point's result.json and the sweep table as CSV."""
    out = {p.id: (store.point_dir(p.id) / "result.json").read_bytes() for p in campaign.points}
    csv = store.root / "sweep.csv"
    write_sweep_csv(sweep_table(campaign, docs), csv)
    out["sweep.csv"] = csv.read_bytes()
    return out


@pytest.fixture(scope="module")
def campaign():
    return campaign_3x3()


@pytest.fixture(scope="module")
def in_process(campaign, tmp_path_factory):
    """The reference: the campaign in this process."""
    store = CampaignStore(tmp_path_factory.mktemp("inprocess"))
    store.open(campaign.identity())
    docs = run_campaign(campaign, store)
    return outputs(campaign, store, docs)


# --- parameters -------------------------------------------------------------------------------


def test_parse_param_values_ranges_and_lists():
    p = parse_param("sensor.sigma_deg=1,2.5,4")
    assert p.path == "sensor.sigma_deg" and p.values == (1, 2.5, 4) and not p.is_range
    r = parse_param("filters.EKF.motion.q=log:1e-6:1e-2")
    assert r.is_range and r.log and (r.low, r.high) == (1e-6, 1e-2)
    assert parse_param("observers[0].sensor.sigma_deg=1:3").path == "observers.0.sensor.sigma_deg"
    lists = parse_param("filters.EKF.r0_diag_si=[3e-4],[1.2e-3, 2.0]")
    assert lists.values == ([3e-4], [1.2e-3, 2.0])
    assert parse_param("observers.0.sensor.convention=math,nautical").values == ("math",
                                                                                  "nautical")
    for bad, words in [("sensor.sigma_deg", "PATH=V1,V2"), ("=1,2", "PATH=V1,V2"),
                       ("sensor.sigma_deg=1,,2", "empty value"),
                       ("sensor.sigma_deg=4:1", "LOW < HIGH"),
                       ("sensor.sigma_deg=log:0:1", "0 < LOW")]:
        with pytest.raises(ValueError, match=words):
            parse_param(bad)


@pytest.mark.parametrize("param, words", [
    ("sensor.sigma_deg=-1,2", ["sensor.sigma_deg", "-1", "greater than 0"]),
    ("sensor.sigma_dg=1", ["sensor.sigma_dg", "no field 'sigma_dg'", "sigma_deg"]),
    ("filters.XKF.motion.q=1", ["filters.XKF", "'XKF'", "['EKF', 'UKF']"]),
    ("filters.EKF.motion.q=abc", ["filters.EKF.motion.q", "abc", "valid number"]),
    ("run.runs=1,2", ["run.runs", "--runs"]),
    ("time.step_s=7", ["time.step_s", "7", "whole number of steps"]),
])
def test_bad_values_name_the_parameter_the_value_and_what_is_allowed(param, words):
    with pytest.raises(ValueError) as err:
        plan_campaign(short_bo_cv(), [parse_param(param)], runs=2)
    for w in words:
        assert w in str(err.value), str(err.value)


def test_a_filter_assumption_is_swept_apart_from_the_truth():
    c = plan_campaign(short_bo_cv(), [parse_param("filters.UKF.motion.q=1e-3"),
                                      parse_param("filters.EKF.prior.std=[1e3,1e3,2,2]")],
                      runs=2)
    s = c.points[0].scenario
    assert s.target.motion.q == 1e-4  # the truth keeps its q
    ukf = next(f for f in s.filters if f.name == "UKF")
    ekf = next(f for f in s.filters if f.name == "EKF")
    assert ukf.motion.q == 1e-3 and ukf.motion.model == "ConstantVelocity"
    assert ekf.motion is None and ekf.prior.std == [1e3, 1e3, 2.0, 2.0]
    assert c.points[0].values == {"filters.UKF.motion.q": 1e-3,
                                  "filters.EKF.prior.std": [1e3, 1e3, 2.0, 2.0]}


def test_values_are_parsed_to_the_field_type():
    c = plan_campaign(short_bo_cv(), [parse_param("sensor.sigma_deg=1,2")], runs=2)
    assert [p.values["sensor.sigma_deg"] for p in c.points] == [1.0, 2.0]
    assert all(isinstance(p.values["sensor.sigma_deg"], float) for p in c.points)
    # an index and a name are one field: one spelling in the table and the hashes
    by_index = plan_campaign(short_bo_cv(), [parse_param("filters.1.motion.q=1e-3")], runs=2)
    assert list(by_index.points[0].values) == ["filters.UKF.motion.q"]


# --- designs and seeds ------------------------------------------------------------------------


def test_a_points_seed_is_unchanged_when_points_are_added():
    small = plan_campaign(short_bo_cv(), [parse_param("sensor.sigma_deg=1,2"),
                                          parse_param("observers.0.initial.speed_kn=8")],
                          runs=2)
    more = plan_campaign(short_bo_cv(), [parse_param("sensor.sigma_deg=4,2,0.5,1"),
                                         parse_param("observers.0.initial.speed_kn=8,6")],
                         runs=2)
    seeds = {p.id: (p.seed, p.key) for p in more.points}
    assert len(more.points) == 8
    for p in small.points:
        assert seeds[p.id] == (p.seed, p.key)
        assert p.seed == point_seed(SEED, p.values) and p.id == point_id(p.values)
    assert len({p.seed for p in more.points}) == 8
    # another campaign seed: other seeds
    other = plan_campaign(short_bo_cv(), [parse_param("sensor.sigma_deg=1,2")], runs=2, seed=12)
    assert {p.seed for p in other.points}.isdisjoint({p.seed for p in small.points})


def test_points_differing_only_in_filter_assumptions_share_their_runs(campaign):
    by_sigma: dict[float, set[int]] = {}
    for p in campaign.points:
        by_sigma.setdefault(p.values["sensor.sigma_deg"], set()).add(p.seed)
    assert len(by_sigma) == 3 and all(len(s) == 1 for s in by_sigma.values())
    assert len({p.id for p in campaign.points}) == 9
    assert canonical({"b": 1.0, "a": [1, 2]}) == '{"a":[1,2],"b":1.0}'


def test_random_and_latin_hypercube_designs_are_seeded():
    params = [parse_param("sensor.sigma_deg=log:0.5:4"),
              parse_param("filters.EKF.motion.q=1e-5,1e-3")]
    lhs = plan_campaign(short_bo_cv(), params, design="lhs", points=5, runs=2)
    again = plan_campaign(short_bo_cv(), params, design="lhs", points=5, runs=2)
    assert [p.values for p in lhs.points] == [p.values for p in again.points]
    sig = sorted(p.values["sensor.sigma_deg"] for p in lhs.points)
    # one point in each of the 5 log-spaced strata of [0.5, 4]
    edges = [0.5 * 8 ** (k / 5) for k in range(6)]
    assert all(edges[k] <= s < edges[k + 1] for k, s in enumerate(sig))
    rnd = plan_campaign(short_bo_cv(), params, design="random", points=3, runs=2)
    rnd5 = plan_campaign(short_bo_cv(), params, design="random", points=5, runs=2)
    assert [p.values for p in rnd5.points[:3]] == [p.values for p in rnd.points]
    with pytest.raises(ValueError, match="--points"):
        plan_campaign(short_bo_cv(), params, design="random", runs=2)


def test_the_sweep_table_of_the_scenario_file(tmp_path):
    d = short_bo_cv().model_dump()
    d["sweep"] = {"params": {"sensor.sigma_deg": "1:3", "filters.EKF.motion.q": [1e-5]},
                  "points": 3}
    c = plan_campaign(parse(d))
    assert [p.values["sensor.sigma_deg"] for p in c.points] == [1.0, 2.0, 3.0]
    d["sweep"] = {"params": {"sensor.sigma_deg": "3:1"}, "points": 3}
    with pytest.raises(ValueError, match="LOW < HIGH"):
        parse(d)


def test_adding_points_reuses_the_stored_ones(tmp_path):
    def run(values):
        c = plan_campaign(short_bo_cv(), [parse_param(f"sensor.sigma_deg={values}")], runs=4,
                          block=2)
        store = CampaignStore(tmp_path)
        store.open(c.identity())
        computed = []

        class Count(Listener):
            def stored(self, i, block):
                computed.append((c.points[i].values["sensor.sigma_deg"], block))

        run_campaign(c, store, listener=Count())
        return c, store, computed

    c1, store, computed = run("1,2")
    assert sorted(computed) == [(1.0, 0), (1.0, 1), (2.0, 0), (2.0, 1)]
    first = {p.id: (store.point_dir(p.id) / "result.json").read_bytes() for p in c1.points}
    c2, store, computed = run("0.5,1,2")
    assert sorted(computed) == [(0.5, 0), (0.5, 1)]  # only the new point ran
    for pid, doc in first.items():
        assert (store.point_dir(pid) / "result.json").read_bytes() == doc


# --- three ways, one result -------------------------------------------------------------------


def test_the_table_has_a_row_per_point_and_filter(campaign, in_process):
    rows = in_process["sweep.csv"].decode().splitlines()
    head = rows[0].split(",")
    assert head[:6] == ["point", "seed", "filters.EKF.motion.q", "sensor.sigma_deg", "filter",
                        "runs"]
    for col in ("rmse_position", "pcrlb_position", "rmse_pcrlb_position", "anees",
                "diverged_share"):
        assert col in head
    assert len(rows) == 1 + 9 * 7
    doc = json.loads(in_process[campaign.points[0].id])
    assert doc["runs"] == RUNS and doc["seed"] == campaign.points[0].seed
    ekf = doc["filters"]["EKF"]
    assert ekf["rmse_pcrlb"]["position"] == ekf["rmse"]["position"] / doc["pcrlb"]["position"]


def _children() -> dict[int, str]:
    """Live child processes of this one (the multiprocessing resource tracker, which a
    spawned process starts once and keeps until this interpreter exits, is not a leak)."""
    out = {}
    for p in psutil.Process().children(recursive=True):
        try:
            if p.status() == psutil.STATUS_ZOMBIE:
                continue
            cmd = " ".join(p.cmdline())
        except psutil.Error:
            continue
        if "resource_tracker" not in cmd:
            out[p.pid] = cmd
    return out


def _no_new_children(before: dict[int, str], timeout: float = 20.0) -> None:
    t0 = time.monotonic()
    while True:
        left = {pid: cmd for pid, cmd in _children().items() if pid not in before}
        if not left or time.monotonic() - t0 > timeout:
            break
        time.sleep(0.2)
    assert not left, f"processes left behind: {left}"


@pytest.mark.slow
def test_a_dask_worker_killed_mid_campaign_loses_no_run(campaign, in_process, tmp_path):
    from dask.distributed import Client, LocalCluster

    before = _children()
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    killed: list[int] = []
    try:
        with Client(cluster) as client:
            pids = sorted(client.run(os.getpid).values())
        assert len(pids) == 2

        class KillAWorker(Listener):
            def stored(self, i, block):  # after the first block is stored, the other
                if not killed:           # blocks queued or running on both workers
                    os.kill(pids[0], signal.SIGKILL)
                    killed.append(pids[0])

        store = CampaignStore(tmp_path)
        store.open(campaign.identity())
        docs = run_campaign(campaign, store, scheduler=cluster.scheduler_address,
                            listener=KillAWorker())
        assert killed == [pids[0]]
        try:
            gone = psutil.Process(pids[0]).status() == psutil.STATUS_ZOMBIE
        except psutil.NoSuchProcess:
            gone = True
        assert gone
        with Client(cluster) as client:  # the nanny started a new worker
            assert len(client.run(os.getpid)) == 2
        assert all(len(store.stored_blocks(p.id)) == BLOCKS // 9 for p in campaign.points)
        log = getattr(cluster.scheduler, "transition_log", None)  # the scheduler is in-process
        if log is not None:  # the killed worker was running blocks: they ran again elsewhere
            assert any(str(rec[0]).startswith("trackkit-sweep-") and rec[1] == "processing"
                       and rec[2] in ("released", "waiting", "no-worker") for rec in log)
        assert outputs(campaign, store, docs) == in_process
    finally:
        cluster.close()
    _no_new_children(before)


def test_a_block_failing_on_dask_stops_the_campaign_naming_point_and_block(tmp_path,
                                                                           monkeypatch):
    """Dask's retries are the attempts; the worker runs in this process (threads), so the
    failure can be injected here."""
    from dask.distributed import LocalCluster

    from trackkit.experiments import sweep as sweep_module
    from trackkit.experiments.sweep import ATTEMPTS, BlockFailed

    c = plan_campaign(short_bo_cv(), [parse_param("sensor.sigma_deg=1,2")], runs=4, block=2)
    real = sweep_module.run_blocks
    tries = []

    def faulty(s, blocks, progress=None):
        if s.run.seed == c.points[1].seed and blocks == [0]:
            tries.append(blocks)
            raise np.linalg.LinAlgError("Matrix is not positive definite")
        return real(s, blocks, progress)

    monkeypatch.setattr(sweep_module, "run_blocks", faulty)
    store = CampaignStore(tmp_path)
    store.open(c.identity())
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        with pytest.raises(BlockFailed) as err:
            run_campaign(c, store, scheduler=cluster.scheduler_address)
    assert len(tries) == ATTEMPTS
    assert str(err.value) == (
        f"point {c.points[1].id} (sensor.sigma_deg=2), block 0 (runs 0-1) failed 3 times: "
        "LinAlgError: Matrix is not positive definite")
    assert store.stored_blocks(c.points[0].id) == {0, 1}  # what finished stays stored
