"""Process plumbing shared by every entry point: logging, stop signals, one-line errors."""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
from collections.abc import Callable

from common.errors import BackendUnavailable, ConfigError, ModelError, StackError

# Exit codes shared by every entry point. 2..4 mean "restarting will not help".
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_CONFIG = 2
EXIT_MODEL = 3
EXIT_BACKEND = 4
EXIT_INTERRUPTED = 130
PERMANENT_FAILURES = frozenset({EXIT_CONFIG, EXIT_MODEL, EXIT_BACKEND})


def exit_code(error: StackError) -> int:
    """The exit code for ``error``: 2 config, 3 model, 4 backend, 1 anything else."""
    if isinstance(error, ConfigError):
        return EXIT_CONFIG
    if isinstance(error, ModelError):
        return EXIT_MODEL
    if isinstance(error, BackendUnavailable):
        return EXIT_BACKEND
    return EXIT_FAILED


def setup_logging(service: str, level: str | None = None) -> logging.Logger:
    """Log to stderr as ``time service level message``; level from STACK_LOG_LEVEL (INFO)."""
    logging.basicConfig(
        level=(level or os.environ.get("STACK_LOG_LEVEL", "INFO")).upper(),
        format=f"%(asctime)s {service} %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    return logging.getLogger(service)


def stop_event() -> threading.Event:
    """An event set on SIGINT or SIGTERM, so loops end cleanly and the process exits 0."""
    event = threading.Event()

    def _handler(signum: int, _frame: object) -> None:
        event.set()

    signal.signal(signal.SIGINT, _handler)
    signal.signal(signal.SIGTERM, _handler)
    return event


def run_main(main: Callable[[], int], prog: str) -> None:
    """Run ``main`` and exit with its code; a StackError becomes one line on stderr."""
    try:
        code = main()
    except StackError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        code = exit_code(exc)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
    raise SystemExit(code)
