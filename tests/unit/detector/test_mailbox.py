from __future__ import annotations

from services.detector.mailbox import Mailbox


def test_newest_item_wins_and_each_overwrite_reports_a_drop() -> None:
    box: Mailbox[int] = Mailbox()
    assert box.put(1) is False
    assert box.put(2) is True  # 1 was never taken: dropped
    item = box.take(timeout=0.1)
    assert item is not None and item[0] == 2 and item[1] > 0
    assert box.take(timeout=0.01) is None
    assert box.put(3) is False  # the slot was empty again
