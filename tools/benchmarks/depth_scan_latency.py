"""python -m tools.benchmarks.depth_scan_latency [--against REV] [--frames N] [--rounds R]

From a depth frame put on the bus to the controller holding its virtual scan, in process: this
checkout (the depth scan stage, services/depthscan, puts the scan and the controller's
DepthInput takes it) against another revision (default ``main``) whose controller made the
scan itself (its depth intake), side by side, rounds alternating so that both see the same
load. Each side runs in a process of its own from its own tree (a ``git archive`` of the
other revision), on an in-memory hub delivering on its own thread (as Zenoh's callbacks do),
with the real clock and each side's own scan thread; a 640x480 16UC1 image of a level floor
seen from 0.6 m, one frame at a time (20 ms apart: no queueing). Not included: Zenoh's
transport (the scan is about 1.5 KB; the depth image, 600 KB, travels once either way).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
W, H, HFOV_DEG, HEIGHT_M = 640, 480, 60.0, 0.6


def _frame_bytes(seq: int) -> bytes:
    """A level floor seen by a level camera HEIGHT_M up, as a 16UC1 DepthFrame stamped now."""
    from common.clock import BOOT_ID, now
    from common.messages import DepthFrame, Header

    fx = W / 2 / np.tan(np.radians(HFOV_DEG / 2))
    cx, cy = W / 2, H / 2
    rows = (np.arange(H) + 0.5 - cy) / fx
    z = np.where(rows > 0, HEIGHT_M / np.where(rows > 0, rows, 1.0), 0.0)
    mm = np.clip(np.round(np.where(z < 10.0, z, 0.0) * 1000.0), 0, 65535).astype("<u2")
    image = np.repeat(mm[:, None], W, axis=1)
    at = now()
    header = Header(
        stamp_ns=at.wall_ns, frame_id="camera", seq=seq, source="camera",
        mono_ns=at.mono_ns, boot_id=BOOT_ID,
    )  # fmt: skip
    return DepthFrame(
        header=header, encoding="16UC1", width=W, height=H, data=image.tobytes(),
        fx=fx, fy=fx, cx=cx, cy=cy, range_min_m=0.2, range_max_m=10.0,
    ).encode()  # fmt: skip


def measure(frames: int) -> list[float]:
    """This tree's latencies (ms), depth frame put -> the controller holds its scan."""
    from common.announce import to_chunk
    from common.bus import QoS
    from common.keys import Keys
    from common.memory_bus import MemoryHub
    from common.messages import CameraAnnouncement
    from common.node import Node
    from services.controller.contract import ControllerSettings
    from services.controller.service import ControlLoop
    from stack.config import Config, SupervisorSettings

    tmp = Path(tempfile.mkdtemp())
    s = ControllerSettings(
        obstacle_sources=("depth",), estop_file=str(tmp / "estop.json"),
        depth_memory_file=str(tmp / "memory.npz"),
    )  # fmt: skip
    staged = _has_stage()
    services = ("depthscan", "controller") if staged else ("controller",)
    config = Config(controller=s, supervisor=SupervisorSettings(services=services))
    hub = MemoryHub(threads=1)
    keys = Keys(config.stack.prefix)
    camera = hub.join("camera")
    announced = CameraAnnouncement(
        camera="front", source="camera", hfov_deg=HFOV_DEG, width=W, height=H, rate_hz=10.0,
        depth=True, mount_height_m=HEIGHT_M,
    )  # fmt: skip
    camera.declare_token(keys.camera_announcement("front", to_chunk(announced)))
    node = Node("controller", config, bus=hub.join("controller"))
    loop = ControlLoop(config, node)
    held = threading.Event()
    stop = threading.Event()
    if staged:
        from services.depthscan.service import DepthScanStage

        stage_node = Node("depthscan", config, bus=hub.join("depthscan"))
        stage = DepthScanStage(config, stage_node)
        serve: Any = stage.intake.serve
        hub.drain()
        assert loop.depth is not None
        latest = loop.depth._scans["front"]  # the controller's held scan of the camera
        latest.arrived = held
    else:
        assert loop.depth is not None and loop.virtual_scans is not None
        serve = loop.depth.serve
        put = loop.virtual_scans.put

        def seen(cam: str, scan: Any) -> None:  # called as soon as the intake holds it
            held.set()
            put(cam, scan)

        loop.depth.on_scan = seen
    worker = threading.Thread(target=serve, args=(stop, 0.1), daemon=True)
    worker.start()
    pub = camera.publisher(keys.depth("front"), QoS.SENSOR)
    out = []
    for seq in range(1, frames + 1):
        payload = _frame_bytes(seq)
        held.clear()
        t0 = time.perf_counter()
        pub.put(payload)
        if not held.wait(5.0):
            raise SystemExit(f"frame {seq}: no scan held within 5 s")
        out.append((time.perf_counter() - t0) * 1000.0)
        time.sleep(0.02)
    stop.set()
    worker.join(5.0)
    return out


def _has_stage() -> bool:
    try:
        import services.depthscan.service  # noqa: F401
    except ImportError:
        return False
    return True


def _run(tree: Path, frames: int) -> list[float]:
    done = subprocess.run(
        [sys.executable, "-m", "tools.benchmarks.depth_scan_latency", "--measure", str(frames)],
        cwd=tree, env={"PYTHONPATH": str(tree), "PATH": "/usr/bin:/bin"},
        capture_output=True, text=True, timeout=600, check=True,
    )  # fmt: skip
    result: list[float] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def _figures(ms: list[float]) -> str:
    a = np.asarray(ms)
    return (
        f"n {len(a)}  p50 {np.percentile(a, 50):.2f} ms  p95 {np.percentile(a, 95):.2f} ms  "
        f"max {a.max():.2f} ms"
    )


def main() -> int:
    p = argparse.ArgumentParser(prog="python -m tools.benchmarks.depth_scan_latency")
    p.add_argument("--against", default="main", help="the other revision (default main)")
    p.add_argument("--frames", type=int, default=100, help="frames per round (default 100)")
    p.add_argument("--rounds", type=int, default=3, help="rounds of each (default 3)")
    p.add_argument("--measure", type=int, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.measure:
        import logging

        logging.disable(logging.WARNING)
        print(json.dumps(measure(args.measure)))
        return 0
    with tempfile.TemporaryDirectory() as other:
        archive = subprocess.run(
            ["git", "archive", args.against], cwd=REPO, capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", other], input=archive, check=True)
        me = Path(__file__).resolve()
        (Path(other) / "tools" / "benchmarks" / me.name).write_bytes(me.read_bytes())
        before: list[float] = []
        after: list[float] = []
        for _ in range(args.rounds):
            before += _run(Path(other), args.frames)
            after += _run(REPO, args.frames)
    print(f"{args.against} (the controller makes the scan): {_figures(before)}")
    print(f"this checkout (the depth scan stage):            {_figures(after)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
