"""Command line interface: ``o3d-rpointhop <command> ...``, one module per command.

Each command module declares its options (``add_parser``) and runs the library
(``run``), importing it lazily; only the command being run declares all its options
(the others only their name and help line), so that ``--help`` and a command's own
``--help`` load only what they need. The options several commands share are declared
once in :mod:`._common`.
"""

from __future__ import annotations

import argparse
import logging
import sys
import warnings
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
    EXIT_UNTRUSTED,
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
    "EXIT_UNTRUSTED",
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
        allow_abbrev=False,
        description="Rotation-invariant R-PointHop descriptors and registration for Open3D.",
        epilog=EXIT_CODES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    _add_output_options(parser, 0, False)
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", help="what to do (COMMAND --help)"
    )

    chosen = _chosen(argv)

    class _Sub:  # every command's --help lists the exit statuses too
        @staticmethod
        def add_parser(name, **kwargs):
            kwargs.setdefault("epilog", EXIT_CODES)
            kwargs.setdefault("allow_abbrev", False)  # --voxel is not --voxel-size
            kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
            sub = commands.add_parser(name, **kwargs)
            if not every and name != chosen:
                raise _Declared
            # After the command too (reconstruct scans/ -v), as people type them.
            _add_output_options(sub, argparse.SUPPRESS, argparse.SUPPRESS)
            return sub

    for command in COMMANDS:
        try:
            command.add_parser(_Sub())
        except _Declared:
            pass
    return parser


def _add_output_options(parser: argparse.ArgumentParser, count, flag) -> None:
    """--debug, -v / --verbose and -q / --quiet, with these defaults (the commands'
    copies default to ``argparse.SUPPRESS``: left out, the ones given before the
    command stand)."""
    parser.add_argument(
        "--debug", action="store_true", default=flag, help="on an error, show the full traceback"
    )
    parser.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=count,
        help="say what is done on stderr: -v each stage (files read, steps, edges), -vv "
        "every detail (the library's 'o3d_rpointhop' logger at INFO / DEBUG)",
    )
    parser.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        default=flag,
        help="errors only on stderr: no warnings (the exit status still says when a "
        "result is flagged)",
    )


class _Lines(logging.Formatter):
    """``o3d-rpointhop: warning: ...``, as the command line's other lines."""

    def format(self, record: logging.LogRecord) -> str:
        return f"{PROG}: {record.levelname.lower()}: {record.getMessage()}"


def _log_to_stderr(verbose: int, quiet: bool) -> None:
    """The library's logger on stderr at the level -v / -q ask for (WARNING without
    either); one handler, whichever ``main`` call set it last."""
    logger = logging.getLogger("o3d_rpointhop")
    for handler in [h for h in logger.handlers if isinstance(h.formatter, _Lines)]:
        logger.removeHandler(handler)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_Lines())
    logger.addHandler(handler)
    levels = [logging.WARNING, logging.INFO, logging.DEBUG]
    logger.setLevel(logging.ERROR if quiet else levels[min(verbose, 2)])
    logger.propagate = False


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    """A Python warning as one ``o3d-rpointhop: warning: ...`` line, without its source."""
    logging.getLogger("o3d_rpointhop.cli").warning(" ".join(str(message).split()))


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    _log_to_stderr(args.verbose, args.quiet)
    try:
        with warnings.catch_warnings():
            if args.quiet:  # the library's warnings too
                warnings.simplefilter("ignore")
            warnings.showwarning = _warning_line
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
