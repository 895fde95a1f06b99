"""``RPointHopTransformer.transform_turns``: the descriptors under local frames turned
about their normals, against a numpy reference that pools in the turned frames."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_motion, relative_difference
from scipy.spatial import cKDTree

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob, make_object
from o3d_rpointhop.descriptors.pointhop._octants import bin_index, octant_means
from o3d_rpointhop.descriptors.pointhop._saab import apply_saab


@pytest.fixture(scope="module")
def one_hop() -> RPointHopTransformer:
    """A one-hop model on coordinates alone, unit scale: simple enough to recompute."""
    return RPointHopTransformer(
        n_neighbors=(16,), hop_sizes=(1.0,), lrf_neighbors=16, scale=1.0, random_state=0
    ).fit([make_object(500, shape_seed=s) for s in range(4)])


def _reference(model: RPointHopTransformer, points: np.ndarray, quarters: int) -> np.ndarray:
    """Hop 1 recomputed in numpy: each point's 16 nearest neighbours in its frame turned
    by ``quarters`` (x' = y, y' = -x), octant means, the model's Saab outputs."""
    frames = model.local_frames(points)
    for _ in range(quarters):
        frames = np.stack([frames[:, :, 1], -frames[:, :, 0], frames[:, :, 2]], axis=2)
    _, nearest = cKDTree(points).query(points, 17)
    offsets = points[nearest[:, 1:]] - points[:, None, :]  # (n, 16, 3), the point left out
    local = np.einsum("nkd,nda->ank", offsets, frames)  # (3, n, 16)
    attrs = octant_means(local, bin_index(local, "octants"))
    out = apply_saab(attrs.T[None], model.kernels_[0], model.means_[0])
    return out.reshape(-1, len(points))[model.selected_[0]].T


@pytest.mark.parametrize("n_turns", [2, 4])
def test_each_turn_is_the_descriptor_pooled_in_the_turned_frames(one_hop, n_turns):
    points = make_object(400, shape_seed=9)
    turned = one_hop.transform_turns(points, n_turns)
    assert turned.shape == (n_turns, 400, one_hop.n_features_out_)
    for t in range(n_turns):
        expected = _reference(one_hop, points, 4 * t // n_turns)
        assert relative_difference(turned[t], expected) < 1e-5


def test_turn_zero_is_transform_to_the_byte(one_hop, fitted, cloud):
    points = make_object(400, shape_seed=9)
    for model, x in ((one_hop, points), (fitted, cloud)):
        np.testing.assert_array_equal(model.transform_turns(x, 4)[0], model.transform(x))
        np.testing.assert_array_equal(model.transform_turns(x, 1)[0], model.transform(x))


def test_a_half_turn_is_the_same_whichever_count_asks_for_it(fitted, cloud):
    """The multi-hop path (octants of the last hop relabelled): turn 1 of two is turn 2
    of four, and a turn changes the descriptors."""
    two, four = fitted.transform_turns(cloud, 2), fitted.transform_turns(cloud, 4)
    np.testing.assert_array_equal(two[1], four[2])
    assert relative_difference(four[1], four[0]) > 1e-3


@pytest.mark.parametrize("seed", [0, 1])
def test_turned_descriptors_are_rigid_invariant_and_permutation_equivariant(fitted, seed):
    points = make_blob(300, shape_seed=seed + 5)
    rot, shift = random_motion(seed)
    perm = np.random.default_rng(seed).permutation(len(points))
    base = fitted.transform_turns(points, 4)
    moved = fitted.transform_turns((points @ rot.T + shift)[perm], 4)
    assert relative_difference(moved, base[:, perm]) < 1e-5


def test_several_clouds_answer_in_the_input_form(fitted, cloud):
    out = fitted.transform_turns([cloud, cloud[:250]], 2)
    assert [o.shape for o in out] == [
        (2, 300, fitted.n_features_out_),
        (2, 250, fitted.n_features_out_),
    ]
    batch = fitted.transform_turns(np.stack([cloud, cloud]), 2)
    assert batch.shape == (2, 2, 300, fitted.n_features_out_)


@pytest.mark.parametrize("bad", [3, 0, 8, True, 2.0])
def test_a_turn_count_other_than_1_2_4_is_refused(fitted, cloud, bad):
    with pytest.raises(ValueError, match="n_turns must be one of"):
        fitted.transform_turns(cloud, bad)


def test_azimuth_pooling_has_no_turns_to_give():
    model = RPointHopTransformer(
        n_neighbors=(16,), hop_sizes=(1.0,), lrf_neighbors=16, pooling="azimuth", random_state=0
    ).fit([make_blob(200, shape_seed=s) for s in range(3)])
    with pytest.raises(ValueError, match="azimuth"):
        model.transform_turns(make_blob(200, shape_seed=7), 4)
    assert model.transform_turns(make_blob(200, shape_seed=7), 1).shape[0] == 1
