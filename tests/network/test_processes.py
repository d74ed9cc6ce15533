"""The agents of Jalalipoor and Kardehi Moghaddam (2021) as operating-system processes over ZeroMQ
(``network.processes``): the same tracks as the in-process run, the channel's counts, kill and
restart, the schema check, clean shutdown, and ``trackkit network --agents processes``. Every test
starts the processes it needs and checks that none is left."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
import zmq

from tests.cli_helpers import assert_user_error, trackkit
from tests.test_network_scenarios import TINY
from trackkit.network.agents import PAYLOAD_VERSION, Payload, empty_bearings
from trackkit.network.inprocess import run_network
from trackkit.network.processes import (
    AgentError,
    Deployment,
    _Environment,
    decode_payload,
    encode,
    run_network_processes,
    settings_from_dict,
    settings_to_dict,
)
from trackkit.scenario.network import load_network

pytestmark = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(),
                                reason="the leak checks read /proc (Linux)")


def _agent_children() -> list[int]:
    """Pids of this process's children that run an agent (zombies included)."""
    me, out = os.getpid(), []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes()
        except OSError:
            continue  # exited meanwhile
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        if ppid == me and b"trackkit.network.processes" in cmd:
            out.append(int(d.name))
    return out


def _sockets() -> int:
    """Open socket descriptors of this process (ZeroMQ's TCP sockets among them)."""
    n = 0
    for fd in Path("/proc/self/fd").iterdir():
        try:
            n += os.readlink(fd).startswith("socket:")
        except OSError:
            pass
    return n


def _port_free(endpoint: str) -> bool:
    ctx = zmq.Context()
    s = ctx.socket(zmq.ROUTER)
    s.setsockopt(zmq.LINGER, 0)
    try:
        s.bind(endpoint)
        return True
    except zmq.ZMQError:
        return False
    finally:
        s.close(0)
        ctx.term()


def _setup(duration: float) -> tuple[tuple, dict]:
    sc = load_network("net-baseline")
    n = sc.network
    kw = dict(duration=duration, period=n.period_s, sigma=sc.sigma_rad(), mr=sc.meas_range(),
              cr=sc.comm_range(), max_delay=n.max_delay_s, q=n.q, steering=True)
    return (11, 0, sc.target_states(11, 0), sc.agent_states()), kw


@pytest.fixture(scope="module")
def pair():
    """One short steered baseline run (3 agents, 3 targets, 180 s), both ways."""
    args, kw = _setup(180.0)
    before = _sockets()
    ref = run_network(*args, central=True, **kw)
    got = run_network_processes(*args, central=True, **kw)
    return ref, got, before, _sockets()


def test_processes_equal_in_process_bit_for_bit(pair):
    ref, got, _, _ = pair
    assert len(got.agents) == len(ref.agents) == 3
    for a, (x, y) in enumerate(zip(ref.agents + [ref.central], got.agents + [got.central],
                                   strict=True)):
        for f in x._fields:
            u, v = getattr(x, f), getattr(y, f)
            if f == "reports":
                assert u == v, f"agent {a}: reports differ"
                continue
            assert u.dtype == v.dtype, f"agent {a}: {f} dtype {v.dtype} != {u.dtype}"
            assert np.array_equal(u, v, equal_nan=True), f"agent {a}: {f} differs"
    assert got.agents[0].offsets[-1] > 0  # something was tracked
    assert (got.sent, got.delivered, got.lost) == (ref.sent, ref.delivered, ref.lost)
    assert got.lost == 0 and got.late == 0


def _own_address() -> str:
    """This machine's outbound interface address (no packet is sent), else loopback."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("10.255.255.255", 1))
            return s.getsockname()[0]
        except OSError:
            return "127.0.0.1"


def test_agents_started_by_a_launcher_dial_the_advertised_address():
    """The way agents run on other machines: the environment listens on every interface,
    each agent is started through a command prefix (here ``env``, where ``ssh host`` would
    go) and dials the advertised address (this machine's own interface address): the same
    tracks as in process, bit for bit, and no process left. Without ``advertise`` the
    wildcard address is refused, naming it."""
    import sys

    args, kw = _setup(90.0)
    ref = run_network(*args, **kw)
    got = run_network_processes(*args, deployment=Deployment(
        host="0.0.0.0", advertise=_own_address(),
        launch={a: ["env", "TRACKKIT_LAUNCHED=1"] for a in range(3)},
        remote_python=sys.executable), **kw)
    for x, y in zip(ref.agents, got.agents, strict=True):
        np.testing.assert_array_equal(x.mean, y.mean)
        np.testing.assert_array_equal(x.offsets, y.offsets)
    assert got.endpoint.startswith("tcp://0.0.0.0:")
    assert (got.curve, got.refused) == (True, 0)  # off loopback: CURVE, keys made for the run
    assert _agent_children() == []
    with pytest.raises(ValueError, match="advertise"):
        run_network_processes(*args, deployment=Deployment(host="0.0.0.0", launch={0: ["env"]}),
                              **kw)
    with pytest.raises(ValueError, match="launch"):
        run_network_processes(*args, deployment=Deployment(launch={5: ["env"]}), **kw)


def test_no_process_socket_or_port_left_after_a_run(pair):
    _, got, before, after = pair
    assert _agent_children() == []
    assert after == before, f"{after - before} sockets left open"
    assert _port_free(got.endpoint)


@pytest.mark.parametrize("exc", [KeyboardInterrupt, RuntimeError])
def test_no_process_or_socket_left_after_a_run_that_raises(exc):
    args, kw = _setup(100.0)
    before = _sockets()
    seen: list[float] = []

    def stop_at_30s(t: float) -> None:
        seen.append(t)
        if t >= 30.0:
            assert len(_agent_children()) == 3  # they were running
            raise exc("stop")

    with pytest.raises(exc):
        run_network_processes(*args, on_event=stop_at_30s, **kw)
    assert seen[-1] >= 30.0
    assert _agent_children() == []
    assert _sockets() == before


def test_loss_and_delay_counts_add_up():
    args, kw = _setup(150.0)
    res = run_network_processes(*args, loss=0.3, delay=7.0, **kw)
    E = res.agents[0].time.shape[0]
    assert all(tr.time.shape[0] == E for tr in res.agents)  # the run completed
    assert res.sent == res.delivered + res.lost
    # 3 agents, 2 links each per execution; 30% lost, give or take
    assert res.sent == 3 * 2 * E
    assert 0.2 * res.sent < res.lost < 0.4 * res.sent
    # a 7 s delay with a 5 s period: most deliveries miss an execution
    assert 0 < res.late <= res.delivered
    assert _agent_children() == []


def test_kill_agent_2_and_restart(capsys):
    args, kw = _setup(400.0)
    kill, back = 150.0, 200.0
    res = run_network_processes(*args, outages=[(1, kill, back)], **kw)
    assert _agent_children() == []
    assert res.restarts == 1
    counts = [np.diff(tr.offsets) for tr in res.agents]
    t = res.agents[0].time
    # the others hold all 3 targets from 120 s on and never break while agent 2 is down
    for a in (0, 2):
        on = res.agents[a].time >= 120.0
        assert np.all(counts[a][on] == 3), f"agent {a + 1}: {counts[a][on].tolist()}"
    t1 = res.agents[1].time
    dead = (t1 >= kill) & (t1 < back)
    assert dead.any() and np.all(counts[1][dead] == 0)
    assert counts[1][t1 < kill][-1] == 3
    # agent 2 rebuilds its tracks: all 3 within 100 s of its restart, and keeps them
    rec = res.recovered[0]
    assert math.isfinite(rec) and rec < 100.0, rec
    assert np.all(counts[1][t1 >= back + rec] == 3)
    assert res.sent == res.delivered + res.lost and res.lost > 0  # sent to a dead agent
    with capsys.disabled():
        print(f"\n[kill agent 2 at {kill:g} s, restart {back:g} s: all targets held again "
              f"{rec:.1f} s after the restart; run {res.seconds:.1f} s, {t.shape[0]} "
              "executions per agent]")


def test_wrong_schema_version_is_refused():
    p = Payload(0, 1.0, empty_bearings(), np.zeros(0, np.int64), np.zeros((0, 4)),
                np.zeros((0, 4, 4)), np.zeros(0, np.int8), np.zeros(0, bool), np.zeros(2),
                np.zeros(2), math.inf)
    d = json.loads(json.dumps(p.to_dict()))
    assert decode_payload(d).version == PAYLOAD_VERSION
    bad = {**d, "version": PAYLOAD_VERSION + 1}
    with pytest.raises(ValueError, match=f"payload version = {PAYLOAD_VERSION + 1}"):
        decode_payload(bad)
    # and over the wire: a live agent refuses it, and the environment says so
    _, kw = _setup(10.0)
    env = _Environment("127.0.0.1", 0, 30.0, 60.0, 60.0)
    try:
        from trackkit.network.agents import AgentSettings

        env.start([0], [AgentSettings()], 1, [(0, 3, 0)])
        step = encode("step", 0, 1.0, inbox=[bad], bearings={
            "z": [], "t": [], "sensor": [], "sigma": [], "source": []},
            position=[0.0, 0.0], velocity=[0.0, 0.0], course=0.0, speed=0.0, dt_next=5.0)
        with pytest.raises(AgentError, match=f"payload version = {PAYLOAD_VERSION + 1}; "
                           f"expected {PAYLOAD_VERSION}"):
            env.request(0, step)
    finally:
        env.close()
    assert _agent_children() == []


def test_settings_cross_the_wire_unchanged():
    from trackkit.network.agents import AgentSettings
    from trackkit.network.steering import Steering

    s = AgentSettings(q=3e-4, steering=Steering(margin=25.0), comm_range=math.inf)
    assert settings_from_dict(json.loads(json.dumps(settings_to_dict(s)))) == s


def test_cli_agents_processes_writes_the_same_report(tmp_path):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY, encoding="utf-8")
    outs = {}
    for mode in ("inprocess", "processes"):
        ran = trackkit("network", str(f), "--runs", "1", "--seed", "3", "--agents", mode,
                       "--out", str(tmp_path / mode))
        assert ran.code == 0, ran.text
        assert (tmp_path / mode / "report.html").is_file()
        outs[mode] = (tmp_path / mode / "results.json").read_bytes()
    assert outs["processes"] == outs["inprocess"]
    assert_user_error(trackkit("network", str(f), "--agents", "threads", "--out",
                               str(tmp_path / "x")), 2, "--agents", "threads")
