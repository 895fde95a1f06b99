"""``o3d-rpointhop fit``: fit an R-PointHop model on point cloud files."""

from __future__ import annotations

import argparse
import time

from ._common import EXIT_OK, UsageError, add_config, add_viewpoints
from ._config import estimator_section, load_config
from ._record import run_record, write_record


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


#: Options that become RPointHopTransformer parameters of the same name.
_PARAMETERS = (
    "n_neighbors",
    "hop_sizes",
    "pooling",
    "lrf_neighbors",
    "energy_threshold",
    "fit_subsample",
    "n_jobs",
    "random_state",
)


def add_parser(commands) -> None:
    p = commands.add_parser("fit", help="fit an R-PointHop model on point cloud files")
    p.add_argument("clouds", nargs="+", help="training clouds (.ply, .las, .e57, .npy, ...)")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="model file to write (.npz); what made it is recorded beside it in <output>.json",
    )
    p.add_argument(
        "--scene",
        action="store_true",
        help="the scene variant: the shipped scene model's recipe (normals and eigenvalue "
        "features as attributes, one hop of 96 neighbours, 96 axes); other options "
        "override it",
    )
    p.add_argument(
        "--n-components",
        type=_components,
        default=argparse.SUPPRESS,
        help="principal axes the model keeps ('none': the full descriptor)",
    )
    p.add_argument(
        "--pooling",
        choices=["octants", "azimuth"],
        help="the eight bins each neighbourhood is averaged over: the local frame's octants "
        "(R-PointHop's, default) or above / below the tangent plane times four distance "
        "shells (only the normal axis counts: walls and floors)",
    )
    p.add_argument("--n-neighbors", type=_ints, help="per hop, e.g. 64,32,48,48")
    p.add_argument("--hop-sizes", type=_sizes, help="per hop, e.g. 1.0,0.75,0.5,0.375")
    p.add_argument(
        "--lrf-neighbors",
        type=int,
        help="points whose principal axes give each point's local frame (default 64; the "
        "paper's scene variant: 256)",
    )
    p.add_argument(
        "--energy-threshold",
        type=float,
        help="channels whose share of the variance falls below this are not passed to the "
        "next hop (default 0.001)",
    )
    p.add_argument(
        "--fit-subsample",
        type=int,
        help="draw at most this many points of each training cloud at random (the paper: "
        "1024 of ModelNet40's 2048; default: every point)",
    )
    p.add_argument(
        "--n-jobs",
        type=int,
        help="processes over the training clouds (-1: every core; default 1); the model "
        "does not depend on it",
    )
    p.add_argument(
        "--random-state",
        type=int,
        help="seeds --fit-subsample (everything else is deterministic; default: unseeded)",
    )
    add_viewpoints(p, "training cloud")
    add_config(p)
    p.set_defaults(func=run)


def _components(text: str) -> int | None:
    if text.lower() == "none":
        return None
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive count or 'none', got {text!r}")
    return value


def run(args: argparse.Namespace) -> int:
    from ..descriptors import RPointHopTransformer
    from ..io import check_output_path, read_cloud

    # The recipe (--scene), then [fit] and [descriptor] n_jobs, then the flags.
    config = load_config(args.config, args.set)
    params: dict = {}
    if args.scene:
        from ..evaluation.scene_models import SCENE_PARAMS

        params.update(SCENE_PARAMS)
    params.update(config.get("fit", {}))
    if config.get("descriptor", {}).get("n_jobs") is not None:
        params["n_jobs"] = config["descriptor"]["n_jobs"]
    params.update(
        {name: getattr(args, name) for name in _PARAMETERS if getattr(args, name) is not None}
    )
    if hasattr(args, "n_components"):  # given ('none' too)
        params["n_components"] = args.n_components
    try:
        estimator = RPointHopTransformer(**params)
        estimator.validate()
    except (ValueError, TypeError) as exc:
        raise UsageError(f"[fit]: {exc}") from None
    check_output_path(args.output)
    clouds = [read_cloud(p) for p in args.clouds]
    start = time.perf_counter()
    model = estimator.fit(clouds, viewpoints=args.viewpoints)
    model.save(args.output)
    record = run_record("fit", {"fit": estimator_section(model)}, model)
    record["training_clouds"] = list(args.clouds)
    write_record(args.output, record)
    print(
        f"fitted on {len(clouds)} clouds in {time.perf_counter() - start:.2f} s: "
        f"{model.n_features_out_}-D descriptors, model written to {args.output}"
    )
    return EXIT_OK
