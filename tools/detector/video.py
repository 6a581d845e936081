"""``detect`` on a video file or a camera device: every frame through the detector, a result
per frame on stdout, a progress bar on stderr, and with ``--save-dir`` an annotated video and
the per-frame results as JSON lines.

The video is opened by the camera's own source parsing (``services.camera``), so ``detect``
and the camera service accept the same ``device:0``, ``device:/dev/video0`` and path forms.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

import cv2
import numpy as np
import numpy.typing as npt

from common.annotate import annotate
from common.errors import ConfigError, ImageError
from perception import Detector
from services.camera import CaptureSource
from tools.detector.progress import ProgressBar
from tools.detector.results import result_json, result_text

#: The frame rate written for a device that does not declare one.
FALLBACK_FPS = 30.0
#: What the annotated video is written as, in order of preference: OpenCV's FFmpeg writes
#: MPEG-4 Part 2 into .mp4 everywhere (no H.264 encoder in opencv-python-headless), and
#: Motion-JPEG into .avi where even that is missing.
VIDEO_FORMATS = (("mp4v", ".mp4"), ("MJPG", ".avi"))


def output_stem(spec: str) -> str:
    """The file name (without suffix) of a stream's outputs: ``clip`` for ``dir/clip.mp4``,
    ``device0`` for ``device:0``, ``video0`` for ``/dev/video0``."""
    name = spec.removeprefix("device:")
    stem = f"device{name}" if name.isdigit() else Path(name).stem
    return re.sub(r"[^A-Za-z0-9._-]", "_", stem) or "stream"


class AnnotatedVideo:
    """The annotated frames written as a video (mp4v .mp4, else MJPG .avi) at the source's
    frame rate and size; the writer is opened on the first frame, which sets the size."""

    def __init__(self, save_dir: Path, stem: str, fps: float, source: Path | None) -> None:
        self._save_dir = save_dir
        self._stem = stem
        self._fps = fps
        self._source = source.resolve() if source is not None else None
        self._writer: cv2.VideoWriter | None = None
        self.path: Path | None = None
        self.frames = 0

    def write(self, frame: npt.NDArray[np.uint8]) -> None:
        if self._writer is None:
            self._writer, self.path = self._open(frame.shape[1], frame.shape[0])
        self._writer.write(frame)
        self.frames += 1

    def _open(self, width: int, height: int) -> tuple[cv2.VideoWriter, Path]:
        for fourcc, suffix in VIDEO_FORMATS:
            path = self._save_dir / f"{self._stem}{suffix}"
            if self._source is not None and path.resolve() == self._source:
                raise ConfigError(f"{path}: --save-dir would overwrite the input video")
            writer = cv2.VideoWriter(
                str(path), cv2.VideoWriter.fourcc(*fourcc), self._fps, (width, height)
            )
            if writer.isOpened():
                return writer, path
            writer.release()
        raise ImageError(f"{self._save_dir}: cannot write a video there (no mp4v nor MJPG writer)")

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()


def detect_stream(
    spec: str,
    source: CaptureSource,
    detector: Detector,
    *,
    as_json: bool,
    save_dir: Path | None,
    out: Callable[[str], None] = print,
    progress: TextIO | None = None,
) -> int:
    """Detect on every frame of ``source`` until it ends; returns the number of frames.

    ConfigError when not one frame can be read (raised by the source); ImageError when the
    outputs cannot be written. Whatever was written stays valid if it ends early (Ctrl-C).
    """
    bar = ProgressBar(spec, source.frame_count, stream=progress)
    path = None if spec.startswith("device:") else Path(spec)
    stem = output_stem(spec)
    video = jsonl = None
    try:
        if save_dir is not None:
            video = AnnotatedVideo(save_dir, stem, source.fps or FALLBACK_FPS, path)
            jsonl = _open_text(save_dir / f"{stem}.jsonl")
        while (image := source.read()) is not None:
            result = detector.detect(image)
            line = result_json(spec, result, frame=bar.done)
            out(line if as_json else result_text(f"{spec} frame {bar.done}", result))
            if video is not None and jsonl is not None:
                video.write(annotate(image, result.boxes, result.class_names))
                jsonl.write(line + "\n")
            bar.advance()
    finally:
        bar.finish()
        if video is not None:
            video.close()
        if jsonl is not None:
            jsonl.close()
    return bar.done


def _open_text(path: Path) -> TextIO:
    try:
        return path.open("w", encoding="utf-8")
    except OSError as exc:
        raise ImageError(f"{path}: cannot write ({exc.strerror or exc})") from exc
