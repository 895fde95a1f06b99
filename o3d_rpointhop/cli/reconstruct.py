"""``o3d-rpointhop reconstruct``: rebuild an object or scene from unposed scans."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ._common import (
    EXIT_OK,
    EXIT_UNRELIABLE,
    PROG,
    CommandError,
    add_descriptor,
    add_force,
    add_model,
    add_seed,
    add_viewpoints,
    check_size,
    cloud_bytes,
    descriptor_of,
)
from .view import add_view


def add_parser(commands) -> None:
    p = commands.add_parser(
        "reconstruct",
        help="rebuild an object or scene from unposed scans (multiway registration)",
        description="Register every scan to scan 0 through a pose graph and write the "
        "merged cloud: every point of every placed scan with its colours and normals, "
        "downsampled only with --voxel-size, coloured by scan with --colour-by-scan. "
        "Scans no other scan overlaps are reported and left out (exit status 3).",
    )
    p.add_argument(
        "scans", nargs="+", help="two or more scans (.ply, .las, .laz, .e57, .bin, .npy, ...)"
    )
    p.add_argument("-o", "--output", required=True, help="merged cloud to write (.ply, ...)")
    p.add_argument("--poses", help="write the poses (scan -> scan 0), edges and flags as JSON")
    p.add_argument("--mesh", help="also write an Open3D Poisson surface mesh here")
    p.add_argument(
        "--pose-graph",
        help="write the optimised pose graph in Open3D's JSON (open3d.io.read_pose_graph)",
    )
    p.add_argument(
        "--trajectory", help="write the placed scans' poses (scan -> scan 0) as a trajectory"
    )
    p.add_argument(
        "--trajectory-format",
        choices=["kitti", "tum", "3dmatch"],
        default="kitti",
        help="format of --trajectory (default: kitti; 3dmatch: a .log of (0, k) records)",
    )
    p.add_argument(
        "--result", help="save the whole result as JSON (MultiwayResult.load reads it back)"
    )
    add_descriptor(p)
    add_model(p, default="the one-hop object model")
    p.add_argument(
        "--voxel-size", type=float, help="downsample the merged cloud (and the mesh) to this voxel"
    )
    p.add_argument(
        "--colour-by-scan", action="store_true", help="paint each scan in its own colour"
    )
    p.add_argument("--n-jobs", type=int, help="parallel pair registrations")
    add_viewpoints(p, "scan")
    add_seed(p)
    add_force(p)
    add_view(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import open3d as o3d

    from ..io import check_output_path, read_cloud, write_cloud
    from ..poses import write_pose_graph, write_poses
    from ..registration import register_multiway

    outputs = (args.output, args.poses, args.mesh, args.pose_graph, args.trajectory, args.result)
    for out in outputs:
        if out:
            check_output_path(out)
    scans = [read_cloud(p) for p in args.scans]
    result = register_multiway(
        scans,
        descriptor_of(args),
        viewpoints=args.viewpoints,
        n_jobs=args.n_jobs,
        seed=args.seed,
        progress=None,
    )
    merged = result.merge(scans, voxel_size=args.voxel_size, colour=args.colour_by_scan)
    check_size(args.output, cloud_bytes(merged), args.force, "downsample with --voxel-size")
    write_cloud(args.output, merged)
    summary = result.as_dict(list(args.scans))
    if args.poses:
        Path(args.poses).write_text(json.dumps(summary, indent=2))
    if args.pose_graph:
        write_pose_graph(args.pose_graph, result.pose_graph)
    if args.trajectory:
        placed = [k for k, pose in enumerate(result.poses) if pose is not None]
        write_poses(
            args.trajectory,
            [result.poses[k] for k in placed],
            args.trajectory_format,
            timestamps=[float(k) for k in placed],
            pairs=[(0, k) for k in placed],
            n_fragments=len(scans),
        )
    if args.result:
        result.save(args.result)
    if args.mesh:
        mesh = result.mesh(scans, voxel_size=args.voxel_size)
        if not o3d.io.write_triangle_mesh(args.mesh, mesh):
            raise CommandError(f"{args.mesh}: Open3D could not write the mesh")
    print(
        f"{len(scans) - len(result.unconnected)} of {len(scans)} scans placed, "
        f"{len(result.edges)} edges kept, {result.seconds:.1f} s; merged cloud "
        f"({len(merged.points)} points) written to {args.output}"
    )
    if result.unconnected:
        names = ", ".join(summary["unconnected"])
        print(f"{PROG}: warning: unconnected (left out): {names}", file=sys.stderr)
    if args.view:
        from ..viewer import show_multiway

        show_multiway(scans, result, host=args.host, port=args.port)
    return EXIT_UNRELIABLE if result.unconnected else EXIT_OK
