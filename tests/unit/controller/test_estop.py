"""The persisted e-stop latch: survives a reload, refuses old releases, fails safe."""

from __future__ import annotations

from pathlib import Path

from services.controller.estop import EStopLatch


def test_engaged_state_survives_a_new_latch(tmp_path: Path) -> None:
    path = tmp_path / "state" / "estop.json"
    latch = EStopLatch(path)
    assert not latch.engaged and "none was ever engaged" in latch.note
    latch.engage(100, "estop-cli", "operator")
    again = EStopLatch(path)
    assert again.engaged and again.state.by == "estop-cli" and again.state.reason == "operator"


def test_release_must_be_newer_than_the_engagement(tmp_path: Path) -> None:
    latch = EStopLatch(tmp_path / "estop.json")
    latch.engage(200, "estop-cli", "")
    assert not latch.release(150, "estop-cli")  # an old release played back
    assert not latch.release(200, "estop-cli")
    assert latch.engaged and EStopLatch(latch.path).engaged
    assert latch.release(201, "estop-cli")
    assert not latch.engaged and not EStopLatch(latch.path).engaged


def test_engage_keeps_the_newest_stamp(tmp_path: Path) -> None:
    latch = EStopLatch(tmp_path / "estop.json")
    latch.engage(300, "a", "")
    latch.engage(100, "b", "")  # an old engage still latches, but cannot lower the bar
    assert not latch.release(250, "estop-cli")
    assert latch.release(301, "estop-cli")


def test_unreadable_state_counts_as_engaged(tmp_path: Path) -> None:
    path = tmp_path / "estop.json"
    path.write_text("{not json")
    latch = EStopLatch(path)
    assert latch.engaged and "unreadable" in latch.note
    path.write_text('{"engaged": false}')  # a field missing
    assert EStopLatch(path).engaged
