"""Multiway registration: poses of many unposed scans in one call, through a pose graph.

Every scan is prepared once (:mod:`.prepared`): downsampled to one common resolution,
described, and given normals. Candidate pairs (all pairs of a few scans; for many
scans, each scan's nearest neighbours by a pooled descriptor) are screened through
:class:`~o3d_rpointhop.RegistrationPipeline` on a context whose only clouds are the
prepared ones, with ``register()``'s global step (descriptor matches, then RANSAC, or
the step the descriptor states), centring, resolution rules and flags, and one
point-to-plane ICP pass at the common resolution, then measured there (fitness and
Open3D's information matrix at the settings' ``edge_distance``). Pairs that fit become
edges of an Open3D ``PoseGraph``: a maximum spanning tree of the best edges gives the
starting poses and is kept as certain, every other edge is a loop closure that Open3D's
Levenberg-Marquardt optimisation may prune (line process; :mod:`.pose_graph`). The
optimised poses are refined once more (every kept edge re-registered by
``register()``'s ICP from them, ending on the full scans, then optimised again). The
scans are worked on in a canonical order by content, so their given order changes
nothing; the graph is rooted in the largest part its edges join, and scans outside it
are reported as unconnected and get no pose there (each smaller part is reconstructed
on its own, ``MultiwayResult.part_poses``). A candidate pair that fails its screening
one way is screened the other way too.
"""

from __future__ import annotations

import copy
import hashlib
import logging
import time
import warnings
from dataclasses import replace
from numbers import Integral, Real
from typing import Any

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree
from sklearn.base import clone

from .._utils.geometry import vectors
from .._utils.parallel import parallel_map, worker_copy
from .._utils.params import HasMethods, Interval, StrOptions, validate_params
from .._utils.threads import core_budget, repeatable_open3d
from .._utils.validation import as_points, as_viewpoints, renamed_seed
from ..descriptors import PRETRAINED_MODELS
from ..transforms import from_centred
from .checks import RegistrationWarning
from .context import RegistrationContext
from .correspondences import shared_matches
from .defaults import default_descriptor, resolve_global_points
from .free_space import free_space_violation
from .model_choice import ModelChoice, resolve_model
from .pipeline import RegistrationPipeline, build_chain
from .pose_graph import largest_part, optimise, poses_from_tree, spanning_tree
from .prepared import PreparedCloud, estimate_normals, prepare_cloud
from .result import MultiwayResult
from .settings import RegistrationSettings, common_voxel
from .steps import PointToPlaneICP

__all__ = ["register_multiway"]

log = logging.getLogger(__name__)

reg = o3d.pipelines.registration

#: Smallest ICP fitness (at 1.5 resolutions) for a pair to become an edge; a pair whose
#: inliers spread like a chance alignment's (``RegistrationResult.converged``) never does.
MIN_EDGE_FITNESS = 0.3
#: The largest share of either scan a pair's pose may put in space the other scan's
#: sensor saw empty, for the pair to become an edge (when the sensors are known).
MAX_FREE_SPACE_VIOLATION = 0.1
#: Pairs registered per scan when there are too many scans for all pairs.
RETRIEVED_NEIGHBOURS = 6
#: Up to this many scans, every pair is a candidate.
ALL_PAIRS_UP_TO = 12
#: A screening whose matcher keeps at most ``max_matches`` matches found both ways
#: searches from this share of that count in each direction; None: from every point
#: (what a share does to the rooms: docs/multiway.md, "Searching from half the cap").
SCREENING_QUERIES = None
#: The leading principal axes the model ``descriptor="auto"`` chooses describes the scans
#: on, by model (a model not named: its own axes); e.g. ``{"scene": 32}``. Empty: every
#: model on its own axes (what such a width and :data:`SCREENING_HYPOTHESES` do to the
#: rooms: docs/multiway.md, "A lighter screening").
SCREENING_AXES: dict[str, int] = {}
#: Hypotheses a screening's consensus verifies when every scan's sensor is known and its
#: ``n_hypotheses`` is ``"auto"`` (a pair's own default is
#: :data:`~o3d_rpointhop.registration.steps.consensus.SENSOR_HYPOTHESES`, 16); None: the
#: step's own.
SCREENING_HYPOTHESES: int | None = None


def _pair_steps(settings: RegistrationSettings, screen: bool, global_method: Any = "ransac"):
    """How a pair is registered. Screening a candidate pair: the global step
    (``global_method``: a key of ``GLOBAL_METHODS`` or a step, copied unfitted; by
    default ``register()``'s for the descriptor), then one point-to-plane ICP pass at
    the settings' widest ICP distance on the global clouds (the common resolution).
    Refining a kept edge from the optimised poses: ``register()``'s point-to-plane ICP,
    ending on the full scans."""
    if screen:
        coarse = PointToPlaneICP(settings.icp_distances[0], full_resolution=False)
        step = global_method if isinstance(global_method, str) else clone(global_method)
        return build_chain(step, [coarse])
    return build_chain(None, [PointToPlaneICP()])


def chosen_model(descriptor: Any, choice: ModelChoice) -> tuple[Any, ModelChoice]:
    """The model ``descriptor="auto"`` chose (``descriptor``, as ``choice`` says), on the
    axes :data:`SCREENING_AXES` gives it for rebuilding scans: a copy on those axes and
    the choice saying so, or both as given.

    Parameters
    ----------
    descriptor : RPointHopTransformer
        The shipped model ``choice`` names.
    choice : ModelChoice

    Returns
    -------
    descriptor, choice
    """
    axes = SCREENING_AXES.get(choice.model)
    if axes is None or getattr(descriptor, "n_components", None) == axes:
        return descriptor, choice
    # A shallow copy: the fitted arrays are shared, only the projection's width differs.
    return copy.copy(descriptor).set_params(n_components=axes), replace(choice, axes=axes)


def _screening_step(step, sensors: bool = False):
    """The screening's global step: with :data:`SCREENING_QUERIES` set, one whose
    default matcher keeps at most ``max_matches`` matches found both ways (the
    consensus's 4000) searches, in each direction, from that share of the count spread
    over the scan (a scan at the common resolution holds several times the points a
    pair's global cloud does, and the matches beyond the cap are thrown away); with
    every scan's sensor known (``sensors``), a consensus left to choose its hypotheses
    verifies :data:`SCREENING_HYPOTHESES`. A step with its own matcher and hypotheses,
    another kind, or no setting: the step given."""
    params = {}
    if (
        sensors
        and SCREENING_HYPOTHESES is not None
        and getattr(step, "n_hypotheses", None) == "auto"
    ):
        params["n_hypotheses"] = SCREENING_HYPOTHESES
    default = getattr(step, "default_matcher", None)
    if (
        SCREENING_QUERIES is not None
        and default is not None
        and getattr(step, "matcher", 0) is None
    ):
        matcher = default()
        if matcher.both_directions and matcher.max_matches is not None:
            queries = max(3, int(matcher.max_matches * SCREENING_QUERIES))
            params["matcher"] = matcher.set_params(max_queries=queries)
    return clone(step).set_params(**params) if params else step


def _pair_context(source, target, prepared_source, prepared_target, settings, seed, views=None):
    """A context for scan ``source`` onto scan ``target`` at the common resolution, with
    the scans' prepared global clouds (and descriptors, when they carry them) and, when
    both are known, their sensor positions ``views`` (source's, target's; the global
    step checks its hypotheses against what the sensors saw)."""
    known = views is not None and all(v is not None for v in views)
    return RegistrationContext(
        source,
        target,
        voxel_size=settings.voxel_size,
        random_state=seed,
        check=False,
        settings=settings,
        prepared=(prepared_source, prepared_target),
        viewpoints=tuple(views) if known else None,
    )


def _register_pair(
    source,
    target,
    prepared_source,
    prepared_target,
    settings,
    seed,
    init=None,
    normals=None,
    global_method="ransac",
    min_fitness=None,
    views=None,
):
    """Scan ``source`` onto scan ``target``: screened from scratch (``init=None``) or
    refined from ``init``.

    Screening runs :class:`RegistrationPipeline` (matches, RANSAC, one ICP pass) on the
    prepared clouds at the common resolution, which are then the pair's only clouds
    (its flags are measured there too; ``source`` and ``target`` are not needed), and
    returns the transformation, its edge fitness (the share of source points within
    the settings' ``edge_distance``; 0 for a result that did not converge) and Open3D's
    information matrix at that distance (in the pair's centred frame; None for a pair
    whose edge fitness falls below ``min_fitness``, which no edge needs). Refining runs
    ``register()``'s point-to-plane ICP from ``init``, ending on the full scans, and
    returns the transformation and the information matrix there (fitness None: a kept
    edge keeps the fitness that made it one, so neither it nor the flags are measured
    again). ``normals``: the full target scan's normals (:func:`_full_normals`);
    ``global_method``: the screening's global step (a key of ``GLOBAL_METHODS`` or a
    step, copied). With ``min_fitness``, a screened pair whose edge fitness falls below
    it is screened the other way too (target onto source), and that pose, inverted, is
    kept when it brings more of the source within the edge distance: a pair is not
    lost to the direction its canonical order gave it. ``views``: the two scans' sensor
    positions (source's, target's), given to the screening's context."""
    edge = settings.edge_distance
    if init is None:
        source, target = prepared_source.points, prepared_target.points
    elif normals is not None:
        target = o3d.geometry.PointCloud(vectors(target))
        target.normals = vectors(normals)
    screening = views if init is None else None
    context = _pair_context(
        source, target, prepared_source, prepared_target, settings, seed, screening
    )
    if init is None:
        # Screened the other way round too, the pair's descriptors are matched once.
        with shared_matches():
            transformation, fitness = _screened(context, settings, global_method)
            if min_fitness is not None and fitness < min_fitness:
                back_views = None if views is None else views[::-1]
                back = _pair_context(
                    target, source, prepared_target, prepared_source, settings, seed, back_views
                )
                turned, back_fitness = _screened(back, settings, global_method)
                if back_fitness > 0.0:
                    candidate = np.linalg.inv(turned)
                    forward = context.evaluate(context.to_local(candidate), edge).fitness
                    if forward > fitness:
                        transformation, fitness = candidate, forward
        local = context.to_local(transformation)
    else:
        ((_, step),) = _pair_steps(settings, screen=False)
        local = step.run(context, context.to_local(np.asarray(init, dtype=np.float64)))
        local = local.transformation
        transformation, fitness = context.to_world(local), None
    if fitness is not None and min_fitness is not None and fitness < min_fitness:
        return transformation, fitness, None  # no edge: its information is never read
    with repeatable_open3d():
        information = reg.get_information_matrix_from_point_clouds(*context.clouds(), edge, local)
    # In the coordinates the scans were given in, as the pose graph's edges are.
    return transformation, fitness, information_about(np.asarray(information), context.origin)


def _screened(context, settings, global_method) -> tuple[np.ndarray, float]:
    """A candidate pair screened on its prepared clouds: the transformation (in the
    caller's coordinates) and its edge fitness (0 unless the result converged)."""
    with warnings.catch_warnings():  # a pair that does not fit is simply no edge
        warnings.simplefilter("ignore", RegistrationWarning)
        pipeline = RegistrationPipeline(_pair_steps(settings, True, global_method))
        result = pipeline.run(context, None, assess_ambiguity=False)
    local = context.to_local(result.transformation)
    edge = settings.edge_distance
    fitness = context.evaluate(local, edge).fitness if result.converged else 0.0
    return result.transformation, fitness


def information_about(information: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """An Open3D information matrix measured on clouds centred on ``origin``, expressed
    for the same clouds in the coordinates they were centred from.

    Open3D linearises a motion as ``p -> p + w x p + t`` (``w`` first, then ``t``); with
    ``p = q + origin`` the same motion of the centred points ``q`` has ``t_q = t - origin
    x w``, so the information transforms by that linear map. Without this, a pose graph
    whose poses are in one frame and whose information matrices are in each pair's
    centred frame weighs rotations by the wrong lever arm, badly so far from the origin.
    """
    change = np.eye(6)
    x, y, z = np.asarray(origin, dtype=np.float64)
    change[3:, :3] = -np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return change.T @ information @ change


def _graph_about(graph, centres: list[np.ndarray], scans: list[int], canon: list[int], poses):
    """The optimised pose graph of scans in their canonical order, each centred on its
    own centroid (``centres``), as the user gave them: nodes in the given order
    (``canon``: the given index of each canonical scan) with the result's ``poses`` (by
    given index), edges in the scans' own coordinates. Node ``m`` of ``graph`` is scan
    ``scans[m]``; an edge's information is about its target's points, as Open3D
    measures it."""
    given = sorted(scans, key=lambda c: canon[c])
    node_of = {c: m for m, c in enumerate(given)}
    out = reg.PoseGraph()
    for c in given:
        out.nodes.append(reg.PoseGraphNode(poses[canon[c]]))
    for edge in graph.edges:
        i, j = scans[edge.target_node_id], scans[edge.source_node_id]
        out.edges.append(
            reg.PoseGraphEdge(
                node_of[j],
                node_of[i],
                from_centred(np.asarray(edge.transformation), centres[i], centres[j]),
                information_about(np.asarray(edge.information), centres[i]),
                uncertain=edge.uncertain,
                confidence=edge.confidence,
            )
        )
    return out


def _full_normals(points: np.ndarray, settings: RegistrationSettings) -> np.ndarray:
    """A full scan's normals as a pair's context estimates them for its target (in the
    frame centred on the scan's centroid, :func:`~.prepared.estimate_normals` at the
    settings' normal radius): estimated once per scan instead of once per edge."""
    cloud = o3d.geometry.PointCloud(vectors(points))
    cloud.translate(-cloud.get_center())
    estimate_normals(cloud, settings.normal_radius)
    return np.asarray(cloud.normals).copy()


def _prepare_scan(k: int, *args) -> PreparedCloud:
    """:func:`~.prepared.prepare_cloud` of scan ``k``; its errors say which scan
    (``scan k: ...``)."""
    try:
        return prepare_cloud(*args)
    except ValueError as exc:
        raise ValueError(f"scan {k}: {exc}") from exc


def _canonical_order(points: list[np.ndarray]) -> list[int]:
    """The scans ordered by their content, the same wherever the set lies: the point
    count, then the spreads of the points (covariance eigenvalues to 6 digits), then a
    hash of the coordinates, then (equal scans) the given index. The given index of
    each."""

    def key(k: int):
        p = points[k]
        spread = np.linalg.eigvalsh(np.cov(p.T)) if len(p) > 1 else np.zeros(3)
        rounded = tuple(float(f"{v:.6g}") for v in spread)
        return len(p), rounded, hashlib.sha256(np.ascontiguousarray(p).tobytes()).hexdigest(), k

    return sorted(range(len(points)), key=key)


def _candidates(
    features: list[np.ndarray], k: int, sequence: list[int] | None = None
) -> list[tuple[int, int]]:
    """All pairs of a few scans; for many, each scan's ``k`` nearest by its pooled
    (mean, unit-length) descriptor, plus, with ``sequence`` (the scans in the order of
    their acquisition), each scan's neighbours in it: at most ``(k + 1) n`` pairs,
    found by a k-d tree in O(n log n) time and O(n k) memory."""
    n = len(features)
    if n <= ALL_PAIRS_UP_TO:
        return [(i, j) for i in range(n) for j in range(i + 1, n)]
    pooled = np.stack([f.mean(axis=0) for f in features])
    pooled /= np.linalg.norm(pooled, axis=1, keepdims=True) + 1e-12
    # k + 1: a scan is its own nearest (or ties with a duplicate of itself).
    _, nearest = cKDTree(pooled).query(pooled, k=min(k + 1, n))
    sequence = sequence or []
    pairs = {(min(a, b), max(a, b)) for a, b in zip(sequence, sequence[1:], strict=False)}
    for i, row in enumerate(nearest):
        others = [int(j) for j in row if j != i][:k]
        pairs.update((min(i, j), max(i, j)) for j in others)
    return sorted(pairs)


@validate_params(
    {
        "clouds": [list, tuple],
        "descriptor": [None, StrOptions({"auto", *PRETRAINED_MODELS}), HasMethods(["transform"])],
        "global_method": [str, HasMethods(["run"])],
        "voxel_size": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "n_global_points": [Interval(Integral, 3, None, closed="left"), StrOptions({"auto"})],
        "min_fitness": [Interval(Real, 0, 1, closed="right")],
        "max_violation": [Interval(Real, 0, 1, closed="both"), None],
        "n_jobs": [None, Integral],
        "progress": [None, "boolean"],
        "random_state": [Interval(Integral, 0, None, closed="left")],
        "settings": [None, RegistrationSettings],
        "seed": [None, Interval(Integral, 0, None, closed="left")],
        "viewpoints": [None, StrOptions({"origin", "auto"}), "array-like"],
        "sequential": ["boolean"],
    },
    prefer_skip_nested_validation=False,  # the descriptor is the caller's, checked by itself
)
def register_multiway(
    clouds: list[Any],
    descriptor: Any = "auto",
    *,
    viewpoints: Any = "auto",
    global_method: Any = "auto",
    voxel_size: float | str = "auto",
    n_global_points: int | str = "auto",
    min_fitness: float = MIN_EDGE_FITNESS,
    max_violation: float | None = MAX_FREE_SPACE_VIOLATION,
    n_jobs: int | None = None,
    progress: bool | None = None,
    random_state: int = 0,
    settings: RegistrationSettings | None = None,
    sequential: bool = False,
    seed: int | None = None,
) -> MultiwayResult:
    """Poses of unposed scans of one object or scene, in scan 0's frame (or, when scan 0
    overlaps no placed scan, the frame of the placed scan given first).

    Parameters
    ----------
    clouds : list of array-like (n_k, 3) or Open3D point clouds
        At least two scans; sizes and resolutions may differ.
    descriptor : "auto", a shipped model's name, transformer or None, \
            default="auto"
        ``"auto"``: the shipped model chosen from the scans as ``register()`` chooses
        it (:func:`~o3d_rpointhop.registration.model_choice.choose_model`): the scene
        model, facing a sensor at each scan's origin, when at least half of the scans
        read as rooms scanned from their origin, else the one-hop object model;
        ``result.model`` says which and why (and the axes it describes on, with
        :data:`SCREENING_AXES` set). A name: that shipped model; ``None``: the
        object model (``pretrained("object")``); an ``FPFHTransformer`` or any fitted
        descriptor works the same way. Each scan is described once. Pairs are screened
        with the global step the descriptor states
        (``registration_global_method_``: the consensus for the shipped scene model,
        so that ``RPointHopTransformer.pretrained("scene")`` registers scans of rooms
        as ``register()`` does), else RANSAC.
    viewpoints : "auto", None, "origin" or array-like of shape (n_scans, 3), \
            default="auto"
        Where each scan's sensor stood, in the scan's own coordinates; ``"origin"``:
        every scan is in its sensor's frame. Normals and local frames then face the
        sensor (see :func:`~o3d_rpointhop.register`). ``None``: no sensor is known.
        ``"auto"``: chosen with the model when ``descriptor="auto"``, else None.
    global_method : str or step, default="auto"
        The step that screens each candidate pair: ``"auto"`` (the one the descriptor
        states, as above), a name of :data:`~o3d_rpointhop.registration.GLOBAL_METHODS`
        (``"ransac"``, ``"consensus"``, ...) or a configured step such as
        ``RANSACGlobal(max_iteration=200_000)`` (copied for every pair). With every
        scan's sensor known and :data:`SCREENING_HYPOTHESES` set, a consensus left
        to choose its hypotheses (``n_hypotheses="auto"``) verifies that many per
        pair instead of a pair's 16.
    voxel_size : float or "auto", default="auto"
        The common resolution, as ``register()``'s ``voxel_size`` is a pair's: every
        distance of the settings is a multiple of it. ``"auto"``: the coarsest any scan
        needs to keep about ``n_global_points`` points.
    n_global_points : int or "auto", default="auto"
        With ``voxel_size="auto"``, the common resolution keeps about this many points
        of the largest scan; ``"auto"``: the descriptor's ``registration_points_`` (the
        scene model: 4096), else 2048.
    min_fitness : float, default=0.3
        A pair becomes an edge when its screening leaves at least this share of the
        source scan (at the common resolution) within the settings' ``edge_distance``
        (1.5 resolutions) of the target.
    max_violation : float or None, default=MAX_FREE_SPACE_VIOLATION
        With every scan's sensor position known (``viewpoints``), a fitting pair becomes
        an edge only when its pose puts at most this share of either scan in front of
        what the other scan's sensor saw (:mod:`~o3d_rpointhop.registration.free_space`):
        wrong poses of rooms that fit as well as right ones (floors and walls aligned,
        repeated furniture) do, right ones barely. ``result.free_space`` holds each
        fitting pair's share. ``None``: no such check.
    n_jobs : int, default=None
        Cores to use. ``None``: every core, scans and pairs one after another, each on
        the compiled kernels' threads. An int ``k``: ``k`` joblib processes of one
        thread each, over the scans' descriptors, the screening of candidate pairs and
        the refinement of kept edges (a Dask cluster under
        ``joblib.parallel_config(backend="dask")``), and this process's own work on
        ``k`` cores (``1``: everything on one core, Open3D and BLAS included); ``-1``:
        every core. The result does not depend on it.
    progress : bool, default=None
        A bar on stderr over the pairs (``None``: when stderr is a terminal).
    random_state : int, default=0
        Seeds every pair's random draws (the same draws for a pair whatever the order
        the scans are given in).
    settings : RegistrationSettings, default=None
        The multiples of the common resolution (RANSAC, ICP, normals, edges); ``None``
        is ``RegistrationSettings()``.
    sequential : bool, default=False
        The scans were given in the order they were taken: with more than 12 scans,
        each is also paired with the scans given next to it (besides its nearest by
        pooled descriptor), so the pairs screened, and with them the result, depend on
        that order. ``False``: the same scans in any order give the same result. (On
        the scene model's training scenes above 12 fragments, the pairs the sequence
        added placed no more ground-truth pairs: benchmarks/rooms_order.py.)
    seed : int, default=None
        The former name of ``random_state``; given, it wins with a ``FutureWarning``.

    Returns
    -------
    MultiwayResult

    Raises
    ------
    ValueError
        For fewer than two clouds, or a cloud that is not a valid point cloud.
    """
    seed = renamed_seed(random_state, seed, "register_multiway")
    with core_budget(n_jobs):
        start = time.perf_counter()
        if len(clouds) < 2:
            raise ValueError(f"register_multiway needs at least two clouds, got {len(clouds)}")
        points = [as_points(c, f"clouds[{k}]") for k, c in enumerate(clouds)]
        descriptor, viewpoints, choice = resolve_model(descriptor, viewpoints, points)
        if choice is not None:
            descriptor, choice = chosen_model(descriptor, choice)
        views = as_viewpoints(viewpoints, len(points))
        n = len(points)
        # The scans in a canonical order, by content: the same files in any order give the
        # same pairs, in the same directions, and the same poses. canon[c]: the given
        # index of the scan at canonical place c.
        canon = _canonical_order(points)
        points = [points[k] for k in canon]
        views = [views[k] for k in canon]
        # Every scan in its own frame centred on its centroid, for the whole run: edges,
        # information matrices and the optimisation stay well conditioned at survey
        # coordinates, and a scan set gives the same edges and poses wherever each of its
        # scans lies, in one frame or several. Results go back at the end.
        centres = [p.mean(axis=0) for p in points]
        points = [p - c for p, c in zip(points, centres, strict=True)]
        views = [None if v is None else v - c for v, c in zip(views, centres, strict=True)]
        worker = worker_copy(descriptor if descriptor is not None else default_descriptor())
        # The screening step, resolved and checked as register() does (copied per pair),
        # without register()'s FPFH fallback: the rooms were chosen with the model alone.
        global_method = build_chain(global_method, None, worker, fpfh_fallback=False)[0][1]
        global_method = _screening_step(global_method, all(v is not None for v in views))
        if voxel_size == "auto":
            voxel = common_voxel(points, resolve_global_points(n_global_points, worker))
        else:
            voxel = float(voxel_size)
        settings = (settings or RegistrationSettings()).at(voxel)
        # Every scan is downsampled, described and given normals once, for all its pairs.
        try:
            prepared = parallel_map(
                _prepare_scan,
                [
                    (canon[c], p, voxel, worker, view, settings.normal_radius, settings)
                    for c, (p, view) in enumerate(zip(points, views, strict=True))
                ],
                n_jobs=n_jobs,
                progress=progress,
                desc="describe",
                unit="scan",
            )
        except ValueError as exc:
            if voxel_size != "auto":
                raise
            # Say which scan made the common resolution as coarse as it is.
            n_points = resolve_global_points(n_global_points, worker)
            setter = int(np.argmax([common_voxel([p], n_points) for p in points]))
            raise ValueError(
                f"{exc} (downsampled to the common resolution {voxel:.4g}, which scan "
                f"{canon[setter]} ({len(points[setter])} points) needs: too small a scan "
                "coarsens them all)"
            ) from exc
        features = [p.features for p in prepared]
        place = {k: c for c, k in enumerate(canon)}
        sequence = [place[k] for k in range(n)] if sequential else None
        candidates = _candidates(features, RETRIEVED_NEIGHBOURS, sequence)
        log.info(
            "%d scans prepared at resolution %.4g; screening %d candidate pairs with %s",
            len(points),
            voxel,
            len(candidates),
            global_method.name,
        )
        results = parallel_map(
            _register_pair,
            [
                (None, None, prepared[j], prepared[i], settings, seed, None, None, global_method)
                + (min_fitness, (views[j], views[i]))
                for i, j in candidates
            ],
            n_jobs=n_jobs,
            progress=progress,
            desc="pairs",
            unit="pair",
        )
        pairs = {pair: (t, f) for pair, (t, f, _) in zip(candidates, results, strict=True)}
        fitting = {p: r for p, r in zip(candidates, results, strict=True) if r[1] >= min_fitness}
        seen = _free_space(fitting, prepared, views, voxel)
        limit = 1.0 if max_violation is None else max_violation
        edges = {p: r for p, r in fitting.items() if seen.get(p, 0.0) <= limit}
        if len(edges) < len(fitting):
            log.info(
                "%d fitting pairs left out: they put over %.2f of a scan in space the other "
                "sensor saw empty",
                len(fitting) - len(edges),
                limit,
            )
        log.info(
            "%d of %d pairs fit (edge fitness >= %.2f)", len(edges), len(candidates), min_fitness
        )
        for (i, j), (_, fitness, _) in zip(candidates, results, strict=True):
            log.debug("pair %d-%d: edge fitness %.3f", canon[i], canon[j], fitness)
        # Rooted in the largest part the edges join, not in whichever scan came first.
        (root, *_), every_part = largest_part(edges, n)
        tree = spanning_tree(edges, n)
        work = (edges, tree, points, prepared, settings, seed, n_jobs, progress)
        graph, poses, kept = _reconstruct_part(root, *work)
        placed = [c for c, p in enumerate(poses) if p is not None]  # the graph's nodes
        log.info("pose graph: %d edges kept, %d of %d scans placed", len(kept), len(placed), n)
        # Back in the given order and coordinates, in the frame of the placed scan given
        # first (scan 0 whenever it is placed).
        given_poses, frame = _in_given_frame(poses, canon, centres)
        # Every smaller part of two scans or more is reconstructed the same way, on its own
        # (as COLMAP returns several models), in the frame of its scan given first.
        part_poses = [given_poses]
        for part in every_part[1:]:
            if len(part) > 1:
                own = _reconstruct_part(part[0], *work)[1]
                part_poses.append(_in_given_frame(own, canon, centres)[0])
            else:
                alone = [None] * n
                alone[canon[part[0]]] = np.eye(4)
                part_poses.append(alone)
        given_pairs = {}
        for (i, j), (t, f) in pairs.items():
            moved = from_centred(t, centres[i], centres[j])  # scan j into scan i
            a, b = canon[i], canon[j]
            given_pairs[(a, b) if a < b else (b, a)] = (moved if a < b else np.linalg.inv(moved), f)
        return MultiwayResult(
            poses=given_poses,
            pose_graph=_graph_about(graph, centres, placed, canon, given_poses),
            pairs=dict(sorted(given_pairs.items())),
            edges=sorted((min(canon[i], canon[j]), max(canon[i], canon[j])) for i, j in kept),
            unconnected=sorted(canon[c] for c in range(n) if poses[c] is None),
            voxel_size=voxel,
            seconds=time.perf_counter() - start,
            frame=canon[frame],
            parts=[sorted(canon[c] for c in part) for part in every_part],
            part_poses=part_poses,
            model=None if choice is None else choice.as_dict(),
            free_space={
                (min(canon[i], canon[j]), max(canon[i], canon[j])): share
                for (i, j), share in sorted(seen.items())
            },
            min_fitness=float(min_fitness),
            max_violation=max_violation,
        )


def _free_space(fitting: dict, prepared: list, views: list, voxel: float) -> dict:
    """The free-space violation (:func:`~.free_space.free_space_violation`, on the
    global clouds, one resolution of margin) of every fitting pair's pose; empty unless
    every scan's sensor position is known."""
    if any(v is None for v in views):
        return {}
    return {
        (i, j): free_space_violation(
            prepared[j].points, prepared[i].points, result[0], views[j], views[i], voxel
        )
        for (i, j), result in fitting.items()
    }


def _reconstruct_part(root, edges, tree, points, prepared, settings, seed, n_jobs, progress):
    """Poses of the scans ``edges`` join to scan ``root`` (canonical indices), in its
    centred frame: along the spanning tree, optimised, every kept edge refined by ICP
    from them (each keeps the fitness that made it an edge) ending on the full scans,
    then optimised again. Returns the graph, the poses (None outside the part) and the
    kept edges."""
    n = len(points)
    poses = poses_from_tree(tree, edges, n, root)
    graph, poses, kept = optimise(edges, tree, poses, settings, root)
    normals = {i: _full_normals(points[i], settings) for i in sorted({i for i, _ in kept})}
    results = parallel_map(
        _register_pair,
        [
            (
                points[j],
                points[i],
                PreparedCloud(prepared[j].points, normals=prepared[j].normals),
                PreparedCloud(prepared[i].points, normals=prepared[i].normals),
                settings,
                seed,
                np.linalg.inv(poses[i]) @ poses[j],
                normals[i],
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
        graph, poses, kept = optimise(refined, tree, poses, settings, root)
    return graph, poses, kept


def _in_given_frame(poses: list, canon: list[int], centres: list[np.ndarray]):
    """Canonical, centred poses as the caller gave the scans: in the given order and
    coordinates, in the frame of the placed scan given first (that one exactly the
    identity); returns the poses and that scan's canonical index."""
    placed = [c for c, p in enumerate(poses) if p is not None]
    frame = min(placed, key=lambda c: canon[c])
    into_frame = np.linalg.inv(poses[frame])
    given: list = [None] * len(poses)
    for c in placed:
        given[canon[c]] = from_centred(into_frame @ poses[c], centres[frame], centres[c])
    given[canon[frame]] = np.eye(4)  # exactly, not to rounding
    return given, frame
