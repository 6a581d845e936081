"""python -m tools.benchmarks ros2: what the bridge adds, side by side with the direct path.

Two paths, interleaved one message at a time so that both see the same machine load:

- frames in: a 640x480 bgr8 image put as a ROS 2 ``sensor_msgs/Image`` on the robot's graph,
  through the bridge (a real ``ros2`` service process), received as the stack's ``Frame``;
  against the same ``Frame`` put directly on the stack's key;
- detections out: the stack's ``Detections`` (10 boxes) through the bridge, received as a
  ``vision_msgs/Detection2DArray`` in the ROS graph; against the same message received
  directly on the stack's key.

Latency is put to receipt on one clock, in this process. Prints p50 and p95 per path and the
bridge's added p50, with the machine it ran on.
"""

from __future__ import annotations

import dataclasses
import json
import statistics
import sys
import threading
from typing import Any

import numpy as np

from common.boxes import Boxes
from common.clock import perf_ns, wall_ns
from common.keys import Keys
from common.machine import machine_info
from common.messages import Detections, Frame, Header
from common.settings import ZenohSettings
from common.zenoh_bus import open_session
from rosmsg.convert import DETECTION_2D_ARRAY, cdr_decode
from rosmsg.graph import RosGraph
from rosmsg.images import IMAGE, frame_to_image
from stack.config import Config
from stack.config_file import to_toml
from tools.launch import free_port, run_folder, start_supervisor, stop_supervisor, wait_ready
from tools.ports import private_endpoint

_TIMEOUT_S = 2.0  # a message not received by then counts as lost


def _config(ros_endpoint: str) -> Config:
    base = Config()
    return dataclasses.replace(
        base,
        zenoh=ZenohSettings(endpoint=private_endpoint()),
        stack=dataclasses.replace(base.stack, prefix=f"bench/{free_port()}"),
        ros2=dataclasses.replace(base.ros2, router=(ros_endpoint,), node="bridge_bench"),
        supervisor=dataclasses.replace(base.supervisor, services=("ros2",)),
    )


class _Arrivals:
    """Receipt times (perf_counter ns) by a message's stamp, with a wait for each."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._at: dict[int, int] = {}

    def arrived(self, stamp_ns: int) -> None:
        with self._cond:
            self._at[stamp_ns] = perf_ns()
            self._cond.notify_all()

    def wait(self, stamp_ns: int) -> int | None:
        with self._cond:
            self._cond.wait_for(lambda: stamp_ns in self._at, _TIMEOUT_S)
            return self._at.pop(stamp_ns, None)


def _frame(stamp_ns: int, pixels: np.ndarray) -> Frame:
    header = Header(stamp_ns=stamp_ns, frame_id="camera", seq=0, source="bench")
    return Frame(header=header, encoding="bgr8", width=640, height=480, data=pixels.tobytes())


def _detections(stamp_ns: int) -> Detections:
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 500, (10, 2)).astype(np.float32)
    return Detections(
        header=Header(stamp_ns=stamp_ns, frame_id="camera", seq=0, source="bench"),
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.hstack([xy, xy + 100]),
            scores=np.full(10, 0.8, np.float32),
            class_ids=np.zeros(10, np.int32),
            track_ids=np.arange(10, dtype=np.int32),
        ),
        class_names=("person",) * 10,
    )


def _summary(samples: list[float]) -> dict[str, float]:
    q = statistics.quantiles(samples, n=20) if len(samples) > 1 else samples * 19
    return {"p50_ms": round(statistics.median(samples), 3), "p95_ms": round(q[18], 3)}


def run(runs: int, progress: Any = print) -> dict[str, Any]:
    ros_endpoint = private_endpoint()
    config = _config(ros_endpoint)
    keys = Keys(config.stack.prefix)
    robot = RosGraph(dataclasses.replace(config.ros2, node="bench_robot"), host=True)
    workdir = run_folder("ros2-bench-")
    config_path = workdir / "stack.toml"
    config_path.write_text(to_toml(dataclasses.replace(config, path=str(config_path))))
    with (workdir / "stack.log").open("wb") as log:
        proc = start_supervisor(config_path, log)
    session = sender = None
    try:
        session = open_session(config.zenoh, config.principal("observer"))
        # The direct path crosses a link too.
        sender = open_session(config.zenoh, config.principal("observer"))
        wait_ready(session, keys, {"ros2"}, proc, 60.0)
        frames, dets_stack, dets_ros = _Arrivals(), _Arrivals(), _Arrivals()
        session.declare_subscriber(
            keys.frame(config.stack.camera),
            lambda s: frames.arrived(Frame.decode(s.payload.to_bytes()).header.stamp_ns),
        )
        session.declare_subscriber(
            keys.detections(config.stack.camera),
            lambda s: dets_stack.arrived(Detections.decode(s.payload.to_bytes()).header.stamp_ns),
        )
        robot.subscribe(
            config.ros2.detections_topic, DETECTION_2D_ARRAY,
            lambda _k, cdr: dets_ros.arrived(_ros_stamp(config, cdr)),
        )  # fmt: skip
        image_pub = robot.publisher(config.ros2.image_topic, IMAGE)
        frame_pub = sender.declare_publisher(keys.frame(config.stack.camera))
        det_pub = sender.declare_publisher(keys.detections(config.stack.camera))
        pixels = np.random.default_rng(1).integers(0, 255, (480, 640, 3), np.uint8)
        threading.Event().wait(1.0)  # the bridge's subscriptions reach us
        lat: dict[str, list[float]] = {k: [] for k in ("frame_direct", "frame_bridge",
                                                       "dets_direct", "dets_bridge")}  # fmt: skip
        lost = dict.fromkeys(lat, 0)
        for i in range(runs):
            stamp = wall_ns()
            pairs = (
                ("frame_bridge", lambda s=stamp: image_pub.put(
                    frame_to_image(config.ros2.distro, _frame(s, pixels))), frames),
                ("frame_direct", lambda s=stamp + 1: frame_pub.put(
                    _frame(s, pixels).encode()), frames),
                ("dets_bridge", lambda s=stamp + 2: det_pub.put(_detections(s).encode()),
                 dets_ros),
            )  # fmt: skip
            for name, send, arrivals in pairs if i % 2 else reversed(pairs):
                offset = {"frame_bridge": 0, "frame_direct": 1, "dets_bridge": 2}[name]
                t0 = perf_ns()
                send()
                at = arrivals.wait(stamp + offset)
                if name == "dets_bridge":
                    # The same put also reached the stack's own subscriber: the direct path.
                    direct = dets_stack.wait(stamp + offset)
                    if direct is None:
                        lost["dets_direct"] += 1
                    else:
                        lat["dets_direct"].append((direct - t0) / 1e6)
                if at is None:
                    lost[name] += 1
                else:
                    lat[name].append((at - t0) / 1e6)
            threading.Event().wait(0.02)
            if (i + 1) % 50 == 0:
                progress(f"ros2 benchmark: {i + 1}/{runs}")
        report = {name: {**_summary(v), "lost": lost[name]} for name, v in lat.items() if v}
        return {
            "runs": runs,
            "paths": report,
            "added_p50_ms": {
                "frames_in": round(
                    report["frame_bridge"]["p50_ms"] - report["frame_direct"]["p50_ms"], 3
                ),
                "detections_out": round(
                    report["dets_bridge"]["p50_ms"] - report["dets_direct"]["p50_ms"], 3
                ),
            },
            "machine": machine_info(),
        }
    finally:
        for s in (session, sender):
            if s is not None:
                s.close()
        stop_supervisor(proc, 10.0)
        robot.close()


def _ros_stamp(config: Config, cdr: memoryview) -> int:
    stamp = cdr_decode(config.ros2.distro, DETECTION_2D_ARRAY, cdr).header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def main(runs: int, as_json: bool) -> int:
    """Measure ``runs`` messages per path and print the figures (one JSON object with
    ``as_json``)."""

    def progress(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    result = run(runs, progress)
    if as_json:
        print(json.dumps(result))
        return 0
    for name, figures in result["paths"].items():
        print(f"{name:14} p50 {figures['p50_ms']:7.3f} ms  p95 {figures['p95_ms']:7.3f} ms"
              f"  lost {figures['lost']}")  # fmt: skip
    added = result["added_p50_ms"]
    print(f"bridge adds at p50: frames in {added['frames_in']:+.3f} ms, "
          f"detections out {added['detections_out']:+.3f} ms")  # fmt: skip
    return 0
