"""The detector: letterbox, run the backend, decode, NMS, map boxes back; each stage timed."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from common.boxes import Boxes
from common.clock import ms_since, perf_s
from common.letterbox import Letterbox, Preprocessor, unletterbox
from common.lifecycle import Closing
from perception.decode import Family, decode, sane_outputs
from perception.model_info import ModelInfo, read_model_info
from perception.postprocess import class_mask, select
from perception.settings import DecodeOptions
from perception.types import DetectionResult, StageTiming
from runtimes import Backend, open_backend


class Detector(Closing):
    """A model loaded on one backend, with its post-processing settings.

    Its ``settings`` are DecodeOptions (``conf``, ``iou``, ``max_det``, ``classes``; any
    DetectorSpec, the detector service's settings included, is one); which model and backend
    to load are :meth:`open`'s arguments.

    Not thread-safe: the input buffer is reused between calls. Use one Detector per thread.
    """

    def __init__(
        self, backend: Backend, model_path: Path, settings: DecodeOptions | None = None
    ) -> None:
        """Wrap an open ``backend``; prefer :meth:`open`. Closes it on any error here."""
        try:
            self.info: ModelInfo = read_model_info(backend)
            self.settings = settings if settings is not None else DecodeOptions()
            self._class_mask = class_mask(self.info.names, self.settings.classes or None)
        except BaseException:
            backend.close()
            raise
        self.backend = backend
        self.model_path = model_path
        self._pre = Preprocessor(
            self.info.input_height, self.info.input_width, self.info.batch_size
        )

    @classmethod
    def open(
        cls,
        model_path: str | Path,
        *,
        backend: str = "onnx",
        settings: DecodeOptions | None = None,
        **backend_options: Any,
    ) -> Detector:
        """Load ``model_path`` on the named backend.

        Raises ConfigError (unknown backend or class name), BackendUnavailable, ModelError or
        UnknownModelFamily, each with a one-line message.
        """
        path = Path(model_path)
        return cls(open_backend(backend, path, **backend_options), path, settings)

    @property
    def names(self) -> tuple[str, ...]:
        """All class names of the model, indexed by class id."""
        return self.info.names

    def detect(self, image_bgr: npt.NDArray[np.uint8]) -> DetectionResult:
        """Detect objects in one ``(H, W, 3)`` uint8 BGR image; boxes in its pixels."""
        return self.detect_batch([image_bgr])[0]

    def detect_batch(self, images: Sequence[npt.NDArray[np.uint8]]) -> list[DetectionResult]:
        """Detect objects in several BGR images, in model-sized batches.

        Each stage is timed per batch and its time shared equally among the batch's images
        (NMS and box mapping are timed per image).
        """
        step = self.info.batch_size or max(1, len(images))
        results: list[DetectionResult] = []
        for start in range(0, len(images), step):
            results.extend(self._run_batch(list(images[start : start + step])))
        return results

    def preprocess(
        self, images: list[npt.NDArray[np.uint8]]
    ) -> tuple[npt.NDArray[np.float32], list[Letterbox]]:
        """Letterbox ``images`` into the reused input buffer (a view, overwritten next call)."""
        return self._pre.run(images)

    def _run_batch(self, images: list[npt.NDArray[np.uint8]]) -> list[DetectionResult]:
        t0 = perf_s()
        batch, boxes = self._pre.run(images)
        pre_ms = ms_since(t0)
        t1 = perf_s()
        output = self.backend.infer(batch)[0]
        infer_ms = ms_since(t1) / len(images)
        t2 = perf_s()
        s = self.settings
        output = output[: len(images)]
        sane = sane_outputs(output)
        candidates = decode(self.info.layout, output, s.conf, len(self.names), self._class_mask)
        decode_ms = ms_since(t2) / len(images)
        results = []
        for cands, lb, ok in zip(candidates, boxes, sane.tolist(), strict=True):
            t3 = perf_s()
            kept = select(
                cands,
                iou=s.iou,
                max_det=s.max_det,
                apply_nms=self.info.family is not Family.END2END,
            )
            timing = StageTiming(
                preprocess_ms=pre_ms / len(images),
                inference_ms=infer_ms,
                postprocess_ms=decode_ms + ms_since(t3),
            )
            results.append(
                DetectionResult(
                    boxes=kept.with_xyxy(unletterbox(kept.xyxy, lb)) if ok else Boxes(),
                    output_sane=ok,
                    names=self.names,
                    image_width=lb.src_width,
                    image_height=lb.src_height,
                    timing=timing,
                )
            )
        return results

    def close(self) -> None:
        """Release the backend."""
        self.backend.close()
