"""The depth cameras' images in, their virtual scans and the depth memory out: the depth scan
stage's work (services/depthscan/service.py is its bus side), over depthscan/.

A depth image is large (600 KB at 640x480) and turning it into a scan takes a few
milliseconds, so nothing of it happens on a bus thread. The bus callback only leaves the
payload in its camera's latest-only slot (:meth:`DepthIntake.offer`: a newer image replaces
one not yet looked at, counted ``depth_dropped``); the stage's thread
(:meth:`DepthIntake.serve`) decodes, judges freshness, makes the scan and hands it on at once
(``on_scan``: published on ``<prefix>/scan/virtual/<camera>``), then what the memory holds
(``on_memory``: :meth:`DepthIntake.memory`).

The intake drops, counted, before any conversion: the images of cameras not announced with
depth and those put by a Zenoh session other than the one that announced the camera
(``depth_foreign``, both at :meth:`DepthIntake.offer`, before decoding; depthscan/trust.py), images
stamped on this host's boot more than ``depth_future_tolerance_s`` ahead of its clock
(``depth_future``), images of more than ``depth_max_pixels``, and frames whose
intrinsics or mounting are implausible (depthscan/frame.py ``implausible``): with no scan, the
controller reads depth missing and the robot does not drive forward. A camera whose frames keep
arriving older than the one held (a second stream on its key) is logged as a WARNING and
counted in the gauge ``depth_second_stream``, which the metrics turn into a warning. Only every
``depth_scan_stride_px``-th row and column is converted to metres. A scan is kept only if the
announcement it was made with is still the camera's. An error while making a scan is logged,
counted and the thread goes on.

The memory (depthscan/local_map.py) is moved by the controller's commands (:meth:`moved`, from
cmd_vel), written to its file at once when it gains a hazard and every ``depth_memory_save_s``,
and taken back by a stage that starts within ``depth_memory_max_age_s`` of the last write.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from common.clock import BOOT_ID, Clock, Stamp
from common.counters import IN, LATE, input_counter, per_camera
from common.files import atomic_write_bytes
from common.freshness import FreshnessGate, Verdict, capture_age_s
from common.messages import CameraAnnouncement, DepthFrame, Header, LaserScan
from common.node import Tally
from common.odometry import Odometry
from depthscan.frame import Plausible, ScanParams, blind_zone, implausible, sample_frame, usable
from depthscan.local_map import LocalMap, MapParams
from depthscan.observe import observe
from depthscan.trust import LateWatch, ahead_on_same_clock, foreign_source
from perception import Intrinsics, Mounting
from services.controller.contract import ControllerSettings
from services.depthscan import contract

#: Bytes of a depth payload beyond its pixels' (header, intrinsics, framing): a payload larger
#: than ``depth_max_pixels`` 4-byte pixels and this is dropped before it is decoded.
PAYLOAD_OVERHEAD_BYTES = 64 * 1024


class DepthIntake:
    """Every announced depth camera's newest virtual scan and the depth memory (thread-safe: a
    bus thread offers, the stage's thread makes the scans)."""

    def __init__(
        self,
        s: ControllerSettings,
        tally: Tally,
        tolerance_s: float,
        clock: Clock,
        memory_path: Path | None = None,
        on_scan: Callable[[str, LaserScan], None] | None = None,
        on_memory: Callable[[LaserScan, LaserScan], None] | None = None,
    ) -> None:
        self.tally = tally
        self.clock = clock
        # Each new virtual scan, as soon as it is held (published: the stage's service).
        self.on_scan = on_scan
        # What the memory holds, after each batch of images (published: the stage's service).
        self.on_memory = on_memory
        self.timeout_s = s.depth_timeout_s
        self.tolerance_s = tolerance_s
        self.params = ScanParams(
            floor_margin_m=s.depth_floor_margin_m,
            max_height_m=s.depth_max_height_m,
            stride_px=s.depth_scan_stride_px,
            resolution_deg=s.depth_scan_resolution_deg,
            hole_px=s.depth_hole_px,
            edge_band_px=s.depth_edge_band_px,
        )
        # The short memory (depthscan/local_map.py), moved by the controller's commands.
        self.odometry = Odometry()
        self.map = LocalMap(
            MapParams(
                resolution_m=s.depth_memory_resolution_m,
                size_m=s.depth_memory_size_m,
                corridor_half_width_m=s.robot_width_m / 2,
                footprint_half_m=s.robot_width_m / 2,
            ),
            s.depth_scan_resolution_deg,
        )
        self._map_lock = threading.Lock()
        # The map kept on disk across restarts (None: not kept, as in unit tests).
        self.memory_path = memory_path
        self.memory_save_s = s.depth_memory_save_s
        self.memory_coast_s = s.depth_memory_coast_s
        self._saved_at = -math.inf  # monotonic s of the last write
        self._unsaved_hazard = False  # a hazard or unknown cell new since the last write
        if memory_path is not None:
            self._restore(memory_path, s.depth_memory_max_age_s)
        self.plausible = Plausible(
            hfov_tolerance_deg=s.depth_hfov_tolerance_deg,
            max_pixel_aspect=s.depth_max_pixel_aspect,
            max_height_m=s.depth_max_height_m,
        )
        self.max_pixels = s.depth_max_pixels
        self.safety_distance_m = s.safety_distance_m
        self._cond = threading.Condition()
        self._waiting: dict[str, bytes] = {}  # camera -> its newest payload not looked at
        self._lock = threading.Lock()  # the cameras and their scans
        self._cameras: dict[str, CameraAnnouncement] = {}  # announced with depth
        self._scans: dict[str, tuple[LaserScan, float]] = {}  # camera -> (scan, arrival mono s)
        # A gate outlives its camera's withdrawal: a replay is refused after a re-announcement.
        self._gates: dict[str, FreshnessGate] = {}
        self._told: dict[str, CameraAnnouncement] = {}  # the blind zone logged, per camera
        # Whose depth is believed (depthscan/trust.py).
        self.future_tolerance_s = s.depth_future_tolerance_s
        self.late_watch = LateWatch(s.depth_late_warn_count, s.depth_late_warn_window_s)
        self._unchecked: dict[str, CameraAnnouncement] = {}  # told: no zid to check, per camera

    def set_cameras(self, cameras: Mapping[str, CameraAnnouncement]) -> None:
        """The cameras announced now: those announced with depth are used; the scans of the
        others (withdrawn, or announced again without depth) are dropped."""
        with self._lock:
            self._cameras = {c: a for c, a in cameras.items() if a.depth}
            for camera in list(self._scans):
                if camera not in self._cameras:
                    del self._scans[camera]
            for camera in self._cameras:
                self._gates.setdefault(
                    camera, FreshnessGate(self.timeout_s, self.tolerance_s, BOOT_ID)
                )

    def offer(self, camera: str, payload: bytes, source: str) -> None:
        """A depth image's payload as it arrives (on a bus thread), put by ``source`` (the
        sample's publisher, "zid/eid"): left for :meth:`serve`, unless its camera is not
        announced with depth (counted ``depth_unannounced``) or ``source`` is not in the
        session that announced it (``depth_foreign``)."""
        with self._lock:
            announced = self._cameras.get(camera)
            unchecked = announced is not None and not announced.zid
            tell = unchecked and self._unchecked.get(camera) != announced
            if tell and announced is not None:
                self._unchecked[camera] = announced
        if announced is None:
            self._unannounced(camera)
            return
        if foreign_source(announced, source):
            self._refuse(
                contract.DEPTH_FOREIGN, camera,
                f"put by {source!r:.80}, not by the session that announced the camera "
                f"({announced.zid}): a second stream on its key",
            )  # fmt: skip
            return
        if tell:
            self.tally.log.warning(
                "depth camera %s is announced by %s without its session id (an older source): "
                "its depth is taken from any publisher on its key",
                camera, announced.source or "?",
            )  # fmt: skip
        with self._cond:
            if camera in self._waiting:
                self.tally.counters.add(contract.DEPTH_DROPPED)
                self.tally.counters.add(per_camera(contract.DEPTH_DROPPED, camera))
            self._waiting[camera] = payload
            self._cond.notify()

    def handle_waiting(self, timeout_s: float) -> int:
        """Make the scans of the images waiting (waiting up to ``timeout_s`` for one), then
        hand on what the memory holds (``on_memory``: also when no image came, so that the
        controller knows the stage alive); how many images were looked at."""
        with self._cond:
            self._cond.wait_for(lambda: bool(self._waiting), timeout_s)
            taken, self._waiting = self._waiting, {}
        for camera, payload in taken.items():
            self._handle(camera, payload)
        if self.on_memory is not None:
            self.on_memory(*self.memory(self.clock.now()))
        return len(taken)

    def serve(
        self, stop: threading.Event, poll_s: float, beat: Callable[[], None] | None = None
    ) -> None:
        """The stage's thread: make scans until ``stop`` is set (looked at every ``poll_s``),
        ``beat`` called on every pass (the counters: the stage's heartbeat). An error is
        logged (rate-limited), counted ``depth_errors``, and the thread goes on: the scans it
        did not make age, and depth goes missing as a stale stream does."""
        while not stop.is_set():
            try:
                self.handle_waiting(poll_s)
                # A new hazard is written at once, not at the next period: a crash in
                # between would forget it.
                self.save_memory(force=self._unsaved_hazard)
            except Exception as exc:
                self.tally.reject(
                    contract.DEPTH_ERRORS, f"making a virtual scan failed: {exc!r:.200}"
                )
            if beat is not None:
                beat()

    def _unannounced(self, camera: str) -> None:
        self.tally.reject(
            contract.DEPTH_UNANNOUNCED,
            f"depth from {camera!r:.80}, a camera not announced with depth, ignored",
        )

    def _handle(self, camera: str, payload: bytes) -> None:
        tally = self.tally
        with self._lock:
            announced, gate = self._cameras.get(camera), self._gates.get(camera)
        if announced is None or gate is None:
            self._unannounced(camera)
            return
        key = tally.keys.depth(camera)
        if len(payload) > self.max_pixels * 4 + PAYLOAD_OVERHEAD_BYTES:
            self._refuse(contract.DEPTH_OVERSIZE, camera, f"a {len(payload)}-byte depth payload")
            return
        msg = tally.decode(key, DepthFrame.decode, payload)
        if msg is None:
            return
        if msg.width * msg.height > self.max_pixels:
            self._refuse(contract.DEPTH_OVERSIZE, camera, f"a {msg.width}x{msg.height} image")
            return
        now = self.clock.now()
        ahead = ahead_on_same_clock(msg.header, now, BOOT_ID, self.future_tolerance_s)
        if ahead:  # before the gate, which would remember its stamp as the source's newest
            self._refuse(
                input_counter(contract.DEPTH, Verdict.FUTURE), camera,
                f"stamped on this host {ahead:.3f} s ahead of its clock (at most "
                f"{self.future_tolerance_s:g} s, controller.depth_future_tolerance_s)",
            )  # fmt: skip
            return
        verdict, age = gate.check(msg.header, now)
        if verdict is not Verdict.FRESH:
            counter = input_counter(contract.DEPTH, verdict)
            tally.reject(counter, f"{verdict} depth from {camera} ({age:.2f} s) ignored")
            tally.counters.add(per_camera(counter, camera))
            return
        self._watch_order(camera, msg.header.stamp_ns, key)
        mount = Mounting.of(announced)
        if not usable(mount):
            tally.reject(
                contract.DEPTH_NO_MOUNT,
                f"depth from {camera} cannot show obstacles: its source announces no height "
                "above the floor (mount_height_m 0), so the floor cannot be taken out",
                key=key,
            )
            tally.counters.add(per_camera(contract.DEPTH_NO_MOUNT, camera))
            return
        intr = Intrinsics.of(msg)
        why = implausible(intr, announced.hfov_deg, mount, self.plausible)
        if why:
            self._refuse(contract.DEPTH_IMPLAUSIBLE, camera, why)
            return
        try:
            seen = observe(
                sample_frame(msg, self.params.stride_px), intr, mount, self.params, msg.header,
                msg.range_max_m, msg.range_min_m,
            )  # fmt: skip
        except ValueError as exc:
            tally.bad_input(key, exc)
            return
        scan = seen.scan
        with self._lock:
            held = self._scans.get(camera)
            # Made with the announcement still current: not a withdrawn or changed camera's.
            current = self._cameras.get(camera) == announced
            newer = current and (held is None or held[0].header.stamp_ns <= msg.header.stamp_ns)
            if newer:
                self._scans[camera] = (scan, self.clock.mono_s())
            tell = newer and self._told.get(camera) != announced
            if tell:
                self._told[camera] = announced
        if newer:
            # Remembered where the robot stood when the frame was captured.
            captured = now.mono_ns / 1e9 - capture_age_s(msg.header, now, BOOT_ID)
            pose = self.odometry.pose_at(captured)
            with self._map_lock:
                if self.map.observe(seen, pose):
                    self._unsaved_hazard = True  # written at once: see serve
            if self.on_scan is not None:  # after the map: a failure to publish loses nothing
                self.on_scan(camera, scan)
        if tell:
            floor_m, below_m = blind_zone(intr, mount, self.safety_distance_m)
            tally.log.info(
                "depth camera %s (%.2f m above the floor) sees the floor from %.2f m ahead of "
                "it; at the safety distance (%.2f m) an obstacle lower than %.2f m is unseen",
                camera, mount.height_m, floor_m, self.safety_distance_m, below_m,
            )  # fmt: skip
        if not current:
            tally.reject(
                contract.DEPTH_UNANNOUNCED,
                f"depth from {camera} made with an announcement no longer current, ignored",
            )
            return
        counter = input_counter(contract.DEPTH, IN if newer else LATE)
        if newer:
            tally.counters.add(counter)
        else:
            tally.reject(counter, f"depth from {camera} older than the one held ignored")
        tally.counters.add(per_camera(counter, camera))

    def _watch_order(self, camera: str, stamp_ns: int, key: str) -> None:
        """A fresh frame of ``camera`` stamped ``stamp_ns``: is it older than the one held, and
        have so many been lately that a second stream runs on its key? The gauge
        ``depth_second_stream`` follows; a WARNING (rate-limited) says so while it lasts."""
        tally = self.tally
        with self._lock:
            held = self._scans.get(camera)
            late = held is not None and stamp_ns < held[0].header.stamp_ns
            was = camera in self.late_watch.suspect
            n, suspect = self.late_watch.saw(camera, late, self.clock.mono_s())
        if suspect != was:
            self._second_stream_gauge(camera, 1 if suspect else -1)
        if late and suspect:
            tally.warn(
                contract.DEPTH_SECOND_STREAM,
                f"depth camera {camera}: {n} frames within {self.late_watch.window_s:g} s "
                f"arrived older than the one held: a second stream on {key} stamped ahead of "
                "its source's? Its real frames are being ignored as late (depth_late)",
                key=contract.DEPTH_SECOND_STREAM + camera,
            )

    def _second_stream_gauge(self, camera: str, step: int) -> None:
        self.tally.counters.add(contract.DEPTH_SECOND_STREAM, step)
        self.tally.counters.add(per_camera(contract.DEPTH_SECOND_STREAM, camera), step)

    def keep_watching(self, cameras: Mapping[str, CameraAnnouncement]) -> None:
        """The cameras announced now: the second-stream suspicion of the others is dropped
        (their gauges back to 0)."""
        with self._lock:
            gone = self.late_watch.keep(set(cameras))
        for camera in gone:
            self._second_stream_gauge(camera, -1)

    def _refuse(self, counter: str, camera: str, why: str) -> None:
        """A depth frame of ``camera`` dropped for ``why``: counted (per camera too), logged
        rate-limited."""
        self.tally.reject(counter, f"depth from {camera} refused: {why}", key=counter + camera)
        self.tally.counters.add(per_camera(counter, camera))

    def _restore(self, path: Path, max_age_s: float) -> None:
        """Take back the hazards of the map a stage before this one wrote, if it wrote
        it within ``max_age_s`` (a crash or a restart: the robot has not gone far)."""
        log = self.tally.log
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            return
        except OSError as exc:
            self.tally.reject(contract.DEPTH_MEMORY_ERRORS, f"depth map {path} unreadable: {exc}")
            return
        try:
            pose, kept, saved_ns = self.map.restore(data)
        except ValueError as exc:
            self.tally.reject(contract.DEPTH_MEMORY_ERRORS, f"depth map {path} not taken: {exc}")
            return
        age_s = (self.clock.wall_ns() - saved_ns) / 1e9
        if not 0 <= age_s <= max_age_s:
            self.map = LocalMap(self.map.p, self.params.resolution_deg)
            log.warning(
                "depth map %s is %.0f s old (over depth_memory_max_age_s %g): not taken; the "
                "robot creeps until it has seen the floor ahead", path, age_s, max_age_s,
            )  # fmt: skip
            return
        self.odometry = Odometry(start=pose)
        log.info(
            "depth map %s taken back (written %.1f s ago): %d remembered hazard or unknown "
            "cells; the floor it had seen is to be seen again", path, age_s, kept,
        )  # fmt: skip

    def save_memory(self, force: bool = False) -> None:
        """Write the map to its file (at most every ``depth_memory_save_s``, or now with
        ``force``), with the pose the robot would reach if its last command went on for
        ``depth_memory_coast_s``: what a stage taking it back after a crash must assume.
        A write that fails is logged and counted; nothing waits on it."""
        if self.memory_path is None:
            return
        mono = self.clock.mono_s()
        if not force and mono - self._saved_at < self.memory_save_s:
            return
        self._saved_at = mono
        pose = self.odometry.coasted(mono, self.memory_coast_s)
        with self._map_lock:
            data = self.map.dump(pose, self.clock.wall_ns())
            self._unsaved_hazard = False
        try:
            self.memory_path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(self.memory_path, data)
        except OSError as exc:
            self.tally.reject(
                contract.DEPTH_MEMORY_ERRORS,
                f"depth map not written to {self.memory_path}: {exc.strerror or exc}",
            )

    def moved(self, mono_s: float, linear: float, angular: float) -> None:
        """The command sent at monotonic ``mono_s``: the robot moves so from then on."""
        self.odometry.command(mono_s, linear, angular)

    def memory(self, at: Stamp) -> tuple[LaserScan, LaserScan]:
        """What the memory holds round the robot at ``at`` (its pose then, by the commands
        heard), stamped with ``at``: the remembered scan (its hazard and unknown cells) and the
        known floor (one ray straight ahead: how far the corridor ahead is known, inf: all of
        it within the map's reach)."""
        header = Header(
            stamp_ns=at.wall_ns, frame_id="base_link", seq=0, source=contract.SERVICE,
            mono_ns=at.mono_ns, boot_id=BOOT_ID,
        )  # fmt: skip
        pose = self.odometry.pose_at(at.mono_ns / 1e9)
        with self._map_lock:
            self.map.stand(pose)
            held = self.map.read(pose, header)
        known = LaserScan(
            header=header,
            angle_min=0.0,
            angle_increment=math.tau,
            range_min=0.0,
            range_max=held.scan.range_max,
            ranges=np.array([held.known_m], np.float32),
        )
        return held.scan, known
