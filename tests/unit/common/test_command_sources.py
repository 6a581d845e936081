from __future__ import annotations

from common.command_sources import MAX_SOURCES, CommandSources


def test_one_source_then_a_second_within_the_window() -> None:
    sources = CommandSources(window_s=1.0)
    assert sources.heard("ctrl", 0.0) == (1, True)
    assert sources.heard("ctrl", 0.5) == (1, False)
    assert sources.heard("rogue", 0.6) == (2, True)
    assert sources.heard("ctrl", 0.7) == (2, False)
    # The second one went quiet: after the window only the controller is left.
    assert sources.heard("ctrl", 1.65) == (1, False)
    assert sources.active() == ["ctrl"]


def test_a_flood_of_ids_is_bounded() -> None:
    sources = CommandSources(window_s=10.0)
    for i in range(MAX_SOURCES * 3):
        sources.heard(f"id{i}", 0.0)
    assert len(sources.active()) == MAX_SOURCES
