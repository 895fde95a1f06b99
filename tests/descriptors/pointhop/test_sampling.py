"""Sampling for the hops: farthest points, Poisson disks, neighbour search."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import CONTRACT, random_motion, relative_difference
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob, make_object
from o3d_rpointhop.descriptors.pointhop._neighbors import HopSearch, spatial_order
from o3d_rpointhop.descriptors.pointhop._sampling import (
    fps_subsets,
    hop_subsets,
    poisson_disk_subset,
)


@pytest.fixture(scope="module")
def poisson_model(train_clouds):
    return RPointHopTransformer(sampling="poisson", random_state=0).fit(train_clouds)


# ----------------------------------------------------------------------------- sampling
def _reference_fps(points, m, start):
    chosen = [start]
    dist = np.linalg.norm(points - points[start], axis=1)
    for _ in range(m - 1):
        j = int(np.argmax(dist))
        chosen.append(j)
        dist = np.minimum(dist, np.linalg.norm(points - points[j], axis=1))
    return np.sort(chosen)


# ----------------------------------------------------------------------------- sampling
@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.05, 1.0))
def test_poisson_disk_moves_with_the_cloud(seed, share):
    points = make_object(1500, shape_seed=seed % 50, sample_seed=seed)
    m = max(1, int(share * len(points)))
    base = poisson_disk_subset(points, m)
    rot, shift = random_motion(seed, 1000.0)
    perm = np.random.default_rng(seed).permutation(len(points))
    assert len(base) == m and np.all(np.diff(base) > 0)
    np.testing.assert_array_equal(poisson_disk_subset(points @ rot.T + shift, m), base)
    np.testing.assert_array_equal(np.sort(perm[poisson_disk_subset(points[perm], m)]), base)


@pytest.mark.parametrize("kind", ["object", "duplicates", "lattice"])
def test_poisson_disk_on_the_neighbour_lists_draws_what_its_own_search_draws(kind):
    """The first round's competitors taken from the hops' wider lists (in their own
    order) are the same as searched, ties and coincident points included; on any
    number of threads."""
    pts = make_object(3000, shape_seed=4, sample_seed=1)
    if kind == "duplicates":  # coincident points
        pts = np.round(np.concatenate([pts, pts[:400]]), 2)
    elif kind == "lattice":  # twelve neighbours tie at the eighth: the lower rows go first
        pts = np.stack(np.meshgrid(*[np.arange(a, dtype=float) for a in (20, 20, 8)]), -1)
        pts = pts.reshape(-1, 3)
    pts = np.ascontiguousarray(pts[spatial_order(pts)])
    lists = HopSearch(pts).neighbours(None, 40, (32, 20))[0]
    for m in (2000, 900, 100):  # one round, one round at the limit, several rounds
        searched = poisson_disk_subset(pts, m)
        for n_threads in (1, 3):
            np.testing.assert_array_equal(poisson_disk_subset(pts, m, lists, n_threads), searched)
    sizes = [2500, 1500, 600]
    for a, b in zip(
        hop_subsets(pts, sizes, "poisson", (lists, None), 2),
        hop_subsets(pts, sizes, "poisson"),
        strict=True,
    ):
        np.testing.assert_array_equal(a, b)


def test_poisson_disk_spreads_the_sample():
    points = make_blob(4000, shape_seed=2)
    kept = points[poisson_disk_subset(points, 1000)]
    chance = points[np.random.default_rng(0).choice(4000, 1000, replace=False)]

    def closest(sample):
        d = np.linalg.norm(sample[:, None] - sample[None], axis=2)
        np.fill_diagonal(d, np.inf)
        return d.min(axis=1)

    # A hard-core sample: its closest pairs are far apart compared with a random one's.
    assert np.percentile(closest(kept), 1) > 4 * np.percentile(closest(chance), 1)


def test_hop_subsets_are_nested_and_auto_switches_at_the_threshold(monkeypatch):
    points = make_blob(3000, shape_seed=4)
    for method in ("fps", "poisson"):
        big, small = hop_subsets(points, [2000, 900], method)
        assert len(big) == 2000 and len(small) == 900 and np.isin(small, big).all()
    import o3d_rpointhop.descriptors.pointhop._sampling as sampling

    monkeypatch.setattr(sampling, "FPS_MAX_POINTS", 2999)
    np.testing.assert_array_equal(
        hop_subsets(points, [1500], "auto")[0], hop_subsets(points, [1500], "poisson")[0]
    )
    monkeypatch.setattr(sampling, "FPS_MAX_POINTS", 3000)
    np.testing.assert_array_equal(
        hop_subsets(points, [1500], "auto")[0], hop_subsets(points, [1500], "fps")[0]
    )


@pytest.mark.parametrize("seed", [0, 1])
def test_poisson_descriptors_are_rigid_invariant_and_permutation_equivariant(poisson_model, seed):
    cloud = make_blob(700, shape_seed=40 + seed)
    base = poisson_model.transform(cloud)
    rot, shift = random_motion(seed, 100.0)
    assert relative_difference(base, poisson_model.transform(cloud @ rot.T + shift)) < CONTRACT
    perm = np.random.default_rng(seed).permutation(len(cloud))
    assert relative_difference(poisson_model.transform(cloud[perm]), base[perm]) < CONTRACT
    np.testing.assert_array_equal(poisson_model.transform(cloud), base)  # deterministic


def test_fps_matches_reference_and_is_nested():
    pts = make_blob(400, shape_seed=8)
    start = int(np.argmax(np.linalg.norm(pts - pts.mean(0), axis=1)))
    big, small = fps_subsets(pts, [300, 120])
    np.testing.assert_array_equal(big, _reference_fps(pts, 300, start))
    np.testing.assert_array_equal(small, _reference_fps(pts, 120, start))
    assert np.isin(small, big).all()


@pytest.mark.parametrize("n", [500, 3000])
def test_fps_on_the_neighbour_lists_picks_what_the_full_update_picks(n):
    """The same samples, to the bit, whether every pick updates every point or only
    the neighbours it can reach; and the same as Open3D's farthest point sampling."""
    import open3d as o3d

    pts = make_object(n, shape_seed=8, sample_seed=n)
    pts = np.ascontiguousarray(pts[spatial_order(pts)])
    nb, reach, _ = HopSearch(pts).neighbours(None, 40)
    sizes = [int(0.75 * n), int(0.5 * n), int(0.1 * n)]
    full = fps_subsets(pts, sizes)
    for a, b in zip(fps_subsets(pts, sizes, (nb, reach)), full, strict=True):
        np.testing.assert_array_equal(a, b)
    start = int(np.argmax(np.linalg.norm(pts - pts.mean(0), axis=1)))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    picked = np.asarray(cloud.farthest_point_down_sample(sizes[0], start).points)
    np.testing.assert_array_equal(np.sort(cKDTree(pts).query(picked)[1]), full[0])


def test_fps_fills_up_with_duplicates_lowest_rows_first():
    pts = np.repeat(make_blob(20, shape_seed=3), 3, axis=0)  # every point three times
    (sample,) = fps_subsets(pts, [30])
    assert len(np.unique(pts[sample], axis=0)) == 20  # every distinct point first
    assert len(sample) == 30


def test_fps_is_rigid_and_permutation_invariant():
    pts = make_blob(400, shape_seed=9)
    rot, shift = random_motion(1, 50.0)
    perm = np.random.default_rng(2).permutation(400)
    (base,) = fps_subsets(pts, [150])
    (moved,) = fps_subsets(pts @ rot.T + shift, [150])
    (permuted,) = fps_subsets(pts[perm], [150])
    np.testing.assert_array_equal(base, moved)
    np.testing.assert_array_equal(np.sort(perm[permuted]), base)


def test_hop_neighbours_leave_the_query_out_and_serve_every_level():
    pts = make_blob(300, shape_seed=10)
    order = np.argsort(((pts[:, None] - pts[None]) ** 2).sum(-1), axis=1, kind="stable")
    nb, reach, mean_dist = HopSearch(pts).neighbours(None, 12, levels=(5, 11), n_mean=3)
    assert nb.dtype == np.int32 and nb.shape == (300, 12)
    for s in (12, 11, 5, 3):  # the first s are the s nearest other points
        np.testing.assert_array_equal(np.sort(nb[:, :s], axis=1), np.sort(order[:, 1 : s + 1], 1))
    sq = ((pts[nb] - pts[:, None]) ** 2).sum(-1)
    # reach: the farthest neighbour's squared distance less its key's rounding, below
    # which every other point is a neighbour.
    assert np.all(reach <= sq.max(axis=1)) and np.all(reach >= sq.max(axis=1) * (1 - 1e-4))
    everyone = ((pts[:, None] - pts[None]) ** 2).sum(-1)
    outside = np.ones_like(everyone, dtype=bool)
    np.put_along_axis(outside, nb, False, axis=1)
    np.fill_diagonal(outside, False)
    assert np.all(everyone[outside] >= np.broadcast_to(reach[:, None], everyone.shape)[outside])
    np.testing.assert_allclose(mean_dist, np.sqrt(sq[:, :3]).mean(axis=1))
    with pytest.raises(ValueError, match="cannot take 300 neighbours among 300"):
        HopSearch(pts).neighbours(None, 300)


def test_hop_neighbours_do_not_change_with_a_power_of_two_scale_up_to_the_largest():
    """Scaled by 2**495 (squared distances near 1e298, coordinates the input checks
    accept), the ties are rounded as at scale 1, without overflow: the same neighbours
    and samples (overflowing keys were NaN, and the lists came out wrong)."""
    pts = np.round(make_blob(300, shape_seed=10) * 64) / 64  # on a grid: many ties
    pts = np.ascontiguousarray(pts[spatial_order(pts)])
    big = pts * 2.0**495
    for k in (5, 12):
        np.testing.assert_array_equal(
            HopSearch(big).neighbours(None, k)[0], HopSearch(pts).neighbours(None, k)[0]
        )
    np.testing.assert_array_equal(fps_subsets(big, [120])[0], fps_subsets(pts, [120])[0])


def test_hop_neighbours_among_a_sample_by_position():
    """Sources are a sample: neighbours are positions in it; a query in the sample
    leaves itself out, a query outside leaves out one source it coincides with."""
    pts = make_blob(200, shape_seed=11)
    pts[151] = pts[20]  # row 151 (not sampled) duplicates row 20 (sampled)
    sample = np.arange(0, 200, 2)
    queries = np.array([20, 151, 153])
    nb = HopSearch(pts, sample).neighbours(queries, 6)[0]
    src = pts[sample]
    expected = cKDTree(src).query(pts[queries], 7)[1]
    np.testing.assert_array_equal(np.sort(nb[0]), np.sort(expected[0, 1:]))  # itself out
    np.testing.assert_array_equal(np.sort(nb[1]), np.sort(expected[1, 1:]))  # its twin out
    np.testing.assert_array_equal(np.sort(nb[2]), np.sort(expected[2, :6]))  # nothing out
    assert 10 not in nb[0] and 10 not in nb[1]  # position of row 20 in the sample


def test_spatial_order_is_a_permutation_that_keeps_neighbours_together():
    pts = make_blob(3000, shape_seed=13)
    order = spatial_order(pts)
    np.testing.assert_array_equal(np.sort(order), np.arange(3000))
    step = np.linalg.norm(np.diff(pts[order], axis=0), axis=1).mean()
    scattered = np.linalg.norm(np.diff(pts, axis=0), axis=1).mean()
    assert step < scattered / 5  # consecutive points are near each other
    # Points in one Morton cell stay in input order; a cloud without extent is kept.
    np.testing.assert_array_equal(spatial_order(np.zeros((4, 3))), np.arange(4))


def test_sampling_refuses_sizes_it_cannot_draw_and_keeps_small_clouds_whole():
    from o3d_rpointhop.descriptors.pointhop._sampling import _thin

    points = make_blob(50)
    for method in ("fps", "poisson"):
        with pytest.raises(ValueError, match="must not increase|cannot sample 60 of 50"):
            hop_subsets(points, [60], method)
        with pytest.raises(ValueError, match="cannot sample 0 of"):
            hop_subsets(points, [20, 0], method)
    with pytest.raises(ValueError, match="must not increase"):
        fps_subsets(points, [10, 20])
    with pytest.raises(ValueError, match="cannot sample 51 of 50"):
        poisson_disk_subset(points, 51)
    np.testing.assert_array_equal(_thin(points, 50), np.arange(50))  # nothing to thin
    np.testing.assert_array_equal(_thin(points[:1], 1), [0])  # one point, no neighbour
    whole = hop_subsets(points, [50, 20], "poisson")
    np.testing.assert_array_equal(whole[0], np.arange(50))  # the whole cloud, as given
    assert len(whole[1]) == 20 and set(whole[1]) <= set(whole[0])
