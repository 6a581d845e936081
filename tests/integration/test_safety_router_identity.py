"""Clients accept only the supervisor's router (docs/security.md, "The secure profile").

A fake router, a real Zenoh router session on the stack's TLS endpoint with the same CA and
access rules as the supervisor's but presenting another principal's certificate (the viewer's),
answers the e-stop as a controller would. The e-stop CLI must refuse it; the same router with
the supervisor's certificate is accepted.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from common.clock import now
from common.contracts import ControllerState
from common.keys import Keys
from common.messages import ControllerStatus, Header
from common.zenoh_bus import HUB_PRINCIPAL, zenoh_config
from stack.config_file import load_config
from stack.hub import hub_access
from tests.integration.conftest import REPO, credentials_for, write_config
from tools.launch import free_port

pytestmark = pytest.mark.integration


def _router(config_path: Path, principal: str) -> zenoh.Session:
    """A router on the stack's endpoint with the supervisor's config but ``principal``'s
    certificate, which acknowledges every e-stop as the controller would."""
    config = load_config(config_path, environ={})
    keys = Keys(config.stack.prefix)
    conf = zenoh_config(config.zenoh, principal, access=hub_access(config))
    session = zenoh.open(conf)

    def acknowledge(_: zenoh.Sample) -> None:
        header = Header(stamp_ns=now().wall_ns, frame_id="", seq=1, source="controller")
        state = ControllerState.ESTOP
        status = ControllerStatus(header=header, mode="follow", target="", state=state)
        session.put(keys.controller_status(), status.encode())

    session.declare_subscriber(keys.estop(), acknowledge)
    return session


def _engage(config_path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "services.controller", "estop", "engage",
         "--config", str(config_path), "--reason", "test"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip


@pytest.mark.parametrize("auth", ["password", "certificate"])
def test_estop_cli_refuses_a_router_with_another_principals_certificate(
    tmp_path: Path, auth: str
) -> None:
    creds = tmp_path / "credentials"
    prefix = credentials_for(creds)
    endpoint = f"tls/127.0.0.1:{free_port()}"
    table = {"mode": "client", "auth": auth, "credentials_dir": str(creds), "endpoint": endpoint}
    config_path = write_config(tmp_path, zenoh=table, stack={"prefix": prefix})

    with _router(config_path, f"{prefix}/viewer"):
        done = _engage(config_path)
    assert "e-stop engaged" not in done.stdout + done.stderr, "accepted the viewer as the router"
    assert done.returncode != 0
    assert done.stderr.count("\n") == 1, done.stderr
    for word in (endpoint, f"'{prefix}/estop'", f"{auth} auth"):
        assert word in done.stderr, done.stderr

    with _router(config_path, load_config(config_path, environ={}).principal(HUB_PRINCIPAL)):
        done = _engage(config_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "e-stop engaged\n"
