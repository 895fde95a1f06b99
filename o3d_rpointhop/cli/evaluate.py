"""``o3d-rpointhop evaluate``: score a transformation obtained elsewhere."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ._common import CommandError, add_json
from ._paths import fragment_number
from ._trust import flag_status

__all__ = ["add_parser", "run"]


def add_parser(commands) -> None:
    p = commands.add_parser(
        "evaluate",
        help="score a transformation of SOURCE onto TARGET (fitness, RMSE, flags, errors)",
        description="Measure how well a 4x4 transformation (a text file of four rows) maps "
        "SOURCE onto TARGET: Open3D's fitness and inlier RMSE at the correspondence "
        "distance, this library's converged / ambiguous flags, and, with --truth, the "
        "errors against a ground-truth transformation: the rotation error, the translation "
        "error about the source's centroid (at the origin a survey cloud's rotation digits "
        "would be magnified by its distance), and the RMS displacement of the source's "
        "points between the two transformations. --truth may be a 3DMatch gt.log: the "
        "record of the two fragments the file names end in (cloud_bin_14.ply: 14), either "
        "way round, and with gt.info beside it the official RMSE (registered under 0.2 m).",
    )
    p.add_argument("source", help="the cloud the transformation moves")
    p.add_argument("target", help="the cloud it moves the source onto")
    p.add_argument("--transform", required=True, help="text file with the 4x4 transformation")
    p.add_argument(
        "--truth",
        help="text file with the ground-truth 4x4 transformation, or a 3DMatch .log of "
        "pairs (gt.log) holding the two fragments'",
    )
    p.add_argument(
        "--distance",
        type=float,
        help="correspondence distance (default: where register measures its fitness, the "
        "last ICP distance: 0.5 resolution)",
    )
    p.add_argument("--voxel-size", type=float, help="the resolution (default: auto)")
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..io import read_cloud
    from ..poses import read_matrix
    from ..registration.evaluate import evaluate
    from ..transforms import rms_displacement, rotation_error_deg, translation_error

    transformation = read_matrix(args.transform)
    truth, record = _truth(args.truth, args.source, args.target) if args.truth else (None, None)
    source, target = read_cloud(args.source), read_cloud(args.target)
    result = evaluate(
        source,
        target,
        transformation,
        distance=args.distance,
        voxel_size="auto" if args.voxel_size is None else args.voxel_size,
    )
    summary = {
        "source": args.source,
        "target": args.target,
        "transformation": result.transformation.tolist(),
        "fitness": result.fitness,
        "inlier_rmse": result.inlier_rmse,
        "distance": result.distance,
        "voxel_size": result.voxel_size,
        "converged": result.converged,
        "ambiguous": result.ambiguous,
    }
    if truth is not None:
        points = np.asarray(source.points)
        summary["rotation_error_deg"] = rotation_error_deg(transformation, truth)
        summary["translation_error"] = translation_error(
            transformation, truth, about=points.mean(axis=0)
        )
        summary["rms_displacement"] = rms_displacement(transformation, truth, points)
    if record is not None:
        summary.update(_official(transformation, *record))
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(np.array2string(result.transformation, precision=8, suppress_small=True))
        print(
            f"fitness {result.fitness:.3f}, inlier RMSE {result.inlier_rmse:.6g} within "
            f"{result.distance:.6g} (voxel {result.voxel_size:.6g}); converged "
            f"{result.converged}, ambiguous {result.ambiguous}"
        )
        if truth is not None:
            print(
                f"against the truth: rotation error {summary['rotation_error_deg']:.4g} deg, "
                f"translation error {summary['translation_error']:.6g} about the source's "
                f"centroid, RMS displacement of the source's points "
                f"{summary['rms_displacement']:.6g}"
            )
        if "rmse_3dmatch" in summary:
            from ..evaluation.metrics import REGISTERED_RMSE

            verdict = "registered" if summary["registered_3dmatch"] else "not registered"
            print(
                f"3DMatch record {tuple(summary['record_3dmatch'])}: RMSE "
                f"{summary['rmse_3dmatch']:.4g} (gt.info), {verdict} by the official test "
                f"(under {REGISTERED_RMSE})"
            )
    return flag_status(result)


def _truth(path: str, source: str, target: str):
    """The ground truth of SOURCE onto TARGET: a matrix file's, or for a 3DMatch
    ``.log`` the record of the two fragments (``(i, j)`` maps fragment ``j`` into
    ``i``, inverted when the source is ``i``) and, with the ``.info`` file beside it
    (:func:`~o3d_rpointhop.evaluation.rooms.read_truth`), ``(record, its matrix, its
    information, whether the record maps source into target)`` for the official RMSE
    (else None)."""
    from ..datasets.threedmatch import read_gt_log
    from ..evaluation.rooms import read_truth
    from ..poses import pose_format, read_matrix

    if pose_format(path) != "3dmatch":
        return read_matrix(path), None
    why = "no gt.log record can be chosen for it (give --truth a 4x4 matrix file instead)"
    a, b = fragment_number(source, why), fragment_number(target, why)
    if Path(path).with_suffix(".info").is_file():
        records = read_truth(path)
    else:
        records = {pair: (matrix, None) for pair, matrix in read_gt_log(path).items()}
    if (b, a) in records:
        key, forward = (b, a), True
    elif (a, b) in records:
        key, forward = (a, b), False
    else:
        raise CommandError(f"{path} holds no record of fragments {a} and {b}")
    matrix, information = records[key]
    truth = matrix if forward else np.linalg.inv(matrix)
    return truth, None if information is None else (key, matrix, information, forward)


def _official(transformation, key, matrix, information, forward) -> dict:
    """The official 3DMatch RMSE of ``transformation`` (source onto target) against the
    record, in the record's direction."""
    from ..evaluation.metrics import REGISTERED_RMSE, rmse_3dmatch

    estimate = transformation if forward else np.linalg.inv(transformation)
    rmse = rmse_3dmatch(estimate, matrix, information)
    return {
        "record_3dmatch": list(key),
        "rmse_3dmatch": rmse,
        "registered_3dmatch": bool(rmse < REGISTERED_RMSE),
    }
