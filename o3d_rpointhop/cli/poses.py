"""``o3d-rpointhop poses convert``: a trajectory from one pose format into another."""

from __future__ import annotations

import argparse

from ._common import EXIT_OK, POSE_FORMATS

__all__ = ["add_parser", "run"]


def add_parser(commands) -> None:
    p = commands.add_parser(
        "poses",
        help="convert a trajectory between KITTI, TUM and 3DMatch .log",
        description="Convert a trajectory (scan k's pose at scan k) from one format into "
        "another. KITTI: line k is scan k (12 nan for a scan without a pose); TUM: a "
        "whole-number timestamp k is scan k; 3DMatch .log: record 0 k n is scan k of n. "
        "Scans without a pose stay without one: a line of nan in KITTI, left out in TUM "
        "and .log (which cannot mark them).",
    )
    actions = p.add_subparsers(
        dest="action", required=True, metavar="ACTION", help="convert: between formats"
    )
    convert = actions.add_parser(
        "convert",
        help="read INPUT in one format, write OUTPUT in another",
        description="Read INPUT as --from and write OUTPUT as --to, scan by scan. Either "
        "format left out is the file's by its suffix: 3dmatch for .log, else kitti (TUM "
        "files end in .txt as KITTI's do: name it).",
    )
    convert.add_argument("input", help="the trajectory file to read")
    convert.add_argument("output", help="the trajectory file to write")
    convert.add_argument(
        "--from",
        dest="source_format",
        choices=POSE_FORMATS,
        default="auto",
        help="INPUT's format (default: by its suffix)",
    )
    convert.add_argument(
        "--to",
        dest="target_format",
        choices=POSE_FORMATS,
        default="auto",
        help="OUTPUT's format (default: by its suffix)",
    )
    convert.add_argument(
        "--scans",
        type=int,
        help="how many scans there are (KITTI: that many lines, nan for the missing "
        "last ones; default: up to the last scan with a pose, or a .log's n)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..io import check_output_path
    from ..poses import pose_format, read_trajectory, write_trajectory

    check_output_path(args.output)
    args.source_format = pose_format(args.input, args.source_format)
    args.target_format = pose_format(args.output, args.target_format)
    poses = read_trajectory(args.input, args.source_format, args.scans)
    write_trajectory(args.output, poses, args.target_format)
    placed = sum(p is not None for p in poses)
    print(
        f"{placed} of {len(poses)} scans' poses converted from {args.source_format} to "
        f"{args.target_format}, written to {args.output}"
    )
    return EXIT_OK
