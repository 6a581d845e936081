"""``record`` on the bus and by the clock it is given (an in-process test's): it joins no Zenoh
session and reads no clock of its own; the log time of each message is the given clock's."""

from __future__ import annotations

import threading
from pathlib import Path

from mcap.reader import make_reader

from common.bus import QoS
from common.clock import FakeClock
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import EStop, Header
from services.recorder.contract import RecorderSettings
from services.recorder.service import SERVICE, record
from stack.config import Config
from tests.polling import wait_for

CONFIG = Config(recorder=RecorderSettings(flush_period_s=0.05))
KEYS = Keys(CONFIG.stack.prefix)


def test_record_uses_the_bus_and_clock_it_is_given(tmp_path: Path) -> None:
    hub, clock, stop = MemoryHub(), FakeClock(), threading.Event()
    path = tmp_path / "given.mcap"
    lines: list[str] = []
    codes: list[int] = []
    bus = hub.join(SERVICE)
    recording = threading.Thread(
        target=lambda: codes.append(record(CONFIG, path, stop, lines.append, bus=bus, clock=clock))
    )
    recording.start()
    try:
        wait_for(lambda: hub.tokens(KEYS.health(SERVICE)), 10, "the recorder to be ready")
        header = Header(stamp_ns=clock.wall_ns(), frame_id="", seq=1, source="estop")
        estop = EStop(header=header, engaged=True, reason="test").encode()
        hub.join("estop").publisher(KEYS.estop(), QoS.CONTROL).put(estop)
    finally:
        stop.set()
        recording.join(30)
    assert codes == [0] and lines[-1].endswith(", done"), lines
    assert bus.closed  # its node closed the bus it was given
    with path.open("rb") as f:
        messages = [(c.topic, m.log_time) for _, c, m in make_reader(f).iter_messages()]
    estops = [at for topic, at in messages if "estop" in topic]
    assert estops == [clock.wall_ns()], messages
