"""The persisted e-stop latch: survives a reload, refuses old releases, fails safe, holds
when it cannot be saved, and bounds the stamps it keeps."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from services.controller.estop import MAX_STAMP_NS, EStopLatch, parse

LATEST = 10**18  # the receiver's clock plus tolerance, in these tests


def test_engaged_state_survives_a_new_latch(tmp_path: Path) -> None:
    path = tmp_path / "state" / "estop.json"
    latch = EStopLatch(path, LATEST)
    assert not latch.engaged and "none was ever engaged" in latch.note
    latch.engage(100, "estop-cli", "operator", LATEST)
    again = EStopLatch(path, LATEST)
    assert again.engaged and again.state.by == "estop-cli" and again.state.reason == "operator"


def test_release_must_be_newer_than_the_engagement(tmp_path: Path) -> None:
    latch = EStopLatch(tmp_path / "estop.json", LATEST)
    latch.engage(200, "estop-cli", "", LATEST)
    assert not latch.release(150, "estop-cli")  # an old release played back
    assert not latch.release(200, "estop-cli")
    assert latch.engaged and EStopLatch(latch.path, LATEST).engaged
    assert "stamped before the stop" in latch.describe()
    assert latch.release(201, "estop-cli")
    assert not latch.engaged and not EStopLatch(latch.path, LATEST).engaged


def test_engage_keeps_the_newest_stamp(tmp_path: Path) -> None:
    latch = EStopLatch(tmp_path / "estop.json", LATEST)
    latch.engage(300, "a", "", LATEST)
    latch.engage(100, "b", "", LATEST)  # an old engage still latches, but cannot lower the bar
    assert not latch.release(250, "estop-cli")
    assert latch.release(301, "estop-cli")


def test_unreadable_state_counts_as_engaged(tmp_path: Path) -> None:
    path = tmp_path / "estop.json"
    path.write_text("{not json")
    latch = EStopLatch(path, LATEST)
    assert latch.engaged and "unreadable" in latch.note
    path.write_text('{"engaged": false}')  # a field missing
    assert EStopLatch(path, LATEST).engaged


@pytest.mark.parametrize(
    "text",
    [
        '{"engaged": false, "since_ns": 1e400, "by": "x", "reason": "y"}',  # inf: once a crash
        '{"engaged": [], "since_ns": 0, "by": "x", "reason": "y"}',  # once read as released
        '{"engaged": 0, "since_ns": 0, "by": "x", "reason": "y"}',
        '{"engaged": false, "since_ns": -1, "by": "x", "reason": "y"}',
        f'{{"engaged": false, "since_ns": {MAX_STAMP_NS + 1}, "by": "x", "reason": "y"}}',
        '{"engaged": false, "since_ns": true, "by": "x", "reason": "y"}',
        '{"engaged": false, "since_ns": 1, "by": 5, "reason": "y"}',
        '{"engaged": false, "since_ns": 1, "by": "x", "reason": "y", "extra": 1}',
        "[false]",
        "[" * 100_000,  # nested past the parser's recursion limit
        "\udcff",
    ],
)
def test_anything_but_a_well_formed_released_state_is_engaged(tmp_path: Path, text: str) -> None:
    path = tmp_path / "estop.json"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    latch = EStopLatch(path, LATEST)
    assert latch.engaged and "unreadable" in latch.note
    # ... and the file is made well-formed and engaged, so the next start reads it as such.
    assert EStopLatch(path, LATEST).engaged
    assert parse(json.loads(path.read_text())).engaged


def test_a_future_stamp_is_bounded_by_the_clock(tmp_path: Path) -> None:
    path = tmp_path / "estop.json"
    latch = EStopLatch(path, LATEST)
    century = LATEST + 100 * 365 * 86400 * 10**9
    latch.engage(century, "rogue", "", LATEST)
    assert latch.state.since_ns == LATEST
    assert latch.release(LATEST + 1, "estop-cli")  # a fresh release still clears it
    # A state file that an older controller wrote with such a stamp: bounded when read.
    path.write_text(json.dumps({"engaged": True, "since_ns": century, "by": "r", "reason": ""}))
    again = EStopLatch(path, LATEST)
    assert again.engaged and again.state.since_ns == LATEST and "in the future" in again.note
    assert again.release(LATEST + 1, "estop-cli")


def test_a_latch_that_cannot_be_saved_starts_and_stays_engaged(tmp_path: Path) -> None:
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")  # its 'state folder' is a file: nothing can be written inside
    path = blocker / "estop.json"
    latch = EStopLatch(path, LATEST)
    assert latch.engaged and not latch.saved and "NOT SAVED" in latch.describe()
    assert not latch.release(LATEST, "estop-cli") and latch.engaged  # cannot be saved: refused
    assert "cannot be saved" in latch.describe()
    # An engage holds in memory and says it was not saved.
    assert not latch.engage(5, "estop-cli", "operator", LATEST) and latch.engaged
    # Once the folder can be written, a release works and is saved.
    blocker.unlink()
    assert latch.release(LATEST, "estop-cli") and not latch.engaged and latch.saved
    assert not EStopLatch(path, LATEST).engaged


def test_the_stop_goes_out_once_latched_in_memory_before_it_is_saved(tmp_path: Path) -> None:
    latch = EStopLatch(tmp_path / "estop.json", LATEST)
    seen: list[tuple[bool, bool]] = []  # (engaged in memory, engaged on disk) when called

    def latched() -> None:
        seen.append((latch.engaged, EStopLatch(latch.path, LATEST).engaged))

    assert latch.engage(100, "estop-cli", "", LATEST, latched)
    assert seen == [(True, False)]  # the zero is sent before the disk is touched
    assert EStopLatch(latch.path, LATEST).engaged
