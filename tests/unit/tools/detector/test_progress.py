"""detect's plain-text progress bar: its line, and how often it is written."""

from __future__ import annotations

import io

from tools.detector.progress import ProgressBar, progress_line


def test_progress_line_with_and_without_a_total() -> None:
    assert progress_line("clip.mp4", 5, 10, 2.5) == (
        "clip.mp4: [##########..........]  50% 5/10 frames, 2.0 fps, 2 s left"
    )
    assert progress_line("clip.mp4", 10, 10, 5.0).endswith("10/10 frames, 2.0 fps, done in 5.0 s")
    assert progress_line("device:0", 42, 0, 4.2) == "device:0: 42 frames, 10.0 fps, 4 s"
    assert progress_line("images", 0, 3, 0.0, unit="images").endswith(
        "0/3 images, 0.0 fps, starting"
    )


def test_updates_are_throttled_and_the_last_one_is_always_written() -> None:
    t = [0.0]
    out = io.StringIO()
    bar = ProgressBar("v", 100, stream=out, period_s=1.0, clock=lambda: t[0])
    for _ in range(100):
        t[0] += 0.1  # 10 frames a second for 10 s: 10 updates at most, then the final one
        bar.advance()
    bar.finish()
    lines = out.getvalue().splitlines()
    assert 9 <= len(lines) <= 11
    assert lines[-1] == "v: [####################] 100% 100/100 frames, 10.0 fps, done in 10.0 s"


def test_nothing_done_writes_nothing() -> None:
    out = io.StringIO()
    ProgressBar("v", 10, stream=out).finish()
    assert out.getvalue() == ""
