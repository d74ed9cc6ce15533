"""``trackkit network`` on Dask: the same runs of net-baseline (shortened to 300 s) on two local
Dask workers, in blocks of 2, give the same bytes as in this process in one block of 25; the
cluster is gone when the command ends; the options that cannot go together are refused in
words."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from tests.cli_helpers import Ran, assert_user_error, trackkit
from trackkit.experiments.network_mc import NETWORK_BLOCK, run_network_mc
from trackkit.scenario.network import load_network

RUNS = 4
BLOCK = 2  # two blocks: one task for each worker
DURATION = 300.0  # a fifth of net-baseline: the close pass and the steering still happen
COMPARED = ("results.json", "report.html", "paths.png", "errors.png", "gospa.png")


def _short_baseline(where: Path) -> Path:
    """net-baseline as ``trackkit show`` writes it, with a shorter duration."""
    ran = trackkit("show", "net-baseline")
    assert ran.code == 0, ran.text
    text = ran.out.replace("duration_s = 1000.0\n", f"duration_s = {DURATION}\n")
    assert f"duration_s = {DURATION}\n" in text
    path = where / "net-baseline.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def in_process(tmp_path_factory) -> tuple[Path, Path]:
    """The scenario file and the in-process output (one block of 25 holding every run)."""
    where = tmp_path_factory.mktemp("net-dask")
    scenario = _short_baseline(where)
    ran = trackkit("network", str(scenario), "--runs", str(RUNS), "--out", str(where / "here"))
    assert ran.code == 0, ran.text
    assert "agents in this process" in ran.text
    return scenario, where / "here"


def _alone(*args: str) -> tuple[Ran, int]:
    """``trackkit ARGS`` in its own session (its process group's id, the pid, returned: every
    process it starts, Dask's nannies and workers among them, stays in that group)."""
    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1"}
    env.pop("TRACKKIT_DEBUG", None)
    p = subprocess.Popen([sys.executable, "-m", "trackkit.cli", *args], env=env, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    out, err = p.communicate(timeout=300)
    return Ran(p.returncode, out, err), p.pid


def _group_is_empty(pgid: int, wait: float = 5.0) -> bool:
    """No process left in group ``pgid`` within ``wait`` s (multiprocessing's resource
    tracker outlives the command by a moment: it exits when it sees the command's pipe
    close)."""
    t0 = time.monotonic()
    while True:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        if time.monotonic() - t0 > wait:
            return False
        time.sleep(0.1)


def _assert_same_files(a: Path, b: Path) -> None:
    for name in COMPARED:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    doc = json.loads((a / "results.json").read_text())
    assert doc["runs"] == RUNS and doc["duration_s"] == DURATION


def test_two_local_dask_workers_give_the_in_process_bytes(in_process, tmp_path):
    scenario, here = in_process
    ran, pgid = _alone("network", str(scenario), "--runs", str(RUNS), "--block", str(BLOCK),
                       "--workers", "2", "--out", str(tmp_path / "dask"))
    try:
        assert ran.code == 0, ran.text
        assert "blocks of runs on 2 local Dask workers" in ran.text
        _assert_same_files(here, tmp_path / "dask")
        assert _group_is_empty(pgid), "the command left its Dask cluster running"
    finally:
        if not _group_is_empty(pgid, wait=0.0):
            os.killpg(pgid, signal.SIGKILL)


def test_a_running_scheduler_gives_the_in_process_bytes(in_process, tmp_path):
    """--scheduler: the blocks run on a cluster started here (and shut down here), the
    command's own client closed when it ends."""
    from dask.distributed import Client, LocalCluster

    scenario, here = in_process
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        pids = list(client.run(os.getpid).values())
        ran = trackkit("network", str(scenario), "--runs", str(RUNS), "--block", str(BLOCK),
                       "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "d"))
        assert ran.code == 0, ran.text
        assert f"on the Dask scheduler at {cluster.scheduler_address}" in ran.text
        ran_here = client.run(lambda dask_worker: sorted(
            {str(rec[0]) for rec in dask_worker.state.log
             if str(rec[0]).startswith("trackkit-")}))
        # the blocks ran on the cluster's workers: trackkit-TASK-FIRST, one per block
        assert sorted(k for keys in ran_here.values() for k in keys) == [
            "trackkit-0-0", "trackkit-1-1"]
    _assert_same_files(here, tmp_path / "d")
    assert len(pids) == 2
    for pid in pids:
        try:
            assert psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
        except psutil.NoSuchProcess:
            pass


def test_the_library_on_dask_gives_the_same_arrays_and_example():
    """run_network_mc with workers: every array of the Monte Carlo and run 0's example the
    same bits as in process (here with the default block, so the tasks differ from the
    in-process blocks too)."""
    sc = load_network("net-baseline")
    d = sc.model_dump()
    d["network"]["duration_s"] = 100.0
    short = type(sc).model_validate(d)
    a = run_network_mc(short, runs=3, block=NETWORK_BLOCK)
    b = run_network_mc(short, runs=3, block=1, workers=2)
    for name in ("count", "gospa", "central_count", "central_gospa", "central_held_final",
                 "bound_pos", "bound_vel", "bound_rng", "held_final", "final_range",
                 "spacing", "sent", "delivered", "lost", "late", "recovered", "refused",
                 "time"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name
    for kind in a.err:
        assert a.err[kind].tobytes() == b.err[kind].tobytes(), kind
        assert a.central_err[kind].tobytes() == b.central_err[kind].tobytes(), kind
    assert b.wall.shape == (3,) and np.all(b.wall > 0)
    assert a.example_targets.tobytes() == b.example_targets.tobytes()
    for ta, tb in zip(a.example.agents, b.example.agents, strict=True):
        assert ta.mean.tobytes() == tb.mean.tobytes()
    assert a.example.sent == b.example.sent


def test_options_that_do_not_go_together_are_refused(in_process):
    scenario, _ = in_process
    assert_user_error(trackkit("network", str(scenario), "--workers", "2", "--scheduler",
                               "tcp://h:1"), 2, "--workers 2", "--scheduler tcp://h:1",
                      "give one")
    for dask in (["--workers", "2"], ["--scheduler", "tcp://h:1"]):
        assert_user_error(trackkit("network", str(scenario), "--agents", "processes", *dask),
                          2, "--agents processes", "--workers", "--scheduler",
                          "--agents inprocess")
    assert_user_error(trackkit("network", str(scenario), "--block", "0"), 2, "--block", "0",
                      ">= 1")
    with pytest.raises(ValueError, match="agents = 'processes' with workers = 2"):
        run_network_mc(load_network("net-baseline"), runs=1, agents="processes", workers=2)


def test_the_block_option_shows_the_library_default():
    """``--block``'s shown default is the library's (the command does not import it)."""
    import typing

    from trackkit.cli.network import network

    hint = typing.get_type_hints(network, include_extras=True)["block"]
    option = next(m for m in hint.__metadata__ if hasattr(m, "show_default"))
    assert option.show_default.startswith(f"{NETWORK_BLOCK}, ")
