"""The latched e-stop, kept in a file so that no restart can forget it.

Rules:
- An engage always latches, whatever its stamp; so does garbage on the e-stop key (fail safe).
- Only a release clears it, and only a release that is fresh (captured within the release's
  maximum age, not from the future) and stamped after the engagement it clears: an old release
  played back cannot undo a newer stop.
- Every change is written to disk (atomically, fsynced) before the controller acts on it, and
  the controller reads the file before it commands anything. A missing file means no e-stop was
  ever engaged for this stack; an unreadable one counts as engaged.
"""

from __future__ import annotations

import json
import threading
from dataclasses import asdict, dataclass
from pathlib import Path

from common.files import atomic_write_bytes


@dataclass(frozen=True, slots=True)
class EStopState:
    """``since_ns``: wall stamp of the message that set this state; ``by``: its source."""

    engaged: bool
    since_ns: int = 0
    by: str = ""
    reason: str = ""


def load(path: Path) -> tuple[EStopState, str]:
    """The persisted state and a note on how it was found (for the log)."""
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
        state = EStopState(
            engaged=bool(raw["engaged"]),
            since_ns=int(raw["since_ns"]),
            by=str(raw["by"]),
            reason=str(raw["reason"]),
        )
    except FileNotFoundError:
        return EStopState(False), f"no e-stop state at {path}: none was ever engaged"
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return (
            EStopState(True, 0, "controller", f"unreadable state file {path}"),
            f"e-stop state {path} is unreadable ({exc}): latched until released",
        )
    return state, f"e-stop state from {path}"


def save(path: Path, state: EStopState) -> None:
    """Write ``state`` so that a crash or a power cut at any instant leaves the old or the new
    file whole."""
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, json.dumps(asdict(state)).encode(), durable=True)


class EStopLatch:
    """The e-stop as the controller holds it: in memory for the loop, on disk for restarts."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lock = threading.Lock()
        self.state, self.note = load(path)

    @property
    def engaged(self) -> bool:
        return self.state.engaged

    def engage(self, stamp_ns: int, by: str, reason: str) -> None:
        """Latch (in memory first, so that a disk error cannot delay the stop), then persist."""
        with self._lock:
            self.state = EStopState(True, max(stamp_ns, self.state.since_ns), by, reason)
            save(self.path, self.state)

    def release(self, stamp_ns: int, by: str) -> bool:
        """Clear the latch if ``stamp_ns`` is after the engagement; False when refused."""
        with self._lock:
            if self.state.engaged and stamp_ns <= self.state.since_ns:
                return False
            released = EStopState(False, stamp_ns, by, "released")
            save(self.path, released)  # persisted before the robot may move again
            self.state = released
            return True
