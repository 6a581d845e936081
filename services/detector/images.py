"""Reading images from disk, with one clear ImageError for anything unreadable."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from common.errors import ImageError

#: File extensions treated as images when a folder is listed (compared lower-case).
IMAGE_EXTENSIONS = frozenset({".bmp", ".jpeg", ".jpg", ".png", ".tif", ".tiff", ".webp"})


def load_image(path: str | Path) -> npt.NDArray[np.uint8]:
    """Read ``path`` as an ``(H, W, 3)`` uint8 BGR image (grey and alpha are converted).

    Raises ImageError when the file is missing, unreadable, or not a decodable image.
    """
    path = Path(path)
    try:
        data = np.fromfile(path, dtype=np.uint8)  # bytes first: imread cannot say *why* it failed
    except FileNotFoundError as exc:
        raise ImageError(f"{path}: no such file") from exc
    except OSError as exc:
        raise ImageError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    image = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if image is None:
        raise ImageError(f"{path}: not a readable image (corrupt or unsupported format)")
    return np.asarray(image, dtype=np.uint8)


def list_images(paths: Iterable[str | Path]) -> list[Path]:
    """Expand each path: a folder gives its image files (sorted, not recursive), a file itself.

    Paths that do not exist are kept, so that reading them reports the error in order.
    """
    found: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            found.extend(
                sorted(
                    p
                    for p in path.iterdir()
                    if p.suffix.lower() in IMAGE_EXTENSIONS and not p.is_dir()
                )
            )
        else:
            found.append(path)
    return found
