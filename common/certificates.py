"""Which certificates could serve as the router's: only the supervisor's may (docs/security.md).

Credentials made before this rule gave every principal a certificate that names the hosts and
allows server authentication, so any of them could stand in for the router. Sessions and
``zstack credentials`` refuse such a folder until it is made again with ``--force``.
"""

from __future__ import annotations

from pathlib import Path

from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID

from common.errors import ConfigError
from common.security import ca_file, is_router


def serves_tls(cert: x509.Certificate) -> bool:
    """Whether ``cert`` may serve a TLS listener: it allows server authentication or names a
    host (as every certificate made before this rule did)."""
    try:
        purposes = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    except x509.ExtensionNotFound:
        return True  # no restriction: any purpose
    try:
        cert.extensions.get_extension_for_class(x509.SubjectAlternativeName)
    except x509.ExtensionNotFound:
        return ExtendedKeyUsageOID.SERVER_AUTH in purposes
    return True


def server_capable(directory: Path) -> list[str]:
    """The principals other than a router (``<prefix>/supervisor``, each stack's) whose
    certificate in ``directory`` could serve as the router's (credentials made by an older
    version); unreadable files are skipped."""
    found = []
    # Every principal's certificate there, a further camera's (``camera_<name>``) too.
    # Each robot's in its subfolder (``site/robot1/camera.pem``): named by its path there.
    paths = sorted(directory.rglob("*.pem")) if directory.is_dir() else []
    for path in paths:
        p = path.relative_to(directory).with_suffix("").as_posix()
        if path == ca_file(directory) or is_router(p):  # a stack's router: <prefix>/supervisor
            continue
        if not path.is_file():
            continue
        try:
            cert = x509.load_pem_x509_certificate(path.read_bytes())
        except (OSError, ValueError):
            continue
        if serves_tls(cert):
            found.append(p)
    return found


def refuse_server_capable(directory: Path) -> None:
    """Raise ConfigError, one line, if ``directory`` holds credentials of the older kind."""
    if old := server_capable(directory):
        raise ConfigError(
            f"the credentials in {directory} were made by an older version: the "
            f"certificates of {', '.join(old)} could serve as the router; make them again "
            "with `zstack credentials --force` (docs/security.md)"
        )
