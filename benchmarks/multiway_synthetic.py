"""Many scans at once: 50 partial views of one synthetic object, unposed, in one call.

Each scan keeps the 70 % of a freshly sampled copy of ``make_object(shape_seed=21)``
nearest to a random point of it (a partial view, 2400 points before the crop), and every
scan but the first is moved by a random rigid motion (rotation uniform over SO(3),
translation up to 0.5). :func:`~o3d_rpointhop.register_multiway` recovers the poses with
the pretrained R-PointHop model and with FPFH through the same pipeline (candidate pairs
from pooled-descriptor retrieval above 12 scans). Reported: wall time, scans placed,
scans within 2 deg and 2 % of the object's radius of their true pose.

Usage: python benchmarks/multiway_synthetic.py [--scans 50] [--n-jobs 2] [--output DIR]
Writes DIR/multiway_synthetic.json (what was found: a rerun leaves it unchanged) and
DIR/multiway_synthetic_timings.json (wall times and machine).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from o3d_rpointhop import FPFHTransformer, register_multiway
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation._common import machine_facts
from o3d_rpointhop.evaluation.protocols import crop_nearest
from o3d_rpointhop.evaluation.provenance import multiway_provenance
from o3d_rpointhop.evaluation.report import write_split
from o3d_rpointhop.transforms import apply_transform, random_rigid_motion, rotation_error_deg

RESULTS = Path(__file__).resolve().parent / "results"
TOLERANCE = (2.0, 0.02)  # degrees, share of the unit-size object's radius


def make_scans(n_scans: int, seed: int = 0) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The moved scans and each scan's true pose in scan 0's frame."""
    rng = np.random.default_rng(seed)
    scans, poses = [], []
    for k in range(n_scans):
        whole = make_object(2400, shape_seed=21, sample_seed=1000 + k)
        view = whole[crop_nearest(whole, 0.7, rng)]
        motion = random_rigid_motion(rng, 0.5) if k else np.eye(4)
        scans.append(apply_transform(view, motion))
        poses.append(np.linalg.inv(motion))
    return scans, poses


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=50)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    scans, truth = make_scans(args.scans, args.seed)
    out = {
        "settings": {
            "scans": args.scans,
            "n_jobs": args.n_jobs,
            "seed": args.seed,
            "tolerance": TOLERANCE,
            "machine": machine_facts()["machine"],
        },
        "methods": {},
    }
    for method, descriptor in (("rpointhop", None), ("fpfh", FPFHTransformer())):
        start = time.perf_counter()
        result = register_multiway(scans, descriptor, n_jobs=args.n_jobs, random_state=args.seed)
        seconds = time.perf_counter() - start
        rot, gap = [], []
        for k, pose in enumerate(result.poses):
            if pose is None:
                continue
            rot.append(rotation_error_deg(pose, truth[k]))
            moved = apply_transform(scans[k], pose) - apply_transform(scans[k], truth[k])
            gap.append(float(np.linalg.norm(moved, axis=1).mean()))
        within = sum(r < TOLERANCE[0] and g < TOLERANCE[1] for r, g in zip(rot, gap, strict=True))
        out["methods"][method] = {
            "seconds": round(seconds, 1),
            "placed": len(rot),
            "within_tolerance": int(within),
            "unconnected": result.unconnected,
            "pairs_tried": len(result.pairs),
            "edges_kept": len(result.edges),
            "max_rotation_error_deg": round(max(rot), 3) if rot else None,
            "max_mean_point_error": round(max(gap), 4) if gap else None,
        }
        print(method, json.dumps(out["methods"][method]), flush=True)
    out["provenance"] = multiway_provenance(["rpointhop", "fpfh"])
    write_split(out, args.output, "multiway_synthetic")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
