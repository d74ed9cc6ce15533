"""the agents of Jalalipoor and Kardehi Moghaddam (2021) as separate operating-system processes
talking over ZeroMQ.

:func:`run_network_processes` runs the same network as
:func:`trackkit.network.inprocess.run_network`
(same arguments, same :class:`~trackkit.network.inprocess.NetworkResult`), but every agent lives in
its own process (``python -m trackkit.network.processes agent ...``, a fresh interpreter, so
nothing depends on the caller's ``__main__``) holding its own
:class:`~trackkit.network.agents.Agent`; the calling process is the **environment**: it owns
the truth and the schedule, runs the agents' executions one at a time in simulated time order
(ties: lower agent index first, as ``run_network``), hands each agent its bearings and the
messages delivered to it, and routes each agent's broadcast through the **channel** to the
agents within communication range.

**Transport.** The environment binds one ZeroMQ ROUTER socket (``tcp://HOST:PORT``, loopback
and an OS-chosen port by default, so parallel runs never collide); each agent connects one
DEALER socket with the identity ``agent-<index>-<incarnation>`` (a restarted agent is a new
incarnation, so the ROUTER never confuses it with the killed one). Every message is one frame
of UTF-8 JSON (Python's ``json``: floats are written with ``repr`` and read back exactly,
``NaN`` and ``Infinity`` included), so the process run reproduces the in-process run bit for
bit. Every receive has a timeout (``timeout_s``) and a clear error; nothing busy-waits.

**Envelope** (protocol version :data:`PROTOCOL_VERSION`; every message): ``protocol`` (int),
``type`` (str), ``agent`` (int), ``time`` (float, simulated seconds; never wall-clock).

Agent -> environment:

* ``hello``: the agent is up (``time`` = -inf, i.e. ``-Infinity`` in JSON).
* ``result``: the outcome of a ``step``: ``payload`` (``Payload.to_dict()``, schema
  :data:`~trackkit.network.agents.PAYLOAD_VERSION`), ``report`` (the 7 ``StepReport``
  counts), ``confirmed`` (``ids``, ``mean``, ``cov`` of the confirmed tracks after the
  step), ``course`` (the commanded course, rad, or null without steering).
* ``error``: ``error`` (str): the agent could not carry out the request (a payload of a
  wrong schema version, a malformed message, an exception in ``Agent.step``); the
  environment raises :class:`AgentError` with it.
* ``delivered``: answer to ``deliver``.
* ``bye``: answer to ``stop``; the agent exits.

Environment -> agent:

* ``step``: execute at ``time``: ``inbox`` (the payload dicts delivered since the last step,
  in delivery order, each checked by ``Payload.from_dict`` on receipt), ``bearings`` (the own
  bearings as a ``BearingSet``: ``z``, ``t``, ``sensor``, ``sigma``, ``source``),
  ``position``, ``velocity`` (m, m/s), ``course``, ``speed``, ``dt_next`` (for steering).
* ``deliver``: ``inbox`` only (no execution): the messages that arrived after the agent's
  last execution, handed over when the run ends (so that, as in ``run_network``, every
  message sent is received).
* ``stop``: exit cleanly.

**Channel** (options): each delivery is lost with probability ``loss`` (the same stream as
``run_network``: ``SeedSequence(seed, spawn_key=(run, 4))``) and arrives ``delay`` simulated
seconds after it was sent; an agent gets the messages that arrived by its execution time.
Counts: ``sent`` (one per sender-receiver link at the broadcast), ``delivered``, ``lost``
(dropped by the channel, addressed to a dead agent, or still in flight ``delay`` after the
last execution when the run ends), so
``sent = delivered + lost``; ``late``: delivered messages that missed at least one of the
receiver's executions they would have reached without the delay.

**Kill and restart** (``outages``: ``(agent, kill_at, restart_at or None)``): at the first
execution at or after ``kill_at`` the environment kills the agent's process (SIGKILL); while
it is dead it neither measures nor broadcasts, its executions are recorded with no tracks,
and messages to it are lost. At ``restart_at`` a new process starts with an empty agent (its
initiation stream ``SeedSequence(seed, spawn_key=(run, 3, a, k))`` for its k-th restart) and
rebuilds its tracks from its own bearings and its neighbours' messages.

**CURVE.** Whenever the environment listens on an address other than loopback (and on
loopback when asked, ``curve=True``), the ROUTER is a ZeroMQ CURVE server: every connection is
encrypted and authenticated (Hintjens 2013, ZeroMQ RFC 26 CurveZMQ, RFC 27 ZAP). A ZAP handler
in the environment admits only the public keys of the run's agents; any other peer (another
key, or no CURVE) fails its handshake before a message of it reaches the environment, and is
counted (``ProcessNetworkResult.refused``). The keys are made afresh for every run
(``zmq.curve_keypair``: the environment's keypair and one per agent) or read from a
directory of certificates (``keys``: ``server.key_secret`` and ``client.key_secret`` or
``agent-N.key_secret`` for agent N from 1, as ``zmq.auth.create_certificates`` writes them).
An agent gets its keys as one JSON line on its standard input (through a ``launch`` prefix
such as ``ssh`` too), never on its command line, which ``ps`` shows to every user.

**Shutdown.** On success, on error and on KeyboardInterrupt: ``stop`` to every live agent,
then ``join`` with a timeout, ``terminate``, ``kill``; sockets closed with linger 0 and the
context terminated. Agents ignore SIGINT (the environment decides when they end) and exit by
themselves when they hear nothing for ``idle_timeout_s``.
"""

from __future__ import annotations

import argparse
import dataclasses
import ipaddress
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zmq
from numpy.typing import ArrayLike, NDArray

from trackkit.network.agents import (
    Agent,
    AgentSettings,
    BearingSet,
    Payload,
    StepReport,
    empty_tracks,
    own_bearings,
    run_inline,
)
from trackkit.network.central import CentralSettings
from trackkit.network.inprocess import (
    Motion,
    NetworkResult,
    Recorder,
    Spacing,
    World,
    build_world,
    central_trace,
    check_loss,
    relay_to_hub,
)
from trackkit.network.steering import Steering
from trackkit.network.tracks import Message
from trackkit.sim.sensor_network import bearings_at, disk_graph

__all__ = ["PROTOCOL_VERSION", "AgentError", "CurveKeys", "Deployment", "ProcessNetworkResult",
           "decode",
           "decode_payload", "encode", "is_loopback", "run_network_processes",
           "settings_from_dict", "settings_to_dict"]

Array = NDArray[np.float64]

#: version of the envelope and message types above (``decode`` refuses any other)
PROTOCOL_VERSION = 1

#: listening addresses that mean "every interface" (an agent cannot dial them)
_WILDCARD = ("0.0.0.0", "*", "::")

#: the monitor events of a peer whose handshake failed: the peers CURVE refused
_REFUSED = (zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
            | zmq.EVENT_HANDSHAKE_FAILED_AUTH)


class AgentError(RuntimeError):
    """An agent process failed, answered with an error, or did not answer in time."""


class ProcessNetworkResult(NetworkResult):
    """A :class:`NetworkResult` (same fields, ``late`` counted) with the process run's extras
    as attributes: ``endpoint`` (the ROUTER's address, now closed), ``restarts`` (processes
    started after a kill), ``recovered`` (per outage: the simulated time after the restart
    when the agent first held as many confirmed tracks as before the kill, nan if
    never), ``curve`` (whether the agents were authenticated and encrypted with CURVE) and
    ``refused`` (peers whose connection CURVE refused)."""

    endpoint: str
    restarts: int
    recovered: list[float]
    curve: bool
    refused: int


# --------------------------------------------------------------------------------------------
# the wire


def encode(kind: str, agent: int, t: float, **fields: Any) -> bytes:
    """One message (module docstring): the envelope plus ``fields``, as UTF-8 JSON."""
    return json.dumps({"protocol": PROTOCOL_VERSION, "type": kind, "agent": int(agent),
                       "time": float(t), **fields}).encode()


def decode(frame: bytes, expect: Sequence[str] | None = None) -> dict[str, Any]:
    """A received frame as a dict, its envelope checked: ``protocol`` equal to
    :data:`PROTOCOL_VERSION`, ``type`` among ``expect`` (when given), ``agent`` an int and
    ``time`` a number."""
    try:
        d = json.loads(frame.decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"message is not UTF-8 JSON ({err}); expected one JSON object") from None
    if not isinstance(d, dict):
        raise ValueError(f"message is a JSON {type(d).__name__}; expected an object")
    v = d.get("protocol")
    if v != PROTOCOL_VERSION:
        raise ValueError(f"message protocol = {v!r}; expected {PROTOCOL_VERSION}")
    kind = d.get("type")
    if expect is not None and kind not in expect:
        raise ValueError(f"message type = {kind!r}; expected one of {list(expect)}")
    if not isinstance(d.get("agent"), int) or not isinstance(d.get("time"), int | float):
        raise ValueError(f"message agent = {d.get('agent')!r}, time = {d.get('time')!r}; "
                         "expected an int and a number (simulated seconds)")
    return d


def decode_payload(d: Any) -> Payload:
    """``Payload.from_dict`` of a received payload dict: refuses any schema version other
    than ``PAYLOAD_VERSION`` with an error naming the version."""
    if not isinstance(d, dict):
        raise ValueError(f"payload is a {type(d).__name__}; expected a JSON object")
    return Payload.from_dict(d)


def _bearings_dict(b: BearingSet) -> dict[str, list]:
    return {"z": b.z.tolist(), "t": b.t.tolist(), "sensor": b.sensor.tolist(),
            "sigma": b.sigma.tolist(), "source": b.source.tolist()}


def _bearings_from(d: dict[str, list]) -> BearingSet:
    M = len(d["z"])
    return BearingSet(np.asarray(d["z"], float).reshape(M), np.asarray(d["t"], float).reshape(M),
                      np.asarray(d["sensor"], float).reshape(M, 2),
                      np.asarray(d["sigma"], float).reshape(M),
                      np.asarray(d["source"], np.int64).reshape(M))


# --------------------------------------------------------------------------------------------
# the agent process


def settings_to_dict(s: AgentSettings) -> dict[str, Any]:
    """``AgentSettings`` as plain JSON values (``steering`` a dict or None)."""
    return dataclasses.asdict(s)


def settings_from_dict(d: dict[str, Any]) -> AgentSettings:
    """The inverse of :func:`settings_to_dict` (the dataclasses validate the values)."""
    st = d.get("steering")
    return AgentSettings(**{**d, "steering": None if st is None else Steering(**st)})


def _agent_main(endpoint: str, index: int, incarnation: int, settings: AgentSettings,
                entropy: int, spawn_key: tuple[int, ...], idle_timeout_s: float,
                curve: dict[str, str] | None = None) -> None:
    """An agent process: connect, say hello, answer ``step`` and ``stop`` (module
    docstring). Exits on ``stop``, when its parent process is gone, or when nothing arrives
    for ``idle_timeout_s``. ``curve``: the keys (``CurveKeys.for_agent``) of a CURVE
    connection."""
    # the environment owns our lifetime (a Ctrl-C is its to handle, and it stops us)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = os.getppid()
    agent = Agent(index, settings,
                  np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=spawn_key)))
    ctx = zmq.Context()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.IDENTITY, f"agent-{index}-{incarnation}".encode())
    if curve is not None:
        sock.setsockopt(zmq.CURVE_SERVERKEY, curve["server"].encode())
        sock.setsockopt(zmq.CURVE_PUBLICKEY, curve["public"].encode())
        sock.setsockopt(zmq.CURVE_SECRETKEY, curve["secret"].encode())
    try:
        sock.connect(endpoint)
        sock.send(encode("hello", index, -math.inf))
        t_last = -math.inf
        idle = 0.0
        while True:
            # wait in 1 s slices (a blocking poll) to notice an orphaned agent
            if not sock.poll(1000):
                idle += 1.0
                if idle >= idle_timeout_s or os.getppid() != parent:
                    return  # the environment is gone: do not linger
                continue
            idle = 0.0
            frame = sock.recv()
            try:
                d = decode(frame, ("step", "deliver", "stop"))
                if d["type"] == "stop":
                    sock.send(encode("bye", index, d["time"]))
                    return
                if d["type"] == "deliver":
                    _agent_receive(agent, d["inbox"])
                    sock.send(encode("delivered", index, d["time"]))
                    continue
                t_last = float(d["time"])
                sock.send(_agent_step(agent, d))
            except Exception as err:  # answered, so that the environment can name it
                sock.send(encode("error", index, t_last, error=f"{type(err).__name__}: {err}"))
    finally:
        sock.close(0)
        ctx.term()


def _agent_receive(agent: Agent, inbox: list[Any]) -> None:
    """Hand the agent the delivered payloads in order, each checked on receipt."""
    for p in inbox:
        payload = decode_payload(p)
        agent.receive(Message(payload.sender, payload.time, payload))


def _agent_step(agent: Agent, d: dict[str, Any]) -> bytes:
    """Receive the inbox, run ``Agent.step`` at ``d["time"]``, steer; the ``result``."""
    t = float(d["time"])
    _agent_receive(agent, d["inbox"])
    own = _bearings_from(d["bearings"])
    here = np.asarray(d["position"], float).reshape(2)
    vel = np.asarray(d["velocity"], float).reshape(2)
    msg, rep = agent.step(t, own, here, vel)
    course = None
    if agent.settings.steering is not None:
        course = agent.steer(here, float(d["course"]), float(d["speed"]), float(d["dt_next"]))
    c = agent.confirmed()
    return encode("result", agent.index, t, payload=msg.payload.to_dict(), report=list(rep),
                  confirmed={"ids": c.ids.tolist(), "mean": c.mean.tolist(),
                             "cov": c.cov.tolist()},
                  course=course)


# --------------------------------------------------------------------------------------------
# CURVE: who may connect


def is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address ("localhost", 127.0.0.0/8, ::1), which only
    this machine can reach."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class CurveKeys:
    """A run's CURVE keys, Z85 text as ZeroMQ takes them: the environment's keypair and each
    agent's (index from 0)."""

    server_public: bytes
    server_secret: bytes
    agents: tuple[tuple[bytes, bytes], ...]  # (public, secret) per agent

    @classmethod
    def generate(cls, n_agents: int) -> CurveKeys:
        """Fresh keys for one run."""
        pub, sec = zmq.curve_keypair()
        return cls(pub, sec, tuple(zmq.curve_keypair() for _ in range(n_agents)))

    @classmethod
    def from_dir(cls, path: str | Path, n_agents: int) -> CurveKeys:
        """The certificates in directory ``path`` (module docstring): ``server.key_secret``
        for the environment, ``agent-N.key_secret`` for agent N (from 1) or else
        ``client.key_secret`` for every agent."""
        d = Path(path)
        if not d.is_dir():
            raise ValueError(f"keys = {str(d)!r}: not a directory; expected one holding "
                             "server.key_secret and client.key_secret (or agent-N.key_secret)"
                             " as zmq.auth.create_certificates writes them")
        server = _certificate(d / "server.key_secret")
        own = [d / f"agent-{a + 1}.key_secret" for a in range(n_agents)]
        shared = d / "client.key_secret"
        return cls(*server, tuple(_certificate(f if f.exists() else shared) for f in own))

    def for_agent(self, a: int) -> bytes:
        """What agent ``a`` reads on its standard input: one JSON line of its keys."""
        pub, sec = self.agents[a]
        return json.dumps({"server": self.server_public.decode(), "public": pub.decode(),
                           "secret": sec.decode()}).encode() + b"\n"


def _certificate(path: Path) -> tuple[bytes, bytes]:
    """(public, secret) key of a secret certificate file of ``zmq.auth``."""
    import zmq.auth

    try:
        pub, sec = zmq.auth.load_certificate(path)
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: cannot be read as a secret certificate ({err}); expected "
                         "a file zmq.auth.create_certificates writes (NAME.key_secret)") from None
    if not sec:
        raise ValueError(f"{path}: holds no secret key; expected the NAME.key_secret file "
                         "zmq.auth.create_certificates writes, not NAME.key")
    return pub, sec


class _Gatekeeper:
    """Who may talk to the environment's CURVE ROUTER: a ZAP handler (ZeroMQ RFC 27) that
    admits the run's agents' public keys alone, and a monitor of the socket that counts every
    peer whose handshake failed (another key, or no CURVE at all). Both in one thread that
    blocks in a poll, woken every 0.1 s to see whether it should stop."""

    def __init__(self, ctx: zmq.Context, sock: zmq.Socket, allowed: Sequence[bytes]) -> None:
        from zmq.utils import z85

        self.allowed = {z85.decode(k) for k in allowed}
        self.refused = 0
        self.zap = ctx.socket(zmq.REP)
        self.zap.setsockopt(zmq.LINGER, 0)
        self.zap.bind("inproc://zeromq.zap.01")  # where libzmq asks (RFC 27)
        self.monitor = sock.get_monitor_socket(_REFUSED)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="trackkit-zap", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        poller = zmq.Poller()
        poller.register(self.zap, zmq.POLLIN)
        poller.register(self.monitor, zmq.POLLIN)
        while not self._stop.is_set():
            ready = dict(poller.poll(100))
            if self.zap in ready:
                self._answer(self.zap.recv_multipart())
            if self.monitor in ready:
                self._count()
        self._count()

    def _answer(self, req: list[bytes]) -> None:
        # version, request id, domain, address, identity, mechanism, credentials...
        ok = len(req) >= 7 and req[5] == b"CURVE" and req[6] in self.allowed
        self.zap.send_multipart([b"1.0", req[1] if len(req) > 1 else b"",
                                 b"200" if ok else b"400",
                                 b"OK" if ok else b"not a key of this run", b"", b""])

    def _count(self) -> None:
        while self.monitor.poll(0):
            self.monitor.recv_multipart()  # only the refusals are monitored
            self.refused += 1

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.monitor.close(0)
        self.zap.close(0)


# --------------------------------------------------------------------------------------------
# the environment


@dataclass
class _Link:
    """One live agent process and its ROUTER identity."""

    index: int
    identity: bytes
    proc: subprocess.Popen
    stderr: Any  # a temporary file with the process's stderr (for error messages)


class _Confirmed:
    """What ``Recorder.add`` reads from an agent, rebuilt from a ``result`` message."""

    def __init__(self, t: float, conf: dict[str, list] | None) -> None:
        self.time = t
        if conf is None:
            self._c = empty_tracks()
        else:
            T = len(conf["ids"])
            self._c = empty_tracks()._replace(ids=np.asarray(conf["ids"], np.int64).reshape(T),
                                              mean=np.asarray(conf["mean"], float).reshape(T, 4),
                                              cov=np.asarray(conf["cov"], float).reshape(T, 4, 4))

    def confirmed(self):  # noqa: ANN201 (duck-typed Agent for Recorder.add)
        return self._c


class _Environment:
    """The ROUTER socket, the agent processes and their shutdown."""

    def __init__(self, host: str, port: int, timeout_s: float, start_timeout_s: float,
                 idle_timeout_s: float, advertise: str | None = None,
                 launch: dict[int, list[str]] | None = None,
                 remote_python: str = "python3", keys: CurveKeys | None = None) -> None:
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.ROUTER)
        self.sock.setsockopt(zmq.LINGER, 0)
        # a message to an identity that is not connected is an error, not a silent drop
        self.sock.setsockopt(zmq.ROUTER_MANDATORY, 1)
        self.keys, self.gate = keys, None
        if keys is not None:  # before the bind: no peer ever meets an open socket
            self.sock.setsockopt(zmq.CURVE_SERVER, 1)
            self.sock.setsockopt(zmq.CURVE_SECRETKEY, keys.server_secret)
            self.sock.setsockopt(zmq.ZAP_DOMAIN, b"trackkit")
            self.gate = _Gatekeeper(self.ctx, self.sock, [p for p, _ in keys.agents])
        try:
            if port == 0:
                port = self.sock.bind_to_random_port(f"tcp://{host}")
            else:
                self.sock.bind(f"tcp://{host}:{port}")
        except zmq.ZMQError as err:
            if self.gate is not None:
                self.gate.close()
            self.sock.close(0)
            self.ctx.destroy(0)
            raise ValueError(f"host = {host!r}, port = {port!r}: cannot listen there "
                             f"({err}); expected a local address and a free port") from None
        self.endpoint = f"tcp://{host}:{port}"
        # the address the agents dial: where the environment listens on every interface,
        # the one given (another machine cannot dial 0.0.0.0)
        local = "127.0.0.1" if host in _WILDCARD else host
        self.connect = f"tcp://{advertise or local}:{port}"
        self.launch = launch or {}
        self.remote_python = remote_python
        self.timeout_s, self.start_timeout_s = timeout_s, start_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.links: dict[int, _Link] = {}
        self.incarnations: dict[int, int] = {}

    def start(self, indices: Sequence[int], settings: Sequence[AgentSettings], seed: int,
              keys: Sequence[tuple[int, ...]]) -> None:
        """Start the agents' processes and wait for every ``hello``."""
        waiting = {}
        for a, s, key in zip(indices, settings, keys, strict=True):
            k = self.incarnations.get(a, -1) + 1
            self.incarnations[a] = k
            ident = f"agent-{a}-{k}".encode()
            # a launcher prefix (e.g. ["ssh", "boat2"]) runs the agent on another machine,
            # whose python must have trackkit installed
            python = [self.remote_python] if self.launch.get(a) else [sys.executable]
            cmd = [*self.launch.get(a, []), *python, "-m", "trackkit.network.processes",
                   "agent", "--endpoint", self.connect, "--index", str(a),
                   "--incarnation", str(k),
                   "--seed", str(seed), "--key", ",".join(str(int(v)) for v in key),
                   "--idle-timeout", repr(float(self.idle_timeout_s)),
                   "--settings", json.dumps(settings_to_dict(s))]
            if self.keys is not None:
                cmd.append("--curve")  # the keys follow on its standard input
            err = tempfile.TemporaryFile()
            # its own session: a Ctrl-C in the terminal reaches the environment only
            proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL if self.keys is None else
                                    subprocess.PIPE, stdout=subprocess.DEVNULL,
                                    stderr=err, start_new_session=True)
            if self.keys is not None:
                _hand_keys(proc, self.keys.for_agent(a))
            self.links[a] = _Link(a, ident, proc, err)
            waiting[ident] = a
        deadline = _time.monotonic() + self.start_timeout_s
        while waiting:
            ident, d = self._recv(deadline, "hello", set(waiting))
            del waiting[ident]

    def _recv(self, deadline: float, kind: str, idents: set[bytes]
              ) -> tuple[bytes, dict[str, Any]]:
        """The next message from one of ``idents`` before ``deadline`` (monotonic s);
        checks the agents' processes are alive while it waits."""
        while True:
            left = deadline - _time.monotonic()
            if left <= 0:
                names = sorted(i.decode() for i in idents)
                raise AgentError(f"no {kind!r} from {names} within the timeout; expected an "
                                 "answer (raise timeout_s for slow machines)")
            # wake at least every 0.5 s to notice a dead process (a blocking poll, not a spin)
            if self.sock.poll(int(1000 * min(left, 0.5))):
                ident, frame = self.sock.recv_multipart()
                if ident not in idents:
                    continue  # a killed incarnation's late words: not ours to read
                d = decode(frame)
                if d["type"] == "error":
                    raise AgentError(f"agent {d['agent']} failed at t = {d['time']!r} s: "
                                     f"{d.get('error')}")
                if d["type"] != kind:
                    raise AgentError(f"agent {d['agent']} sent type = {d['type']!r}; "
                                     f"expected {kind!r}")
                return ident, d
            for link in self.links.values():
                if link.identity in idents and link.proc.poll() is not None:
                    link.stderr.seek(0)
                    tail = link.stderr.read()[-2000:].decode(errors="replace").strip()
                    raise AgentError(f"agent {link.index}'s process exited with code "
                                     f"{link.proc.returncode} before its {kind!r}"
                                     + (f"; its stderr ends:\n{tail}" if tail else ""))

    def request(self, a: int, frame: bytes, kind: str = "result") -> dict[str, Any]:
        """Send ``frame`` to agent a and wait for its answer of type ``kind``."""
        link = self.links[a]
        self.sock.send_multipart([link.identity, frame])
        return self._recv(_time.monotonic() + self.timeout_s, kind, {link.identity})[1]

    def kill(self, a: int) -> None:
        """Kill agent a's process at once (SIGKILL): the failure the option simulates."""
        link = self.links.pop(a)
        link.proc.kill()
        link.proc.wait(self.timeout_s)
        link.stderr.close()

    def close(self, grace_s: float = 5.0) -> None:
        """``stop`` every live agent, then join, terminate, kill; close the socket and the
        context (linger 0). Safe to call on any path."""
        try:
            for link in self.links.values():
                try:
                    self.sock.send_multipart([link.identity, encode("stop", link.index, 0.0)],
                                             zmq.NOBLOCK)
                except zmq.ZMQError:
                    pass  # not connected (or already gone): terminate below
            deadline = _time.monotonic() + grace_s
            for link in self.links.values():
                try:
                    link.proc.wait(max(0.01, deadline - _time.monotonic()))
                except subprocess.TimeoutExpired:
                    link.proc.terminate()
                    try:
                        link.proc.wait(grace_s)
                    except subprocess.TimeoutExpired:
                        link.proc.kill()
                        link.proc.wait(grace_s)
                link.stderr.close()
            self.links.clear()
        finally:
            if self.gate is not None:
                self.gate.close()
            self.sock.close(0)
            self.ctx.destroy(0)

    @property
    def refused(self) -> int:
        """Peers CURVE refused so far (0 without CURVE)."""
        return 0 if self.gate is None else self.gate.refused


def _hand_keys(proc: subprocess.Popen, line: bytes) -> None:
    """Write an agent's keys to its standard input and close it (a process that died at
    once is noticed while waiting for its ``hello``)."""
    try:
        proc.stdin.write(line)
        proc.stdin.flush()
    except OSError:
        pass
    finally:
        try:
            proc.stdin.close()
        except OSError:
            pass


@dataclass(frozen=True)
class Deployment:
    """Where and how ``run_network_processes`` runs the agents' processes.

    ``host``, ``port``: the environment's ROUTER address (port 0: chosen by the OS; host
    "0.0.0.0" listens on every interface, for agents on other machines). ``advertise``: the
    address the agents dial (default ``host``): this machine's name or address as the
    agents' machines see it, when ``host`` is "0.0.0.0". ``launch``: per agent (0-based), a
    command prefix that starts its process elsewhere, e.g. ``{2: ["ssh", "boat2"]}``: the
    agent runs ``remote_python -m trackkit.network.processes agent ...`` there
    (``remote_python``: an interpreter with trackkit installed, "python3" on the remote PATH
    by default) and dials ``advertise``; killing it (``outages``) kills the local launcher,
    and the remote agent, hearing nothing for ``idle_timeout_s``, exits by itself.
    ``timeout_s``: the longest wait for one agent's answer (wall-clock s);
    ``start_timeout_s`` for the processes to start; ``idle_timeout_s``: an agent that hears
    nothing that long exits by itself. ``curve``: authenticate and encrypt the agents with
    CURVE (module docstring); None: on whenever ``host`` is not a loopback address (the
    results are the same bits). ``keys``: a directory of CURVE certificates (module
    docstring) instead of keys made for the run; implies ``curve``."""

    host: str = "127.0.0.1"
    port: int = 0
    advertise: str | None = None
    launch: Mapping[int, Sequence[str]] | None = None
    remote_python: str = "python3"
    timeout_s: float = 60.0
    start_timeout_s: float = 120.0
    idle_timeout_s: float = 300.0
    curve: bool | None = None
    keys: str | Path | None = None


def run_network_processes(
    seed: int,
    run: int,
    targets: ArrayLike,
    agents: ArrayLike,
    *,
    duration: float,
    period: float,
    sigma: ArrayLike,
    mr: ArrayLike = math.inf,
    cr: ArrayLike = math.inf,
    max_delay: float | None = None,
    q: float = 0.0,
    settings: AgentSettings | None = None,
    steering: bool = False,
    central: bool | str = False,
    loss: float = 0.0,
    central_settings: CentralSettings | None = None,
    delay: float = 0.0,
    outages: Sequence[tuple[int, float, float | None]] = (),
    deployment: Deployment = Deployment(),
    on_event: Callable[[float], None] | None = None,
) -> ProcessNetworkResult:
    """Run ``run`` of a network with every agent in its own process (module docstring).

    Args:

        seed, run, targets, agents, duration, period, sigma, mr, cr, max_delay, q, settings,
            steering, central, loss, central_settings: as ``run_network``; with ``loss`` 0,
            ``delay`` 0 and no outages the tracks equal ``run_network``'s bit for bit.
        delay: the channel's delivery delay (simulated s, >= 0).
        outages: ``(agent, kill_at, restart_at)`` (0-based agent index, simulated s;
            ``restart_at`` None: never restarted, else > ``kill_at``).
        deployment: where and how the processes run (addresses, launchers, timeouts,
            CURVE): ``Deployment``.
        on_event: called with the simulated time after every execution (progress; an
            exception it raises ends the run, cleanly).
    """
    check_loss(loss)
    if not (math.isfinite(delay) and delay >= 0):
        raise ValueError(f"delay = {delay!r}; expected simulated seconds >= 0")
    _check_timeouts_and_port(deployment)
    w = build_world(seed, run, targets, agents, duration=duration, period=period,
                    sigma=sigma, mr=mr, cr=cr, max_delay=max_delay, q=q, settings=settings,
                    steering=steering, central=central)
    A = w.times.shape[0]
    kills = _outage_times(outages, A)
    t0 = _time.perf_counter()
    launch = _launch_commands(deployment, A)
    d = deployment
    env = _Environment(d.host, d.port, d.timeout_s, d.start_timeout_s, d.idle_timeout_s,
                       d.advertise, launch, d.remote_python,
                       _curve_keys(d.curve, d.keys, d.host, A))
    ex = _Exchange(w, env, seed, run, kills, steering, loss, delay, period)
    try:
        env.start(range(A), w.settings, seed, [(run, 3, a) for a in range(A)])
        for a, e in w.order:
            ex.execute(a, e)
            if on_event is not None:
                on_event(float(w.times[a, e]))
        ex.finish()
    finally:
        env.close()
    trace_c, fusion = central_trace(w, ex.rec_c, ex.Zc, ex.Sc, q, central_settings)
    seconds = _time.perf_counter() - t0
    out = ProcessNetworkResult([r.trace() for r in ex.rec], trace_c, w.sim, ex.sent,
                               ex.delivered, ex.lost, seconds, fusion, ex.spacing.span,
                               ex.late)
    out.endpoint, out.restarts = env.endpoint, ex.restarts
    out.curve, out.refused = env.keys is not None, env.refused
    out.recovered = [ex.recovered[a] for a in sorted(kills)]
    return out


def _check_timeouts_and_port(d: Deployment) -> None:
    for name, v in (("timeout_s", d.timeout_s), ("start_timeout_s", d.start_timeout_s),
                    ("idle_timeout_s", d.idle_timeout_s)):
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} = {v!r}; expected seconds > 0")
    if not (isinstance(d.port, int) and 0 <= d.port < 65536):
        raise ValueError(f"port = {d.port!r}; expected 0 (OS-chosen) or a TCP port")


def _outage_times(outages: Sequence[tuple[int, float, float | None]],
                  A: int) -> dict[int, tuple[float, float]]:
    """``outages`` checked, as ``{agent: (kill_at, restart_at or inf)}``."""
    kills: dict[int, tuple[float, float]] = {}
    for k, o in enumerate(outages):
        a, t_kill, t_back = int(o[0]), float(o[1]), math.inf if o[2] is None else float(o[2])
        if not 0 <= a < A:
            raise ValueError(f"outages[{k}] agent = {a}; expected an index in 0..{A - 1}")
        if a in kills:
            raise ValueError(f"outages[{k}] agent = {a}; expected one outage per agent")
        if not (math.isfinite(t_kill) and t_kill < t_back):
            raise ValueError(f"outages[{k}] = {tuple(o)!r}; expected a finite kill time "
                             "before the restart time")
        kills[a] = (t_kill, t_back)
    return kills


def _launch_commands(d: Deployment, A: int) -> dict[int, list[str]]:
    """``d.launch`` checked, as lists of strings; agents launched elsewhere need an address
    to dial other than the wildcard."""
    launch = {int(a): [str(c) for c in cmd] for a, cmd in (d.launch or {}).items()}
    for a, cmd in launch.items():
        if not 0 <= a < A or not cmd:
            raise ValueError(f"launch[{a}] = {cmd!r}; expected an agent index in 0..{A - 1} "
                             "and a non-empty command prefix such as ['ssh', 'host']")
    if d.host in _WILDCARD and d.advertise is None and launch:
        raise ValueError(f"host = {d.host!r} with agents launched elsewhere; expected "
                         "advertise = this machine's address as the agents see it")
    return launch


class _Exchange:
    """A process run in progress: the agents' executions in the world's order, the messages
    in flight between them (lost, delayed, or dropped with a killed agent), the outages and
    the records (``run_network_processes``)."""

    def __init__(self, w: World, env: _Environment, seed: int, run: int,
                 kills: dict[int, tuple[float, float]], steering: bool, loss: float,
                 delay: float, period: float) -> None:
        A, E = w.times.shape
        self.w, self.env, self.seed, self.run, self.kills = w, env, seed, run, kills
        self.steering, self.loss, self.delay, self.period = steering, loss, delay, period
        self.motion = Motion(w.ag0, steering)
        self.rec = [Recorder() for _ in range(A)]
        self.rec_c = Recorder() if w.hub is not None else None
        self.Zc = np.full((A, E, w.Nt), np.nan)
        self.Sc = np.zeros((A, E, 2))
        # in flight: per receiver, (arrival time, send time, payload dict), in sending order
        self.flight: list[list[tuple[float, float, dict[str, Any]]]] = [[] for _ in range(A)]
        self.last_exec = np.full(A, -math.inf)  # each agent's last execution (for "late")
        self.alive = np.ones(A, bool)
        self.sent = self.delivered = self.lost = self.late = self.restarts = 0
        self.spacing = Spacing(w.CR)
        self.held_before = dict.fromkeys(kills, 0)
        self.recovered = {a: math.nan for a in kills}

    def execute(self, a: int, e: int) -> None:
        """Agent a's execution e: its outage (if due), its bearings and inbox, its answer,
        the payload broadcast to its neighbours and relayed to the hub."""
        w, t = self.w, float(self.w.times[a, e])
        if a in self.kills:
            self._outage(a, t)
        here, vel = run_inline(self.motion.at(a, t))
        truth = w.sim.target_at_bearing[0, a, e]
        if not self.alive[a]:
            self.rec[a].add(_Confirmed(t, None), truth, here,  # type: ignore[arg-type]
                            StepReport(0, 0, 0, 0, 0, 0, 0))
            return
        z, _ = bearings_at(here, truth, w.noise[a, e], w.sig[a], w.MR[a])
        self.Zc[a, e], self.Sc[a, e] = z, here
        own = own_bearings(z, t, here, float(w.sig[a]), a)
        inbox = self._receive(a, t)
        E = w.times.shape[1]
        dt_next = float(w.times[a, e + 1] - t) if e + 1 < E else self.period
        res = self.env.request(a, encode(
            "step", a, t, inbox=[m[2] for m in inbox], bearings=_bearings_dict(own),
            position=here.tolist(), velocity=vel.tolist(),
            course=float(self.motion.course[a]), speed=float(self.motion.speed[a]),
            dt_next=dt_next))
        self.last_exec[a] = t
        if float(res["time"]) != t:
            raise AgentError(f"agent {a} answered for time = {res['time']!r}; expected "
                             f"{t!r}")
        self._record(a, t, res, truth, here)
        if self.steering and res["course"] is not None:
            self.motion.cmd[a] = float(res["course"])
        pd = res["payload"]
        payload = decode_payload(pd)  # checks the schema on receipt
        self._broadcast(a, t, pd)
        if self.rec_c is not None:
            run_inline(relay_to_hub(w.hub, self.rec_c, payload, t, truth))

    def _outage(self, a: int, t: float) -> None:
        """Kill agent a at its kill time (what it had not yet read dies with it); restart it
        at its restart time."""
        t_kill, t_back = self.kills[a]
        if self.alive[a] and t_kill <= t < t_back:
            self.env.kill(a)
            self.alive[a] = False
            self.lost += len(self.flight[a])
            self.flight[a].clear()
            self.held_before[a] = self.rec[a].sizes[-1] if self.rec[a].sizes else 0
        elif not self.alive[a] and t >= t_back:
            self.restarts += 1
            self.env.start([a], [self.w.settings[a]], self.seed,
                           [(self.run, 3, a, self.restarts)])
            self.alive[a] = True

    def _receive(self, a: int, t: float) -> list[tuple[float, float, dict[str, Any]]]:
        """The messages that have reached agent a by t, taken out of flight."""
        inbox = [m for m in self.flight[a] if m[0] <= t]
        self.flight[a] = [m for m in self.flight[a] if m[0] > t]
        for _, t_sent, _ in inbox:
            self.delivered += 1
            # it would have arrived at the receiver's first execution after t_sent
            self.late += int(self.last_exec[a] >= t_sent and self.delay > 0)
        return inbox

    def _record(self, a: int, t: float, res: dict[str, Any], truth: Array,
                here: Array) -> None:
        """Agent a's answer into its record; the time it took a restarted agent to hold
        again as many tracks as before its outage."""
        conf = _Confirmed(t, res["confirmed"])
        self.rec[a].add(conf, truth, here,  # type: ignore[arg-type]
                        StepReport(*(int(v) for v in res["report"])))
        if a in self.kills and math.isnan(self.recovered[a]) and t >= self.kills[a][1] and (
                conf.confirmed().size >= max(self.held_before[a], 1)):
            self.recovered[a] = t - self.kills[a][1]

    def _broadcast(self, a: int, t: float, pd: dict[str, Any]) -> None:
        """Agent a's payload to every neighbour in communication range: lost with
        probability ``loss`` or to a dead agent, else in flight for ``delay``."""
        where = run_inline(self.motion.where(t))
        self.spacing.add(where)
        links = disk_graph(where, self.w.CR)[a]
        for b in np.flatnonzero(links).tolist():
            self.sent += 1
            if self.loss > 0 and self.w.lose.random() < self.loss:
                self.lost += 1
                continue
            if not self.alive[b]:
                self.lost += 1
                continue
            self.flight[b].append((t + self.delay, t, pd))

    def finish(self) -> None:
        """The run ends at the last execution: what has arrived by then is handed over (as
        run_network's receive at once); what is still in flight is never delivered."""
        t_end = float(self.w.times.max())
        for b, flight in enumerate(self.flight):
            due = [m for m in flight if m[0] <= t_end]
            self.lost += len(flight) - len(due)
            if due and self.alive[b]:
                self.env.request(b, encode("deliver", b, t_end, inbox=[m[2] for m in due]),
                                 "delivered")
                self.delivered += len(due)


def _curve_keys(curve: bool | None, keys: str | Path | None, host: str,
                n_agents: int) -> CurveKeys | None:
    """The run's CURVE keys, or None without CURVE (``run_network_processes``)."""
    if keys is not None and curve is False:
        raise ValueError(f"keys = {str(keys)!r} with curve = False; expected CURVE on (the "
                         "keys are CURVE certificates) or no keys")
    if not (curve or keys is not None or (curve is None and not is_loopback(host))):
        return None
    if not zmq.has("curve"):
        raise ValueError(f"CURVE is needed (host = {host!r}, curve = {curve!r}) but this "
                         f"ZeroMQ (libzmq {zmq.zmq_version()}) was built without it; expected "
                         "a pyzmq wheel (they bundle libzmq with CURVE)")
    if keys is not None:
        return CurveKeys.from_dir(keys, n_agents)
    return CurveKeys.generate(n_agents)


def _main(argv: Sequence[str] | None = None) -> int:
    """``python -m trackkit.network.processes agent --endpoint ... --index ...``: one agent
    process (started by the environment). Without arguments: print the protocol."""
    ap = argparse.ArgumentParser(prog="python -m trackkit.network.processes")
    sub = ap.add_subparsers(dest="command")
    ag = sub.add_parser("agent", help="run one agent (the environment starts these)")
    ag.add_argument("--endpoint", required=True)
    ag.add_argument("--index", type=int, required=True)
    ag.add_argument("--incarnation", type=int, default=0)
    ag.add_argument("--seed", type=int, required=True)
    ag.add_argument("--key", required=True, help="the SeedSequence spawn key, e.g. 0,3,1")
    ag.add_argument("--idle-timeout", type=float, default=300.0)
    ag.add_argument("--settings", default="{}", help="AgentSettings as JSON")
    ag.add_argument("--curve", action="store_true",
                    help="connect with CURVE; the keys are one JSON line on standard input")
    ns = ap.parse_args(argv)
    if ns.command != "agent":
        print(__doc__)
        return 0
    key = tuple(int(v) for v in ns.key.split(","))
    curve = json.loads(sys.stdin.readline()) if ns.curve else None
    _agent_main(ns.endpoint, ns.index, ns.incarnation,
                settings_from_dict(json.loads(ns.settings)), ns.seed, key, ns.idle_timeout,
                curve)
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
