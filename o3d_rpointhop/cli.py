"""Command line interface: ``o3d-rpointhop <command> ...``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from . import __version__

PROG = "o3d-rpointhop"


class CommandError(Exception):
    """A failure to report as one line on stderr with exit status 1."""


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


def _load_model(path: str):
    from .rpointhop import RPointHopTransformer

    return RPointHopTransformer.load(path)


# --------------------------------------------------------------------------- commands
def cmd_fit(args: argparse.Namespace) -> int:
    from .io import read_cloud
    from .rpointhop import RPointHopTransformer

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
    from .io import read_cloud

    cloud = read_cloud(args.cloud)
    model = _load_model(args.model)
    start = time.perf_counter()
    desc = model.transform(cloud)
    np.save(args.output, np.ascontiguousarray(desc))
    print(
        f"{len(desc)} points described ({desc.shape[1]}-D) in "
        f"{time.perf_counter() - start:.3f} s, written to {args.output}"
    )
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from .datasets import make_blob
    from .rpointhop import RPointHopTransformer

    out = Path(args.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    train = [make_blob(1024, shape_seed=s) for s in range(16)]
    start = time.perf_counter()
    model = RPointHopTransformer(random_state=0).fit(train)
    fit_s = time.perf_counter() - start
    cloud = make_blob(1024, shape_seed=100)
    start = time.perf_counter()
    desc = model.transform(cloud)
    describe_s = time.perf_counter() - start
    model.save(out / "demo_model.npz")
    np.save(out / "demo_descriptors.npy", np.ascontiguousarray(desc))
    summary = {
        "fit_clouds": len(train),
        "fit_seconds": round(fit_s, 3),
        "points": len(cloud),
        "descriptor_dim": int(desc.shape[1]),
        "describe_seconds": round(describe_s, 4),
        "outputs": [str(out / "demo_model.npz"), str(out / "demo_descriptors.npy")],
    }
    print(json.dumps(summary, indent=2))
    return 0


# --------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Rotation-invariant R-PointHop descriptors and registration for Open3D.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("demo", help="fit a model on sample clouds and describe one")
    p.add_argument("--output-dir", default="demo_output", help="where results go")
    p.set_defaults(func=cmd_demo)

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
    p.add_argument("-o", "--output", required=True, help="descriptor file to write (.npy)")
    p.add_argument("--model", required=True, help="model file written by 'fit'")
    p.set_defaults(func=cmd_describe)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (CommandError, ValueError, FileNotFoundError, OSError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
