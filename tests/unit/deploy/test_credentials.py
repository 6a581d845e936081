from __future__ import annotations

import ipaddress
import json
import stat
import sys
from pathlib import Path

import pytest
import zenoh
from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID

from common.certificates import server_capable, serves_tls
from common.errors import ConfigError
from common.lifecycle import run_main
from common.security import (
    ROUTER_PRINCIPAL,
    ca_file,
    ca_key_file,
    cert_file,
    key_file,
    password_file,
    stack_principals,
    users_file,
    viewer_token_file,
)
from common.settings import REPO_ROOT
from common.zenoh_bus import zenoh_config
from deploy import credentials
from deploy.credentials import DEFAULT_PRINCIPALS as PRINCIPALS  # the default stack's names
from deploy.credentials import generate
from stack.config_file import load_config
from tests.unit.common.test_certificates import old_style
from tools.launch import free_port

#: The default stack's router: each stack's is <stack.prefix>/supervisor.
ROUTER = f"stack/{ROUTER_PRINCIPAL}"
HOSTS = ("robot.local", "10.0.0.5")


@pytest.fixture(scope="module")
def creds(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Path]]:
    directory = tmp_path_factory.mktemp("creds") / "secrets"
    return directory, generate(directory, HOSTS, days=30)


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _cert(path: Path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def test_writes_every_file_with_private_modes(creds: tuple[Path, list[Path]]) -> None:
    directory, written = creds
    assert _mode(directory) == 0o700
    secret = [users_file(directory), viewer_token_file(directory), ca_key_file(directory)]
    public = [ca_file(directory)]
    for p in PRINCIPALS:
        secret += [password_file(directory, p), key_file(directory, p)]
        public.append(cert_file(directory, p))
    assert sorted(written) == sorted(secret + public)
    assert sorted(p for p in directory.rglob("*") if p.is_file()) == sorted(written)
    assert _mode(directory / "stack") == 0o700  # the default robot's subfolder
    assert {path.name: _mode(path) for path in secret} == {path.name: 0o600 for path in secret}
    assert all(_mode(path) & 0o022 == 0 for path in public)  # readable, never writable by others


def test_users_file_has_every_principal_and_its_password(creds: tuple[Path, list[Path]]) -> None:
    directory, _ = creds
    users = dict(line.split(":", 1) for line in users_file(directory).read_text().splitlines())
    assert list(users) == list(PRINCIPALS)
    for p in PRINCIPALS:
        password = password_file(directory, p).read_text()
        assert password.endswith("\n") and password.count("\n") == 1
        assert users[p] == password.strip()
        assert len(users[p]) >= 32  # token_urlsafe(24): 192 random bits
    assert len(set(users.values())) == len(PRINCIPALS)


def test_certificates_name_their_principal_and_are_signed_by_the_ca(
    creds: tuple[Path, list[Path]],
) -> None:
    directory, _ = creds
    ca = _cert(ca_file(directory))
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    ca_key = serialization.load_pem_private_key(ca_key_file(directory).read_bytes(), None)
    assert ca_key.public_key() == ca.public_key()
    for p in PRINCIPALS:
        cert = _cert(cert_file(directory, p))
        names = cert.subject.get_attributes_for_oid(x509.NameOID.COMMON_NAME)
        assert [n.value for n in names] == [p]
        cert.verify_directly_issued_by(ca)  # raises if the signature or issuer is wrong
        assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
        key = serialization.load_pem_private_key(key_file(directory, p).read_bytes(), None)
        assert key.public_key() == cert.public_key()
        days = (cert.not_valid_after_utc - cert.not_valid_before_utc).days
        assert 30 <= days <= 31


def test_only_the_supervisors_certificate_names_hosts_and_serves(
    creds: tuple[Path, list[Path]],
) -> None:
    directory, _ = creds
    router = _cert(cert_file(directory, ROUTER))
    san = router.extensions.get_extension_for_class(x509.SubjectAlternativeName)
    assert san.value.get_values_for_type(x509.DNSName) == ["localhost", "robot.local"]
    assert san.value.get_values_for_type(x509.IPAddress) == [
        ipaddress.ip_address("127.0.0.1"),
        ipaddress.ip_address("10.0.0.5"),
    ]
    # Its router also connects to another host's router, as a client.
    assert _purposes(router) == [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
    assert serves_tls(router)
    for p in PRINCIPALS:
        if p == ROUTER:
            continue
        cert = _cert(cert_file(directory, p))
        with pytest.raises(x509.ExtensionNotFound):
            cert.extensions.get_extension_for_class(x509.SubjectAlternativeName)
        assert _purposes(cert) == [ExtendedKeyUsageOID.CLIENT_AUTH], p
        assert not serves_tls(cert), p
    assert server_capable(directory) == []


def _roles(creds: Path) -> list[str]:
    """The users of ``creds``' dictionary by role: each of the default stack's, ``stack/<role>``
    (common/security.py), the router's ``stack/supervisor`` too."""
    users = [line.split(":", 1)[0] for line in users_file(creds).read_text().splitlines()]
    assert all(u.startswith("stack/") for u in users), users
    return [u.removeprefix("stack/") for u in users]


def _purposes(cert: x509.Certificate) -> list[x509.ObjectIdentifier]:
    return list(cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value)


def test_old_server_capable_credentials_are_named_and_replaced_with_force(tmp_path: Path) -> None:
    generate(tmp_path)
    old_style(tmp_path, "stack/viewer")
    old_style(tmp_path, "stack/camera")
    with pytest.raises(
        ConfigError, match=r"certificates of stack/camera, stack/viewer could.*--force"
    ):
        generate(tmp_path)
    generate(tmp_path, force=True)
    assert server_capable(tmp_path) == []


def test_an_existing_open_folder_and_files_become_private(tmp_path: Path) -> None:
    directory = tmp_path / "secrets"
    directory.mkdir()
    directory.chmod(0o777)
    (directory / "stack").mkdir(mode=0o777)
    password_file(directory, "stack/camera").write_text("old\n")
    password_file(directory, "stack/camera").chmod(0o666)
    generate(directory, force=True)
    assert _mode(directory) == 0o700 and _mode(directory / "stack") == 0o700
    assert _mode(password_file(directory, "stack/camera")) == 0o600
    assert _mode(users_file(directory)) == 0o600


def test_modes_do_not_depend_on_the_umask_and_pass_the_start_up_check(tmp_path: Path) -> None:
    import os

    from common.credential_modes import check_credentials_folder

    directory = tmp_path / "secrets"
    old = os.umask(0)  # the loosest: mkdir and open would give 0777 and 0666
    try:
        written = generate(directory)
    finally:
        os.umask(old)
    assert _mode(directory) == 0o700
    assert {_mode(p) for p in written if p.suffix != ".pem"} == {0o600}
    assert {_mode(p) for p in written if p.suffix == ".pem"} == {0o644}
    check_credentials_folder(directory)  # what the supervisor checks before it starts


def test_a_link_in_the_folder_is_not_followed(tmp_path: Path) -> None:
    directory, elsewhere = tmp_path / "secrets", tmp_path / "elsewhere"
    (directory / "stack").mkdir(parents=True)
    password_file(directory, ROUTER).symlink_to(elsewhere)
    with pytest.raises(ConfigError, match=r"cannot write .*supervisor.password"):
        generate(directory, force=True)
    assert not elsewhere.exists()


def test_another_ca_does_not_verify(creds: tuple[Path, list[Path]], tmp_path: Path) -> None:
    directory, _ = creds
    generate(tmp_path)
    other_ca = _cert(ca_file(tmp_path))
    with pytest.raises(InvalidSignature):  # same issuer name, a different key
        _cert(cert_file(directory, "stack/controller")).verify_directly_issued_by(other_ca)


def test_refuses_to_overwrite_without_force(tmp_path: Path) -> None:
    generate(tmp_path)
    before = users_file(tmp_path).read_text()
    with pytest.raises(ConfigError, match=r"already exist.*--force"):
        generate(tmp_path)
    assert users_file(tmp_path).read_text() == before
    password_file(tmp_path, "stack/camera").chmod(0o644)
    generate(tmp_path, force=True)
    assert users_file(tmp_path).read_text() != before
    assert _mode(password_file(tmp_path, "stack/camera")) == 0o600


@pytest.mark.parametrize(("hosts", "days"), [(("bad host",), 30), (("tcp/x:1",), 30), ((), 0)])
def test_rejects_bad_hosts_and_days(tmp_path: Path, hosts: tuple[str, ...], days: int) -> None:
    with pytest.raises(ConfigError):
        generate(tmp_path / "s", hosts, days)
    assert not (tmp_path / "s").exists()


def test_cli_refuses_existing_with_one_line_and_exit_2(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(sys, "argv", ["credentials", "--dir", str(tmp_path), "--host", "::1"])
    with pytest.raises(SystemExit) as first:
        run_main(credentials.main, "credentials")
    assert first.value.code == 0
    assert 'auth = "password" or "certificate"' in capsys.readouterr().err
    with pytest.raises(SystemExit) as second:
        run_main(credentials.main, "credentials")
    assert second.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("credentials: error: ")


#: A camera robot's services (the default, as deploy/stack.toml, is the simulator's stack).
CAMERA_ROBOT = '[supervisor]\nservices = ["camera", "detector", "controller", "metrics"]\n'


def test_cli_makes_a_principal_per_camera_of_the_config(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    creds = tmp_path / "creds"
    config = tmp_path / "three.toml"
    config.write_text(
        f'[zenoh]\ncredentials_dir = "{creds}"\n[stack]\ncamera = "front"\n'
        "[cameras.rear]\nmount_yaw_deg = 180.0\n[cameras.left]\nmount_yaw_deg = 90.0\n"
        + CAMERA_ROBOT
    )
    monkeypatch.setattr(sys, "argv", ["credentials", "--config", str(config)])
    with pytest.raises(SystemExit) as done:
        run_main(credentials.main, "credentials")
    assert done.value.code == 0, capsys.readouterr().err
    # The config runs a camera robot's services: each camera, the detector, the controller,
    # the metrics; with the router and the tools, 10 principals; no sim, ros2 or viewer.
    assert "wrote 10 passwords" in capsys.readouterr().err
    users = _roles(creds)
    assert users == [
        "supervisor", "recorder", "camera", "camera_rear", "camera_left", "detector",
        "controller", "metrics", "estop", "observer",
    ]  # fmt: skip
    ca = _cert(ca_file(creds))
    for p in ("stack/camera_rear", "stack/camera_left"):
        assert _mode(password_file(creds, p)) == 0o600
        cert = _cert(cert_file(creds, p))
        cert.verify_directly_issued_by(ca)
        assert [n.value for n in cert.subject.get_attributes_for_oid(x509.NameOID.COMMON_NAME)] == [
            p
        ]
        assert _purposes(cert) == [ExtendedKeyUsageOID.CLIENT_AUTH]  # never the router's
    # Again without --force: refused, in one line, the folder kept.
    with pytest.raises(SystemExit) as again:
        run_main(credentials.main, "credentials")
    assert again.value.code == 2
    assert capsys.readouterr().err.count("\n") == 1
    # An old-style further camera's certificate is found like any other.
    old_style(creds, "stack/camera_rear")
    assert server_capable(creds) == ["stack/camera_rear"]


def test_cli_makes_a_principal_per_worker_and_for_other_hosts_workers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    creds = tmp_path / "creds"
    config = tmp_path / "robot.toml"
    config.write_text(
        f'[zenoh]\ncredentials_dir = "{creds}"\n[detector]\nworkers = 2\nworker_id = "b"\n'
        + CAMERA_ROBOT
    )
    argv = ["credentials", "--config", str(config), "--worker", "detector_a"]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as done:
        run_main(credentials.main, "credentials")
    assert done.value.code == 0
    assert "wrote 10 passwords" in capsys.readouterr().err
    users = _roles(creds)
    workers = ("detector_b", "detector_b_2", "detector_a")
    assert users == [
        p
        for p in stack_principals("front", workers)
        if p not in ("sim", "ros2", "depthscan", "viewer")
    ]
    assert "detector" not in users
    ca = _cert(ca_file(creds))
    for p in workers:
        cert = _cert(cert_file(creds, f"stack/{p}"))
        cert.verify_directly_issued_by(ca)
        assert _purposes(cert) == [ExtendedKeyUsageOID.CLIENT_AUTH]
    # A name no worker can have: one line, exit 2.
    monkeypatch.setattr(sys, "argv", [*argv[:3], "--worker", "rogue", "--force"])
    with pytest.raises(SystemExit) as bad:
        run_main(credentials.main, "credentials")
    assert bad.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--worker 'rogue'" in err


@pytest.mark.integration
def test_mtls_router_admits_only_clients_with_a_certificate(
    creds: tuple[Path, list[Path]],
) -> None:
    directory, _ = creds
    endpoint = f"tls/127.0.0.1:{free_port()}"

    def config(mode: str, tls: dict[str, object], **endpoints: list[str]) -> zenoh.Config:
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(mode))
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("listen/endpoints", json.dumps(endpoints.get("listen", [])))
        conf.insert_json5("connect/endpoints", json.dumps(endpoints.get("connect", [])))
        tls = {"root_ca_certificate": str(ca_file(directory)), **tls}
        conf.insert_json5("transport/link/tls", json.dumps(tls))
        return conf

    router_tls = {
        "listen_private_key": str(key_file(directory, ROUTER)),
        "listen_certificate": str(cert_file(directory, ROUTER)),
        "enable_mtls": True,
    }
    client_tls = {
        "connect_private_key": str(key_file(directory, "stack/controller")),
        "connect_certificate": str(cert_file(directory, "stack/controller")),
        "enable_mtls": True,  # without it the client never presents its certificate
    }
    with zenoh.open(config("router", router_tls, listen=[endpoint])):
        with zenoh.open(config("client", client_tls, connect=[endpoint])) as client:
            assert str(client.zid())
        with pytest.raises(zenoh.ZError):
            zenoh.open(config("client", {}, connect=[endpoint]))


def test_cli_makes_a_principal_for_the_workers_the_config_links_to(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    creds = tmp_path / "creds"
    config = tmp_path / "robot.toml"
    config.write_text(
        f'[zenoh]\nmode = "client"\nauth = "certificate"\nendpoint = "tls/10.0.0.2:7448"\n'
        f'credentials_dir = "{creds}"\nremote_principals = ["detector_a"]\n'
        '[detector]\nworker_id = "b"\n' + CAMERA_ROBOT
    )
    monkeypatch.setattr(sys, "argv", ["credentials", "--config", str(config)])
    with pytest.raises(SystemExit) as done:
        run_main(credentials.main, "credentials")
    assert done.value.code == 0, capsys.readouterr().err
    users = _roles(creds)
    assert users == [
        p
        for p in stack_principals("front", ("detector_b", "detector_a"))
        if p not in ("sim", "ros2", "depthscan", "viewer")
    ]


def _cli(monkeypatch: pytest.MonkeyPatch, *argv: str | Path) -> int:
    monkeypatch.setattr(sys, "argv", ["credentials", *map(str, argv)])
    with pytest.raises(SystemExit) as done:
        run_main(credentials.main, "credentials")
    return int(done.value.code or 0)


def _secure(path: Path, creds: Path, services: list[str], **zenoh_table: str) -> Path:
    """A secure config of the default stack that runs ``services``."""
    table = "".join(f'{k} = "{v}"\n' for k, v in zenoh_table.items())
    path.write_text(
        f'extends = "{REPO_ROOT / "deploy" / "secure.toml"}"\n'
        f'[zenoh]\ncredentials_dir = "{creds}"\n{table}'
        f"[supervisor]\nservices = {json.dumps(services)}\n"
    )
    return path


def test_a_simulator_stack_gets_no_camera_secret_and_the_command_says_why(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from stack.hub import check_credentials

    creds = tmp_path / "creds"
    sim = _secure(tmp_path / "sim.toml", creds, ["sim", "detector", "controller", "metrics"])
    assert _cli(monkeypatch, "--config", sim) == 0
    err = capsys.readouterr().err
    assert all(line.startswith("credentials: ") for line in err.splitlines()), err
    made = ["supervisor", "recorder", "sim", "detector", "controller", "metrics", "estop",
            "observer"]  # fmt: skip
    users = _roles(creds)
    assert users == made
    for p in ("camera", "ros2", "viewer"):
        n = f"stack/{p}"
        for path in (password_file(creds, n), key_file(creds, n), cert_file(creds, n)):
            assert not path.exists(), path
        line = f"credentials: {n}: not made, the config runs no {p} service (supervisor.services)"
        assert f"{line}\n" in err, err
    assert (
        "made for stack/supervisor (the routers); stack/sim, stack/detector, stack/controller, "
        "stack/metrics (supervisor.services); stack/recorder, stack/estop, stack/observer "
        "(the tools" in err
    ), err
    assert f"`zstack credentials --config {sim} --force`" in err, err
    config = load_config(sim, environ={})
    check_credentials(config)  # the supervisor accepts them
    # The attack of issue 38: nobody can join as the camera, which the stack does not run.
    with pytest.raises(ConfigError, match=r"stack/camera.password is missing"):
        zenoh_config(config.zenoh, config.principal("camera"))


def test_a_service_added_later_stops_the_stack_in_one_line_naming_the_command(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from stack.hub import check_credentials

    creds = tmp_path / "creds"
    services = ["sim", "detector", "controller"]
    assert _cli(monkeypatch, "--config", _secure(tmp_path / "sim.toml", creds, services)) == 0
    tls = {"auth": "certificate", "endpoint": f"tls/127.0.0.1:{free_port()}"}
    for name, table in (("camera.toml", {}), ("camera-tls.toml", tls)):
        path = _secure(tmp_path / name, creds, ["camera", *services[1:], "viewer"], **table)
        with pytest.raises(ConfigError) as refused:
            check_credentials(load_config(path, environ={}))
        line = str(refused.value)
        assert "\n" not in line and "no principal stack/camera, stack/viewer " in line, line
        assert f"make them again with `zstack credentials --config {path} --force`" in line
    # Made again for that config, the stack starts.
    assert _cli(monkeypatch, "--config", path, "--force") == 0
    check_credentials(load_config(path, environ={}))
    assert (
        password_file(creds, "stack/camera").exists() and cert_file(creds, "stack/viewer").exists()
    )
    capsys.readouterr()


def test_force_for_a_config_that_runs_less_removes_the_secrets_it_no_longer_needs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    creds = tmp_path / "creds"
    camera = _secure(tmp_path / "camera.toml", creds, ["camera", "detector", "controller"])
    assert _cli(monkeypatch, "--config", camera, "--worker", "detector_a") == 0
    old_style(creds, "stack/camera")  # as an older version made it: it could serve as the router
    (creds / "notes.txt").write_text("mine\n")
    outside = tmp_path / "outside.password"
    outside.write_text("kept\n")
    password_file(creds, "stack/detector_a").unlink()
    password_file(creds, "stack/detector_a").symlink_to(outside)
    capsys.readouterr()

    sim = _secure(tmp_path / "sim.toml", creds, ["sim", "detector", "controller"])
    assert _cli(monkeypatch, "--config", sim, "--force") == 0
    err = capsys.readouterr().err
    for p in ("stack/camera", "stack/detector_a"):
        for path in (password_file(creds, p), key_file(creds, p), cert_file(creds, p)):
            assert not path.is_symlink() and not path.exists(), path
    assert outside.read_text() == "kept\n"  # a link is removed, never what it points to
    assert (creds / "notes.txt").exists() and viewer_token_file(creds).exists()
    assert (
        "credentials: stack/camera: not made, the config runs no camera service "
        "(supervisor.services); its earlier secrets removed\n" in err
    ), err
    assert (
        "credentials: stack/detector_a: earlier secrets removed, neither the config nor" in err
    ), err
    assert server_capable(creds) == []  # the old certificate no longer stops TLS sessions
    assert password_file(creds, "stack/sim").exists()
