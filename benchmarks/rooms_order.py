"""Rooms from their fragments in five orders: does the order the files come in matter?

For every chosen 3DMatch scene, every fragment in its folder is given to
``register_multiway`` in five orders: by fragment number, reversed, and three seeded
shuffles. Each reconstruction is scored on the scene's ground-truth pairs (``gt.log`` of
3DMatch and 3DLoMatch, both fragments present): a pair counts when the relative pose of
its two fragments passes the official test (``gt.info`` RMSE below 0.2 m). Reported per
scene: the pairs counted and the fragments placed in each order, their spread, and the
largest difference between two orders in the relative pose of one pair of placed
fragments (which is zero when the order does not matter). One method per run, the
defaults (the model chosen from the scans, with the viewpoints) unless ``--model`` and
``--viewpoints`` say otherwise.

Writes ``rooms_order.json`` (and ``rooms_order_timings.json``, the times apart) to
``--output``::

    python benchmarks/rooms_order.py --scenes hotel1,lab_hj [--model scene] [--n-jobs 2]
"""

from __future__ import annotations

import argparse
import json
import time
from itertools import combinations
from pathlib import Path

import numpy as np

from o3d_rpointhop import RPointHopTransformer, register_multiway
from o3d_rpointhop.datasets.threedmatch import threedmatch_root
from o3d_rpointhop.evaluation._common import machine_facts
from o3d_rpointhop.evaluation.provenance import descriptor_provenance
from o3d_rpointhop.evaluation.report import write_split
from o3d_rpointhop.evaluation.rooms import RECALL_RMSE, pairs_registered, scene_data
from o3d_rpointhop.transforms import rotation_error_deg

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
#: Seeds of the three shuffled orders.
SHUFFLES = (0, 1, 2)


def orders(n: int) -> dict[str, list[int]]:
    """The five orders of ``n`` fragments: by number, reversed, three seeded shuffles."""
    found = {"by number": list(range(n)), "reversed": list(range(n))[::-1]}
    for seed in SHUFFLES:
        found[f"shuffle {seed}"] = [int(k) for k in np.random.default_rng(seed).permutation(n)]
    return found


def relative(poses: dict[int, np.ndarray], i: int, j: int) -> np.ndarray | None:
    """Fragment ``j`` into fragment ``i``'s frame, when both are placed."""
    if poses.get(i) is None or poses.get(j) is None:
        return None
    return np.linalg.inv(poses[i]) @ poses[j]


def run_scene(root, scene, descriptor, viewpoints, n_jobs, seed, sequential=False) -> dict:
    ids, points, truth = scene_data(root, scene)
    runs, poses_by_order = {}, {}
    for name, order in orders(len(ids)).items():
        start = time.perf_counter()
        result = register_multiway(
            [points[k] for k in order],
            descriptor,
            viewpoints=viewpoints,
            n_jobs=n_jobs,
            random_state=seed,
            progress=False,
            sequential=sequential,
        )
        seconds = time.perf_counter() - start
        poses = {ids[k]: result.poses[place] for place, k in enumerate(order)}
        runs[name] = {
            "gt_pairs_registered": pairs_registered(poses, truth),
            "placed": sum(p is not None for p in poses.values()),
            "seconds": round(seconds, 1),
        }
        poses_by_order[name] = poses
        print(scene, name, json.dumps(runs[name]), flush=True)
    # The largest difference between two orders in one pair's relative pose.
    worst_rot, worst_shift = 0.0, 0.0
    for a, b in combinations(poses_by_order.values(), 2):
        for i, j in combinations(ids, 2):
            x, y = relative(a, i, j), relative(b, i, j)
            if x is None or y is None:
                continue
            worst_rot = max(worst_rot, rotation_error_deg(x, y))
            worst_shift = max(worst_shift, float(np.linalg.norm(x[:3, 3] - y[:3, 3])))
    counts = [r["gt_pairs_registered"] for r in runs.values()]
    return {
        "fragments": len(ids),
        "gt_pairs": len(truth),
        "orders": runs,
        "min": min(counts),
        "max": max(counts),
        "spread": max(counts) - min(counts),
        "largest_pose_difference_deg": round(worst_rot, 4),
        "largest_pose_difference_m": round(worst_shift, 5),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="data folder (default: data_home())")
    parser.add_argument("--scenes", required=True, help="comma-separated scene names or parts")
    parser.add_argument(
        "--model",
        default="auto",
        help="a shipped model name, or auto (register_multiway's default: chosen from the "
        "scans, with the viewpoints)",
    )
    parser.add_argument("--viewpoints", choices=("auto", "origin", "none"), default="auto")
    parser.add_argument("--n-jobs", type=int, default=-1)
    parser.add_argument(
        "--sequential",
        choices=("yes", "no"),
        default="no",
        help="pair each fragment with those given next to it (register_multiway's sequential)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    root = threedmatch_root(args.data)
    wanted = [s.strip() for s in args.scenes.split(",") if s.strip()]
    scenes = [
        p.name for p in sorted((root / "fragments").iterdir()) if any(w in p.name for w in wanted)
    ]
    if not scenes:
        parser.error(f"no scene matches {wanted}")
    auto = args.model == "auto"
    descriptor = "auto" if auto else RPointHopTransformer.pretrained(args.model)
    viewpoints = None if args.viewpoints == "none" else args.viewpoints
    out = {
        "settings": {
            "model": args.model,
            "viewpoints": args.viewpoints,
            "sequential": args.sequential,
            "seed": args.seed,
            "orders": "by number, reversed, shuffles " + ", ".join(map(str, SHUFFLES)),
            "recall_rmse": RECALL_RMSE,
            "machine": machine_facts()["machine"],
        },
        "scenes": {},
    }
    sequential = args.sequential == "yes"
    for scene in scenes:
        out["scenes"][scene] = run_scene(
            root, scene, descriptor, viewpoints, args.n_jobs, args.seed, sequential
        )
    models = ("object", "scene") if auto else (args.model,)
    out["provenance"] = descriptor_provenance(
        {f"rpointhop-{m}": RPointHopTransformer.pretrained(m) for m in models}
    )
    write_split(out, args.output, "rooms_order")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
