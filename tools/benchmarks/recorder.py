"""python -m tools.benchmarks recorder: the default stack with and without the recorder.

One stack (simulator, detector, controller, metrics: the default) runs throughout; a recorder
process (``python -m services.recorder record``, as the service would run) is started and
stopped in alternation, so that both conditions see the same machine load, phase after phase.
In each phase this process counts the detections (frames the detector finished: FPS) and pairs
each command with the frame it reacts to (capture-to-command latency, one clock: the stamps).
Prints each condition's FPS and latency p50 over all its phases, and their ratio.
"""

from __future__ import annotations

import dataclasses
import json
import re
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

from common.clock import mono_s
from common.errors import StackError
from common.files import temp_root
from common.keys import Keys
from common.machine import machine_info
from common.messages import Detections, Twist
from common.settings import REPO_ROOT, ZenohSettings
from common.spawn import spawn, stop_child
from common.zenoh_bus import open_session
from stack.config import Config
from stack.config_file import load_config, to_toml
from tools.launch import free_port, start_supervisor, stop_supervisor, wait_ready
from tools.ports import private_endpoint

STARTUP_S = 180.0
WARMUP_S = 10.0
STACK = ("sim", "detector", "controller", "metrics")
#: Where a frame's time to detections goes: capture -> the detector took it, then its stages.
STAGES = ("transport", "preprocess", "inference", "postprocess")


class _Phase:
    """What one phase saw: detections' arrival times, and capture-to-command latencies."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.reset()

    def reset(self) -> None:
        with self._lock:
            self.frames = 0
            self.start = mono_s()
            self.latency_ms: list[float] = []
            self.detections_ms: list[float] = []
            self.stages_ms: dict[str, list[float]] = {s: [] for s in STAGES}
            self._seen: set[int] = set()

    def on_detections(self, msg: Detections) -> None:
        with self._lock:
            self.frames += 1
            self.detections_ms.append((msg.published_ns - msg.header.stamp_ns) / 1e6)
            self.stages_ms["transport"].append((msg.received_ns - msg.header.stamp_ns) / 1e6)
            for stage in STAGES[1:]:
                self.stages_ms[stage].append(msg.timing_ms.get(stage, float("nan")))

    def on_twist(self, msg: Twist) -> None:
        with self._lock:
            stamp = msg.input_stamp_ns
            if stamp > 0 and stamp not in self._seen:  # the first command for each frame
                self._seen.add(stamp)
                self.latency_ms.append((msg.header.stamp_ns - stamp) / 1e6)

    def take(self) -> tuple[int, float, list[float], list[float], dict[str, list[float]]]:
        with self._lock:
            elapsed = mono_s() - self.start
            stages = {s: list(v) for s, v in self.stages_ms.items()}
            return self.frames, elapsed, list(self.latency_ms), list(self.detections_ms), stages


def _config(base: Config, workdir: Path) -> Config:
    return dataclasses.replace(
        base,
        zenoh=ZenohSettings(endpoint=private_endpoint()),
        stack=dataclasses.replace(base.stack, prefix=f"bench/{free_port()}"),
        supervisor=dataclasses.replace(base.supervisor, services=STACK),
        recorder=dataclasses.replace(base.recorder, output_dir=str(workdir)),
        controller=dataclasses.replace(base.controller, estop_file=str(workdir / "estop.json")),
    )


def _p50(values: list[float]) -> float:
    return float(np.nanpercentile(values, 50)) if values else float("nan")


def _summary(
    frames: int, seconds: float, e2e: list[float], dets: list[float],
    stages: dict[str, list[float]],
) -> dict[str, float]:  # fmt: skip
    return {
        "fps": frames / seconds if seconds > 0 else 0.0,
        "e2e_p50_ms": _p50(e2e),  # capture -> first command reacting to the frame
        "detections_p50_ms": _p50(dets),  # capture -> detections sent
        **{f"{s}_p50_ms": _p50(v) for s, v in stages.items()},
        "commands": float(len(e2e)),
    }


def _add(total: list[Any], took: tuple[Any, ...]) -> list[Any]:
    """Phase figures summed: counts and seconds added, lists (and lists per stage) joined."""
    out = []
    for t, v in zip(total, took, strict=True):
        out.append({s: t[s] + v[s] for s in t} if isinstance(t, dict) else t + v)
    return out


def main(
    config_path: str | None, rounds: int, phase_s: float, as_json: bool, stop: threading.Event
) -> int:
    """Run the stack of ``config_path`` (None: deploy/stack.toml) for ``rounds`` phases of
    ``phase_s`` seconds in each condition, and print the figures (as JSON with ``as_json``)."""
    if rounds < 1 or phase_s <= 0:
        raise StackError("--rounds must be >= 1 and --phase > 0")
    with tempfile.TemporaryDirectory(prefix="recorder-bench-", dir=temp_root()) as tmp:
        workdir = Path(tmp)
        config = _config(load_config(config_path), workdir)
        path = workdir / "stack.toml"
        path.write_text(to_toml(dataclasses.replace(config, path=str(path))))
        with (workdir / "stack.log").open("wb") as log:
            proc = start_supervisor(path, log)
        try:
            figures = _run(config, path, proc, workdir, rounds, phase_s, stop)
        finally:
            stop_supervisor(proc, 30.0)
    off, on = figures["without"], figures["with"]
    figures["fps_ratio"] = on["fps"] / off["fps"] if off["fps"] else float("nan")
    figures["e2e_p50_ratio"] = on["e2e_p50_ms"] / off["e2e_p50_ms"]
    figures["detections_p50_ratio"] = on["detections_p50_ms"] / off["detections_p50_ms"]
    figures["machine"] = machine_info()
    if as_json:
        print(json.dumps(figures, indent=2))
        return 0
    print(f"{'':18}{'without':>10}{'with':>10}{'ratio':>8}")
    print(f"{'FPS':18}{off['fps']:10.2f}{on['fps']:10.2f}{figures['fps_ratio']:8.3f}")
    print(
        f"{'capture->cmd p50':18}{off['e2e_p50_ms']:10.0f}{on['e2e_p50_ms']:10.0f}"
        f"{figures['e2e_p50_ratio']:8.3f}   (ms; {off['commands']:.0f} and "
        f"{on['commands']:.0f} commands reacting to a frame)"
    )
    print(
        f"{'capture->det p50':18}{off['detections_p50_ms']:10.0f}"
        f"{on['detections_p50_ms']:10.0f}{figures['detections_p50_ratio']:8.3f}   (ms)"
    )
    for stage in STAGES:
        a, b = off[f"{stage}_p50_ms"], on[f"{stage}_p50_ms"]
        print(f"{'  ' + stage + ' p50':18}{a:10.1f}{b:10.1f}{b / a if a else float('nan'):8.3f}")
    print(f"({rounds} phases of {phase_s:.0f} s each; recorder wrote "
          f"{figures['recorded_mb']:.1f} MB, dropped {figures['dropped']})")  # fmt: skip
    return 0


def _run(
    config: Config, path: Path, proc: subprocess.Popen[bytes], workdir: Path,
    rounds: int, phase_s: float, stop: threading.Event,
) -> dict[str, Any]:  # fmt: skip
    keys = Keys(config.stack.prefix)
    phase = _Phase()
    session = open_session(config.zenoh, config.principal("observer"))
    subs = [
        session.declare_subscriber(
            keys.detections(config.stack.camera),
            lambda s: phase.on_detections(Detections.decode(s.payload.to_bytes())),
        ),
        session.declare_subscriber(
            keys.cmd_vel(), lambda s: phase.on_twist(Twist.decode(s.payload.to_bytes()))
        ),
    ]
    try:
        wait_ready(session, keys, set(STACK), proc, STARTUP_S, stop=stop)
        stop.wait(WARMUP_S)
        totals: dict[str, list[Any]] = {
            c: [0, 0.0, [], [], {s: [] for s in STAGES}] for c in ("without", "with")
        }
        dropped, recorded = 0, 0.0
        for k in range(rounds):
            for condition in ("without", "with"):
                recorder = None
                out, err_path = workdir / f"bench-{k}.mcap", workdir / f"bench-{k}.log"
                if condition == "with":
                    with err_path.open("wb") as err:  # the child holds its own descriptor
                        # In the stack's session, as the service runs (common/spawn.py).
                        recorder = spawn(
                            [sys.executable, "-m", "services.recorder", "record", "--config",
                             str(path), "--out", str(out)],
                            cwd=REPO_ROOT, stderr=err,
                        )  # fmt: skip
                    wait_ready(session, keys, {"recorder"}, proc, 60.0, stop=stop)
                phase.reset()
                if stop.wait(phase_s):
                    raise KeyboardInterrupt
                took = phase.take()
                totals[condition] = _add(totals[condition], took)
                if recorder is not None:
                    stop_child(recorder, 60.0)
                    found = re.findall(r"(\d+) dropped", err_path.read_text(errors="replace"))
                    dropped += int(found[-1]) if found else 0
                    recorded += out.stat().st_size / 1e6
                    out.unlink()
        return {
            **{c: _summary(*totals[c]) for c in totals},
            "rounds": rounds, "phase_s": phase_s, "dropped": dropped,
            "recorded_mb": recorded,
        }  # fmt: skip
    finally:
        for sub in subs:
            sub.undeclare()
        session.close()
