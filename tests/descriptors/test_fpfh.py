"""FPFHTransformer: Open3D's FPFH behind the descriptor interface."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from helpers import NOT_APPLICABLE, assert_passes_check_estimator
from scipy.spatial import cKDTree
from sklearn.base import clone

from o3d_rpointhop import FPFHTransformer
from o3d_rpointhop.datasets import make_object


def _reference(points, radius=0.25, normal_radius=0.1):
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=normal_radius, max_nn=30))
    feature = o3d.pipelines.registration.compute_fpfh_feature(
        pcd, o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=100)
    )
    return np.asarray(feature.data).T


# FPFH learns nothing and transforms without fit, so sklearn also runs its stateless
# check, which feeds 5 columns like the others listed.
FPFH_NOT_APPLICABLE = {
    **NOT_APPLICABLE,
    "check_transformers_unfitted_stateless": NOT_APPLICABLE["check_n_features_in"],
}


def test_matches_open3d_and_needs_no_fit():
    pts = make_object(500, shape_seed=1)
    fpfh = FPFHTransformer(radius=0.25, normal_radius=0.1)
    out = fpfh.transform(pts)  # no fit needed
    assert out.shape == (500, 33)
    np.testing.assert_allclose(out, _reference(pts))
    # "auto" alone: 5 and 2 median spacings
    spacing = np.median(cKDTree(pts).query(pts, k=2)[0][:, 1])
    np.testing.assert_allclose(
        FPFHTransformer().transform(pts), _reference(pts, 5 * spacing, 2 * spacing)
    )
    fitted = clone(fpfh).fit(pts)
    assert fitted.n_features_in_ == 3 and fitted.n_features_out_ == 33
    assert list(fitted.get_feature_names_out()[:2]) == ["fpfhtransformer0", "fpfhtransformer1"]


def test_input_forms_and_existing_normals():
    pts = make_object(400, shape_seed=2)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.normals = o3d.utility.Vector3dVector(np.tile([0.0, 0.0, 1.0], (400, 1)))
    fpfh = FPFHTransformer()
    with_own = fpfh.transform(pcd)
    estimated = fpfh.set_params(use_existing_normals=False).transform(pcd)
    assert not np.allclose(with_own, estimated)  # the given normals were used
    outs = FPFHTransformer().transform([pts, pts[:300]])
    assert [o.shape for o in outs] == [(400, 33), (300, 33)]
    batch = FPFHTransformer().transform(np.stack([pts, pts]))
    assert batch.shape == (2, 400, 33)


def test_auto_radii_follow_a_registrations_resolution():
    """In a registration, "auto" radii are multiples of its resolution (the settings'
    5 and 2): register() describes its global clouds exactly as FPFH with those radii."""
    from o3d_rpointhop.registration import RegistrationSettings
    from o3d_rpointhop.registration.context import RegistrationContext

    auto = FPFHTransformer()
    bound = auto.at_resolution(0.04, RegistrationSettings().at(0.04))
    assert (bound.radius, bound.normal_radius) == pytest.approx((0.2, 0.08))
    assert auto.radius == "auto"  # a copy: the caller's object is unchanged
    assert auto.at_resolution(0.04).radius == pytest.approx(0.2)
    fixed = FPFHTransformer(radius=0.3, normal_radius="auto").at_resolution(0.04)
    assert (fixed.radius, fixed.normal_radius) == pytest.approx((0.3, 0.08))
    mine = FPFHTransformer(radius=0.3, normal_radius=0.1)
    assert mine.at_resolution(0.04) is mine
    settings = RegistrationSettings(feature_radius_factor=4.0)
    context = RegistrationContext(
        make_object(3000, shape_seed=4), make_object(3000, shape_seed=5), settings=settings
    )
    cloud = np.asarray(context.global_cloud("source").points)
    voxel = context.voxel_size
    np.testing.assert_allclose(
        context.features(auto, "source"),
        FPFHTransformer(radius=4 * voxel, normal_radius=2 * voxel).transform(cloud),
    )


def test_auto_radii_follow_the_units():
    pts = make_object(600, shape_seed=3)
    auto = FPFHTransformer(radius="auto", normal_radius="auto")
    big, small = auto.transform(pts * 1000.0), auto.transform(pts)
    # the same neighbourhoods at both scales; a few angles fall into the next histogram
    # bin after rounding, so the histograms agree closely rather than exactly
    assert np.abs(big - small).mean() < 0.02 * np.abs(small).mean()
    fixed = FPFHTransformer(radius=0.25, normal_radius=0.1)
    assert np.abs(fixed.transform(pts * 1000.0) - small).mean() > 0.2 * np.abs(small).mean()


@pytest.mark.parametrize(
    "params, message",
    [
        (dict(radius=0), "radius"),
        (dict(normal_radius="big"), "normal_radius"),
        (dict(max_nn=0), "max_nn"),
        (dict(normal_max_nn=2.5), "normal_max_nn"),
    ],
)
def test_bad_parameters(params, message):
    with pytest.raises(ValueError, match=message):
        FPFHTransformer(**params).transform(make_object(100))


def test_bad_input():
    with pytest.raises(ValueError, match="NaN"):
        FPFHTransformer().transform(np.full((50, 3), np.nan))
    with pytest.raises(ValueError, match="no spatial extent"):
        FPFHTransformer(radius="auto").transform(np.zeros((50, 3)))


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.SkipTestWarning")
def test_sklearn_check_estimator():
    estimator = FPFHTransformer(radius=0.5, normal_radius=0.5, max_nn=10, normal_max_nn=10)
    assert_passes_check_estimator(estimator, FPFH_NOT_APPLICABLE)


def test_parameters_are_validated_declaratively():
    cloud = make_object(300)
    for bad, name in [
        (dict(radius=-1.0), "radius"),
        (dict(radius="big"), "radius"),
        (dict(max_nn=0), "max_nn"),
        (dict(normal_radius=float("inf")), "normal_radius"),
        (dict(use_existing_normals="yes"), "use_existing_normals"),
    ]:
        with pytest.raises(ValueError, match=name):
            FPFHTransformer(**bad).transform(cloud)


def test_normalize_gives_unit_histograms_and_keeps_empty_ones_zero():
    pts = make_object(500, shape_seed=6)
    plain = FPFHTransformer(radius=0.25, normal_radius=0.1).transform(pts)
    unit = FPFHTransformer(radius=0.25, normal_radius=0.1, normalize=True).transform(pts)
    lengths = np.linalg.norm(plain, axis=1)
    np.testing.assert_allclose(unit[lengths > 0], plain[lengths > 0] / lengths[lengths > 0, None])
    lonely = np.vstack([pts, [[50.0, 50.0, 50.0]]])  # no neighbour within the radius
    last = FPFHTransformer(radius=0.25, normal_radius=0.1, normalize=True).transform(lonely)[-1]
    assert np.isfinite(last).all() and not last.any()
