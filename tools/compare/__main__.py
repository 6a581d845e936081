"""python -m tools.compare [compare] RECORDING [OTHER] [options]

compare (the only command) reports how two recordings differ, or, given one, how a recording
and its replay through the running stack differ: detections matched per frame, commands,
latency per stage.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from common.cli import Command, add_config, replay_rate, service_main
from common.errors import ConfigError, RecordingError, StackError
from common.lifecycle import print_progress, run_main, setup_logging, stop_event
from stack.config_file import load_config


def _compare_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="run A (an MCAP recording of this stack)")
    p.add_argument("other", type=Path, nargs="?",
                   help="run B; without it, A is played through the running stack and that "
                        "replay, recorded, is B")  # fmt: skip
    add_config(p)
    p.add_argument("--out", type=Path, default=Path("compare"), help="folder for the report")
    p.add_argument("--iou", type=float, default=0.5, help="least IoU of a match (default 0.5)")
    p.add_argument("--rate", type=replay_rate, default=1.0, help="replay speed (without run B)")
    p.add_argument("--wait", action=argparse.BooleanOptionalAction, default=True,
                   help="without run B: wait for a detector to be ready before replaying, "
                        "up to recorder.detector_wait_s (--no-wait: at once)")  # fmt: skip


def compare(args: argparse.Namespace) -> int:
    stop = stop_event()
    setup_logging("compare", "WARNING")
    from tools.compare import compare as cmp
    from tools.compare import plots, runs

    if not 0 < args.iou <= 1:
        raise ConfigError(f"--iou must be within (0, 1], got {args.iou}")
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    run_a = runs.load_run(args.recording)  # a bad file fails before any replay
    other = args.other
    if other is None:
        from tools.compare.replay import replay_and_record

        config = load_config(args.config)
        other = replay_and_record(config, args.recording, out / "replay.mcap", stop,
                                  print_progress, args.rate, wait=args.wait)  # fmt: skip
    try:
        run_b = runs.load_run(other)
    except RecordingError as exc:
        if args.other is not None:
            raise
        from common.reach import describe

        where = describe(config.zenoh, config.stack.prefix, "recorder")
        raise StackError(
            f"the stack at {where} made no detections of the replay of {args.recording} "
            f"(kept in {other}): is a detector running there, on the same cameras?"
        ) from exc
    result = cmp.compare_runs(run_a, run_b, args.iou)
    name_a, name_b = Path(args.recording).name, Path(other).name
    plot = plots.comparison_plot(result, name_a, name_b, out / "compare.png")
    report = out / "compare.md"
    report.write_text(cmp.report_markdown(result, name_a, name_b, plot.name), encoding="utf-8")
    print(report.read_text(encoding="utf-8"))
    print_progress(f"wrote {report} and {plot}")
    return 0


COMMANDS = [
    Command("compare", "how two runs differ: detections, commands, latency", _compare_arguments,
            compare),
]  # fmt: skip


def main() -> int:
    return service_main("python -m tools.compare", __doc__ or "", COMMANDS, default="compare")


if __name__ == "__main__":
    run_main(main, "compare")
