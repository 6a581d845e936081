"""The one place where a Zenoh configuration is built, a session opened and a publisher
declared; :class:`ZenohBus` is the bus protocol (common/bus.py) over a Zenoh session.

Only service I/O modules (``services/*/service.py``, and ``rosmsg/graph.py`` for a ROS 2
graph's session), the supervisor and the command-line clients import this module; the logic
modules never touch the bus (tests/unit/test_bus_io.py).

Topology. In ``peer`` mode (the default) the supervisor listens on ``zenoh.endpoint``, services
connect there and then mesh directly. In ``client`` mode the supervisor is a Zenoh router and
every message passes through it; that is where authentication and access control run
(common/security.py; the rules: stack/access.py, the hub: stack/hub.py).

QoS by role (:class:`QoS`): control and safety messages (cmd_vel, e-stop) go first, express,
on the real-time queue; sensor data goes last, so that a flood of frames can never hold back a
stop. Every role drops under congestion, control too: Zenoh honours the flag on every hop, and
with "block" a router forwarding a command into one full link (a frozen listener) waits up to
5 s, holding up every other receiver's control traffic behind it. A dropped copy is lost only
for the receiver whose queue is full; the controller repeats cmd_vel every tick and the e-stop
command repeats until acknowledged (docs/security.md, "QoS by role"). And a client's choice is
not trusted: the router overwrites congestion control to DROP on every key but the e-stop
(:func:`drop_overwrite`).
"""

from __future__ import annotations

import itertools
import json
import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import zenoh

from common.bus import Answer, Declared, OnSample, OnToken, Reply, Sample
from common.bus import QoS as QoS
from common.credential_modes import check_folder, check_public, check_secret
from common.errors import ConfigError, StackError
from common.reach import connected
from common.security import (
    ROUTER_PRINCIPAL,
    ca_file,
    cert_file,
    is_router,
    key_file,
    made_by_role,
    password_file,
    remake_by_role,
    users_file,
)
from common.settings import ZenohSettings
from common.zenoh_errors import explain

log = logging.getLogger(__name__)

HUB_PRINCIPAL = ROUTER_PRINCIPAL


def zenoh_qos(qos: QoS) -> tuple[zenoh.Priority, zenoh.CongestionControl, bool]:
    """A role's profile in Zenoh's terms: (priority, congestion control, express)."""
    priority, drop, express = qos.value
    congestion = zenoh.CongestionControl.DROP if drop else zenoh.CongestionControl.BLOCK
    return getattr(zenoh.Priority, priority), congestion, express


class Publisher:
    """A declared publisher that stamps each sample with Zenoh's source info (its global id and
    a sequence number), so that a receiver can tell one publisher from another.

    A payload over ``max_payload_bytes`` is not sent: ``on_refused(key, size)`` is told, and
    ``put`` returns False. Zenoh does not refuse it, it loses it: on loopback a 64 MiB put
    with congestion control DROP never arrived while 48 MiB did (zenoh 1.10, measured), and
    nothing tells either end; the limit turns that into a count (zenoh.max_payload_bytes).
    """

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        qos: QoS,
        *,
        max_payload_bytes: int | None = None,
        on_refused: Callable[[str, int], None] | None = None,
    ) -> None:
        priority, congestion, express = zenoh_qos(qos)
        self.key = key
        self.qos = qos
        self.max_payload_bytes = max_payload_bytes
        self._on_refused = on_refused
        self._pub = session.declare_publisher(
            key, priority=priority, congestion_control=congestion, express=express
        )
        self._id = self._pub.id
        self._sn = itertools.count(1)

    def put(self, payload: bytes) -> bool:
        """Send ``payload``; False (and ``on_refused`` told) when it is over the limit."""
        if self.max_payload_bytes is not None and len(payload) > self.max_payload_bytes:
            if self._on_refused is not None:
                self._on_refused(self.key, len(payload))
            return False
        self._pub.put(
            payload,
            encoding=zenoh.Encoding("application/msgpack"),  # every payload is a common.codec one
            source_info=zenoh.SourceInfo(self._id, next(self._sn)),
        )
        return True

    def undeclare(self) -> None:
        self._pub.undeclare()


def source_of(sample: zenoh.Sample) -> str:
    """Who published ``sample``: its publisher's global id, or "unidentified"."""
    info = sample.source_info
    if info is None:
        return "unidentified"
    return f"{info.source_id.zid}/{info.source_id.eid}"


class ZenohBus:
    """The bus protocol (common/bus.py) over one Zenoh session, which it owns: ``close()``
    closes it."""

    def __init__(self, session: zenoh.Session, logger: logging.Logger | None = None) -> None:
        self.session = session
        self._log = logger or log
        self._zid = str(session.info.zid())

    @property
    def zid(self) -> str:
        return self._zid

    def publisher(
        self,
        key: str,
        qos: QoS,
        *,
        max_payload_bytes: int | None = None,
        on_refused: Callable[[str, int], None] | None = None,
    ) -> Publisher:
        return Publisher(
            self.session, key, qos, max_payload_bytes=max_payload_bytes, on_refused=on_refused
        )

    def subscribe(self, key: str, handle: OnSample) -> Declared:
        return self.session.declare_subscriber(key, lambda sample: handle(_sample(sample)))

    def subscribe_bounded(self, key: str, handle: OnSample, depth: int) -> Declared:
        return Bounded(self.session, key, handle, self._log, depth)

    def declare_token(self, key: str) -> Declared:
        return self.session.liveliness().declare_token(key)

    def watch_tokens(self, key: str, handle: OnToken) -> Declared:
        return self.session.liveliness().declare_subscriber(
            key,
            lambda s: handle(str(s.key_expr), s.kind == zenoh.SampleKind.PUT),
            history=True,
        )

    def live_tokens(self, key: str, timeout_s: float) -> list[str]:
        replies = self.session.liveliness().get(key, timeout=timeout_s)
        return [str(r.ok.key_expr) for r in replies if r.ok is not None]

    def serve(self, key: str, answer: Answer) -> Declared:
        def on_query(query: zenoh.Query) -> None:
            payload = query.payload.to_bytes() if query.payload is not None else b""
            out = answer(str(query.key_expr), payload)
            if out is not None:
                query.reply(key, out, encoding=zenoh.Encoding.APPLICATION_JSON)

        return self.session.declare_queryable(key, on_query)

    def query(self, key: str, timeout_s: float, payload: bytes = b"") -> list[Reply]:
        replies = self.session.get(key, timeout=timeout_s, payload=payload or None)
        return [
            Reply(str(r.ok.key_expr), r.ok.payload.to_bytes()) for r in replies if r.ok is not None
        ]

    def linked(self, timeout_s: float = 0.0) -> bool:
        return connected(self.session, timeout_s)

    def close(self) -> None:
        self.session.close()


class Bounded:
    """A subscription with at most ``depth`` samples waiting between Zenoh and its handler.

    A callback subscription (``ZenohBus.subscribe``) hands each sample from Zenoh's thread to
    a Python thread through a queue of 256 samples (zenoh-python's ``Callback(indirect=True)``):
    a publisher faster than the callback fills it, and with 6.2 MB frames that is 1.6 GB of
    stale frames held in the receiving process, each delivered late. Here Zenoh puts each
    sample in a FIFO of ``depth`` (``FifoChannel``) and this subscription's thread takes it
    from there. When it is full Zenoh stops reading that link: the sender's queue fills and
    its congestion control (DROP for every sample of the stack) drops the excess there, which
    the receiver sees as a gap in the sender's numbering. Nothing that arrives is lost on the
    way to the handler, so bad input is still counted in full, and Python's lock is never
    taken on Zenoh's thread. ``undeclare()`` ends the subscription and its thread.
    """

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        handle: OnSample,
        log: logging.Logger,
        depth: int,
    ) -> None:
        self.key = key
        self._handle = handle
        self._log = log
        self._sub = session.declare_subscriber(key, zenoh.handlers.FifoChannel(depth))
        # Received through the handler, not the subscriber: a recv() blocked on the
        # subscriber would hold it borrowed, and undeclare() would fail ("Already borrowed").
        self._queue = self._sub.handler
        self._thread = threading.Thread(target=self._run, name=f"bounded {key}", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            try:
                sample = self._queue.recv()
            except zenoh.ZError:
                return  # undeclared: the queue is closed
            try:
                self._handle(_sample(sample))
            except Exception:
                # As Zenoh does for a callback: a handler's bug is logged, and the
                # subscription goes on.
                self._log.exception("the handler of %s failed", self.key)

    def undeclare(self) -> None:
        self._sub.undeclare()
        if threading.current_thread() is not self._thread:  # from its own handler: no wait
            self._thread.join()


def _sample(sample: zenoh.Sample) -> Sample:
    return Sample(str(sample.key_expr), sample.payload.to_bytes(), source_of(sample))


def readable(path: Path, what: str, *, secret: bool = True, root: Path | None = None) -> str:
    """``path`` as Zenoh reads it, once it is there and no one else may change it (nor, for a
    ``secret``, read it): ConfigError, one line, otherwise (common/credential_modes.py).
    ``root``: the credentials folder, when ``path`` lies in a subfolder of it (a robot's:
    each folder from the root down is checked)."""
    root = root or path.parent
    if not path.is_file():
        fix = "run `zstack credentials`"
        if ca_file(root).is_file():  # a folder made for fewer cameras, or not all copied
            fix = (
                "make them again for the config's services and cameras with `zstack "
                "credentials --config FILE --force`, or copy the file from where they were made"
            )
        raise ConfigError(f"{what} {path} is missing: {fix} (docs/security.md)")
    folders = [path.parent]
    if root in path.parent.parents:
        folders += [f for f in path.parent.parents if f == root or root in f.parents]
    for folder in folders:
        check_folder(folder)
    (check_secret if secret else check_public)(path)
    return str(path)


def _own(settings: ZenohSettings, principal: str, file: Callable[[Path, str], Path]) -> Path:
    """``principal``'s own file; ConfigError, one line, when the folder holds it under its
    role alone (made by an older version: common.security.made_by_role)."""
    creds = settings.credentials_path
    if made_by_role(creds, principal):
        raise ConfigError(remake_by_role(creds))
    return file(creds, principal)


def _password(settings: ZenohSettings, principal: str) -> str:
    creds = settings.credentials_path
    path = Path(readable(_own(settings, principal, password_file), "password file", root=creds))
    try:
        password = path.read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read {path}: {exc}") from exc
    if not password:
        raise ConfigError(f"{path} is empty")
    return password


def _security(settings: ZenohSettings, principal: str, hub: bool) -> dict[str, Any]:
    """The ``transport`` options for authentication and TLS, by dotted path."""
    out: dict[str, Any] = {}
    creds = settings.credentials_path
    if settings.auth == "password":
        usrpwd: dict[str, Any] = {"user": principal, "password": _password(settings, principal)}
        if hub:
            usrpwd["dictionary_file"] = readable(users_file(creds), "user dictionary")
        out["transport/auth/usrpwd"] = usrpwd
    if settings.uses_tls:
        # Here, not at the top: cryptography costs every process about 15 MB, and only TLS
        # profiles read certificates.
        from common.certificates import refuse_server_capable

        refuse_server_capable(creds)  # any principal's certificate could pose as the router
        tls: dict[str, Any] = {
            "root_ca_certificate": readable(ca_file(creds), "CA certificate", secret=False),
            # Zenoh's default, stated: a client accepts only a certificate that names the host
            # it dialled, which only the supervisor's does (deploy/credentials.py).
            "verify_name_on_connect": True,
        }
        if hub:
            tls["listen_certificate"] = readable(
                cert_file(creds, principal), "certificate", secret=False
            )
            tls["listen_private_key"] = readable(key_file(creds, principal), "private key")
            tls["enable_mtls"] = settings.auth == "certificate"
            if settings.auth == "certificate" and settings.connect:
                # Linked to another host's router: prove this router with the same certificate
                # (client authentication too), so that the other admits it as the supervisor.
                tls["connect_certificate"] = tls["listen_certificate"]
                tls["connect_private_key"] = tls["listen_private_key"]
        elif settings.auth == "certificate":
            cert = _own(settings, principal, cert_file)
            tls["connect_certificate"] = readable(cert, "certificate", secret=False, root=creds)
            key = key_file(creds, principal)
            tls["connect_private_key"] = readable(key, "private key", root=creds)
            # A client sends its certificate only with this set too (checked on zenoh 1.10).
            tls["enable_mtls"] = True
        out["transport/link/tls"] = tls
    return out


def zenoh_config(
    settings: ZenohSettings,
    principal: str,
    *,
    access: dict[str, Any] | None = None,
    drop_keys: tuple[str, ...] = (),
) -> zenoh.Config:
    """Build the Zenoh config of one process.

    ``access`` is given for the supervisor only: its access-control rules. The supervisor
    listens on ``settings.endpoint`` (as a router in client mode); everyone else connects there.
    ``drop_keys``: as a router, the supervisor sets congestion control DROP on every put and
    delete it takes in on these keys (:func:`drop_overwrite`).
    """
    hub = access is not None
    if hub:
        listen = [settings.endpoint, *settings.listen]
        listen = [ep for ep in listen if not ep.endswith(":0")] or [settings.endpoint]
        connect = list(settings.connect)
        mode = "router" if settings.mode == "client" else "peer"
    else:
        listen = [] if settings.mode == "client" else list(settings.listen)
        connect = [settings.endpoint, *settings.connect]
        mode = settings.mode
    options: dict[str, Any] = {
        "mode": mode,
        "listen/endpoints": listen,
        "connect/endpoints": connect,
        "scouting/multicast/enabled": settings.multicast_scouting,
        **_security(settings, principal, hub),
    }
    if hub and settings.auth != "none":
        options["access_control"] = access
    if hub and mode == "router" and drop_keys:
        options["qos/network"] = [drop_overwrite(drop_keys)]
    conf = zenoh.Config()
    for path, value in options.items():
        conf.insert_json5(path, json.dumps(value))
    return conf


def drop_overwrite(key_exprs: tuple[str, ...]) -> dict[str, Any]:
    """Zenoh's ``qos/network`` item that makes the router drop, never wait, when a link a put
    on ``key_exprs`` goes to is full, whatever congestion control its publisher chose: it
    rewrites the sample as it comes in, and the router forwards it so (zenoh 1.10)."""
    return {
        "id": "drop_under_congestion",
        "messages": ["put", "delete"],
        "flows": ["ingress"],
        "key_exprs": list(key_exprs),
        "overwrite": {"congestion_control": "drop"},
    }


def open_configured(
    conf: zenoh.Config, settings: ZenohSettings, where: str, principal: str
) -> zenoh.Session:
    try:
        return zenoh.open(conf)
    except zenoh.ZError as exc:
        auth = f" as {principal!r} ({settings.auth} auth)" if settings.auth != "none" else ""
        # A refused router certificate reads as "unable to connect": say what is accepted.
        tls = (
            f" (over TLS only a router with a {ROUTER_PRINCIPAL}'s certificate signed by "
            f"{ca_file(settings.credentials_path)} is accepted)"
            if settings.uses_tls and not is_router(principal)
            else ""
        )
        raise ConfigError(
            f"cannot open a Zenoh session on {where}{auth}{tls}: {explain(str(exc))}"
        ) from exc


def open_session(settings: ZenohSettings, principal: str) -> zenoh.Session:
    """Join the stack as ``principal`` (a service's name, "estop" or "observer")."""
    conf = zenoh_config(settings, principal)
    where = settings.endpoint if settings.mode == "client" else ", ".join(settings.listen)
    return open_configured(conf, settings, where, principal)


class RosRouter(Protocol):
    """Where a ROS 2 graph's router is (the ROS 2 bridge's settings,
    services/ros2/contract.py)."""

    @property
    def router(self) -> tuple[str, ...]: ...

    @property
    def listen(self) -> tuple[str, ...]: ...

    @property
    def router_timeout_s(self) -> float: ...


def open_ros_session(s: RosRouter, *, host: bool = False) -> zenoh.Session:
    """A session in a ROS 2 graph, as an rmw_zenoh node joins it: a peer that connects to the
    router and listens for the other nodes. ``host`` opens the router itself instead (the
    simulator playing a robot). No router within ``router_timeout_s`` is a StackError."""
    options: dict[str, Any] = {
        "mode": "router" if host else "peer",
        "listen/endpoints": list(s.router if host else s.listen),
        "connect/endpoints": [] if host else list(s.router),
        "scouting/multicast/enabled": False,
        "connect/exit_on_failure": True,
        "connect/timeout_ms": int(s.router_timeout_s * 1000),
    }
    conf = zenoh.Config()
    for path, value in options.items():
        conf.insert_json5(path, json.dumps(value))
    try:
        return zenoh.open(conf)
    except zenoh.ZError as exc:
        where = ", ".join(s.router)
        if host:
            why = explain(str(exc))
            raise ConfigError(f"cannot host the ROS 2 router on {where}: {why}") from exc
        raise StackError(
            f"no rmw_zenoh router answered on {where} within {s.router_timeout_s:.0f} s: "
            "start rmw_zenohd on the robot, or set ros2.router"
        ) from exc
