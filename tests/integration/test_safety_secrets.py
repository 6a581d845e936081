"""Credentials that others may read or change are refused at start-up, as ssh refuses a private
key that others can read (issue 29): a credentials folder that group or others may write, a
password or key that others may read, stops the secure stack with one line naming the file and
the chmod that fixes it. The real supervisor and a real service's command line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from common.security import key_file, password_file, users_file
from stack.config_file import load_config
from tests.integration.conftest import REPO, credentials_for, free_port, write_config
from tests.polling import wait_for
from tools.launch import start_supervisor, stop_supervisor

pytestmark = pytest.mark.integration


def _run(*args: str | Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("STACK__")}
    return subprocess.run(
        [sys.executable, "-m", *map(str, args)],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip


def _one_line(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 2, (done.returncode, done.stderr)
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]


def test_the_secure_stack_refuses_credentials_others_may_read_or_change(tmp_path: Path) -> None:
    creds = tmp_path / "credentials"
    prefix = credentials_for(creds)
    # What a careless copy leaves: a folder anyone may write, secrets anyone may read.
    creds.chmod(0o777)
    for path in creds.rglob("*"):
        if path.is_file():
            path.chmod(0o666)
    config = write_config(
        tmp_path,
        zenoh={"mode": "client", "auth": "password", "credentials_dir": str(creds)},
        supervisor={"services": ["controller"]},
        stack={"prefix": prefix},
    )
    # --duration: a supervisor that did start would stop by itself (exit 0), not hang the test.
    supervisor = ("deploy.supervisor", "--config", config, "--duration", "5")

    line = _one_line(_run(*supervisor))
    assert line.startswith("supervisor: error: "), line
    assert str(creds) in line and f"chmod 700 {creds}" in line, line

    creds.chmod(0o700)  # the folder fixed, its files still 0666
    line = _one_line(_run(*supervisor))
    named = [p for p in creds.rglob("*") if f"chmod 600 {p}" in line]
    assert len(named) == 1, line
    assert str(named[0]) in line.split("chmod")[0], line

    # A service that reads its own secret refuses it too, started on its own: the operator's
    # e-stop with a password file others may read.
    for path in creds.rglob("*"):
        path.chmod(0o700 if path.is_dir() else 0o600)
    estop_password = password_file(creds, f"{prefix}/estop")
    estop_password.chmod(0o644)
    estop = ("services.controller", "estop", "engage", "--config", config, "--reason", "test")
    line = _one_line(_run(*estop))
    assert f"chmod 600 {estop_password}" in line, line

    # A key or the router's dictionary that group or others may change is refused as well.
    estop_password.chmod(0o600)
    users_file(creds).chmod(0o620)
    line = _one_line(_run(*supervisor))
    assert f"chmod 600 {users_file(creds)}" in line, line
    users_file(creds).chmod(0o600)
    key_file(creds, f"{prefix}/supervisor").chmod(0o604)
    tls = write_config(
        tmp_path,
        zenoh={"mode": "client", "auth": "certificate", "credentials_dir": str(creds),
               "endpoint": f"tls/127.0.0.1:{free_port()}"},
        supervisor={"services": ["controller"]}, stack={"prefix": prefix},
    )  # fmt: skip
    line = _one_line(_run("deploy.supervisor", "--config", tls, "--duration", "5"))
    assert f"chmod 600 {key_file(creds, f'{prefix}/supervisor')}" in line, line


def test_credentials_are_made_only_for_the_principals_the_stack_runs(tmp_path: Path) -> None:
    """Issue 38: a stack that runs the simulator had a `camera` secret, enough to put forged
    frames and depth on the camera's keys. `zstack credentials` now makes none for a service
    the config does not run, says so, and a stack that runs one later stops in one line."""
    creds = tmp_path / "credentials"
    secure = {"mode": "client", "auth": "password", "credentials_dir": str(creds)}
    (tmp_path / "sim").mkdir()
    sim = write_config(
        tmp_path / "sim", zenoh=secure, supervisor={"services": ["sim", "controller"]}
    )
    prefix = load_config(sim, environ={}).stack.prefix  # each config below the same robot's
    camera_p = f"{prefix}/camera"
    made = _run("deploy.credentials", "--config", sim)
    assert made.returncode == 0, made.stderr
    assert f"credentials: {camera_p}: not made, the config runs no camera service" in made.stderr
    assert not password_file(creds, camera_p).exists()
    assert not key_file(creds, camera_p).exists()

    # The camera's process cannot join: it has no secret.
    line = _one_line(_run("services.camera", "serve", "--config", sim))
    assert f"{password_file(creds, camera_p)} is missing" in line, line
    # The stack it was made for starts on it: each service ready, then stopped cleanly. (A
    # fixed --duration could end before a loaded machine had started them: seen in CI.)
    log_path = tmp_path / "sim.log"
    with log_path.open("wb") as log:
        env = {k: v for k, v in os.environ.items() if not k.startswith("STACK__")}
        proc = start_supervisor(sim, log, env)
        try:
            wait_for(
                lambda: "sim:ready controller:ready" in log_path.read_text(errors="replace"),
                120,
                "the stack on the credentials made for it",
            )
        finally:
            stopped = stop_supervisor(proc, 60)
    assert stopped and proc.returncode == 0, log_path.read_text(errors="replace")[-2000:]

    # A config that runs a camera stops before it starts anything, with passwords and with
    # certificates, in one line naming the command that makes them again.
    tls = {**secure, "auth": "certificate", "endpoint": f"tls/127.0.0.1:{free_port()}"}
    for name, table in (("camera", secure), ("camera_tls", tls)):
        (tmp_path / name).mkdir()
        camera = write_config(
            tmp_path / name,
            zenoh=table,
            supervisor={"services": ["camera", "controller"]},
            stack={"prefix": prefix},
        )
        line = _one_line(_run("deploy.supervisor", "--config", camera, "--duration", "3"))
        assert line.startswith("supervisor: error: "), line
        assert f"no principal {camera_p} " in line, line
        assert f"`zstack credentials --config {camera} --force`" in line, line
