"""The pairing of colour and depth frames by stamp (services/detector/depth_stage.py's
:class:`Pairing`): pure, stamps in ms for reading, the items their names."""

from __future__ import annotations

import pytest

from services.detector.depth_stage import Pairing

MS = 1_000_000


def pairing(*depths: int, buffer: int = 4, tolerance_ms: int = 20) -> Pairing[str]:
    """A pairing that has heard depth frames stamped ``depths`` (ms), in that order."""
    p: Pairing[str] = Pairing(buffer, tolerance_ms * MS)
    for at in depths:
        p.depth(at * MS, f"d{at}")
    return p


def paired(p: Pairing[str], colour_ms: int) -> str | None:
    """What a colour frame stamped ``colour_ms`` gets: it arrives, a round takes it, its
    detections are built."""
    p.colour(colour_ms * MS)
    p.hold(colour_ms * MS)
    return p.take(colour_ms * MS)


def test_the_nearest_stamp_wins() -> None:
    assert paired(pairing(100, 133, 166), 140) == "d133"
    assert paired(pairing(100, 133, 166), 150) == "d166"
    assert paired(pairing(100, 133, 166), 133) == "d133"


def test_of_two_as_near_the_first_heard_wins() -> None:
    assert paired(pairing(130, 150), 140) == "d130"
    assert paired(pairing(150, 130), 140) == "d150"


def test_nothing_beyond_the_tolerance_which_is_inclusive() -> None:
    p = pairing(100, tolerance_ms=20)
    assert paired(p, 121) is None
    assert paired(p, 79) is None
    assert paired(p, 120) == "d100"
    assert paired(pairing(100, tolerance_ms=0), 101) is None
    assert paired(pairing(100, tolerance_ms=0), 100) == "d100"


def test_depth_heard_out_of_order_pairs_by_stamp_not_by_arrival() -> None:
    assert paired(pairing(166, 100, 133), 130) == "d133"
    assert paired(pairing(166, 100, 133), 105) == "d100"


def test_a_depth_frame_arriving_after_its_colour_frame_is_paired() -> None:
    p = pairing(100)
    p.colour(133 * MS)  # nearest so far: d100, beyond the tolerance
    p.depth(133 * MS, "d133")  # on its way still
    p.hold(133 * MS)
    assert p.take(133 * MS) == "d133"


def test_a_depth_frame_arriving_while_the_model_runs_is_paired() -> None:
    p = pairing(120)
    p.colour(133 * MS)  # d120 claimed
    p.hold(133 * MS)  # the round took it: the model runs
    p.colour(166 * MS)  # the next frame waits in the slot meanwhile
    p.depth(133 * MS, "d133")  # nearer: betters the claim of the frame in the round
    p.depth(166 * MS, "d166")
    assert p.take(133 * MS) == "d133"
    assert paired(p, 166) == "d166"


def test_the_buffer_keeps_the_last_frames_only() -> None:
    p = pairing(100, 110, 120, buffer=2, tolerance_ms=5)
    assert len(p.recent) == 2
    assert paired(p, 100) is None  # d100 gone
    assert paired(p, 110) == "d110"


def test_a_claim_outlives_the_buffer_while_its_frame_waits_and_runs() -> None:
    """Depth at 30 Hz, a detector round of 200 ms: the depth frame of the colour frame in
    the slot leaves a 2-frame buffer long before its detections are built."""
    p = pairing(100, buffer=2)
    p.colour(100 * MS)
    for at in range(133, 300, 33):
        p.depth(at * MS, f"d{at}")
    p.hold(100 * MS)
    for at in range(300, 400, 33):
        p.depth(at * MS, f"d{at}")
    assert "d100" not in dict(p.recent).values()
    assert p.take(100 * MS) == "d100"


def test_a_newer_colour_frame_replaces_the_claim_as_it_replaces_the_frame_in_the_slot() -> None:
    p = pairing(100, 200, buffer=4)
    p.colour(100 * MS)
    p.colour(200 * MS)  # the slot's frame now
    p.hold(200 * MS)
    assert p.take(200 * MS) == "d200"
    # The replaced frame never reaches a round; were it taken, the buffer is what there is.
    assert paired(p, 100) == "d100"


def test_a_frame_taken_before_its_claim_pairs_with_what_has_arrived() -> None:
    """The round took the frame between its slot's put and its claim (another thread)."""
    p = pairing(100, 133)
    p.hold(133 * MS)
    assert p.take(133 * MS) == "d133"


def test_a_take_clears_the_held_claim() -> None:
    p = pairing(100)
    p.colour(100 * MS)
    p.hold(100 * MS)
    assert p.take(100 * MS) == "d100"
    assert p.take(300 * MS) is None  # no claim left over to hand out


@pytest.mark.parametrize("buffer, tolerance", [(0, 0), (1, -1)])
def test_a_pairing_needs_a_buffer_and_a_tolerance(buffer: int, tolerance: int) -> None:
    with pytest.raises(ValueError):
        Pairing(buffer, tolerance)
