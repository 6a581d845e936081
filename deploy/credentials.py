"""python -m deploy.credentials [--config FILE] [--dir DIR] [--host ADDR ...] [--worker NAME ...]
                               [--robot FILE ...] [--force] [--days N]

Creates the credentials of the secure profile in DIR (default: the config's
``zenoh.credentials_dir``, ``secrets/``, git-ignored): a private CA, and for each principal the
config has a use for (stack.principals.running_principals) a random password, its line in the
router's ``user:password`` dictionary, and a key and certificate (common name = the principal's
name). A principal is named by whose it is (common/security.py): ``<stack.prefix>/<role>``
for a robot's (``stack/controller``, ``site/robot1/estop``), ``<pool>/<worker>`` for a
detector worker (``detector.pool_prefix``, or the stack's prefix), ``<stack.prefix>/supervisor``
for routers; its files lie at its name under DIR (``site/robot1/estop.password``), one subfolder
per robot. Those principals are the supervisor's, those of the processes of
``supervisor.services`` (one per camera, ``camera`` and ``camera_<name>``, when it runs
``camera``; one per detector worker, ``detector``, ``detector_2`` ... or
``detector_<worker_id>`` ..., when it runs ``detector``; the service's own otherwise), the
tools' (``recorder`` for record and play, ``estop``, ``observer``), and the other hosts'
(``zenoh.remote_principals``, and each --worker NAME: a detector worker another host runs,
``detector_a``), so that one set of credentials (one CA) serves a pool across hosts; each
--robot FILE adds another robot's (its config's) the same way, so that one run serves a site.
A principal of a service the config does not run (the ``camera`` of a stack that runs the
simulator) gets no secret, so nobody can log in as it; the command says which it made, and
which it left out and why, one line each (deploy/credential_names.py).
Only the supervisor's certificate can serve the TLS listener: it alone names ``localhost``,
``127.0.0.1`` and each --host and allows server authentication. Every other certificate names
no host and allows client authentication only, so a client that checks the router's name
refuses it. DIR and its subfolders are made 0700 and every secret 0600, whatever their
modes were; a symbolic link among them is refused. Existing credentials are kept unless
--force is given (needed, too, after adding a service, a camera or a worker to the config);
with --force every principal's password, key and certificate not made this time is removed
(an earlier config's, or an older version's named by role alone, now useless: not in the new
dictionary, signed by the old CA), and said so.
"""

from __future__ import annotations

import argparse
import datetime
import ipaddress
import os
import re
import secrets
import sys
from collections.abc import Sequence
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from common.certificates import refuse_server_capable
from common.cli import Command, add_config, service_main
from common.clock import utc_now
from common.errors import ConfigError
from common.keys import Keys
from common.lifecycle import run_main
from common.security import (
    PRINCIPALS,
    ROUTER_PRINCIPAL,
    ca_file,
    ca_key_file,
    cert_file,
    is_router,
    key_file,
    password_file,
    qualified,
    users_file,
    viewer_token_file,
)
from deploy.credential_names import (
    chosen_lines,
    credential_principals,
    credential_workers,
    remove_stale,
)
from stack.config_file import load_config

__all__ = [
    "chosen_lines",
    "credential_principals",
    "credential_workers",
    "generate",
    "remove_stale",
]

#: The principals :func:`generate` makes by default: a one-camera stack's, under the default
#: ``stack.prefix``.
DEFAULT_PRINCIPALS = tuple(qualified(Keys().prefix, p) for p in PRINCIPALS)

DEFAULT_DAYS = 825  # the longest validity that browsers and most TLS stacks still accept
DEFAULT_HOSTS = ("localhost", "127.0.0.1")
SECRET_MODE = 0o600
PUBLIC_MODE = 0o644
_HOSTNAME = re.compile(r"[A-Za-z0-9]([A-Za-z0-9.-]*[A-Za-z0-9])?")
# Back-date certificates a little so a peer whose clock runs slightly behind accepts them.
_CLOCK_SKEW = datetime.timedelta(minutes=5)

PrivateKey = ec.EllipticCurvePrivateKey


def _subject_names(hosts: tuple[str, ...]) -> list[x509.GeneralName]:
    """SubjectAltNames for ``localhost``, ``127.0.0.1`` and ``hosts``: IP or DNS, no repeats."""
    names: list[x509.GeneralName] = []
    for host in dict.fromkeys((*DEFAULT_HOSTS, *hosts)):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            if not _HOSTNAME.fullmatch(host):
                msg = f"--host {host!r} is neither an IP address nor a DNS name"
                raise ConfigError(msg) from None
            names.append(x509.DNSName(host))
    return names


def _new_key() -> PrivateKey:
    # ECDSA P-256: accepted by rustls (Zenoh's TLS) as PKCS#8, and small and fast.
    return ec.generate_private_key(ec.SECP256R1())


def _key_pem(key: PrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _builder(
    subject: str, issuer: x509.Name, key: PrivateKey, days: int
) -> x509.CertificateBuilder:
    now = utc_now()
    public_key = key.public_key()
    return (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
        .issuer_name(issuer)
        .public_key(public_key)
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - _CLOCK_SKEW)
        .not_valid_after(now + datetime.timedelta(days=days))
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(public_key), critical=False)
    )


def _key_usage(*, signs_certificates: bool) -> x509.KeyUsage:
    """A CA signs certificates and CRLs; a leaf signs TLS handshakes only."""
    return x509.KeyUsage(
        digital_signature=not signs_certificates,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=False,
        key_cert_sign=signs_certificates,
        crl_sign=signs_certificates,
        encipher_only=False,
        decipher_only=False,
    )


def _ca_certificate(key: PrivateKey, days: int) -> x509.Certificate:
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "zenoh-yolo-stack CA")])
    return (
        _builder("zenoh-yolo-stack CA", name, key, days)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(_key_usage(signs_certificates=True), critical=True)
        .sign(key, hashes.SHA256())
    )


def _leaf_certificate(
    principal: str,
    key: PrivateKey,
    ca: x509.Certificate,
    ca_key: PrivateKey,
    names: list[x509.GeneralName],
    days: int,
) -> x509.Certificate:
    """A certificate for ``principal``. The supervisor's serves the TLS listener (its host
    names, server authentication) and authenticates it when its router connects to another
    host's; every other principal's authenticates a client only and names no host, so no
    client accepts it as the router's."""
    authority = x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key())
    builder = (
        _builder(principal, ca.subject, key, days)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(_key_usage(signs_certificates=False), critical=True)
        .add_extension(authority, critical=False)
    )
    purposes = [ExtendedKeyUsageOID.CLIENT_AUTH]
    if is_router(principal):
        purposes.insert(0, ExtendedKeyUsageOID.SERVER_AUTH)
        builder = builder.add_extension(x509.SubjectAlternativeName(names), critical=False)
    return builder.add_extension(x509.ExtendedKeyUsage(purposes), critical=False).sign(
        ca_key, hashes.SHA256()
    )


def _write(path: Path, data: bytes, mode: int) -> Path:
    # O_NOFOLLOW: a link planted in the folder must not redirect a secret elsewhere.
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, mode)
    except OSError as exc:
        raise ConfigError(f"cannot write {path}: {exc.strerror}") from exc
    with os.fdopen(fd, "wb") as f:
        os.fchmod(f.fileno(), mode)  # with --force an existing file would keep its old mode
        f.write(data)
    return path


def _targets(directory: Path, principals: tuple[str, ...]) -> list[Path]:
    files = [users_file(directory), viewer_token_file(directory)]
    files += [ca_file(directory), ca_key_file(directory)]
    for p in principals:
        files += [password_file(directory, p), cert_file(directory, p), key_file(directory, p)]
    return files


def _folders(directory: Path, principals: Sequence[str]) -> None:
    """Make each principal's subfolder (``site/robot1`` for ``site/robot1/estop``) 0700, as
    ``directory``; ConfigError, one line, for one that is a symbolic link (a link planted
    there must not carry secrets elsewhere) or no folder."""
    for p in principals:
        folder = password_file(directory, p).parent
        for f in reversed((folder, *folder.parents)):
            if f != directory and directory not in f.parents:
                continue
            if f.is_symlink() or (f.exists() and not f.is_dir()):
                raise ConfigError(f"{f} is a symbolic link or not a folder: refused")
            f.mkdir(mode=0o700, exist_ok=True)
            f.chmod(0o700)


def generate(
    directory: Path,
    hosts: tuple[str, ...] = (),
    days: int = DEFAULT_DAYS,
    force: bool = False,
    principals: tuple[str, ...] = DEFAULT_PRINCIPALS,
) -> list[Path]:
    """Write passwords, the user dictionary, a CA and one certificate per principal into
    ``directory`` (created 0700, each robot's subfolder too; secrets 0600). ``principals``, by
    name (common/security.py): every principal of a one-camera stack under the default prefix
    by default; the command passes a config's :func:`credential_principals`. Returns the
    files written, in order."""
    if not any(is_router(p) for p in principals):
        raise ValueError(f"the principals must include a router's, <prefix>/{ROUTER_PRINCIPAL}")
    if days < 1:
        raise ConfigError(f"--days must be at least 1, got {days}")
    names = _subject_names(hosts)
    if not force:
        refuse_server_capable(directory)
    if not force and (existing := [f.name for f in _targets(directory, principals) if f.exists()]):
        raise ConfigError(
            f"credentials already exist in {directory} ({', '.join(existing[:3])}"
            f"{', ...' if len(existing) > 3 else ''}); pass --force to replace them"
        )
    if directory.exists() and not directory.is_dir():
        raise ConfigError(f"{directory} exists and is not a directory")
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    # mkdir's mode is reduced by the umask, and a folder that existed keeps its own mode.
    directory.chmod(0o700)
    _folders(directory, principals)

    written: list[Path] = []
    passwords = {p: secrets.token_urlsafe(24) for p in principals}
    for p, password in passwords.items():
        written.append(_write(password_file(directory, p), f"{password}\n".encode(), SECRET_MODE))
    users = "".join(f"{p}:{password}\n" for p, password in passwords.items())
    written.append(_write(users_file(directory), users.encode(), SECRET_MODE))
    token = f"{secrets.token_urlsafe(24)}\n".encode()
    written.append(_write(viewer_token_file(directory), token, SECRET_MODE))

    ca_key = _new_key()
    ca = _ca_certificate(ca_key, days)
    written.append(_write(ca_key_file(directory), _key_pem(ca_key), SECRET_MODE))
    ca_pem = ca.public_bytes(serialization.Encoding.PEM)
    written.append(_write(ca_file(directory), ca_pem, PUBLIC_MODE))
    for p in principals:
        key = _new_key()
        cert = _leaf_certificate(p, key, ca, ca_key, names, days)
        written.append(_write(key_file(directory, p), _key_pem(key), SECRET_MODE))
        pem = cert.public_bytes(serialization.Encoding.PEM)
        written.append(_write(cert_file(directory, p), pem, PUBLIC_MODE))
    return written


def say_written(
    directory: Path,
    hosts: tuple[str, ...],
    days: int,
    principals: tuple[str, ...] = DEFAULT_PRINCIPALS,
    chosen: Sequence[str] = (),
) -> None:
    """What :func:`generate` wrote, for whom (``chosen``: :func:`chosen_lines`), and how to use
    it, on stderr."""
    n = len(principals)
    names = ", ".join(dict.fromkeys((*DEFAULT_HOSTS, *hosts)))
    for line in (
        f"wrote {n} passwords and {users_file(directory).name} to {directory}",
        f"wrote a CA and {n} certificates (only the supervisor's serves, for {names}), "
        f"valid {days} days, to {directory}",
        *chosen,
        f'use in the stack config: [zenoh] auth = "password" or "certificate", '
        f'credentials_dir = "{directory}"',
    ):
        print(f"credentials: {line}", file=sys.stderr)


# --- the command line: python -m deploy.credentials (zstack credentials) ------------------------


def _credentials_arguments(p: argparse.ArgumentParser) -> None:
    add_config(p)  # its cameras name the camera principals; its credentials_dir the folder
    p.add_argument("--dir", type=Path, help="default: the config's zenoh.credentials_dir")
    p.add_argument(
        "--host",
        action="append",
        default=[],
        help="another name or IP address the supervisor is reached at (repeatable)",
    )
    p.add_argument(
        "--worker",
        action="append",
        default=[],
        help="a detector worker another host runs, by its name (detector_<worker_id>, "
        "detector_<worker_id>_2 ...): its principal too (repeatable)",
    )
    p.add_argument(
        "--robot",
        action="append",
        default=[],
        metavar="FILE",
        help="another robot's config: its principals too, under the same CA, in its own "
        "subfolder (repeatable: one run for a site's robots)",
    )
    p.add_argument("--force", action="store_true", help="replace existing credentials")
    p.add_argument("--days", type=int, default=DEFAULT_DAYS, help="certificate validity")


def _credentials(args: argparse.Namespace) -> int:
    config = load_config(args.config)
    robots = [load_config(path) for path in args.robot]
    directory: Path = (args.dir or config.zenoh.credentials_path).resolve()
    hosts = tuple(args.host)
    made, left_out = credential_principals(config, args.worker)
    for robot in robots:  # each further robot's principals, under the same CA
        theirs, their_left = credential_principals(robot)
        made = tuple(dict.fromkeys((*made, *theirs)))
        left_out.update(their_left)
    left_out = {p: why for p, why in left_out.items() if p not in made}
    generate(directory, hosts, args.days, args.force, made)
    removed = remove_stale(directory, made) if args.force else []
    options = [f"--dir {args.dir}"] if args.dir else []
    options += [f"--host {h}" for h in hosts] + [f"--worker {w}" for w in args.worker]
    options += [f"--robot {r}" for r in args.robot]
    again = "".join(f" {o}" for o in options)
    chosen = chosen_lines(config, made, left_out, removed, again, robots)
    say_written(directory, hosts, args.days, made, chosen)
    return 0


COMMANDS = [
    Command("credentials", "write the secure profile's credentials", _credentials_arguments,
            _credentials),
]  # fmt: skip


def main() -> int:
    return service_main(
        "python -m deploy.credentials", __doc__ or "", COMMANDS, default="credentials"
    )


if __name__ == "__main__":
    run_main(main, "credentials")
