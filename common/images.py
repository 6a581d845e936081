"""Images from disk and scikit-image's sample photos, as BGR uint8, with one clear ImageError.

Shared by the camera (image and folder sources), the simulator (its sprites), the detector's
command line, benchmark and INT8 calibration, and the metrics' dataset evaluation.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from common.errors import ConfigError, ImageError

#: An OpenCV image: ``(H, W, 3)`` BGR or ``(H, W)`` grey, uint8.
Image = npt.NDArray[np.uint8]

#: File extensions treated as images when a folder is listed (compared lower-case).
IMAGE_EXTENSIONS = frozenset({".bmp", ".jpeg", ".jpg", ".png", ".tif", ".tiff", ".webp"})

# scikit-image ships these public-domain photos, so the stack runs with no camera and no download.
_SAMPLE_FILES = {
    "astronaut": "astronaut.png",
    "cameraman": "camera.png",
    "chelsea": "chelsea.png",
    "coffee": "coffee.png",
    "rocket": "rocket.jpg",
    "motorcycle": "motorcycle_left.png",
}
SAMPLES = tuple(_SAMPLE_FILES)


def load_image(path: str | Path) -> Image:
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


def load_sample(name: str) -> Image:
    """A scikit-image sample photo (one of :data:`SAMPLES`) as ``(H, W, 3)`` BGR uint8.

    ``cameraman`` is ``data.camera()`` (grey, expanded to BGR); ``motorcycle`` is
    ``stereo_motorcycle``'s left view. Read straight from the files scikit-image ships, with
    OpenCV: the same pixels as ``skimage.data`` (a unit test compares them), without importing
    scikit-image and SciPy, which cost every camera process about 20 MB. ConfigError names the
    samples for any other name; ImageError if the installed scikit-image lacks the file.
    """
    if name not in _SAMPLE_FILES:
        raise ConfigError(f"unknown sample {name!r}; choose one of {', '.join(SAMPLES)}")
    return load_image(_sample_folder() / _SAMPLE_FILES[name])


def _sample_folder() -> Path:
    """scikit-image's ``data`` folder, found without importing the package."""
    spec = importlib.util.find_spec("skimage")
    if spec is None or spec.origin is None:
        raise ImageError("scikit-image is not installed: its sample photos are unavailable")
    return Path(spec.origin).parent / "data"
