"""Speed of RPointHopTransformer against Open3D FPFH, measured in the same run.

* transform: one 1024-point object in the unit sphere (a ModelNet40 test shape, or a
  synthetic one without the data), timed interleaved with Open3D FPFH on the same cloud
  (normals radius 0.1, FPFH radius 0.25, max_nn 100); medians and their ratio.
* fit: the ModelNet40 train subset (first 1024 points of each shape), wall time with
  1 and 2 processes, and the fitting process's peak memory.
* bounded memory: peak memory of fits on 1x and 4x the training set with the cache
  budget lowered, each in a fresh process.

Usage: python benchmarks/speed.py [--data PATH] [--repeats 100] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np

from o3d_rpointhop import FPFHTransformer, RPointHopTransformer
from o3d_rpointhop.datasets import load_modelnet40, make_blob
from o3d_rpointhop.descriptors import descriptor_identity
from o3d_rpointhop.evaluation._common import machine_facts, peak_rss_mb
from o3d_rpointhop.evaluation.provenance import descriptor_provenance


def training_clouds(data):
    try:
        return list(load_modelnet40("train", data).points[:, :1024]), "ModelNet40 train subset"
    except FileNotFoundError:
        return [make_blob(1024, shape_seed=s) for s in range(144)], "144 synthetic blobs"


def test_object(data):
    try:
        return load_modelnet40("test", data).points[0, :1024], "ModelNet40 test shape 0"
    except FileNotFoundError:
        return make_blob(1024, shape_seed=1000), "synthetic blob"


def fit_memory_child(n_copies: int, budget_mb: float, data) -> None:
    """Run in a fresh process: fit on n_copies x the training set, print peak RSS."""
    import o3d_rpointhop.descriptors.pointhop._tree as module

    module.FIT_CACHE_BYTES = int(budget_mb * 1024**2)
    clouds, _ = training_clouds(data)
    rng = np.random.default_rng(0)
    many = [c + rng.normal(scale=1e-3, size=c.shape) for _ in range(n_copies) for c in clouds]
    before = peak_rss_mb()
    t = time.perf_counter()
    RPointHopTransformer().fit(many)
    print(
        json.dumps(
            {
                "clouds": len(many),
                "budget_mb": budget_mb,
                "seconds": time.perf_counter() - t,
                "rss_before_mb": before,
                "peak_rss_mb": peak_rss_mb(),
            }
        )
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", default=None, help="data folder (default: ../shared/data)")
    parser.add_argument("--repeats", type=int, default=100)
    parser.add_argument("--json", default=None, help="write the results here")
    parser.add_argument("--skip-memory", action="store_true")
    parser.add_argument("--_memory-child", nargs=2, type=float, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args._memory_child:
        fit_memory_child(int(args._memory_child[0]), args._memory_child[1], args.data)
        return

    facts = machine_facts()
    clouds, train_name = training_clouds(args.data)
    cloud, cloud_name = test_object(args.data)
    results = {
        **{k: facts[k] for k in ("machine", "python", "open3d", "numpy")},
    }

    fits = {}
    for n_jobs in (1, 2):
        t = time.perf_counter()
        model = RPointHopTransformer(n_jobs=n_jobs).fit(clouds)
        fits[n_jobs] = time.perf_counter() - t
    results["fit"] = {
        "data": train_name,
        "clouds": len(clouds),
        "seconds_1_job": fits[1],
        "seconds_2_jobs": fits[2],
        "peak_rss_mb": peak_rss_mb(),
        "n_features_out": model.n_features_out_,
    }

    fpfh = FPFHTransformer(radius=0.25, max_nn=100, normal_radius=0.1, normal_max_nn=30)
    model.transform(cloud), fpfh.transform(cloud)  # warm up
    t_rph, t_fpfh = [], []
    for _ in range(args.repeats):
        t = time.perf_counter()
        model.transform(cloud)
        t_rph.append(time.perf_counter() - t)
        t = time.perf_counter()
        fpfh.transform(cloud)
        t_fpfh.append(time.perf_counter() - t)
    med_rph, med_fpfh = np.median(t_rph), np.median(t_fpfh)
    results["transform"] = {
        "cloud": cloud_name,
        "points": len(cloud),
        "repeats": args.repeats,
        "rpointhop_ms": 1e3 * med_rph,
        "fpfh_ms": 1e3 * med_fpfh,
        "ratio_rpointhop_over_fpfh": med_rph / med_fpfh,
        "rpointhop_p10_ms": 1e3 * np.percentile(t_rph, 10),
        "fpfh_p10_ms": 1e3 * np.percentile(t_fpfh, 10),
    }

    if not args.skip_memory:
        runs = []
        for copies, budget in ((1, 2048), (1, 64), (4, 64)):
            cmd = [sys.executable, __file__, "--_memory-child", str(copies), str(budget)]
            if args.data:
                cmd += ["--data", args.data]
            out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
            runs.append(json.loads(out.strip().splitlines()[-1]))
        results["fit_memory"] = runs

    results["provenance"] = descriptor_provenance(
        {
            "rpointhop": model,
            "fpfh": descriptor_identity(fpfh),
        },
        threads="one and two jobs for the fit; the transform on the default budget",
    )
    print(json.dumps(results, indent=2))
    tr = results["transform"]
    print(
        f"\ntransform {tr['points']} points: R-PointHop {tr['rpointhop_ms']:.1f} ms, "
        f"FPFH {tr['fpfh_ms']:.1f} ms, ratio {tr['ratio_rpointhop_over_fpfh']:.2f}"
    )
    print(f"fit {len(clouds)} clouds: {fits[1]:.2f} s (1 job), {fits[2]:.2f} s (2 jobs)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)


if __name__ == "__main__":
    main()
