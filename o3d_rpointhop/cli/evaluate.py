"""``o3d-rpointhop evaluate``: score a transformation obtained elsewhere."""

from __future__ import annotations

import argparse
import json

import numpy as np

from ._common import add_json
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
        "points between the two transformations.",
    )
    p.add_argument("source", help="the cloud the transformation moves")
    p.add_argument("target", help="the cloud it moves the source onto")
    p.add_argument("--transform", required=True, help="text file with the 4x4 transformation")
    p.add_argument("--truth", help="text file with the ground-truth 4x4 transformation")
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
    truth = read_matrix(args.truth) if args.truth else None
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
    return flag_status(result)
