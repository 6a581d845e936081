"""python -m deploy.supervisor [--config FILE] [--duration S]

Starts every service of the stack config as its own process, shows their state and the stack's
live figures, restarts a service that crashes (with backoff), and stops everything cleanly on
Ctrl-C or SIGTERM. With --duration it runs headless for S seconds and ends with a JSON summary
on stdout (status lines go to stderr, so the summary can be piped). A service that exits for a
bad config, model or backend (exit codes 2, 3, 4) stops the whole stack: the supervisor exits
with that code and the service's own error line, unless the service is optional
(``supervisor.optional``): the stack then runs on without it, and the run exits 0 all the same.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
from typing import cast

import zenoh

from common.cli import Command, add_config, service_main
from common.clock import mono_s
from common.contracts import MetricsAnswer
from common.credential_modes import check_credentials_folder
from common.errors import BackendUnavailable, ConfigError, DecodeError, ModelError, StackError
from common.keys import Keys
from common.lifecycle import (
    EXIT_BACKEND,
    EXIT_CONFIG,
    EXIT_MODEL,
    run_main,
    setup_logging,
    stop_event,
)
from common.messages import ControllerStatus, GroundTruth, ServiceCounters, Twist
from common.queries import query_metrics
from common.settings import service_package
from deploy.crosscheck import cross_check, model_classes
from deploy.lock import acquire
from deploy.processes import ServiceProcess, stack_processes
from deploy.watchdog import Observation, check_settings, judge
from services.camera.contract import CameraSettings
from stack.config import Config
from stack.config_file import load_config
from stack.hub import open_hub

METRICS_TIMEOUT_S = 0.5
# the status line must not wait long for a missing metrics service


class LiveView:
    """What the supervisor shows and its watchdog judges: readiness from liveliness tokens (and
    when one vanished), each service's last counters (its work loop's heartbeat), the latest
    command, controller status and ground truth."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.keys = keys
        self.ready: set[str] = set()
        self.token_lost_at: dict[str, float] = {}
        self.progress_at: dict[str, float] = {}
        self.status: ControllerStatus | None = None
        self.twist: Twist | None = None
        self.truth: GroundTruth | None = None
        self._lock = threading.Lock()
        self._subs = [
            session.liveliness().declare_subscriber(
                keys.all_health(), self._on_health, history=True
            ),
            session.declare_subscriber(keys.all_counters(), self._on_counters),
            session.declare_subscriber(keys.controller_status(), self._on_status),
            session.declare_subscriber(keys.cmd_vel(), self._on_twist),
            session.declare_subscriber(keys.sim_truth(), self._on_truth),
        ]

    def _on_health(self, sample: zenoh.Sample) -> None:
        service = str(sample.key_expr).rsplit("/", 1)[-1]
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self.ready.add(service)
                self.token_lost_at.pop(service, None)
            else:
                self.ready.discard(service)
                self.token_lost_at[service] = mono_s()

    def _on_counters(self, sample: zenoh.Sample) -> None:
        try:
            ServiceCounters.decode(sample.payload.to_bytes())
        except DecodeError:
            return  # garbage is no sign of life
        service = str(sample.key_expr).rsplit("/", 1)[-1]
        with self._lock:
            self.progress_at[service] = mono_s()

    def _on_status(self, sample: zenoh.Sample) -> None:
        try:
            self.status = ControllerStatus.decode(sample.payload.to_bytes())
        except DecodeError:
            return  # the controller and metrics count garbage; the view just skips it

    def _on_twist(self, sample: zenoh.Sample) -> None:
        try:
            self.twist = Twist.decode(sample.payload.to_bytes())
        except DecodeError:
            return

    def _on_truth(self, sample: zenoh.Sample) -> None:
        try:
            self.truth = GroundTruth.decode(sample.payload.to_bytes())
        except DecodeError:
            return

    def is_ready(self, service: str) -> bool:
        with self._lock:
            return service in self.ready

    def observe(self, p: ServiceProcess) -> Observation:
        """What the watchdog judges ``p`` by (deploy/watchdog.py)."""
        with self._lock:
            return Observation(
                ready_at=p.ready_at,
                token_lost_at=self.token_lost_at.get(p.name),
                last_progress=self.progress_at.get(p.name),
            )


def status_line(procs: list[ServiceProcess], view: LiveView, metrics: MetricsAnswer | None) -> str:
    parts = []
    for p in procs:
        hung = f", {p.hangs} hung" if p.hangs else ""
        parts.append(f"{p.name}:{p.state}" + (f"(r{p.restarts}{hung})" if p.restarts else ""))
    line = " ".join(parts)
    if metrics:
        lat = metrics["latency_ms"]
        line += (
            f" | fps {metrics['fps']:.1f} det/frame {metrics['detections_per_frame']:.1f}"
            f" e2e p50 {lat['end_to_end']['p50']:.0f} ms"
        )
        if metrics.get("warnings"):
            line += f" | WARNING {', '.join(metrics['warnings'])} (said above)"
    if view.status is not None:
        s, t = view.status, view.twist
        cmd = f" v={t.linear[0]:+.2f} w={t.angular[2]:+.2f}" if t else ""
        target = f" {s.target}#{s.track_id}" if s.track_id >= 0 else f" {s.target}"
        line += f" | {s.mode} {s.state}{target if s.target else ''}{cmd}"
        if s.state == "estop" or not s.estop_saved:
            line += f" ({s.reason})"  # who stopped it, and whether the stop could be saved
        if s.no_laser:
            line += " NO LASER: forward motion unchecked for obstacles"
    if view.truth is not None:
        x, y, theta = view.truth.robot
        line += f" | pose x={x:+.2f} y={y:+.2f} th={math.degrees(theta):+.0f}deg"
    return line


def supervise(
    config: Config, stop: threading.Event, duration_s: float | None, *, timeline: bool = False
) -> int:
    log = setup_logging("supervisor")
    s = config.supervisor
    keys = Keys(config.stack.prefix)
    check_settings(config)
    if config.zenoh.auth != "none" or config.zenoh.uses_tls:
        # Before any process reads them: a folder others may write, a secret others may read.
        check_credentials_folder(config.zenoh.credentials_path)
    cross_check(config, model_classes)
    grace, progress = s.watchdog_grace_s, s.watchdog_progress_s
    lock = acquire(s.lock_dir, config.zenoh.endpoint, config.stack.prefix)
    session = open_hub(config)
    view = LiveView(session, keys)
    for warning in config_warnings(config):
        log.warning("%s", warning)
    # One process per service, and per camera: camera, camera_<name> (deploy/processes.py).
    procs = [ServiceProcess(name, command, s) for name, command in stack_processes(config)]
    log.info("hub on %s; starting %s", config.zenoh.endpoint, ", ".join(p.name for p in procs))
    for p in procs:
        p.start()
    end = mono_s() + duration_s if duration_s else None
    next_status = mono_s()
    last_metrics: MetricsAnswer | None = None
    warned: set[str] = set()  # the metrics answer's warnings already said
    failed: ServiceProcess | None = None
    # An optional "camera" makes every camera's process optional.
    optional = {p.name for p in procs if service_package(p.name) in s.optional}
    left_behind = set[str]()
    try:
        while failed is None and not stop.wait(0.1):
            now = mono_s()
            if end is not None and now >= end:
                break
            for p in procs:
                event = p.poll(now)
                if event:
                    log.warning("%s", event)
                if p.state == "starting" and view.is_ready(p.name):
                    p.mark_ready(now)
                elif p.state == "ready":
                    why = judge(p.name, view.observe(p), now, grace_s=grace, progress_s=progress)
                    if why:
                        log.warning("%s", p.hung(why, now))
                if p.state == "failed" and failed is None and p.name not in optional:
                    failed = p  # restarting will not help: stop the stack and say why
                elif p.state == "failed" and p.name not in left_behind:
                    left_behind.add(p.name)
                    why = p.last_error or f"exit code {p.last_exit}"
                    log.error("%s failed for good (%s); it is optional: the stack runs on", p.name,
                              why)  # fmt: skip
            if failed is None and now >= next_status:  # none once a failure stops it
                next_status = now + s.status_period_s
                last_metrics = query_metrics(session, keys, METRICS_TIMEOUT_S) or last_metrics
                warnings = last_metrics.get("warnings", {}) if last_metrics else {}
                for name, text in warnings.items():
                    if name not in warned:  # said once, in full; the status line names it
                        warned.add(name)
                        log.warning("%s", text)
                # Status lines go to stderr: stdout carries only the --duration summary.
                print(status_line(procs, view, last_metrics), file=sys.stderr, flush=True)
    finally:
        log.info("stopping")
        for p in reversed(procs):
            p.signal_stop()
        deadline = mono_s() + s.stop_timeout_s
        for p in procs:
            p.wait_stopped(deadline)
        session.close()
        lock.close()
    summary = {
        "services": {p.name: {"exit_code": p.last_exit, "restarts": p.restarts} for p in procs},
        "metrics": brief(last_metrics, timeline=timeline),
    }
    if duration_s:
        print(json.dumps(summary, indent=2), flush=True)
    if failed is not None:
        raise service_failure(failed)
    unclean = [p for p in procs if p.last_exit != 0]
    if not unclean:
        log.info("stopped; all services exited cleanly")
        return 0
    log.warning("stopped; %s", "; ".join(_exit_words(p) for p in unclean))
    # An optional service (the viewer, the recorder: nothing else reads from them) that failed
    # was said so when it did; the run itself did its work.
    return 1 if any(p.name not in optional for p in unclean) else 0


def _exit_words(p: ServiceProcess) -> str:
    """How one service ended, in words: ``viewer exited with code 2 (port 8766 is taken)``."""
    if p.last_exit is not None and p.last_exit < 0:
        how = f"was killed by signal {-p.last_exit}"
    else:
        how = f"exited with code {p.last_exit}"
    why = p.last_error
    for prefix in (f"{p.name}: ", "error: "):
        why = why.removeprefix(prefix)
    return f"{p.name} {how}" + (f" ({why})" if why else "")


def brief(metrics: MetricsAnswer | None, *, timeline: bool) -> MetricsAnswer | None:
    """The metrics answer for the summary: without its per-second ``timeline`` arrays (a few
    hundred lines for a minute's run) unless they were asked for."""
    if metrics is None or timeline:
        return metrics
    return cast(MetricsAnswer, {k: v for k, v in metrics.items() if k != "timeline"})


# Said once at start-up without the secure profile (docs/security.md).
OPEN_BUS_WARNING = (
    'NO ACCESS CONTROL (default profile, zenoh.auth = "none"): any process that reaches '
    "zenoh.endpoint can drive the robot and release its e-stop, with no credentials; on a real "
    "robot use the secure profile (make credentials; make run CONFIG=deploy/secure.toml)"
)


def config_warnings(config: Config) -> list[str]:
    """Settings that are valid but will not do what their author meant."""
    out = []
    if config.zenoh.auth == "none":
        out.append(OPEN_BUS_WARNING)
    services = config.supervisor.services
    first, default_source = config.stack.camera, CameraSettings().source
    changed = {
        ("camera" if name == first else f"cameras.{name}") + ".source": c.source
        for name, c in config.all_cameras.items()
        if c.source != default_source
    }
    if changed and "camera" not in services:
        sources = ", ".join(f"{field} is {source!r}" for field, source in changed.items())
        what = "the source is" if len(changed) == 1 else "the sources are"
        out.append(
            f"{sources} but the camera service is not in supervisor.services "
            f'{list(services)}: {what} unused; list "camera" there (in place of "sim") '
            "to use it"
        )
    out += _camera_warnings(config)
    return out


def _camera_warnings(config: Config) -> list[str]:
    """Several cameras set up in a way that works but hides something."""
    out = []
    cameras = config.all_cameras
    by_frame_id: dict[str, list[str]] = {}
    for name, c in cameras.items():
        by_frame_id.setdefault(c.frame_id, []).append(name)
    for frame_id, names in by_frame_id.items():
        if len(names) > 1:
            out.append(
                f"cameras {names} share frame_id {frame_id!r}: their frames differ only by key "
                "(a ROS 2 graph, a recording's reader and the sequence-gap count tell streams "
                "apart by frame_id); give each [cameras.<name>] a frame_id of its own"
            )
    s = config.supervisor
    if len(cameras) > 1 and "sim" in s.services and config.sim.ros2_robot:
        out.append(
            f"sim.ros2_robot plays a robot with one image topic (ros2.image_topic): only the "
            f"first camera, {config.stack.camera!r}, is rendered; {list(cameras)[1:]} are not"
        )
    return out


def service_failure(p: ServiceProcess) -> StackError:
    """The supervisor's own error for a service that failed for good: the service's words, and
    the service's exit code (2 config, 3 model, 4 backend) through the matching error type."""
    kinds: dict[int | None, type[StackError]] = {
        EXIT_CONFIG: ConfigError,
        EXIT_MODEL: ModelError,
        EXIT_BACKEND: BackendUnavailable,
    }
    why = p.last_error or f"{p.name}: exited with code {p.last_exit}"
    return kinds.get(p.last_exit, StackError)(f"{why} (exit code {p.last_exit}; not restarted)")


# --- the command line: python -m deploy.supervisor (zstack run) --------------------------------


def _run_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    p.add_argument("--duration", type=float, help="run headless for S seconds, then stop")
    p.add_argument(
        "--timeline", action="store_true",
        help="with --duration: keep the metrics' per-second timeline in the JSON summary",
    )  # fmt: skip


def _run(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    return supervise(config, stop, args.duration, timeline=args.timeline)


COMMANDS = [
    Command("run", "start the stack under the supervisor (Ctrl-C stops it)", _run_arguments, _run)
]


def main() -> int:
    return service_main("python -m deploy.supervisor", __doc__ or "", COMMANDS, default="run")


if __name__ == "__main__":
    run_main(main, "supervisor")
