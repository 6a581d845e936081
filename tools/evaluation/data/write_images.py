"""Write the photos skimage_coco.json labels: python tools/evaluation/data/write_images.py DIR

The photos are scikit-image's samples, so they are not committed here; only the hand-made
labels are. The file names match ``file_name`` in skimage_coco.json; pass the same DIR to
``python -m tools.evaluation --images DIR``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2

ANNOTATIONS = Path(__file__).resolve().parent / "skimage_coco.json"
#: The camera service's sample names; ``motorcycle`` is stereo_motorcycle's left view.
SAMPLES = ("astronaut", "cameraman", "chelsea", "coffee", "motorcycle", "rocket")


def write_images(folder: Path) -> list[Path]:
    """Save every labelled photo as ``<name>.png`` in ``folder`` (lossless: labels stay exact)."""
    from common.images import load_sample

    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in SAMPLES:
        path = folder / f"{name}.png"
        if not cv2.imwrite(str(path), load_sample(name)):
            raise OSError(f"cannot write {path}")
        paths.append(path)
    return paths


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[3]))  # the repo root, for common
    for written in write_images(Path(sys.argv[1] if len(sys.argv) > 1 else ".")):
        print(written)
