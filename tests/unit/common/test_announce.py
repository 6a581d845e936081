"""Announcements in token keys (common/announce.py) over an in-process bus, and the pool rule
with capacities (common/pool_rule.py)."""

from __future__ import annotations

import pytest

from common.announce import (
    MAX_CHUNK_CHARS,
    Announced,
    Announcer,
    ConflictError,
    announced_cameras,
    from_chunk,
    to_chunk,
)
from common.camera_announce import CameraAnnouncements, announcement_of
from common.errors import DecodeError
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import MAX_ANNOUNCED_RATE_HZ, CameraAnnouncement, WorkerAnnouncement
from common.pool_rule import assign
from services.camera.contract import CameraSettings

KEYS = Keys("robot1")


def _camera(name: str = "front", **kw: object) -> CameraAnnouncement:
    fields: dict[str, object] = {"camera": name, "width": 640, "height": 480, "rate_hz": 10.0}
    fields.update(kw)
    return CameraAnnouncement(**fields)  # type: ignore[arg-type]


def _cameras(bus_hub: MemoryHub, **kw: object) -> Announced[CameraAnnouncement]:
    return Announced(
        bus_hub.join("listener"),
        KEYS.all_camera_announcements(),
        KEYS.camera_announcement_parts,
        CameraAnnouncement.decode,
        lambda a: a.camera,
        **kw,  # type: ignore[arg-type]
    )


def test_a_chunk_is_a_key_chunk_and_reads_back() -> None:
    ann = _camera(mount_yaw_deg=-90.0, frame_id="robot/camera_left", source="sim")
    chunk = to_chunk(ann)
    assert KEYS.camera_announcement_parts(KEYS.camera_announcement("front", chunk)) == (
        "front",
        chunk,
    )
    assert from_chunk(CameraAnnouncement.decode, chunk) == ann


@pytest.mark.parametrize("chunk", ["", "@@@", "AAAA", "x" * 5000, to_chunk(_camera())[:-7]])
def test_garbage_chunks_are_decode_errors(chunk: str) -> None:
    with pytest.raises(DecodeError):
        from_chunk(CameraAnnouncement.decode, chunk)


@pytest.mark.parametrize(
    "bad",
    [
        {"rate_hz": 0.0},
        {"rate_hz": float("nan")},
        {"rate_hz": 1e9},
        {"width": 640, "height": 0},
        {"mount_yaw_deg": 200.0},
        {"hfov_deg": 180.0},
        {"camera": "a/b"},
    ],
)
def test_an_announcement_out_of_bounds_is_refused(bad: dict[str, object]) -> None:
    with pytest.raises(ValueError):
        _camera(**bad)


def test_a_listener_sees_announcements_come_change_and_go() -> None:
    hub = MemoryHub()
    changes: list[int] = []
    heard = _cameras(hub, on_change=lambda: changes.append(1))
    source = hub.join("camera")
    announcer: Announcer[CameraAnnouncement] = Announcer(
        source, lambda chunk: KEYS.camera_announcement("front", chunk)
    )
    assert heard.current() == {}
    announcer.update(_camera(width=0, height=0))
    assert heard.current() == {"front": _camera(width=0, height=0)}
    assert announcer.update(_camera(width=0, height=0)) is False  # same: nothing declared
    announcer.update(_camera())
    assert heard.current() == {"front": _camera()}  # the new one, never none between
    assert len(hub.tokens(KEYS.all_camera_announcements())) == 1
    source.close()  # the process ends: its announcement goes with it
    assert heard.current() == {}
    assert len(changes) == 4  # came, changed (two events: new came, old went), went


def test_a_source_cannot_announce_another_camera_and_garbage_is_reported() -> None:
    hub = MemoryHub()
    bad: list[str] = []
    heard = _cameras(hub, on_bad=lambda key, exc: bad.append(key))
    rogue = hub.join("rogue")
    rogue.declare_token(KEYS.camera_announcement("left", to_chunk(_camera("front"))))
    rogue.declare_token(KEYS.camera_announcement("rear", "notbase64atall"))
    rogue.declare_token(f"{KEYS.prefix}/camera/rear/announce")  # no chunk: not an announcement
    assert heard.current() == {}
    assert len(bad) == 2


def test_workers_announce_capacity_and_the_newest_token_is_current() -> None:
    hub = MemoryHub()
    heard = Announced(
        hub.join("listener"),
        KEYS.all_worker_announcements(),
        KEYS.worker_announcement_parts,
        WorkerAnnouncement.decode,
        lambda a: a.worker,
    )
    worker = hub.join("w")
    first = worker.declare_token(
        KEYS.worker_announcement("gpu", to_chunk(WorkerAnnouncement(worker="gpu", capacity_hz=5)))
    )
    worker.declare_token(
        KEYS.worker_announcement(
            "gpu", to_chunk(WorkerAnnouncement(worker="gpu", capacity_hz=50, seq=1))
        )
    )
    assert heard.current()["gpu"].capacity_hz == 50
    first.undeclare()
    assert heard.current()["gpu"].capacity_hz == 50


def test_shares_follow_capacity() -> None:
    weights = {f"cam{i}": 1.0 for i in range(12)}
    owners = assign({"fast": 3.0, "slow": 1.0}, weights, 1.0)
    fast = sum(1 for w in owners.values() if w == "fast")
    assert fast == 9  # 3/4 of 12, within the bound exactly
    assert assign(["a", "b"], weights, 1.25) == assign({"a": 7.0, "b": 7.0}, weights, 1.25)


def test_a_capacity_must_be_positive() -> None:
    with pytest.raises(ValueError):
        assign({"a": 0.0}, {"c": 1.0}, 1.25)


def test_the_announcers_session_id_is_bounded_and_the_longest_announcement_still_fits() -> None:
    zid = "0123456789abcdef0123456789abcdef"  # a Zenoh id: 16 bytes in hex
    longest = _camera(
        "c" * 64, frame_id="f" * 128, source="s" * 128, zid="z" * 64, depth=True,
        mount_yaw_deg=-179.123456789, hfov_deg=87.123456789, rate_hz=999.123456789,
        mount_height_m=9.123456789, mount_x_m=-9.123456789, mount_y_m=9.123456789,
    )  # fmt: skip
    assert len(to_chunk(longest)) <= MAX_CHUNK_CHARS
    assert from_chunk(CameraAnnouncement.decode, to_chunk(_camera(zid=zid))).zid == zid
    for bad in ("z" * 65, "a/b", "a b"):
        with pytest.raises(ValueError, match="zid"):
            _camera(zid=bad)


def test_a_camera_source_names_its_session_in_its_announcements() -> None:
    hub = MemoryHub()
    bus = hub.join("sim")
    with CameraAnnouncements(bus, KEYS, "sim") as announcements:
        said = announcements.announce(
            "front", CameraSettings(rate_hz=5.0, frame_id="cam", mount_height_m=0.5), depth=True
        )
        assert (said.rate_hz, said.frame_id, said.mount_height_m) == (5.0, "cam", 0.5)
        assert said.zid == bus.zid
        announcements.saw("front", 640, 480)
        current = announcements.current("front")
        assert current is not None and current.zid == bus.zid


def test_a_second_announcer_with_another_mounting_is_refused_while_the_first_lives() -> None:
    # Issue 39: a second announcer of "front" looking backwards was believed (newest wins):
    # the robot turned 259 degrees and lost the person. Now refused, and said, while the
    # first lives; believed once the first has gone.
    hub = MemoryHub()
    bad: list[tuple[str, Exception]] = []
    changes: list[int] = []
    heard = announced_cameras(
        hub.join("listener"), KEYS, lambda: changes.append(1), lambda k, e: bad.append((k, e))
    )
    real = Announcer(hub.join("camera"), lambda c: KEYS.camera_announcement("front", c))
    real.update(_camera(mount_yaw_deg=0.0))
    rogue = Announcer(hub.join("rogue"), lambda c: KEYS.camera_announcement("front", c))
    rogue.update(_camera(mount_yaw_deg=180.0, hfov_deg=90.0))
    assert heard.current()["front"].mount_yaw_deg == 0.0
    [(_, error)] = bad
    assert isinstance(error, ConflictError)
    assert "mount_yaw_deg 0 -> 180" in str(error) and "hfov_deg 60 -> 90" in str(error)
    # The real source learns its size: the same mounting, believed.
    real.update(_camera(mount_yaw_deg=0.0, width=1280, height=720))
    assert heard.current()["front"].width == 1280
    assert len(bad) == 1
    # A rogue with the same mounting is no conflict (nothing it says turns the robot).
    real.close()
    assert heard.current()["front"].mount_yaw_deg == 180.0  # the first gone: the other's
    rogue.close()
    assert "front" not in heard.current()


def test_a_source_that_moves_its_own_camera_is_believed_after_a_moment() -> None:
    hub = MemoryHub()
    bad: list[tuple[str, Exception]] = []
    heard = announced_cameras(hub.join("listener"), KEYS, None, lambda k, e: bad.append((k, e)))
    source = Announcer(hub.join("camera"), lambda c: KEYS.camera_announcement("front", c))
    source.update(_camera(mount_yaw_deg=0.0))
    source.update(_camera(mount_yaw_deg=90.0))  # new token first, then the old withdrawn
    assert heard.current()["front"].mount_yaw_deg == 90.0
    assert len(bad) == 1  # said once, as it overlapped


def test_one_builder_makes_a_cameras_announcement_from_its_settings() -> None:
    # Issue 40: announcements were built field by field in four places (camera, simulator,
    # bridge, player); every source now builds them with announcement_of.
    settings = CameraSettings(
        rate_hz=25.0, hfov_deg=70.0, mount_yaw_deg=90.0, frame_id="left_optical",
        mount_height_m=0.4, mount_x_m=0.1, mount_y_m=-0.2,
    )  # fmt: skip
    a = announcement_of("left", settings, source="camera", zid="abc", depth=True)
    assert (a.camera, a.source, a.zid, a.depth) == ("left", "camera", "abc", True)
    assert (a.hfov_deg, a.mount_yaw_deg, a.frame_id) == (70.0, 90.0, "left_optical")
    assert (a.mount_height_m, a.mount_x_m, a.mount_y_m) == (0.4, 0.1, -0.2)
    assert a.rate_hz == 25.0
    capped = announcement_of("left", settings, source="play", zid="", rate_hz=5000.0)
    assert capped.rate_hz == MAX_ANNOUNCED_RATE_HZ
    b = announcement_of(
        "left", settings, source="sim", zid="", rate_hz=2.0, frame_id="f", width=64, height=48,
        mount_height_m=0.0,
    )  # fmt: skip
    assert (b.rate_hz, b.frame_id, b.width, b.height, b.mount_height_m) == (2.0, "f", 64, 48, 0.0)
    assert b.mount_x_m == 0.1  # what is not changed is the settings'
    # an announcement read back describes the same camera
    assert announcement_of("left", a, source="camera", zid="abc", depth=True) == a
