"""Labelled datasets for ``evaluate``: a COCO JSON file or a YOLO folder, checked up front.

Both formats become one :class:`LabelledSet`: images with their pixel size, categories by id,
and COCO-style annotations (``bbox`` = x, y, width, height in pixels, origin top-left). Every
problem is found before the model runs, and raised as :class:`DatasetError` with one line that
names the file and what is wrong with it: a missing image, a box outside its image, a class id
with no name, malformed JSON.

COCO: each image's ``file_name`` is resolved against ``images_dir`` when given, else the JSON
file's folder. The YOLO layout is read by :mod:`tools.evaluation.yolo_dataset`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tools.evaluation.labelled import (
    DatasetError,
    LabelledImage,
    LabelledSet,
    check_box,
    read_text,
)
from tools.evaluation.yolo_dataset import load_yolo


def load_dataset(path: str | Path, images_dir: str | Path | None = None) -> LabelledSet:
    """Read a COCO JSON file or a YOLO folder (see the module docstring); DatasetError if bad."""
    path = Path(path)
    if path.is_dir():
        if images_dir is not None:
            raise DatasetError(
                f"{path}: --images applies to a COCO JSON file; a YOLO folder has its own images/"
            )
        return load_yolo(path)
    if not path.exists():
        raise DatasetError(f"{path}: no such file or folder")
    return load_coco(path, Path(images_dir) if images_dir is not None else None)


# --- COCO JSON ---------------------------------------------------------------------------------


def _field(where: str, item: Mapping[str, Any], key: str, kind: type | tuple[type, ...]) -> Any:
    value = item.get(key)
    if not isinstance(value, kind) or isinstance(value, bool):
        names = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
        raise DatasetError(f"{where}: '{key}' must be a {names}, got {value!r}")
    return value


def _objects(path: Path, data: Mapping[str, Any], key: str) -> list[Mapping[str, Any]]:
    items = data.get(key)
    if not isinstance(items, list):
        raise DatasetError(f"{path}: a COCO file needs a '{key}' list")
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise DatasetError(f"{path}: {key}[{i}] must be an object, got {item!r}")
    return items


def _read_json(path: Path) -> Any:
    text = read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise DatasetError(
            f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from exc


def _coco_categories(path: Path, data: Mapping[str, Any]) -> dict[int, str]:
    categories: dict[int, str] = {}
    for i, cat in enumerate(_objects(path, data, "categories")):
        where = f"{path}: categories[{i}]"
        cid = _field(where, cat, "id", int)
        name = _field(where, cat, "name", str).strip()
        if not name:
            raise DatasetError(f"{where}: empty category name")
        if cid in categories:
            raise DatasetError(f"{where}: duplicate category id {cid}")
        if name in categories.values():
            raise DatasetError(f"{where}: duplicate category name {name!r}")
        categories[cid] = name
    return categories


# A labelled set that ships without its photos carries a script beside it that writes them.
IMAGE_WRITER = "write_images.py"


def _how_to_get_images(annotations: Path) -> str:
    """The hint for a labelled set whose photos are written by a script beside its labels."""
    writer = annotations.parent / IMAGE_WRITER
    if not writer.is_file():
        return " (--images names the folder the file names are relative to)"
    return f"; write its photos with `python {writer} DIR`, then pass --images DIR"


def _coco_images(path: Path, data: Mapping[str, Any], root: Path) -> dict[int, LabelledImage]:
    images: dict[int, LabelledImage] = {}
    for i, im in enumerate(_objects(path, data, "images")):
        where = f"{path}: images[{i}]"
        iid = _field(where, im, "id", int)
        file_name = _field(where, im, "file_name", str)
        width, height = _field(where, im, "width", int), _field(where, im, "height", int)
        if width <= 0 or height <= 0:
            raise DatasetError(f"{where}: size {width}x{height} must be positive")
        if iid in images:
            raise DatasetError(f"{where}: duplicate image id {iid}")
        image_path = root / file_name
        if not image_path.is_file():
            raise DatasetError(
                f"{path}: image {file_name!r} (id {iid}) not found at {image_path}"
                + _how_to_get_images(path)
            )
        images[iid] = LabelledImage(iid, image_path, width, height)
    if not images:
        raise DatasetError(f"{path}: no images")
    return images


def load_coco(path: Path, images_dir: Path | None = None) -> LabelledSet:
    """Read and check a COCO detection file; images resolve against ``images_dir`` or its folder."""
    data = _read_json(path)
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: a COCO file is a JSON object with images, annotations, ...")
    categories = _coco_categories(path, data)
    images = _coco_images(path, data, images_dir if images_dir is not None else path.parent)
    annotations: list[dict[str, Any]] = []
    seen: set[int] = set()
    for i, ann in enumerate(_objects(path, data, "annotations")):
        where = f"{path}: annotations[{i}]"
        aid = ann.get("id", i + 1)
        if not isinstance(aid, int) or isinstance(aid, bool) or aid in seen:
            raise DatasetError(f"{where}: 'id' must be a unique integer, got {aid!r}")
        seen.add(aid)
        image = images.get(_field(where, ann, "image_id", int))
        if image is None:
            raise DatasetError(f"{where}: image_id {ann['image_id']} is not in images")
        cid = _field(where, ann, "category_id", int)
        if cid not in categories:
            raise DatasetError(f"{where}: category_id {cid} is not in categories")
        bbox = _field(where, ann, "bbox", list)
        if len(bbox) != 4 or not all(isinstance(v, int | float) for v in bbox):
            raise DatasetError(f"{where}: 'bbox' must be [x, y, width, height], got {bbox!r}")
        box = (float(bbox[0]), float(bbox[1]), float(bbox[2]), float(bbox[3]))
        check_box(f"{where} (image {image.path.name})", box, image.width, image.height)
        iscrowd = ann.get("iscrowd", 0)
        if iscrowd not in (0, 1):
            raise DatasetError(f"{where}: 'iscrowd' must be 0 or 1, got {iscrowd!r}")
        area = ann.get("area", box[2] * box[3])
        if not isinstance(area, int | float) or isinstance(area, bool):
            raise DatasetError(f"{where}: 'area' must be a number, got {area!r}")
        annotations.append(
            {
                "id": aid,
                "image_id": image.id,
                "category_id": cid,
                "bbox": list(box),
                "area": float(area),
                "iscrowd": int(iscrowd),
            }
        )
    return LabelledSet(path, tuple(images.values()), categories, tuple(annotations))
