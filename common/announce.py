"""Announcements: what a camera source or a detector worker says of itself on the bus, carried
in the key of a liveliness token, so that it lives exactly as long as its announcer does.

A token's key cannot carry bytes, so the announcement (a message of common/messages.py) is
encoded into one key chunk: base64url of the message's msgpack, unpadded (letters, digits,
``-`` and ``_``: a valid Zenoh chunk). rmw_zenoh puts its graph (node, topic, type, QoS) in
liveliness keys the same way. The announcer's own key chunk before it names it (common/keys.py):

    <prefix>/camera/<camera>/announce/<chunk>        CameraAnnouncement
    <prefix>/detector/workers/<worker>/<chunk>       WorkerAnnouncement

An announcement that changes (a camera's size learnt from its first frame, a worker's measured
capacity) is a new token: :class:`Announcer` declares the new one before it withdraws the old,
so a listener never sees the announcer gone. :class:`Announced` is the listener's side: every
live announcement on a key expression by name, the newest of a name when two overlap, garbage
(a key that does not decode, or whose name differs from the message's) reported and ignored.
:func:`announced_now` (:func:`cameras_now`, :func:`workers_now`) is one look at the tokens alive
now, for a reader that does not stay (``zstack pool``, a benchmark, a worker's catch-up): read
and checked by the same :func:`read_token`, garbage reported the same way.

Every reader of announcements goes through these. The one exception is the recorder, which
records each camera announcement's chunk raw as it comes, with its arrival time, and decodes it
later on its writer thread, as it does every payload (services/recorder/service.py).
"""

from __future__ import annotations

import base64
import binascii
import threading
from collections.abc import Callable
from typing import Generic, Protocol, TypeAlias, TypeVar

from common.bus import Bus, Declared
from common.errors import DecodeError
from common.keys import Keys
from common.messages import CameraAnnouncement, WorkerAnnouncement

#: The longest announcement chunk read: a real one is under 300 characters.
MAX_CHUNK_CHARS = 1024


class _Announcement(Protocol):
    def encode(self) -> bytes: ...


_A = TypeVar("_A")

#: Splits a token's key into (announcer name, chunk); None for a key that is no announcement
#: (common/keys.py's ``*_parts``).
Parse: TypeAlias = Callable[[str], tuple[str, str] | None]


def to_chunk(message: _Announcement) -> str:
    """``message`` as one key chunk (see the module's docstring)."""
    return base64.urlsafe_b64encode(message.encode()).rstrip(b"=").decode("ascii")


def from_chunk(decode: Callable[[bytes], _A], chunk: str) -> _A:
    """The message of a key chunk made by :func:`to_chunk`, decoded by ``decode`` (a
    message type's ``decode``); DecodeError for anything else."""
    if len(chunk) > MAX_CHUNK_CHARS:
        raise DecodeError(f"an announcement of {len(chunk)} characters is over {MAX_CHUNK_CHARS}")
    try:
        raw = base64.urlsafe_b64decode(chunk + "=" * (-len(chunk) % 4))
    except (binascii.Error, ValueError) as exc:
        raise DecodeError(f"an announcement that is not base64url: {exc}") from exc
    return decode(raw)


def read_token(
    key: str, parse: Parse, decode: Callable[[bytes], _A], name_of: Callable[[_A], str]
) -> tuple[str, _A] | None:
    """(announcer name, announcement) of a token's ``key``; None for a key that is no
    announcement (``parse`` gives None); DecodeError for one that does not decode, or whose
    message names another announcer than its key does (a camera's source cannot announce
    another camera under its own key)."""
    parts = parse(key)
    if parts is None:
        return None
    name, chunk = parts
    message = from_chunk(decode, chunk)
    if name_of(message) != name:
        raise DecodeError(
            f"an announcement under the name {name!r} names itself {name_of(message)!r}"
        )
    return name, message


def announced_now(
    bus: Bus,
    expr: str,
    parse: Parse,
    decode: Callable[[bytes], _A],
    name_of: Callable[[_A], str],
    timeout_s: float,
    on_bad: Callable[[str, Exception], None] | None = None,
) -> dict[str, list[_A]]:
    """One look at the announcements alive on ``expr`` now (the bus asked for at most
    ``timeout_s``): every live announcement of each name, as :meth:`Announced.every` gives
    them, each read by :func:`read_token`; ``on_bad(key, error)`` for one that does not decode,
    which is left out. A look has no order of arrival, so no ``conflict`` rule applies: two
    announcements of one name are both there, for the reader to choose (the highest ``seq``,
    the lowest capacity: common/pool_rule.py's ``one_worker``)."""
    out: dict[str, list[_A]] = {}
    for key in bus.live_tokens(expr, timeout_s):
        try:
            read = read_token(key, parse, decode, name_of)
        except DecodeError as exc:
            if on_bad is not None:
                on_bad(key, exc)
            continue
        if read is not None:
            out.setdefault(read[0], []).append(read[1])
    return out


class Announcer(Generic[_A]):
    """One announcer's current token: :meth:`update` declares the token of a new announcement,
    then withdraws the previous one (never a moment with none); :meth:`close` withdraws it.
    ``key_of(chunk)`` is the announcer's key for a chunk (common/keys.py). Thread-safe."""

    def __init__(self, bus: Bus, key_of: Callable[[str], str]) -> None:
        self._bus = bus
        self._key_of = key_of
        self._lock = threading.Lock()
        self._token: Declared | None = None
        self._key = ""
        self.current: _A | None = None

    def update(self, message: _A) -> bool:
        """Announce ``message`` (instead of the previous one); False when it is the one
        already announced (nothing declared)."""
        key = self._key_of(to_chunk(message))  # type: ignore[arg-type]
        with self._lock:
            if key == self._key and self._token is not None:
                return False
            token = self._bus.declare_token(key)
            old, self._token, self._key, self.current = self._token, token, key, message
        if old is not None:
            old.undeclare()
        return True

    def close(self) -> None:
        with self._lock:
            token, self._token, self._key, self.current = self._token, None, "", None
        if token is not None:
            token.undeclare()


class Announced(Generic[_A]):
    """Every announcement alive on ``expr``, by announcer name: the listener's side.

    ``parse(key)`` splits a token's key into (name, chunk), or None for a key that is not an
    announcement; ``decode`` is the message type's decode; ``name_of`` reads the name the
    message gives itself, which must equal the key's (a camera's source cannot announce
    another camera under its own key). ``on_change()`` is called (on the bus's thread, no lock
    held) whenever the set of current announcements changed; ``on_bad(key, error)`` for an
    announcement that does not decode, which is then ignored. While two tokens of one name are
    alive (a re-announcement's overlap), the one that came last is current, unless
    ``conflict(current, new)`` gives a reason to refuse the new one (a second announcer of a
    camera with another mounting, issue 39): it is then refused, reported to ``on_bad``
    (:class:`ConflictError`), and held aside while the current one lives; once every token
    believed of the name has gone, the oldest refused one still alive is believed instead (so
    a source that changes its own camera's mounting, declaring the new token before it
    withdraws the old, is believed after a moment's warning). Thread-safe.
    """

    def __init__(
        self,
        bus: Bus,
        expr: str,
        parse: Parse,
        decode: Callable[[bytes], _A],
        name_of: Callable[[_A], str],
        *,
        on_change: Callable[[], None] | None = None,
        on_bad: Callable[[str, Exception], None] | None = None,
        conflict: Callable[[_A, _A], str | None] | None = None,
    ) -> None:
        self._parse, self._decode, self._name_of = parse, decode, name_of
        self._conflict = conflict
        # Per name, the live tokens refused for a conflict, in the order they came.
        self._refused: dict[str, dict[str, _A]] = {}
        self._on_change = on_change
        self._on_bad = on_bad
        self._lock = threading.Lock()
        # Per name, its live tokens in the order they came: key -> announcement.
        self._live: dict[str, dict[str, _A]] = {}
        self._watch = bus.watch_tokens(expr, self._on_token)

    def current(self) -> dict[str, _A]:
        """The current announcement of every announcer alive, by name."""
        with self._lock:
            return {name: list(keys.values())[-1] for name, keys in self._live.items() if keys}

    def every(self) -> dict[str, list[_A]]:
        """Every live announcement believed of each name (oldest first): more than one while
        two tokens of a name are alive (a re-announcement's overlap, or two announcers of
        one name: common/pool_rule.py's ``one_worker`` says how the pool counts those)."""
        with self._lock:
            return {name: list(keys.values()) for name, keys in self._live.items() if keys}

    def get(self, name: str) -> _A | None:
        with self._lock:
            keys = self._live.get(name)
            return list(keys.values())[-1] if keys else None

    def _on_token(self, key: str, alive: bool) -> None:
        if not alive:
            parts = self._parse(key)
            if parts is None:
                return
            name = parts[0]
            with self._lock:
                self._refused.get(name, {}).pop(key, None)
                keys = self._live.get(name, {})
                changed = keys.pop(key, None) is not None
                if not keys:
                    self._live.pop(name, None)
                    changed = self._promote(name) or changed
            if changed and self._on_change is not None:
                self._on_change()
            return
        try:
            read = read_token(key, self._parse, self._decode, self._name_of)
        except DecodeError as exc:
            if self._on_bad is not None:
                self._on_bad(key, exc)
            return
        if read is None:
            return
        name, message = read
        with self._lock:
            why = self._refusal(name, message)
            if why is None:
                self._live.setdefault(name, {})[key] = message
            else:
                self._refused.setdefault(name, {})[key] = message
        if why is not None:
            if self._on_bad is not None:
                self._on_bad(
                    key, ConflictError(f"a second announcement of {name!r} refused: {why}")
                )
            return
        if self._on_change is not None:
            self._on_change()

    def _refusal(self, name: str, message: _A) -> str | None:
        """Why ``message`` may not replace the current announcement of ``name`` (the caller
        holds the lock); None when it may."""
        keys = self._live.get(name)
        if not keys or self._conflict is None:
            return None
        return self._conflict(list(keys.values())[-1], message)

    def _promote(self, name: str) -> bool:
        """Every believed token of ``name`` has gone: believe the refused ones still alive,
        oldest first, as far as they agree with each other (the caller holds the lock)."""
        refused = self._refused.pop(name, {})
        for key, message in refused.items():
            if self._refusal(name, message) is None:
                self._live.setdefault(name, {})[key] = message
            else:
                self._refused.setdefault(name, {})[key] = message
        return name in self._live

    def close(self) -> None:
        self._watch.undeclare()


class ConflictError(DecodeError):
    """An announcement refused for contradicting the one believed of its name."""


def camera_conflict(current: CameraAnnouncement, new: CameraAnnouncement) -> str | None:
    """Why ``new`` may not replace the ``current`` announcement of one camera: another
    mounting (where it looks, its field of view, where it stands), which would turn every
    bearing the controller computes from it; None when they agree (a size or a frame id
    learnt from the first frame, a rate, depth)."""
    fields = ("mount_yaw_deg", "hfov_deg", "mount_x_m", "mount_y_m", "mount_height_m")
    differ = [f for f in fields if getattr(current, f) != getattr(new, f)]
    if not differ:
        return None
    said = ", ".join(f"{f} {getattr(current, f):g} -> {getattr(new, f):g}" for f in differ)
    return f"another mounting ({said}) while the first announcement lives"


def _camera_name(a: CameraAnnouncement) -> str:
    return a.camera


def _worker_name(a: WorkerAnnouncement) -> str:
    return a.worker


def announced_cameras(
    bus: Bus,
    keys: Keys,
    on_change: Callable[[], None] | None = None,
    on_bad: Callable[[str, Exception], None] | None = None,
) -> Announced[CameraAnnouncement]:
    """Every camera announced under ``keys``' prefix (the listener's side)."""
    return Announced(
        bus,
        keys.all_camera_announcements(),
        keys.camera_announcement_parts,
        CameraAnnouncement.decode,
        _camera_name,
        on_change=on_change,
        on_bad=on_bad,
        conflict=camera_conflict,
    )


def announced_workers(
    bus: Bus,
    keys: Keys,
    on_change: Callable[[], None] | None = None,
    on_bad: Callable[[str, Exception], None] | None = None,
) -> Announced[WorkerAnnouncement]:
    """Every pool worker announced under ``keys``' prefix (the pool's)."""
    return Announced(
        bus,
        keys.all_worker_announcements(),
        keys.worker_announcement_parts,
        WorkerAnnouncement.decode,
        _worker_name,
        on_change=on_change,
        on_bad=on_bad,
    )


def cameras_now(
    bus: Bus,
    keys: Keys,
    timeout_s: float,
    on_bad: Callable[[str, Exception], None] | None = None,
) -> dict[str, list[CameraAnnouncement]]:
    """One look at the cameras announced under ``keys``' prefix now (:func:`announced_now`)."""
    return announced_now(
        bus,
        keys.all_camera_announcements(),
        keys.camera_announcement_parts,
        CameraAnnouncement.decode,
        _camera_name,
        timeout_s,
        on_bad,
    )


def workers_now(
    bus: Bus,
    keys: Keys,
    timeout_s: float,
    on_bad: Callable[[str, Exception], None] | None = None,
) -> dict[str, list[WorkerAnnouncement]]:
    """One look at the pool workers announced under ``keys``' prefix now
    (:func:`announced_now`)."""
    return announced_now(
        bus,
        keys.all_worker_announcements(),
        keys.worker_announcement_parts,
        WorkerAnnouncement.decode,
        _worker_name,
        timeout_s,
        on_bad,
    )
