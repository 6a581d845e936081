"""One robot's credentials work on no other robot (issue 39, item 1; docs/security.md,
"Several robots").

Two robots of one site, ``<site>/robot1`` and ``<site>/robot2``, secured with certificates
made by ONE ``zstack credentials`` run (``--robot``: one CA for the site), as docs/security.md's
several robots would be. Robot 2's router runs (its controller, e-stop engaged by its own
``estop``). Each principal robot 1 has a secret for (its estop, controller, observer,
recorder, simulator, metrics, viewer, its local worker, and its router's key,
``<site>/robot1/supervisor``) connects straight to robot 2's
router, subscribes to all of robot 2's keys, asks for its tokens and metrics, and puts a
release of the e-stop, a command and garbage on robot 2's keys. Robot 2's e-stop stays
engaged, its readers hear none of it, and robot 1's principals hear and learn nothing of
robot 2's; robot 2's own principals still work (its observer hears its controller, its
estop releases). On the code before per-robot principals, robot 1's ``estop`` was robot 2's
``estop``: its release went through; before per-stack routers, robot 1's router key was robot
2's ``supervisor``, in robot 2's "everyone" group: it read robot 2's health tokens.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import uuid
from pathlib import Path

import pytest
import zenoh

from common.clock import now
from common.contracts import ControllerState
from common.control_messages import ControllerStatus
from common.messages import EStop, Twist
from common.zenoh_bus import open_session
from stack.config_file import load_config
from tests.integration.conftest import REPO, Stack, wait_for, write_config
from tests.integration.test_safety import header, pause
from tools.launch import free_port

pytestmark = pytest.mark.integration

#: What robot 1 runs (so each of these has a secret): a simulated robot with its own worker.
ROBOT1_SERVICES = ["sim", "detector", "controller", "metrics", "viewer"]
ROUNDS = 10


def _config(tmp: Path, name: str, prefix: str, creds: Path, services: list[str]) -> Path:
    (tmp / name).mkdir()
    zenoh = {"mode": "client", "auth": "certificate", "credentials_dir": str(creds),
             "endpoint": f"tls/127.0.0.1:{free_port()}"}  # fmt: skip
    return write_config(
        tmp / name, zenoh=zenoh, stack={"prefix": prefix, "camera": "front"},
        supervisor={"services": services}, detector={"pool_prefix": prefix.rsplit("/", 1)[0],
                                                     "worker_id": name},
    )  # fmt: skip


def _status(raw: bytes) -> ControllerStatus | None:
    try:
        return ControllerStatus.decode(raw)
    except Exception:
        return None


def test_one_robots_principals_do_nothing_on_another_robots_router(tmp_path: Path) -> None:
    site = f"site{uuid.uuid4().hex[:6]}"
    creds = tmp_path / "credentials"
    one = _config(tmp_path, "robot1", f"{site}/robot1", creds, ROBOT1_SERVICES)
    two = _config(tmp_path, "robot2", f"{site}/robot2", creds, ["controller"])
    made = subprocess.run(
        [sys.executable, "-m", "deploy.zstack", "credentials", "--config", str(one),
         "--robot", str(two)],
        cwd=REPO, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    r1 = load_config(one, environ={})
    users = [line.split(":", 1)[0] for line in (creds / "users.txt").read_text().splitlines()]
    # Its router's key (site/robot1/supervisor) too.
    roles = ["estop", "controller", "observer", "recorder", "sim", "metrics", "viewer",
             "detector_robot1", "supervisor"]  # fmt: skip
    mine = [r1.principal(r) for r in roles]
    assert set(mine) <= set(users), users  # one run made both robots' principals

    r2 = Stack(two, tmp_path / "robot2.log")
    sessions: dict[str, zenoh.Session] = {}
    try:
        r2.wait_ready({"controller"})
        _, statuses = r2.subscribe(r2.keys.controller_status())
        _, cmds = r2.subscribe(r2.keys.cmd_vel())
        _, estops = r2.subscribe(r2.keys.estop())
        r2.estop("engage")  # robot 2's own estop
        # Robot 1's principals on robot 2's router (its endpoint, robot 1's own files).
        on_two = dataclasses.replace(r2.config.zenoh, connect=())
        heard: dict[str, list[str]] = {}
        for name in mine:
            s = sessions[name] = open_session(on_two, name)
            got = heard[name] = []
            s.declare_subscriber(f"{r2.keys.prefix}/**", lambda x, g=got: g.append(str(x.key_expr)))
            for key in (r2.keys.cmd_vel(), r2.keys.controller_status(), r2.keys.estop()):
                s.declare_subscriber(key, lambda x, g=got: g.append(str(x.key_expr)))
        marker = 0.77  # a command robot 2's controller never gives
        for _ in range(ROUNDS):
            for name, s in sessions.items():
                at = now()
                h = header(at.wall_ns, source=f"rogue-{name}", mono_ns=at.mono_ns)
                s.put(r2.keys.estop(), EStop(header=h, engaged=False, reason="rogue").encode())
                twist = Twist(header=h, linear=(marker, 0.0, 0.0), input_stamp_ns=at.wall_ns)
                s.put(r2.keys.cmd_vel(), twist.encode())
                s.put(r2.keys.frame("front"), b"rogue")
            pause(0.05)
        asked = {
            name: (list(s.liveliness().get(f"{r2.keys.prefix}/**", timeout=0.5)),
                   list(s.get(r2.keys.metrics(), timeout=0.5)))
            for name, s in sessions.items()
        }  # fmt: skip
        assert all(t == [] and q == [] for t, q in asked.values()), asked
        # Robot 2's own observer keeps hearing its controller, which stays engaged.
        seen = len(statuses)
        wait_for(lambda: len(statuses) >= seen + 3, 30, f"robot 2's status:\n{r2.log()}")
        states = [st.state for st in map(_status, statuses[seen:]) if st]
        assert states and set(states) == {ControllerState.ESTOP.value}, states
        assert not [t for t in map(Twist.decode, cmds) if abs(t.linear[0] - marker) < 1e-6]
        rogue_estops = [e for e in map(EStop.decode, estops) if e.reason == "rogue"]
        assert rogue_estops == [], "robot 1's estop reached robot 2's e-stop key"
        # A session hears its own puts (Zenoh delivers them locally), and nothing else: not
        # robot 2's controller's commands, statuses or counters, nor another's puts.
        own = {r2.keys.estop(), r2.keys.cmd_vel(), r2.keys.frame("front")}
        assert {n: [k for k in h if k not in own] for n, h in heard.items()} == {
            n: [] for n in heard
        }, "robot 1 heard robot 2"
        assert {n: h.count(r2.keys.cmd_vel()) for n, h in heard.items()} == dict.fromkeys(
            heard,
            2 * ROUNDS,  # its two subscriptions to cmd_vel, each its own ROUNDS puts
        )
        for s in sessions.values():
            s.close()
        sessions.clear()
        # Robot 2's own estop still releases it.
        r2.estop("release")
        wait_for(
            lambda: (st := _status(statuses[-1])) is not None and st.state != "estop",
            30, "robot 2's own release",
        )  # fmt: skip
    finally:
        for s in sessions.values():
            s.close()
        code = r2.stop()
    assert code == 0, r2.log()
    print(json.dumps({"robot1_principals_tried": mine, "rounds": ROUNDS}))
