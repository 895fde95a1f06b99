"""DescriptorUnion: several descriptors side by side, each row at unit length and
weighted, against numpy references; its parameters, turns, resolution and contract."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from helpers import (
    NOT_APPLICABLE,
    SMALL,
    assert_passes_check_estimator,
    consensus_matcher,
    moved_copy,
    random_motion,
    relative_difference,
)
from sklearn.base import clone
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from o3d_rpointhop import (
    ConsensusGlobal,
    DescriptorUnion,
    FPFHTransformer,
    RPointHopTransformer,
    register,
)
from o3d_rpointhop.datasets import make_blob, make_object
from o3d_rpointhop.descriptors import descriptor_identity
from o3d_rpointhop.registration import RegistrationSettings
from o3d_rpointhop.transforms import rotation_error_deg


def _unit(rows: np.ndarray) -> np.ndarray:
    rows = np.asarray(rows, dtype=np.float64)
    norms = np.linalg.norm(rows, axis=-1, keepdims=True)
    return np.divide(rows, norms, out=np.zeros_like(rows), where=norms > 0)


@pytest.fixture
def union(fitted) -> DescriptorUnion:
    return DescriptorUnion(
        [("rph", fitted), ("fpfh", FPFHTransformer())], transformer_weights={"fpfh": 0.5}
    )


def test_rows_are_each_part_at_unit_length_weighted_side_by_side(union, fitted, cloud):
    out = union.transform(cloud)
    fpfh = FPFHTransformer().transform(cloud)
    expected = np.hstack([_unit(fitted.transform(cloud)), 0.5 * _unit(fpfh)])
    assert out.dtype == np.float32 and out.shape == (300, fitted.n_features_out_ + 33)
    np.testing.assert_allclose(out, expected, rtol=1e-5, atol=1e-6)
    # every row: the parts' lengths are their weights
    np.testing.assert_allclose(np.linalg.norm(out[:, : fitted.n_features_out_], axis=1), 1, 1e-5)
    np.testing.assert_allclose(np.linalg.norm(out[:, fitted.n_features_out_ :], axis=1), 0.5, 1e-5)


def test_a_weight_scales_its_part_alone(fitted, cloud):
    one = DescriptorUnion([("a", fitted), ("b", FPFHTransformer())]).transform(cloud)
    two = DescriptorUnion(
        [("a", fitted), ("b", FPFHTransformer())], transformer_weights={"b": 2.0}
    ).transform(cloud)
    width = fitted.n_features_out_
    np.testing.assert_array_equal(two[:, :width], one[:, :width])
    np.testing.assert_allclose(two[:, width:], 2 * one[:, width:], rtol=1e-6)


def test_a_zero_row_stays_zero():
    class Zeros:
        def transform(self, X):
            return np.zeros((len(X), 4))

    out = DescriptorUnion([("z", Zeros()), ("f", FPFHTransformer())]).transform(make_blob(100))
    assert np.isfinite(out).all() and not out[:, :4].any()


def test_viewpoints_reach_every_part(union, fitted, cloud):
    out = union.transform(cloud, viewpoints=[0.0, 0.0, 5.0])
    fpfh = FPFHTransformer().transform(cloud, viewpoints=[0.0, 0.0, 5.0])
    np.testing.assert_allclose(
        out,
        np.hstack([_unit(fitted.transform(cloud, viewpoints=[0, 0, 5])), 0.5 * _unit(fpfh)]),
        rtol=1e-5,
        atol=1e-6,
    )
    assert relative_difference(out, union.transform(cloud)) > 1e-3  # the sensor mattered


def test_viewpoints_to_a_part_that_takes_none_are_refused(cloud):
    class Plain:
        def transform(self, X):
            return np.ones((len(X), 2))

    union = DescriptorUnion([("plain", Plain())])
    assert union.transform(cloud).shape == (300, 2)
    with pytest.raises(TypeError, match="Plain.transform takes none"):
        union.transform(cloud, viewpoints="origin")


def test_input_forms_answer_as_the_parts_do(union, cloud):
    single = union.transform(cloud)
    listed = union.transform([cloud, cloud[:250]])
    assert [a.shape for a in listed] == [single.shape, (250, single.shape[1])]
    np.testing.assert_array_equal(listed[0], single)
    batch = union.transform(np.stack([cloud, cloud]))
    assert batch.shape == (2, *single.shape)
    np.testing.assert_array_equal(batch[1], single)


@pytest.mark.parametrize("seed", [0, 1])
def test_rigid_invariant_and_permutation_equivariant(fitted, object_model, seed):
    """Parts that are invariant make an invariant union (FPFH's Open3D normals are not
    exactly invariant, so two R-PointHop models stand in); permuted points permute the
    rows whatever the parts."""
    points = make_blob(300, shape_seed=seed + 5)
    rot, shift = random_motion(seed)
    perm = np.random.default_rng(seed).permutation(len(points))
    union = DescriptorUnion([("a", fitted), ("b", object_model)], transformer_weights={"b": 0.7})
    base = union.transform(points)
    moved = union.transform((points @ rot.T + shift)[perm])
    assert relative_difference(moved, base[perm]) < 1e-5
    with_fpfh = DescriptorUnion([("a", fitted), ("fpfh", FPFHTransformer())])
    np.testing.assert_allclose(
        with_fpfh.transform(points[perm]), with_fpfh.transform(points)[perm], rtol=1e-5, atol=1e-6
    )


def test_turns_turn_the_framed_parts_and_repeat_the_others(union, fitted, cloud):
    turned = union.transform_turns(cloud, 4)
    own = fitted.transform_turns(cloud, 4)
    fpfh = 0.5 * _unit(FPFHTransformer().transform(cloud))
    width = fitted.n_features_out_
    assert turned.shape == (4, 300, width + 33)
    np.testing.assert_array_equal(turned[0], union.transform(cloud))
    for t in range(4):
        np.testing.assert_allclose(turned[t, :, :width], _unit(own[t]), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(turned[t, :, width:], fpfh, rtol=1e-5, atol=1e-6)
    assert relative_difference(turned[1], turned[0]) > 1e-3
    batch = union.transform_turns(np.stack([cloud, cloud]), 2)
    assert batch.shape == (2, 2, 300, width + 33)
    np.testing.assert_array_equal(batch[1], turned[[0, 2]])
    listed = union.transform_turns([cloud, cloud[:200]], 2)
    assert [a.shape for a in listed] == [(2, 300, width + 33), (2, 200, width + 33)]


def test_turns_need_a_part_with_frames(cloud):
    union = DescriptorUnion([("fpfh", FPFHTransformer())])
    with pytest.raises(TypeError, match="no part of the union has local frames"):
        union.transform_turns(cloud, 4)


def test_at_resolution_binds_each_part_and_keeps_the_rest(union, fitted):
    settings = RegistrationSettings().at(0.05)
    bound = union.at_resolution(0.05, settings)
    (_, model), (_, fpfh) = bound.transformer_list
    assert model is fitted and fpfh.radius == pytest.approx(settings.feature_radius)
    assert fpfh.normal_radius == pytest.approx(settings.normal_radius)
    assert bound.transformer_weights == {"fpfh": 0.5}
    assert union.transformer_list[1][1].radius == "auto"  # the union itself unchanged
    fixed = DescriptorUnion(
        [("rph", fitted), ("fpfh", FPFHTransformer(radius=0.2, normal_radius=0.1))]
    )
    assert fixed.at_resolution(0.05) is fixed


def test_what_a_part_states_for_register_is_the_unions(fitted):
    scene = RPointHopTransformer.pretrained("scene")
    union = DescriptorUnion([("fpfh", FPFHTransformer()), ("scene", scene)])
    assert union.registration_points_ == scene.registration_points_ == 4096
    assert union.registration_global_method_ == "consensus"
    plain = DescriptorUnion([("rph", fitted), ("fpfh", FPFHTransformer())])
    assert not hasattr(plain, "registration_points_")
    assert not hasattr(plain, "registration_global_method_")


@pytest.mark.parametrize(
    ("parts", "weights", "error", "message"),
    [
        ([], None, ValueError, "non-empty list"),
        ("fpfh", None, ValueError, "non-empty list"),
        ([FPFHTransformer()], None, ValueError, r"\(name, transformer\) pair"),
        ([("a", FPFHTransformer()), ("a", FPFHTransformer())], None, ValueError, "unique"),
        ([("a__b", FPFHTransformer())], None, ValueError, "without '__'"),
        ([("a", object())], None, TypeError, "has no transform"),
        ([("a", FPFHTransformer())], {"b": 1.0}, ValueError, r"names no part: \['b'\]"),
        ([("a", FPFHTransformer())], {"a": 0.0}, ValueError, "positive and finite"),
        ([("a", FPFHTransformer())], {"a": np.inf}, ValueError, "positive and finite"),
        ([("a", FPFHTransformer())], {"a": True}, ValueError, "positive and finite"),
        ([("a", FPFHTransformer())], {"a": "1"}, ValueError, "positive and finite"),
    ],
)
def test_bad_parameters_are_refused_when_used(parts, weights, error, message, cloud):
    union = DescriptorUnion(parts, transformer_weights=weights)  # __init__ only stores
    with pytest.raises(error, match=message):
        union.transform(cloud)


def test_bad_input_is_refused_by_the_parts(union):
    with pytest.raises(ValueError, match="NaN or infinite"):
        union.transform(np.full((100, 3), np.nan))


def test_an_unfitted_part_refuses_to_transform(cloud):
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        DescriptorUnion([("rph", RPointHopTransformer())]).transform(cloud)


def test_fit_fits_every_part_and_names_the_outputs(train_clouds, cloud):
    union = DescriptorUnion(
        [("rph", RPointHopTransformer(random_state=0, **SMALL)), ("fpfh", FPFHTransformer())]
    )
    assert union.fit(train_clouds) is union
    (_, model), _ = union.transformer_list
    assert hasattr(model, "kernels_")
    assert union.n_features_in_ == 3
    assert union.n_features_out_ == model.n_features_out_ + 33
    names = union.get_feature_names_out()
    assert len(names) == union.n_features_out_
    assert names[0].startswith("rph__") and names[-1] == "fpfh__fpfhtransformer32"
    np.testing.assert_array_equal(
        union.fit_transform(train_clouds[:2])[1], union.transform(train_clouds[1])
    )


class _Recorder:
    """A part that records what ``fit`` was given and answers ``rows`` rows per cloud."""

    def __init__(self, width=2, rows=None):
        self.width, self.rows = width, rows

    def fit(self, X, y=None, viewpoints=None):
        self.seen_ = (len(X), y, viewpoints)
        self.n_features_out_ = self.width
        return self

    def transform(self, X):
        return np.ones((len(X) if self.rows is None else self.rows, self.width))


def test_fit_passes_viewpoints_and_y_to_every_part(train_clouds):
    a, b = _Recorder(), _Recorder(3)
    union = DescriptorUnion([("a", a), ("b", b)]).fit(train_clouds, "y", viewpoints="origin")
    assert a.seen_ == b.seen_ == (len(train_clouds), "y", "origin")
    assert union.n_features_out_ == 5
    union.fit(train_clouds)
    assert a.seen_[2] is None  # no viewpoints: none passed on


def test_parts_that_disagree_or_do_not_say_their_width_are_named(cloud, train_clouds):
    union = DescriptorUnion([("a", _Recorder()), ("b", _Recorder(rows=7))])
    with pytest.raises(ValueError, match="different numbers of rows"):
        union.transform(cloud)
    with pytest.raises(ValueError, match="different numbers of rows"):
        union.transform([cloud, cloud])

    class Silent:
        def fit(self, X, y=None):
            return self

        def transform(self, X):
            return np.ones((len(X), 2))

    with pytest.raises(AttributeError, match="part 'quiet' does not say its width"):
        DescriptorUnion([("a", _Recorder()), ("quiet", Silent())]).fit(train_clouds)


def test_clone_pickle_and_pipeline(union, cloud):
    copy = clone(union)
    assert copy.get_params(deep=False).keys() == union.get_params(deep=False).keys()
    assert not hasattr(copy.transformer_list[0][1], "kernels_")  # parts cloned unfitted
    again = pickle.loads(pickle.dumps(union))
    np.testing.assert_array_equal(again.transform(cloud), union.transform(cloud))
    scaled = make_pipeline(union, StandardScaler()).fit_transform(cloud)
    np.testing.assert_allclose(scaled.mean(axis=0), 0, atol=1e-5)


def test_a_frozen_part_survives_clone_and_fit(fitted, cloud, train_clouds):
    """Where something else clones and fits (a RegistrationPipeline, GridSearchCV), a
    pretrained part wrapped in FrozenEstimator stays as it is."""
    from sklearn.frozen import FrozenEstimator

    union = DescriptorUnion([("rph", FrozenEstimator(fitted)), ("fpfh", FPFHTransformer())])
    expected = union.transform(cloud)
    refitted = clone(union).fit(train_clouds)
    np.testing.assert_array_equal(refitted.transform(cloud), expected)
    assert refitted.n_features_out_ == fitted.n_features_out_ + 33
    np.testing.assert_array_equal(refitted.transform_turns(cloud, 2)[0], expected)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.SkipTestWarning")
def test_sklearn_check_estimator():
    estimator = DescriptorUnion(
        [("rph", RPointHopTransformer(**{**SMALL, "n_neighbors": (4, 3), "lrf_neighbors": 5}))]
    )
    assert_passes_check_estimator(estimator, NOT_APPLICABLE)


def test_identity_names_every_part_and_the_weights(union):
    identity = descriptor_identity(union)
    assert identity["class"] == "o3d_rpointhop.DescriptorUnion"
    assert identity["parts"]["rph"]["class"] == "o3d_rpointhop.RPointHopTransformer"
    assert identity["parts"]["fpfh"]["class"] == "o3d_rpointhop.FPFHTransformer"
    assert identity["transformer_weights"] == {"fpfh": 0.5}


@pytest.mark.parametrize("turns", [1, 4])
def test_register_and_the_consensus_take_a_union(object_model, turns):
    target = make_object(1200, shape_seed=5)
    source, truth = moved_copy(target, seed=3)
    union = DescriptorUnion(
        [("rph", object_model), ("fpfh", FPFHTransformer())], transformer_weights={"fpfh": 0.7}
    )
    result = register(
        source,
        target,
        union,
        random_state=0,
        global_method=ConsensusGlobal(matcher=consensus_matcher(frame_turns=turns)),
    )
    assert rotation_error_deg(result.transformation[:3, :3], truth[:3, :3]) < 2.0
    assert np.linalg.norm(result.transformation[:3, 3] - truth[:3, 3]) < 0.02
