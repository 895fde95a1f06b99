"""The registration methods every benchmark table compares, measured in the same run.

R-PointHop methods go through :func:`~o3d_rpointhop.register`. The FPFH methods are
Open3D's own pipeline, step for step as in its global registration tutorial (voxel
downsampling, normals at 2 voxels, FPFH at 5 voxels, RANSAC on mutual feature matches at
1.5 voxels or FGR at 0.5 voxels, point-to-plane ICP at 0.4 voxels), so "beats FPFH" means
beats what an Open3D user gets. ``fpfh-pipeline-ransac-icp`` runs FPFH through this
library's pipeline instead, to separate the descriptor from the pipeline.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import open3d as o3d

from .._utils.threads import repeatable_open3d
from ..descriptors import FPFHTransformer, RPointHopTransformer
from ..open3d_interop import to_point_cloud
from ..registration import RegistrationWarning, register

__all__ = ["DEFAULT_METHODS", "METHODS", "Method", "run_method"]

reg = o3d.pipelines.registration


@dataclass(frozen=True)
class Method:
    name: str
    description: str
    #: Only on 3DMatch: the method needs the pair's scene (leave-one-scene-out models).
    scenes_only: bool = False


METHODS = {
    m.name: m
    for m in (
        Method("rpointhop-svd", "R-PointHop + the paper's one-shot SVD"),
        Method("rpointhop-svd-icp", "R-PointHop + SVD + point-to-plane ICP"),
        Method("rpointhop-ransac", "R-PointHop + RANSAC"),
        Method("rpointhop-ransac-icp", "R-PointHop + RANSAC + point-to-plane ICP"),
        Method(
            "rpointhop-ransac-icp-4096",
            "R-PointHop + RANSAC + point-to-plane ICP, 4096 global points",
        ),
        Method(
            "rpointhop-scene",
            "R-PointHop, shipped scene model + RANSAC + point-to-plane ICP (register() defaults)",
        ),
        Method(
            "rpointhop-loso",
            "R-PointHop, scene model fitted on the other scenes + RANSAC + point-to-plane ICP",
            scenes_only=True,
        ),
        Method(
            "rpointhop-ransac-icp-sym",
            "R-PointHop + RANSAC + point-to-plane ICP + symmetry check",
        ),
        Method("fpfh-ransac", "FPFH + RANSAC (Open3D's recipe)"),
        Method("fpfh-fgr", "FPFH + FGR (Open3D's recipe)"),
        Method("fpfh-ransac-icp", "FPFH + RANSAC + point-to-plane ICP (Open3D's recipe)"),
        Method(
            "fpfh-ransac-icp-5cm",
            "FPFH + RANSAC + point-to-plane ICP (Open3D's recipe), 5 cm voxel",
        ),
        Method("fpfh-pipeline-ransac-icp", "FPFH through this library's RANSAC + ICP"),
        Method(
            "rpointhop-open3d-ransac-icp",
            "R-PointHop (32 axes) in Open3D's RANSAC recipe + point-to-plane ICP",
        ),
        Method("icp", "point-to-point ICP alone, from the identity"),
    )
}


#: What ``o3d-rpointhop benchmark <dataset>`` runs when not given ``--methods``.
DEFAULT_METHODS = {
    "3dmatch": [
        "rpointhop-scene",
        "rpointhop-loso",
        "rpointhop-ransac-icp-4096",
        "fpfh-ransac-icp",
        "fpfh-ransac-icp-5cm",
        "fpfh-pipeline-ransac-icp",
    ],
    # The objects (ModelNet40, bunny): every method but the scene-oriented ones.
    "objects": [
        name
        for name in METHODS
        if name
        not in (
            "rpointhop-scene",
            "rpointhop-loso",
            "rpointhop-ransac-icp-4096",
            "fpfh-ransac-icp-5cm",
        )
    ],
}

# Methods that are Open3D calls from end to end (the others go through register(), whose
# steps already run Open3D repeatably).
_OPEN3D_ONLY = {
    "fpfh-ransac",
    "fpfh-fgr",
    "fpfh-ransac-icp",
    "fpfh-ransac-icp-5cm",
    "rpointhop-open3d-ransac-icp",
    "icp",
}


def _fpfh_recipe_inputs(source, target, voxel):
    def prepare(points):
        cloud = to_point_cloud(points).voxel_down_sample(voxel)
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
        feature = reg.compute_fpfh_feature(
            cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
        )
        return cloud, feature

    return (*prepare(source), *prepare(target))


def _feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter: bool):
    """Open3D's RANSAC on feature matches, as in its global registration tutorial."""
    distance = 1.5 * voxel
    o3d.utility.random.seed(seed)
    result = reg.registration_ransac_based_on_feature_matching(
        src,
        tgt,
        f_src,
        f_tgt,
        mutual_filter,
        distance,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [
            reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
            reg.CorrespondenceCheckerBasedOnDistance(distance),
        ],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    return np.array(result.transformation)


def _fpfh_ransac(source, target, voxel, seed):
    src, f_src, tgt, f_tgt = _fpfh_recipe_inputs(source, target, voxel)
    return _feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter=True)


def open3d_recipe_descriptor():
    """The descriptor of the Open3D-native recipe: the pretrained model on 32 axes, which
    Open3D's k-d tree over features searches fast (1624-D made its RANSAC 40-230x slower)."""
    return RPointHopTransformer.pretrained(n_components=32)


def _rpointhop_open3d_ransac(source, target, voxel, seed, model):
    """docs/registration.md, "Inside Open3D's own pipeline", step for step."""
    from ..open3d_interop import to_open3d_feature

    src = to_point_cloud(source).voxel_down_sample(voxel)
    tgt = to_point_cloud(target).voxel_down_sample(voxel)
    f_src = to_open3d_feature(model.transform(src))
    f_tgt = to_open3d_feature(model.transform(tgt))
    # mutual_filter=False: RANSAC does the filtering, and Open3D prints no fallback warning.
    return _feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter=False)


def _fpfh_fgr(source, target, voxel, seed):
    src, f_src, tgt, f_tgt = _fpfh_recipe_inputs(source, target, voxel)
    o3d.utility.random.seed(seed)
    result = reg.registration_fgr_based_on_feature_matching(
        src,
        tgt,
        f_src,
        f_tgt,
        reg.FastGlobalRegistrationOption(maximum_correspondence_distance=0.5 * voxel),
    )
    return np.array(result.transformation)


def _recipe_icp(source, target, voxel, init):
    src, tgt = to_point_cloud(source), to_point_cloud(target)
    tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    result = reg.registration_icp(
        src, tgt, 0.4 * voxel, init, reg.TransformationEstimationPointToPlane()
    )
    return np.array(result.transformation)


_LOADED: dict = {}


def _recipe_model():
    """Loaded once per process (loading is not part of the recipe's time)."""
    if "recipe" not in _LOADED:
        _LOADED["recipe"] = open3d_recipe_descriptor()
    return _LOADED["recipe"]


def shipped_scene_model():
    """The shipped scene model, loaded once per process."""
    if "scene" not in _LOADED:
        _LOADED["scene"] = RPointHopTransformer.pretrained("scene")
    return _LOADED["scene"]


def run_method(
    name: str,
    source: np.ndarray,
    target: np.ndarray,
    *,
    descriptor,
    voxel: float,
    seed: int = 0,
) -> tuple[np.ndarray, float]:
    """Run one method on one pair; return its transformation and wall time in seconds.

    Parameters
    ----------
    descriptor : RPointHopTransformer
        The model the R-PointHop methods use (``rpointhop-loso``: the pair's
        leave-one-scene-out model; ``rpointhop-scene`` always uses the shipped scene
        model).
    voxel : float
        Resolution of the FPFH recipe and of ICP alone (0.05 for unit-sphere objects, as
        in the Open3D tutorial).
    """
    runners: dict[str, Callable[[], np.ndarray]] = {
        "rpointhop-svd": lambda: (
            register(
                source, target, descriptor, global_method="svd", refine=None, seed=seed
            ).transformation
        ),
        "rpointhop-svd-icp": lambda: (
            register(source, target, descriptor, global_method="svd", seed=seed).transformation
        ),
        "rpointhop-ransac": lambda: (
            register(source, target, descriptor, refine=None, seed=seed).transformation
        ),
        "rpointhop-ransac-icp": lambda: (
            register(source, target, descriptor, seed=seed).transformation
        ),
        "rpointhop-ransac-icp-4096": lambda: (
            register(source, target, descriptor, n_global_points=4096, seed=seed).transformation
        ),
        "rpointhop-scene": lambda: (
            register(source, target, shipped_scene_model(), seed=seed).transformation
        ),
        "rpointhop-ransac-icp-sym": lambda: (
            register(
                source, target, descriptor, refine=["point_to_plane", "symmetry_check"], seed=seed
            ).transformation
        ),
        "fpfh-ransac": lambda: _fpfh_ransac(source, target, voxel, seed),
        "fpfh-fgr": lambda: _fpfh_fgr(source, target, voxel, seed),
        "fpfh-ransac-icp": lambda: _recipe_icp(
            source, target, voxel, _fpfh_ransac(source, target, voxel, seed)
        ),
        "fpfh-ransac-icp-5cm": lambda: _recipe_icp(
            source, target, 0.05, _fpfh_ransac(source, target, 0.05, seed)
        ),
        "fpfh-pipeline-ransac-icp": lambda: (
            register(
                source, target, FPFHTransformer(radius="auto", normal_radius="auto"), seed=seed
            ).transformation
        ),
        "rpointhop-open3d-ransac-icp": lambda: _recipe_icp(
            source,
            target,
            voxel,
            _rpointhop_open3d_ransac(source, target, voxel, seed, _recipe_model()),
        ),
        "icp": lambda: np.array(
            reg.registration_icp(
                to_point_cloud(source),
                to_point_cloud(target),
                4 * voxel,
                np.eye(4),
                reg.TransformationEstimationPointToPoint(False),
            ).transformation
        ),
    }
    # The pair's leave-one-scene-out model goes through register() like any model.
    runners["rpointhop-loso"] = runners["rpointhop-ransac-icp"]
    if name not in runners:
        raise ValueError(f"unknown method {name!r}; choose from {sorted(METHODS)}")
    # Open3D's recipe warns when its mutual filter leaves few matches; the result says it.
    # Its RANSAC is only repeatable on one thread (see repeatable_open3d), as ours runs.
    # Loading a model file is not part of a method's time.
    if name == "rpointhop-open3d-ransac-icp":
        _recipe_model()
    if name == "rpointhop-scene":
        shipped_scene_model()
    # Flagged results are scored like any other; the flags' warnings would only repeat.
    with (
        warnings.catch_warnings(),
        o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error),
    ):
        warnings.simplefilter("ignore", RegistrationWarning)
        start = time.perf_counter()
        if name in _OPEN3D_ONLY:
            with repeatable_open3d():
                transformation = runners[name]()
        else:
            transformation = runners[name]()
        return transformation, time.perf_counter() - start
