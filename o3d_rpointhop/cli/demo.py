"""``o3d-rpointhop demo``: register a sample pair with the pretrained model and draw it."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ._common import (
    CommandError,
    add_data,
    add_json,
)
from ._trust import flag_status


def add_parser(commands) -> None:
    p = commands.add_parser(
        "demo",
        help="register a sample pair with the pretrained model; write a before/after PNG",
        description="Register a sample pair with the pretrained R-PointHop model (RANSAC, "
        "then ICP) and write aligned.ply, transform.txt and before_after.png. The pair is "
        "--source/--target if given, else two Stanford Bunny scans when the data folder "
        "exists, else a synthetic object.",
    )
    p.add_argument("--output-dir", default="demo_output", help="where results go")
    p.add_argument("--source", help="your own source cloud")
    p.add_argument("--target", help="your own target cloud")
    add_data(p)
    p.add_argument("--synthetic", action="store_true", help="use the synthetic pair")
    add_json(p)
    p.set_defaults(func=run)


def _sample_pair(args: argparse.Namespace):
    """The demo's pair: the user's files, else two real Bunny scans when the data is
    around, else two samples of a synthetic object rotated apart."""
    from scipy.spatial.transform import Rotation

    from ..datasets import make_object
    from ..io import read_cloud

    if args.source or args.target:
        if not (args.source and args.target):
            raise CommandError("give both --source and --target, or neither")
        return (
            read_cloud(args.source),
            read_cloud(args.target),
            None,
            (f"{args.source} -> {args.target}"),
        )
    if not args.synthetic:
        from ..datasets.bunny import load_bunny

        try:
            scans = load_bunny(("bun000", "bun045"), args.data)
        except FileNotFoundError as exc:
            args.fallback_reason = str(exc)
        else:
            truth = scans["bun045"].relative_pose(scans["bun000"])
            return (
                scans["bun045"].points,
                scans["bun000"].points,
                truth,
                "Stanford Bunny range scans bun045 -> bun000 (real data, bun.conf ground truth)",
            )
    target = make_object(2048, shape_seed=7, sample_seed=1)
    rotation = Rotation.random(random_state=3).as_matrix()
    shift = np.array([0.4, -0.3, 0.2])
    source = make_object(2048, shape_seed=7, sample_seed=2) @ rotation.T + shift
    truth = np.eye(4)
    truth[:3, :3], truth[:3, 3] = rotation.T, -rotation.T @ shift
    return source, target, truth, "synthetic object: two different samples, rotated apart"


def run(args: argparse.Namespace) -> int:
    from ..io import write_cloud
    from ..open3d_interop import to_point_cloud
    from ..plotting import save_registration_png
    from ..poses import write_matrix
    from ..registration import register
    from ..transforms import rotation_error_deg, translation_error

    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    source, target, truth, name = _sample_pair(args)
    result = register(source, target)  # the pretrained R-PointHop model, RANSAC, then ICP
    write_cloud(out / "aligned.ply", to_point_cloud(source).transform(result.transformation))
    write_matrix(out / "transform.txt", result.transformation)
    picture = out / "before_after.png"
    errors = None
    if truth is not None:
        errors = (
            rotation_error_deg(result.transformation, truth),
            translation_error(result.transformation, truth),
        )
    numbers = f"fitness {result.fitness:.3f}, {result.seconds:.2f} s"
    if errors is not None:
        numbers = f"error {errors[0]:.3f} deg / {errors[1]:.3g} (units of the data), " + numbers
    outputs = [out / "aligned.ply", out / "transform.txt"]
    try:
        save_registration_png(
            source,
            target,
            result.transformation,
            picture,
            title=f"{name}\nR-PointHop (pretrained) + RANSAC + ICP: {numbers}",
        )
        outputs.append(picture)
        no_picture = None
    except ImportError as exc:  # matplotlib is the optional [plot] extra
        no_picture = str(exc)
    summary = {
        "pair": name,
        "synthetic_fallback": getattr(args, "fallback_reason", None),
        "source_points": len(to_point_cloud(source).points),
        "target_points": len(to_point_cloud(target).points),
        "transformation": result.transformation.round(8).tolist(),
        "fitness": round(result.fitness, 4),
        "inlier_rmse": result.inlier_rmse,
        "converged": result.converged,
        "ambiguous": result.ambiguous,
        "seconds": round(result.seconds, 3),
        "steps": {s.name: round(s.seconds, 3) for s in result.steps},
        "outputs": [str(path) for path in outputs],
        "no_picture": no_picture,
    }
    if errors is not None:
        summary["rotation_error_deg"] = round(errors[0], 4)
        summary["translation_error"] = errors[1]
    if args.json:
        print(json.dumps(summary, indent=2))
        return flag_status(result)
    lines = []
    if summary["synthetic_fallback"]:
        lines.append(
            "No real data found, so the demo uses a synthetic object (set O3D_RPOINTHOP_DATA "
            "or pass --data to register two Stanford Bunny scans)."
        )
    lines.append(f"Registered {name}")
    lines.append(
        f"  {summary['source_points']} -> {summary['target_points']} points, pretrained "
        f"R-PointHop + RANSAC + ICP in {result.seconds:.2f} s"
    )
    if errors is not None:
        lines.append(
            f"  against the ground truth: rotation error {errors[0]:.3f} deg, translation "
            f"error {errors[1]:.3g} (units of the data)"
        )
    lines.append(
        f"  fitness {result.fitness:.3f}: share of source points within "
        f"{result.distance:.3g} of the target"
    )
    if no_picture:
        lines.append(f"  wrote {', '.join(summary['outputs'])}; no picture: {no_picture}")
    else:
        lines.append(f"  wrote {', '.join(summary['outputs'])} (the picture: before and after)")
    print("\n".join(lines))
    return flag_status(result)
