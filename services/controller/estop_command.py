"""The e-stop command line (``zstack estop engage|release``): publish an EStop until the
controller's status acknowledges it.

A module of its own, apart from the controller's service, so that the command imports only what
its first put needs: Zenoh, the config and the numpy-free control messages (no numpy, OpenCV or
ONNX Runtime; tests/unit/controller/test_estop_imports.py). Its first put leaves about as soon
as Python has started (docs/benchmarks.md, "E-stop command start-up").
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
from common.zenoh_bus import Publisher, QoS, open_session
from stack.config import Config

# The e-stop command line: how long it repeats its message, how long a controller that answers
# but keeps its old state is given before that counts as a refusal, how long it waits for a
# first link to the stack before saying it reached nothing.
ESTOP_ACK_TIMEOUT_S = 10.0
ESTOP_VERDICT_S = 2.0
ESTOP_LINK_TIMEOUT_S = 3.0
ESTOP_REPEAT_S = 0.2


def send_estop(config: Config, engaged: bool, reason: str) -> int:
    """Publish an EStop until the controller's status acknowledges it; say truly what
    happened. An engage the controller could not save, a release it refused, no link to the
    stack and no controller at all are each one StackError line."""
    keys = Keys(config.stack.prefix)
    session = open_session(config.zenoh, config.principal("estop"))
    lock = threading.Lock()
    heard: list[tuple[float, ControllerStatus]] = []  # the latest status and when it came

    def on_status(sample: zenoh.Sample) -> None:
        try:
            status = ControllerStatus.decode(sample.payload.to_bytes())
        except DecodeError:
            return
        with lock:
            heard[:] = [(mono_s(), status)]

    def latest() -> tuple[float, ControllerStatus] | None:
        with lock:
            return heard[0] if heard else None

    sub = session.declare_subscriber(keys.controller_status(), on_status)
    pub = Publisher(session, keys.estop(), QoS.CONTROL)
    verb = "engage" if engaged else "release"
    try:
        if not reach.connected(session, ESTOP_LINK_TIMEOUT_S):
            raise StackError(
                reach.unreached(
                    f"cannot {verb} the e-stop: no link to the stack",
                    config.zenoh,
                    config.stack.prefix,
                    "estop",
                    linked=False,
                )
            )
        start = mono_s()
        seq = 0
        while mono_s() - start < ESTOP_ACK_TIMEOUT_S:
            # Repeated until acknowledged: the first put may race the mesh being formed. Each
            # is stamped afresh, since the controller refuses a release that is not fresh.
            seq += 1
            at = now()
            header = Header(
                stamp_ns=at.wall_ns, frame_id="", seq=seq, source="estop-cli",
                mono_ns=at.mono_ns, boot_id=BOOT_ID,
            )  # fmt: skip
            pub.put(EStop(header=header, engaged=engaged, reason=reason).encode())
            threading.Event().wait(ESTOP_REPEAT_S)
            got = latest()
            if got is None:
                continue
            arrived, status = got
            if (status.state == ControllerState.ESTOP) == engaged:
                if engaged and not status.estop_saved:
                    raise StackError(
                        "e-stop engaged: the robot is stopped, but the controller could NOT "
                        f"save the stop ({status.reason}); it holds while the controller runs "
                        "and until its state can be saved: fix the state folder, then engage "
                        "again"
                    )
                print(f"e-stop {verb}d")
                return 0
            if not engaged and arrived - start >= ESTOP_VERDICT_S:
                raise StackError(f"the controller refused the release: {status.reason}")
        got = latest()
        if got is None:
            linked = reach.connected(session)
            raise StackError(
                reach.unreached(
                    f"no controller acknowledged the e-stop within {ESTOP_ACK_TIMEOUT_S:.0f} s",
                    config.zenoh,
                    config.stack.prefix,
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
