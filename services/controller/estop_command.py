"""The e-stop command line (``zstack estop engage|release``): publish an EStop until the
controller's status acknowledges it.

A module of its own, apart from the controller's service, so that the command imports only what
its first put needs: Zenoh, the config's [zenoh] and [stack] tables (stack/config_read.py: no
other service's settings) and the numpy-free control messages (no numpy, OpenCV or ONNX
Runtime; tests/unit/controller/test_estop_imports.py). Its first put leaves about as soon as
Python has started (docs/benchmarks.md, "E-stop command start-up" and "E-stop: from the command
to the first zero").
"""

from __future__ import annotations

import threading

import zenoh

from common import reach
from common.clock import BOOT_ID, mono_s, now
from common.contracts import ControllerState
from common.control_messages import ControllerStatus, EStop, Header
from common.errors import DecodeError, StackError
from common.keys import Keys
from common.settings import ZenohSettings, principal_name
from common.zenoh_bus import Publisher, QoS, open_session

# The e-stop command line: how long it repeats its message, how long a controller that answers
# but keeps its old state is given before that counts as a refusal, how long it waits for a
# first link to the stack before saying it reached nothing.
ESTOP_ACK_TIMEOUT_S = 10.0
ESTOP_VERDICT_S = 2.0
ESTOP_LINK_TIMEOUT_S = 3.0
ESTOP_REPEAT_S = 0.2


def send_estop(settings: ZenohSettings, prefix: str, engaged: bool, reason: str) -> int:
    """Publish an EStop until the controller's status acknowledges it; say truly what
    happened. An engage the controller could not save, a release it refused, no link to the
    stack and no controller at all are each one StackError line.

    The first put leaves as soon as the session has a link. It is put again at once when the
    controller's first status arrives without acknowledging it: in peer mode the first put
    reaches only the peers this session already meshed with, and the controller's status is
    the sign that it is one of them now (before, the next put came ``ESTOP_REPEAT_S`` later).
    Each status is looked at as it arrives: the command answers as soon as it is
    acknowledged."""
    keys = Keys(prefix)
    session = open_session(settings, principal_name(prefix, "estop"))
    lock = threading.Lock()
    heard: list[tuple[float, ControllerStatus]] = []  # the latest status and when it came
    news = threading.Event()  # a status came

    def on_status(sample: zenoh.Sample) -> None:
        try:
            status = ControllerStatus.decode(sample.payload.to_bytes())
        except DecodeError:
            return
        with lock:
            heard[:] = [(mono_s(), status)]
        news.set()

    def latest() -> tuple[float, ControllerStatus] | None:
        with lock:
            return heard[0] if heard else None

    sub = session.declare_subscriber(keys.controller_status(), on_status)
    pub = Publisher(session, keys.estop(), QoS.CONTROL)
    verb = "engage" if engaged else "release"
    seq = 0

    def put() -> float:
        # Each is stamped afresh, since the controller refuses a release that is not fresh.
        nonlocal seq
        seq += 1
        at = now()
        header = Header(
            stamp_ns=at.wall_ns, frame_id="", seq=seq, source="estop-cli",
            mono_ns=at.mono_ns, boot_id=BOOT_ID,
        )  # fmt: skip
        pub.put(EStop(header=header, engaged=engaged, reason=reason).encode())
        return at.mono_ns / 1e9

    try:
        if not reach.connected(session, ESTOP_LINK_TIMEOUT_S):
            raise StackError(
                reach.unreached(
                    f"cannot {verb} the e-stop: no link to the stack",
                    settings,
                    prefix,
                    "estop",
                    linked=False,
                )
            )
        start = last_put = put()
        first_status = True
        while mono_s() - start < ESTOP_ACK_TIMEOUT_S:
            # Repeated until acknowledged: a put may be lost while the mesh is being formed.
            news.wait(max(0.0, last_put + ESTOP_REPEAT_S - mono_s()))
            news.clear()
            got = latest()
            if got is not None:
                arrived, status = got
                if (status.state == ControllerState.ESTOP) == engaged:
                    if engaged and not status.estop_saved:
                        raise StackError(
                            "e-stop engaged: the robot is stopped, but the controller could NOT "
                            f"save the stop ({status.reason}); it holds while the controller "
                            "runs and until its state can be saved: fix the state folder, then "
                            "engage again"
                        )
                    print(f"e-stop {verb}d")
                    return 0
                if not engaged and arrived - start >= ESTOP_VERDICT_S:
                    raise StackError(f"the controller refused the release: {status.reason}")
                if first_status:
                    first_status = False
                    last_put = put()  # the controller is in reach now; the first may not have been
                    continue
            if mono_s() - last_put >= ESTOP_REPEAT_S:
                last_put = put()
        got = latest()
        if got is None:
            linked = reach.connected(session)
            raise StackError(
                reach.unreached(
                    f"no controller acknowledged the e-stop within {ESTOP_ACK_TIMEOUT_S:.0f} s",
                    settings,
                    prefix,
                    "estop",
                    linked=linked,
                    ready=_ready(session, keys) if linked else frozenset(),
                )
            )
        raise StackError(
            f"the controller answers but did not {verb} the e-stop within "
            f"{ESTOP_ACK_TIMEOUT_S:.0f} s: {got[1].state} ({got[1].reason})"
        )
    finally:
        sub.undeclare()
        session.close()


def _ready(session: zenoh.Session, keys: Keys) -> frozenset[str]:
    """The services whose health token is up: only on the failure path, so imported there."""
    from common.queries import ready_services

    return frozenset(ready_services(session, keys))
