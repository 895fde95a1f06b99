"""``o3d-rpointhop reconstruct``: rebuild an object or scene from unposed scans."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from ._common import (
    EXIT_OK,
    EXIT_UNRELIABLE,
    POSE_FORMATS,
    CommandError,
    UsageError,
    add_config,
    add_descriptor,
    add_force,
    add_model,
    add_seed,
    add_viewpoints,
    check_size,
    cloud_bytes,
    global_points,
    positive_or_auto,
)
from ._config import load_config
from ._descriptor import chosen_descriptor, descriptor_from
from ._edge_flags import add_edge_limits
from ._options import reconstruct_options
from ._paths import scan_paths
from ._trust import log, report_reconstruction
from .view import add_view


def add_parser(commands) -> None:
    p = commands.add_parser(
        "reconstruct",
        help="rebuild an object or scene from unposed scans (multiway registration)",
        description="Register the scans to one another through a pose graph (in scan 0's "
        "frame, or the first placed scan's when scan 0 overlaps none) and write the "
        "merged cloud: every point of every placed scan with its colours and normals "
        "(grey for scans without colours beside scans with them; from LAS / LAZ scans to a "
        "LAS / LAZ output, every point dimension: intensity, classification, GPS time, ...), "
        "downsampled only with --output-voxel-size, coloured by scan with --colour-by-scan. "
        "Scans left out of the placed part are named with why (exit status 3). "
        "--voxel-size is the registration's resolution, as register's is.",
    )
    p.add_argument(
        "scans",
        nargs="+",
        help="two or more scans (.ply, .las, .laz, .e57, .bin, .npy, ...), folders (every "
        "scan file in them but .txt / .csv, in natural order: scan_9 before scan_10) or quoted "
        "glob patterns (also in natural order); -v prints the order",
    )
    p.add_argument("-o", "--output", required=True, help="merged cloud to write (.ply, ...)")
    p.add_argument(
        "--poses",
        help="write the poses (scan -> the frame's scan, scan 0 when placed), edges, "
        "parts and flags as JSON",
    )
    p.add_argument("--mesh", help="also write an Open3D Poisson surface mesh here")
    p.add_argument(
        "--pose-graph",
        help="write the optimised pose graph in Open3D's JSON (open3d.io.read_pose_graph)",
    )
    p.add_argument(
        "--trajectory",
        action="append",
        help="write the scans' poses (scan -> the frame's scan) as a trajectory (repeatable, one "
        "file per format): KITTI keeps line k for scan k (12 nan for an unplaced scan); "
        "TUM (timestamp k, the run recorded in a comment) and 3dmatch (record 0 k n) name "
        "each scan and leave unplaced ones out",
    )
    p.add_argument(
        "--trajectory-format",
        action="extend",
        nargs="+",
        choices=POSE_FORMATS,
        help="format of each --trajectory, in the same order (one format applies to "
        "all; default: each file's by its suffix, 3dmatch for .log, else kitti)",
    )
    p.add_argument(
        "--result", help="save the whole result as JSON (MultiwayResult.load reads it back)"
    )
    from ..registration.pipeline import GLOBAL_METHODS  # declared in full: this command runs

    add_descriptor(p)
    add_model(
        p,
        default="auto: the scene model, facing the sensors, when at least half "
        "of the scans read as rooms scanned from their origin; else the one-hop object model",
    )
    p.add_argument(
        "--global",
        dest="global_method",
        choices=["auto", *GLOBAL_METHODS],
        help="the global step that screens each pair (default: auto, the one the "
        "descriptor states: consensus for --model scene, else ransac)",
    )
    p.add_argument(
        "--voxel-size",
        type=positive_or_auto,
        help="the common resolution every distance is a multiple of, as register's "
        "(default: auto, the coarsest any scan needs to keep --n-global-points)",
    )
    p.add_argument(
        "--n-global-points",
        type=global_points,
        help="points the largest scan keeps at the common resolution (default: auto, what "
        "the model states: 4096 for --model scene; else 2048)",
    )
    add_edge_limits(p)
    p.add_argument(
        "--sequential",
        action="store_true",
        help="the scans are given in the order they were taken: above 12 scans, pair each "
        "with those given next to it too (the result then depends on their order)",
    )
    add_config(p)
    p.add_argument(
        "--output-voxel-size",
        type=float,
        help="downsample the merged cloud (and the mesh) to this voxel (default: every point)",
    )
    p.add_argument(
        "--colour-by-scan", action="store_true", help="paint each scan in its own colour"
    )
    p.add_argument(
        "--n-jobs",
        type=int,
        default=-1,
        help="parallel pair registrations (default -1: every core; the poses do not depend on it)",
    )
    add_viewpoints(p, "scan", chosen=True)
    add_seed(p, default=None)
    add_force(p)
    add_view(p)
    p.set_defaults(func=run)


def _trajectories(paths: list[str], formats: list[str]) -> dict[str, str]:
    """Each --trajectory file with its format (one format for all, or one each; none:
    each file's by its suffix)."""
    from ..poses import pose_format

    if not formats:
        formats = [pose_format(p) for p in paths]
    if len(formats) == 1:
        formats = formats * len(paths)
    if paths and len(formats) != len(paths):
        raise UsageError(
            f"{len(paths)} --trajectory files and {len(formats)} --trajectory-format: give "
            "one format for all or one for each"
        )
    return dict(zip(paths, formats, strict=False))


def run(args: argparse.Namespace) -> int:
    import open3d as o3d

    from ..io import check_output_path, read_cloud, write_cloud
    from ..poses import write_pose_graph, write_trajectory
    from ..registration import register_multiway

    # Settings, model and outputs are checked before any scan is read.
    config = load_config(args.config, args.set)
    descriptor, section = descriptor_from(config, args.descriptor, args.model)
    flags = {
        "global_method": args.global_method,
        "voxel_size": args.voxel_size,
        "n_global_points": args.n_global_points,
        "random_state": args.seed,
        "viewpoints": args.viewpoints,
        "min_fitness": args.min_fitness,
        "max_violation": args.max_violation,
    }
    options, record = reconstruct_options(config, flags, descriptor, section, args.sequential)
    trajectories = _trajectories(args.trajectory or [], args.trajectory_format or [])
    outputs = (args.output, args.poses, args.mesh, args.pose_graph, *trajectories, args.result)
    for out in outputs:
        if out:
            check_output_path(out)
    args.scans = scan_paths(args.scans)
    log.info("scans, in this order (scan 0 first): %s", ", ".join(args.scans))
    if len(args.scans) < 2:
        raise CommandError(f"reconstruct needs two or more scans, got {len(args.scans)}")
    scans = [read_cloud(p) for p in args.scans]
    choice = None
    if descriptor is None:  # the model is chosen from the scans, as register_multiway() does
        descriptor, flags["viewpoints"], choice = chosen_descriptor(
            section, options["viewpoints"], scans, args.scans, multiway=True
        )
        options, record = reconstruct_options(config, flags, descriptor, section, args.sequential)
    try:
        result = register_multiway(scans, descriptor, n_jobs=args.n_jobs, progress=None, **options)
    except ValueError as exc:  # name the files, not their places in the list
        if not re.match(r"scan \d+: ", str(exc)):
            raise
        named = re.sub(r"scan (\d+)", lambda m: args.scans[int(m[1])], str(exc))
        raise CommandError(named) from exc
    result.model = choice
    merged = result.merge(scans, voxel_size=args.output_voxel_size, colour=args.colour_by_scan)
    check_size(args.output, cloud_bytes(merged), args.force, "downsample with --output-voxel-size")
    # A LAS/LAZ output keeps scan 0's grid (offsets, scales), and,
    # when every point is kept and every scan is LAS / LAZ, every dimension of each.
    placed = [p for p, pose in zip(args.scans, result.poses, strict=True) if pose is not None]
    las = all(Path(p).suffix.lower() in (".las", ".laz") for p in placed)
    every = args.output_voxel_size is None and las
    write_cloud(
        args.output,
        merged,
        like=args.scans[0],
        provenance=record,
        las_points_of=placed if every else None,
        keep_colours=not args.colour_by_scan,
    )
    summary = {**result.as_dict(list(args.scans)), "provenance": record}
    if args.poses:
        Path(args.poses).write_text(json.dumps(summary, indent=2))
    if args.pose_graph:
        write_pose_graph(args.pose_graph, result.pose_graph)
    for path, fmt in trajectories.items():
        comment = f"o3d-rpointhop {json.dumps(record)}" if fmt == "tum" else None
        write_trajectory(path, result.poses, fmt, comment=comment)
    if args.result:
        result.save(args.result, provenance=record)
    if args.mesh:
        mesh = result.mesh(scans, voxel_size=args.output_voxel_size)
        if not o3d.io.write_triangle_mesh(args.mesh, mesh):
            raise CommandError(f"{args.mesh}: Open3D could not write the mesh")
    print(
        f"{len(scans) - len(result.unconnected)} of {len(scans)} scans placed, "
        f"{len(result.edges)} edges kept, {result.seconds:.1f} s; merged cloud "
        f"({len(merged.points)} points) written to {args.output}"
    )
    report_reconstruction(summary, args.scans[0])
    if args.view:
        from ..viewer import show_multiway

        names = [Path(p).name for p in args.scans]
        show_multiway(scans, result, host=args.host, port=args.port, names=names)
    return EXIT_UNRELIABLE if result.unconnected else EXIT_OK
