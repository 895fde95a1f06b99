"""Command line interface: ``o3d-rpointhop <command> ...``, one module per command.

Each command module declares its options (``add_parser``) and runs the library
(``run``), importing it lazily so that ``--help`` answers at once; the options several
commands share are declared once in :mod:`._common`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from .._version import __version__
from . import benchmark, config, demo, describe, evaluate, fit, reconstruct, register, view
from ._common import (
    EXIT_CODES,
    EXIT_ERROR,
    EXIT_OK,
    EXIT_UNRELIABLE,
    EXIT_USAGE,
    MAX_OUTPUT_BYTES,
    PROG,
    CommandError,
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
COMMANDS = (demo, register, evaluate, view, config, benchmark, reconstruct, fit, describe)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Rotation-invariant R-PointHop descriptors and registration for Open3D.",
        epilog=EXIT_CODES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("--debug", action="store_true", help="on an error, show the full traceback")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    class _Sub:  # every command's --help lists the exit statuses too
        @staticmethod
        def add_parser(name, **kwargs):
            kwargs.setdefault("epilog", EXIT_CODES)
            kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
            return commands.add_parser(name, **kwargs)

    for command in COMMANDS:
        command.add_parser(_Sub())
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
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
