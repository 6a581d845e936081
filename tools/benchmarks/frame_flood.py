"""python -m tools.benchmarks.frame_flood --config FILE [options]

A flood of large frames: join the stack (in peer mode as a peer, so linked to the detector
directly; in client mode through the router) as ``--principal`` and put full-HD ``bgr8``
frames (6.2 MB each) on one camera's frame key as fast as this process can, for
``--seconds``, each freshly stamped and numbered. ``--congestion block`` puts with congestion
control BLOCK, as a hostile or careless client may (the router overwrites it: docs/security.md,
"QoS by role"). ``--size`` and ``--rate-hz`` make it a smaller or a paced one. Prints
``flooding`` once its session is open and, at the end, how many frames it put and at what
rate. What the flood does to the detector: docs/benchmarks.md, "A flood of large frames".
"""

from __future__ import annotations

import argparse
import itertools
import threading

import numpy as np
import zenoh

from common.clock import BOOT_ID, mono_s, now
from common.keys import Keys
from common.messages import Frame, Header
from common.zenoh_bus import open_session
from stack.config_file import load_config

FULL_HD = (1920, 1080)
CONGESTION = {"drop": zenoh.CongestionControl.DROP, "block": zenoh.CongestionControl.BLOCK}


def flood(
    session: zenoh.Session,
    key: str,
    seconds: float,
    *,
    size: tuple[int, int] = FULL_HD,
    congestion: zenoh.CongestionControl = zenoh.CongestionControl.DROP,
    rate_hz: float = 0.0,
    stop: threading.Event | None = None,
) -> int:
    """Put ``size`` bgr8 frames on ``key`` for ``seconds`` (or until ``stop``), back to back
    or, with ``rate_hz``, at that rate; the number put. Each is stamped now and numbered, so
    that a receiver takes it as fresh."""
    width, height = size
    # Noise, not a flat grey: nothing on the way may compress it.
    pixels = np.random.default_rng(0).integers(0, 256, width * height * 3, np.uint8).tobytes()
    pub = session.declare_publisher(
        key, priority=zenoh.Priority.DATA, congestion_control=congestion
    )
    pause = stop or threading.Event()  # its wait() paces the puts
    start = mono_s()
    put = 0
    try:
        for seq in itertools.count(1):
            if rate_hz > 0:
                pause.wait(max(0.0, start + (seq - 1) / rate_hz - mono_s()))
            if mono_s() >= start + seconds or pause.is_set():
                break
            at = now()
            header = Header(stamp_ns=at.wall_ns, frame_id="flood", seq=seq, source="flood",
                            mono_ns=at.mono_ns, boot_id=BOOT_ID)  # fmt: skip
            frame = Frame(header=header, encoding="bgr8", width=width, height=height, data=pixels)
            pub.put(frame.encode())
            put = seq
    finally:
        pub.undeclare()
    return put


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m tools.benchmarks.frame_flood")
    parser.add_argument("--config", required=True, help="the stack's config file")
    parser.add_argument("--principal", default="camera", help="who to join as (default camera)")
    parser.add_argument("--camera", help="whose frame key (default the stack's first camera)")
    parser.add_argument("--seconds", type=float, default=20.0, help="how long (default 20)")
    parser.add_argument("--congestion", choices=sorted(CONGESTION), default="drop")
    parser.add_argument("--size", default="1920x1080", help="WxH (default 1920x1080)")
    parser.add_argument("--rate-hz", type=float, default=0.0, help="0: as fast as it can")
    args = parser.parse_args()
    config = load_config(args.config, environ={})
    camera = args.camera or next(iter(config.all_cameras))
    width, height = (int(n) for n in args.size.split("x"))
    with open_session(config.zenoh, config.principal(args.principal)) as session:
        print("flooding", flush=True)
        started = mono_s()
        put = flood(
            session,
            Keys(config.stack.prefix).frame(camera),
            args.seconds,
            size=(width, height),
            congestion=CONGESTION[args.congestion],
            rate_hz=args.rate_hz,
        )
        took = mono_s() - started
    print(f"put {put} frames in {took:.1f} s ({put / took:.1f} Hz)", flush=True)


if __name__ == "__main__":
    main()
