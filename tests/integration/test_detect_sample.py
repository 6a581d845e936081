"""``zstack detect`` with no file at hand: the bundled scikit-image photos, as a user runs it.

With no PATH it looks at ``sample:chelsea`` (as ``yolo predict`` has its bundled images), and
any ``sample:<name>`` (the camera's own source form) works in place of a path.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from tests.integration.conftest import REPO
from tests.integration.test_detect_real import CHELSEA_CAT, box_iou

pytestmark = pytest.mark.integration


def zstack(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "deploy.zstack", *map(str, args)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )


def test_detect_with_no_path_finds_the_cat_in_the_bundled_photo(
    default_model: Path, tmp_path: Path
) -> None:
    proc = zstack("detect")
    assert proc.returncode == 0, proc.stderr
    assert "sample:chelsea" in proc.stderr  # it says which photo it looked at
    [line] = proc.stdout.strip().splitlines()
    assert line.startswith("sample:chelsea: 451x300"), line
    assert " cat " in line, line

    proc = zstack("detect", "--json", "--save-dir", tmp_path)
    assert proc.returncode == 0, proc.stderr
    [record] = [json.loads(row) for row in proc.stdout.strip().splitlines()]
    assert record["image"] == "sample:chelsea"
    top = record["detections"][0]
    assert top["class_name"] == "cat"
    assert box_iou(top["bbox_xyxy"], CHELSEA_CAT) >= 0.5
    saved = cv2.imread(str(tmp_path / "chelsea.png"))
    assert saved is not None and saved.shape == (300, 451, 3)


def test_detect_a_named_sample_as_json(default_model: Path) -> None:
    proc = zstack("detect", "sample:astronaut", "--json")
    assert proc.returncode == 0, proc.stderr
    assert "sample:astronaut" in proc.stderr
    [record] = [json.loads(row) for row in proc.stdout.strip().splitlines()]
    assert record["image"] == "sample:astronaut"
    assert (record["width"], record["height"]) == (512, 512)
    assert "person" in {d["class_name"] for d in record["detections"]}
    assert set(record["timing_ms"]) == {"preprocess", "inference", "postprocess"}


def test_unknown_sample_is_one_line_naming_the_samples() -> None:
    proc = zstack("detect", "sample:dog")
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "unknown sample 'dog'" in lines[0] and "chelsea" in lines[0]
