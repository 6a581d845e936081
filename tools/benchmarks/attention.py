"""python -m tools.benchmarks attention: the target's camera first when short of capacity.

Three cameras (front, left, rear) at the default input (640), rendered by the simulator at
``--camera-rate`` (default 10 Hz, a real camera's ``camera.rate_hz``), on one detector worker,
which on a 2-core CPU detects 4 to 7 frames a second of the 30 they send. Each scenario is run with
``detector.attention`` on and off (off: the fair rounds), through the scenario runner
(tools/scenarios/runner.py), side by side:

- ``ahead`` and ``behind`` with all three cameras: whether each passes, each camera's
  detections a second, and a camera's detections a second while a person is in its view
  (the simulator's truth at each frame's capture) against while nobody is, over every camera
  (in ``behind`` the person passes from the rear camera's view to the front one's as the
  robot turns);
- ``appears`` (alice ahead; bob steps into the empty rear camera's view for 2 s, four times):
  for each time, from bob's entering the rear camera's field of view (the simulator's truth)
  to the first detections of the rear camera naming a person on a frame captured while he
  was in it ("missed": none).

Detections a second count the frames captured while the scenario clock ran (before, the
controller is not up and every camera is served alike).

Progress goes to stderr, the table (or ``--json``) to stdout.
"""

from __future__ import annotations

import bisect
import dataclasses
import itertools
import json
import math
import sys
from collections.abc import Callable
from typing import Any

from common.contracts import ScenarioResult
from common.messages import GroundTruth
from simworld.scenarios import LEFT_CAMERA, REAR_CAMERA, SCENARIOS
from stack.config import Config
from tools.scenarios.runner import run_scenario
from tools.scenarios.score import ScenarioLog

CAMERAS = {"left": LEFT_CAMERA, "rear": REAR_CAMERA}
SCENARIO_NAMES = ("ahead", "behind", "appears")


def _variant(name: str, attention: bool) -> Any:
    sc = SCENARIOS[name]
    detector = {**sc.detector, "imgsz": 0, "attention": attention}  # 0: the model's own, 640
    return dataclasses.replace(sc, cameras=CAMERAS, detector=detector)


def _in_view(truth: GroundTruth, target: str, yaw_deg: float, hfov_deg: float) -> bool:
    if target not in truth.target_ids:
        return False
    x, y, theta = truth.robot
    tx, ty = truth.targets_xy[truth.target_ids.index(target)]
    b = math.atan2(ty - y, tx - x) - theta - math.radians(yaw_deg)
    return abs(math.degrees(math.atan2(math.sin(b), math.cos(b)))) <= hfov_deg / 2


def visits(rec: ScenarioLog, target: str, yaw_deg: float, hfov_deg: float) -> list[tuple[int, int]]:
    """Each stretch of ``target``'s centre within the camera's field of view, as the wall
    stamps of the first and last truth that had it there."""
    out: list[tuple[int, int]] = []
    start = last = None
    for truth in rec.truths:
        if _in_view(truth, target, yaw_deg, hfov_deg):
            start = truth.header.stamp_ns if start is None else start
            last = truth.header.stamp_ns
        elif start is not None and last is not None:
            out.append((start, last))
            start = last = None
    if start is not None and last is not None:
        out.append((start, last))
    return out


def first_detection_s(rec: ScenarioLog, camera: str, since_ns: int, until_ns: int) -> float | None:
    """Seconds from ``since_ns`` to the publication of ``camera``'s first detections naming a
    person on a frame captured from ``since_ns`` to ``until_ns``; None if there were none."""
    for det in rec.detections.get(camera, []):
        if since_ns <= det.header.stamp_ns <= until_ns and "person" in det.class_names:
            return (det.published_ns - since_ns) / 1e9
    return None


def rates(rec: ScenarioLog) -> dict[str, float]:
    """Each camera's detections a second, of frames captured while the scenario clock ran
    (before it starts the controller is not yet up, and every camera is served alike)."""
    running = [t.header.stamp_ns for t in rec.truths if t.sim_time_s > 0]
    if len(running) < 2:
        return {}
    t0, t1 = running[0], running[-1]
    return {
        cam: sum(t0 <= d.header.stamp_ns <= t1 for d in dets) / ((t1 - t0) / 1e9)
        for cam, dets in rec.detections.items()
    }


def seeing_rates(
    rec: ScenarioLog, yaws: dict[str, float], hfov_deg: float
) -> tuple[float | None, float | None]:
    """Detections a second of a camera while a person is in its view, and while nobody is
    (the simulator's truth at each frame's capture), over every camera, in the scenario's
    window: ``(seeing, empty)``, None where no camera was ever so."""
    truths = [t for t in rec.truths if t.sim_time_s > 0]
    if len(truths) < 2:
        return None, None
    stamps = [t.header.stamp_ns for t in truths]

    def occupied(truth: GroundTruth, cam: str) -> bool:
        return any(_in_view(truth, who, yaws[cam], hfov_deg) for who in truth.target_ids)

    time_s = {True: 0.0, False: 0.0}
    for a, b in itertools.pairwise(truths):
        for cam in yaws:
            time_s[occupied(a, cam)] += (b.header.stamp_ns - a.header.stamp_ns) / 1e9
    count = {True: 0, False: 0}
    for cam, dets in rec.detections.items():
        for det in dets:
            i = bisect.bisect_right(stamps, det.header.stamp_ns) - 1
            if 0 <= i < len(truths) - 1:
                count[occupied(truths[i], cam)] += 1
    seeing, empty = (count[k] / time_s[k] if time_s[k] > 0 else None for k in (True, False))
    return seeing, empty


def measure(base: Config, name: str, attention: bool, log: Callable[[str], None]) -> dict[str, Any]:
    rec = ScenarioLog()
    result: ScenarioResult = run_scenario(
        base, name, log=log, variant=_variant(name, attention), rec=rec
    )
    yaws = {"front": 0.0, **{c: float(v["mount_yaw_deg"]) for c, v in CAMERAS.items()}}
    seeing, empty = seeing_rates(rec, yaws, base.camera.hfov_deg)
    figures: dict[str, Any] = {
        "scenario": name,
        "attention": attention,
        "success": bool(result["success"]),
        "duration_s": result.get("duration_s"),
        "detections_per_s": rates(rec),
        "seeing_per_s": seeing,
        "empty_per_s": empty,
        "seeing_over_empty": seeing / empty if seeing is not None and empty else None,
        "log": result.get("log"),
    }
    if name == "appears":
        yaw = float(REAR_CAMERA["mount_yaw_deg"])
        figures["first_detection_s"] = [
            first_detection_s(rec, "rear", start, end)
            for start, end in visits(rec, "bob", yaw, base.camera.hfov_deg)
        ]
    return figures


def _fmt(v: Any) -> str:
    return "-" if v is None else f"{v:.2f}" if isinstance(v, float) else str(v)


def table(rows: list[dict[str, Any]]) -> str:
    lines = [
        f"{'scenario':9} {'attention':9} {'pass':5} {'front/s':>8} {'left/s':>7} {'rear/s':>7} "
        f"{'seeing/s':>8} {'empty/s':>7} {'ratio':>5}  bob found after (s)"
    ]
    for r in rows:
        d = r["detections_per_s"]
        lines.append(
            f"{r['scenario']:9} {'on' if r['attention'] else 'off':9} "
            f"{'yes' if r['success'] else 'NO':5} {_fmt(d.get('front')):>8} "
            f"{_fmt(d.get('left')):>7} {_fmt(d.get('rear')):>7} "
            f"{_fmt(r['seeing_per_s']):>8} {_fmt(r['empty_per_s']):>7} "
            f"{_fmt(r['seeing_over_empty']):>5}  "
            + " ".join(
                _fmt(v) if v is not None else "missed" for v in r.get("first_detection_s", [])
            )
        )
    return "\n".join(lines)


def main(base: Config, names: tuple[str, ...], as_json: bool, camera_rate_hz: float) -> int:
    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    # Every camera at the real cameras' rate (the simulator's own default is lower).
    base = dataclasses.replace(
        base, sim=dataclasses.replace(base.sim, camera_rate_hz=camera_rate_hz)
    )

    rows = []
    for name in names:
        for attention in (True, False):
            log(f"attention benchmark: {name}, attention {'on' if attention else 'off'}")
            rows.append(measure(base, name, attention, log))
    print(json.dumps(rows) if as_json else table(rows))
    return 0
