"""The peers every benchmark measures against, written as their authors publish them:
Open3D's FPFH + RANSAC / FGR + ICP recipe step for step as in its global registration
tutorial (voxel downsampling, normals at 2 voxels, FPFH at 5 voxels, RANSAC on mutual
feature matches at 1.5 voxels or FGR at 0.5 voxels, point-to-plane ICP at 0.4 voxels),
the same recipe with R-PointHop's features, KISS-Matcher from its pip wheel (the
optional ``[peers]`` extra) and SC2-PCR (:mod:`.sc2pcr`)."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from .._utils.threads import repeatable_open3d
from ..descriptors import RPointHopTransformer
from ..open3d_interop import to_point_cloud

__all__ = [
    "feature_ransac",
    "fpfh_fgr",
    "fpfh_ransac",
    "fpfh_recipe_cloud",
    "kiss_matcher_available",
    "kiss_matcher_estimate",
    "open3d_recipe_descriptor",
    "recipe_icp",
    "rpointhop_open3d_ransac",
    "sc2pcr_step",
]

reg = o3d.pipelines.registration


def fpfh_recipe_cloud(points, voxel, viewpoint=None):
    """A cloud as Open3D's global registration tutorial prepares it: voxel-downsampled,
    normals at 2 voxels (turned towards ``viewpoint`` when given, with Open3D's
    ``orient_normals_towards_camera_location``), FPFH at 5 voxels; returns the cloud and
    its features."""
    cloud = to_point_cloud(points).voxel_down_sample(voxel)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    if viewpoint is not None:
        cloud.orient_normals_towards_camera_location(np.asarray(viewpoint, dtype=np.float64))
    feature = reg.compute_fpfh_feature(
        cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    )
    return cloud, feature


def _fpfh_recipe_inputs(source, target, voxel, viewpoints=None):
    views = (None, None) if viewpoints is None else viewpoints
    return (
        *fpfh_recipe_cloud(source, voxel, views[0]),
        *fpfh_recipe_cloud(target, voxel, views[1]),
    )


def feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter: bool):
    """Open3D's RANSAC on feature matches, as in its global registration tutorial (on one
    thread: only so does a seed repeat it, see ``repeatable_open3d``)."""
    distance = 1.5 * voxel
    o3d.utility.random.seed(seed)
    with repeatable_open3d():
        result = _open3d_ransac(src, tgt, f_src, f_tgt, mutual_filter, distance)
    return np.array(result.transformation)


def _open3d_ransac(src, tgt, f_src, f_tgt, mutual_filter, distance):
    return reg.registration_ransac_based_on_feature_matching(
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


def fpfh_ransac(source, target, voxel, seed, viewpoints=None):
    src, f_src, tgt, f_tgt = _fpfh_recipe_inputs(source, target, voxel, viewpoints)
    return feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter=True)


def open3d_recipe_descriptor():
    """The descriptor of the Open3D-native recipe: the one-hop object model (24-D), what
    docs/registration.md recommends for Open3D's RANSAC (chosen on training pairs by
    benchmarks/open3d_tutorial.py); Open3D's k-d tree over features searches a few
    dozen dimensions fast (the 1624-D descriptor made its RANSAC 40-230x slower)."""
    return RPointHopTransformer.pretrained("object")


def rpointhop_open3d_ransac(source, target, voxel, seed, model, viewpoints=None):
    """docs/registration.md, "Inside Open3D's own pipeline", step for step."""
    from ..open3d_interop import to_open3d_feature

    views = (None, None) if viewpoints is None else viewpoints
    src = to_point_cloud(source).voxel_down_sample(voxel)
    tgt = to_point_cloud(target).voxel_down_sample(voxel)
    f_src = to_open3d_feature(model.transform(src, viewpoints=views[0]))
    f_tgt = to_open3d_feature(model.transform(tgt, viewpoints=views[1]))
    # mutual_filter=False: RANSAC does the filtering, and Open3D prints no fallback warning.
    return feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter=False)


def fpfh_fgr(source, target, voxel, seed, viewpoints=None):
    src, f_src, tgt, f_tgt = _fpfh_recipe_inputs(source, target, voxel, viewpoints)
    o3d.utility.random.seed(seed)
    option = reg.FastGlobalRegistrationOption(maximum_correspondence_distance=0.5 * voxel)
    with repeatable_open3d():
        result = reg.registration_fgr_based_on_feature_matching(src, tgt, f_src, f_tgt, option)
    return np.array(result.transformation)


def recipe_icp(source, target, voxel, init):
    src, tgt = to_point_cloud(source), to_point_cloud(target)
    tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    result = reg.registration_icp(
        src, tgt, 0.4 * voxel, init, reg.TransformationEstimationPointToPlane()
    )
    return np.array(result.transformation)


def kiss_matcher_available() -> bool:
    """Whether the optional KISS-Matcher wheel is installed and imports."""
    try:
        import kiss_matcher  # noqa: F401
    except ImportError:
        return False
    return True


def kiss_matcher_estimate(source, target, voxel):
    """KISS-Matcher's own pipeline (voxelisation, Faster-PFH, matching, ROBIN pruning,
    GNC-TLS) at the resolution the other methods use; no refinement after it. It takes
    no viewpoints; it claims the result it calls valid."""
    import kiss_matcher

    config = kiss_matcher.KISSMatcherConfig(voxel_size=float(voxel))
    matcher = kiss_matcher.KISSMatcher(config)
    src = np.asarray(to_point_cloud(source).points, dtype=np.float32)
    tgt = np.asarray(to_point_cloud(target).points, dtype=np.float32)
    solution = matcher.estimate(src, tgt)
    out = np.eye(4)
    if solution.valid:
        out[:3, :3] = np.asarray(solution.rotation)
        out[:3, 3] = np.asarray(solution.translation).ravel()
    return out, bool(solution.valid)


def sc2pcr_step(*args, **kwargs):
    """The SC2-PCR peer step (:class:`.sc2pcr.SC2PCRGlobal`), imported when used."""
    from .sc2pcr import SC2PCRGlobal

    return SC2PCRGlobal(*args, **kwargs)
