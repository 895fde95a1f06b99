"""How a user puts Open3D on one thread, measured: which ways really limit it, and what
the one-thread budget of the benchmarks should be.

Open3D's normals + FPFH on a bunny scan (or a synthetic object without the data) and
Open3D's nearest-point distances between two 400k-point clouds, each in a fresh
process, under:

* ``default``: nothing set (every core);
* ``OMP_NUM_THREADS=1`` in the environment;
* ``threadpoolctl.threadpool_limits(1)`` around the calls;
* ``open3d.utility.set_max_threads(1)`` (what ``evaluation.runner``'s one-thread
  budget sets);
* ``taskset -c 0`` (the process pinned to one core: one thread whatever the library
  does), where ``taskset`` exists.

Prints and writes ``benchmarks/results/thread_budgets.{json,md}``: the median time of
each, and the thread count Open3D reports (``get_max_threads``).

Usage: python benchmarks/thread_budgets.py [--data PATH] [--repeats 15]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"

#: The ways tried, each an environment, a command prefix and what runs inside.
WAYS = {
    "default": ({}, [], "none"),
    "OMP_NUM_THREADS=1": ({"OMP_NUM_THREADS": "1"}, [], "none"),
    "threadpoolctl.threadpool_limits(1)": ({}, [], "threadpoolctl"),
    "open3d.utility.set_max_threads(1)": ({}, [], "set_max_threads"),
    "taskset -c 0": ({}, ["taskset", "-c", "0"], "none"),
}

# What each fresh process runs: ``mode``, data folder and repeats on argv.
_CHILD = r"""
import json, sys, time
import numpy as np
import open3d as o3d

mode, data, repeats = sys.argv[1], sys.argv[2], int(sys.argv[3])
try:
    from o3d_rpointhop.datasets.bunny import load_bunny

    points = load_bunny(("bun000",), data_dir=data or None)["bun000"].points
    what = "bunny bun000 at 2.5 mm"
except (FileNotFoundError, ValueError):
    from o3d_rpointhop.datasets import make_object

    points = make_object(20000, shape_seed=3, sample_seed=1) * 0.08
    what = "a synthetic object"
scan = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(0.0025)
rng = np.random.default_rng(0)
a = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.random((400_000, 3))))
b = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.random((400_000, 3))))
if mode == "set_max_threads":
    o3d.utility.set_max_threads(1)
if mode == "threadpoolctl":
    from threadpoolctl import threadpool_limits

    limit = threadpool_limits(1)


def fpfh():
    cloud = o3d.geometry.PointCloud(scan)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.005, max_nn=30))
    o3d.pipelines.registration.compute_fpfh_feature(
        cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=0.0125, max_nn=100)
    )


def distances():
    a.compute_point_cloud_distance(b)


out = {"cloud": what, "points": len(scan.points), "threads": o3d.utility.get_max_threads()}
for name, job in (("fpfh", fpfh), ("distances", distances)):
    job()
    times = []
    for _ in range(repeats if name == "fpfh" else max(3, repeats // 5)):
        start = time.perf_counter()
        job()
        times.append(time.perf_counter() - start)
    out[name + "_ms"] = 1000 * float(np.median(times))
print(json.dumps(out))
"""


def measure(data: str, repeats: int) -> dict:
    """Every available way, each in a fresh process, in the order of :data:`WAYS`."""
    results = {}
    for label, (env, prefix, mode) in WAYS.items():
        if prefix and shutil.which(prefix[0]) is None:
            continue
        command = [*prefix, sys.executable, "-c", _CHILD, mode, data or "", str(repeats)]
        done = subprocess.run(
            command, env={**os.environ, **env}, capture_output=True, text=True, check=True
        )
        results[label] = json.loads(done.stdout.strip().splitlines()[-1])
        print(f"{label:40s} {results[label]}", flush=True)
    return results


def markdown(results: dict) -> str:
    first = next(iter(results.values()))
    rows = [
        "# One thread for Open3D, five ways",
        "",
        f"Normals + FPFH on {first['cloud']} ({first['points']} points) and nearest-point "
        "distances between two 400k-point clouds, each way in a fresh process "
        "(`python benchmarks/thread_budgets.py`); medians. `threads`: what "
        "`open3d.utility.get_max_threads()` reports.",
        "",
        "| way | threads | normals + FPFH ms | distances ms |",
        "|---|---|---|---|",
    ]
    for label, r in results.items():
        rows.append(f"| {label} | {r['threads']} | {r['fpfh_ms']:.1f} | {r['distances_ms']:.0f} |")
    return "\n".join(rows) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", default=None)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--output", default=str(RESULTS / "thread_budgets"))
    args = parser.parse_args()
    results = measure(args.data, args.repeats)
    from o3d_rpointhop.evaluation.provenance import descriptor_provenance

    record = {"results": results, "provenance": descriptor_provenance({}, threads="as listed")}
    Path(args.output + ".json").write_text(json.dumps(record, indent=2) + "\n")
    Path(args.output + ".md").write_text(markdown(results))
    print(f"written: {args.output}.json, {args.output}.md")


if __name__ == "__main__":
    main()
