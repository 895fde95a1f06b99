"""``o3d-rpointhop register``: align one cloud to another."""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

from ._common import (
    CommandError,
    add_config,
    add_descriptor,
    add_force,
    add_json,
    add_model,
    add_seed,
    add_viewpoints,
    check_size,
    cloud_bytes,
    global_points,
    positive_or_auto,
    vector,
)
from ._config import load_config
from ._descriptor import chosen_descriptor, descriptor_from
from ._options import registration_options, used_config
from ._record import run_record
from ._trust import read_noting_precision, trust_problems, trust_status
from .view import add_view


def add_parser(commands) -> None:
    p = commands.add_parser(
        "register",
        help="align SOURCE to TARGET: global estimate from descriptors, then ICP",
        description="Align SOURCE to TARGET and print the 4x4 transformation that maps the "
        "source into the target frame. Clouds: .ply, .pcd, .xyz, .pts, .las/.laz, .e57, "
        "KITTI .bin, meshes (.obj, .stl, .off, .glb), .npy/.npz/.txt/.csv.",
    )
    from ..registration.pipeline import GLOBAL_METHODS, REFINE_METHODS

    p.add_argument("source", help="the cloud to move (.ply, .las, .e57, .bin, .npy, ...)")
    p.add_argument("target", help="the cloud to move it onto")
    add_descriptor(p)
    add_model(
        p,
        default="auto: the scene model, facing the sensor, when both clouds read "
        "as rooms scanned from their origin; else the one-hop object model",
    )
    p.add_argument(
        "--global",
        dest="global_method",
        choices=["auto", *GLOBAL_METHODS, "none"],
        help="global estimate (default: auto, the step that won on the descriptor's "
        "training data: consensus for --model scene, else ransac; with --descriptor fpfh "
        "on indoor scans, consensus wins)",
    )
    p.add_argument(
        "--with-fpfh",
        nargs="?",
        const="always",
        choices=["always", "fallback", "never"],
        default=None,
        help="the consensus on FPFH's matches too, every hypothesis of both verified "
        "together: always (more pairs that overlap little, about twice the time), "
        "fallback (only where the model's estimate explains under 1.5%% of its matches: "
        "the default for --model scene), or never (docs/low_overlap.md)",
    )
    refinements = [name for name in REFINE_METHODS if name != "symmetry_check"]
    p.add_argument(
        "--refine",
        choices=[*refinements, "none"],
        help="ICP refinement (default: point_to_plane)",
    )
    p.add_argument(
        "--symmetry-check",
        action="store_true",
        default=None,
        help="after ICP, also try the estimate's 180-degree twins and keep the best fit "
        "(for objects seen whole)",
    )
    p.add_argument("--voxel-size", type=positive_or_auto, help="'auto' (the default) or a length")
    p.add_argument(
        "--n-global-points",
        type=global_points,
        help="points per cloud for the global step: a count, or 'auto' (what the model "
        "states: 4096 for --model scene; else 2048)",
    )
    p.add_argument("--init", help="text file with a 4x4 start transformation (for ICP alone)")
    add_viewpoints(p, "cloud (source first)", chosen=True)
    p.add_argument(
        "--up",
        type=vector,
        help="an up direction both clouds share, 'x,y,z' (LiDAR: 0,0,1): the global step "
        "rejects upside-down hypotheses (default: none)",
    )
    add_seed(p, default=None)
    add_config(p)
    p.add_argument("-o", "--output", help="write the aligned source cloud here")
    p.add_argument("--transform", help="write the transformation here (.txt: 4x4; .json: all)")
    p.add_argument(
        "--result",
        help="save the whole result (inlier pairs and every step) as JSON; "
        "RegistrationResult.load reads it back",
    )
    add_json(p)
    add_force(p)
    add_view(p)
    p.set_defaults(func=run)


def _is_las(path: str) -> bool:
    return Path(path).suffix.lower() in (".las", ".laz")


def run(args: argparse.Namespace) -> int:
    from ..io import check_output_path, write_cloud
    from ..poses import read_matrix, write_matrix
    from ..registration import RegistrationWarning, register

    # Settings, model and outputs are checked before any cloud is read.
    config = load_config(args.config, args.set)
    descriptor, section = descriptor_from(config, args.descriptor, args.model)
    flags = {
        "global_method": args.global_method,
        "refine": args.refine,
        "voxel_size": args.voxel_size,
        "n_global_points": args.n_global_points,
        "random_state": args.seed,
        "symmetry_check": args.symmetry_check,
        "viewpoints": args.viewpoints,
        "up": args.up,
        "with_fpfh": {"always": True, "never": False}.get(args.with_fpfh, args.with_fpfh),
    }
    options = registration_options(config, flags, descriptor)
    record = run_record("register", used_config(options, section), descriptor)
    for out in (args.output, args.transform, args.result):
        if out:
            check_output_path(out)
    init = read_matrix(args.init) if args.init else None
    rounded: list[str] = []
    source = read_noting_precision(args.source, rounded)
    target = read_noting_precision(args.target, rounded)
    choice = None
    if descriptor is None:  # the model is chosen from the clouds, as register() does
        descriptor, flags["viewpoints"], choice = chosen_descriptor(
            section, options["viewpoints"], [source, target], [args.source, args.target]
        )
        options = registration_options(config, flags, descriptor)
        record = run_record("register", used_config(options, section), descriptor)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RegistrationWarning)  # reported below, once
            result = register(
                source,
                target,
                descriptor,
                init=init,
                **options,
            )
    except ValueError as exc:  # name the files, not just "source" and "target"
        raise CommandError(f"{exc} (source: {args.source}, target: {args.target})") from exc
    result.model = choice
    summary = result.as_dict()
    problems = trust_problems(result, rounded)
    summary.update(
        {
            "trusted": result.converged and not result.ambiguous and not problems,
            "trust_problems": problems,
            "source": args.source,
            "target": args.target,
            "provenance": record,
        }
    )
    if args.output:
        aligned = type(source)(source).transform(result.transformation)  # a copy
        check_size(args.output, cloud_bytes(aligned), args.force, "downsample the source")
        # In the target's frame: a LAS/LAZ output keeps the target's grid when it is one.
        like = args.target if _is_las(args.target) else args.source
        # Every dimension of a LAS / LAZ source's points goes with them.
        origin = [args.source] if _is_las(args.source) else None
        write_cloud(args.output, aligned, like=like, provenance=record, las_points_of=origin)
        summary["aligned_cloud"] = args.output
    if args.transform:
        if args.transform.lower().endswith(".json"):
            Path(args.transform).write_text(json.dumps(summary, indent=2))
        else:
            write_matrix(args.transform, result.transformation)
        summary["transform_file"] = args.transform
    if args.result:
        result.save(args.result, provenance=record)
        summary["result_file"] = args.result
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(np.array2string(result.transformation, precision=8, suppress_small=True))
        steps = ", ".join(f"{s.name} {s.seconds:.2f}s" for s in result.steps)
        print(
            f"fitness {result.fitness:.3f}, inlier RMSE {result.inlier_rmse:.6g}, "
            f"voxel {result.voxel_size:.6g} ({steps})"
        )
        if any(s.info.get("fallback") for s in result.steps):
            print("FPFH's consensus was asked too: the model's estimate explained few matches")
    status = trust_status(result, problems)
    if args.view:
        from ..viewer import show_registration

        show_registration(source, target, result, host=args.host, port=args.port)
    return status
