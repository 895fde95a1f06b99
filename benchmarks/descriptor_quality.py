"""Descriptor quality on real shapes: R-PointHop against Open3D FPFH, same pairs, same run.

Protocol (ModelNet40 subset in ../shared/data, or --data): the model is fitted on the
train shapes (points 0-1023 of each). For every test shape the target is points
0-1023 and the source is points 1024-2047 (a different sample of the same surface),
rotated uniformly over SO(3) and translated. For each source point we take the target
point with the nearest descriptor and count it correct when it lies within 0.05 (and
0.1) of the source point's true position; "chance" is the same count for a random
target point.

Usage: python benchmarks/descriptor_quality.py [--data PATH] [--seed 0] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from o3d_rpointhop import FPFHTransformer, RPointHopTransformer
from o3d_rpointhop.datasets import load_modelnet40
from o3d_rpointhop.descriptors import descriptor_identity
from o3d_rpointhop.evaluation.provenance import descriptor_provenance
from o3d_rpointhop.transforms import apply_transform, random_rigid_motion


def nearest_descriptor(source_desc: np.ndarray, target_desc: np.ndarray) -> np.ndarray:
    """For each source row, the index of the nearest target row (Euclidean)."""
    a = np.asarray(source_desc, dtype=np.float64)
    b = np.asarray(target_desc, dtype=np.float64)
    sq = (a * a).sum(1)[:, None] - 2.0 * a @ b.T + (b * b).sum(1)[None, :]
    return sq.argmin(axis=1)


def noisy_pairs(points: np.ndarray, seed: int, noise: float = 0.0):
    rng = np.random.default_rng(seed)
    pairs = []
    for shape in points:
        target = shape[:1024]
        truth = shape[1024:2048]
        observed = truth
        if noise:
            observed = truth + np.clip(rng.normal(scale=noise, size=truth.shape), -0.05, 0.05)
        motion = random_rigid_motion(rng, 0.5)
        pairs.append((apply_transform(observed, motion), target, truth))
    return pairs


def evaluate(describe, pairs, radii=(0.05, 0.1)) -> dict:
    hits = {r: [] for r in radii}
    chance = {r: [] for r in radii}
    rng = np.random.default_rng(123)
    seconds = 0.0
    for source, target, truth in pairs:
        t = time.perf_counter()
        d_src, d_tgt = describe(source), describe(target)
        seconds += time.perf_counter() - t
        error = np.linalg.norm(target[nearest_descriptor(d_src, d_tgt)] - truth, axis=1)
        random_error = np.linalg.norm(target[rng.permutation(len(target))] - truth, axis=1)
        for r in radii:
            hits[r].append(np.mean(error < r))
            chance[r].append(np.mean(random_error < r))
    out = {f"correct_within_{r}": float(np.mean(hits[r])) for r in radii}
    out.update({f"chance_within_{r}": float(np.mean(chance[r])) for r in radii})
    out["seconds_per_cloud"] = seconds / (2 * len(pairs))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    train = load_modelnet40("train", args.data)
    test = load_modelnet40("test", args.data)

    models = {
        "R-PointHop (paper settings)": RPointHopTransformer(random_state=0),
        "R-PointHop (energy_threshold=0.005)": RPointHopTransformer(
            energy_threshold=0.005, random_state=0
        ),
    }
    results = {"train_shapes": len(train), "test_shapes": len(test), "seed": args.seed}
    rows = []
    for protocol, noise in (("resampled", 0.0), ("resampled + noise 0.01", 0.01)):
        pairs = noisy_pairs(test.points, args.seed, noise)
        for name, model in models.items():
            if not hasattr(model, "kernels_"):
                t = time.perf_counter()
                model.fit(list(train.points[:, :1024]))
                results[f"{name} fit_seconds"] = time.perf_counter() - t
                results[f"{name} n_features_out"] = model.n_features_out_
            rows.append({"protocol": protocol, "method": name, **evaluate(model.transform, pairs)})
        fpfh = FPFHTransformer(radius=0.25, max_nn=100, normal_radius=0.1)
        rows.append(
            {"protocol": protocol, "method": "FPFH (Open3D)", **evaluate(fpfh.transform, pairs)}
        )
    results["rows"] = rows
    results["provenance"] = descriptor_provenance(
        {**models, "FPFH (Open3D)": descriptor_identity(fpfh)}, threads="default"
    )

    header = "| protocol | method | correct within 0.05 | within 0.1 | chance (0.05 / 0.1) |"
    print(header + " s per cloud |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['protocol']} | {r['method']} | {100 * r['correct_within_0.05']:.1f} % | "
            f"{100 * r['correct_within_0.1']:.1f} % | {100 * r['chance_within_0.05']:.1f} % / "
            f"{100 * r['chance_within_0.1']:.1f} % | {r['seconds_per_cloud']:.3f} |"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)


if __name__ == "__main__":
    main()
