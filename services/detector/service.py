"""The detector service: the newest frame of every camera it serves in, each camera's
Detections out, with its frame's header, on its own key; several cameras' frames batched
(docs/detector.md, "Several cameras"). Several workers divide the cameras between them as a
pool (services/detector/pool.py; :class:`PoolMember` here is its bus side)."""

from __future__ import annotations

import json
import logging
import threading
from dataclasses import dataclass
from functools import partial

import numpy as np
import numpy.typing as npt

from common.bus import Declared, QoS
from common.clock import BOOT_ID, mono_s, now, wall_ns
from common.contracts import DetectorInfo
from common.counters import per_camera
from common.errors import DecodeError, ImageError, ImageTooLarge, StackError
from common.frames import check_pixel_budget, frame_to_bgr
from common.freshness import FreshnessGate, Verdict
from common.messages import Detections, Frame, Header
from common.node import Node, Put, Tally
from common.pool_audit import MAX_LINES, PoolAudit, Report, Serving, lines
from common.seqgaps import SeqGaps
from common.settings import Config, DetectorSettings
from perception import DetectionResult, Detector, Tracker, load, tracker_clock, variant_of
from perception import measure_batch as measure
from services.detector.pool import Change, PoolView, camera_weights
from services.detector.schedule import CameraSlots, Waiting

_WAIT_S = 0.2  # how often the idle loop looks at the stop flag (and the pool's membership)
#: How long a joining worker asks who is already in the pool before it takes its cameras: the
#: query ends as soon as every peer answered; this bounds it on a slow link.
POOL_ASK_TIMEOUT_S = 1.0
AUDIT_PERIOD_S = 0.5  # how often the loop audits the pool's tokens (common/pool_audit.py)


def open_detector(s: DetectorSettings, max_batch: int = 1) -> tuple[Detector, str]:
    """Load what ``zstack prepare`` made for ``s`` (the model at its size and precision, or the
    fast profile's choice), for batches of up to ``max_batch`` frames, with a note on what was
    chosen; builds and measures nothing (NotPrepared names what is missing)."""
    return load(s, max_batch)


def to_message(
    frame: Frame,
    result: DetectionResult,
    det: Detector,
    received_ns: int,
    track_ids: npt.NDArray[np.int32] | None,
) -> Detections:
    """The Detections message for ``frame``: its header, the result, the detector's stamps."""
    t = result.timing
    return Detections(
        header=frame.header,
        image_width=frame.width,
        image_height=frame.height,
        boxes=result.boxes.with_track_ids(track_ids),
        class_names=tuple(result.class_names),
        timing_ms={
            "preprocess": t.preprocess_ms,
            "inference": t.inference_ms,
            "postprocess": t.postprocess_ms,
        },
        model=det.model_path.name,
        backend=f"{det.backend.name}/{det.backend.device}/{det.backend.precision}",
        received_ns=received_ns,
        published_ns=wall_ns(),
    )


def served_batch(config: Config) -> int:
    """The most frames one round takes: ``detector.max_batch``, never more than there are
    cameras (one frame per camera per round), so one camera always runs batches of 1."""
    return min(config.detector.max_batch, len(config.all_cameras))


class DetectorHandlers:
    """What the detector does with a frame as it arrives: decode it, count it (in all and for
    its camera), and leave it in its camera's slot, from which the loop takes rounds."""

    def __init__(self, config: Config, tally: Tally) -> None:
        self.settings = config.detector
        self.tally = tally
        self.frame_keys = {cam: tally.keys.frame(cam) for cam in config.all_cameras}
        self.slots: CameraSlots[Frame] = CameraSlots(self.frame_keys)
        self.gaps = {cam: SeqGaps() for cam in self.frame_keys}  # one numbering per camera
        #: The cameras this worker serves (all of them outside a pool); a frame of another,
        #: late from a subscription just undeclared, is left to its new worker.
        self.serving: frozenset[str] = frozenset(self.frame_keys)

    def serve(
        self, cameras: frozenset[str], gained: tuple[str, ...], lost: tuple[str, ...]
    ) -> None:
        """Serve ``cameras`` from now on: a camera ``lost`` has its waiting frame dropped (its
        new worker detects on it), one ``gained`` starts its frame numbering afresh (the frames
        sent while another worker served it are no loss)."""
        self.serving = cameras
        for cam in lost:
            self.slots.clear(cam)
        for cam in gained:
            self.gaps[cam] = SeqGaps()

    def on_frame(self, camera: str, payload: bytes) -> None:
        # Decode here, not in the loop: garbage must be counted even when a newer frame would
        # have replaced it in the slot before the loop looked at it; and an oversize frame
        # must never displace a real one there.
        if camera not in self.serving:
            return
        count = partial(count_for, self.tally, camera)
        count("frames_in")
        key = self.frame_keys[camera]
        try:
            frame = Frame.decode(payload)
            missed = self.gaps[camera].observe(frame.header)
            if missed:
                count("frames_missed", missed)
            check_pixel_budget(frame, self.settings.max_frame_pixels)
        except DecodeError as exc:
            self.tally.bad_input(key, exc)
            self.tally.counters.add(per_camera("bad_input", camera))
            return
        except ImageTooLarge as exc:
            reject_for(self.tally, camera, "frames_oversize", str(exc), key)
            return
        if self.slots.put(camera, frame):
            count("dropped")


def count_for(tally: Tally, camera: str, name: str, n: int = 1) -> None:
    """Count ``n`` under ``name`` (the detector's total) and under ``name.<camera>``."""
    tally.counters.add(name, n)
    tally.counters.add(per_camera(name, camera), n)


def reject_for(tally: Tally, camera: str, counter: str, message: str, key: str) -> None:
    """``Tally.reject`` (counted in all, logged rate-limited per key) and counted for
    ``camera`` too."""
    tally.reject(counter, message, key=key)
    tally.counters.add(per_camera(counter, camera))


@dataclass(slots=True)
class CameraOutput:
    """What the detector keeps per camera: its frames' freshness (replays are judged per
    camera), its own tracker (track ids never cross cameras) and its detections' publisher."""

    camera: str
    frame_key: str
    gate: FreshnessGate
    tracker: Tracker | None
    put: Put


class Rounds:
    """The detection loop's work: take a round of frames, one per waiting camera, run them
    through the model as one batch, and publish each camera's detections with its frame's
    header on its own key. Counted in all and per camera; a round's size is counted as
    ``batches`` (rounds run) and ``batched_frames`` (frames in them): their ratio is the mean
    batch size."""

    def __init__(
        self, config: Config, tally: Tally, detector: Detector, outputs: dict[str, CameraOutput]
    ) -> None:
        self.settings = config.detector
        self.tally = tally
        self.detector = detector
        self.outputs = outputs

    def run(self, waiting: list[Waiting[Frame]]) -> None:
        ready: list[tuple[CameraOutput, Frame, int, npt.NDArray[np.uint8]]] = []
        for w in waiting:
            out, frame = self.outputs[w.camera], w.item
            # Judged as it leaves the slot: a frame that waited out a pause (or was stamped
            # wrong, or sent again) is not worth a detection nobody may act on.
            verdict, age = out.gate.check(frame.header, now())
            if verdict is not Verdict.FRESH:
                reject_for(
                    self.tally,
                    w.camera,
                    f"frames_{verdict}",
                    f"{verdict} frame from {w.camera} ({age:.2f} s old) dropped",
                    out.frame_key,
                )
                continue
            try:
                image = frame_to_bgr(frame, self.settings.max_frame_pixels)
            except ImageError as exc:
                self.tally.bad_input(out.frame_key, exc)
                self.tally.counters.add(per_camera("bad_input", w.camera))
                continue
            ready.append((out, frame, w.received_ns, image))
        if not ready:
            return
        results = self.detector.detect_batch([image for *_, image in ready])
        self.tally.counters.add("batches")
        self.tally.counters.add("batched_frames", len(ready))
        for (out, frame, received_ns, _), result in zip(ready, results, strict=True):
            self._publish(out, frame, received_ns, result)

    def _publish(
        self, out: CameraOutput, frame: Frame, received_ns: int, result: DetectionResult
    ) -> None:
        if not result.output_sane:
            # Zero boxes from a broken model are no verdict: publish nothing, so that the
            # controller's detection timeout stops the robot.
            reject_for(
                self.tally,
                out.camera,
                "nonfinite_outputs",
                f"the model's output for frame {frame.header.seq} from {out.camera} is not "
                "finite (NaN, infinity or a magnitude over 1e6): no detections published",
                out.frame_key,
            )
            return
        track_ids = (
            None
            if out.tracker is None
            else _track(self.tally, out, result, frame.header, received_ns)
        )
        out.put(to_message(frame, result, self.detector, received_ns, track_ids).encode())
        count_for(self.tally, out.camera, "detections_out")


def run(config: Config, stop: threading.Event, worker: str = "detector") -> int:
    """Detect on the newest frame of every camera this worker serves until ``stop`` is set;
    ``worker``: its one name (one of ``Config.detector_services``), its service, pool id and
    principal."""
    s = config.detector
    with Node(worker, config, counters_period_s=s.counters_period_s) as node:
        served = served_batch(config)
        detector, note = open_detector(s, served)
        b = detector.backend
        node.log.info(
            "model %s on %s (%s, %s, input %d)%s",
            detector.model_path,
            b.name,
            b.device,
            b.precision,
            detector.info.input_height,
            f": {note}" if note else "",
        )
        per_round = round_size(detector, served, node.log)
        detector, note, per_round = settle_batch(detector, note, per_round, s, node.log)
        b = detector.backend  # the one that runs (settle_batch may have opened it again)
        handlers = DetectorHandlers(config, node)
        outputs = {
            cam: CameraOutput(
                camera=cam,
                frame_key=key,
                gate=FreshnessGate(s.max_frame_age_s, config.stack.clock_tolerance_s, BOOT_ID),
                tracker=Tracker(config.tracker) if config.tracker.enabled else None,
                put=node.publisher(node.keys.detections(cam), QoS.PERCEPTION).put,
            )
            for cam, key in handlers.frame_keys.items()
        }
        rounds = Rounds(config, node, detector, outputs)
        pool = PoolMember(node, worker, handlers)
        info = json.dumps(
            DetectorInfo(
                model=detector.model_path.name,
                classes=list(detector.names),
                backend=b.name,
                device=b.device,
                precision=b.precision,
                variant=variant_of(detector),
                note=note,
            )
        )
        queryables = [_info_queryable(node, node.keys.detector_info(cam), info) for cam in outputs]
        # Warm the backend up before announcing readiness: the first run allocates, and each
        # batch size may (a CUDA graph, an OpenVINO shape) on its first run.
        warm = np.full((480, 640, 3), 114, np.uint8)
        for size in sorted({1, per_round}):
            detector.detect_batch([warm] * size)
        pool.join()
        node.ready()
        try:
            while not stop.is_set():
                pool.beat()
                pool.settle()
                pool.audit()
                node.publish_counters()
                waiting = handlers.slots.take(per_round, _WAIT_S)
                if waiting:
                    rounds.run(waiting)
        finally:
            pool.close()
            for queryable in queryables:
                queryable.undeclare()
            detector.close()
    return 0


def settle_batch(
    detector: Detector, note: str, per_round: int, s: DetectorSettings, log: logging.Logger
) -> tuple[Detector, str, int]:
    """With ``batch_choice`` "measured" and rounds of several frames on a model of dynamic
    batch: time the batch sizes and keep the one that serves frames fastest
    (perception/batching.py). When that is 1, the model is opened again for batch 1:
    the fastest batch-1 session, and the buffers the large batches took given back."""
    if per_round == 1 or s.batch_choice != "measured" or detector.info.batch_size is not None:
        return detector, note, per_round
    choice = measure(detector.detect_batch, per_round, s.batch_probe_runs, s.batch_min_gain)
    log.info("%s", choice.describe())
    if choice.size == 1:
        detector.close()
        detector, note = open_detector(s, 1)
    return detector, note, choice.size


class PoolMember:
    """This worker's place in the detector pool (services/detector/pool.py): its liveliness
    token ``<prefix>/detector/pool/<worker id>``, the others' tokens as they come and go, and a
    frame subscription for each camera it serves.

    Zenoh's threads only note a join or a leave; the detection loop calls :meth:`settle`
    between rounds, which recomputes the assignment and declares and undeclares subscriptions
    there (never inside a Zenoh callback). Counted: ``serving`` and ``serving.<cam>`` (1 while
    served), ``pool_members``, ``pool_load_permille`` (the served cameras' share of every
    camera's pixel rate), ``cameras_gained`` and ``cameras_lost`` (and ``.<cam>``: hand-overs
    after the first assignment).

    A worker whose loop stalls (an inference that never returns, a deadlock) while Zenoh's
    threads still keep its token alive would hold its cameras until the watchdog restarts it.
    So a thread here watches the loop's :meth:`beat`: none for ``detector.pool_stall_s`` while
    other workers are in the pool and the worker **resigns**, withdrawing its pool token (the
    others take its cameras at once) and refusing frames; its next beat declares the token
    again and it takes its share back. A worker alone in the pool stays: nobody could take over.
    Counted as ``pool_resigned``.

    For each camera it serves, the worker declares a serving token ``<prefix>/detector/serving/
    <worker>/<zenoh id>/<camera>`` (withdrawn with its pool token on a stall), and it hears
    everyone's: :meth:`audit` checks them against the membership (common/pool_audit.py) and
    logs a WARNING for what has been wrong for ``detector.pool_alarm_s`` (a member that serves
    nothing, a camera nobody or two serve, a name held twice), and a line when it clears.
    Counted: ``pool_warnings`` (how many hold now)."""

    def __init__(self, node: Node, worker_id: str, handlers: DetectorHandlers) -> None:
        config = node.config
        self.node = node
        self.handlers = handlers
        self.view = PoolView(
            worker_id, camera_weights(config.all_cameras), config.detector.pool_balance
        )
        self._stall_s = config.detector.pool_stall_s
        self._last_beat = mono_s()
        self._resigned = False
        self._closed = threading.Event()
        self._stall_watch: threading.Thread | None = None
        # Two locks, taken in this order: _token_lock around declaring and undeclaring the
        # token (a Zenoh call, which may deliver our own liveliness change to _member at once,
        # in this thread), _lock around the view and the flags (never held over a Zenoh call).
        self._token_lock = threading.Lock()
        self._lock = threading.Lock()
        self._dirty = True
        self._subs: dict[str, Declared] = {}
        self._token: Declared | None = None
        self._watch: Declared | None = None
        self._gauges: dict[str, int] = {}
        self._handed_over = False
        self.zid = node.bus.zid
        self._serving_tokens: dict[str, Declared] = {}  # under _token_lock
        self._servers: set[Serving] = set()  # everyone's serving tokens, as heard
        self._serving_watch: Declared | None = None
        self._audit = PoolAudit(self.view.weights, self.view.balance, config.detector.pool_alarm_s)
        self._audit_next = 0.0
        for cam in handlers.frame_keys:
            self._gauge(per_camera("serving", cam), 0)
        for name in ("serving", "pool_members", "pool_load_permille", "pool_warnings"):
            self._gauge(name, 0)
        for name in ("cameras_gained", "cameras_lost", "pool_resigned"):
            node.counters.add(name, 0)

    def join(self) -> None:
        """Learn who is in the pool, declare this worker's token and take its cameras. A worker
        of this name already there is a StackError (one line, exit 1): two processes of one
        name would each serve every camera the rule gives the name. (One the query misses, two
        started at once, is the audit's ``name_twice`` warning.) The supervisor tries again
        after its backoff: a process just killed takes its token with its links."""
        node, keys = self.node, self.node.keys
        bus = node.bus
        members = bus.live_tokens(keys.all_pool_members(), POOL_ASK_TIMEOUT_S)
        mine = keys.pool_member(self.view.me)
        if mine in members:
            raise StackError(
                f"a detector worker named {self.view.me!r} is already in the pool ({mine}): "
                "not starting a second; give each host its own detector.worker_id"
            )
        with self._token_lock:
            self._token = bus.declare_token(mine)
        self._watch = bus.watch_tokens(keys.all_pool_members(), self._on_member)
        for key in members:
            self._member(key, joined=True)
        self._serving_watch = bus.watch_tokens(keys.all_pool_serving(), self._on_serving)
        self.settle()
        self._last_beat = mono_s()
        self._stall_watch = threading.Thread(
            target=self._watch_stalls, name="pool-stall-watch", daemon=True
        )
        self._stall_watch.start()

    def beat(self) -> None:
        """The detection loop passed (call it on every pass, before :meth:`settle`). After a
        stall that made this worker resign, declare its token again: the pool gives its share
        back, and the next settle() serves it again."""
        with self._token_lock:
            with self._lock:
                self._last_beat = mono_s()
                back = self._resigned and not self._closed.is_set()
                self._resigned = False
                if back:
                    self._dirty = True
            if back:
                keys = self.node.keys
                self._token = self.node.bus.declare_token(keys.pool_member(self.view.me))
        if back:
            self.node.log.warning("the detection loop runs again: back in the pool")

    def _watch_stalls(self) -> None:
        period = max(0.05, self._stall_s / 4)
        while not self._closed.wait(period):
            with self._token_lock:
                with self._lock:
                    stalled = (
                        not self._resigned
                        and len(self.view.members) > 1  # alone, there is nobody to hand to
                        and mono_s() - self._last_beat > self._stall_s
                    )
                    if stalled:
                        self._resigned = True
                        # The frames that come meanwhile are not ours: restored by the
                        # settle() after the next beat(), never before (beat clears the flag).
                        self.handlers.serving = frozenset()
                if stalled and self._token is not None:
                    self._token.undeclare()
                    self._token = None
                if stalled:
                    self._withdraw_serving()
            if not stalled:
                continue
            self.node.counters.add("pool_resigned")
            self.node.log.warning(
                "the detection loop has not passed for %.1f s (detector.pool_stall_s): "
                "leaving the pool so that the other workers take its cameras",
                self._stall_s,
            )

    def _on_serving(self, key: str, alive: bool) -> None:
        parts = self.node.keys.pool_serving_parts(key)
        if parts is None:
            return
        with self._lock:
            if alive:
                self._servers.add(parts)
            else:
                self._servers.discard(parts)

    def audit(self) -> Report | None:
        """Check the pool's tokens (at most every :data:`AUDIT_PERIOD_S`): log what became
        wrong, and what stopped being so; None when it is not yet time."""
        now = mono_s()
        if now < self._audit_next:
            return None
        self._audit_next = now + AUDIT_PERIOD_S
        with self._token_lock:
            mine = {(self.view.me, self.zid, cam) for cam in self._serving_tokens}
        with self._lock:
            members = set(self.view.members)
            servers = self._servers | mine
        report = self._audit.check(now, members, servers)
        for line in lines(report.raised, now):
            self.node.log.warning("pool: %s", line)
        for finding in report.cleared[:MAX_LINES]:
            self.node.log.info("pool: no longer so: %s", finding.detail)
        self._gauge("pool_warnings", len(report.current))
        return report

    def _withdraw_serving(self) -> None:
        """Undeclare every serving token (the caller holds _token_lock)."""
        for token in self._serving_tokens.values():
            token.undeclare()
        self._serving_tokens.clear()

    def _sync_serving(self, serving: frozenset[str]) -> None:
        """One serving token for each camera of ``serving``, and none for another."""
        keys, bus = self.node.keys, self.node.bus
        with self._token_lock:
            if self._token is None:
                return  # resigned or closed: it serves nothing until it is back
            for cam in [c for c in self._serving_tokens if c not in serving]:
                self._serving_tokens.pop(cam).undeclare()
            for cam in sorted(serving - self._serving_tokens.keys()):
                key = keys.pool_serving(self.view.me, self.zid, cam)
                self._serving_tokens[cam] = bus.declare_token(key)

    def _on_member(self, key: str, alive: bool) -> None:
        self._member(key, joined=alive)

    def _member(self, key: str, *, joined: bool) -> None:
        worker = key.rsplit("/", 1)[-1]
        with self._lock:
            if joined:
                self.view.joined(worker)
            else:
                self.view.left(worker)
            self._dirty = True

    def settle(self) -> None:
        """Apply a membership change, if any, to this worker's subscriptions and counters."""
        with self._lock:
            if not self._dirty:
                return
            self._dirty = False
            change = self.view.settle()
        self._apply(change)

    def _apply(self, change: Change) -> None:
        node, handlers = self.node, self.handlers
        for cam in change.lost:
            sub = self._subs.pop(cam, None)
            if sub is not None:
                sub.undeclare()
        with self._lock:
            # Under the lock the stall watch resigns under: a change computed before a
            # resignation (this pass stalled inside it) never switches serving back on; the
            # settle() after the next beat() serves the share again.
            handlers.serve(
                frozenset() if self._resigned else change.serving, change.gained, change.lost
            )
        for cam in change.gained:
            key = handlers.frame_keys[cam]
            # Bounded: no queue of stale frames ahead of the slot, which keeps the newest only.
            self._subs[cam] = node.subscribe_bounded(key, partial(handlers.on_frame, cam))
        for cam in (*change.gained, *change.lost):
            self._gauge(per_camera("serving", cam), int(cam in change.serving))
        self._sync_serving(change.serving)
        if self._handed_over:  # the first assignment, at start, is no hand-over
            for cam in change.gained:
                count_for(node, cam, "cameras_gained")
            for cam in change.lost:
                count_for(node, cam, "cameras_lost")
        self._handed_over = True
        self._gauge("serving", len(change.serving))
        self._gauge("pool_members", change.members)
        self._gauge("pool_load_permille", round(change.load * 1000))
        if change.gained or change.lost:
            node.log.info(
                "pool of %d: serving %s (gained %s, lost %s)",
                change.members,
                sorted(change.serving) or "no camera",
                list(change.gained),
                list(change.lost),
            )

    def _gauge(self, name: str, value: int) -> None:
        # Counters only add: a gauge moves by its difference.
        self.node.counters.add(name, value - self._gauges.get(name, 0))
        self._gauges[name] = value

    def close(self) -> None:
        self._closed.set()
        if self._stall_watch is not None:
            self._stall_watch.join()
        for sub in self._subs.values():
            sub.undeclare()
        for watch in (self._watch, self._serving_watch):
            if watch is not None:
                watch.undeclare()
        self._subs.clear()
        with self._token_lock:
            self._withdraw_serving()
            if self._token is not None:
                self._token.undeclare()
                self._token = None


def round_size(detector: Detector, served: int, log: logging.Logger) -> int:
    """Frames per round: ``served``, cut to a fixed-batch model's batch (which a smaller
    round is padded to), said in one line when the model's batch is not ``served``."""
    fixed = detector.info.batch_size
    if fixed is None or fixed == served:
        return served
    log.info(
        "the model takes a fixed batch of %d: rounds of up to %d frame(s) (detector.max_batch "
        "and the cameras allow %d), each run as one batch of %d",
        fixed,
        min(served, fixed),
        served,
        fixed,
    )
    return min(served, fixed)


def _info_queryable(node: Node, key: str, info: str) -> Declared:
    return node.bus.serve(key, lambda _key, _query: info.encode())


def _track(
    tally: Tally,
    out: CameraOutput,
    result: DetectionResult,
    header: Header,
    received_ns: int,
) -> npt.NDArray[np.int32]:
    """Track ids for ``result`` from its camera's tracker; a frame whose stamp jumped is
    counted, its ids left at -1."""
    tracker = out.tracker
    assert tracker is not None
    ignored, resets = tracker.ignored_frames, tracker.resets
    at, arrival = tracker_clock(
        header.stamp_ns, header.mono_ns, header.boot_id, received_ns, BOOT_ID
    )
    ids = tracker.update(result.boxes, at, arrival)
    if tracker.ignored_frames > ignored:
        reject_for(
            tally,
            out.camera,
            "tracker_stamp_jumps",
            "frame stamp jumped: the tracker ignored it",
            out.frame_key,
        )
    if tracker.resets > resets:
        reject_for(
            tally,
            out.camera,
            "tracker_resets",
            "frame stamps jumped for good: tracks restarted",
            out.frame_key,
        )
    return ids
