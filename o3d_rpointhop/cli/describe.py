"""``o3d-rpointhop describe``: one descriptor per point of a cloud, to a ``.npy`` file."""

from __future__ import annotations

import argparse
import time

import numpy as np

from ._common import (
    EXIT_OK,
    MAX_OUTPUT_BYTES,
    add_config,
    add_descriptor,
    add_model,
    add_viewpoints,
    check_size,
)
from ._config import load_config
from ._descriptor import descriptor_from
from ._record import run_record, write_record


def add_parser(commands) -> None:
    p = commands.add_parser("describe", help="write one descriptor per point of a cloud (.npy)")
    p.add_argument("cloud", help="the cloud to describe (.ply, .las, .e57, .npy, ...)")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="descriptor file to write (.npy format, this exact path); what made it is "
        "recorded beside it in <output>.json",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help=f"write outputs over {MAX_OUTPUT_BYTES // 1024**2} MB (a 1624-D descriptor is "
        "6.5 kB a point)",
    )
    add_descriptor(p)
    add_model(p, default="modelnet40")
    p.add_argument(
        "--n-components",
        type=int,
        help="project the descriptors on this many principal axes (pretrained: up to 128)",
    )
    add_viewpoints(p, "cloud")
    add_config(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..io import check_output_path, read_cloud, save_npy

    config = load_config(args.config, args.set)
    model, section = descriptor_from(
        config, args.descriptor, args.model, args.n_components, registering=False
    )
    record = run_record("describe", {"descriptor": section}, model)
    check_output_path(args.output)
    cloud = read_cloud(args.cloud)
    if hasattr(model, "n_features_out_"):
        # 4 bytes a value, plus the header: refuse before spending the time.
        check_size(args.output, 4 * len(cloud.points) * model.n_features_out_, args.force)
    start = time.perf_counter()
    if "progress" in model.get_params():
        model.set_params(progress=None)
    desc = model.transform(cloud, viewpoints=args.viewpoints)
    save_npy(args.output, np.ascontiguousarray(desc))
    write_record(args.output, record)
    print(
        f"{len(desc)} points described ({desc.shape[1]}-D) in "
        f"{time.perf_counter() - start:.3f} s, written to {args.output}"
    )
    return EXIT_OK
