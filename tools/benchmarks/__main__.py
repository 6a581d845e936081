"""python -m tools.benchmarks recorder|ros2|scale|pool|batch|attention|estop|depth|tracker [options]

recorder runs the default stack with and without the recorder, side by side; ros2 measures
what the ROS 2 bridge adds against the direct path; scale runs 1, 2, 4, 8 cameras on one
detector against as many one-camera stacks, batched and batch 1; pool runs 4 and 8 cameras on 1
and 2 detector workers, times the hand-over after a worker's SIGKILL and the assignment under
uneven load; batch times one backend per image at batch 1, 2, 4 ... (the whole detection and
the model alone) with the choice the detector would make; attention runs three cameras at 640
on one CPU worker with attention on and off (frames per camera, time to find a person stepping
into an empty camera); estop times ``zstack estop
engage``'s start to its first put against another revision; depth measures the distance to
detected people against the simulator's truth in its hard world (``--world simple``: today's)
by five methods side by side (ours, a yolo_ros-like one, the box's centre pixel, ours without
background rejection, the laser) and the depth stage's time per frame. (The detector's own
benchmark is ``python -m tools.detector benchmark``.) tracker times the trackers per frame
for 1 to 20 people.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable

from common.cli import Command, options_from, service_main
from common.lifecycle import run_main, setup_logging, stop_event
from tools.ports import add_port, use_ports


def _recorder_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="the stack to run (default deploy/stack.toml)")
    p.add_argument("--rounds", type=int, default=3, help="phases of each condition (default 3)")
    p.add_argument("--phase", type=float, default=20.0, help="seconds per phase (default 20)")
    add_port(p)
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def recorder(args: argparse.Namespace) -> int:
    stop = stop_event()
    logging.getLogger().setLevel(logging.WARNING)
    from tools.benchmarks import recorder as bench

    use_ports(args.port)

    return bench.main(args.config, args.rounds, args.phase, args.json, stop)


def _ros2_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--runs", type=int, default=200, help="messages per path (default 200)")
    add_port(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def ros2(args: argparse.Namespace) -> int:
    setup_logging("ros2-bench", "WARNING")
    from tools.benchmarks import ros2 as bench

    use_ports(args.port)

    return bench.main(args.runs, args.json)


def _counts(low: int, high: int) -> Callable[[str], tuple[int, ...]]:
    def parse(text: str) -> tuple[int, ...]:
        try:
            counts = tuple(int(x) for x in text.split(",") if x.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"a list of numbers like 1,2, got {text!r}") from None
        if not counts or any(not low <= n <= high for n in counts):
            raise argparse.ArgumentTypeError(f"numbers within {low}..{high}, got {text!r}")
        return counts

    return parse


#: Camera counts as the scale benchmark takes them ("1,2,4,8").
_camera_counts = _counts(1, 32)


def _scale_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="the stack to start from (default deploy/stack.toml)")
    p.add_argument(
        "--cameras",
        type=_camera_counts,
        default=(1, 2, 4, 8),
        help="camera counts to compare (default 1,2,4,8)",
    )
    p.add_argument(
        "--seconds", type=float, default=20.0, help="measured seconds per condition (default 20)"
    )
    p.add_argument(
        "--warmup",
        type=float,
        default=20.0,
        help="seconds after readiness left out of each condition (default 20)",
    )
    p.add_argument(
        "--source",
        default="sample:chelsea",
        help="every camera process's source with --cameras-from processes (default sample:chelsea)",
    )
    p.add_argument(
        "--rate",
        dest="rate_hz",
        type=float,
        default=10.0,
        help="every camera's rate in Hz (default 10: more than a CPU detector serves)",
    )
    p.add_argument(
        "--cameras-from",
        choices=("sim", "processes"),
        default="sim",
        help="sim: the simulator renders every camera in one process (default); processes: "
        "one camera process per camera, each with --source",
    )
    add_port(p)
    p.add_argument("--json", action="store_true", help="print the figures as JSON")  # fmt: skip


def scale(args: argparse.Namespace) -> int:
    stop = stop_event()
    logging.getLogger().setLevel(logging.WARNING)
    from tools.benchmarks import scale as bench

    use_ports(args.port)

    return bench.main(options_from(bench.ScaleOptions, args, as_json=args.json), stop)


def _pool_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="the stack to start from (default deploy/stack.toml)")
    p.add_argument(
        "--cameras", type=_camera_counts, default=(4, 8), help="camera counts (default 4,8)"
    )
    p.add_argument(
        "--workers",
        type=_counts(1, 8),
        default=(1, 2),
        help="worker counts to compare (default 1,2)",
    )
    p.add_argument(
        "--seconds", type=float, default=20.0, help="measured seconds per condition (default 20)"
    )
    p.add_argument(
        "--warmup",
        type=float,
        default=15.0,
        help="seconds after the split left out of each condition (default 15)",
    )
    p.add_argument(
        "--rate",
        dest="rate_hz",
        type=float,
        default=10.0,
        help="every camera's rate in Hz (default 10)",
    )
    p.add_argument(
        "--kills",
        type=int,
        default=20,
        help="SIGKILLs of a worker, 4 cameras on 2 (default 20; 0 skips)",
    )
    p.add_argument(
        "--uneven",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="2 heavy and 2 light cameras on 2 workers (default on)",
    )
    p.add_argument(
        "--capacity",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="a fast and a slow worker: shares by measured capacity vs even (default on)",
    )
    p.add_argument("--fast-size", type=int, default=320, help="the fast worker's input size")
    p.add_argument("--slow-size", type=int, default=480, help="the slow worker's input size")
    p.add_argument(
        "--capacity-cameras", type=int, default=8, help="cameras of the capacity part (default 8)"
    )
    p.add_argument(
        "--capacity-rate",
        dest="capacity_rate_hz",
        type=float,
        default=2.0,
        help="their rate in Hz (default 2)",
    )
    p.add_argument(
        "--robots",
        type=int,
        default=0,
        help="N simulated robots (2..8) on one pool of 2 workers vs one robot with as many "
        "cameras (default 0: skipped)",
    )
    add_port(p)
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def pool(args: argparse.Namespace) -> int:
    stop = stop_event()
    logging.getLogger().setLevel(logging.WARNING)
    from tools.benchmarks.pool import PoolOptions
    from tools.benchmarks.pool_runs import main as run

    use_ports(args.port)

    return run(options_from(PoolOptions, args, as_json=args.json), stop)


def _batch_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", help="ONNX model (default: the YOLOv5s COCO model, fetched)")
    p.add_argument(
        "--backend", default="onnx", help="onnx, cuda, tensorrt or openvino (default onnx)"
    )
    p.add_argument("--largest", type=int, default=8, help="the largest batch timed (default 8)")
    p.add_argument("--runs", type=int, default=20, help="timed runs of each size (default 20)")
    p.add_argument(
        "--min-gain",
        type=float,
        default=0.2,
        help="what a batch must save per image to be chosen (default 0.2: detector.batch_min_gain)",
    )
    p.add_argument(
        "--precision", help="the backend's precision where it has a choice (cuda: fp16 or fp32)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")


def batch(args: argparse.Namespace) -> int:
    # No stop event: Ctrl-C interrupts a measurement at once (run_main: exit 130); it writes
    # no file.
    setup_logging("batch-bench", "WARNING")
    from pathlib import Path

    from modelprep.files import ensure_default_model
    from tools.benchmarks import batch_sizes as bench

    model = Path(args.model) if args.model else ensure_default_model()
    extra = {"precision": args.precision} if args.precision else {}
    options = bench.BatchOptions(
        model, args.backend, args.largest, args.runs, args.min_gain, extra, args.json
    )
    return bench.run(options, lambda line: print(line, file=sys.stderr, flush=True))


def _attention_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="the stack to start from (default deploy/stack.toml)")
    p.add_argument(
        "--scenarios",
        nargs="+",
        default=["ahead", "behind", "appears"],
        choices=["ahead", "behind", "appears"],
        help="the scenarios to run, each with attention on and off (default all three)",
    )
    p.add_argument(
        "--camera-rate",
        type=float,
        default=10.0,
        help="frames a second the simulator renders of each camera (default 10)",
    )
    add_port(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def attention(args: argparse.Namespace) -> int:
    setup_logging("attention-bench", "WARNING")
    from stack.config_file import load_config
    from tools.benchmarks.attention import main

    use_ports(args.port)

    return main(load_config(args.config), tuple(args.scenarios), args.json, args.camera_rate)


def _estop_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--runs", type=int, default=20, help="starts of each revision (default 20)")
    p.add_argument(
        "--against",
        default="main",
        help="the git revision to compare with (default main; name the one before a change)",
    )
    p.add_argument(
        "--to-zero",
        action="store_true",
        help="time to a real controller's stop (its e-stop status), not to the first put",
    )
    p.add_argument(
        "--burners",
        type=int,
        default=2,
        help="with --to-zero: busy loops beside the controller (default 2: a 2-core machine busy)",
    )
    add_port(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def estop(args: argparse.Namespace) -> int:
    from tools.benchmarks.estop import EstopOptions, main

    use_ports(args.port)
    options = options_from(EstopOptions, args, as_json=args.json)
    if options.to_zero:
        from tools.benchmarks.estop_zero import main as to_zero

        return to_zero(options)
    return main(options)


def _depth_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--worlds", type=int, default=150, help="simulated worlds (default 150)")
    p.add_argument("--seed", type=int, default=1, help="the worlds' and noise's seed (default 1)")
    p.add_argument("--threads", type=int, default=2, help="the detector's threads (default 2)")
    p.add_argument("--models-dir", help="where the default model is (default: the stack's)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--world",
        choices=("hard", "simple"),
        default="hard",
        help="the simulator's world: hard (people with bodies, the D435-like camera's faults; "
        "the default) or simple (flat cards, today's camera)",
    )


def depth(args: argparse.Namespace) -> int:
    # No stop event: Ctrl-C interrupts at once (run_main: exit 130); it writes no file.
    setup_logging("depth-bench", "WARNING")
    from tools.benchmarks.depth import DepthBenchOptions, main

    return main(options_from(DepthBenchOptions, args, as_json=args.json))


def _tracker_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--people", type=_counts(1, 100), default=(1, 5, 10, 20),
                   help="people per frame, e.g. 1,5,10,20 (the default)")  # fmt: skip
    p.add_argument("--frames", type=int, default=300, help="frames per row (default 300)")


def tracker(args: argparse.Namespace) -> int:
    from tools.benchmarks import tracker_cost as bench

    return bench.main(args.people, args.frames)


COMMANDS = [
    Command("recorder", "the stack's FPS and latency with and without the recorder",
            _recorder_arguments, recorder),
    Command("ros2", "the ROS 2 bridge's added latency against the direct path",
            _ros2_arguments, ros2),
    Command("scale", "N cameras on one detector against N one-camera stacks, batched and not",
            _scale_arguments, scale),
    Command("pool", "4 and 8 cameras on 1 and 2 detector workers; hand-over after SIGKILL",
            _pool_arguments, pool),
    Command("batch", "time per image by batch size on one backend, and the detector's choice",
            _batch_arguments, batch),
    Command("attention", "three cameras at 640 on a CPU: the target's camera first, and the "
            "time to find a person stepping into an empty one, attention on and off",
            _attention_arguments, attention),
    Command("estop", "how soon zstack estop puts its first EStop, against another revision",
            _estop_arguments, estop),
    Command("depth", "distance to detected people against the simulator's truth (hard world by "
            "default): ours, a yolo_ros-like one, the centre pixel, ours without background "
            "rejection, the laser; the depth stage's time",
            _depth_arguments, depth),
    Command("tracker", "the trackers' cost per frame for 1 to 20 people: IoU, Kalman, Kalman "
            "with colours", _tracker_arguments, tracker),
]  # fmt: skip


def main() -> int:
    return service_main("python -m tools.benchmarks", __doc__ or "", COMMANDS, default=None)


if __name__ == "__main__":
    run_main(main, "benchmark")
