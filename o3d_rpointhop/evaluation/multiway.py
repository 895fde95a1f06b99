"""Multiway benchmark: rebuild the Stanford bunny and dragon from unposed scans.

Every scan but the first is moved by a random rigid motion (seeded: rotation uniform
over SO(3), translation up to 0.2 m); :func:`~o3d_rpointhop.register_multiway` then
recovers the poses with R-PointHop and with FPFH through the same pipeline, and Open3D's
multiway tutorial recipe (FPFH + RANSAC + ICP for every pair, its odometry-and-loop-
closure pose graph) runs as the peer at the same resolution. Each scan's rotation error
and mean point error are measured against the official ``.conf`` poses; success is
every scan within 2 deg and 2 mm.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d

from ..descriptors import FPFHTransformer
from ..registration.defaults import DEFAULT_GLOBAL_POINTS
from ..registration.multiway import register_multiway
from ..registration.pose_graph import optimise_pose_graph
from ..registration.result import MultiwayResult
from ..registration.settings import common_voxel
from ..transforms import apply_transform, random_rigid_motion, rotation_error_deg
from .peers import feature_ransac, fpfh_recipe_cloud
from .provenance import multiway_provenance
from .records import ScanRecord
from .registry import entries

__all__ = [
    "OBJECTS",
    "MultiwayRun",
    "open3d_multiway_recipe",
    "run_multiway",
    "plot_reconstruction",
]

OBJECTS = ("bunny", "dragon")
#: The methods of the benchmark, by name (their entries: :mod:`.registry`).
DESCRIPTORS = {name: e.description for name, e in entries("multiway").items()}
TOLERANCE = (2.0, 0.002)  # degrees, metres


def _scans(name: str, data):
    from ..datasets import BUNNY_SCANS, load_bunny, load_dragon

    return load_bunny(BUNNY_SCANS, data) if name == "bunny" else load_dragon(data)


def open3d_multiway_recipe(clouds: list[np.ndarray], voxel: float, seed: int = 0):
    """Open3D's multiway registration tutorial, with a global step per pair since the
    scans start from unknown poses: every scan voxel-downsampled with normals and FPFH
    (the global registration tutorial's radii: 2 and 5 voxels), every pair registered by
    FPFH + RANSAC (mutual matches, 1.5 voxels) then point-to-plane ICP at 15 and 1.5
    voxels, consecutive scans as odometry edges and all other pairs as uncertain loop
    closures, Levenberg-Marquardt with an edge prune threshold of 0.25.

    Returns
    -------
    MultiwayResult
        Poses mapping each scan into the first scan's frame (every scan gets one: the
        recipe does not detect unconnected scans); ``edges``: the pose graph's edges
        left after pruning.
    """
    reg = o3d.pipelines.registration
    start = time.perf_counter()
    prepared = [fpfh_recipe_cloud(c, voxel) for c in clouds]
    graph = reg.PoseGraph()
    odometry = np.eye(4)
    graph.nodes.append(reg.PoseGraphNode(odometry))
    pairs = {}
    coarse, fine = 15 * voxel, 1.5 * voxel
    for i in range(len(clouds)):
        for j in range(i + 1, len(clouds)):
            (src, f_src), (tgt, f_tgt) = prepared[i], prepared[j]
            # Open3D warns when the mutual filter leaves few matches (it then uses all).
            with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
                estimate = feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter=True)
            plane = reg.TransformationEstimationPointToPlane()
            step = reg.registration_icp(src, tgt, coarse, estimate, plane)
            step = reg.registration_icp(src, tgt, fine, step.transformation, plane)
            moved = np.array(step.transformation)  # maps scan i into scan j
            information = reg.get_information_matrix_from_point_clouds(src, tgt, fine, moved)
            pairs[(i, j)] = (np.linalg.inv(moved), float(step.fitness))  # j into i
            if j == i + 1:
                odometry = moved @ odometry
                graph.nodes.append(reg.PoseGraphNode(np.linalg.inv(odometry)))
            graph.edges.append(reg.PoseGraphEdge(i, j, moved, information, uncertain=j != i + 1))
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=fine, edge_prune_threshold=0.25, reference_node=0
    )
    optimise_pose_graph(graph, option)  # the tutorial's options, its optimiser
    return MultiwayResult(
        poses=[np.array(node.pose) for node in graph.nodes],
        pose_graph=graph,
        pairs=pairs,
        edges=sorted((e.source_node_id, e.target_node_id) for e in graph.edges),
        unconnected=[],
        voxel_size=voxel,
        seconds=time.perf_counter() - start,
    )


@dataclass
class MultiwayRun:
    """What :func:`run_multiway` measured.

    Attributes
    ----------
    results : dict
        JSON-ready: settings, and per object its scans and, per descriptor, each scan's
        errors, the edges kept, the time and the poses.
    moved : dict
        Per object, the scans as they were registered (moved from their official
        poses), for pictures; not part of the results.
    """

    results: dict
    moved: dict = field(default_factory=dict)


def run_multiway(objects=OBJECTS, descriptors=tuple(DESCRIPTORS), *, data=None, seed=0, n_jobs=-1):
    """Every object with every descriptor; returns a :class:`MultiwayRun`.

    ``n_jobs`` is :func:`register_multiway`'s (parallel pairs; default all cores, as
    Open3D's recipe runs its RANSAC and ICP on all cores); the poses do not depend on it.
    """
    out = {
        "dataset": "multiway",
        "settings": {"seed": seed, "tolerance": TOLERANCE, "n_jobs": n_jobs},
        "objects": {},
        "provenance": multiway_provenance(descriptors),
    }
    moved_scans = {}
    for name in objects:
        scans = _scans(name, data)
        names = list(scans)
        rng = np.random.default_rng(seed)
        motions = [np.eye(4)]
        for _ in names[1:]:
            motions.append(random_rigid_motion(rng, 0.2))
        moved = [apply_transform(scans[n].points, m) for n, m in zip(names, motions, strict=True)]
        reference = np.linalg.inv(scans[names[0]].pose)
        truth = [
            reference @ scans[n].pose @ np.linalg.inv(m)
            for n, m in zip(names, motions, strict=True)
        ]
        entry = {"scans": names, "points": [len(m) for m in moved], "methods": {}}
        for method in descriptors:
            if method == "open3d-recipe":
                voxel = common_voxel(moved, DEFAULT_GLOBAL_POINTS)  # register_multiway's
                result = open3d_multiway_recipe(moved, voxel, seed)
            else:
                descriptor = FPFHTransformer() if method == "fpfh" else None
                result = register_multiway(moved, descriptor, random_state=seed, n_jobs=n_jobs)
            rows = []
            # The truth in the frame the result's poses are in (scan 0's unless unplaced).
            into = np.linalg.inv(truth[getattr(result, "frame", 0)])
            for k, n in enumerate(names):
                pose = result.poses[k]
                if pose is None:
                    rows.append(ScanRecord(n, placed=False))
                    continue
                want = into @ truth[k]
                gap = apply_transform(moved[k], pose) - apply_transform(moved[k], want)
                rows.append(
                    ScanRecord(
                        n,
                        placed=True,
                        rotation_error_deg=rotation_error_deg(pose, want),
                        mean_point_error=float(np.linalg.norm(gap, axis=1).mean()),
                    )
                )
            ok = [r.within(TOLERANCE) for r in rows]
            entry["methods"][method] = {
                "description": DESCRIPTORS[method],
                "scans": [r.as_dict() for r in rows],
                "all_within_tolerance": bool(all(ok)),
                "within_tolerance": int(sum(ok)),
                "edges_kept": len(result.edges),
                "pairs_tried": len(result.pairs),
                "seconds": result.seconds,
                "poses": [None if p is None else p.tolist() for p in result.poses],
            }
        moved_scans[name] = moved
        out["objects"][name] = entry
    return MultiwayRun(results=out, moved=moved_scans)


def plot_reconstruction(run: MultiwayRun, name: str, method: str, path: Path, title: str) -> None:
    """Object ``name`` rebuilt by ``method``: the merged scans coloured by scan, seen
    along their thinnest axis."""
    from ..plotting import require_matplotlib

    figure_class = require_matplotlib()
    poses = run.results["objects"][name]["methods"][method]["poses"]
    parts = [
        apply_transform(m[:: max(1, len(m) // 3000)], np.array(p))
        for m, p in zip(run.moved[name], poses, strict=True)
        if p is not None
    ]
    every = np.concatenate(parts)
    centre = every.mean(axis=0)
    _, _, axes = np.linalg.svd(every - centre, full_matrices=False)
    fig = figure_class(figsize=(5.5, 5.5))
    ax = fig.add_subplot(1, 1, 1)
    for k, part in enumerate(parts):
        view = (part - centre) @ axes.T
        ax.scatter(view[:, 0], view[:, 1], s=0.2, alpha=0.5, color=f"C{k % 10}")
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def timings_markdown(results: dict) -> str:
    """Seconds per object and descriptor (kept apart from the deterministic results)."""
    lines = ["# Benchmark timings: multiway registration", "", "| object | method | s |"]
    lines.append("|---|---|---|")
    for name, entry in results["objects"].items():
        for method, row in entry["methods"].items():
            lines.append(f"| {name} | {method} | {row['seconds']:.1f} |")
    return "\n".join(lines) + "\n"


def markdown(results: dict) -> str:
    """The per-scan errors (and the times, when ``results`` still holds them)."""
    lines = ["# Benchmark: multiway registration", ""]
    for name, entry in results["objects"].items():
        methods = list(entry["methods"])
        lines += [f"## {name} ({len(entry['scans'])} scans)", ""]
        lines.append(
            "| scan | "
            + " | ".join(f"{m}: rot. err. deg / mean point err. mm" for m in methods)
            + " |"
        )
        lines.append("|---" * (len(methods) + 1) + "|")
        for k, scan in enumerate(entry["scans"]):
            cells = []
            for m in methods:
                row = entry["methods"][m]["scans"][k]
                cells.append(
                    f"{row['rotation_error_deg']:.3f} / {1000 * row['mean_point_error']:.3f}"
                    if row["placed"]
                    else "unconnected"
                )
            lines.append(f"| {scan} | " + " | ".join(cells) + " |")
        summary = [
            f"{m}: {entry['methods'][m]['within_tolerance']}/{len(entry['scans'])} scans within "
            f"2 deg and 2 mm, {entry['methods'][m]['edges_kept']} of "
            f"{entry['methods'][m]['pairs_tried']} pairs kept as edges"
            + (
                f", {entry['methods'][m]['seconds']:.0f} s"
                if "seconds" in entry["methods"][m]
                else ""
            )
            for m in methods
        ]
        lines += ["", "; ".join(summary) + ".", ""]
    return "\n".join(lines)
