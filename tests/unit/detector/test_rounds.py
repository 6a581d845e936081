"""The detector's rounds over several cameras (services/detector/handlers.py and
rounds.py), with a real ONNX Runtime backend on a tiny model whose boxes depend on the image:
each camera's detections carry its own frame's header, go to its own output, are tracked by its
own tracker, and are counted in all and for that camera."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from common.clock import BOOT_ID
from common.counters import per_camera
from common.frames import image_to_frame
from common.freshness import FreshnessGate
from common.messages import Detections, Frame
from common.node import Tally
from perception.pipeline import Detector
from perception.tracker import Tracker
from services.camera.contract import CameraSettings
from services.detector.contract import DetectorSettings, TrackerSettings
from services.detector.handlers import DetectorHandlers
from services.detector.rounds import CameraOutput, Rounds
from services.detector.service import round_size, served_batch
from stack.config import Config
from tests.unit.detector.halves import halves_model, image
from tests.unit.detector.headers import camera_header


def frame(camera: str, seq: int, left: bool, right: bool) -> Frame:
    return image_to_frame(image(left, right), camera_header(camera, seq))


CAMERAS = ("front", "rear", "left")


def three_cameras(model: Path, max_batch: int = 4) -> Config:
    base = Config()
    return replace(
        base,
        cameras=tuple((name, replace(base.camera, frame_id=name)) for name in CAMERAS[1:]),
        detector=DetectorSettings(model=str(model), max_batch=max_batch),
        tracker=TrackerSettings(),
    )


class Served:
    """The handlers, rounds and outputs of one detector over ``config``'s cameras, no bus."""

    def __init__(self, config: Config, detector: Detector) -> None:
        self.config = config
        self.tally = Tally("detector", config)
        self.handlers = DetectorHandlers(config, self.tally)
        self.sent: dict[str, list[Detections]] = {cam: [] for cam in config.all_cameras}
        s = config.detector
        outputs = {
            cam: CameraOutput(
                camera=cam,
                frame_key=key,
                gate=FreshnessGate(s.max_frame_age_s, config.stack.clock_tolerance_s, BOOT_ID),
                tracker=Tracker(config.tracker),
                put=lambda payload, cam=cam: self.sent[cam].append(Detections.decode(payload)),
            )
            for cam, key in self.handlers.frame_keys.items()
        }
        self.rounds = Rounds(config, self.tally, detector, outputs)

    def feed(self, *frames: tuple[str, Frame]) -> int:
        """Put each frame on its camera's slot, run one round; the round's size."""
        for camera, f in frames:
            self.handlers.on_frame(camera, f.encode())
        waiting = self.handlers.slots.take(served_batch(self.config), timeout=0)
        self.rounds.run(waiting)
        return len(waiting)

    def count(self, name: str, camera: str | None = None) -> int:
        return self.tally.counters.get(name if camera is None else per_camera(name, camera))


@pytest.fixture()
def served(tmp_path: Path) -> Served:
    config = three_cameras(halves_model(tmp_path))
    detector = Detector.open(
        config.detector.model, settings=config.detector, max_batch=served_batch(config)
    )
    return Served(config, detector)


def test_one_round_batches_every_camera_and_each_gets_its_own_frames_header(
    served: Served,
) -> None:
    assert served.rounds.detector.info.batch_size is None  # dynamic: one backend call
    frames = {
        "front": frame("front", 7, left=True, right=False),
        "rear": frame("rear", 40, left=False, right=False),
        "left": frame("left", 3, left=False, right=True),
    }
    assert served.feed(*frames.items()) == 3
    for cam, f in frames.items():
        (dets,) = served.sent[cam]
        assert dets.header == f.header  # stamp, frame id, seq: the frame's own
    xs = {cam: served.sent[cam][0].boxes.xyxy[:, 0].tolist() for cam in CAMERAS}
    assert xs == {"front": [2.0], "rear": [], "left": [18.0]}
    assert (served.count("batches"), served.count("batched_frames")) == (1, 3)
    for cam in CAMERAS:
        assert served.count("frames_in", cam) == served.count("detections_out", cam) == 1
    assert served.count("detections_out") == 3


def test_track_ids_never_cross_cameras(served: Served) -> None:
    # The front camera sees the left box (its track 1), then the right one too (track 2).
    served.feed(("front", frame("front", 1, left=True, right=False)))
    served.feed(("front", frame("front", 2, left=True, right=True)))
    front = served.sent["front"][-1]
    by_x = dict(zip(front.boxes.xyxy[:, 0].tolist(), front.boxes.track_ids.tolist(), strict=True))
    assert by_x == {2.0: 1, 18.0: 2}
    # The rear camera sees a box where the front camera's track 2 is: a track of its own, its
    # first (a shared tracker would have continued the front's track 2).
    served.feed(("rear", frame("rear", 1, left=False, right=True)))
    served.feed(("rear", frame("rear", 2, left=False, right=True)))
    assert served.sent["rear"][-1].boxes.track_ids.tolist() == [1]
    # And the front camera's tracks go on undisturbed.
    served.feed(("front", frame("front", 3, left=True, right=True)))
    assert sorted(served.sent["front"][-1].boxes.track_ids.tolist()) == [1, 2]


def test_a_newer_frame_replaces_the_waiting_one_counted_for_its_camera(served: Served) -> None:
    old, new = frame("rear", 1, True, False), frame("rear", 2, True, False)
    served.handlers.on_frame("rear", old.encode())
    served.handlers.on_frame("rear", new.encode())
    served.handlers.on_frame("front", b"garbage")
    assert served.feed() == 1
    assert [d.header.seq for d in served.sent["rear"]] == [2]
    assert served.count("dropped") == served.count("dropped", "rear") == 1
    assert served.count("dropped", "front") == 0
    assert served.count("bad_input") == served.count("bad_input", "front") == 1


def test_a_stale_frame_is_counted_for_its_camera_and_not_detected_on(served: Served) -> None:
    fresh = frame("front", 1, True, False)
    h, ago = fresh.header, 5_000_000_000  # 5 s old: past detector.max_frame_age_s
    stale = replace(fresh, header=replace(h, stamp_ns=h.stamp_ns - ago, mono_ns=h.mono_ns - ago))
    served.feed(("left", stale), ("front", fresh))
    assert served.count("frames_stale") == served.count("frames_stale", "left") == 1
    assert served.sent["left"] == [] and len(served.sent["front"]) == 1
    assert served.count("batched_frames") == 1  # the stale frame never reached the model


def test_the_served_batch_is_max_batch_whatever_the_configs_cameras(tmp_path: Path) -> None:
    """The cameras are those announced at run time: a round takes at most one frame per
    camera waiting (so one camera runs batches of 1), up to ``detector.max_batch``."""
    model = halves_model(tmp_path)
    assert served_batch(three_cameras(model, max_batch=4)) == 4
    assert served_batch(three_cameras(model, max_batch=2)) == 2
    assert served_batch(Config(detector=DetectorSettings(max_batch=32))) == 32


def test_detect_batch_equals_one_detect_per_image(served: Served) -> None:
    det = served.rounds.detector
    images = [image(True, False), image(False, True), image(True, True), image(False, False)]
    batched = det.detect_batch(images)
    for img, got in zip(images, batched, strict=True):
        want = det.detect(img)
        np.testing.assert_allclose(got.boxes.xyxy, want.boxes.xyxy, atol=1e-4)
        np.testing.assert_allclose(got.boxes.scores, want.boxes.scores, atol=1e-4)


def test_a_fixed_batch_model_cuts_rounds_to_its_batch_and_says_so(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    log = logging.getLogger("test-detector")
    with Detector.open(halves_model(tmp_path, batch=2), max_batch=3) as fixed:
        assert fixed.info.batch_size == 2
        with caplog.at_level(logging.INFO, logger="test-detector"):
            assert round_size(fixed, 3, log) == 2
            assert round_size(fixed, 1, log) == 1  # one camera: padded to 2, as it always was
        assert len(caplog.records) == 2 and "fixed batch of 2" in caplog.records[0].message
        results = fixed.detect_batch([image(True, False)])  # padded to the model's batch
        assert results[0].boxes.xyxy[:, 0].tolist() == [2.0]
    with Detector.open(halves_model(tmp_path, batch=1), max_batch=1) as one:
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="test-detector"):
            assert round_size(one, 1, log) == 1
        assert caplog.records == []  # a batch-1 model with one camera: nothing to say


def test_settings_bound_max_batch(tmp_path: Path) -> None:
    from common.errors import ConfigError

    for bad in (0, 33):
        with pytest.raises(ConfigError, match=r"detector\.max_batch must be within 1\.\.32"):
            DetectorSettings(max_batch=bad)
    assert DetectorSettings().max_batch == 1  # the CPU's best (docs/benchmarks.md)
    assert CameraSettings().frame_id == "camera"  # the default camera is unchanged
