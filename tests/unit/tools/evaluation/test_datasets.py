"""Reading COCO JSON and YOLO folders, and the one-line errors for bad ones."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from tools.evaluation.datasets import load_dataset
from tools.evaluation.labelled import DatasetError
from tools.evaluation.yolo_dataset import read_class_names


def _image(path: Path, width: int, height: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), np.zeros((height, width, 3), np.uint8))
    return path


def _coco(tmp_path: Path, **changes: Any) -> Path:
    data: dict[str, Any] = {
        "images": [{"id": 7, "file_name": "a.png", "width": 64, "height": 48}],
        "categories": [{"id": 1, "name": "person"}, {"id": 3, "name": "cup"}],
        "annotations": [
            {"id": 1, "image_id": 7, "category_id": 1, "bbox": [10, 5, 20, 30], "iscrowd": 0},
            {"image_id": 7, "category_id": 3, "bbox": [0, 0, 64, 48], "area": 100.0},
        ],
    }
    data.update(changes)
    _image(tmp_path / "a.png", 64, 48)
    path = tmp_path / "ann.json"
    path.write_text(json.dumps(data))
    return path


def test_coco_file_is_read_with_defaults_filled_in(tmp_path: Path) -> None:
    ds = load_dataset(_coco(tmp_path))
    (image,) = ds.images
    assert (image.id, image.path.name, image.width, image.height) == (7, "a.png", 64, 48)
    assert ds.categories == {1: "person", 3: "cup"}
    first, second = ds.annotations
    assert first["area"] == 600.0 and first["bbox"] == [10.0, 5.0, 20.0, 30.0]
    assert second["id"] == 2 and second["iscrowd"] == 0 and second["area"] == 100.0
    gt = ds.ground_truth({3})
    assert [c["name"] for c in gt["categories"]] == ["cup"]
    assert [a["category_id"] for a in gt["annotations"]] == [3]


def test_coco_images_resolve_against_the_images_folder(tmp_path: Path) -> None:
    ann = _coco(tmp_path)
    elsewhere = _image(tmp_path / "pics" / "a.png", 64, 48)
    assert load_dataset(ann, tmp_path / "pics").images[0].path == elsewhere


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"images": [{"id": 7, "file_name": "nope.png", "width": 64, "height": 48}]},
         "image 'nope.png' (id 7) not found"),
        ({"annotations": [{"image_id": 7, "category_id": 1, "bbox": [50, 5, 20, 30]}]},
         "lies outside its 64x48 image"),
        ({"annotations": [{"image_id": 7, "category_id": 1, "bbox": [5, 5, 0, 30]}]},
         "has no area"),
        ({"annotations": [{"image_id": 9, "category_id": 1, "bbox": [5, 5, 5, 5]}]},
         "image_id 9 is not in images"),
        ({"annotations": [{"image_id": 7, "category_id": 2, "bbox": [5, 5, 5, 5]}]},
         "category_id 2 is not in categories"),
        ({"annotations": [{"image_id": 7, "category_id": 1, "bbox": [5, 5, 5]}]},
         "'bbox' must be [x, y, width, height]"),
        ({"categories": [{"id": 1, "name": "a"}, {"id": 1, "name": "b"}]},
         "duplicate category id 1"),
        ({"images": "a.png"}, "needs a 'images' list"),
    ],
)  # fmt: skip
def test_bad_coco_files_name_the_file_and_the_problem(
    tmp_path: Path, changes: dict[str, Any], message: str
) -> None:
    path = _coco(tmp_path, **changes)
    with pytest.raises(DatasetError) as err:
        load_dataset(path)
    assert message in str(err.value)
    assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)


def test_malformed_json_says_where(tmp_path: Path) -> None:
    path = tmp_path / "ann.json"
    path.write_text('{"images": [\n  {"id": 1,}\n]}')
    with pytest.raises(DatasetError, match=r"ann.json: not valid JSON \(line 2, column 12"):
        load_dataset(path)


def test_a_missing_dataset_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no such file or folder"):
        load_dataset(tmp_path / "missing.json")


def _yolo(tmp_path: Path, names_file: str, names_text: str, label: str) -> Path:
    root = tmp_path / "yolo"
    _image(root / "images" / "val" / "x.v2.jpg", 100, 50)
    _image(root / "images" / "val" / "empty.png", 10, 10)
    (root / "labels" / "val").mkdir(parents=True)
    (root / "labels" / "val" / "x.v2.txt").write_text(label)
    (root / names_file).write_text(names_text)
    return root


def test_yolo_folder_becomes_pixel_boxes(tmp_path: Path) -> None:
    labels = "1 0.5 0.5 0.2 0.4\n\n0 0.1 0.1 0.2 0.2\n"  # a blank line is allowed
    root = _yolo(tmp_path, "classes.txt", "person\ncup\n", labels)
    ds = load_dataset(root)
    assert ds.categories == {1: "person", 2: "cup"}
    assert sorted((im.path.name, im.width, im.height) for im in ds.images) == [
        ("empty.png", 10, 10), ("x.v2.jpg", 100, 50)
    ]  # fmt: skip
    cup, person = ds.annotations
    assert cup["category_id"] == 2 and cup["bbox"] == pytest.approx([40, 15, 20, 20])
    assert person["category_id"] == 1 and person["bbox"] == pytest.approx([0, 0, 20, 10])


@pytest.mark.parametrize(
    "text",
    [
        "path: ../x\nnames: [person, 'cup', \"dining table\"]\nnc: 3\n",
        "names:\n  - person\n  - cup  # a comment\n  - 'dining table'\nnc: 3\n",
        "names:\n  0: person\n  1: cup\n  2: dining table\n",
        "names: {0: person, 1: cup, 2: 'dining table'}\n",
    ],
)
def test_data_yaml_names_in_the_forms_ultralytics_writes(tmp_path: Path, text: str) -> None:
    (tmp_path / "data.yaml").write_text(text)
    (tmp_path / "classes.txt").write_text("ignored\n")  # data.yaml comes first
    assert read_class_names(tmp_path)[1] == ["person", "cup", "dining table"]


@pytest.mark.parametrize(
    ("label", "message"),
    [
        ("2 0.5 0.5 0.2 0.2\n", r"x.v2.txt:1: class id 2 is out of range: classes.txt names 2"),
        ("0 0.5 1.5 0.2 0.2\n", r"x.v2.txt:1: coordinates .* must be normalised to 0..1"),
        ("0 0.9 0.5 0.4 0.2\n", r"x.v2.txt:1: box .* lies outside its 100x50 image"),
        ("0 0.5 0.5 0.2\n", r"x.v2.txt:1: expected 'class cx cy w h'"),
        ("person 0.5 0.5 0.2 0.2\n", r"x.v2.txt:1: expected 'class cx cy w h'"),
    ],
)
def test_bad_yolo_labels_name_file_and_line(tmp_path: Path, label: str, message: str) -> None:
    root = _yolo(tmp_path, "classes.txt", "person\ncup\n", label)
    with pytest.raises(DatasetError, match=message):
        load_dataset(root)


def test_yolo_label_without_its_image_is_a_missing_image(tmp_path: Path) -> None:
    root = _yolo(tmp_path, "classes.txt", "person\n", "0 0.5 0.5 0.2 0.2\n")
    (root / "labels" / "val" / "gone.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    with pytest.raises(DatasetError, match=r"gone.txt: its image is missing"):
        load_dataset(root)


def test_yolo_without_names_or_with_images_option(tmp_path: Path) -> None:
    root = _yolo(tmp_path, "notes.txt", "", "0 0.5 0.5 0.2 0.2\n")
    with pytest.raises(DatasetError, match=r"no class names; add classes\.txt"):
        load_dataset(root)
    with pytest.raises(DatasetError, match=r"--images applies to a COCO JSON file"):
        load_dataset(root, tmp_path)


def test_only_classes_the_model_knows_are_scored(tmp_path: Path) -> None:
    from tools.evaluation.evaluate import ground_truth_for

    ds = load_dataset(_coco(tmp_path))
    gt, mapping, excluded = ground_truth_for(ds, ("person", "dog"))
    assert mapping == {"person": 1} and excluded == ("cup",)
    assert [a["category_id"] for a in gt["annotations"]] == [1]
    with pytest.raises(DatasetError, match=r"ann\.json: no labelled box of a class the model"):
        ground_truth_for(ds, ("dog",))
