"""``detect`` on a video and a camera device, and sources that give nothing readable: the
command line and the camera service as a user runs them (real processes, real photos)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from skimage import data

from common.annotate import class_colour
from common.lifecycle import PERMANENT_FAILURES
from tests.integration.conftest import wait_for, write_config

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[2]
FRAMES = 3
FPS = 5.0
SIZE = (448, 300)  # chelsea (451x300) cropped to an even width, which every codec accepts


def run(*args: str | Path, module: str = "tools.detector") -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", module, *map(str, args)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )


def read_video(path: Path) -> tuple[list[npt.NDArray[np.uint8]], float]:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while (got := cap.read())[0]:
        frames.append(got[1])
    fps = float(cap.get(cv2.CAP_PROP_FPS))
    cap.release()
    return frames, fps


@pytest.fixture(scope="module")
def cat_video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short clip of the cat photo panning sideways."""
    path = tmp_path_factory.mktemp("video") / "cat.avi"
    cat = np.ascontiguousarray(data.chelsea()[:, : SIZE[0], ::-1])
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), FPS, SIZE)
    for i in range(FRAMES):
        writer.write(np.roll(cat, 12 * i, axis=1))
    writer.release()
    return path


@pytest.fixture
def corrupt_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "corrupt"
    folder.mkdir()
    for i in range(20):
        (folder / f"img{i:02d}.jpg").write_bytes(b"\xff\xd8 not really a jpeg %d" % i)
    return folder


def test_detect_video_progress_annotated_video_and_json(
    default_model: Path, cat_video: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    proc = run("detect", cat_video, "--model", default_model, "--json", "--save-dir", out)
    assert proc.returncode == 0, proc.stderr
    # The progress bar: its last line is the whole video, with a frame rate.
    last = proc.stderr.strip().splitlines()[-1]
    assert f"{cat_video}: [" in last and f"100% {FRAMES}/{FRAMES} frames" in last, proc.stderr
    assert "fps, done in" in last
    records = [json.loads(line) for line in proc.stdout.splitlines()]
    assert [r["frame"] for r in records] == list(range(FRAMES))
    for r in records:
        assert r["image"] == str(cat_video) and (r["width"], r["height"]) == SIZE
        assert r["detections"][0]["class_name"] == "cat", r
    # The per-frame results, as on stdout; the annotated video at the source's rate and size.
    saved = (out / "cat.jsonl").read_text().splitlines()
    assert [json.loads(line) for line in saved] == records
    frames, fps = read_video(out / "cat.mp4")
    assert len(frames) == FRAMES and fps == FPS
    assert all(f.shape == (SIZE[1], SIZE[0], 3) for f in frames)
    # It is annotated: the label's patch at the cat box's top-left corner is the class colour.
    det = records[0]["detections"][0]
    x1, y1 = (round(v) for v in det["bbox_xyxy"][:2])
    patch = frames[0][y1 + 2 : y1 + 8, x1 + 2 : x1 + 30].reshape(-1, 3)
    colour = np.array(class_colour(det["class_id"]), np.float64)
    assert np.abs(np.median(patch, axis=0) - colour).max() < 40, np.median(patch, axis=0)


def test_detect_missing_device_is_one_line() -> None:
    proc = run("detect", "device:97")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines() == [
        "error: cannot open camera device 97 (no such device)"
    ]


def test_detect_folder_of_only_corrupt_images_fails(
    default_model: Path, corrupt_folder: Path
) -> None:
    proc = run("detect", corrupt_folder, "--model", default_model)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == "error: none of the 20 image(s) could be read"
    assert proc.stdout == ""


def test_camera_on_a_folder_of_only_corrupt_images_ends_with_one_line(
    corrupt_folder: Path, tmp_path: Path
) -> None:
    """Before, it logged a line per file per frame, forever: the deadline catches that."""
    config = write_config(tmp_path, camera={"source": str(corrupt_folder), "rate_hz": 30.0})
    log = tmp_path / "camera.log"
    with log.open("wb") as sink:
        proc = subprocess.Popen(
            [sys.executable, "-m", "services.camera", "serve", "--config", str(config)],
            cwd=REPO, stdout=sink, stderr=subprocess.STDOUT,
        )  # fmt: skip
        try:
            wait_for(
                lambda: proc.poll() is not None, 30, lambda: f"the camera to exit:\n{tail(log)}"
            )
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
    lines = log.read_text().splitlines()
    assert proc.returncode in PERMANENT_FAILURES, lines
    errors = [line for line in lines if "error:" in line]
    assert errors == [
        f"camera: error: folder {corrupt_folder} (20 images): not one of them is a readable image"
    ]
    assert len([line for line in lines if "skipped" in line]) <= 4, lines
    assert len(lines) <= 10, lines


def tail(path: Path) -> str:
    return "\n".join(path.read_text(errors="replace").splitlines()[-10:])


def test_detect_reads_a_network_stream_at_the_asked_size(cat_video: Path, tmp_path: Path) -> None:
    """A video served over HTTP (a real socket, OpenCV's FFmpeg on the other end), as `yolo
    predict source=http://...` would read it, at --imgsz 320 on --device cpu."""
    import functools
    import http.server
    import threading

    handler = functools.partial(
        http.server.SimpleHTTPRequestHandler, directory=str(cat_video.parent)
    )
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/{cat_video.name}"
        done = run("detect", url, "--json", "--imgsz", "320", "--device", "cpu")
    finally:
        server.shutdown()
        server.server_close()
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(lines) == FRAMES, done.stdout
    assert any(d["class_name"] == "cat" for line in lines for d in line["detections"]), lines


def test_a_stream_that_does_not_answer_is_one_line(tmp_path: Path) -> None:
    done = run("detect", "rtsp://127.0.0.1:9/stream")
    assert done.returncode in PERMANENT_FAILURES, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines()[-1] == (
        "error: cannot open network stream rtsp://127.0.0.1:9/stream "
        "(no stream there, or none within 5 s)"
    ), done.stderr
