"""`evaluate` on bad datasets: one line on stderr naming the file, exit 2, before any model."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[4]


def _evaluate(*args: str) -> subprocess.CompletedProcess[str]:
    # A model path that does not exist: the dataset must be refused before it is looked at.
    cmd = [sys.executable, "-m", "tools.evaluation", "evaluate", "--model", "/nonexistent.onnx"]
    return subprocess.run(
        [*cmd, *args], cwd=REPO, capture_output=True, text=True, timeout=60, check=False
    )


def _one_line_error(proc: subprocess.CompletedProcess[str]) -> str:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("evaluate: error: "), proc.stderr
    assert "Traceback" not in proc.stderr
    return lines[0]


def test_missing_image(tmp_path: Path) -> None:
    ann = tmp_path / "ann.json"
    ann.write_text(json.dumps({
        "images": [{"id": 1, "file_name": "gone.jpg", "width": 10, "height": 10}],
        "categories": [{"id": 1, "name": "person"}],
        "annotations": [],
    }))  # fmt: skip
    line = _one_line_error(_evaluate("--dataset", str(ann)))
    assert f"{ann}: image 'gone.jpg' (id 1) not found at {tmp_path / 'gone.jpg'}" in line
    assert "--images names the folder" in line


def test_the_shipped_labels_without_their_photos_name_the_script() -> None:
    ann = REPO / "tools" / "evaluation" / "data" / "skimage_coco.json"
    line = _one_line_error(_evaluate("--dataset", str(ann)))
    assert f"write its photos with `python {ann.parent / 'write_images.py'} DIR`" in line


def test_label_out_of_range(tmp_path: Path) -> None:
    import cv2
    import numpy as np

    (tmp_path / "images").mkdir()
    (tmp_path / "labels").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "a.png"), np.zeros((8, 8, 3), np.uint8))
    (tmp_path / "labels" / "a.txt").write_text("0 0.5 0.5 0.5 0.5\n3 0.5 0.5 0.2 0.2\n")
    (tmp_path / "classes.txt").write_text("person\ncup\n")
    line = _one_line_error(_evaluate("--dataset", str(tmp_path)))
    label = tmp_path / "labels" / "a.txt"
    assert f"{label}:2: class id 3 is out of range: classes.txt names 2 classes (0..1)" in line


def test_malformed_json(tmp_path: Path) -> None:
    ann = tmp_path / "ann.json"
    ann.write_text('{"images": [}')
    line = _one_line_error(_evaluate("--dataset", str(ann)))
    assert f"{ann}: not valid JSON (line 1, column 13: Expecting value)" in line
