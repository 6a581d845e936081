"""The camera service with a depth source, in-process on a MemoryHub: one DepthFrame per colour
frame with that frame's header, sent before it and resized with it; a bad depth PNG logged,
counted and skipped while its colour frame still goes out; the camera announced with depth and
its mounting."""

from __future__ import annotations

import threading
from pathlib import Path

import cv2
import numpy as np

from common.bus import Sample
from common.images import load_sample
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import DepthFrame, Frame, ServiceCounters
from services.camera import contract
from services.camera.contract import CameraSettings
from services.camera.service import run
from stack.config import Config
from tests.polling import wait_for
from tests.unit.heard import heard_cameras

CONFIG = Config()
CAMERA = CONFIG.stack.camera
KEYS = Keys(CONFIG.stack.prefix)


def _folders(tmp_path: Path) -> tuple[Path, Path]:
    """Three colour photos (80x60) and their depth PNGs; the second's is 8-bit (bad)."""
    rgb, depth = tmp_path / "rgb", tmp_path / "depth"
    rgb.mkdir()
    depth.mkdir()
    for i, name in enumerate(("chelsea", "coffee", "astronaut")):
        assert cv2.imwrite(str(rgb / f"{i}.png"), cv2.resize(load_sample(name), (80, 60)))
        mm = np.full((60, 80), 1000 * (i + 1), np.uint16)
        assert cv2.imwrite(str(depth / f"{i}.png"), mm if i != 1 else (mm // 100).astype(np.uint8))
    return rgb, depth


def test_a_depth_folder_camera_sends_depth_with_each_colour_frames_header(
    tmp_path: Path,
) -> None:
    rgb, depth = _folders(tmp_path)
    settings = CameraSettings(
        source=str(rgb),
        depth_source=str(depth),
        rate_hz=100.0,
        resize=(40, 30),
        intrinsics=(70.0, 70.0, 40.0, 30.0),
        depth_max_m=8.0,
        mount_height_m=0.42,
        mount_x_m=0.1,
        mount_y_m=-0.05,
        frame_id="rgbd_optical",
    )
    hub = MemoryHub()
    heard = heard_cameras(hub, KEYS)
    listener = hub.join("listener")
    arrivals: list[Frame | DepthFrame] = []  # in the order they were sent
    counters: list[ServiceCounters] = []
    lock = threading.Lock()

    def on(decode: type[Frame] | type[DepthFrame]) -> object:
        def handle(sample: Sample) -> None:
            with lock:
                arrivals.append(decode.decode(sample.payload))

        return handle

    listener.subscribe(KEYS.frame(CAMERA), on(Frame))  # type: ignore[arg-type]
    listener.subscribe(KEYS.depth(CAMERA), on(DepthFrame))  # type: ignore[arg-type]
    listener.subscribe(
        KEYS.counters("camera"), lambda s: counters.append(ServiceCounters.decode(s.payload))
    )
    stop = threading.Event()
    thread = threading.Thread(
        target=run,
        args=(CONFIG, CAMERA, settings, stop),
        kwargs={"bus": hub.join("camera", principal="camera")},
        daemon=True,
    )
    thread.start()
    wait_for(lambda: sum(isinstance(a, Frame) for a in arrivals) >= 7, 30, "seven colour frames")
    announced = heard.get(CAMERA)
    stop.set()
    thread.join(10)
    assert not thread.is_alive()

    assert announced is not None and announced.depth
    assert (announced.mount_height_m, announced.mount_x_m, announced.mount_y_m) == (
        0.42, 0.1, -0.05,
    )  # fmt: skip
    with lock:
        sent = list(arrivals)
    frames = [a for a in sent if isinstance(a, Frame)]
    depths = [a for a in sent if isinstance(a, DepthFrame)]
    # Each depth image just before the colour frame it was read with, with its very header.
    for i, item in enumerate(sent[:-1]):
        if isinstance(item, DepthFrame):
            after = sent[i + 1]
            assert isinstance(after, Frame) and after.header == item.header
    by_seq = {d.header.seq: d for d in depths}
    assert len(by_seq) == len(depths)
    # Folder order 0, 1, 2, 0, ...: the second image's depth PNG is 8-bit, so it has none.
    for n, frame in enumerate(frames):
        assert frame.header.frame_id == "rgbd_optical"
        if n % 3 == 1:
            assert frame.header.seq not in by_seq
            continue
        d = by_seq[frame.header.seq]
        assert (d.width, d.height, d.encoding) == (frame.width, frame.height, "16UC1") == (
            40, 30, "16UC1",
        )  # fmt: skip
        assert (d.fx, d.fy, d.cx, d.cy, d.range_max_m) == (35.0, 35.0, 19.75, 14.75, 8.0)
        values = np.unique(np.frombuffer(d.data, "<u2"))
        assert values.tolist() == [1000 * (n % 3 + 1)]
    final = counters[-1].counters
    bad = sum(1 for n in range(len(frames)) if n % 3 == 1)
    assert final[contract.BAD_DEPTH] == bad >= 2
    assert final[contract.DEPTH_OUT] == len(depths) == len(frames) - bad
    assert final[contract.FRAMES_OUT] == len(frames)
    assert final.get(contract.DEPTH_MISSING, 0) == 0
