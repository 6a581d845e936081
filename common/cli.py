"""One command-line shape for every entry point: ``python -m services.<name> COMMAND [options]``
and ``python -m tools.<name> COMMAND [options]``.

A service lists its commands; ``serve`` (run the service on the bus) comes first and is the
default, so ``python -m services.camera --config X`` and ``... serve --config X`` are the same,
and the supervisor starts every service as ``python -m services.<name> serve --config FILE``.
A module of one command may leave its name out: its options are then the module's own, and its
usage and help name the module (``python -m deploy.supervisor --duration 5``, ``zstack run``).
Results meant for programs go to stdout; progress and status go to stderr.

A module's ``__main__`` lists its :class:`Command` entries and calls :func:`service_main`; each
command's ``run`` turns the parsed arguments into typed values (keyword arguments or a frozen
options dataclass of the module that does the work, filled by :func:`options_from`) and calls
it: no namespace goes further.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

_Options = TypeVar("_Options", bound="DataclassInstance")

CONFIG_HELP = "stack config (default deploy/stack.toml)"

# Set by ``zstack`` before it runs a module's main: (the module's subcommand, or "" for a
# module without any, and the words a user typed: "zstack scenarios"), so that usage lines and
# help name the command the user ran, not the module behind it.
_invoked_as: tuple[str, str] | None = None


def invoked_as(subcommand: str, words: str) -> None:
    global _invoked_as
    _invoked_as = (subcommand, words)


def program(default: str, subcommand: str = "") -> str:
    """The name a parser shows: ``default`` (``python -m services.sim``, or that plus
    ``subcommand``), or what the user typed when ``zstack`` ran it."""
    if _invoked_as is not None:
        if _invoked_as[0] == subcommand:
            return _invoked_as[1]
        if not subcommand:
            return "zstack"
    return f"{default} {subcommand}" if subcommand else default


@dataclass(frozen=True, slots=True)
class Command:
    """One subcommand: its name, one line of help, its arguments and what runs it."""

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def add_config(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", help=CONFIG_HELP)


def options_from(cls: type[_Options], args: argparse.Namespace, **values: Any) -> _Options:
    """A command's options dataclass ``cls``: ``values`` for the fields named there, the
    parsed argument of the same name for every other (one missing is an AttributeError)."""
    taken = {f.name: getattr(args, f.name) for f in fields(cls) if f.name not in values}
    return cls(**taken, **values)


def with_default(argv: Sequence[str], names: Sequence[str], default: str = "serve") -> list[str]:
    """``argv`` with ``default`` put first when it names no command (nor asks for help)."""
    out = list(argv)
    if not out or (out[0] not in names and out[0] not in ("-h", "--help")):
        out.insert(0, default)
    return out


def build_parser(
    prog: str, description: str, commands: Sequence[Command]
) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=program(prog),
        description=description,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for c in commands:
        p = sub.add_parser(c.name, help=c.help, description=c.help, prog=program(prog, c.name))
        c.add_arguments(p)
        p.set_defaults(run=c.run)
    return parser


def build_single_parser(prog: str, description: str, command: Command) -> argparse.ArgumentParser:
    """The parser of a module of one command run without naming it: the command's options are
    the module's own."""
    parser = argparse.ArgumentParser(
        prog=program(prog),
        description=description,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    command.add_arguments(parser)
    parser.set_defaults(run=command.run)
    return parser


def service_main(
    prog: str,
    description: str,
    commands: Sequence[Command],
    argv: Sequence[str] | None = None,
    default: str | None = "serve",
) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``) and run the chosen command; ``default`` is
    the command run when none is named (a tool has none: ``default=None``)."""
    args = list(sys.argv[1:] if argv is None else argv)
    names = [c.name for c in commands]
    if default is not None and names == [default] and (not args or args[0] != default):
        parser = build_single_parser(prog, description, commands[0])
    else:
        if default is not None:
            args = with_default(args, names, default)
        parser = build_parser(prog, description, commands)
    parsed = parser.parse_args(args)
    run: Callable[[argparse.Namespace], int] = parsed.run
    return run(parsed)


def replay_rate(text: str) -> float:
    rate = float(text)
    if not 0.01 <= rate <= 100:
        raise argparse.ArgumentTypeError(f"the rate must be within 0.01..100, got {text}")
    return rate
