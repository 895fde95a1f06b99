"""The registration methods every benchmark table compares, measured in the same run:
the table (:data:`METHODS`) of recipes by name. The peers' code is in :mod:`.peers`,
running one on a pair in :mod:`.runner`.

R-PointHop methods go through :func:`~o3d_rpointhop.register`, with the global step
they name. The ``fpfh-ransac*`` and ``fpfh-fgr`` methods are Open3D's own pipeline, step
for step as in its global registration tutorial (voxel downsampling, normals at 2
voxels, FPFH at 5 voxels, RANSAC on mutual feature matches at 1.5 voxels or FGR at 0.5
voxels, point-to-plane ICP at 0.4 voxels), so "beats FPFH" means beats what an Open3D
user gets. ``fpfh-pipeline-*`` run FPFH through this library's steps instead, to
separate the descriptor from the pipeline. ``kiss-matcher`` is KISS-Matcher (Lim et
al., 2025) end to end, from its pip wheel (the optional ``[peers]`` extra); without it
installed the method is skipped with a line on stderr.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import open3d as o3d
from sklearn.base import BaseEstimator, clone

from ..descriptors import DescriptorUnion, FPFHTransformer, RPointHopTransformer
from ..open3d_interop import to_point_cloud
from ..registration import ConsensusGlobal, Matcher, PooledMatcher, RANSACGlobal, register
from ..registration.defaults import SCENE_FPFH_WEIGHT
from .peers import (
    fpfh_fgr,
    fpfh_ransac,
    kiss_matcher_available,
    kiss_matcher_estimate,
    open3d_recipe_descriptor,
    recipe_icp,
    rpointhop_open3d_ransac,
    sc2pcr_step,
)

__all__ = [
    "DATASETS",
    "METHODS",
    "Method",
    "default_methods",
    "check_methods",
    "claimed_by",
    "pooled_hypotheses_step",
    "pooled_step",
    "scene_with_fpfh",
    "shipped_scene_model",
]

reg = o3d.pipelines.registration


def shipped_scene_model():
    """The shipped scene model (``pretrained()`` reads its file once per process)."""
    return RPointHopTransformer.pretrained("scene")


def scene_with_fpfh() -> DescriptorUnion:
    """The shipped scene model and FPFH side by side, FPFH weighing
    :data:`~o3d_rpointhop.registration.defaults.SCENE_FPFH_WEIGHT`."""
    return DescriptorUnion(
        [("rpointhop", shipped_scene_model()), ("fpfh", FPFHTransformer())],
        transformer_weights={"fpfh": SCENE_FPFH_WEIGHT},
    )


#: The pair datasets a method can be run on (multiway has its own descriptor list).
DATASETS = ("modelnet40", "bunny", "3dmatch")
_ALL = frozenset(DATASETS)
_OBJECTS = frozenset({"modelnet40", "bunny"})
_SCENES = frozenset({"3dmatch"})


@dataclass(frozen=True)
class Method:
    """One registration method of the benchmarks.

    Attributes
    ----------
    name, description : str
    run : callable
        ``run(source, target, descriptor, voxel, seed, viewpoints)`` -> the 4x4
        source-to-target transformation and whether the method claims it (``None`` for
        a method that reports no such flag), or a whole ``RegistrationResult`` (the
        methods through ``register()``); ``viewpoints`` is None or the sensor
        positions of the source and the target, each in its own coordinates.
    datasets : frozenset of str
        The datasets it can be run on.
    default_on : frozenset of str
        The datasets whose benchmark runs it when no method is named.
    model : {"given", "scene", "loso", "recipe", None}
        The R-PointHop model it describes with: the benchmark's (``"given"``), the
        shipped scene model, each pair's leave-one-scene-out model, the Open3D recipe's
        model (:func:`open3d_recipe_descriptor`: the object model), or none.
    descriptor : {"rpointhop", "fpfh", "union", "open3d-fpfh", "kiss-matcher", "none"}
        What describes the points: R-PointHop (``model`` says which), this library's
        ``FPFHTransformer``, a ``DescriptorUnion`` the method builds (its runner's
        ``describe_with``), Open3D's FPFH as its tutorial computes it, KISS-Matcher's
        own, or nothing (ICP alone). Records name it (:mod:`.provenance`).
    open3d_only : bool
        Open3D calls from end to end (a recipe).
    available : callable
        ``available() -> bool``: whether what the method needs is installed (an
        optional peer's wheel); :func:`check_methods` skips it, with a line saying why,
        when not.
    install : str or None
        What to install when it is not available.
    """

    name: str
    description: str
    run: Callable[..., np.ndarray] = field(repr=False)
    datasets: frozenset = _ALL
    default_on: frozenset = frozenset()
    model: str | None = "given"
    open3d_only: bool = False
    descriptor: str = "rpointhop"
    available: Callable[[], bool] = field(default=lambda: True, repr=False)
    install: str | None = None

    def preload(self, descriptor: Any) -> Any:
        """The descriptor the method runs with, its model read now (reading a model file
        is not part of a method's time): the shipped scene model for ``model="scene"``,
        the recipe's model read once for ``"recipe"``, else ``descriptor``."""
        if self.model == "scene":
            return shipped_scene_model()
        if self.model == "recipe":
            open3d_recipe_descriptor()
        return descriptor


#: Up in a camera's frame (image rows grow downwards): the up-axis prior of the 3DMatch
#: methods that name it; between fragments the camera tilts by 15-45 degrees, so the
#: prior only refuses upside-down hypotheses.
CAMERA_UP = (0.0, -1.0, 0.0)


def claimed_by(result) -> bool:
    """Whether a result of :func:`~o3d_rpointhop.register` says it can be trusted
    (converged, not ambiguous)."""
    return bool(result.converged and not result.ambiguous)


def _resolved(options: dict) -> dict:
    """``options`` for one pair: an estimator (a global step) cloned, so that no pair
    sees another's fitted state, and a callable ``global_method`` called."""
    chosen = {k: clone(v) if isinstance(v, BaseEstimator) else v for k, v in options.items()}
    if callable(chosen.get("global_method")):
        chosen["global_method"] = chosen["global_method"]()
    return chosen


def global_step(
    kind: str, n_hypotheses: int = 1, step: dict | None = None, **matching
) -> RANSACGlobal | ConsensusGlobal:
    """A global step named by its public parameters: ``kind`` (``"ransac"`` or
    ``"consensus"``), ``n_hypotheses``, the step's other parameters ``step`` and the
    :class:`~o3d_rpointhop.registration.Matcher` parameters ``matching`` (over the
    step's default matcher). The table holds the step itself; each pair registers with
    a clone."""
    step_class = {"ransac": RANSACGlobal, "consensus": ConsensusGlobal}[kind]
    matcher = step_class.default_matcher().set_params(**matching) if matching else None
    return step_class(matcher=matcher, **{**(step or {}), "n_hypotheses": n_hypotheses})


def pooled_step(model: int, fpfh: int, fpfh_max_nn: int) -> ConsensusGlobal:
    """The consensus on the model's matches (at most ``model``) pooled with FPFH's (at
    most ``fpfh``, its histograms on at most ``fpfh_max_nn`` neighbours), both nearest
    both ways."""
    return ConsensusGlobal(
        matcher=PooledMatcher.with_fpfh(
            Matcher(both_directions=True, max_matches=model),
            FPFHTransformer(max_nn=fpfh_max_nn),
            Matcher(both_directions=True, max_matches=fpfh),
            combine="matches",
        )
    )


def pooled_hypotheses_step(
    n_hypotheses: int | str = "auto",
    fpfh_max_nn: int = 100,
    fpfh_matches: int = 4000,
    combine: str = "hypotheses",
) -> ConsensusGlobal:
    """One consensus on the model's matches (nearest both ways, at most 4000, as it runs
    alone) and one on FPFH's (its histograms on at most ``fpfh_max_nn`` neighbours, at
    most ``fpfh_matches``), every hypothesis of both verified together (``n_hypotheses``
    of each); with ``combine="fallback"`` FPFH's only when the model's estimate is
    weak."""
    return ConsensusGlobal(
        matcher=PooledMatcher.with_fpfh(
            fpfh=FPFHTransformer(max_nn=fpfh_max_nn),
            fpfh_matcher=Matcher(both_directions=True, max_matches=fpfh_matches),
            combine=combine,
        ),
        n_hypotheses=n_hypotheses,
    )


_SALIENT = {"salient_share": 0.75}
_TURNS = {"frame_turns": 4}


def _register_with(describe_with: Callable[[], Any] | None = None, **options):
    """A runner through :func:`~o3d_rpointhop.register` with ``options`` (a global step
    given as an estimator is cloned for each pair, a callable ``global_method`` called
    for each): it returns the whole result (the runner reads its transformation, its
    flags and, for the records, what its global step saw). ``describe_with``: a factory
    of the descriptor to use instead of the benchmark's (FPFH), one per pair."""

    def run(source, target, descriptor, voxel, seed, viewpoints):
        chosen = _resolved(options)
        used = descriptor if describe_with is None else describe_with()
        return register(source, target, used, random_state=seed, viewpoints=viewpoints, **chosen)

    run.options = options  # what the records name (provenance)
    run.describe_with = describe_with
    return run


def _fpfh_recipe(voxel_of: Callable[[float], float] = lambda voxel: voxel, icp: bool = True):
    """Open3D's FPFH + RANSAC recipe (then its ICP) at ``voxel_of(voxel)``."""

    def run(source, target, descriptor, voxel, seed, viewpoints):
        voxel = voxel_of(voxel)
        estimate = fpfh_ransac(source, target, voxel, seed, viewpoints)
        return (recipe_icp(source, target, voxel, estimate) if icp else estimate), None

    return run


def _run_fpfh_fgr(source, target, descriptor, voxel, seed, viewpoints):
    return fpfh_fgr(source, target, voxel, seed, viewpoints), None


def _fpfh_pipeline(**options):
    """FPFH through :func:`~o3d_rpointhop.register` (a callable ``global_method`` makes
    a fresh step per pair)."""
    return _register_with(FPFHTransformer, **options)


def _kiss_matcher(source, target, descriptor, voxel, seed, viewpoints):
    return kiss_matcher_estimate(source, target, voxel)


def _run_rpointhop_open3d(source, target, descriptor, voxel, seed, viewpoints):
    model = open3d_recipe_descriptor()
    estimate = rpointhop_open3d_ransac(source, target, voxel, seed, model, viewpoints)
    return recipe_icp(source, target, voxel, estimate), None


def _run_icp(source, target, descriptor, voxel, seed, viewpoints):
    return np.array(
        reg.registration_icp(
            to_point_cloud(source),
            to_point_cloud(target),
            4 * voxel,
            np.eye(4),
            reg.TransformationEstimationPointToPoint(False),
        ).transformation
    ), None


def _methods(*methods: Method) -> dict[str, Method]:
    return {m.name: m for m in methods}


#: Every method, by name; the order of the reports' rows.
METHODS = _methods(
    Method(
        "rpointhop-svd",
        "R-PointHop + the paper's one-shot SVD",
        _register_with(global_method="svd", refine=None),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-svd-icp",
        "R-PointHop + SVD + point-to-plane ICP",
        _register_with(global_method="svd"),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-ransac",
        "R-PointHop + RANSAC",
        _register_with(global_method="ransac", refine=None),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-ransac-icp",
        "R-PointHop + RANSAC + point-to-plane ICP",
        _register_with(global_method="ransac"),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-consensus-icp",
        "R-PointHop + consensus + point-to-plane ICP",
        _register_with(global_method="consensus"),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-scene",
        "R-PointHop, shipped scene model, register() defaults",
        _register_with(),
        default_on=_SCENES,
        model="scene",
    ),
    *(
        Method(
            f"rpointhop-scene-matches-{cap}",
            f"R-PointHop, shipped scene model, consensus on at most {cap} matches (spread "
            "by index) + point-to-plane ICP",
            _register_with(global_method=global_step("consensus", max_matches=cap)),
            datasets=_SCENES,
            model="scene",
        )
        for cap in (2000, 4000)
    ),
    *(
        Method(
            f"rpointhop-scene-seeds-{seeds}",
            f"R-PointHop, shipped scene model, consensus seeded by its {seeds} best-connected "
            "matches + point-to-plane ICP",
            _register_with(global_method=global_step("consensus", step={"n_seeds": seeds})),
            datasets=_SCENES,
            model="scene",
        )
        for seeds in (500, 1000)
    ),
    *(
        Method(
            f"rpointhop-scene-matches-{cap}-seeds-{seeds}",
            f"R-PointHop, shipped scene model, consensus on at most {cap} matches seeded by its "
            f"{seeds} best-connected + point-to-plane ICP",
            _register_with(
                global_method=global_step("consensus", step={"n_seeds": seeds}, max_matches=cap)
            ),
            datasets=_SCENES,
            model="scene",
        )
        for cap, seeds in ((8000, 5000), (4000, 1000))
    ),
    Method(
        "rpointhop-scene-one-hypothesis",
        "R-PointHop, shipped scene model, consensus with its own choice, nothing verified "
        "(the default before free-space verification) + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", 1)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-verified",
        "R-PointHop, shipped scene model, consensus with three hypotheses verified by "
        "overlap + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", 3)),
        datasets=_SCENES,
        model="scene",
    ),
    *(
        Method(
            f"rpointhop-scene-verified-{k}-free-{limit}",
            f"R-PointHop, shipped scene model, consensus with {k} hypotheses verified by "
            f"overlap, those putting over {limit} of a cloud in the other sensor's seen free "
            "space rejected, + point-to-plane ICP",
            _register_with(
                global_method=global_step("consensus", k, step={"max_violation": limit})
            ),
            datasets=_SCENES,
            model="scene",
        )
        for k, limit in ((3, 0.1), (8, 0.05), (8, 0.1), (8, 0.15), (16, 0.1))
    ),
    Method(
        "rpointhop-scene-salient",
        "R-PointHop, shipped scene model, consensus on matches between salient points "
        "(salient_share=0.75) + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", **_SALIENT)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-salient-verified",
        "R-PointHop, shipped scene model, consensus on matches between salient points "
        "(salient_share=0.75) with three hypotheses verified by overlap + point-to-plane "
        "ICP",
        _register_with(global_method=global_step("consensus", 3, **_SALIENT)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-salient-2nearest",
        "R-PointHop, shipped scene model, consensus on matches between salient points "
        "(salient_share=0.75), two nearest descriptors per point + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", **_SALIENT, n_nearest=2)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-salient-2nearest-12000",
        "R-PointHop, shipped scene model, consensus on up to 12000 matches between "
        "salient points (salient_share=0.75), two nearest descriptors per point + "
        "point-to-plane ICP",
        _register_with(
            global_method=global_step("consensus", **_SALIENT, n_nearest=2, max_matches=12000)
        ),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-salient-8192",
        "R-PointHop, shipped scene model, 8192 global points, consensus on matches between "
        "salient points (salient_share=0.75) + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", **_SALIENT), n_global_points=8192),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-turns",
        "R-PointHop, shipped scene model, consensus on matches over every quarter turn "
        "of the local frames (frame_turns=4) + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", **_TURNS)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-own-matches",
        "R-PointHop, shipped scene model, consensus on the model's own matches alone (at "
        "most 4000; global_method='consensus', the default before FPFH was asked as a "
        "fallback) + point-to-plane ICP",
        _register_with(global_method="consensus"),
        datasets=_SCENES,
        model="scene",
    ),
    *(
        Method(
            f"rpointhop-scene-pooled-{model}-{fpfh}-nn{nn}",
            f"R-PointHop, shipped scene model, consensus on its matches (at most {model}) "
            f"pooled with FPFH's (at most {fpfh}, {nn} neighbours) + point-to-plane ICP",
            _register_with(global_method=pooled_step(model, fpfh, nn)),
            datasets=_SCENES,
            model="scene",
        )
        for model, fpfh, nn in (
            (4000, 2000, 100),
            (4000, 2000, 50),
            (3000, 1000, 50),
            (4000, 1000, 50),
        )
    ),
    *(
        Method(
            f"rpointhop-scene-pooled-hypotheses{suffix}",
            "R-PointHop, shipped scene model: one consensus on its matches and one on "
            f"FPFH's{fpfh}, {count} hypotheses of each verified together + point-to-plane "
            "ICP",
            _register_with(global_method=pooled_hypotheses_step(*args)),
            datasets=_SCENES,
            model="scene",
        )
        for suffix, fpfh, count, args in (
            ("", "", "16 (auto)", ("auto",)),
            ("-8", "", "8", (8,)),
            ("-8-2000-nn50", " (at most 2000, 50 neighbours)", "8", (8, 50, 2000)),
        )
    ),
    Method(
        "rpointhop-scene-fpfh-fallback",
        "R-PointHop, shipped scene model: its consensus alone, and when its estimate "
        "explains under 1.5 % of its matches one on FPFH's too, 16 (auto) hypotheses of "
        "each verified together + point-to-plane ICP",
        _register_with(global_method=pooled_hypotheses_step(combine="fallback")),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-fpfh",
        "R-PointHop, shipped scene model, and FPFH side by side (DescriptorUnion, FPFH "
        "weighing 0.7), register() defaults (consensus) + point-to-plane ICP",
        _register_with(scene_with_fpfh),
        datasets=_SCENES,
        model="scene",
        descriptor="union",
    ),
    Method(
        "rpointhop-scene-fpfh-turns",
        "R-PointHop, shipped scene model, and FPFH side by side (DescriptorUnion, FPFH "
        "weighing 0.7), consensus on matches over every quarter turn of the local frames "
        "(frame_turns=4) + point-to-plane ICP",
        _register_with(scene_with_fpfh, global_method=global_step("consensus", **_TURNS)),
        datasets=_SCENES,
        model="scene",
        descriptor="union",
    ),
    Method(
        "rpointhop-scene-half-turns",
        "R-PointHop, shipped scene model, consensus on matches over the local frames and "
        "their half turns (frame_turns=2) + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", frame_turns=2)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-turns-salient",
        "R-PointHop, shipped scene model, consensus on matches over every quarter turn "
        "of the local frames between salient points (frame_turns=4, salient_share=0.75) "
        "+ point-to-plane ICP",
        _register_with(global_method=global_step("consensus", **_TURNS, **_SALIENT)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-turns-verified",
        "R-PointHop, shipped scene model, consensus on matches over every quarter turn "
        "of the local frames with three hypotheses verified by overlap (frame_turns=4, "
        "n_hypotheses=3) + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", 3, **_TURNS)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-turns-salient-verified",
        "R-PointHop, shipped scene model, consensus on matches over every quarter turn "
        "of the local frames between salient points with three hypotheses verified by "
        "overlap (frame_turns=4, salient_share=0.75, n_hypotheses=3) + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", 3, **_TURNS, **_SALIENT)),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-cosine",
        "R-PointHop, shipped scene model, consensus on matches by cosine distance "
        "(metric='cosine') + point-to-plane ICP",
        _register_with(global_method=global_step("consensus", metric="cosine")),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-turns-cosine",
        "R-PointHop, shipped scene model, consensus on matches by cosine distance over "
        "every quarter turn of the local frames (metric='cosine', frame_turns=4) + "
        "point-to-plane ICP",
        _register_with(global_method=global_step("consensus", **_TURNS, metric="cosine")),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-turns-salient-cosine",
        "R-PointHop, shipped scene model, consensus on matches by cosine distance over "
        "every quarter turn of the local frames between salient points "
        "(metric='cosine', frame_turns=4, salient_share=0.75) + point-to-plane ICP",
        _register_with(
            global_method=global_step("consensus", **_TURNS, **_SALIENT, metric="cosine")
        ),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-up",
        "R-PointHop, shipped scene model, register() defaults, up-axis prior (camera -y)",
        _register_with(up=CAMERA_UP),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-ransac",
        "R-PointHop, shipped scene model + RANSAC + point-to-plane ICP",
        _register_with(global_method="ransac"),
        default_on=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-loso",
        "R-PointHop, scene model fitted on the other scenes, register() defaults",
        _register_with(),
        datasets=_SCENES,
        default_on=_SCENES,
        model="loso",
    ),
    Method(
        "rpointhop-ransac-icp-4096",
        "R-PointHop + RANSAC + point-to-plane ICP, 4096 global points",
        _register_with(global_method="ransac", n_global_points=4096),
    ),
    Method(
        "rpointhop-ransac-icp-verified",
        "R-PointHop + RANSAC, three hypotheses verified by overlap + point-to-plane ICP",
        _register_with(global_method=global_step("ransac", 3)),
        datasets=_OBJECTS,
    ),
    Method(
        "rpointhop-ransac-icp-sym",
        "R-PointHop + RANSAC + point-to-plane ICP + symmetry check",
        _register_with(global_method="ransac", refine=["point_to_plane", "symmetry_check"]),
        default_on=_OBJECTS,
    ),
    Method(
        "fpfh-ransac",
        "FPFH + RANSAC (Open3D's recipe)",
        _fpfh_recipe(icp=False),
        default_on=_OBJECTS,
        model=None,
        open3d_only=True,
        descriptor="open3d-fpfh",
    ),
    Method(
        "fpfh-fgr",
        "FPFH + FGR (Open3D's recipe)",
        _run_fpfh_fgr,
        default_on=_OBJECTS,
        model=None,
        open3d_only=True,
        descriptor="open3d-fpfh",
    ),
    Method(
        "fpfh-ransac-icp",
        "FPFH + RANSAC + point-to-plane ICP (Open3D's recipe)",
        _fpfh_recipe(),
        default_on=_ALL,
        model=None,
        open3d_only=True,
        descriptor="open3d-fpfh",
    ),
    Method(
        "fpfh-ransac-icp-5cm",
        "FPFH + RANSAC + point-to-plane ICP (Open3D's recipe), 5 cm voxel",
        _fpfh_recipe(lambda voxel: 0.05),
        default_on=_SCENES,
        model=None,
        open3d_only=True,
        descriptor="open3d-fpfh",
    ),
    Method(
        "fpfh-pipeline-ransac-icp",
        "FPFH through this library's RANSAC + ICP",
        _fpfh_pipeline(global_method="ransac"),
        default_on=_ALL,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-icp",
        "FPFH through this library's consensus + ICP",
        _fpfh_pipeline(global_method="consensus"),
        default_on=_ALL,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-salient-icp",
        "FPFH through this library's consensus on matches between salient points "
        "(salient_share=0.75) + ICP",
        _fpfh_pipeline(global_method=global_step("consensus", **_SALIENT)),
        datasets=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-salient-verified-icp",
        "FPFH through this library's consensus on matches between salient points "
        "(salient_share=0.75) with three hypotheses verified by overlap + ICP",
        _fpfh_pipeline(global_method=global_step("consensus", 3, **_SALIENT)),
        datasets=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-cosine-icp",
        "FPFH through this library's consensus on matches by cosine distance "
        "(metric='cosine') + ICP",
        _fpfh_pipeline(global_method=global_step("consensus", metric="cosine")),
        datasets=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-cosine-icp-4096",
        "FPFH through this library's consensus on matches by cosine distance "
        "(metric='cosine') + ICP, 4096 global points",
        _fpfh_pipeline(
            global_method=global_step("consensus", metric="cosine"), n_global_points=4096
        ),
        datasets=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-icp-4096",
        "FPFH through this library's consensus + ICP, 4096 global points",
        _fpfh_pipeline(global_method="consensus", n_global_points=4096),
        datasets=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    *(
        Method(
            f"fpfh-pipeline-consensus-icp-4096-matches-{cap}",
            f"FPFH through this library's consensus on at most {cap} matches + ICP, 4096 "
            "global points",
            _fpfh_pipeline(
                global_method=global_step("consensus", max_matches=cap), n_global_points=4096
            ),
            datasets=_SCENES,
            model=None,
            descriptor="fpfh",
        )
        for cap in (4000, 8000)
    ),
    Method(
        "fpfh-sc2pcr-icp",
        "FPFH + SC2-PCR (from its paper, on the consensus's matches) + ICP",
        _fpfh_pipeline(global_method=sc2pcr_step),
        datasets=_SCENES,
        default_on=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-icp-up",
        "FPFH through this library's consensus + ICP, up-axis prior (camera -y)",
        _fpfh_pipeline(global_method="consensus", up=CAMERA_UP),
        datasets=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "rpointhop-open3d-ransac-icp",
        "R-PointHop (object model) in Open3D's RANSAC recipe + point-to-plane ICP",
        _run_rpointhop_open3d,
        default_on=_OBJECTS,
        model="recipe",
        open3d_only=True,
    ),
    Method(
        "kiss-matcher",
        "KISS-Matcher end to end (pip wheel)",
        _kiss_matcher,
        default_on=_SCENES,
        model=None,
        descriptor="kiss-matcher",
        available=kiss_matcher_available,
        install="pip install '.[peers]' in the project folder (or kiss-matcher)",
    ),
    Method(
        "icp",
        "point-to-point ICP alone, from the identity",
        _run_icp,
        default_on=_OBJECTS,
        model=None,
        open3d_only=True,
        descriptor="none",
    ),
)


def default_methods(dataset: str) -> list[str]:
    """The methods ``o3d-rpointhop benchmark <dataset>`` runs when not given ``--methods``."""
    return [name for name, m in METHODS.items() if dataset in m.default_on]


def check_methods(methods, dataset: str) -> list[str]:
    """``methods`` as a list, refused if one is unknown or does not apply to ``dataset``."""
    methods = list(methods)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ValueError(f"unknown methods {unknown}; choose from {sorted(METHODS)}")
    elsewhere = [m for m in methods if dataset not in METHODS[m].datasets]
    if elsewhere:
        where = sorted({d for m in elsewhere for d in METHODS[m].datasets})
        raise ValueError(f"{elsewhere} do not apply to {dataset} (only to {', '.join(where)})")
    for name in [m for m in methods if not METHODS[m].available()]:
        print(
            f"benchmark: {name} skipped: not installed ({METHODS[name].install})",
            file=sys.stderr,
        )
        methods.remove(name)
    return methods
