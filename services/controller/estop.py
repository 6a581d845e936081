"""The latched e-stop, kept in a file so that no restart can forget it.

Rules:
- An engage always latches, whatever its stamp; so does garbage on the e-stop key (fail safe).
  Its stamp is bounded by the receiver's clock: an engage stamped in the future latches as of
  now, so that a stamp a century ahead cannot make every later release look older.
- Only a release clears it, and only a release that is fresh (captured within the release's
  maximum age, not from the future) and stamped after the engagement it clears: an old release
  played back cannot undo a newer stop.
- Every change is written to disk (atomically, fsynced) before the controller acts on it, and
  the controller reads the file before it commands anything. A missing file means no e-stop was
  ever engaged for this stack; anything but a well-formed state (unreadable, malformed, a stamp
  out of range) counts as engaged, and never as an error that stops the controller.
- A latch that cannot be saved is no weaker in memory, and is said so: ``saved`` is False
  and the status says why. At start-up the controller proves it can save (it writes the state
  it read back); if it cannot, it starts engaged and stays so until it can: a restart must
  never turn a stop that could not be saved into "none was ever engaged". A release that
  cannot be saved is refused.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from common.files import atomic_write_bytes

#: The largest stamp a state may hold: int64 nanoseconds (year 2262), as every stamp on the wire.
MAX_STAMP_NS = 2**63 - 1
#: How much of a reason is kept and shown (the e-stop CLI's --reason is free text).
MAX_REASON_CHARS = 200


@dataclass(frozen=True, slots=True)
class EStopState:
    """``since_ns``: wall stamp of the message that set this state; ``by``: its source."""

    engaged: bool
    since_ns: int = 0
    by: str = ""
    reason: str = ""


def parse(raw: Any) -> EStopState:
    """A state from the file's JSON; ValueError for anything but a well-formed one."""
    if not isinstance(raw, dict) or set(raw) != {"engaged", "since_ns", "by", "reason"}:
        raise ValueError("not an object with exactly engaged, since_ns, by and reason")
    engaged, since, by, reason = raw["engaged"], raw["since_ns"], raw["by"], raw["reason"]
    if not isinstance(engaged, bool):
        raise ValueError(f"engaged must be true or false, got {engaged!r:.40}")
    if isinstance(since, bool) or not isinstance(since, int) or not 0 <= since <= MAX_STAMP_NS:
        raise ValueError(f"since_ns must be a stamp in 0..2^63-1 ns, got {since!r:.40}")
    if not isinstance(by, str) or not isinstance(reason, str):
        raise ValueError("by and reason must be text")
    return EStopState(engaged, since, by[:MAX_REASON_CHARS], reason[:MAX_REASON_CHARS])


def load(path: Path) -> tuple[EStopState, str]:
    """The persisted state and a note on how it was found (for the log). Never raises."""
    try:
        state = parse(json.loads(path.read_text(encoding="utf-8")))
    except FileNotFoundError:
        return EStopState(False), f"no e-stop state at {path}: none was ever engaged"
    except (OSError, ValueError, RecursionError) as exc:
        # ValueError covers bad UTF-8, bad JSON and a malformed state; RecursionError, JSON
        # nested too deep. Whatever it is, it is not a released state: engaged.
        why = str(exc)[:MAX_REASON_CHARS]
        return (
            EStopState(True, 0, "controller", f"unreadable state file {path}"),
            f"e-stop state {path} is unreadable ({why}): latched until released",
        )
    return state, f"e-stop state from {path}"


def save(path: Path, state: EStopState) -> None:
    """Write ``state`` so that a crash or a power cut at any instant leaves the old or the new
    file whole. OSError when it cannot."""
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, json.dumps(asdict(state)).encode(), durable=True)


class EStopLatch:
    """The e-stop as the controller holds it: in memory for the loop, on disk for restarts.

    ``now_ns`` bounds stamps: the receiver's wall clock plus the tolerance allowed between
    hosts. ``saved`` says whether the state in memory is also the one on disk; ``save_error``
    why not.
    """

    def __init__(self, path: Path, latest_ns: int) -> None:
        self.path = path
        self._lock = threading.Lock()
        state, self.note = load(path)
        if state.since_ns > latest_ns:
            # Stamped ahead of this clock (an engage from a century ahead, kept by an older
            # controller): the latch dates from now, so a release can still clear it.
            state = EStopState(state.engaged, latest_ns, state.by, state.reason)
            self.note += f"; its stamp was in the future, bounded to {latest_ns}"
        self.state = state
        self.last_refusal = ""
        self.save_error = self._write(state)  # proves the state can be kept; if not, engaged
        self.saved = not self.save_error
        if not self.saved and not state.engaged:
            self.state = EStopState(True, latest_ns, "controller", "state cannot be saved")
            self.note += f"; cannot save it ({self.save_error}): latched until it can be"

    @property
    def engaged(self) -> bool:
        return self.state.engaged

    def _write(self, state: EStopState) -> str:
        """Save ``state``; "" when done, else why not."""
        try:
            save(self.path, state)
        except OSError as exc:
            return f"{exc.strerror or exc}: {self.path}"
        return ""

    def engage(
        self,
        stamp_ns: int,
        by: str,
        reason: str,
        latest_ns: int,
        latched: Callable[[], None] | None = None,
    ) -> bool:
        """Latch (in memory first, so that neither a slow disk nor a disk error can delay the
        stop), call ``latched`` (the controller sends its zero there), then persist; False
        when the latch could not be saved (it holds in memory all the same)."""
        with self._lock:  # the state read and the state written under one lock
            since = min(max(stamp_ns, self.state.since_ns), latest_ns)
            self.state = EStopState(True, since, by[:MAX_REASON_CHARS], reason[:MAX_REASON_CHARS])
            if latched is not None:
                latched()
            self.save_error = self._write(self.state)
            self.saved = not self.save_error
            return self.saved

    def release(self, stamp_ns: int, by: str) -> bool:
        """Clear the latch if ``stamp_ns`` is after the engagement and the release can be
        saved; False (and ``last_refusal`` says why) when refused."""
        with self._lock:
            if self.state.engaged and stamp_ns <= self.state.since_ns:
                self.last_refusal = "a release stamped before the stop it would clear"
                return False
            released = EStopState(False, stamp_ns, by[:MAX_REASON_CHARS], "released")
            error = self._write(released)  # persisted before the robot may move again
            if error:
                # The latch and what is on disk are as they were: only the release failed.
                self.last_refusal = f"the release cannot be saved ({error})"
                return False
            self.state, self.saved, self.save_error = released, True, ""
            self.last_refusal = ""
            return True

    def refuse(self, why: str) -> None:
        """Remember why a release was refused before it reached the latch (not fresh)."""
        self.last_refusal = why

    def describe(self) -> str:
        """The latch in one line, for the controller's status and the supervisor's line."""
        s = self.state
        if not s.engaged:
            return "released"
        text = f"e-stop by {s.by or '?'}" + (f": {s.reason}" if s.reason else "")
        if not self.saved:
            text += f"; NOT SAVED ({self.save_error}): stays engaged until it can be saved"
        if self.last_refusal:
            text += f"; last release refused: {self.last_refusal}"
        return text
