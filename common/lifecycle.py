"""Process plumbing shared by every entry point: logging, stop signals, one-line errors."""

from __future__ import annotations

import ctypes
import faulthandler
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable
from typing import Self

from common.clock import mono_s
from common.errors import BackendUnavailable, ConfigError, ModelError, StackError

# Exit codes shared by every entry point. 2..4 mean "restarting will not help".
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_CONFIG = 2
EXIT_MODEL = 3
EXIT_BACKEND = 4
EXIT_INTERRUPTED = 130
PERMANENT_FAILURES = frozenset({EXIT_CONFIG, EXIT_MODEL, EXIT_BACKEND})
#: What asks a process to stop: Ctrl-C, and the supervisor's or the system's polite kill.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Closing:
    """``with thing:`` closes the thing at the end, however the block ends."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def exit_code(error: StackError) -> int:
    """The exit code for ``error``: 2 config, 3 model, 4 backend, 1 anything else."""
    if isinstance(error, ConfigError):
        return EXIT_CONFIG
    if isinstance(error, ModelError):
        return EXIT_MODEL
    if isinstance(error, BackendUnavailable):
        return EXIT_BACKEND
    return EXIT_FAILED


#: Where a long command reports how it is getting on (a model fetch, an evaluation, a report).
Progress = Callable[[str], None]


def print_progress(line: str) -> None:
    """A progress line on stderr, at once: stdout is kept for a command's result."""
    print(line, file=sys.stderr, flush=True)


def setup_logging(service: str, level: str | None = None) -> logging.Logger:
    """Log to stderr as ``time service level message``; level from STACK_LOG_LEVEL (INFO)."""
    logging.basicConfig(
        level=(level or os.environ.get("STACK_LOG_LEVEL", "INFO")).upper(),
        format=f"%(asctime)s {service} %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    return logging.getLogger(service)


# Set by the supervisor in each service's environment: the PID the service must not outlive.
SUPERVISOR_PID_ENV = "STACK_SUPERVISOR_PID"
ORPHAN_POLL_S = 0.1  # how often a service checks that its supervisor is still its parent
ORPHAN_GRACE_S = 1.0  # time to stop cleanly (the controller: command zero) before a hard exit
#: A service still running this long after it was asked to stop writes every thread's stack
#: to stderr (the supervisor's log), once: what holds a stop up is then on record, before the
#: supervisor's stop_timeout_s (5 s) kills it.
STOP_STACKS_AFTER_S = 3.0
SIGNAL_POLL_S = 0.2  # the longest a StopEvent wait holds off a signal that hit another thread


class StopEvent(threading.Event):
    """An Event whose ``wait`` wakes at least every ``SIGNAL_POLL_S``.

    Python runs a signal handler only when the main thread next executes Python code. A SIGINT
    that the kernel hands to one of Zenoh's threads (any thread may take a process's signal)
    leaves the main thread asleep in a plain ``Event.wait(timeout)`` for the whole timeout:
    the metrics service, waiting 5 s between reports, was seen to overrun the supervisor's stop
    timeout that way and be killed. Waiting in short slices bounds that delay.
    """

    def __init__(self) -> None:
        super().__init__()
        # Set by the signal handler itself (a plain assignment takes no lock): the stop counts
        # from the handler's run, not from the relay thread's, which a loaded machine may
        # schedule late (a worker resumed by the watchdog's SIGCONT rejoined the pool in
        # that gap, issue 39).
        self.asked = False

    def is_set(self) -> bool:
        return self.asked or super().is_set()

    def wait(self, timeout: float | None = None) -> bool:
        deadline = None if timeout is None else mono_s() + timeout
        while True:
            if self.asked:
                return True
            left = SIGNAL_POLL_S if deadline is None else deadline - mono_s()
            if left <= 0:
                return self.is_set()
            if super().wait(min(left, SIGNAL_POLL_S)):
                return True


_PR_SET_PDEATHSIG = 1


def stop_event() -> StopEvent:
    """An event set on SIGINT or SIGTERM, so loops end cleanly and the process exits 0.

    A service started by the supervisor also stops when the supervisor dies, however it dies:
    the kernel sends it SIGTERM (Linux), and a watcher thread sees that its parent changed
    (anywhere). Either way it then has ``ORPHAN_GRACE_S`` to stop cleanly (the controller
    commands zero) before the kernel ends it: an alarm with its default action, which needs no
    Python code to run, so that a shutdown stuck in a call that holds the interpreter still
    ends on time.
    """
    event = StopEvent()
    supervisor = os.environ.get(SUPERVISOR_PID_ENV, "")
    supervisor_pid = int(supervisor) if supervisor.isdigit() else None
    # The handler must not set the event itself: a handler runs in the main thread between
    # two bytecodes, possibly while that thread holds the event's lock (inside its own
    # ``stop.wait()``, which every loop calls ten times a second), and Event.set() would then
    # wait for that lock forever: a stop lost. (A supervisor was seen hung so at the end of a
    # scenario, its services left running until killed.) So the handler only writes a byte to
    # a pipe, which takes no lock, and a thread of its own reads it and sets the event.
    wake_read, wake_write = os.pipe()
    threading.Thread(
        target=_relay_stops,
        args=(wake_read, event, supervisor_pid is not None),  # stacks: a supervised service's
        name="stop-relay",
        daemon=True,
    ).start()

    def _handler(signum: int, _frame: object) -> None:
        if supervisor_pid is not None and os.getppid() != supervisor_pid:
            _leave_soon(supervisor_pid)
        event.asked = True
        os.write(wake_write, b"\0")

    signal.signal(signal.SIGINT, _handler)
    signal.signal(signal.SIGTERM, _handler)
    if supervisor_pid is not None:
        _die_with(supervisor_pid, event)
    return event


def _relay_stops(wake_read: int, event: threading.Event, stacks: bool = False) -> None:
    """Set ``event`` for each byte a stop signal's handler writes (see :func:`stop_event`);
    draining every byte, so that no number of signals can fill the pipe."""
    armed = not stacks
    while os.read(wake_read, 1):
        if not armed:  # the first stop; a process that exits in time never writes them
            faulthandler.dump_traceback_later(STOP_STACKS_AFTER_S, exit=False)
            armed = True
        event.set()


def _leave_soon(supervisor_pid: int) -> None:
    """Arm the kernel's alarm: whatever this process is doing, it ends in ORPHAN_GRACE_S."""
    if signal.getitimer(signal.ITIMER_REAL)[0] > 0:
        return  # armed already (by the signal handler or the watcher, whichever came first)
    signal.setitimer(signal.ITIMER_REAL, ORPHAN_GRACE_S)
    logging.getLogger().error("the supervisor (pid %d) is gone: stopping", supervisor_pid)


def _die_with(supervisor_pid: int, event: threading.Event) -> None:
    signal.signal(signal.SIGALRM, signal.SIG_DFL)  # an alarm terminates: see _leave_soon
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)

    def watch() -> None:
        # Also covers a supervisor that died before prctl took effect, and systems without
        # it. It keeps watching after a stop was asked for: the stop may have come first.
        tick = threading.Event()  # never set: its wait() is the poll interval
        while os.getppid() == supervisor_pid:
            tick.wait(ORPHAN_POLL_S)
        _leave_soon(supervisor_pid)
        event.set()

    threading.Thread(target=watch, name="supervisor-watch", daemon=True).start()


def _interrupt(_signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def run_main(main: Callable[[], int], prog: str, *, skip_finalizing: bool = False) -> None:
    """Run ``main`` and exit with its code; a StackError becomes one line on stderr.

    SIGTERM is taken as Ctrl-C (KeyboardInterrupt, exit 130) unless something already handles
    it: Python's default would end a command mid-step without running its cleanup (a
    half-converted model, a temporary folder left in models/). A service's own handler
    (stop_event) replaces this one when the service starts.

    ``skip_finalizing``: once ``main`` has returned (it closes what it opened: its session, its
    model), flush the logs and standard streams and end the process at once, without the
    interpreter's finalization. The detector, its Python done, was seen to hang there for
    more than the supervisor's stop_timeout_s on a loaded machine (its stacks, dumped after
    3 s: one thread, no Python frame: native runtimes' teardown) and be killed (issue 39);
    the controller too, and later the camera (OpenCV), in CI runs beside CPU burners.
    """
    if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _interrupt)
    try:
        code = main()
        sys.stdout.flush()
    except StackError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        code = exit_code(exc)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader went away (`... --json | head`): not an error of ours. Point stdout at
        # /dev/null so that the interpreter's own final flush cannot fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = EXIT_OK
    if skip_finalizing:
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    raise SystemExit(code)
