"""Open3D's global registration tutorial, step for step, with FPFH and with R-PointHop.

The tutorial's flow (``preprocess_point_cloud``, ``execute_global_registration``,
``refine_registration``): voxel-downsample, normals at 2 voxels, features (FPFH at 5
voxels, at most 100 neighbours), Open3D's RANSAC on mutual feature matches (1.5 voxels,
the edge-length and distance checkers, 100,000 iterations at 0.999 confidence), then
point-to-plane ICP at 0.4 voxels on the full clouds. The R-PointHop flow changes one
line: the features are ``to_open3d_feature(model.transform(pcd_down))`` with a shipped
model: ``rpointhop-K``, the paper's four-hop model on K principal axes
(``RPointHopTransformer.pretrained(n_components=K)``), or ``object``, the one-hop object
model's whole 24-D descriptor (``pretrained("object")``). Both flows are timed whole,
from the raw clouds to the refined transformation, interleaved pair by pair.

Pairs (seeded; the ground truth known):

* ``choose``: ModelNet40 *training* shapes (two samples of each surface, one turned
  over SO(3)), voxel 0.05 (the benchmarks' recipe voxel for unit objects): where the
  features are chosen, as the fastest flow that places as many runs as FPFH's on one
  thread (``recommended`` in the results);
* ``bunny-neighbours``: the Stanford Bunny's ring scans 45 degrees apart (bun045 to
  bun000, bun090 to bun045, bun315 to bun000, bun270 to bun315), and ``bunny``: every
  scan to bun000; ground truth from ``bun.conf``, each source moved by a random rigid
  motion; the voxel is the resolution ``register()`` picks for the pair (about 2000
  points per scan: 3.8 mm for bun045 and bun000).

Thread budgets: ``one`` (Open3D and the descriptor on one thread each) and ``all``
(every core each; Open3D's RANSAC then draws in an order set by its threads, so a pair
may land differently from run to run).

Usage: python benchmarks/open3d_tutorial.py [--data PATH]
       [--features object rpointhop-16 rpointhop-32] [--output benchmarks/results]
Writes open3d_tutorial.json and open3d_tutorial.md.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

from o3d_rpointhop import RPointHopTransformer, to_open3d_feature
from o3d_rpointhop.evaluation._common import machine_facts
from o3d_rpointhop.transforms import rotation_error_deg, translation_error

reg = o3d.pipelines.registration
RESULTS = Path(__file__).resolve().parent / "results"


def preprocess_point_cloud(pcd, voxel_size, model=None):
    """The tutorial's preprocessing; ``model``: R-PointHop features instead of FPFH."""
    pcd_down = pcd.voxel_down_sample(voxel_size)
    radius_normal = voxel_size * 2
    pcd_down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius_normal, max_nn=30))
    if model is not None:
        return pcd_down, to_open3d_feature(model.transform(pcd_down))
    radius_feature = voxel_size * 5
    pcd_fpfh = reg.compute_fpfh_feature(
        pcd_down, o3d.geometry.KDTreeSearchParamHybrid(radius=radius_feature, max_nn=100)
    )
    return pcd_down, pcd_fpfh


def execute_global_registration(source_down, target_down, source_fpfh, target_fpfh, voxel):
    distance_threshold = voxel * 1.5
    return reg.registration_ransac_based_on_feature_matching(
        source_down,
        target_down,
        source_fpfh,
        target_fpfh,
        True,
        distance_threshold,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [
            reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
            reg.CorrespondenceCheckerBasedOnDistance(distance_threshold),
        ],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )


def refine_registration(source, target, voxel, result_ransac):
    distance_threshold = voxel * 0.4
    return reg.registration_icp(
        source,
        target,
        distance_threshold,
        result_ransac.transformation,
        reg.TransformationEstimationPointToPlane(),
    )


def flow(source_points, target_points, voxel, model=None, seed=0):
    """The whole tutorial flow on two raw clouds; returns the refined transformation."""
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source_points))
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target_points))
    source_down, source_features = preprocess_point_cloud(source, voxel, model)
    target_down, target_features = preprocess_point_cloud(target, voxel, model)
    o3d.utility.random.seed(seed)
    result = execute_global_registration(
        source_down, target_down, source_features, target_features, voxel
    )
    for cloud in (source, target):
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=voxel * 2, max_nn=30))
    return np.asarray(refine_registration(source, target, voxel, result).transformation)


def _moved(points, seed, shift):
    rotation = Rotation.random(random_state=seed).as_matrix()
    translation = np.random.default_rng(seed).uniform(-shift, shift, 3)
    truth = np.eye(4)
    truth[:3, :3], truth[:3, 3] = rotation.T, -rotation.T @ translation
    return points @ rotation.T + translation, truth  # truth maps the moved source back


def choose_pairs(data, n_pairs=20, seed=11):
    """Resampled pairs of ModelNet40 training shapes (unit sphere), voxel 0.05."""
    from o3d_rpointhop.datasets import load_modelnet40

    train = load_modelnet40("train", data)
    pairs = []
    for i, shape in enumerate(train.points[:n_pairs]):
        source, truth = _moved(shape[1024:2048], seed + i, 0.5)
        pairs.append((f"train{i}", source, shape[:1024], truth, 0.05))
    return pairs, (5.0, 0.05)


#: The bunny's ring scans 45 degrees apart, source first.
NEIGHBOURS = (
    ("bun045", "bun000"),
    ("bun090", "bun045"),
    ("bun315", "bun000"),
    ("bun270", "bun315"),
)


def _scan_pairs(data, names, seed):
    from o3d_rpointhop.datasets.bunny import BUNNY_SCANS, load_bunny
    from o3d_rpointhop.registration.context import RegistrationContext

    scans = load_bunny(BUNNY_SCANS, data)
    pairs = []
    for i, (a, b) in enumerate(names):
        source, back = _moved(scans[a].points, seed + i, 0.1)
        voxel = RegistrationContext(source, scans[b].points).voxel_size
        truth = scans[a].relative_pose(scans[b]) @ back
        pairs.append((f"{a} to {b}", source, scans[b].points, truth, voxel))
    return pairs, (2.0, 0.002)


def neighbour_pairs(data, seed=21):
    return _scan_pairs(data, NEIGHBOURS, seed)


def bunny_pairs(data, seed=31):
    from o3d_rpointhop.datasets.bunny import BUNNY_SCANS

    return _scan_pairs(data, [(n, "bun000") for n in BUNNY_SCANS if n != "bun000"], seed)


def feature_model(name: str) -> RPointHopTransformer:
    """The model a feature name stands for: ``object`` or ``rpointhop-K``."""
    if name == "object":
        return RPointHopTransformer.pretrained("object")
    prefix, _, axes = name.partition("-")
    if prefix != "rpointhop" or not axes.isdigit():
        raise ValueError(f"features are 'object' or 'rpointhop-K', got {name!r}")
    return RPointHopTransformer.pretrained(n_components=int(axes))


def run(pairs, tol, features, budget, repeats=3):
    """Every flow on every pair, ``repeats`` times interleaved; medians per pair."""
    threads = 1 if budget == "one" else o3d.utility.get_max_threads()
    previous = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(threads)
    models = {
        name: feature_model(name).set_params(n_jobs=1 if budget == "one" else None)
        for name in features
    }
    flows = {"fpfh": None, **models}
    rows = {name: [] for name in flows}
    try:
        for pair_name, source, target, truth, voxel in pairs:
            for name, model in flows.items():
                flow(source, target, voxel, model)  # warm
                seconds, results = [], []
                for r in range(repeats):
                    start = time.perf_counter()
                    transformation = flow(source, target, voxel, model, seed=r)
                    seconds.append(time.perf_counter() - start)
                    results.append(transformation)
                errors = [
                    (rotation_error_deg(t[:3, :3], truth[:3, :3]), translation_error(t, truth))
                    for t in results
                ]
                placed = [r <= tol[0] and e <= tol[1] for r, e in errors]
                rows[name].append(
                    {
                        "pair": pair_name,
                        "seconds": float(np.median(seconds)),
                        "placed": int(sum(placed)),
                        "runs": repeats,
                    }
                )
    finally:
        o3d.utility.set_max_threads(previous)
    return rows


def summary(rows):
    fpfh = np.median([r["seconds"] for r in rows["fpfh"]])
    out = {}
    for name, recs in rows.items():
        seconds = float(np.median([r["seconds"] for r in recs]))
        out[name] = {
            "median_seconds": seconds,
            "ratio_to_fpfh": seconds / fpfh,
            "placed": int(sum(r["placed"] for r in recs)),
            "runs": int(sum(r["runs"] for r in recs)),
        }
    return out


def recommend(summary) -> str:
    """The features whose flow is fastest among those that place as many runs as
    FPFH's (the fastest of those that place the most, if none does)."""
    fpfh = summary["fpfh"]["placed"]
    ours = {n: s for n, s in summary.items() if n != "fpfh"}
    good = [n for n, s in ours.items() if s["placed"] >= fpfh]
    if not good:
        best = max(s["placed"] for s in ours.values())
        good = [n for n, s in ours.items() if s["placed"] == best]
    return min(good, key=lambda n: ours[n]["median_seconds"])


def markdown(results):
    lines = ["# Open3D's global registration tutorial: FPFH and R-PointHop features", ""]
    lines.append(f"Machine: {results['machine']['machine']}.")
    if "recommended" in results:
        lines.append(f"Features chosen on the training pairs: {results['recommended']}.")
    lines.append("")
    lines += [
        "| pairs | thread budget | features | flow s per pair (median) | ratio to FPFH | "
        "placed runs |",
        "|---|---|---|---|---|---|",
    ]
    for key, entry in results["runs"].items():
        pairs, budget = key.split("/")
        for name, s in entry["summary"].items():
            lines.append(
                f"| {pairs} | {'one thread' if budget == 'one' else 'every core'} each | "
                f"{name} | {s['median_seconds']:.3f} | {s['ratio_to_fpfh']:.2f}x | "
                f"{s['placed']} / {s['runs']} |"
            )
    return "\n".join(lines) + "\n"


def provenance(args) -> dict:
    """What made the run: each flow's features (the R-PointHop models by content hash)
    and the thread budgets it ran on."""
    from o3d_rpointhop.evaluation.provenance import descriptor_provenance

    features = {
        "fpfh": {
            "class": "open3d.pipelines.registration.compute_fpfh_feature",
            "params": "the tutorial's: normals within 2 voxels (30 neighbours), "
            "features within 5 voxels (100 neighbours)",
        }
    }
    features.update({name: feature_model(name) for name in args.features})
    return descriptor_provenance(features, threads=" and ".join(args.budgets) + " (per run)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None)
    parser.add_argument("--features", nargs="+", default=["object", "rpointhop-16", "rpointhop-32"])
    parser.add_argument("--sets", nargs="+", default=["choose", "bunny-neighbours", "bunny"])
    parser.add_argument("--budgets", nargs="+", default=["one", "all"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    makers = {"choose": choose_pairs, "bunny-neighbours": neighbour_pairs, "bunny": bunny_pairs}
    results = {"machine": machine_facts(), "runs": {}, "provenance": provenance(args)}
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        for name in args.sets:
            pairs, tol = makers[name](args.data)
            for budget in args.budgets:
                rows = run(pairs, tol, args.features, budget, args.repeats)
                key = f"{name}/{budget}"
                results["runs"][key] = {
                    "voxels": [p[4] for p in pairs],
                    "tolerance": tol,
                    "summary": summary(rows),
                    "records": rows,
                }
                entry = {"machine": results["machine"], "runs": {key: results["runs"][key]}}
                print(markdown(entry), flush=True)
    chosen = results["runs"].get("choose/one")
    if chosen is not None:
        results["recommended"] = recommend(chosen["summary"])
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "open3d_tutorial.json").write_text(json.dumps(results, indent=1))
    (args.output / "open3d_tutorial.md").write_text(markdown(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
