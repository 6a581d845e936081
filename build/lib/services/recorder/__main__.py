"""python -m services.recorder [serve|record|play|compare|benchmark] ...

serve (the default) records the stack to recorder.output_dir for as long as it runs (list
"recorder" first in [supervisor].services); record does the same from the command line until
Ctrl-C or --duration; play publishes a recording's frames and scans onto the stack as if live;
compare reports how two recordings (or a recording and its replay through the running stack)
differ; benchmark runs the default stack with and without the recorder, side by side.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence
from pathlib import Path

from common.cli import Command, add_config, service_main
from common.config_file import load_config
from common.errors import ConfigError
from common.lifecycle import print_progress, run_main, setup_logging, stop_event


def serve(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    log = setup_logging("recorder")
    from services.recorder import service

    return service.record(config, service.default_path(config), stop, log.info)


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


def _rate(text: str) -> float:
    rate = float(text)
    if not 0.01 <= rate <= 100:
        raise argparse.ArgumentTypeError(f"the rate must be within 0.01..100, got {text}")
    return rate


def _play_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=Path, help="an MCAP recording, ours or a ROS 2 bag's")
    add_config(p)
    p.add_argument("--rate", type=_rate, default=1.0, help="speed: 2 plays twice as fast")
    p.add_argument("--loop", action="store_true", help="play again from the start at the end")
    p.add_argument("--topics", nargs="+", help="only these MCAP topics (default: every frame "
                   "and scan topic)")  # fmt: skip


def play(args: argparse.Namespace) -> int:
    stop = stop_event()
    config = load_config(args.config)
    setup_logging("play", "WARNING")
    from services.recorder import play as player

    played = player.play(config, args.file, stop, print_progress, rate=args.rate, loop=args.loop,
                         topics=args.topics)  # fmt: skip
    return 0 if played.frames + played.scans else 1


def _compare_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="run A (an MCAP recording of this stack)")
    p.add_argument("other", type=Path, nargs="?",
                   help="run B; without it, A is played through the running stack and that "
                        "replay, recorded, is B")  # fmt: skip
    add_config(p)
    p.add_argument("--out", type=Path, default=Path("compare"), help="folder for the report")
    p.add_argument("--iou", type=float, default=0.5, help="least IoU of a match (default 0.5)")
    p.add_argument("--rate", type=_rate, default=1.0, help="replay speed (without run B)")


def compare(args: argparse.Namespace) -> int:
    stop = stop_event()
    setup_logging("compare", "WARNING")
    from services.recorder import compare as cmp
    from services.recorder import plots, runs

    if not 0 < args.iou <= 1:
        raise ConfigError(f"--iou must be within (0, 1], got {args.iou}")
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    run_a = runs.load_run(args.recording)  # a bad file fails before any replay
    other = args.other
    if other is None:
        from services.recorder.replay import replay_and_record

        config = load_config(args.config)
        other = replay_and_record(config, args.recording, out / "replay.mcap", stop,
                                  print_progress, args.rate)  # fmt: skip
    run_b = runs.load_run(other)
    result = cmp.compare_runs(run_a, run_b, args.iou)
    name_a, name_b = Path(args.recording).name, Path(other).name
    plot = plots.comparison_plot(result, name_a, name_b, out / "compare.png")
    report = out / "compare.md"
    report.write_text(cmp.report_markdown(result, name_a, name_b, plot.name), encoding="utf-8")
    print(report.read_text(encoding="utf-8"))
    print_progress(f"wrote {report} and {plot}")
    return 0


def _benchmark_arguments(p: argparse.ArgumentParser) -> None:
    from services.recorder import bench

    bench.add_arguments(p)


def benchmark(args: argparse.Namespace) -> int:
    stop = stop_event()
    logging.getLogger().setLevel(logging.WARNING)
    from services.recorder import bench

    return bench.main(args, stop)


COMMANDS = [
    Command("serve", "record the stack while it runs (the service)", add_config, serve),
    Command("record", "record the stack to an MCAP file", _record_arguments, record),
    Command("play", "publish a recording's frames and scans onto the stack", _play_arguments,
            play),
    Command("compare", "how two runs differ: detections, commands, latency", _compare_arguments,
            compare),
    Command("benchmark", "the stack's FPS and latency with and without the recorder",
            _benchmark_arguments, benchmark),
]  # fmt: skip
DESCRIPTION = (__doc__ or "").split("\n\n", 1)[-1]


def main(argv: Sequence[str] | None = None) -> int:
    return service_main("python -m services.recorder", DESCRIPTION, COMMANDS, argv)


if __name__ == "__main__":
    run_main(main, "recorder")
