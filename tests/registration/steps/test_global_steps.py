"""Global steps: the paper's SVD, RANSAC, FGR and the tuple test, Open3D's own recipes, and
the up-axis prior."""

from __future__ import annotations

import warnings

import numpy as np
import open3d as o3d
import pytest
from helpers import REPO, assert_close_pose, moved_copy

from o3d_rpointhop import (
    Matcher,
    RegistrationWarning,
    find_correspondences,
    register,
    to_open3d_feature,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.context import RegistrationContext
from o3d_rpointhop.registration.steps.fgr import tuple_test
from o3d_rpointhop.transforms import rotation_error_deg


def test_open3d_feature_interop(object_model, object_target):
    feature = to_open3d_feature(object_model.transform(object_target))
    assert isinstance(feature, o3d.pipelines.registration.Feature)
    assert feature.data.shape == (object_model.n_features_out_, len(object_target))
    corr = find_correspondences(feature, feature)  # Features are accepted directly
    # every point finds a descriptor identical to its own (itself, or a point so close
    # that it pools the same neighbours in the same octants)
    np.testing.assert_array_equal(corr.distances, 0.0)
    with pytest.raises(ValueError, match="2-D"):
        to_open3d_feature(np.zeros(5))


# ----------------------------------------------------------------------------- global steps
def test_svd_is_exact_on_a_moved_copy(object_model, object_target):
    """The paper's protocol: same points, moved: the one-shot SVD is exact."""
    source, truth = moved_copy(object_target, 1)
    result = register(source, object_target, object_model, global_method="svd", refine=None)
    np.testing.assert_allclose(result.transformation, truth, atol=1e-8)
    assert result.steps[0].info["matches_used"] == round(0.125 * len(object_target))


@pytest.mark.parametrize("seed", [2, 3])
def test_ransac_recovers_any_rotation_exactly(object_model, object_target, seed):
    source, truth = moved_copy(object_target, seed, translation_scale=5.0)
    result = register(source, object_target, object_model, refine=None, random_state=seed)
    np.testing.assert_allclose(result.transformation, truth, atol=1e-8)
    assert result.fitness == pytest.approx(1.0)


def test_ransac_through_open3d_feature_matching_agrees(object_model, object_target):
    """The descriptors drop into Open3D's own RANSAC pipeline."""
    reg = o3d.pipelines.registration
    source, truth = moved_copy(object_target, 4)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(object_target))
    o3d.utility.random.seed(0)
    result = reg.registration_ransac_based_on_feature_matching(
        src,
        tgt,
        to_open3d_feature(object_model.transform(source)),
        to_open3d_feature(object_model.transform(object_target)),
        True,
        0.05,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    assert_close_pose(np.asarray(result.transformation), truth, 1e-4, 1e-6)


def test_fgr_recovers_a_moved_copy(object_model, object_target):
    source, truth = moved_copy(object_target, 5)
    result = register(source, object_target, object_model, global_method="fgr", refine=None)
    assert_close_pose(result.transformation, truth, 1.0, 0.01)
    assert result.steps[0].info["after_tuple_test"] <= result.steps[0].info["candidate_matches"]


def test_tuple_test_drops_inconsistent_matches():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(60, 3))
    pairs = np.c_[np.arange(60), np.arange(60)]
    pairs[:20, 1] = rng.permutation(20) + 40  # 20 wrong matches (to scrambled points)
    kept = tuple_test(pts, pts, pairs, seed=0)
    good = kept[:, 0] == kept[:, 1]
    # every right match survives; a wrong one survives only if a random triple happens
    # to be length-consistent, which is rarer: FGR's test thins outliers, it is no oracle
    assert good.sum() == 40 and (~good).sum() <= 12


def test_documented_open3d_recipes_run_silently_and_register(capfd):
    """The two code blocks of docs/registration.md's Open3D section, as written."""
    import re

    doc = (REPO / "docs" / "registration.md").read_text()
    section = doc[doc.index("## Inside Open3D's own pipeline") : doc.index("## Command line")]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert len(blocks) == 2
    scope: dict = {}
    capfd.readouterr()
    exec(compile(blocks[0], "registration.md", "exec"), scope)
    first = np.asarray(scope["result"].transformation)
    printed = capfd.readouterr().out
    exec(compile(blocks[1], "registration.md", "exec"), scope)
    second = np.asarray(scope["result"].transformation)
    out, err = capfd.readouterr()
    assert "WARNING" not in printed + out + err and err == ""
    truth = np.eye(4)
    truth[:3, :3] = np.diag([1.0, -1.0, -1.0])
    truth[:3, 3] = [-0.3, 0.3, 0.3]
    # The first recipe ends with ICP; the second is a global estimate on 0.05-voxel
    # clouds (Open3D's RANSAC runs on several threads, so it varies from run to run).
    assert rotation_error_deg(first, truth) < 2.0
    assert np.linalg.norm(first[:3, 3] - truth[:3, 3]) < 0.02
    assert rotation_error_deg(second, truth) < 20.0
    assert np.linalg.norm(second[:3, 3] - truth[:3, 3]) < 0.15


@pytest.mark.parametrize("ransac_n, edge_length", [(3, 0.9), (4, 0.7), (3, 0.0)])
def test_compiled_draw_check_keeps_exactly_what_the_numpy_check_keeps(ransac_n, edge_length):
    """The RANSAC samples kept by the compiled check (distinct matches, Open3D's
    edge-length checker) are the ones a numpy check with lengths rounded as
    ``sqrt((x^2 + y^2) + z^2)`` keeps (numpy 2's ``linalg.norm`` order), near-ties
    included: one differently rounded length would change the seeded result."""
    from scipy.spatial.transform import Rotation

    from o3d_rpointhop.registration.steps._edges import consistent_edges

    rng = np.random.default_rng(ransac_n)
    source = rng.normal(size=(300, 3)) * [1.0, 5.0, 0.01]
    target = source @ Rotation.random(random_state=3).as_matrix().T
    target[::3] += rng.normal(scale=0.3, size=(100, 3))  # a third of the matches wrong
    if edge_length:
        # A third scaled by exactly the checker's ratio: their edges sit on its boundary,
        # where the last bit of a length decides.
        target[1::3] = source[1::3] / edge_length
    samples = rng.integers(0, 300, size=(200_000, ransac_n))
    kept = consistent_edges(samples, source, target, edge_length)

    expected = (np.diff(np.sort(samples, axis=1), axis=1) != 0).all(axis=1)
    src, tgt = source[samples], target[samples]

    def length(d, order=(0, 1, 2)):
        sq = d * d
        return np.sqrt((sq[:, order[0]] + sq[:, order[1]]) + sq[:, order[2]])

    other = expected.copy()
    if edge_length:
        for a, b in zip(*np.triu_indices(ransac_n, 1), strict=True):
            ls, lt = length(src[:, a] - src[:, b]), length(tgt[:, a] - tgt[:, b])
            expected &= (ls > edge_length * lt) & (lt > edge_length * ls)
            ls, lt = (
                length(src[:, a] - src[:, b], (1, 2, 0)),
                length(tgt[:, a] - tgt[:, b], (1, 2, 0)),
            )
            other &= (ls > edge_length * lt) & (lt > edge_length * ls)
        assert (other != expected).any()  # the boundary cases see the rounding
    assert 0 < expected.sum() < len(samples)
    np.testing.assert_array_equal(kept, expected)


def test_compiled_moved_clouds_round_in_their_stated_order():
    """RANSAC's verification moves the source cloud by 64 hypotheses in a kernel that
    sums each coordinate ``(r0 x + r2 z) + r1 y`` (the order numpy 2's einsum takes,
    so registrations did not move when it replaced the einsum); the order matters
    (the left-to-right sum differs in about 30 % of the coordinates here)."""
    from scipy.spatial.transform import Rotation

    from o3d_rpointhop.registration.steps._ransac import _moved_clouds

    rng = np.random.default_rng(5)
    rot = Rotation.random(64, random_state=2).as_matrix()
    shift = rng.normal(scale=0.01, size=(64, 3))
    points = rng.normal(size=(3000, 3)) * [0.05, 2.0, 1e-3] + [10.0, -3.0, 0.5]
    term = [rot[:, None, :, j] * points[None, :, None, j] for j in range(3)]
    stated = ((term[0] + term[2]) + term[1]) + shift[:, None, :]
    np.testing.assert_array_equal(_moved_clouds(rot, shift, points), stated)
    in_order = ((term[0] + term[1]) + term[2]) + shift[:, None, :]
    assert (in_order != stated).mean() > 0.05


@pytest.mark.parametrize("method", ["ransac", "consensus"])
def test_an_up_prior_rejects_hypotheses_that_turn_the_source_upside_down(object_model, method):
    """The source is the target turned upside down (half a turn about x): found without
    a prior; with up = z for both clouds that answer is refused and whatever wins keeps
    z up."""
    target = make_object(1500, shape_seed=9, sample_seed=1)
    flip = np.diag([1.0, -1.0, -1.0])
    source = make_object(1500, shape_seed=9, sample_seed=2) @ flip.T
    free = register(source, target, object_model, global_method=method, refine=None)
    undo = np.eye(4)
    undo[:3, :3] = flip.T
    assert rotation_error_deg(free.transformation, undo) < 5.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RegistrationWarning)
        kept = register(
            source, target, object_model, global_method=method, refine=None, up=[0, 0, 1.0]
        )
    assert kept.transformation[2, 2] > 0.0  # z stays up
    context = RegistrationContext(source, target, up=([0, 0, 1.0], [0, 0, 2.0]))
    assert context.upright(np.stack([np.eye(3), flip])).tolist() == [True, False]
    with pytest.raises(ValueError, match="up must be a non-zero vector"):
        RegistrationContext(source, target, up=[0.0, 0.0, 0.0])


def test_filters_that_leave_fewer_than_three_matches_are_a_clear_error():
    from o3d_rpointhop import RANSACGlobal, RegistrationPipeline

    rng = np.random.default_rng(0)
    target = make_object(200, shape_seed=1, sample_seed=0)
    source = target[:199] + rng.normal(0, 1e-3, (199, 3))

    class Noise:  # unrelated random descriptors (seeded by the cloud's size)
        def transform(self, X):
            n = len(np.asarray(X.points if hasattr(X, "points") else X))
            return np.random.default_rng(n).normal(size=(n, 4))

    pipe = RegistrationPipeline(
        [("global", RANSACGlobal(matcher=Matcher(max_ratio=1e-6)))], descriptor=Noise()
    )
    with pytest.raises(ValueError, match=r"RANSACGlobal: only 0 correspondences survived"):
        pipe.register(source, target)
