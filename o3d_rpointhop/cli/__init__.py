"""Command line interface: ``o3d-rpointhop <command> ...``, one module per command.

Each command module declares its options (``add_parser``) and runs the library
(``run``), importing it lazily; only the command being run declares all its options
(the others only their name and help line), so that ``--help`` and a command's own
``--help`` load only what they need. The options several commands share are declared
once in :mod:`._common`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from .._version import __version__
from . import (
    benchmark,
    config,
    demo,
    describe,
    evaluate,
    fit,
    poses,
    reconstruct,
    register,
    view,
)
from ._common import (
    EXIT_CODES,
    EXIT_ERROR,
    EXIT_OK,
    EXIT_UNRELIABLE,
    EXIT_USAGE,
    MAX_OUTPUT_BYTES,
    PROG,
    CommandError,
    UsageError,
)

__all__ = [
    "EXIT_CODES",
    "EXIT_ERROR",
    "EXIT_OK",
    "EXIT_UNRELIABLE",
    "EXIT_USAGE",
    "MAX_OUTPUT_BYTES",
    "CommandError",
    "build_parser",
    "main",
]

#: The commands, in the order ``--help`` lists them.
COMMANDS = (demo, register, evaluate, view, config, benchmark, reconstruct, poses, fit, describe)


class _Declared(Exception):
    """Raised once a command not being run has declared its name and help line."""


def _chosen(argv: Sequence[str] | None) -> str | None:
    """The command named on the command line (its first word that is not an option)."""
    words = sys.argv[1:] if argv is None else list(argv)
    return next((w for w in words if not w.startswith("-")), None)


def build_parser(
    argv: Sequence[str] | None = None, *, every: bool = False
) -> argparse.ArgumentParser:
    """The parser; with ``every`` (or for the command ``argv`` names) the commands'
    options are declared in full, otherwise only their names and help lines."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Rotation-invariant R-PointHop descriptors and registration for Open3D.",
        epilog=EXIT_CODES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("--debug", action="store_true", help="on an error, show the full traceback")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    chosen = _chosen(argv)

    class _Sub:  # every command's --help lists the exit statuses too
        @staticmethod
        def add_parser(name, **kwargs):
            kwargs.setdefault("epilog", EXIT_CODES)
            kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
            sub = commands.add_parser(name, **kwargs)
            if not every and name != chosen:
                raise _Declared
            return sub

    for command in COMMANDS:
        try:
            command.add_parser(_Sub())
        except _Declared:
            pass
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except UsageError as exc:
        if args.debug:
            raise
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except Exception as exc:
        if args.debug:
            raise
        expected = isinstance(
            exc, (CommandError, ValueError, FileNotFoundError, OSError, ImportError)
        )
        detail = "" if expected else f"unexpected {type(exc).__name__}: "
        hint = "" if expected else f" (please report it; '{PROG} --debug ...' shows where)"
        print(f"{PROG}: error: {detail}{exc}{hint}", file=sys.stderr)
        return EXIT_ERROR
