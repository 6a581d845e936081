"""INT8 calibration data: a folder of images as fixed-size batches of network input.

TensorRT's entropy calibrator asks for batches of exactly the size it was told, and measures
activation ranges on them. The images must be letterboxed exactly as at inference time, or the
ranges describe inputs the engine will never see, so batches are built with the pipeline's own
:class:`~common.letterbox.Preprocessor`.

A last partial batch is **padded by repeating images from the start of the folder** (cycling),
by default: every image is then seen at least once, and no synthetic pixels (a grey or black
pad) skew the histograms. ``last="drop"`` drops it instead, for folders large enough that a
few images do not matter. Kept free of TensorRT so it is unit-tested here.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

from common.errors import ConfigError
from common.images import list_images, load_image
from common.letterbox import Preprocessor

LastBatch = Literal["pad", "drop"]


def calibration_images(folder: str | Path) -> list[Path]:
    """The image files of ``folder``, sorted; ConfigError when it is missing or has none."""
    path = Path(folder)
    if not path.is_dir():
        raise ConfigError(f"calibration folder {path} does not exist or is not a folder")
    images = list_images([path])
    if not images:
        raise ConfigError(f"calibration folder {path} has no images (.jpg, .png, ...)")
    return images


def batch_count(n_images: int, batch_size: int, last: LastBatch = "pad") -> int:
    """How many batches :func:`calibration_batches` yields for ``n_images``."""
    if batch_size < 1:
        raise ConfigError(f"calibration batch size must be at least 1, got {batch_size}")
    full, rest = divmod(n_images, batch_size)
    return full + (1 if rest and last == "pad" else 0)


def calibration_batches(
    paths: Sequence[Path],
    batch_size: int,
    input_height: int,
    input_width: int,
    *,
    last: LastBatch = "pad",
) -> Iterator[npt.NDArray[np.float32]]:
    """Yield ``(batch_size, 3, H, W)`` float32 batches, letterboxed as at inference time.

    Each batch is a fresh array (the calibrator copies it to the GPU, but a caller keeping
    them must not see them overwritten). Images are read lazily, one batch at a time, so a
    large folder never sits in memory whole. An unreadable image raises ImageError: a
    calibration set with holes should be fixed, not silently shrunk.
    """
    if last not in ("pad", "drop"):
        raise ConfigError(f"last batch policy must be 'pad' or 'drop', got {last!r}")
    n = batch_count(len(paths), batch_size, last)
    if n == 0:
        raise ConfigError(
            f"{len(paths)} calibration image(s) make no full batch of {batch_size} "
            "(use fewer per batch, more images, or pad)"
        )
    pre = Preprocessor(input_height, input_width, batch_size)
    for b in range(n):
        # Indices past the end wrap to the start: this is the padding of the last batch.
        chosen = [paths[(b * batch_size + i) % len(paths)] for i in range(batch_size)]
        batch, _ = pre.run([load_image(p) for p in chosen])
        yield batch.copy()


def calibration_digest(paths: Sequence[Path]) -> str:
    """sha256 over the images' names and contents, in order: the calibration set's identity.

    An INT8 engine and its calibration cache are only reusable with the same images.
    """
    digest = hashlib.sha256()
    for path in paths:
        digest.update(path.name.encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()


# ---------------------------------------------------------------- ONNX Runtime / NNCF INT8

#: How each shipped photo is varied for calibration: as it is, mirrored, and the middle
#: two thirds (objects at a larger scale). Still real pixels, three times the frames.
PHOTO_VIEWS = ("full", "mirror", "crop")


def _view(image: npt.NDArray[np.uint8], view: str) -> npt.NDArray[np.uint8]:
    if view == "mirror":
        return np.ascontiguousarray(image[:, ::-1])
    if view == "crop":
        h, w = image.shape[:2]
        return np.ascontiguousarray(image[h // 6 : h - h // 6, w // 6 : w - w // 6])
    return image


def shipped_photo_names() -> tuple[str, ...]:
    """The photos that ship offline: scikit-image's samples, which are also the images of the
    project's hand-labelled set (tools/evaluation/data/skimage_coco.json)."""
    from common.images import SAMPLES

    return tuple(SAMPLES)


def calibration_photos(
    extra: Sequence[Path] = (),
) -> Iterator[tuple[str, npt.NDArray[np.uint8]]]:
    """``(label, BGR image)``: every view of the shipped photos, then the user's ``extra``
    images (as they are). Read lazily; an unreadable image raises ImageError."""
    from common.images import load_sample

    for name in shipped_photo_names():
        image = load_sample(name)
        for view in PHOTO_VIEWS:
            yield f"{name}:{view}", _view(image, view)
    for path in extra:
        yield str(path), load_image(path)


def calibration_frames(
    photos: Sequence[npt.NDArray[np.uint8]], input_height: int, input_width: int
) -> list[npt.NDArray[np.float32]]:
    """Each photo as a ``(1, 3, H, W)`` float32 network input, letterboxed by the pipeline's
    own Preprocessor (each a fresh array)."""
    pre = Preprocessor(input_height, input_width, 1)
    return [pre.run([photo])[0].copy() for photo in photos]
