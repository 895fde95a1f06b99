"""Multiway registration: poses of many unposed scans in one call, through a pose graph.

Every scan is downsampled to one common resolution and described once. Candidate pairs
(all pairs of a few scans; for many scans, each scan's nearest neighbours by a pooled
descriptor) are screened through :class:`~o3d_rpointhop.RegistrationPipeline` on a
context that holds the prepared clouds and descriptors, with ``register()``'s global
step (descriptor matches, RANSAC), centring, resolution rules and flags, and one
point-to-plane ICP pass at the common resolution, then measured there (fitness and
Open3D's information matrix at the settings' ``edge_distance``). Pairs that fit become
edges of an Open3D ``PoseGraph``: a maximum spanning tree of the best edges gives the
starting poses and is kept as certain, every other edge is a loop closure that Open3D's
Levenberg-Marquardt optimisation may prune (line process). The optimised poses are
refined once more (every kept edge re-registered by ``register()``'s ICP from them,
ending on the full scans, then optimised again). Scans that no kept edge joins to scan
0 are reported as unconnected and get no pose.
"""

from __future__ import annotations

import os
import time
import warnings
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any

import numpy as np
import open3d as o3d

from .._utils.geometry import point_spacing
from .._utils.parallel import parallel_map, single_threaded
from .._utils.params import HasMethods, Interval, StrOptions, validate_params
from .._utils.threads import repeatable_open3d
from .._utils.validation import as_points, as_viewpoints
from ..open3d_interop import to_point_cloud
from .context import RegistrationContext
from .defaults import DEFAULT_GLOBAL_POINTS, default_descriptor
from .pipeline import RegistrationPipeline
from .quality import RegistrationWarning
from .result import _matrix, read_json, write_json
from .settings import RegistrationSettings
from .steps import PointToPlaneICP, RANSACGlobal

__all__ = ["MultiwayResult", "common_voxel", "optimise_pose_graph", "register_multiway"]

reg = o3d.pipelines.registration

#: Smallest ICP fitness (at 1.5 resolutions) for a pair to become an edge; a pair whose
#: inliers spread like a chance alignment's (``RegistrationResult.converged``) never does.
MIN_EDGE_FITNESS = 0.3
#: Pairs registered per scan when there are too many scans for all pairs.
RETRIEVED_NEIGHBOURS = 6
#: Up to this many scans, every pair is a candidate.
ALL_PAIRS_UP_TO = 12


#: Colours of the scans in a merged cloud, in scan order (matplotlib's "tab10").
SCAN_COLOURS = np.array(
    [
        [0.12, 0.47, 0.71],
        [1.0, 0.5, 0.05],
        [0.17, 0.63, 0.17],
        [0.84, 0.15, 0.16],
        [0.58, 0.4, 0.74],
        [0.55, 0.34, 0.29],
        [0.89, 0.47, 0.76],
        [0.5, 0.5, 0.5],
        [0.74, 0.74, 0.13],
        [0.09, 0.75, 0.81],
    ]
)


@dataclass
class MultiwayResult:
    """The outcome of :func:`register_multiway`.

    Attributes
    ----------
    poses : list of (ndarray of shape (4, 4) or None)
        ``poses[k]`` maps scan ``k`` into scan 0's frame; ``None`` for an unconnected
        scan.
    pose_graph : open3d.pipelines.registration.PoseGraph
        The optimised graph (nodes: connected scans in order; edges: kept pairs).
    pairs : dict
        ``(i, j) -> (transformation, fitness)`` for every candidate pair registered
        (the transformation maps scan ``j`` into scan ``i``).
    edges : list of tuple
        The pairs kept after optimisation, ``(i, j)``.
    unconnected : list of int
        Scans no kept edge joins to scan 0 (left out, never placed silently).
    voxel_size : float
        The common resolution.
    seconds : float
    """

    poses: list
    pose_graph: Any
    pairs: dict = field(default_factory=dict)
    edges: list = field(default_factory=list)
    unconnected: list = field(default_factory=list)
    voxel_size: float = 0.0
    seconds: float = 0.0

    def merge(
        self,
        clouds: list[Any],
        *,
        voxel_size: float | str | None = "auto",
        colour: bool = True,
    ) -> o3d.geometry.PointCloud:
        """The placed scans in scan 0's frame as one cloud.

        Parameters
        ----------
        clouds : list of array-like (n_k, 3) or Open3D point clouds
            The scans given to :func:`register_multiway`, in the same order.
        voxel_size : float, "auto" or None, default="auto"
            Voxel the merged cloud is downsampled to; ``"auto"`` is half the common
            resolution, ``None`` keeps every point.
        colour : bool, default=True
            Paint each scan in its own colour (:data:`SCAN_COLOURS`, in scan order);
            ``False`` keeps the scans' own colours and normals (turned with them).

        Returns
        -------
        open3d.geometry.PointCloud
            Unconnected scans are left out.
        """
        if len(clouds) != len(self.poses):
            raise ValueError(f"{len(self.poses)} scans were registered, got {len(clouds)}")
        merged = o3d.geometry.PointCloud()
        for k, (scan, pose) in enumerate(zip(clouds, self.poses, strict=True)):
            if pose is None:
                continue
            part = o3d.geometry.PointCloud(to_point_cloud(scan, f"clouds[{k}]"))
            part.transform(pose)  # turns the normals too
            if colour:
                part.paint_uniform_color(SCAN_COLOURS[k % len(SCAN_COLOURS)])
            merged += part
        if voxel_size is None:
            return merged
        return merged.voxel_down_sample(
            self.voxel_size / 2 if isinstance(voxel_size, str) else float(voxel_size)
        )

    def mesh(
        self, clouds: list[Any], *, voxel_size: float | None = None, depth: int = 9
    ) -> o3d.geometry.TriangleMesh:
        """A surface through the merged scans: Open3D's screened Poisson reconstruction.

        Normals are estimated within 4 voxels of the merged cloud and oriented
        consistently over their tangent planes before meshing.

        Parameters
        ----------
        clouds : list
            As in :meth:`merge`.
        voxel_size : float, default=None
            Voxel the scans are merged at before meshing; ``None`` is half the common
            resolution.
        depth : int, default=9
            Octree depth of the Poisson solver (detail, and memory).

        Returns
        -------
        open3d.geometry.TriangleMesh
        """
        voxel = voxel_size or self.voxel_size / 2
        merged = self.merge(clouds, voxel_size=voxel, colour=False)
        merged.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * voxel, max_nn=30))
        merged.orient_normals_consistent_tangent_plane(16)
        mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(merged, depth=depth)
        return mesh

    def save(self, path: str | os.PathLike) -> None:
        """Write the poses, the candidate pairs, the edges and the optimised pose graph
        (nodes, edges with their information matrices) to a JSON file that
        :meth:`load` reads back. (``o3d-rpointhop reconstruct --pose-graph`` writes the
        graph alone in Open3D's format, for ``open3d.io.read_pose_graph``.)"""
        graph = self.pose_graph
        body = {
            "poses": self.poses,
            "pairs": [[i, j, t, f] for (i, j), (t, f) in sorted(self.pairs.items())],
            "edges": [list(e) for e in self.edges],
            "unconnected": list(self.unconnected),
            "voxel_size": self.voxel_size,
            "seconds": self.seconds,
            "pose_graph": {
                "nodes": [np.asarray(n.pose) for n in graph.nodes],
                "edges": [
                    {
                        "source": int(e.source_node_id),
                        "target": int(e.target_node_id),
                        "transformation": np.asarray(e.transformation),
                        "information": np.asarray(e.information),
                        "uncertain": bool(e.uncertain),
                        "confidence": float(e.confidence),
                    }
                    for e in graph.edges
                ],
            },
        }
        write_json(path, "MultiwayResult", body)

    @classmethod
    def load(cls, path: str | os.PathLike) -> MultiwayResult:
        """A result :meth:`save` wrote; ValueError for any other file."""
        body = read_json(path, "MultiwayResult")
        try:
            graph = reg.PoseGraph()
            for pose in body["pose_graph"]["nodes"]:
                graph.nodes.append(reg.PoseGraphNode(_matrix(pose, (4, 4), f"{path}")))
            for e in body["pose_graph"]["edges"]:
                edge = reg.PoseGraphEdge(
                    int(e["source"]),
                    int(e["target"]),
                    _matrix(e["transformation"], (4, 4), f"{path}"),
                    _matrix(e["information"], (6, 6), f"{path}"),
                    uncertain=bool(e["uncertain"]),
                    confidence=float(e["confidence"]),
                )
                graph.edges.append(edge)
            return cls(
                poses=[None if p is None else _matrix(p, (4, 4), f"{path}") for p in body["poses"]],
                pose_graph=graph,
                pairs={
                    (int(i), int(j)): (_matrix(t, (4, 4), f"{path}"), float(f))
                    for i, j, t, f in body["pairs"]
                },
                edges=[tuple(int(v) for v in e) for e in body["edges"]],
                unconnected=[int(k) for k in body["unconnected"]],
                voxel_size=float(body["voxel_size"]),
                seconds=float(body["seconds"]),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"{path}: a damaged saved result ({exc!r})") from None

    def as_dict(self, names: list[str] | None = None) -> dict:
        """JSON-ready poses, edges and flags, scans called by ``names`` (default: their
        indices)."""
        names = names or [str(k) for k in range(len(self.poses))]
        return {
            "scans": list(names),
            "poses": [None if p is None else p.tolist() for p in self.poses],
            "unconnected": [names[k] for k in self.unconnected],
            "edges": [[names[i], names[j]] for i, j in self.edges],
            "voxel_size": self.voxel_size,
            "seconds": self.seconds,
        }


def common_voxel(clouds: list[np.ndarray], n_global_points: int) -> float:
    """One resolution for every scan: the largest that any scan needs, its own spacing
    widened until it keeps about ``n_global_points`` points (surfaces: count ~ 1 /
    voxel^2), so that no scan is finer than it can be described."""
    return float(
        max(point_spacing(c) * max(1.0, np.sqrt(len(c) / n_global_points)) for c in clouds)
    )


def _prepare(points: np.ndarray, voxel: float, descriptor: Any, viewpoint=None):
    """A scan's global cloud (at the common resolution) and its descriptors (seen from
    ``viewpoint``, the scan's sensor position, when given)."""
    # About the scan's own centroid: the voxel grid and the descriptors lose nothing far
    # from the origin.
    origin = points.mean(axis=0)
    down = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points - origin))
    down = down.voxel_down_sample(voxel).translate(origin)
    kept = np.asarray(down.points)
    if viewpoint is None:
        features = descriptor.transform(kept)
    else:
        features = descriptor.transform(kept, viewpoints=viewpoint)
    return kept, np.asarray(features)


class _Described:
    """Stands for the descriptor in a pair's context, whose descriptors are precomputed
    (so the model is not shipped to every pair's task)."""

    def transform(self, X):  # pragma: no cover - the features are always given
        raise RuntimeError("the scans' descriptors were computed once, before the pairs")


def _pair_steps(settings: RegistrationSettings, screen: bool) -> list:
    """How a pair is registered. Screening a candidate pair: ``register()``'s RANSAC,
    then one point-to-plane ICP pass at the settings' widest ICP distance on the
    global clouds (the common resolution). Refining a kept edge from the optimised
    poses: ``register()``'s point-to-plane ICP, ending on the full scans."""
    if screen:
        coarse = PointToPlaneICP(settings.icp_distances[0], full_resolution=False)
        return [("global", RANSACGlobal()), ("refine", coarse)]
    return [("refine", PointToPlaneICP())]


def _pair_context(source, target, prepared_source, prepared_target, settings, seed):
    """A context for scan ``source`` onto scan ``target`` at the common resolution, with
    the scans' prepared global clouds (and descriptors, when given)."""
    features = None
    descriptor = None
    if prepared_source[1] is not None:
        descriptor = _Described()
        features = (prepared_source[1], prepared_target[1])
    return RegistrationContext(
        source,
        target,
        voxel_size=settings.voxel_size,
        seed=seed,
        descriptor=descriptor,
        check=False,
        settings=settings,
        global_clouds=(prepared_source[0], prepared_target[0]),
        features=features,
    )


def _register_pair(source, target, prepared_source, prepared_target, settings, seed, init=None):
    """Scan ``source`` onto scan ``target`` through :class:`RegistrationPipeline`:
    screened from scratch (``init=None``: matches, RANSAC, ICP at the common resolution)
    or refined by ICP from ``init``. Returns the transformation, its edge fitness (the
    share of source points within the settings' ``edge_distance``; 0 for a result that
    did not converge) and Open3D's information matrix at that distance (in the pair's
    centred frame), both on the clouds the pair was registered at: the global clouds
    when screening, the full scans when refining."""
    context = _pair_context(source, target, prepared_source, prepared_target, settings, seed)
    screen = init is None
    with warnings.catch_warnings():  # a pair that does not fit is simply no edge
        warnings.simplefilter("ignore", RegistrationWarning)
        pipeline = RegistrationPipeline(_pair_steps(settings, screen))
        result = pipeline.run(context, init, assess_ambiguity=False)
    local = context.to_local(result.transformation)
    edge = settings.edge_distance
    which = "global" if screen else "full"
    fitness = context.evaluate(local, edge, which).fitness if result.converged else 0.0
    with repeatable_open3d():
        information = reg.get_information_matrix_from_point_clouds(
            *context.clouds(which), edge, local
        )
    return result.transformation, float(fitness), information


def _candidates(features: list[np.ndarray], k: int) -> list[tuple[int, int]]:
    """All pairs of a few scans; for many, each scan's ``k`` nearest by its pooled
    (mean, unit-length) descriptor, plus its neighbours in the given order."""
    n = len(features)
    if n <= ALL_PAIRS_UP_TO:
        return [(i, j) for i in range(n) for j in range(i + 1, n)]
    pooled = np.stack([f.mean(axis=0) for f in features])
    pooled /= np.linalg.norm(pooled, axis=1, keepdims=True) + 1e-12
    distance = np.linalg.norm(pooled[:, None] - pooled[None], axis=2)
    np.fill_diagonal(distance, np.inf)
    pairs = {(i, i + 1) for i in range(n - 1)}
    for i in range(n):
        for j in np.argsort(distance[i], kind="stable")[:k]:
            pairs.add((min(i, int(j)), max(i, int(j))))
    return sorted(pairs)


def _spanning_tree(edges: dict, n: int) -> list[tuple[int, int]]:
    """Maximum spanning forest by fitness (Kruskal)."""
    parent = list(range(n))

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    tree = []
    for (i, j), _edge in sorted(edges.items(), key=lambda e: -e[1][1]):
        ri, rj = root(i), root(j)
        if ri != rj:
            parent[ri] = rj
            tree.append((i, j))
    return tree


def _poses_from_tree(tree, edges, n: int) -> list:
    """Poses (scan -> scan 0) along the tree; None where scan 0 cannot be reached."""
    poses: list = [None] * n
    poses[0] = np.eye(4)
    changed = True
    while changed:
        changed = False
        for i, j in tree:
            t_ij = edges[(i, j)][0]  # maps j into i
            if poses[i] is not None and poses[j] is None:
                poses[j] = poses[i] @ t_ij
                changed = True
            elif poses[j] is not None and poses[i] is None:
                poses[i] = poses[j] @ np.linalg.inv(t_ij)
                changed = True
    return poses


def optimise_pose_graph(graph, option) -> None:
    """Open3D's Levenberg-Marquardt global optimisation of ``graph`` in place, with
    ``option`` (a ``GlobalOptimizationOption``) and Open3D's default convergence
    criteria, its progress messages silenced."""
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(
            graph,
            reg.GlobalOptimizationLevenbergMarquardt(),
            reg.GlobalOptimizationConvergenceCriteria(),
            option,
        )


def _optimise(edges: dict, tree: list, poses: list, settings: RegistrationSettings):
    """Open3D's global optimisation over the connected scans; returns the graph, the
    optimised poses (None for unconnected scans) and the edges it kept."""
    nodes = [k for k, p in enumerate(poses) if p is not None]
    index = {k: m for m, k in enumerate(nodes)}
    graph = reg.PoseGraph()
    for k in nodes:
        graph.nodes.append(reg.PoseGraphNode(poses[k]))
    tree_set = set(tree)
    listed = []
    for (i, j), (t_ij, _, information) in edges.items():
        if i not in index or j not in index:
            continue
        # Open3D's edge maps its source node into its target node: j into i.
        graph.edges.append(
            reg.PoseGraphEdge(
                index[j], index[i], t_ij, information, uncertain=(i, j) not in tree_set
            )
        )
        listed.append((i, j))
    optimise_pose_graph(
        graph,
        reg.GlobalOptimizationOption(
            max_correspondence_distance=settings.edge_distance,
            edge_prune_threshold=0.25,
            preference_loop_closure=1.0,
            reference_node=0,
        ),
    )
    optimised: list = [None] * len(poses)
    # Relative to scan 0's optimised pose, so that scan 0 is exactly the identity.
    reference = np.linalg.inv(np.array(graph.nodes[index[0]].pose))
    for k in nodes:
        optimised[k] = reference @ np.array(graph.nodes[index[k]].pose)
    optimised[0] = np.eye(4)
    # Open3D removes the edges its line process pruned; what remains was kept.
    remaining = {(nodes[e.target_node_id], nodes[e.source_node_id]) for e in graph.edges}
    kept = [e for e in listed if e in remaining]
    return graph, optimised, kept


@validate_params(
    {
        "clouds": [list, tuple],
        "descriptor": [None, HasMethods(["transform"])],
        "n_global_points": [Interval(Integral, 3, None, closed="left")],
        "min_fitness": [Interval(Real, 0, 1, closed="right")],
        "n_jobs": [None, Integral],
        "progress": [None, "boolean"],
        "seed": [Interval(Integral, 0, None, closed="left")],
        "settings": [None, RegistrationSettings],
        "viewpoints": [None, StrOptions({"origin"}), "array-like"],
    },
    prefer_skip_nested_validation=False,  # the descriptor is the caller's, checked by itself
)
def register_multiway(
    clouds: list[Any],
    descriptor: Any = None,
    *,
    viewpoints: Any = None,
    n_global_points: int = DEFAULT_GLOBAL_POINTS,
    min_fitness: float = MIN_EDGE_FITNESS,
    n_jobs: int | None = None,
    progress: bool | None = None,
    seed: int = 0,
    settings: RegistrationSettings | None = None,
) -> MultiwayResult:
    """Poses of unposed scans of one object or scene, in scan 0's frame.

    Parameters
    ----------
    clouds : list of array-like (n_k, 3) or Open3D point clouds
        At least two scans; sizes and resolutions may differ.
    descriptor : transformer, default=None
        ``None`` is ``register()``'s default (the pretrained R-PointHop model on 128
        principal axes); an ``FPFHTransformer`` works the same way. Each scan is
        described once.
    viewpoints : None, "origin" or array-like of shape (n_scans, 3), default=None
        Where each scan's sensor stood, in the scan's own coordinates; ``"origin"``:
        every scan is in its sensor's frame. Normals and local frames then face the
        sensor (see :func:`~o3d_rpointhop.register`). ``None``: no sensor is known.
    n_global_points : int, default=2048
        The common resolution keeps about this many points of the largest scan.
    min_fitness : float, default=0.3
        A pair becomes an edge when its screening leaves at least this share of the
        source scan (at the common resolution) within the settings' ``edge_distance``
        (1.5 resolutions) of the target.
    n_jobs : int, default=None
        Parallel pair registrations, both the screening of candidate pairs and the
        final refinement of kept edges (joblib; a Dask cluster under
        ``joblib.parallel_config(backend="dask")``). The result does not depend on it.
    progress : bool, default=None
        A bar on stderr over the pairs (``None``: when stderr is a terminal).
    seed : int, default=0
    settings : RegistrationSettings, default=None
        The multiples of the common resolution (RANSAC, ICP, normals, edges); ``None``
        is ``RegistrationSettings()``.

    Returns
    -------
    MultiwayResult

    Raises
    ------
    ValueError
        For fewer than two clouds, or a cloud that is not a valid point cloud.
    """
    start = time.perf_counter()
    if len(clouds) < 2:
        raise ValueError(f"register_multiway needs at least two clouds, got {len(clouds)}")
    points = [as_points(c, f"clouds[{k}]") for k, c in enumerate(clouds)]
    views = as_viewpoints(viewpoints, len(points))
    worker = single_threaded(descriptor if descriptor is not None else default_descriptor())
    voxel = common_voxel(points, n_global_points)
    settings = (settings or RegistrationSettings()).at(voxel)
    prepared = parallel_map(
        _prepare,
        [(p, voxel, worker, view) for p, view in zip(points, views, strict=True)],
        n_jobs=n_jobs,
        progress=progress,
        desc="describe",
        unit="scan",
    )
    features = [f for _, f in prepared]
    candidates = _candidates(features, RETRIEVED_NEIGHBOURS)
    results = parallel_map(
        _register_pair,
        [(points[j], points[i], prepared[j], prepared[i], settings, seed) for i, j in candidates],
        n_jobs=n_jobs,
        progress=progress,
        desc="pairs",
        unit="pair",
    )
    pairs = {pair: (t, f) for pair, (t, f, _) in zip(candidates, results, strict=True)}
    edges = {
        pair: result
        for pair, result in zip(candidates, results, strict=True)
        if result[1] >= min_fitness
    }
    tree = _spanning_tree(edges, len(points))
    poses = _poses_from_tree(tree, edges, len(points))
    graph, poses, kept = _optimise(edges, tree, poses, settings)
    # Final refinement: every kept edge again by ICP from the optimised poses (each
    # keeps the fitness that made it an edge).
    results = parallel_map(
        _register_pair,
        [
            (
                points[j],
                points[i],
                (prepared[j][0], None),
                (prepared[i][0], None),
                settings,
                seed,
                np.linalg.inv(poses[i]) @ poses[j],
            )
            for i, j in kept
        ],
        n_jobs=n_jobs,
        progress=progress,
        desc="refine",
        unit="edge",
    )
    refined = {
        (i, j): (transformation, edges[(i, j)][1], information)
        for (i, j), (transformation, _, information) in zip(kept, results, strict=True)
    }
    if refined:
        tree = [e for e in tree if e in refined]
        graph, poses, kept = _optimise(refined, tree, poses, settings)
    unconnected = [k for k, p in enumerate(poses) if p is None]
    return MultiwayResult(
        poses=poses,
        pose_graph=graph,
        pairs=pairs,
        edges=kept,
        unconnected=unconnected,
        voxel_size=voxel,
        seconds=time.perf_counter() - start,
    )
