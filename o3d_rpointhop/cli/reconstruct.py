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
    add_model,
    add_seed,
    add_viewpoints,
    descriptor_of,
)


def add_parser(commands) -> None:
    p = commands.add_parser(
        "reconstruct",
        help="rebuild an object or scene from unposed scans (multiway registration)",
        description="Register every scan to scan 0 through a pose graph and write the "
        "merged, voxel-downsampled cloud coloured by scan. Scans no other scan overlaps "
        "are reported and left out (exit status 3).",
    )
    p.add_argument("scans", nargs="+", help="two or more scans (.ply, .pcd, .xyz, .npy, ...)")
    p.add_argument("-o", "--output", required=True, help="merged cloud to write (.ply, ...)")
    p.add_argument("--poses", help="write the poses (scan -> scan 0), edges and flags as JSON")
    p.add_argument("--mesh", help="also write an Open3D Poisson surface mesh here")
    add_descriptor(p)
    add_model(p, default="the ModelNet40 model on 128 axes")
    p.add_argument("--voxel-size", type=float, help="voxel of the merged cloud")
    p.add_argument("--n-jobs", type=int, help="parallel pair registrations")
    add_viewpoints(p, "scan")
    add_seed(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import open3d as o3d

    from ..io import check_output_path, read_cloud, write_cloud
    from ..registration import register_multiway

    for out in (args.output, args.poses, args.mesh):
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
    merged = result.merge(scans, voxel_size=args.voxel_size)
    write_cloud(args.output, merged)
    summary = result.as_dict(list(args.scans))
    if args.poses:
        Path(args.poses).write_text(json.dumps(summary, indent=2))
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
        return EXIT_UNRELIABLE
    return EXIT_OK
