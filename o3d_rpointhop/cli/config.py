"""``o3d-rpointhop config``: print (or write) every default as a TOML file to start from,
or the config a saved output was made with."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_parser", "run"]


def add_parser(commands) -> None:
    p = commands.add_parser(
        "config",
        help="print every default (or a saved run's settings) as a TOML file for --config",
        description="Print every default as a TOML file: [register] (what register's and "
        "reconstruct's flags set), one section per global step and ICP variant with its "
        "parameters, [settings] (the multiples of the resolution every unset distance "
        "comes from), [multiway] (reconstruct's edges), [descriptor] (which descriptor, "
        "axes, threads), [fpfh] (FPFH's parameters) and [fit] (what fit fits). Edit it and "
        "pass it to --config of register, reconstruct, describe or fit. With --from, the "
        "config recorded in a JSON output of those commands instead: passed back with "
        "--config, it repeats the run.",
    )
    p.add_argument("-o", "--output", help="write the file here instead of printing it")
    p.add_argument(
        "--from",
        dest="source",
        metavar="JSON",
        help="a JSON output that records its run (register --json / --transform .json / "
        "--result, reconstruct --poses / --result, describe's and fit's sidecars)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..io import check_output_path
    from ._config import default_config, to_toml
    from ._record import config_of_record

    config = config_of_record(args.source) if args.source else default_config()
    text = to_toml(config)
    if args.output:
        Path(check_output_path(args.output)).write_text(text)
    else:
        print(text, end="")
    return 0
