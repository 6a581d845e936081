"""How a child process of ours is started and stopped: the one place a long-running child is
spawned (the supervisor's services in deploy/processes.py, a stack started from outside in
tools/launch.py, a benchmark's recorder).

Each child gets a process group of its own: a Ctrl-C at the terminal reaches only us, and we
stop our children in order, one signal each, instead of all of them dying at once. It stays in
our session, though: with the kernel's autogroup scheduling the CPU is shared between sessions
first, and a service's priority (the recorder's nice, SCHED_IDLE) ranks it against the detector
only within one (common/priority.py). Its stdin is /dev/null (no child reads the terminal) and
its Python output unbuffered, so that its lines reach the log as they are printed.

A stop is a signal (SIGINT, as Ctrl-C would send), a wait with a deadline, then SIGKILL.
"""

from __future__ import annotations

import os
import signal
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import IO

from common.lifecycle import STOP_SIGNALS

#: Where a child's stdout or stderr goes: inherited (None), a file, a descriptor, or one of
#: subprocess's PIPE, STDOUT and DEVNULL.
Output = IO[bytes] | int | None


def spawn(
    argv: Sequence[str],
    *,
    env: Mapping[str, str] | None = None,
    cwd: str | Path | None = None,
    stdout: Output = None,
    stderr: Output = None,
    stop_signals_blocked: bool = False,
    new_session: bool = False,
) -> subprocess.Popen[bytes]:
    """Start ``argv`` in a process group of its own, in our session (with ``new_session``,
    in a session of its own, as from another terminal: its own share of the CPU under the
    kernel's autogroup scheduling, common/priority.py).

    ``env`` is the child's whole environment (ours when None), with ``PYTHONUNBUFFERED=1``.
    With ``stop_signals_blocked`` it starts with SIGINT and SIGTERM blocked (a child inherits
    the signal mask): a stop sent while its interpreter starts stays pending until the child
    unblocks them, ready to take it quietly (services/__init__.py does, under the supervisor).
    Only for a child that unblocks them itself: to any other, a stop would never arrive.
    """
    base = os.environ if env is None else env
    blocked = (
        signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS) if stop_signals_blocked else None
    )
    try:
        return subprocess.Popen(
            list(argv),
            cwd=cwd,
            env={**base, "PYTHONUNBUFFERED": "1"},
            process_group=None if new_session else 0,
            start_new_session=new_session,
            stdin=subprocess.DEVNULL,
            stdout=stdout,
            stderr=stderr,
        )
    finally:
        if blocked is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


def ask_to_stop(proc: subprocess.Popen[bytes], sig: int = signal.SIGINT) -> None:
    """Send ``sig`` to ``proc`` unless it has already exited."""
    if proc.poll() is None:
        proc.send_signal(sig)


def wait_or_kill(
    proc: subprocess.Popen[bytes], timeout_s: float, *, whole_group: bool = False
) -> bool:
    """Wait up to ``timeout_s`` for ``proc`` to exit; True when it did (its code is then
    ``proc.returncode``). Otherwise SIGKILL it, or its whole process group with
    ``whole_group`` (what it started goes too), reap it and return False."""
    try:
        proc.wait(timeout=max(0.0, timeout_s))
    except subprocess.TimeoutExpired:
        if whole_group:
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            proc.kill()
        proc.wait()
        return False
    return True


def stop_child(
    proc: subprocess.Popen[bytes],
    timeout_s: float,
    sig: int = signal.SIGINT,
    *,
    whole_group: bool = False,
) -> bool:
    """Ask ``proc`` to stop with ``sig``, wait ``timeout_s``, then kill it (:func:`wait_or_kill`).
    True when it exited in time."""
    ask_to_stop(proc, sig)
    return wait_or_kill(proc, timeout_s, whole_group=whole_group)
