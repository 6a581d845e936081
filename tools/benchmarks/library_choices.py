"""Our hand-written tracker, settings loader and msgpack field walker against well-kept libraries.

Issue 21, point 6: where a library already does what we wrote by hand, measure and decide. One
run prints the figures of all three decisions side by side (docs/library-decisions.md has them
and the decisions). This module parses the command line and runs the sections; each comparison
is a module of its own beside it (what they share is in library_shared.py):

1. tracker (library_tracker.py; its frames from library_tracker_frames.py):
   perception/tracker.py against ByteTrack of the ``trackers`` package
   (Roboflow's clean-room re-implementation), by identity switches and fragmentations on the
   ``crossing`` and ``two_people`` scenarios, and time per frame. The frames are rendered
   offline with the simulator's own world and renderer, the real default detector runs once on
   each, and every tracker is fed the same boxes; see ``evaluate`` for the ground-truth rule.
2. settings loader (library_settings.py):
   stack/config_file.py + common/setting_checks.py against pydantic-settings
   and msgspec (``msgspec.toml`` + ``Meta`` constraints): load time of deploy/stack.toml, the
   error line for bad configs, dependency size, the lines each would replace.
3. msgpack field walker (library_codec.py):
   common/fields.py + common/codec.py against msgspec Structs decoding
   the very same bytes: decode time of a Frame, a Detections of 20 boxes and a Twist, and the
   error raised for garbage.

A library that is not installed is said in one line (which package to install) and its
comparison skipped; the script always runs with the stack's own code alone. Nothing here is a
dependency of the stack: install the compared libraries into a throwaway place, e.g.
``pip install --target /tmp/site trackers pydantic-settings msgspec`` and run with
``PYTHONPATH=.:/tmp/site``.

    python tools/benchmarks/library_choices.py [--only tracker,settings,codec] [--frames N]
        [--models-dir DIR] [--cache-dir DIR] [--threads N]
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from tools.benchmarks.library_codec import codec_section  # noqa: E402
from tools.benchmarks.library_settings import settings_section  # noqa: E402
from tools.benchmarks.library_tracker import tracker_section  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--only",
        default="tracker,settings,codec",
        help="comma-separated sections: tracker, settings, codec",
    )
    p.add_argument(
        "--frames",
        type=int,
        default=1000,
        help="at most this many frames per scenario run (default: the whole run)",
    )
    p.add_argument(
        "--rate-hz",
        type=float,
        default=None,
        help="camera rate (default: the simulator's, sim.camera_rate_hz)",
    )
    p.add_argument("--models-dir", default="", help="where the default model is (default: models/)")
    p.add_argument(
        "--cache-dir",
        default="",
        help="keep the detections here, so a second run skips the detector",
    )
    p.add_argument("--threads", type=int, default=2, help="ONNX Runtime intra-op threads")
    p.add_argument(
        "--replays",
        type=int,
        default=5,
        help="tracker timing: the least per frame of this many replays",
    )
    p.add_argument(
        "--no-stress",
        action="store_true",
        help="tracker: only the stack's scenarios, not the overlapping-people worlds",
    )
    args = p.parse_args(argv)
    sections = {s.strip() for s in args.only.split(",") if s.strip()}
    unknown = sections - {"tracker", "settings", "codec"}
    if unknown:
        p.error(f"unknown section(s) {sorted(unknown)}")
    # Ctrl-C ends the process at once, even inside an ONNX Runtime call (a KeyboardInterrupt
    # would wait for it to return), and even when a shell started it with SIGINT ignored.
    # Nothing needs cleaning up: the detection cache is written under a temporary name first.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, {os.cpu_count()} CPU(s)")
    if "tracker" in sections:
        tracker_section(args)
    if "settings" in sections:
        settings_section(args)
    if "codec" in sections:
        codec_section(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
