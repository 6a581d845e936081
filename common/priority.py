"""A process's share of the CPU: lowering it, so that it takes only the time perception leaves
over; and giving a short command a share of its own (:func:`own_session`).

Two ways (Linux): ``nice`` (a smaller share of the CPU, still taken in the middle of an
inference) and ``SCHED_IDLE`` (runs only on a core that would otherwise be idle, and gives it up
as soon as anything else wants it). Either is set before any thread starts (Zenoh's included),
as each thread inherits it.

Both rank a process only against those in its own **session**: with the kernel's autogroup
scheduling (``/proc/sys/kernel/sched_autogroup_enabled``, on by default where it is built in),
the CPU is first shared fairly between sessions. That is why the supervisor starts every
service in a process group of its own but in the supervisor's session (common/spawn.py): a
recorder in a session of its own, however niced, took as much CPU in the middle of an inference
as it wanted, and slowed the detector by 5 to 10 % (docs/benchmarks.md).
"""

from __future__ import annotations

import os
import signal


def lower_priority(nice: int, idle: bool) -> str:
    """Raise this process's nice value by ``nice``, then, when ``idle``, put it in
    ``SCHED_IDLE``; returns what was done, for the log."""
    done = []
    if nice > 0:
        done.append(f"nice {os.nice(nice)}")
    if idle:
        try:
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
            done.append("SCHED_IDLE (only cores perception leaves idle)")
        except (AttributeError, OSError) as exc:  # not Linux, or refused: nice alone
            done.append(f"not SCHED_IDLE ({exc})")
    return ", ".join(done) or "unchanged"


def process_threads(pid: int | None = None) -> list[int]:
    """Every thread of process ``pid`` (this one by default; native ids; Linux), those a
    library started included (Zenoh's runtime, which inherits the idle class); elsewhere just
    the calling thread (this process) or none (another)."""
    try:
        return [int(tid) for tid in os.listdir(f"/proc/{'self' if pid is None else pid}/task")]
    except OSError:
        return [0] if pid is None else []


def leave_idle(*threads: int) -> str:
    """Put ``threads`` (native thread ids; 0 is the calling thread) back in the normal class,
    keeping their nice value; returns what was done, for the log.

    For a stop: an idle-class thread gets no CPU at all while every core is busy, so a
    recorder told to stop on a saturated machine could not finish its file before the
    supervisor's stop timeout killed it (a file of its header alone, seen with both cores
    busy). Finishing the file is a moment's work at nice 10."""
    failed = []
    for tid in threads:
        try:
            os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
        except (AttributeError, OSError) as exc:  # not Linux, refused, or the thread is gone
            failed.append(f"{tid}: {exc}")
    if failed:  # the others are back all the same
        return f"still SCHED_IDLE ({'; '.join(failed)[:200]})"
    return "back in the normal class to finish"


#: What the parent passes on to a command moved to a session of its own (:func:`own_session`):
#: the terminal's Ctrl-C and the stops a caller sends.
PASSED_ON = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def own_session() -> int | None:
    """Go on in a session of its own, so that the kernel's autogroup scheduling gives this
    command a share of the CPU of its own instead of a slice of its caller's session (the e-stop
    command, started beside a busy stack or CPU burners in one session, waited behind all of
    their threads: docs/benchmarks.md, "E-stop: from the command to the first zero").

    Forks: the child returns None and goes on, leader of a new session; the parent stays in
    the caller's session (and its terminal's foreground, so that Ctrl-C still reaches it),
    passes on SIGINT, SIGTERM and SIGHUP, and returns the child's exit code (128 + the signal
    that ended it). None at once, in the same process, where there is nothing to gain or no
    way: already a session leader, or no fork (not POSIX)."""
    if not hasattr(os, "fork") or os.getsid(0) == os.getpid():
        return None
    # Held from before the fork until the parent passes them on: one that came in between
    # would end the parent and leave the child's command unwatched.
    held = signal.pthread_sigmask(signal.SIG_BLOCK, PASSED_ON)
    child = os.fork()
    if child == 0:
        os.setsid()
        signal.pthread_sigmask(signal.SIG_SETMASK, held)  # one held meanwhile is acted on now
        return None
    for sig in PASSED_ON:
        signal.signal(sig, lambda s, _frame: _pass_on(child, s))
    signal.pthread_sigmask(signal.SIG_SETMASK, held)  # one held meanwhile is passed on now
    _, status = os.waitpid(child, 0)  # a signal handled meanwhile does not end the wait
    code = os.waitstatus_to_exitcode(status)
    return code if code >= 0 else 128 - code


def _pass_on(child: int, sig: int) -> None:
    try:
        os.kill(child, sig)
    except ProcessLookupError:
        return  # it has just ended: its exit status is what the parent waits for
