"""``o3d-rpointhop poses``: a trajectory from one pose format into another
(``convert``), and a reconstruction's poses scored against a 3DMatch ``gt.log``
(``score``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ._common import EXIT_OK, POSE_FORMATS, CommandError, add_json
from ._paths import fragment_number

__all__ = ["add_parser", "run"]


def add_parser(commands) -> None:
    p = commands.add_parser(
        "poses",
        help="convert a trajectory between KITTI, TUM and 3DMatch .log, or score a "
        "reconstruction against a gt.log",
        description="Convert a trajectory (scan k's pose at scan k) from one format into "
        "another. KITTI: line k is scan k (12 nan for a scan without a pose); TUM: a "
        "whole-number timestamp k is scan k; 3DMatch .log: record 0 k n is scan k of n. "
        "Scans without a pose stay without one: a line of nan in KITTI, left out in TUM "
        "and .log (which cannot mark them). Or score a reconstruction's poses against a "
        "3DMatch gt.log.",
    )
    actions = p.add_subparsers(
        dest="action",
        required=True,
        metavar="ACTION",
        help="convert: between formats; score: against a gt.log",
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
    score = actions.add_parser(
        "score",
        help="count a reconstruction's gt.log pairs that pass the official test",
        description="Score the poses reconstruct --poses wrote against a 3DMatch gt.log "
        "(with gt.info beside it): each scan's fragment number is the one its file name "
        "ends in (cloud_bin_14.ply: 14), and every pair of the log whose two fragments "
        "are among the scans counts when the relative pose of the two passes the "
        "official test (RMSE under the pair's information matrix below 0.2 m); a pair "
        "with a fragment left unplaced does not.",
    )
    score.add_argument("poses", help="the --poses JSON of reconstruct")
    score.add_argument(
        "--truth",
        required=True,
        action="append",
        help="the scene's gt.log, gt.info beside it (repeatable: 3DMatch's and 3DLoMatch's "
        "pairs together)",
    )
    add_json(score)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.action == "score":
        return _score(args)
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


def _score(args: argparse.Namespace) -> int:
    """``poses score``: the reconstruction's gt.log pairs that pass the official test."""
    import numpy as np

    from ..evaluation.metrics import REGISTERED_RMSE
    from ..evaluation.rooms import pair_rmse, read_truth

    try:
        summary = json.loads(Path(args.poses).read_text())
        names, poses = list(summary["scans"]), list(summary["poses"])
        if len(names) != len(poses):
            raise ValueError(f"{len(names)} scans and {len(poses)} poses")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CommandError(f"{args.poses}: not the poses JSON of reconstruct ({exc})") from exc
    why = "its fragment in the gt.log is unknown"
    ids = [fragment_number(name, why) for name in names]
    if len(set(ids)) < len(ids):
        raise CommandError(f"{args.poses}: two scans' names end in the same number")
    arrays = [None if p is None else np.asarray(p, dtype=float) for p in poses]
    for name, pose in zip(names, arrays, strict=True):
        if pose is not None and (pose.shape != (4, 4) or not np.isfinite(pose).all()):
            raise CommandError(f"{args.poses}: the pose of {name} is not a finite 4x4 matrix")
    placed = dict(zip(ids, arrays, strict=True))
    truth, present = {}, set(ids)
    for path in args.truth:
        truth.update((p, t) for p, t in read_truth(path).items() if set(p) <= present)
    if not truth:
        raise CommandError(f"{', '.join(args.truth)}: no pair of these scans' fragments")
    errors = pair_rmse(placed, truth)
    passed = sorted(p for p, e in errors.items() if e is not None and e < REGISTERED_RMSE)
    with_pair = sorted({k for pair in truth for k in pair})
    on = [k for k in with_pair if placed[k] is not None]
    if args.json:
        out = {
            "pairs": len(truth),
            "registered": len(passed),
            "fragments_with_pairs": len(with_pair),
            "placed_with_pairs": len(on),
            "rmse": [{"pair": list(p), "rmse": e} for p, e in sorted(errors.items())],
        }
        print(json.dumps(out, indent=2))
    else:
        print(
            f"{len(passed)} of {len(truth)} gt.log pairs registered (RMSE under "
            f"{REGISTERED_RMSE}); {len(on)} of {len(with_pair)} fragments with a pair placed"
        )
    return EXIT_OK
