"""Command line interface: ``o3d-rpointhop <command> ...``."""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .._version import __version__
from ..registration.quality import RegistrationWarning

PROG = "o3d-rpointhop"

#: Exit statuses (listed in ``--help``).
EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_UNRELIABLE = 0, 1, 2, 3
EXIT_CODES = f"""exit status:
  {EXIT_OK}  success
  {EXIT_ERROR}  error: a missing, empty, damaged or unreadable file, a directory given as a
     file, NaN coordinates, too few points, degenerate geometry, an output that exists
     as a folder or exceeds the size limit without --force; one line on stderr says which
  {EXIT_USAGE}  usage error (unknown option, bad value)
  {EXIT_UNRELIABLE}  register/demo finished, but the result is flagged: not converged (no
     overlap, or a chance alignment) or ambiguous (a symmetric shape); reconstruct
     finished with unconnected scans left out; outputs are written, and stderr says
     which"""
#: Largest output written without --force.
MAX_OUTPUT_BYTES = 512 * 1024**2


class CommandError(Exception):
    """A failure to report as one line on stderr with exit status 1."""


def _check_size(path: str, nbytes: int, force: bool) -> None:
    if nbytes > MAX_OUTPUT_BYTES and not force:
        raise CommandError(
            f"{path}: would write {nbytes / 1024**2:,.0f} MB (limit {MAX_OUTPUT_BYTES // 1024**2} "
            "MB without --force); pass --force, or shorten the descriptor with --n-components"
        )


def _ints(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated ints, got {text!r}") from None


def _sizes(text: str) -> tuple[float | int, ...]:
    try:
        values = [float(v) if "." in v else int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated fractions or counts, got {text!r}"
        ) from None
    return tuple(values)


def _load_model(path: str | None, n_components: int | None = None):
    """A model file, a shipped model by name (``modelnet40``, ``scene``), else the
    pretrained ModelNet40 model; on ``n_components`` axes when given (a shipped model
    otherwise comes as ``pretrained(name)`` gives it)."""
    from ..descriptors import PRETRAINED_MODELS, RPointHopTransformer

    if path is None or path in PRETRAINED_MODELS:
        return RPointHopTransformer.pretrained(
            path or "modelnet40", n_components="default" if n_components is None else n_components
        )
    model = RPointHopTransformer.load(path)
    if n_components is not None:
        model.set_params(n_components=n_components)
    return model


# --------------------------------------------------------------------------- commands
def cmd_fit(args: argparse.Namespace) -> int:
    from ..descriptors import RPointHopTransformer
    from ..io import check_output_path, read_cloud

    check_output_path(args.output)
    clouds = [read_cloud(p) for p in args.clouds]
    params = {
        k: v
        for k, v in dict(
            n_neighbors=args.n_neighbors,
            hop_sizes=args.hop_sizes,
            lrf_neighbors=args.lrf_neighbors,
            energy_threshold=args.energy_threshold,
            fit_subsample=args.fit_subsample,
            n_jobs=args.n_jobs,
            random_state=args.random_state,
        ).items()
        if v is not None
    }
    start = time.perf_counter()
    model = RPointHopTransformer(**params).fit(clouds)
    model.save(args.output)
    print(
        f"fitted on {len(clouds)} clouds in {time.perf_counter() - start:.2f} s: "
        f"{model.n_features_out_}-D descriptors, model written to {args.output}"
    )
    return 0


def cmd_describe(args: argparse.Namespace) -> int:
    from ..io import check_output_path, read_cloud, save_npy

    check_output_path(args.output)
    cloud = read_cloud(args.cloud)
    model = _load_model(args.model, args.n_components)
    # 4 bytes a value, plus the header: refuse before spending the time.
    _check_size(args.output, 4 * len(cloud.points) * model.n_features_out_, args.force)
    start = time.perf_counter()
    desc = model.set_params(progress=None).transform(cloud)
    save_npy(args.output, np.ascontiguousarray(desc))
    print(
        f"{len(desc)} points described ({desc.shape[1]}-D) in "
        f"{time.perf_counter() - start:.3f} s, written to {args.output}"
    )
    return 0


def _auto_or(convert, what: str, valid, problem: str):
    """An argparse type: ``"auto"``, or ``convert(text)`` when ``valid`` accepts it."""

    def parse(text: str):
        if text == "auto":
            return text
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected 'auto' or {what}, got {text!r}") from None
        if not valid(value):
            raise argparse.ArgumentTypeError(f"{problem}, got {text!r}")
        return value

    return parse


_voxel = _auto_or(float, "a number", lambda v: v > 0, "voxel size must be positive")
_global_points = _auto_or(int, "a count", lambda v: v >= 3, "need at least 3 global points")


def _read_matrix(path: str) -> np.ndarray:
    try:
        matrix = np.loadtxt(path, ndmin=2)
    except (OSError, ValueError) as exc:
        raise CommandError(f"cannot read a 4x4 matrix from {path}: {exc}") from exc
    if matrix.shape != (4, 4):
        raise CommandError(f"{path} holds a {matrix.shape} matrix, not 4x4")
    return matrix


def _refine_chain(args) -> list[str]:
    chain = [] if args.refine == "none" else [args.refine]
    if args.symmetry_check:
        if not chain:
            raise CommandError("--symmetry-check needs an ICP refinement (--refine)")
        chain.append("symmetry_check")
    return chain


def cmd_register(args: argparse.Namespace) -> int:
    from ..descriptors import FPFHTransformer
    from ..io import check_output_path, read_cloud, write_cloud
    from ..registration import register

    source = read_cloud(args.source)
    target = read_cloud(args.target)
    for out in (args.output, args.transform):
        if out:
            check_output_path(out)
    if args.descriptor == "fpfh":
        if args.model:
            raise CommandError("--model applies to the rpointhop descriptor, not fpfh")
        descriptor = FPFHTransformer(radius="auto", normal_radius="auto")
    else:
        descriptor = _load_model(args.model) if args.model else None
    init = _read_matrix(args.init) if args.init else None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RegistrationWarning)  # reported below, once
            result = register(
                source,
                target,
                descriptor,
                global_method=None if args.global_method == "none" else args.global_method,
                refine=_refine_chain(args),
                voxel_size=args.voxel_size,
                n_global_points=args.n_global_points,
                init=init,
                seed=args.seed,
            )
    except ValueError as exc:  # name the files, not just "source" and "target"
        raise CommandError(f"{exc} (source: {args.source}, target: {args.target})") from exc
    summary = result.as_dict()
    summary.update({"source": args.source, "target": args.target})
    if args.output:
        aligned = source.transform(result.transformation)  # source is our own copy
        write_cloud(args.output, aligned)
        summary["aligned_cloud"] = args.output
    if args.transform:
        if args.transform.lower().endswith(".json"):
            Path(args.transform).write_text(json.dumps(summary, indent=2))
        else:
            np.savetxt(args.transform, result.transformation, fmt="%.10f")
        summary["transform_file"] = args.transform
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(np.array2string(result.transformation, precision=8, suppress_small=True))
        steps = ", ".join(f"{s.name} {s.seconds:.2f}s" for s in result.steps)
        print(
            f"fitness {result.fitness:.3f}, inlier RMSE {result.inlier_rmse:.6g}, "
            f"voxel {result.voxel_size:.6g} ({steps})"
        )
    return _flag_status(result)


def _flag_status(result) -> int:
    """Exit status of a finished registration: 3, with a line on stderr, when flagged."""
    if not result.converged:
        print(
            f"{PROG}: warning: the result did not converge (fitness {result.fitness:.3f}): "
            "no overlap, or a chance alignment",
            file=sys.stderr,
        )
        return EXIT_UNRELIABLE
    if result.ambiguous:
        print(
            f"{PROG}: warning: the result is ambiguous: turned by 180 degrees it fits about "
            "as well (a symmetric shape or a featureless plane)",
            file=sys.stderr,
        )
        return EXIT_UNRELIABLE
    return EXIT_OK


def cmd_benchmark(args: argparse.Namespace) -> int:
    from ..evaluation.bunny import run_bunny
    from ..evaluation.methods import DEFAULT_METHODS
    from ..evaluation.modelnet40 import MODELNET40_PROTOCOLS, run_modelnet40
    from ..evaluation.report import markdown, write_report
    from ..evaluation.threedmatch import run_3dmatch
    from ..registration.defaults import default_descriptor

    if args.dataset == "multiway":
        return _benchmark_multiway(args)
    default = DEFAULT_METHODS["3dmatch" if args.dataset == "3dmatch" else "objects"]
    methods = args.methods.split(",") if args.methods else list(default)
    model = _load_model(args.model) if args.model else default_descriptor()
    common = dict(data=args.data, seed=args.seed, model=model, progress=not args.no_progress)
    if args.dataset == "modelnet40":
        protocols = args.protocol or list(MODELNET40_PROTOCOLS)
        results = run_modelnet40(protocols, methods, max_shapes=args.max_shapes, **common)
    elif args.dataset == "bunny":
        results = run_bunny(args.protocol or ["scans", "paper"], methods, **common)
    else:
        if args.protocol:
            raise CommandError("3dmatch has no protocols to choose")
        scenes = args.scenes.split(",") if args.scenes else None
        results = run_3dmatch(methods, max_pairs=args.max_pairs, scenes=scenes, **common)
    paths = write_report(results, args.output)
    print(markdown(results))  # with the timings: the terminal is not a result file
    print("written: " + ", ".join(paths))
    return 0


def cmd_reconstruct(args: argparse.Namespace) -> int:
    import open3d as o3d

    from ..descriptors import FPFHTransformer
    from ..io import check_output_path, read_cloud, write_cloud
    from ..registration.multiway import register_multiway

    for out in (args.output, args.poses, args.mesh):
        if out:
            check_output_path(out)
    scans = [read_cloud(p) for p in args.scans]
    descriptor = (
        FPFHTransformer(radius="auto", normal_radius="auto") if args.descriptor == "fpfh" else None
    )
    result = register_multiway(scans, descriptor, n_jobs=args.n_jobs, seed=args.seed, progress=None)
    voxel = args.voxel_size or result.voxel_size / 2
    palette = np.array(
        [
            [0.12, 0.47, 0.71],
            [1.0, 0.5, 0.05],
            [0.17, 0.63, 0.17],
            [0.84, 0.15, 0.16],
            [0.58, 0.4, 0.74],
            [0.55, 0.34, 0.29],
            [0.89, 0.47, 0.76],
            [0.5, 0.5, 0.5],
            [0.74, 0.74, 0.13],
            [0.09, 0.75, 0.81],
        ]
    )
    merged = o3d.geometry.PointCloud()
    for k, (scan, pose) in enumerate(zip(scans, result.poses, strict=True)):
        if pose is None:
            continue
        part = o3d.geometry.PointCloud(scan.points).transform(pose)
        part.paint_uniform_color(palette[k % len(palette)])
        merged += part
    merged = merged.voxel_down_sample(voxel)
    write_cloud(args.output, merged)
    summary = {
        "scans": list(args.scans),
        "poses": [None if p is None else p.tolist() for p in result.poses],
        "unconnected": [args.scans[k] for k in result.unconnected],
        "edges": [[args.scans[i], args.scans[j]] for i, j in result.edges],
        "voxel_size": result.voxel_size,
        "seconds": result.seconds,
    }
    if args.poses:
        Path(args.poses).write_text(json.dumps(summary, indent=2))
    if args.mesh:
        merged.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * voxel, max_nn=30))
        merged.orient_normals_consistent_tangent_plane(16)
        mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(merged, depth=9)
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


def _benchmark_multiway(args: argparse.Namespace) -> int:
    from ..evaluation.multiway import (
        OBJECTS,
        markdown,
        plot_reconstruction,
        run_multiway,
        timings_markdown,
    )
    from ..evaluation.report import write_split

    objects = args.protocol or list(OBJECTS)
    unknown = [o for o in objects if o not in OBJECTS]
    if unknown:
        raise CommandError(f"multiway objects are {list(OBJECTS)}, got {unknown}")
    results = run_multiway(objects, data=args.data, seed=args.seed)
    folder = Path(args.output)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, entry in results["objects"].items():
        for method in entry["methods"]:
            path = folder / f"multiway_{name}_{method}.png"
            plot_reconstruction(entry, method, path, f"{name}: {method}, scans by colour")
            written.append(str(path))
        del entry["moved"]
    files = write_split(results, folder, "multiway", markdown, timings_markdown)
    print(markdown(results))
    print("written: " + ", ".join([*files, *written]))
    return EXIT_OK


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


def cmd_demo(args: argparse.Namespace) -> int:
    from ..io import write_cloud
    from ..open3d_interop import to_point_cloud
    from ..plotting import save_registration_png
    from ..registration import register
    from ..transforms import rotation_error_deg, translation_error

    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    source, target, truth, name = _sample_pair(args)
    result = register(source, target)  # the pretrained R-PointHop model, RANSAC, then ICP
    write_cloud(out / "aligned.ply", to_point_cloud(source).transform(result.transformation))
    np.savetxt(out / "transform.txt", result.transformation, fmt="%.10f")
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
    save_registration_png(
        source,
        target,
        result.transformation,
        picture,
        title=f"{name}\nR-PointHop (pretrained) + RANSAC + ICP: {numbers}",
    )
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
        "outputs": [str(out / "aligned.ply"), str(out / "transform.txt"), str(picture)],
    }
    if errors is not None:
        summary["rotation_error_deg"] = round(errors[0], 4)
        summary["translation_error"] = errors[1]
    if args.json:
        print(json.dumps(summary, indent=2))
        return _flag_status(result)
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
    lines.append(f"  wrote {', '.join(summary['outputs'])} (the picture: before and after)")
    print("\n".join(lines))
    return _flag_status(result)


# --------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Rotation-invariant R-PointHop descriptors and registration for Open3D.",
        epilog=EXIT_CODES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    class _Sub:  # every command's --help lists the exit statuses too
        @staticmethod
        def add_parser(name, **kwargs):
            kwargs.setdefault("epilog", EXIT_CODES)
            kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
            return commands.add_parser(name, **kwargs)

    sub = _Sub()

    p = sub.add_parser(
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
    p.add_argument("--data", help="data folder (default: data_home(), docs/datasets.md)")
    p.add_argument("--synthetic", action="store_true", help="use the synthetic pair")
    p.add_argument("--json", action="store_true", help="print the full result as JSON")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser(
        "register",
        help="align SOURCE to TARGET: global estimate from descriptors, then ICP",
        description="Align SOURCE to TARGET and print the 4x4 transformation that maps the "
        "source into the target frame. Clouds: any format Open3D reads (.ply, .pcd, .xyz, "
        "...) or .npy/.npz/.txt/.csv.",
    )
    p.add_argument("source")
    p.add_argument("target")
    p.add_argument("--descriptor", choices=["rpointhop", "fpfh"], default="rpointhop")
    p.add_argument(
        "--model",
        help="R-PointHop model file, or a shipped model: modelnet40, scene (default: the "
        "ModelNet40 model on 128 axes)",
    )
    p.add_argument(
        "--global",
        dest="global_method",
        choices=["ransac", "fgr", "svd", "none"],
        default="ransac",
        help="global estimate (default: ransac)",
    )
    p.add_argument(
        "--refine",
        choices=["point_to_plane", "point_to_point", "generalized", "multiscale", "none"],
        default="point_to_plane",
        help="ICP refinement (default: point_to_plane)",
    )
    p.add_argument(
        "--symmetry-check",
        action="store_true",
        help="after ICP, also try the estimate's 180-degree twins and keep the best fit "
        "(objects seen whole; see docs/registration.md)",
    )
    p.add_argument("--voxel-size", type=_voxel, default="auto", help="'auto' or a length")
    p.add_argument(
        "--n-global-points",
        type=_global_points,
        default="auto",
        help="points per cloud for the global step: a count, or 'auto' (what the model "
        "states: 4096 for --model scene; else 2048)",
    )
    p.add_argument("--init", help="text file with a 4x4 start transformation (for ICP alone)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-o", "--output", help="write the aligned source cloud here")
    p.add_argument("--transform", help="write the transformation here (.txt: 4x4; .json: all)")
    p.add_argument("--json", action="store_true", help="print the full result as JSON")
    p.set_defaults(func=cmd_register)

    p = sub.add_parser(
        "benchmark",
        help="registration benchmarks against the paper and FPFH (JSON, markdown, PNG)",
        description="Run every method on the dataset's protocols in one run and write "
        "<output>/<dataset>.json, .md and .png. ModelNet40 protocols: paper, "
        "paper-unseen-classes, paper-noise, paper-partial, angle-sweep, resampled, "
        "resampled-noise, resampled-partial; bunny: scans, paper; multiway: bunny, dragon "
        "(every scan from an unknown pose, rebuilt with register_multiway).",
    )
    p.add_argument("dataset", choices=["modelnet40", "bunny", "3dmatch", "multiway"])
    p.add_argument("--protocol", nargs="+", help="protocols to run (default: all)")
    p.add_argument(
        "--methods",
        help="comma-separated methods (default: 3dmatch: scene, leave-one-scene-out and "
        "ModelNet40 models, FPFH recipes and pipeline; objects: every method that needs "
        "no scene)",
    )
    p.add_argument("--data", help="data folder (default: data_home(), docs/datasets.md)")
    p.add_argument("--output", default="benchmark_results", help="where results go")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-shapes", type=int, help="ModelNet40: use only the first N test shapes")
    p.add_argument(
        "--max-pairs", type=int, help="3DMatch: a seeded sample of N pairs per benchmark"
    )
    p.add_argument(
        "--scenes", help="3DMatch: comma-separated scene names (or parts of them) to keep"
    )
    p.add_argument(
        "--model",
        help="R-PointHop model file, or a shipped model: modelnet40, scene (default: "
        "register()'s default, the ModelNet40 model on 128 axes)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_benchmark)

    p = sub.add_parser(
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
    p.add_argument("--descriptor", choices=["rpointhop", "fpfh"], default="rpointhop")
    p.add_argument("--voxel-size", type=float, help="voxel of the merged cloud")
    p.add_argument("--n-jobs", type=int, help="parallel pair registrations")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=cmd_reconstruct)

    p = sub.add_parser("fit", help="fit an R-PointHop model on point cloud files")
    p.add_argument("clouds", nargs="+", help="training clouds (.ply, .pcd, .xyz, .npy, ...)")
    p.add_argument("-o", "--output", required=True, help="model file to write (.npz)")
    p.add_argument("--n-neighbors", type=_ints, help="per hop, e.g. 64,32,48,48")
    p.add_argument("--hop-sizes", type=_sizes, help="per hop, e.g. 1.0,0.75,0.5,0.375")
    p.add_argument("--lrf-neighbors", type=int)
    p.add_argument("--energy-threshold", type=float)
    p.add_argument("--fit-subsample", type=int)
    p.add_argument("--n-jobs", type=int)
    p.add_argument("--random-state", type=int)
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("describe", help="write one descriptor per point of a cloud (.npy)")
    p.add_argument("cloud")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="descriptor file to write (.npy format, this exact path)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help=f"write outputs over {MAX_OUTPUT_BYTES // 1024**2} MB (a 1624-D descriptor is "
        "6.5 kB a point)",
    )
    p.add_argument(
        "--model",
        help="model file written by 'fit', or a shipped model: modelnet40, scene (default: "
        "modelnet40)",
    )
    p.add_argument(
        "--n-components",
        type=int,
        help="project the descriptors on this many principal axes (pretrained: up to 128)",
    )
    p.set_defaults(func=cmd_describe)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (CommandError, ValueError, FileNotFoundError, OSError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # no traceback for a user: one line, and how to get more
        print(
            f"{PROG}: error: unexpected {type(exc).__name__}: {exc} (please report it; "
            f"'python -X dev -m o3d_rpointhop.cli ...' shows where)",
            file=sys.stderr,
        )
        return EXIT_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
