"""CURVE between the environment and its agents (``network.processes``): a peer without a
key of the run is refused before any of its messages reaches the environment, and counted;
the run's results are the same bits as without CURVE. Everything runs on loopback (CURVE
forced on), and every test checks that no agent process is left."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
import zmq
import zmq.auth
from zmq.utils.monitor import recv_monitor_message

from tests.cli_helpers import assert_user_error, trackkit
from tests.network.test_processes import _agent_children, _setup
from tests.test_network_scenarios import TINY
from trackkit.network.processes import (
    CurveKeys,
    Deployment,
    _Environment,
    decode,
    encode,
    is_loopback,
    run_network_processes,
)

pytestmark = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(),
                                reason="the leak checks read /proc (Linux)")

_FAILED = ("HANDSHAKE_FAILED_NO_DETAIL", "HANDSHAKE_FAILED_PROTOCOL", "HANDSHAKE_FAILED_AUTH")


class _Peers:
    """Client sockets dialling an environment, each sending a forged ``hello`` of agent 0,
    with a monitor of its handshake; they never reconnect (one refusal each)."""

    def __init__(self) -> None:
        self.ctx = zmq.Context()
        self.socks: list[tuple[zmq.Socket, zmq.Socket]] = []
        self.seen: list[str] = []

    def dial(self, endpoint: str, server: bytes | None = None, public: bytes | None = None,
             secret: bytes | None = None) -> None:
        s = self.ctx.socket(zmq.DEALER)
        s.setsockopt(zmq.LINGER, 0)
        s.setsockopt(zmq.RECONNECT_IVL, -1)
        s.setsockopt(zmq.IDENTITY, b"agent-0-0")
        if server is not None:
            s.setsockopt(zmq.CURVE_SERVERKEY, server)
            s.setsockopt(zmq.CURVE_PUBLICKEY, public)
            s.setsockopt(zmq.CURVE_SECRETKEY, secret)
        m = s.get_monitor_socket()
        s.connect(endpoint)
        s.send(encode("hello", 0, -math.inf))
        self.socks.append((s, m))

    def rogues(self, endpoint: str, keys: CurveKeys) -> None:
        """No CURVE; a key of its own; an agent's public key without its secret."""
        public, secret = zmq.curve_keypair()
        self.dial(endpoint)
        self.dial(endpoint, keys.server_public, public, secret)
        self.dial(endpoint, keys.server_public, keys.agents[0][0], secret)

    def outcomes(self, timeout: float = 10.0) -> list[str]:
        """Each peer's handshake: a failure's event name or HANDSHAKE_SUCCEEDED (waiting
        up to ``timeout`` s for each peer dialled since the last call)."""
        for _, m in self.socks[len(self.seen):]:
            deadline, got = time.monotonic() + timeout, "none"
            while got == "none" and m.poll(max(1, int(1000 * (deadline - time.monotonic())))):
                name = zmq.Event(recv_monitor_message(m)["event"]).name
                if name in (*_FAILED, "HANDSHAKE_SUCCEEDED"):
                    got = name
            self.seen.append(got)
        return list(self.seen)

    def close(self) -> None:
        for s, m in self.socks:
            m.close(0)
            s.close(0)
        self.ctx.term()


def test_a_peer_without_a_key_of_the_run_never_reaches_the_environment():
    keys = CurveKeys.generate(1)
    env = _Environment("127.0.0.1", 0, 5.0, 5.0, 5.0, keys=keys)
    peers = _Peers()
    try:
        peers.rogues(env.connect, keys)
        assert all(o in _FAILED for o in peers.outcomes()), peers.seen
        assert env.sock.poll(300) == 0  # their hellos never arrived
        peers.dial(env.connect, keys.server_public, *keys.agents[0])
        assert peers.outcomes()[-1] == "HANDSHAKE_SUCCEEDED"
        assert env.sock.poll(5000)
        ident, frame = env.sock.recv_multipart()
        assert ident == b"agent-0-0" and decode(frame)["type"] == "hello"
        assert env.sock.poll(200) == 0
    finally:
        peers.close()
        env.close()
    assert env.refused == 3


def _agent_endpoint() -> str:
    """The endpoint a running agent dials (its command line: no secret is on it)."""
    pid = _agent_children()[0]
    argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    assert b"--curve" in argv and not any(b"secret" in a for a in argv)
    return argv[argv.index(b"--endpoint") + 1].decode()


@pytest.mark.slow
def test_curve_refuses_rogues_during_a_run_and_keeps_the_bits(tmp_path):
    """Agents with the certificates of a key directory; at the first execution three rogues
    dial the environment (no CURVE; their own key; an agent's public key without its secret):
    all are refused and counted, and every track equals the run without CURVE bit for bit."""
    args, kw = _setup(90.0)
    ref = run_network_processes(*args, **kw)
    assert (ref.curve, ref.refused) == (False, 0)
    zmq.auth.create_certificates(tmp_path, "server")
    zmq.auth.create_certificates(tmp_path, "client")
    keys = CurveKeys.from_dir(tmp_path, 3)
    peers = _Peers()
    seen: list[str] = []

    def rogues(t: float) -> None:
        if not seen:
            peers.rogues(_agent_endpoint(), keys)
            seen.extend(peers.outcomes())

    try:
        got = run_network_processes(*args, deployment=Deployment(curve=True, keys=tmp_path),
                                    on_event=rogues, **kw)
    finally:
        peers.close()
    assert all(o in _FAILED for o in seen) and len(seen) == 3, seen
    assert (got.curve, got.refused) == (True, 3)
    for x, y in zip(ref.agents, got.agents, strict=True):
        for f in x._fields:
            u, v = getattr(x, f), getattr(y, f)
            assert u == v if f == "reports" else np.array_equal(u, v, equal_nan=True), f
    assert (got.sent, got.delivered, got.lost) == (ref.sent, ref.delivered, ref.lost)
    assert _agent_children() == []


def test_curve_is_on_off_loopback_and_bad_keys_are_named(tmp_path):
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.4")
    args, kw = _setup(30.0)
    with pytest.raises(ValueError, match=r"not a directory"):
        run_network_processes(*args, deployment=Deployment(keys=tmp_path / "none"), **kw)
    with pytest.raises(ValueError, match=r"server\.key_secret: cannot be read"):
        run_network_processes(*args, deployment=Deployment(keys=tmp_path), **kw)
    zmq.auth.create_certificates(tmp_path, "server")
    (tmp_path / "client.key_secret").write_text("not a certificate\n")
    with pytest.raises(ValueError, match=r"client\.key_secret: cannot be read"):
        run_network_processes(*args, deployment=Deployment(keys=tmp_path), **kw)
    (tmp_path / "client.key_secret").write_bytes((tmp_path / "server.key").read_bytes())
    with pytest.raises(ValueError, match=r"client\.key_secret: holds no secret key"):
        run_network_processes(*args, deployment=Deployment(keys=tmp_path), **kw)
    with pytest.raises(ValueError, match="curve = False"):
        run_network_processes(*args, deployment=Deployment(keys=tmp_path, curve=False), **kw)
    assert _agent_children() == []


def test_cli_curve_writes_the_same_results_and_counts_refusals(tmp_path):
    import json

    f = tmp_path / "tiny.toml"
    f.write_text(TINY, encoding="utf-8")
    docs = {}
    for mode, more in (("inprocess", ()), ("processes", ("--curve",))):
        ran = trackkit("network", str(f), "--runs", "1", "--seed", "3", "--agents", mode,
                       *more, "--out", str(tmp_path / mode))
        assert ran.code == 0, ran.text
        docs[mode] = json.loads((tmp_path / mode / "results.json").read_text())
    assert "CURVE" in ran.text and "0 peers refused" in ran.text, ran.text
    channel = docs["processes"]["channel"]
    assert channel.pop("curve") is True and channel.pop("peers_refused") == 0
    assert docs["processes"] == docs["inprocess"]
    assert _agent_children() == []
    assert_user_error(trackkit("network", str(f), "--curve", "--out", str(tmp_path / "x")),
                      2, "--curve", "--agents processes")
    assert_user_error(trackkit("network", str(f), "--agents", "processes", "--keys",
                               str(tmp_path / "nokeys"), "--out", str(tmp_path / "y")),
                      2, "nokeys", "not a directory")
