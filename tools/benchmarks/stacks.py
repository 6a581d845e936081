"""What the scale and pool benchmarks share: stacks of simulated cameras and detectors on
private ports, a watch on their detections and the detectors' counters, and the figures
(percentiles, fairness, ratios).

A stack here is the simulator (or one camera process per camera) and the detector worker(s),
nothing else: no controller or metrics process competes for the cores, and the watch counts
the detections itself (capture-to-detections latency: the frame's capture stamp to the
detections' arrival here, one host's wall clock).
"""

from __future__ import annotations

import dataclasses
import sys
import threading
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from common.clock import mono_s, wall_ns
from common.counters import per_camera
from common.keys import Keys
from common.messages import Detections, ServiceCounters
from common.settings import ZenohSettings
from common.zenoh_bus import open_session
from services.detector import contract as detector
from services.metrics.pool import Duplicates
from stack.config import Config
from stack.config_file import to_toml
from tools.launch import free_port, start_supervisor, stop_supervisor, wait_ready
from tools.ports import private_endpoint

STARTUP_S = 240.0
STOP_S = 30.0
#: The services a stack runs besides its detector workers, by where its cameras come from.
SOURCES = {"sim": ("sim",), "processes": ("camera",)}
DEFAULT_SOURCE = "sample:chelsea"
#: A rate every camera asks for: above what one CPU detector serves, so the detector is the
#: bottleneck (overload) and fairness is tested.
DEFAULT_RATE_HZ = 10.0


# ---------------------------------------------------------------- pure figures


def percentile(values: Sequence[float], q: float) -> float:
    """The ``q``-th percentile of ``values``; NaN when there are none."""
    return float(np.percentile(values, q)) if len(values) else float("nan")


def fairness(fps: Sequence[float]) -> float:
    """The slowest camera's FPS over the fastest's (1 = fair); NaN without cameras or frames."""
    if not fps or max(fps) <= 0:
        return float("nan")
    return min(fps) / max(fps)


def ratio(a: float, b: float) -> float:
    """``a / b``; NaN when ``b`` is zero or either is NaN."""
    return a / b if b and not (np.isnan(a) or np.isnan(b)) else float("nan")


class PerCamera:
    """The figures over the cameras of a result (a dataclass) with ``fps``, ``p50_ms`` and
    ``p95_ms`` per camera."""

    __slots__ = ()
    fps: dict[str, float]
    p50_ms: dict[str, float]
    p95_ms: dict[str, float]

    @property
    def total_fps(self) -> float:
        return float(sum(self.fps.values()))

    @property
    def fairness(self) -> float:
        return fairness(list(self.fps.values()))

    @property
    def worst_p50_ms(self) -> float:
        return max(self.p50_ms.values(), default=float("nan"))

    @property
    def worst_p95_ms(self) -> float:
        return max(self.p95_ms.values(), default=float("nan"))

    def as_dict(self) -> dict[str, Any]:
        fields = dataclasses.asdict(self)  # type: ignore[call-overload]  # subclasses are dataclasses
        return {**fields, "total_fps": self.total_fps, "fairness": self.fairness}


def progress(text: str) -> None:
    """A progress line on stderr (the figures go to stdout)."""
    print(text, file=sys.stderr, flush=True)


# ---------------------------------------------------------------- configs


@dataclasses.dataclass(frozen=True, slots=True)
class CameraLoad:
    """One camera's rate and size (``(0, 0)``: the simulator's ``sim.width`` x ``height``)."""

    rate_hz: float
    size: tuple[int, int] = (0, 0)


def ring_yaw(i: int, cameras: int) -> float:
    """Camera ``i`` of ``cameras`` spread evenly round the robot, the first looking ahead;
    within -180..180 degrees."""
    yaw = 360.0 * i / cameras
    return yaw - 360.0 if yaw > 180.0 else yaw


def stack_config(
    base: Config,
    path: Path,
    loads: Sequence[CameraLoad],
    *,
    tag: str,
    cameras_from: str = "sim",
    source: str = DEFAULT_SOURCE,
    **detector: Any,
) -> Config:
    """``base`` with one camera per ``loads`` (the first is ``stack.camera``, then ``cam1``
    ...), on a private port and prefix (``<tag>/<port>``), running only the cameras' source
    and the detector, whose settings ``detector`` replaces (``workers``, ``max_batch`` ...)."""
    first_load, *further_loads = loads
    first = dataclasses.replace(
        base.camera,
        source=source,
        rate_hz=first_load.rate_hz,
        resize=first_load.size,
        loop=True,
    )
    further = tuple(
        (
            f"cam{i}",
            dataclasses.replace(
                first,
                frame_id=f"camera_cam{i}",
                mount_yaw_deg=ring_yaw(i, len(loads)),
                rate_hz=load.rate_hz,
                resize=load.size,
            ),
        )
        for i, load in enumerate(further_loads, 1)
    )
    # The simulator renders the first camera at sim.camera_rate_hz and sim.width x height
    # (each further one at its own rate_hz and resize: the pool weighs cameras by the same
    # figures), and starts its world once the (first) detector is ready: no controller here.
    width, height = (
        first_load.size if first_load.size != (0, 0) else (base.sim.width, base.sim.height)
    )
    sim = dataclasses.replace(
        base.sim,
        camera_rate_hz=first_load.rate_hz,
        width=width,
        height=height,
        wait_for=("detector",),
    )
    return dataclasses.replace(
        base,
        path=str(path),
        zenoh=ZenohSettings(endpoint=private_endpoint()),
        stack=dataclasses.replace(base.stack, prefix=f"{tag}/{free_port()}"),
        supervisor=dataclasses.replace(
            base.supervisor, services=(*SOURCES[cameras_from], "detector"), optional=()
        ),
        sim=sim,
        camera=first,
        cameras=further,
        detector=dataclasses.replace(base.detector, **detector),
    )


def source_services(config: Config, cameras_from: str) -> list[str]:
    """The services that bring a stack its frames: the simulator, or each camera's process."""
    if cameras_from == "sim":
        return ["sim"]
    return list(config.camera_services.values())


# ---------------------------------------------------------------- processes


@dataclasses.dataclass
class Stack:
    config: Config
    path: Path
    proc: Any  # subprocess.Popen[bytes]

    @property
    def log_path(self) -> Path:
        return self.path.with_suffix(".log")


def start_stack(config: Config, path: Path) -> Stack:
    """Write ``config`` to ``path`` and start its supervisor (its log beside it)."""
    path.write_text(to_toml(config))
    with path.with_suffix(".log").open("wb") as log:
        return Stack(config, path, start_supervisor(path, log))


def stop_all(stacks: Sequence[Stack]) -> None:
    """Stop every stack at once (a SIGINT each, in parallel), each killed if it lingers."""
    threads = [threading.Thread(target=stop_supervisor, args=(s.proc, STOP_S)) for s in stacks]
    for t in threads:
        t.start()
    for t in threads:
        t.join()


@dataclasses.dataclass(frozen=True, slots=True)
class Taken:
    """What a :class:`Watch` heard since its last reset."""

    elapsed_s: float
    latency_ms: dict[str, list[float]]  # per camera, one per detections message
    counters: dict[str, int]  # each detector counter's growth, summed over the workers
    duplicates: int  # frames detected twice (the same camera and frame)


class Watch:
    """One stack's detections per camera and its detector workers' counters.

    Keeps, since :meth:`reset`, each camera's capture-to-detections latencies and frames
    detected twice; and always each camera's detections (arrival on this process's monotonic
    clock, capture stamp) and each worker's latest counters (arrival, counters)."""

    def __init__(self, stack: Stack, workers: Sequence[str] = ()) -> None:
        """``workers``: the detector workers to hear (default: the config's)."""
        self.stack = stack
        self.cameras = list(stack.config.all_cameras)
        self.workers = list(workers or stack.config.detector_services)
        self.keys = Keys(stack.config.stack.prefix)
        self._lock = threading.Lock()
        self._counters: dict[str, tuple[float, dict[str, int]]] = {}
        self._arrivals: dict[str, list[tuple[float, int]]] = {c: [] for c in self.cameras}
        self.session = open_session(stack.config.zenoh, stack.config.principal("observer"))
        self._subs = [
            self.session.declare_subscriber(self.keys.detections(cam), self._handler(cam))
            for cam in self.cameras
        ]
        self._subs += [
            self.session.declare_subscriber(self.keys.counters(w), self._on_counters)
            for w in self.workers
        ]
        self.reset()

    def wait_ready(self, cameras_from: str, stop: threading.Event) -> None:
        """Until the cameras' source and every detector worker hold their health tokens."""
        want = {*source_services(self.stack.config, cameras_from), *self.workers}
        wait_ready(
            self.session,
            self.keys,
            want,
            self.stack.proc,
            STARTUP_S,
            stop=stop,
            log_path=self.stack.log_path,
        )

    def _handler(self, camera: str) -> Callable[[Any], None]:
        return lambda sample: self._on_detections(camera, sample)

    def _on_detections(self, camera: str, sample: Any) -> None:
        msg = Detections.decode(sample.payload.to_bytes())
        now_ns, now_s = wall_ns(), mono_s()
        with self._lock:
            self.latency_ms[camera].append((now_ns - msg.header.stamp_ns) / 1e6)
            self._duplicates.seen(camera, msg.header)
            self._arrivals[camera].append((now_s, msg.header.stamp_ns))

    def _on_counters(self, sample: Any) -> None:
        msg = ServiceCounters.decode(sample.payload.to_bytes())
        with self._lock:
            self._counters[msg.service] = (mono_s(), dict(msg.counters))

    def reset(self) -> None:
        with self._lock:
            self.latency_ms: dict[str, list[float]] = {c: [] for c in self.cameras}
            self._duplicates = Duplicates()
            self.start = mono_s()
            self.start_counters = {w: dict(c) for w, (_, c) in self._counters.items()}

    def take(self) -> Taken:
        with self._lock:
            grown: dict[str, int] = {}
            for worker, (_, now) in self._counters.items():
                before = self.start_counters.get(worker, {})
                for name, value in now.items():
                    grown[name] = grown.get(name, 0) + value - before.get(name, 0)
            return Taken(
                elapsed_s=mono_s() - self.start,
                latency_ms={c: list(v) for c, v in self.latency_ms.items()},
                counters=grown,
                duplicates=self._duplicates.total,
            )

    def serving(self, after: float = float("-inf")) -> dict[str, set[str] | None]:
        """Each worker's cameras by its latest counters (``serving.<cam>``), None for one
        not heard since ``after`` (monotonic seconds)."""
        with self._lock:
            latest = dict(self._counters)
        out: dict[str, set[str] | None] = {}
        for w in self.workers:
            at, counters = latest.get(w, (float("-inf"), {}))
            out[w] = (
                {c for c in self.cameras if counters.get(per_camera(detector.SERVING, c), 0) > 0}
                if at > after
                else None
            )
        return out

    def loads(self) -> dict[str, float]:
        """Each worker's load by its latest counters: its cameras' share of the frame rate."""
        with self._lock:
            return {
                w: c.get(detector.POOL_LOAD_PERMILLE, 0) / 1000
                for w, (_, c) in self._counters.items()
            }

    def first_after(self, camera: str, stamp_ns: int) -> float | None:
        """When (monotonic seconds) ``camera``'s first detections of a frame captured after
        ``stamp_ns`` (wall clock) arrived; None before any."""
        with self._lock:
            got = list(self._arrivals[camera])
        return next((t for t, stamp in got if stamp > stamp_ns), None)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self.session.close()


def split(serving: dict[str, set[str] | None], cameras: Iterable[str]) -> bool:
    """Whether ``serving`` (from :meth:`Watch.serving`) has every worker heard, each serving
    at least one camera, no camera twice and none missed."""
    sets = list(serving.values())
    if any(not s for s in sets):
        return False
    served = [c for s in sets if s for c in s]
    return len(served) == len(set(served)) and set(served) == set(cameras)
