"""python -m services.recorder [serve|record|play] ...

serve (the default) records the stack to recorder.output_dir for as long as it runs (list
"recorder" first in [supervisor].services); record does the same from the command line until
Ctrl-C or --duration; play publishes a recording's frames, depth images and scans onto the
stack as if live.
Comparing runs is ``python -m tools.compare``; the recorder's benchmark is
``python -m tools.benchmarks recorder``.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from common.cli import Command, add_config, replay_rate, service_main
from common.errors import ConfigError
from common.lifecycle import print_progress, run_main, setup_logging, stop_event
from stack.config_file import load_config


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    log = setup_logging("recorder")
    from services.recorder import service

    code = service.record(config, service.default_path(config), stop, log.info)
    # The file is finished and the session closed: nothing is left to do. The interpreter's
    # own teardown (its modules, the ROS type store, Zenoh's runtime) took over a second more
    # at nice 10 on cores kept busy, past the supervisor's stop timeout: the recorder was
    # killed after finishing its file. Exit at once instead.
    logging.shutdown()  # every handler flushed, a file's too
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _record_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    p.add_argument("--out", type=Path, help="the MCAP file (default: recorder.output_dir/...)")
    p.add_argument("--duration", type=float, default=0.0, help="seconds (default: until Ctrl-C)")


def record(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    setup_logging("recorder", "WARNING")
    from services.recorder import service

    if args.duration < 0:
        raise ConfigError(f"--duration must be >= 0, got {args.duration}")
    path = args.out or service.default_path(config)
    return service.record(config, path, stop, print_progress, args.duration, require_stack=True)


def _play_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=Path, help="an MCAP recording, ours or a ROS 2 bag's")
    add_config(p)
    p.add_argument("--rate", type=replay_rate, default=1.0, help="speed: 2 plays twice as fast")
    p.add_argument("--loop", action="store_true", help="play again from the start at the end")
    p.add_argument("--topics", nargs="+",
                   help="only these MCAP topics (default: every frame, depth image and scan "
                        "topic; a depth image's camera_info goes with it)")  # fmt: skip
    p.add_argument("--wait", action=argparse.BooleanOptionalAction, default=True,
                   help="wait for a detector to be ready before the first frame, up to "
                        "recorder.detector_wait_s (--no-wait plays at once)")  # fmt: skip


def play(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    setup_logging("play", "WARNING")
    from services.recorder import service

    played = service.play(config, args.file, stop, print_progress, rate=args.rate, loop=args.loop,
                         topics=args.topics, wait=args.wait)  # fmt: skip
    return 0 if played.frames + played.depths + played.scans else 1


COMMANDS = [
    Command("serve", "record the stack while it runs (the service)", add_config, serve),
    Command("record", "record the stack to an MCAP file", _record_arguments, record),
    Command("play", "publish a recording's frames and scans onto the stack", _play_arguments,
            play),
]  # fmt: skip
DESCRIPTION = (__doc__ or "").split("\n\n", 1)[-1]


def main(argv: Sequence[str] | None = None) -> int:
    return service_main("python -m services.recorder", DESCRIPTION, COMMANDS, argv)


if __name__ == "__main__":
    run_main(main, "recorder")
