"""The YOLO dataset layout, read into a :class:`~tools.evaluation.labelled.LabelledSet`.

    DATASET/
      data.yaml | classes.txt | names.txt     class names (the first one found, in that order)
      images/**/NAME.jpg                      any image type OpenCV reads; subfolders allowed
      labels/**/NAME.txt                      one "class cx cy w h" line per box

Label coordinates are normalised to 0..1 of the image (centre x, centre y, width, height), the
class is an index into the names. An image without a label file has no objects; a label file
without an image is an error (the image is missing). ``classes.txt`` and ``names.txt`` hold one
name per line. From ``data.yaml`` only the ``names:`` key is read, in the forms Ultralytics
writes: a flow list ``names: [person, car]``, a block list (``- person``) or a block mapping
(``0: person``). That small subset is parsed here, so no YAML library is needed.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from PIL import Image, UnidentifiedImageError

from common.images import IMAGE_EXTENSIONS
from tools.evaluation.labelled import (
    DatasetError,
    LabelledImage,
    LabelledSet,
    check_box,
    read_text,
)

NAME_FILES = ("data.yaml", "classes.txt", "names.txt")
_EXIF_ORIENTATION = 0x0112
_TRANSPOSED = frozenset({5, 6, 7, 8})  # EXIF orientations that swap width and height
_TOKEN = re.compile(r"""\s*(?:'([^']*)'|"([^"]*)"|([^,]+?))\s*(?:,|$)""")


def _unquote(raw: str) -> str:
    raw = raw.strip()
    if len(raw) >= 2 and raw[0] == raw[-1] and raw[0] in "'\"":
        return raw[1:-1]
    return raw.split(" #", 1)[0].strip()  # a trailing comment on an unquoted value


def _flow_items(text: str) -> list[str]:
    return [next(g for g in m.groups() if g is not None) for m in _TOKEN.finditer(text) if m[0]]


def _yaml_names(path: Path, text: str) -> list[str]:
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if re.match(r"names\s*:", line)), None)
    if start is None:
        raise DatasetError(f"{path}: no 'names:' key")
    rest = lines[start].split(":", 1)[1].strip()
    unsupported = DatasetError(
        f"{path}: cannot read 'names:' (write a [list], '- name' lines or '0: name' lines)"
    )
    if rest.startswith("["):  # a flow list, possibly over several lines
        flow = " ".join([rest, *lines[start + 1 :]])
        if "]" not in flow:
            raise unsupported
        return [_unquote(item) for item in _flow_items(flow[1 : flow.index("]")])]
    if rest.startswith("{"):
        flow = " ".join([rest, *lines[start + 1 :]])
        if "}" not in flow:
            raise unsupported
        pairs = [item.split(":", 1) for item in _flow_items(flow[1 : flow.index("}")])]
        return _indexed(path, pairs, unsupported)
    if rest and not rest.startswith("#"):
        raise unsupported
    block = []
    for line in lines[start + 1 :]:
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        if not line[0].isspace():
            break
        block.append(line.strip())
    if block and all(item.startswith("- ") or item == "-" for item in block):
        return [_unquote(item[1:]) for item in block]
    return _indexed(path, [item.split(":", 1) for item in block], unsupported)


def _indexed(path: Path, pairs: list[list[str]], unsupported: DatasetError) -> list[str]:
    """Names from ``index: name`` pairs, which must number 0..n-1."""
    if not pairs or any(len(p) != 2 or not p[0].strip().isdigit() for p in pairs):
        raise unsupported
    by_index = {int(k): _unquote(v) for k, v in pairs}
    if sorted(by_index) != list(range(len(by_index))):
        raise DatasetError(f"{path}: 'names:' indices must run 0..{len(by_index) - 1}")
    return [by_index[i] for i in range(len(by_index))]


def read_class_names(folder: Path) -> tuple[Path, list[str]]:
    """The first of data.yaml, classes.txt, names.txt in ``folder``, and the names in it."""
    for name in NAME_FILES:
        path = folder / name
        if not path.is_file():
            continue
        text = read_text(path)
        if name.endswith(".yaml"):
            names = _yaml_names(path, text)
        else:
            names = [line.strip() for line in text.splitlines() if line.strip()]
        if not names or not all(names):
            raise DatasetError(f"{path}: no class names (or an empty one)")
        if len(set(names)) != len(names):
            raise DatasetError(f"{path}: class names repeat")
        return path, names
    raise DatasetError(
        f"{folder}: no class names; add classes.txt (one name per line) or data.yaml (names:)"
    )


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) as OpenCV will load it: from the header, EXIF rotation applied."""
    try:
        with Image.open(path) as im:
            width, height = im.size
            if im.getexif().get(_EXIF_ORIENTATION, 1) in _TRANSPOSED:
                width, height = height, width
    except (OSError, UnidentifiedImageError) as exc:
        raise DatasetError(f"{path}: not a readable image ({exc})") from exc
    return width, height


def _parse_label(
    path: Path, names: list[str], names_file: Path, image: LabelledImage, next_id: int
) -> list[dict[str, Any]]:
    lines = read_text(path).splitlines()
    annotations: list[dict[str, Any]] = []
    for lineno, line in enumerate(lines, 1):
        if not line.strip():
            continue
        where = f"{path}:{lineno}"
        malformed = DatasetError(f"{where}: expected 'class cx cy w h', got {line.strip()!r}")
        fields = line.split()
        try:
            cls, values = int(fields[0]), [float(v) for v in fields[1:]]
        except ValueError:
            raise malformed from None
        if len(values) != 4:
            raise malformed
        if not 0 <= cls < len(names):
            raise DatasetError(
                f"{where}: class id {cls} is out of range: {names_file.name} names "
                f"{len(names)} classes (0..{len(names) - 1})"
            )
        cx, cy, w, h = values
        if not all(math.isfinite(v) and 0.0 <= v <= 1.0 for v in values):
            raise DatasetError(f"{where}: coordinates {values} must be normalised to 0..1")
        iw, ih = image.width, image.height
        box = ((cx - w / 2) * iw, (cy - h / 2) * ih, w * iw, h * ih)
        check_box(where, box, image.width, image.height)
        annotations.append(
            {
                "id": next_id + len(annotations),
                "image_id": image.id,
                "category_id": cls + 1,  # COCO ids start at 1
                "bbox": list(box),
                "area": box[2] * box[3],
                "iscrowd": 0,
            }
        )
    return annotations


def load_yolo(folder: Path) -> LabelledSet:
    """Read and check a YOLO folder (layout in the module docstring)."""
    names_file, names = read_class_names(folder)
    images_root, labels_root = folder / "images", folder / "labels"
    for sub in (images_root, labels_root):
        if not sub.is_dir():
            raise DatasetError(f"{folder}: a YOLO dataset needs images/ and labels/ folders")
    paths = sorted(
        p for p in images_root.rglob("*") if p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file()
    )
    if not paths:
        raise DatasetError(f"{images_root}: no images")
    by_stem: dict[Path, Path] = {}
    for path in paths:
        stem = path.relative_to(images_root).with_suffix("")
        if stem in by_stem:
            raise DatasetError(f"{path}: same name as {by_stem[stem]}; labels could not tell them")
        by_stem[stem] = path
    for label in sorted(labels_root.rglob("*.txt")):
        if label.relative_to(labels_root).with_suffix("") not in by_stem:
            raise DatasetError(f"{label}: its image is missing from {images_root}")
    images: list[LabelledImage] = []
    annotations: list[dict[str, Any]] = []
    for iid, (stem, path) in enumerate(by_stem.items(), 1):
        width, height = image_size(path)
        image = LabelledImage(iid, path, width, height)
        images.append(image)
        label = labels_root / stem.parent / f"{stem.name}.txt"  # not with_suffix: "a.v2" stems
        if label.is_file():
            annotations += _parse_label(label, names, names_file, image, len(annotations) + 1)
    categories = {i + 1: name for i, name in enumerate(names)}
    return LabelledSet(folder, tuple(images), categories, tuple(annotations))
