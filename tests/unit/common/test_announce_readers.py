"""Every reader of announcements goes through common/announce.py: the listener
(:class:`Announced`) and one look at the tokens alive now (``announced_now``, ``cameras_now``,
``workers_now``), read by the same ``read_token`` and with garbage reported the same way. No
module outside it parses an announcement token by hand, but the recorder, which records each
token's chunk raw and decodes it later (docs/architecture.md)."""

from __future__ import annotations

import re
from pathlib import Path

from common.announce import cameras_now, to_chunk, workers_now
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement, WorkerAnnouncement

KEYS = Keys("robot1")
ROOT = Path(__file__).resolve().parents[3]
LIBRARIES_AND_PROGRAMS = (
    "common", "stack", "perception", "rosmsg", "simworld", "depthscan", "services",
    "runtimes", "modelprep", "tools", "deploy",
)  # fmt: skip
#: Where an announcement token's key is split or its chunk decoded by hand, and why.
BY_HAND = {
    "common/announce.py": "the one place announcements are read",
    "common/keys.py": "the key space: the parts of a key",
    "services/recorder/service.py": "records each chunk raw, decodes it later, as any payload",
}
HAND_READ = re.compile(r"\b(camera|worker)_announcement_parts\b|\bfrom_chunk\(")


def _camera(name: str, **kw: object) -> CameraAnnouncement:
    fields: dict[str, object] = {"camera": name, "width": 640, "height": 480, "rate_hz": 10.0}
    fields.update(kw)
    return CameraAnnouncement(**fields)  # type: ignore[arg-type]


def test_one_look_reads_and_reports_as_the_listener_does() -> None:
    hub = MemoryHub()
    source = hub.join("sources")
    source.declare_token(KEYS.camera_announcement("front", to_chunk(_camera("front"))))
    source.declare_token(KEYS.camera_announcement("rear", to_chunk(_camera("rear", rate_hz=5.0))))
    source.declare_token(KEYS.camera_announcement("rear", to_chunk(_camera("rear", rate_hz=7.0))))
    source.declare_token(KEYS.camera_announcement("left", to_chunk(_camera("front"))))  # not its
    source.declare_token(KEYS.camera_announcement("top", "notbase64atall"))
    source.declare_token(f"{KEYS.prefix}/camera/back/announce")  # no chunk: no announcement
    bad: list[str] = []
    heard = cameras_now(hub.join("reader"), KEYS, 1.0, lambda key, exc: bad.append(key))
    assert sorted(heard) == ["front", "rear"]
    assert sorted(a.rate_hz for a in heard["rear"]) == [5.0, 7.0]  # both, for the reader
    assert sorted(k.split("/")[2] for k in bad) == ["left", "top"]


def test_one_look_at_the_workers() -> None:
    hub = MemoryHub()
    worker = hub.join("w")
    ok = WorkerAnnouncement(worker="gpu", capacity_hz=50.0)
    worker.declare_token(KEYS.worker_announcement("gpu", to_chunk(ok)))
    worker.declare_token(KEYS.worker_announcement("cpu", "AAAA"))  # base64 of no message
    bad: list[str] = []
    assert workers_now(hub.join("reader"), KEYS, 1.0, lambda k, e: bad.append(k)) == {"gpu": [ok]}
    assert len(bad) == 1 and "/cpu/" in bad[0]
    assert workers_now(hub.join("quiet"), KEYS, 1.0) == {"gpu": [ok]}  # no on_bad: left out


def test_no_module_reads_an_announcement_token_by_hand() -> None:
    found = []
    for package in LIBRARIES_AND_PROGRAMS:
        for path in sorted((ROOT / package).rglob("*.py")):
            where = path.relative_to(ROOT).as_posix()
            if where not in BY_HAND and HAND_READ.search(path.read_text(encoding="utf-8")):
                found.append(where)
    assert found == [], f"read announcements through common/announce.py: {found}"
