"""The scale benchmark's pure parts: fairness, percentiles, ratios, the table, the options."""

from __future__ import annotations

import argparse
import math

import pytest

from common.errors import StackError
from tools.benchmarks.__main__ import _camera_counts
from tools.benchmarks.scale import Result, ScaleOptions, ratios, render_table
from tools.benchmarks.stacks import fairness, percentile, ratio, ring_yaw


def _result(n: int, setup: str, fps: list[float], pss: float, det: float, p50: float = 100.0,
            batch: float = 1.0) -> Result:  # fmt: skip
    """A condition's figures; its summed RSS is taken as 1.5 times its PSS (shared pages)."""
    names = [f"c{i}" for i in range(len(fps))]
    return Result(
        n=n, setup=setup, seconds=10.0, fps=dict(zip(names, fps, strict=True)),
        p50_ms={c: p50 for c in names}, p95_ms={c: 2 * p50 for c in names},
        rss_mb=1.5 * pss, detector_rss_mb=1.5 * det, pss_mb=pss, detector_pss_mb=det,
        batch_mean=batch,
    )  # fmt: skip


def test_fairness_is_the_slowest_over_the_fastest() -> None:
    assert fairness([2.0, 4.0, 3.0]) == 0.5
    assert fairness([3.0]) == 1.0
    assert math.isnan(fairness([]))
    assert math.isnan(fairness([0.0, 0.0]))


def test_percentiles() -> None:
    values = [float(v) for v in range(1, 101)]
    assert percentile(values, 50) == pytest.approx(50.5)
    assert percentile(values, 95) == pytest.approx(95.05)
    assert math.isnan(percentile([], 50))


def test_ratio_guards_zero_and_nan() -> None:
    assert ratio(3.0, 2.0) == 1.5
    assert math.isnan(ratio(1.0, 0.0))
    assert math.isnan(ratio(float("nan"), 1.0))


def test_ratios_compare_shared_stacks_and_batching() -> None:
    results = [
        _result(1, "one", [5.0], pss=400, det=270),
        _result(2, "measured", [3.0, 3.0], pss=600, det=300, p50=200),
        _result(2, "shared", [2.0, 2.0], pss=700, det=400, p50=800, batch=2.0),
        _result(2, "batch1", [2.0, 2.0], pss=580, det=290, p50=400),
        _result(2, "stacks", [2.5, 3.5], pss=800, det=540, p50=300),
    ]
    (row,) = ratios(results)
    assert row["n"] == 2
    # Memory (PSS) and the comparison with N stacks are the shipped detector's: measured.
    assert row["memory_vs_one_camera"] == 1.5
    assert row["detector_memory_vs_one_camera"] == pytest.approx(300 / 270)
    assert row["stacks_memory_vs_one_camera"] == 2.0
    assert row["memory_shared_vs_stacks"] == 0.75
    assert row["fps_shared_vs_stacks"] == 1.0
    assert row["fps_measured_vs_batch1"] == 1.5
    assert row["p50_measured_vs_batch1"] == 0.5
    assert row["fps_batched_vs_batch1"] == 1.0
    assert row["p50_batched_vs_batch1"] == 2.0
    assert results[4].fairness == pytest.approx(2.5 / 3.5)


def test_table_shows_every_condition_the_ratios_and_what_was_skipped() -> None:
    results = [
        _result(1, "one", [5.0], pss=400, det=270),
        _result(4, "measured", [1.0, 1.0, 1.0, 1.0], pss=900, det=360, batch=1.0),
        _result(4, "shared", [1.0, 1.0, 1.0, 1.0], pss=1000, det=460, batch=4.0),
    ]
    text = render_table(results, ["8 one-camera stacks: too big"])
    lines = text.splitlines()
    assert lines[0].split()[:2] == ["N", "setup"]
    assert any(line.startswith(" 4  1 detector, batch N") and "4.00" in line for line in lines)
    assert any(line.startswith(" 4  1 detector, measured") and "900" in line for line in lines)
    assert "N=4: PSS, 1 detector / 1 camera 2.25x" in text
    assert "fps_shared_vs_stacks" not in text  # no stacks run: no such ratio
    assert lines[-1] == "skipped: 8 one-camera stacks: too big"


def test_options_are_checked() -> None:
    with pytest.raises(StackError):
        ScaleOptions(cameras=())
    with pytest.raises(StackError):
        ScaleOptions(cameras=(0,))
    with pytest.raises(StackError):
        ScaleOptions(seconds=0)
    assert _camera_counts("1,2,4") == (1, 2, 4)
    with pytest.raises(argparse.ArgumentTypeError):
        _camera_counts("1,x")
    with pytest.raises(argparse.ArgumentTypeError):
        _camera_counts("64")


def test_cameras_spread_round_the_robot_and_the_source_is_checked() -> None:
    assert [ring_yaw(i, 4) for i in range(4)] == [0.0, 90.0, 180.0, -90.0]
    assert all(-180.0 <= ring_yaw(i, 8) <= 180.0 for i in range(8))
    with pytest.raises(StackError, match="--cameras-from must be one of sim, processes"):
        ScaleOptions(cameras_from="usb")
