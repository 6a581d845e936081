"""Letterboxing: BGR images of any size into the network's NCHW float32 input, and back.

The image is scaled by one factor (aspect ratio kept) to fit the network input, centred, and the
border is padded with grey 114, as Ultralytics models were trained. Channels become RGB and
values 0..1. The float32 batch lives in a buffer reused between frames: a camera that keeps
the same frame size only rewrites the image area, since the padding is already in place.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from common.errors import ImageError

PAD_VALUE = 114
_PAD_FLOAT = np.float32(PAD_VALUE / 255.0)
_INV_255 = np.float32(1.0 / 255.0)


@dataclass(frozen=True, slots=True)
class Letterbox:
    """How one source image was placed in the network input.

    A network-input pixel ``(x, y)`` maps to source pixel ``((x - pad_x) / scale,
    (y - pad_y) / scale)``. ``pad_x``/``pad_y`` are the left/top borders in network pixels,
    ``resized_width``/``resized_height`` the size of the scaled image inside the canvas.
    """

    scale: float
    pad_x: int
    pad_y: int
    src_width: int
    src_height: int
    resized_width: int
    resized_height: int


def compute_letterbox(
    src_width: int, src_height: int, dst_width: int, dst_height: int
) -> Letterbox:
    """The letterbox that fits a ``src`` image into a ``dst`` canvas, centred, aspect kept."""
    if min(src_width, src_height, dst_width, dst_height) < 1:
        raise ImageError(
            f"cannot letterbox a {src_width}x{src_height} image into {dst_width}x{dst_height}"
        )
    scale = min(dst_width / src_width, dst_height / src_height)
    resized_width = min(dst_width, max(1, round(src_width * scale)))
    resized_height = min(dst_height, max(1, round(src_height * scale)))
    return Letterbox(
        scale=scale,
        pad_x=(dst_width - resized_width) // 2,
        pad_y=(dst_height - resized_height) // 2,
        src_width=src_width,
        src_height=src_height,
        resized_width=resized_width,
        resized_height=resized_height,
    )


def unletterbox(xyxy: npt.NDArray[np.float32], lb: Letterbox) -> npt.NDArray[np.float32]:
    """Map ``(n, 4)`` boxes from network-input pixels to source-image pixels, clipped to it.

    Returns a new float32 array; ``xyxy`` is not modified.
    """
    out = np.empty_like(xyxy, dtype=np.float32)
    inv = 1.0 / lb.scale
    out[:, 0::2] = (xyxy[:, 0::2] - lb.pad_x) * inv
    out[:, 1::2] = (xyxy[:, 1::2] - lb.pad_y) * inv
    np.clip(out[:, 0::2], 0, lb.src_width, out=out[:, 0::2])
    np.clip(out[:, 1::2], 0, lb.src_height, out=out[:, 1::2])
    return out


def check_bgr_image(image: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """Return ``image`` as an ``(H, W, 3)`` uint8 BGR array; grey images are expanded.

    Raises ImageError, saying what was expected, for anything else.
    """
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
        kind = getattr(image, "dtype", type(image).__name__)
        raise ImageError(f"expected an (H, W, 3) uint8 BGR image, got {kind}")
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        return np.asarray(cv2.cvtColor(image, cv2.COLOR_GRAY2BGR), dtype=np.uint8)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 1 or image.shape[1] < 1:
        raise ImageError(f"expected an (H, W, 3) uint8 BGR image, got shape {image.shape}")
    return image


class Preprocessor:
    """Letterboxes frames into a reused ``(B, 3, H, W)`` float32 RGB 0..1 buffer.

    ``batch_size`` is the model's fixed batch, or ``None`` when the model takes any batch (the
    buffer then grows to the largest batch seen). The arrays returned by :meth:`run` are views
    of that buffer: the next call overwrites them.
    """

    def __init__(self, input_height: int, input_width: int, batch_size: int | None = None) -> None:
        if input_height < 1 or input_width < 1:
            raise ValueError(f"input size must be positive, got {input_width}x{input_height}")
        self.input_height = input_height
        self.input_width = input_width
        self.fixed_batch = batch_size
        # uint8 scratch for the resized image: cv2.resize writes into it, so no frame allocates.
        self._canvas = np.empty((input_height, input_width, 3), np.uint8)
        self._buffer = np.empty((0, 3, input_height, input_width), np.float32)
        self._slot_geometry: list[Letterbox | None] = []
        self._ensure_capacity(batch_size or 1)

    @property
    def buffer(self) -> npt.NDArray[np.float32]:
        """The whole reused input buffer (for tests and benchmarks)."""
        return self._buffer

    def _ensure_capacity(self, n: int) -> None:
        if n <= self._buffer.shape[0]:
            return
        # Padding-grey, not np.empty: spare rows of a fixed batch must not hold NaNs or junk.
        self._buffer = np.full(
            (n, 3, self.input_height, self.input_width), _PAD_FLOAT, dtype=np.float32
        )
        self._slot_geometry = [None] * n

    def run(
        self, images: list[npt.NDArray[np.uint8]]
    ) -> tuple[npt.NDArray[np.float32], list[Letterbox]]:
        """Letterbox ``images`` (BGR uint8) into the buffer.

        Returns the batch to feed the network (``len(images)`` rows, or the model's fixed
        batch size, whose extra rows are left as they were) and one Letterbox per image.
        """
        n = len(images)
        if n == 0:
            raise ValueError("run() needs at least one image")
        if self.fixed_batch is not None and n > self.fixed_batch:
            raise ValueError(f"model takes batches of {self.fixed_batch}, got {n} images")
        self._ensure_capacity(n)
        boxes = [self._fill_slot(i, check_bgr_image(img)) for i, img in enumerate(images)]
        rows = self.fixed_batch if self.fixed_batch is not None else n
        return self._buffer[:rows], boxes

    def _fill_slot(self, slot: int, image: npt.NDArray[np.uint8]) -> Letterbox:
        h, w = image.shape[:2]
        lb = compute_letterbox(w, h, self.input_width, self.input_height)
        dst = self._buffer[slot]
        if self._slot_geometry[slot] != lb:
            # New geometry: repaint the padding once; frames of the same size skip this.
            dst.fill(_PAD_FLOAT)
            self._slot_geometry[slot] = lb
        rw, rh = lb.resized_width, lb.resized_height
        resized = self._canvas[:rh, :rw]
        if (rw, rh) == (w, h):
            resized[...] = image
        else:
            # Use the return value: OpenCV writes into ``dst`` but would reallocate on mismatch.
            resized = np.asarray(
                cv2.resize(image, (rw, rh), dst=resized, interpolation=cv2.INTER_LINEAR), np.uint8
            )
        # BGR HWC uint8 -> RGB CHW float32 0..1, written straight into the image area.
        np.multiply(
            resized[:, :, ::-1].transpose(2, 0, 1),
            _INV_255,
            out=dst[:, lb.pad_y : lb.pad_y + rh, lb.pad_x : lb.pad_x + rw],
            casting="unsafe",
        )
        return lb
