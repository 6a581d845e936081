"""python -m tools.benchmarks estop: how soon ``zstack estop engage`` puts its first EStop,
this checkout against another revision, side by side (with ``--to-zero``, how soon a real
controller stops: tools/benchmarks/estop_zero.py).

This process plays the stack's hub (``stack.hub.open_hub`` on a private endpoint) and
subscribes to the e-stop key; each run starts the command as an operator would
(``python -m deploy.zstack estop engage --config FILE``) and times from just before the
process is started to the arrival of its first EStop, on this process's monotonic clock. The
command is then killed (no controller acknowledges it). The other revision is a ``git
archive`` of it in a temporary folder, run by the same interpreter; the two alternate run by
run, so that both see the same machine load. Prints each one's p50, p90, min and max and the
ratio of the p50s, with the machine it ran on.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import statistics
import subprocess
import sys
import tarfile
import tempfile
import threading
from pathlib import Path
from typing import Any

import zenoh

from common.clock import mono_s
from common.files import temp_root
from common.keys import Keys
from common.machine import machine_info
from common.settings import REPO_ROOT, StackSettings, ZenohSettings
from common.spawn import spawn
from stack.config import Config
from stack.hub import open_hub
from tools.ports import private_endpoint

#: The longest a run waits for the first put before counting it lost.
FIRST_PUT_TIMEOUT_S = 30.0
THIS = "this checkout"


@dataclasses.dataclass(frozen=True, slots=True)
class EstopOptions:
    runs: int = 20
    against: str = "main"
    as_json: bool = False
    #: Time to the controller's stop on a real controller (tools/benchmarks/estop_zero.py),
    #: with ``burners`` busy loops beside it, instead of to the first put.
    to_zero: bool = False
    burners: int = 2


def _export(revision: str, into: Path) -> str:
    """``revision``'s tree in ``into``; its full commit id."""
    commit = subprocess.run(
        ["git", "rev-parse", "--verify", f"{revision}^{{commit}}"],
        cwd=REPO_ROOT, capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    tar = subprocess.run(
        ["git", "archive", "--format=tar", commit], cwd=REPO_ROOT, capture_output=True, check=True
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        archive.extractall(into, filter="data")
    return commit


def _runs_from(folder: Path) -> bool:
    """Whether ``python -m`` in ``folder`` imports that folder's code (not this checkout's, which
    the editable install also offers)."""
    where = subprocess.run(
        [sys.executable, "-c", "import deploy.zstack as z; print(z.__file__)"],
        cwd=folder, capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    return Path(where).resolve().is_relative_to(folder.resolve())


def _summary(values: list[float]) -> dict[str, float]:
    ordered = sorted(values)
    return {
        "p50_ms": round(statistics.median(ordered) * 1000, 1),
        "p90_ms": round(ordered[max(0, math.ceil(0.9 * len(ordered)) - 1)] * 1000, 1),
        "min_ms": round(ordered[0] * 1000, 1),
        "max_ms": round(ordered[-1] * 1000, 1),
    }


def tally(
    times: dict[str, list[float]], lost: dict[str, int], against: str
) -> tuple[dict[str, dict[str, Any]], float | None]:
    """Each revision's summary (with its lost runs and its runs over 0.2 s), and the ratio of
    this checkout's p50 to the other's (None when either has no run)."""
    report: dict[str, dict[str, Any]] = {
        name: {**_summary(v), "lost": lost[name], "over_200_ms": sum(t > 0.2 for t in v)}
        for name, v in times.items()
        if v
    }
    ratio = (
        report[THIS]["p50_ms"] / report[against]["p50_ms"]
        if len(report) == 2 and report[against]["p50_ms"] > 0
        else None
    )
    return report, ratio


def run(options: EstopOptions) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="estop-bench-", dir=temp_root()) as tmp:
        folder = Path(tmp)
        old = folder / "old"
        commit = _export(options.against, old)
        if not _runs_from(old):
            raise SystemExit(f"estop benchmark: {options.against} would not run from {old}")
        endpoint, prefix = private_endpoint(), "estopbench"
        config = Config(
            zenoh=ZenohSettings(endpoint=endpoint),
            stack=StackSettings(prefix=prefix),
        )
        # Only what both revisions read alike: a whole config of this checkout could hold a
        # setting the other does not know.
        config_path = folder / "stack.toml"
        config_path.write_text(
            f'[zenoh]\nendpoint = "{endpoint}"\nmulticast_scouting = false\n'
            f'[stack]\nprefix = "{prefix}"\n'
            f'[controller]\nestop_file = "{folder / "estop.json"}"\n'
        )
        arrived = threading.Event()
        stamp: list[float] = []

        def on_estop(_: zenoh.Sample) -> None:
            if not arrived.is_set():
                stamp[:] = [mono_s()]
                arrived.set()

        times: dict[str, list[float]] = {THIS: [], options.against: []}
        lost = dict.fromkeys(times, 0)
        hub = open_hub(config)
        sub = hub.declare_subscriber(Keys(config.stack.prefix).estop(), on_estop)
        try:
            for i in range(options.runs):
                order = [(THIS, REPO_ROOT), (options.against, old)]
                for name, cwd in order if i % 2 == 0 else order[::-1]:
                    arrived.clear()
                    start = mono_s()
                    proc = spawn(
                        [sys.executable, "-m", "deploy.zstack", "estop", "engage",
                         "--config", str(config_path), "--reason", "benchmark"],
                        cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                    )  # fmt: skip
                    deadline = start + FIRST_PUT_TIMEOUT_S
                    while not arrived.wait(0.02) and proc.poll() is None and mono_s() < deadline:
                        pass  # until the put, the command's exit (an error) or the deadline
                    if arrived.is_set():
                        times[name].append(stamp[0] - start)
                    else:
                        lost[name] += 1
                    proc.kill()
                    proc.wait()
                print(f"estop benchmark: {i + 1}/{options.runs}", file=sys.stderr, flush=True)
        finally:
            sub.undeclare()
            hub.close()
    report, ratio = tally(times, lost, options.against)
    return {
        "runs": options.runs,
        "against": {"revision": options.against, "commit": commit},
        "first_put": report,
        "p50_ratio": None if ratio is None else round(ratio, 2),
        "machine": machine_info(),
    }


def main(options: EstopOptions) -> int:
    return show(run(options), options, "its first EStop put", "first_put")


def show(result: dict[str, Any], options: EstopOptions, title: str, table: str) -> int:
    """Print ``result`` (JSON, or its ``table`` as a table of p50 ... per revision)."""
    if options.as_json:
        print(json.dumps(result, indent=2))
        return 0
    against = result["against"]
    print(f"time from the command's start to {title}, {options.runs} runs each")
    if "burners" in result:
        print(f"{result['burners']} CPU burners beside; load average {result['load_average']}")
    print(f"{'':22} {'p50 ms':>8} {'p90 ms':>8} {'min ms':>8} {'max ms':>8} {'lost':>5}")
    for name, row in result[table].items():
        label = name if name == THIS else f"{name} ({against['commit'][:9]})"
        over = f" {row['over_200_ms']:3d} over 0.2 s" if "over_200_ms" in row else ""
        print(
            f"{label:22} {row['p50_ms']:8.1f} {row['p90_ms']:8.1f} {row['min_ms']:8.1f} "
            f"{row['max_ms']:8.1f} {row['lost']:5d}{over}"
        )
    print(f"p50 ratio (this / {against['revision']}): {result['p50_ratio']}")
    machine = result["machine"]
    print(f"machine: {machine.get('cpu_model')}, {machine.get('cpu_count')} CPUs")
    return 0
