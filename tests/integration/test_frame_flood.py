"""A flood of large frames, straight into the detector (issue 29, item 3): a peer on the
default (peer-mode) bus, linked to the detector directly, puts full-HD frames (6.2 MB) on one
camera's key as fast as it can for 20 s, while another camera sends at 5 Hz. The detector keeps
only the newest frame of each camera, so nothing may queue behind it: its resident memory stays
within 1.5 times what it took serving both cameras at their normal rates, and the flooded camera
is still served at least as often as the steady one (it always has a frame waiting).

The real detector service (the real default model) alone, as in test_detector_cameras.py; the
flood comes from its own process (``python -m tools.benchmarks.frame_flood``).
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import threading
from typing import Any

import pytest

from common.clock import mono_s
from tests.integration.conftest import REPO, wait_for
from tests.integration.test_detector_cameras import Camera, Detector, serve  # noqa: F401 (a fixture)
from tools.benchmarks.frame_flood import FULL_HD
from tools.launch import rss_kb

pytestmark = pytest.mark.integration

FLOOD_S = 20.0
FLOODERS = 3
MAX_GROWTH = 1.5  # the detector's peak resident memory in the flood over its figure before it
#: The flooded camera's detections during the flood over the steady camera's: it always has a
#: frame waiting, so it gets at least every other round (1.0); half of that, for a loaded CI.
MIN_FLOOD_SHARE = 0.5


def rss(det: Detector) -> int:
    kb = rss_kb(det.proc.pid)
    assert kb is not None, f"the detector is gone:\n{det.log()}"
    return kb


def test_a_flood_of_large_frames_is_bounded(serve: Any) -> None:  # noqa: F811
    det: Detector = serve({"flooded": {"frame_id": "flooded"}, "steady": {"frame_id": "steady"}})
    flooded = Camera(det, "flooded", "astronaut", FULL_HD, 5.0)
    steady = Camera(det, "steady", "chelsea", (640, 480), 5.0)
    pace = threading.Event()  # never set: wait() paces the sending, it waits for nothing

    def send_both(until: float, cameras: list[Camera]) -> None:
        while mono_s() < until:
            for cam in cameras:
                cam.send()
            pace.wait(0.2)

    # Serving both at 5 Hz, full HD included: the working set of normal service. Sent until
    # answered (a loaded machine may take the detector a while to serve both cameras: frames
    # sent for a fixed time before that were never answered).
    def sent_and_answered() -> bool:
        send_both(mono_s() + 0.2, [flooded, steady])
        return len(flooded.answered(det)) >= 5

    wait_for(sent_and_answered, 90, "detections of full-HD frames")
    idle: list[int] = []
    until = mono_s() + 4.0
    while mono_s() < until:
        send_both(mono_s() + 0.2, [flooded, steady])
        idle.append(rss(det))
    idle_kb = statistics.median(idle)

    steady_before = len(steady.answered(det))
    argv = [sys.executable, "-m", "tools.benchmarks.frame_flood", "--config",
            str(det.config.path), "--camera", "flooded", "--seconds", str(FLOOD_S)]  # fmt: skip
    floods = [
        subprocess.Popen(argv, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for _ in range(FLOODERS)
    ]
    for flood in floods:
        assert flood.stdout is not None
        assert flood.stdout.readline().strip() == "flooding", flood.stderr
    peak = 0
    while any(flood.poll() is None for flood in floods):
        send_both(mono_s() + 0.2, [steady])
        peak = max(peak, rss(det))
    outs = [flood.communicate() for flood in floods]
    assert all(flood.returncode == 0 for flood in floods), outs
    out = " / ".join(o.strip() for o, _ in outs)
    flood_dets = [d for d in det.detections("flooded") if d.header.source == "flood"]
    served = {"steady": len(steady.answered(det)) - steady_before, "flooded": len(flood_dets)}
    # How old a flood frame was when the detector took it (one host: one clock).
    ages = [(d.received_ns - d.header.stamp_ns) / 1e9 for d in flood_dets]
    # Let the detector settle, then look once more: what it kept after the flood.
    send_both(mono_s() + 5.0, [steady])
    after = rss(det)
    age_p50, age_max = statistics.median(ages or [0]), max(ages or [0])
    print(f"detector RSS: idle {idle_kb / 1024:.0f} MB, flood peak {peak / 1024:.0f} MB "
          f"({peak / idle_kb:.2f}x), 5 s after {after / 1024:.0f} MB; {out}; detections in "
          f"the flood {served}, frame age when taken p50 {age_p50:.3f} s, max {age_max:.3f} s; "
          f"dropped {det.counter('dropped.flooded')}, stale "
          f"{det.counter('frames_stale.flooded')}")  # fmt: skip
    put = sum(int(o.split()[1]) for o, _ in outs)
    assert put >= 10 * FLOOD_S, out  # it did flood: over 10 Hz
    assert peak <= MAX_GROWTH * idle_kb, f"{peak / idle_kb:.2f}x idle"
    assert served["steady"] > 0, served
    assert served["flooded"] >= MIN_FLOOD_SHARE * served["steady"], served
