"""Process plumbing shared by every entry point: logging, stop signals, one-line errors."""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
from collections.abc import Callable

from common.errors import StackError


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
    """Run ``main`` and exit with its code; a StackError becomes one line on stderr, exit 2."""
    try:
        code = main()
    except StackError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:
        code = 130
    raise SystemExit(code)
