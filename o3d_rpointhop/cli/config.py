"""``o3d-rpointhop config``: print (or write) every default as a TOML file to start from."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_parser", "run"]


def add_parser(commands) -> None:
    p = commands.add_parser(
        "config",
        help="print every registration default as a TOML file for --config",
        description="Print every registration default as a TOML file: [register] (what "
        "register's flags set), one section per global step and ICP variant with its "
        "parameters, and [settings] (the multiples of the resolution every unset distance "
        "comes from). Edit it and pass it to 'register --config'.",
    )
    p.add_argument("-o", "--output", help="write the file here instead of printing it")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..io import check_output_path
    from ._config import default_config, to_toml

    text = to_toml(default_config())
    if args.output:
        Path(check_output_path(args.output)).write_text(text)
    else:
        print(text, end="")
    return 0
