"""python -m tools.scenarios scenario NAME [--json] [--ros2] [--mode follow|track] [--config FILE]
                                         [--port N]
python -m tools.scenarios list
python -m tools.scenarios soak [--duration S] [--flood-hz HZ] [--json] [--config FILE] [--port N]

scenario runs the real stack (every service over Zenoh) against a scripted world and prints its
figures; list names the scenarios; soak runs the whole stack for a long time under a garbage
flood. Each run's stack listens on a free port (--port N: on N, and N+1 ... for its further
routers) and keeps its config, log and state in a folder of its own in $TMPDIR (else /tmp).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from typing import Any

from common.cli import Command, add_config, service_main
from common.contracts import ControllerMode, ScenarioResult
from common.lifecycle import run_main, setup_logging
from stack.config_file import load_config
from tools.ports import add_port, use_ports


def _print_text(r: ScenarioResult) -> None:
    def fmt(v: Any) -> str:
        return "-" if v is None else f"{v:.2f}" if isinstance(v, float) else str(v)

    mode = f" ({r['mode']} mode)" if r.get("mode") else ""
    print(f"scenario {r['scenario']}{mode}: {'PASS' if r['success'] else 'FAIL'}")
    if r.get("world"):
        print(f"  {r['world']}")
    for key in (
        "time_to_reach_s",
        "final_distance_m",
        "min_clearance_m",
        "min_edge_clearance_m",
        "mean_bearing_error_deg",
        "final_bearing_deg",
        "stale_commands",
        "stop_after_kill_s",
        "distance_travelled_m",
        "duration_s",
    ):
        print(f"  {key:24} {fmt(r.get(key))}")
    for key, per_camera in (
        ("frames_per_camera", r.get("frames_per_camera", {})),
        ("detections_per_camera", r.get("detections_per_camera", {})),
        ("seen_per_camera", r.get("seen_per_camera", {})),
    ):
        print(f"  {key:24} " + " ".join(f"{c}={n}" for c, n in per_camera.items()))
    if "depth_error" in r:
        e = r["depth_error"]
        print(
            f"  {'depth_error':24} median {e['median_pct']:.2f} % p95 {e['p95_pct']:.2f} % of "
            f"the range ({e['rows']} detections, {e['unknown']} unknown, "
            f"{e['range_m'][0]:.1f}-{e['range_m'][1]:.1f} m; median {e['median_signed_m']:+.3f} m)"
        )
    for check, ok in r.get("checks", {}).items():
        print(f"  [{'x' if ok else ' '}] {check}")
    print(f"  log: {r['log']}")


def _interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def _scenario_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("name", help="scenario name (zstack scenarios lists them)")
    add_config(p)
    add_port(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--ros2",
        action="store_true",
        help="play a ROS 2 robot: every frame, scan and command through the ros2 bridge",
    )
    p.add_argument(
        "--mode",
        choices=[m.value for m in ControllerMode],
        default=ControllerMode.FOLLOW.value,
        help="the controller's mode (default follow)",
    )
    p.add_argument(
        "--robots",
        type=int,
        default=1,
        help="simulated robots, each a stack of its own, sharing one detector pool (default 1: "
        "one robot with its own detector)",
    )
    p.add_argument(
        "--workers", type=int, default=2, help="the shared pool's workers, with --robots"
    )
    p.add_argument(
        "--full-length",
        action="store_true",
        help="run the scenario's whole duration, not only until its pass conditions have held "
        "for a few seconds",
    )


def scenario(args: argparse.Namespace) -> int:
    # Ctrl-C or SIGTERM interrupt the run; the runner then stops the stack it started.
    signal.signal(signal.SIGTERM, _interrupt)
    config = load_config(args.config)
    setup_logging("scenario", "WARNING")
    use_ports(args.port)
    from tools.scenarios.runner import run_scenario

    if args.robots > 1:
        from tools.scenarios.robots import run_robots

        runs = run_robots(
            config, args.name, args.robots, args.workers, ControllerMode(args.mode),
            log=lambda m: print(m, file=sys.stderr),
        )  # fmt: skip
        if args.json:
            print(json.dumps(runs))
        else:
            for prefix, r in zip(runs["prefixes"], runs["robots"], strict=True):
                print(f"--- robot {prefix}")
                _print_text(r)
        return 0 if all(r["success"] for r in runs["robots"]) else 1
    result = run_scenario(
        config,
        args.name,
        log=lambda m: print(m, file=sys.stderr),
        ros2=args.ros2,
        mode=ControllerMode(args.mode),
        full_length=args.full_length,
    )
    if args.json:
        print(json.dumps(result))
    else:
        _print_text(result)
    return 0 if result["success"] else 1


def list_scenarios(args: argparse.Namespace) -> int:
    from simworld.scenarios import SCENARIOS

    for name, sc in SCENARIOS.items():
        print(f"{name:14} {sc.description}")
    return 0


def _soak_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)
    add_port(p)
    p.add_argument("--duration", type=float, default=600.0, help="seconds (default 600)")
    p.add_argument(
        "--flood-hz",
        type=float,
        default=200.0,
        help="garbage messages a second, spread over every key (default 200)",
    )
    p.add_argument("--sample-s", type=float, default=10.0, help="seconds between samples")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def soak(args: argparse.Namespace) -> int:
    signal.signal(signal.SIGTERM, _interrupt)
    config = load_config(args.config)
    setup_logging("soak", "WARNING")
    use_ports(args.port)
    from tools.scenarios.soak import run_soak, soak_table

    result = run_soak(
        config, args.duration, args.flood_hz, args.sample_s, log=lambda m: print(m, file=sys.stderr)
    )
    print(json.dumps(result, indent=1) if args.json else soak_table(result))
    healthy = result["still_following"] and not any(result["restarts"].values())
    return 0 if healthy else 1


COMMANDS = [
    Command("scenario", "run the real stack against a scripted world", _scenario_arguments,
            scenario),
    Command("list", "name the scenarios", lambda p: None, list_scenarios),
    Command("soak", "the stack for a long run under a garbage flood", _soak_arguments, soak),
]  # fmt: skip


def main() -> int:
    return service_main("python -m tools.scenarios", __doc__ or "", COMMANDS, default=None)


if __name__ == "__main__":
    run_main(main, "scenario")
