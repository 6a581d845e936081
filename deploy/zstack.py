"""zstack COMMAND [options]: one command line for every task of the stack.

Each command runs the module that owns it, exactly as ``python -m <module> ...`` would, so the
two spellings always agree (and ``python -m deploy.zstack`` works without the console script).
Results meant for programs go to stdout; progress and status go to stderr.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from common.priority import own_session

# command -> (module, the argv it starts with, help)
COMMANDS: dict[str, tuple[str, tuple[str, ...], str]] = {
    "run": ("deploy.supervisor", (), "start the stack under the supervisor (Ctrl-C stops it)"),
    "serve": ("", (), "run one service: zstack serve camera|sim|detector|controller|metrics|..."),
    "detect": (
        "tools.detector",
        ("detect",),
        "detect on photos, folders, videos, cameras or streams",
    ),
    "benchmark": ("tools.detector", ("benchmark",), "time the detector's stages, per backend"),
    "export": ("tools.detector", ("export",), "build a TensorRT engine ahead of time"),
    "prepare": (
        "tools.detector",
        ("prepare",),
        "prepare the models a config needs (fetch, size, INT8, fast profile) before serving",
    ),
    "fetch-model": ("tools.detector", ("fetch-model",), "fetch and convert the default model"),
    "fast-profile": (
        "tools.detector",
        ("fast-profile",),
        "measure the CPU variants once; the fast profile starts from the cached choice",
    ),
    "query": ("services.metrics", ("query",), "print a running stack's metrics as JSON"),
    "pool": ("services.metrics", ("pool",), "print the detector pool (workers, cameras) as JSON"),
    "evaluate": ("tools.evaluation", ("evaluate",), "accuracy on a labelled dataset"),
    "report": ("tools.report", ("report",), "record a run and write report.md with plots"),
    "scenario": ("tools.scenarios", ("scenario",), "run the real stack against a scripted world"),
    "scenarios": ("tools.scenarios", ("list",), "name the scenarios"),
    "estop": ("services.controller", ("estop",), "engage or release the emergency stop"),
    "ros2-benchmark": ("tools.benchmarks", ("ros2",), "the ROS 2 bridge's added latency"),
    "record": ("services.recorder", ("record",), "record the stack's keys to an MCAP file"),
    "play": ("services.recorder", ("play",), "publish a recording's frames and scans, as live"),
    "compare": ("tools.compare", ("compare",), "how two runs differ (or a replay)"),
    "viewer-layout": (
        "services.viewer",
        ("layout",),
        "write the Foxglove layout for a config's cameras",
    ),
    "recorder-benchmark": (
        "tools.benchmarks",
        ("recorder",),
        "the stack with and without the recorder",
    ),
    "scale-benchmark": (
        "tools.benchmarks",
        ("scale",),
        "several cameras on one detector against one stack per camera",
    ),
    "pool-benchmark": (
        "tools.benchmarks",
        ("pool",),
        "cameras on 1 and 2 detector workers; the hand-over after a SIGKILL; --robots N",
    ),
    "soak": ("tools.scenarios", ("soak",), "the whole stack for a long run under a garbage flood"),
    "credentials": ("deploy.credentials", (), "write the secure profile's credentials"),
}


def usage() -> str:
    lines = [(__doc__ or "").strip().splitlines()[0], "", "commands:"]
    lines += [f"  {name:12} {text}" for name, (_, _, text) in COMMANDS.items()]
    lines += ["", "zstack COMMAND --help shows a command's options."]
    return "\n".join(lines)


def resolve(argv: Sequence[str]) -> tuple[str, list[str]]:
    """The module to run and its arguments for ``argv``; SystemExit(2) with usage if unknown."""
    if not argv or argv[0] in ("-h", "--help"):
        print(usage(), file=sys.stderr if not argv else sys.stdout)
        raise SystemExit(0 if argv else 2)
    command, rest = argv[0], list(argv[1:])
    if command not in COMMANDS:
        print(f"zstack: error: unknown command {command!r}\n\n{usage()}", file=sys.stderr)
        raise SystemExit(2)
    if command == "serve":
        from common.settings import SERVICES

        if not rest or rest[0] not in SERVICES:
            print(f"zstack: error: serve needs one of {', '.join(SERVICES)}", file=sys.stderr)
            raise SystemExit(2)
        return f"services.{rest[0]}", ["serve", *rest[1:]]
    module, lead, _ = COMMANDS[command]
    return module, [*lead, *rest]


def main(argv: Sequence[str] | None = None) -> None:
    words = list(sys.argv[1:] if argv is None else argv)
    if words[:1] == ["estop"]:
        # Before anything else (imports, threads): the stop gets its own share of the CPU.
        code = own_session()
        if code is not None:
            raise SystemExit(code)
        if words[1:2] == ["engage"] and not {"-h", "--help"} & set(words):
            # The local road first (stack/local_estop.py): a datagram to the controller on
            # this host, before Zenoh or the command's parser is imported. The command's
            # Zenoh road follows as always, and reports whether the controller acknowledged.
            from stack.local_estop import engage_here, option

            engage_here(option(words, "--config"), option(words, "--reason") or "")
    import runpy

    from common.cli import invoked_as

    module, args = resolve(words)
    lead = COMMANDS[words[0]][1] if words[0] != "serve" else ("serve",)
    typed = f"zstack {words[0]}" if words[0] != "serve" else f"zstack serve {words[1]}"
    invoked_as(lead[0] if lead else "", typed)  # usage lines name what the user typed
    sys.argv = [f"python -m {module}", *args]
    runpy.run_module(module, run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
