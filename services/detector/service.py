"""The detector service's wiring: the newest frame of every camera it serves in, each camera's
Detections out, with its frame's header, on its own key; several cameras' frames batched
(docs/detector.md, "Several cameras"). Start-up (the model, the batch, the info queryables) and
the loop are here; what the loop does is elsewhere: the handlers (services/detector/handlers.py),
the rounds (services/detector/rounds.py) and the pool membership by which several workers divide
the cameras (services/detector/membership.py, over services/detector/pool.py)."""

from __future__ import annotations

import json
import logging
import threading

import numpy as np

from common.bus import Declared, QoS
from common.contracts import DetectorInfo
from common.node import Node
from perception import Detector, load, variant_of
from perception import measure_batch as measure
from services.detector.attention import Attention
from services.detector.contract import DetectorSettings
from services.detector.handlers import DetectorHandlers
from services.detector.membership import PoolMember
from services.detector.rounds import Rounds, camera_outputs, heed_controller
from stack.config import Config

_WAIT_S = 0.2  # how often the idle loop looks at the stop flag (and the pool's membership)


def open_detector(s: DetectorSettings, max_batch: int = 1) -> tuple[Detector, str]:
    """Load what ``zstack prepare`` made for ``s`` (the model at its size and precision, or the
    fast profile's choice), for batches of up to ``max_batch`` frames, with a note on what was
    chosen; builds and measures nothing (NotPrepared names what is missing)."""
    return load(s, max_batch)


def served_batch(config: Config) -> int:
    """The most frames one round takes: ``detector.max_batch``, never more than there are
    cameras (one frame per camera per round), so one camera always runs batches of 1."""
    return min(config.detector.max_batch, len(config.all_cameras))


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
        handlers = DetectorHandlers(config, node, node.clock)
        outputs = camera_outputs(
            config,
            handlers.frame_keys,
            lambda cam: node.publisher(node.keys.detections(cam), QoS.PERCEPTION).put,
        )
        # Attention when short of capacity (services/detector/attention.py): the rounds'
        # order, fed by the controller's status and each camera's detections.
        attention = Attention(node.clock, s.attention_floor_hz, s.attention_hold_s, s.attention)
        status_sub = node.subscribe(node.keys.controller_status(), heed_controller(node, attention))
        rounds = Rounds(config, node, detector, outputs, node.clock, attention)
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
        pool.start_stall_watch()
        node.ready()
        try:
            while not stop.is_set():
                pool.beat()
                pool.settle()
                pool.audit()
                node.publish_counters()
                waiting = handlers.slots.take(per_round, _WAIT_S, attention)
                if waiting:
                    rounds.run(waiting)
        finally:
            status_sub.undeclare()
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
