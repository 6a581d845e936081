from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization

from common.certificates import server_capable
from common.errors import ConfigError
from common.security import ROUTER_PRINCIPAL, ca_key_file, cert_file, key_file, qualified
from common.settings import ZenohSettings
from common.zenoh_bus import zenoh_config
from deploy.credentials import generate

#: The router of the default stack: each stack's router is <stack.prefix>/supervisor.
ROUTER = qualified("stack", ROUTER_PRINCIPAL)


def old_style(directory: Path, principal: str) -> None:
    """Re-issue ``principal``'s certificate as versions before this one did: host names and
    server authentication, like the supervisor's."""
    ca_key = serialization.load_pem_private_key(ca_key_file(directory).read_bytes(), None)
    key = serialization.load_pem_private_key(key_file(directory, principal).read_bytes(), None)
    router = x509.load_pem_x509_certificate(cert_file(directory, ROUTER).read_bytes())
    purposes = router.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    names = router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    builder = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(x509.NameOID.COMMON_NAME, principal)]))
        .issuer_name(router.issuer)
        .public_key(key.public_key())  # type: ignore[arg-type]
        .serial_number(x509.random_serial_number())
        .not_valid_before(router.not_valid_before_utc)
        .not_valid_after(router.not_valid_after_utc)
        .add_extension(purposes, critical=False)
        .add_extension(names, critical=False)
    )
    cert = builder.sign(ca_key, hashes.SHA256())  # type: ignore[arg-type]
    cert_file(directory, principal).write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def test_older_credentials_are_named_in_principal_order(tmp_path: Path) -> None:
    generate(tmp_path)
    assert server_capable(tmp_path) == []
    old_style(tmp_path, "stack/viewer")
    old_style(tmp_path, "stack/camera")
    assert server_capable(tmp_path) == ["stack/camera", "stack/viewer"]


def test_a_missing_or_unreadable_certificate_is_not_counted(tmp_path: Path) -> None:
    generate(tmp_path)
    cert_file(tmp_path, "stack/camera").unlink()
    cert_file(tmp_path, "stack/viewer").write_text("not a certificate")
    assert server_capable(tmp_path) == []


@pytest.mark.parametrize("principal", ["stack/estop", ROUTER])
def test_no_session_over_tls_with_older_credentials(tmp_path: Path, principal: str) -> None:
    generate(tmp_path)
    old_style(tmp_path, "stack/viewer")
    tls = dataclasses.replace(
        ZenohSettings(),
        mode="client",
        auth="password",
        credentials_dir=str(tmp_path),
        endpoint="tls/127.0.0.1:7447",
    )
    access = {} if principal == ROUTER else None
    with pytest.raises(ConfigError, match=r"certificates of stack/viewer could.*--force"):
        zenoh_config(tls, principal, access=access)
    # Without TLS no certificate is used, so nothing is checked.
    zenoh_config(dataclasses.replace(tls, endpoint="tcp/127.0.0.1:7447"), principal, access=access)
