"""What ``zstack estop`` imports on its way to the first put: the structure that makes it start
fast (the time itself is measured by ``python -m tools.benchmarks estop``, never asserted).

The command runs for real (``python -X importtime``, a config whose endpoint nothing listens
on: it gives up after its link timeout), and the modules it imported are read from Python's
own import log.
"""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

from common.estop_local import ENGAGE, MAX_DATAGRAM, socket_path
from tools.launch import free_port

REPO = Path(__file__).resolve().parents[3]

#: Libraries the e-stop never needs: numpy (and what needs it), the camera's and the
#: detector's runtimes, and the controller's service (its policy, tracker and loop).
HEAVY = ("numpy", "cv2", "onnxruntime", "msgspec", "services.controller.service")
#: Every service's settings (the whole Config): the e-stop reads [zenoh] and [stack] alone.
SETTINGS = ("stack.config", "stack.config_file", "services.detector.contract")


def imported_by(argv: list[str], tmp_path: Path) -> tuple[list[str], str]:
    config = tmp_path / "stack.toml"
    config.write_text(
        f'[zenoh]\nendpoint = "tcp/127.0.0.1:{free_port()}"\nmulticast_scouting = false\n'
        f'[controller]\nestop_file = "{tmp_path / "estop.json"}"\n'
    )
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "deploy.zstack", *argv, "--config", config],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 1, done.stderr[-2000:]
    modules = [  # in the order their imports ended
        line.rsplit("|", 1)[1].strip()
        for line in done.stderr.splitlines()
        if line.startswith("import time:") and line.count("|") == 2
    ]
    errors = [line for line in done.stderr.splitlines() if not line.startswith("import time:")]
    return modules, "\n".join(errors)


def test_the_estop_imports_nothing_heavy(tmp_path: Path) -> None:
    modules, errors = imported_by(["estop", "engage"], tmp_path)
    assert "services.controller.estop_command" in modules, sorted(modules)  # the path ran
    assert "zenoh" in modules  # and reached the bus: the put's own imports were made
    heavy = sorted(m for m in modules if m.split(".")[0] in HEAVY or m in HEAVY)
    assert heavy == [], f"the e-stop imported {heavy}"
    settings = sorted(m for m in modules if m in SETTINGS)
    assert settings == [], f"the e-stop imported every service's settings: {settings}"
    assert "estop: error: cannot engage the e-stop: no link to the stack" in errors, errors


def test_the_local_road_leaves_before_zenoh_is_imported(tmp_path: Path) -> None:
    # A stand-in for the controller's local e-stop socket beside the config's e-stop file.
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as controller:
        controller.bind(str(socket_path(tmp_path / "estop.json")))
        controller.settimeout(0)
        modules, errors = imported_by(["estop", "engage", "--reason", "ramp"], tmp_path)
        assert controller.recv(MAX_DATAGRAM) == ENGAGE + b"ramp"
    assert modules.index("stack.local_estop") < modules.index("zenoh"), modules
    # ... and the Zenoh road, which cannot reach the stack here, says that it was taken.
    assert "took the engage through its local e-stop socket" in errors, errors
