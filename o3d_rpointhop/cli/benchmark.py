"""``o3d-rpointhop benchmark``: the registration benchmarks, in one run per dataset."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import EXIT_OK, CommandError, add_data, add_model, add_seed, load_model


def add_parser(commands) -> None:
    p = commands.add_parser(
        "benchmark",
        help="registration benchmarks against the paper and FPFH (JSON, markdown, PNG)",
    )
    from ..evaluation.bunny import BUNNY_PROTOCOLS
    from ..evaluation.methods import DATASETS
    from ..evaluation.modelnet40 import MODELNET40_PROTOCOLS
    from ..evaluation.multiway import OBJECTS

    p.description = (
        "Run every method on the dataset's protocols in one run and write "
        "<output>/<dataset>.json, .md and .png. ModelNet40 protocols: "
        f"{', '.join(MODELNET40_PROTOCOLS)}; bunny: {', '.join(BUNNY_PROTOCOLS)}; "
        f"multiway: {', '.join(OBJECTS)} (every scan from an unknown pose, rebuilt with "
        "register_multiway); rooms: every 3DMatch scene of the data folder rebuilt from its "
        "unposed fragments (--scenes to choose), against Open3D's multiway recipe."
    )
    p.add_argument(
        "dataset", choices=[*DATASETS, "multiway", "rooms"], help="what to run the methods on"
    )
    p.add_argument("--protocol", nargs="+", help="protocols to run (default: all)")
    p.add_argument(
        "--methods",
        help="comma-separated methods (default: the dataset's own set; "
        "o3d_rpointhop.evaluation.methods.METHODS lists every one)",
    )
    add_data(p)
    p.add_argument("--output", default="benchmark_results", help="where results go")
    add_seed(p)
    p.add_argument("--max-shapes", type=int, help="ModelNet40: use only the first N test shapes")
    p.add_argument(
        "--max-pairs", type=int, help="3DMatch: a seeded sample of N pairs per benchmark"
    )
    p.add_argument(
        "--scenes", help="3DMatch: comma-separated scene names (or parts of them) to keep"
    )
    p.add_argument(
        "--rotate",
        action="store_true",
        help="3DMatch: turn every source fragment by a random rotation (uniform over SO(3), "
        "seeded) before registering",
    )
    p.add_argument(
        "--with-consecutive",
        action="store_true",
        help="3DMatch: keep the pairs of consecutive fragments, which the official protocol "
        "leaves out",
    )
    p.add_argument(
        "--viewpoints",
        choices=["origin", "none"],
        default="origin",
        help="3DMatch: tell the descriptors where the sensors stood ('origin', the default: "
        "every fragment is in its camera's frame) or not ('none')",
    )
    p.add_argument(
        "--n-jobs",
        type=int,
        default=-1,
        help="multiway: parallel pair registrations (default -1: all cores, as Open3D's "
        "recipe uses; the poses do not depend on it)",
    )
    p.add_argument(
        "--threads",
        choices=["one", "all"],
        default="one",
        help="thread budget of both sides of the pair benchmarks: one thread each (the "
        "default), or every core each (Open3D's RANSAC and FGR stay on one thread: only "
        "so does a seed repeat them); the results do not depend on it, the timings do",
    )
    add_model(p, default="register()'s default, the one-hop object model")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..evaluation.methods import default_methods
    from ..evaluation.report import markdown, write_report
    from ..evaluation.runner import thread_budget
    from ..registration.defaults import default_descriptor

    if args.dataset == "multiway":
        return _multiway(args)
    if args.dataset == "rooms":
        return _rooms(args)
    if args.rotate and args.dataset != "3dmatch":
        raise CommandError("--rotate applies to 3dmatch (the object protocols rotate already)")
    if args.dataset != "3dmatch" and (args.with_consecutive or args.viewpoints != "origin"):
        raise CommandError("--with-consecutive and --viewpoints apply to 3dmatch")
    methods = args.methods.split(",") if args.methods else default_methods(args.dataset)
    model = load_model(args.model) if args.model else default_descriptor()
    common = dict(data=args.data, seed=args.seed, model=model, progress=not args.no_progress)
    with thread_budget(args.threads):
        results = _pairs(args, methods, common)
    paths = write_report(results, args.output)
    print(markdown(results))  # with the timings: the terminal is not a result file
    print("written: " + ", ".join(paths))
    return EXIT_OK


def _pairs(args: argparse.Namespace, methods: list[str], common: dict) -> dict:
    """The pair benchmark of ``args.dataset``."""
    from ..evaluation.bunny import default_protocols, run_bunny
    from ..evaluation.modelnet40 import MODELNET40_PROTOCOLS, run_modelnet40
    from ..evaluation.threedmatch import run_3dmatch

    if args.dataset == "modelnet40":
        protocols = args.protocol or list(MODELNET40_PROTOCOLS)
        results = run_modelnet40(protocols, methods, max_shapes=args.max_shapes, **common)
    elif args.dataset == "bunny":
        protocols = args.protocol or default_protocols(common.get("data"))
        results = run_bunny(protocols, methods, **common)
    else:
        if args.protocol:
            raise CommandError("3dmatch has no protocols to choose")
        scenes = args.scenes.split(",") if args.scenes else None
        results = run_3dmatch(
            methods,
            max_pairs=args.max_pairs,
            scenes=scenes,
            rotate=args.rotate,
            official=not args.with_consecutive,
            viewpoints=None if args.viewpoints == "none" else "origin",
            **common,
        )
    return results


def _multiway(args: argparse.Namespace) -> int:
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
    run = run_multiway(objects, data=args.data, seed=args.seed, n_jobs=args.n_jobs)
    folder = Path(args.output)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, entry in run.results["objects"].items():
        for method in entry["methods"]:
            path = folder / f"multiway_{name}_{method}.png"
            plot_reconstruction(run, name, method, path, f"{name}: {method}, scans by colour")
            written.append(str(path))
    files = write_split(run.results, folder, "multiway", markdown, timings_markdown)
    print(markdown(run.results))
    print("written: " + ", ".join([*files, *written]))
    return EXIT_OK


def _rooms(args: argparse.Namespace) -> int:
    from ..evaluation.provenance import rooms_provenance
    from ..evaluation.report import write_split
    from ..evaluation.rooms import ROOM_METHODS, markdown, run_rooms, timings_markdown

    methods = tuple(args.methods.split(",")) if args.methods else tuple(ROOM_METHODS)
    scenes = args.scenes.split(",") if args.scenes else None
    try:
        results = run_rooms(scenes, methods, data=args.data, seed=args.seed, n_jobs=args.n_jobs)
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    results["provenance"] = rooms_provenance(methods)
    folder = Path(args.output)
    folder.mkdir(parents=True, exist_ok=True)
    files = write_split(results, folder, "rooms", markdown, timings_markdown)
    print(markdown(results))
    print(timings_markdown(results))
    print("written: " + ", ".join(files))
    return EXIT_OK
