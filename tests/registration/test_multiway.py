"""Multiway registration: poses of unposed scans through a pose graph."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from helpers import dask_cluster, partial_views
from scipy.spatial.transform import Rotation

from o3d_rpointhop import register_multiway
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration import MultiwayResult
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg


def test_poses_of_a_synthetic_multiscan_object_are_recovered():
    scans, truth = partial_views(4)
    result = register_multiway(scans, random_state=0)
    assert result.unconnected == [] and len(result.poses) == 4
    np.testing.assert_array_equal(result.poses[0], np.eye(4))
    for k in range(1, 4):
        assert rotation_error_deg(result.poses[k], truth[k]) < 2.0
        gap = apply_transform(scans[k], result.poses[k]) - apply_transform(scans[k], truth[k])
        assert np.linalg.norm(gap, axis=1).mean() < 0.02
    assert len(result.pose_graph.nodes) == 4 and len(result.edges) >= 3
    assert set(result.pairs) == {(i, j) for i in range(4) for j in range(i + 1, 4)}


@pytest.mark.slow
def test_a_scan_set_at_survey_coordinates_gives_what_it_gives_at_the_origin():
    """The same scans moved 6000 km from the origin: the same edges, and the same poses
    once moved back, within rounding; its pose graph is in the scans' own coordinates."""
    scans, truth = partial_views(4, seed=5)
    offset = np.array([500_000.0, 6_000_000.0, 120.0])
    near = register_multiway(scans, random_state=0)
    far = register_multiway([s + offset for s in scans], random_state=0)
    assert far.edges == near.edges and far.unconnected == near.unconnected == []
    shift = np.eye(4)
    shift[:3, 3] = offset
    for k, (a, b) in enumerate(zip(near.poses, far.poses, strict=True)):
        back = np.linalg.inv(shift) @ b @ shift
        np.testing.assert_allclose(back[:3, :3], a[:3, :3], atol=1e-7)
        np.testing.assert_allclose(back[:3, 3], a[:3, 3], atol=1e-5)
        assert rotation_error_deg(a, truth[k]) < 2.0
    for node, pose in zip(far.pose_graph.nodes, far.poses, strict=True):
        np.testing.assert_allclose(np.asarray(node.pose), pose, atol=1e-6)


@pytest.mark.slow
def test_scans_in_a_mix_of_frames_give_what_they_give_in_one():
    """One scan at UTM coordinates and the others near the origin (or scan 0 far and
    the rest near): each scan is centred on its own centroid for the whole run, so the
    same edges and, carried back, the same poses and pair transformations (within 1e-6
    of the scans' extent) as when every scan shares a frame."""
    scans, truth = partial_views(4, seed=5)
    extent = np.ptp(np.vstack(scans), axis=0).max()
    utm = np.array([452_310.0, 5_211_870.0, 312.0])
    shared = register_multiway(scans, random_state=0)
    assert shared.unconnected == [] and len(shared.edges) >= 3
    for far in (2, 0):
        offsets = [utm if k == far else np.zeros(3) for k in range(4)]
        mixed = register_multiway(
            [s + o for s, o in zip(scans, offsets, strict=True)], random_state=0
        )
        assert mixed.edges == shared.edges and mixed.unconnected == []

        def back(pose, to, frm, offsets=offsets):  # from the mixed frames to the shared
            into, out = np.eye(4), np.eye(4)
            into[:3, 3], out[:3, 3] = -offsets[to], offsets[frm]
            return into @ pose @ out

        for k in range(4):
            moved = back(mixed.poses[k], 0, k)
            np.testing.assert_allclose(moved[:3, :3], shared.poses[k][:3, :3], atol=1e-6)
            np.testing.assert_allclose(moved[:3, 3], shared.poses[k][:3, 3], atol=1e-6 * extent)
            assert rotation_error_deg(moved, truth[k]) < 2.0
        for (i, j), (t, _) in mixed.pairs.items():
            np.testing.assert_allclose(back(t, i, j), shared.pairs[(i, j)][0], atol=1e-6 * extent)
        for node, pose in zip(mixed.pose_graph.nodes, mixed.poses, strict=True):
            np.testing.assert_allclose(np.asarray(node.pose), pose, atol=1e-6 * extent)


def test_information_matrices_move_with_the_frame():
    """information_about gives what Open3D measures on the uncentred clouds."""
    import open3d as o3d

    from o3d_rpointhop.registration.multiway import information_about

    reg = o3d.pipelines.registration
    centred = np.random.default_rng(0).normal(size=(400, 3))
    origin = np.array([300.0, -200.0, 50.0])

    def measured(points):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        return np.asarray(
            reg.get_information_matrix_from_point_clouds(cloud, cloud, 0.5, np.eye(4))
        )

    expected = measured(centred + origin)
    np.testing.assert_allclose(
        information_about(measured(centred), origin), expected, rtol=1e-12, atol=1e-6
    )


def test_parallel_pairs_give_the_same_poses():
    """Screening and refinement spread over processes: the same bytes as in one."""
    scans, _ = partial_views(3, seed=3)
    one = register_multiway(scans, random_state=0)
    two = register_multiway(scans, random_state=0, n_jobs=2)
    assert one.edges == two.edges
    for a, b in zip(one.poses, two.poses, strict=True):
        np.testing.assert_array_equal(a, b)


def test_n_jobs_one_is_one_core_and_the_same_poses(monkeypatch):
    """``n_jobs=1``: one process on one core (the kernels, Open3D and BLAS), the same
    bytes as every core; the caller's settings are back afterwards."""
    import o3d_rpointhop.registration.multiway as multiway
    from o3d_rpointhop._utils.threads import kernel_threads

    scans, _ = partial_views(3, seed=3)
    every = register_multiway(scans, random_state=0)
    seen = []
    work = multiway._canonical_order  # called once a run, inside its core budget

    def spy(*args):
        seen.append((kernel_threads(None), o3d.utility.get_max_threads()))
        return work(*args)

    monkeypatch.setattr(multiway, "_canonical_order", spy)
    before = o3d.utility.get_max_threads()
    one = register_multiway(scans, random_state=0, n_jobs=1)
    assert seen == [(1, 1)] and o3d.utility.get_max_threads() == before
    assert one.edges == every.edges
    for a, b in zip(one.poses, every.poses, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_pairs_on_a_dask_cluster_give_the_same_poses():
    """Screening and refinement as tasks of a Dask cluster of two worker processes
    (joblib's dask backend): the same edges and the same bytes as one process, and the
    pairs really ran on the workers."""
    scans, _ = partial_views(3, seed=3)
    one = register_multiway(scans, random_state=0)
    with dask_cluster() as client:
        on_cluster = register_multiway(scans, random_state=0, n_jobs=-1)
        ran = client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.task_prefixes))
    assert ran > 0
    assert one.edges == on_cluster.edges
    for a, b in zip(one.poses, on_cluster.poses, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_a_scan_of_something_else_is_reported_unconnected():
    scans, truth = partial_views(3, seed=1)
    stranger = make_object(1700, shape_seed=77) * 0.8 + 0.3  # another object entirely
    result = register_multiway([*scans, stranger], random_state=0)
    assert result.unconnected == [3] and result.poses[3] is None
    assert all((3 not in edge) for edge in result.edges)
    for k in range(1, 3):
        assert rotation_error_deg(result.poses[k], truth[k]) < 2.0


def test_scans_of_different_sizes_and_resolutions():
    scans, truth = partial_views(3, seed=2, n_points=6000)
    scans[1] = scans[1][::3]  # a third of the points: coarser spacing
    scans[2] = np.concatenate([scans[2], scans[2] + 1e-4])  # every point twice
    result = register_multiway(scans, random_state=0)
    assert result.unconnected == []
    for k in (1, 2):
        assert rotation_error_deg(result.poses[k], truth[k]) < 3.0


@pytest.mark.parametrize(
    ("clouds", "message"),
    [
        ([], "at least two clouds"),
        ([make_object(500)], "at least two clouds"),
        (make_object(500), "'clouds' parameter of register_multiway must be"),
        ([make_object(500), np.full((50, 3), np.nan)], r"clouds\[1\]"),
    ],
)
def test_bad_input(clouds, message):
    with pytest.raises(ValueError, match=message):
        register_multiway(clouds)


@pytest.mark.slow
def test_merging_meshing_and_the_summary_are_library_methods():
    from scipy.spatial import cKDTree

    scans, _ = partial_views(3, seed=1)
    result = register_multiway(scans, random_state=0)
    merged = result.merge(scans)
    assert merged.has_colors() and len(merged.points) > 1000
    # The merged cloud is the scans placed in scan 0's frame, downsampled.
    placed = np.concatenate(
        [apply_transform(s, p) for s, p in zip(scans, result.poses, strict=True)]
    )
    assert cKDTree(placed).query(np.asarray(merged.points))[0].max() < result.voxel_size
    coarse = result.merge(scans, voxel_size=2 * result.voxel_size, colour=False)
    assert not coarse.has_colors() and len(coarse.points) < len(merged.points)
    mesh = result.mesh(scans)
    assert len(mesh.triangles) > 100
    vertices = np.asarray(mesh.vertices)
    assert cKDTree(placed).query(vertices)[0].mean() < 0.05  # a surface through the scans
    summary = result.as_dict(["a", "b", "c"])
    assert summary["scans"] == ["a", "b", "c"] and summary["unconnected"] == []
    assert len(summary["poses"]) == 3 and summary["edges"]
    with pytest.raises(ValueError, match="3 scans were registered, got 2"):
        result.merge(scans[:2])


@pytest.mark.slow
def test_scans_are_screened_with_the_global_step_and_size_the_descriptor_states(monkeypatch):
    """A descriptor that states the consensus and a cloud size (as the scene model does)
    has its scan sets screened by the consensus at that size, as register() would."""
    from o3d_rpointhop import FPFHTransformer
    from o3d_rpointhop.registration import multiway
    from o3d_rpointhop.registration.steps import ConsensusGlobal, RANSACGlobal

    ran = []
    for step in (ConsensusGlobal, RANSACGlobal):
        real = step._run
        monkeypatch.setattr(
            step, "_run", lambda self, c, t, real=real: ran.append(type(self)) or real(self, c, t)
        )
    sizes = []
    real_voxel = multiway.common_voxel
    monkeypatch.setattr(
        multiway, "common_voxel", lambda clouds, n: sizes.append(n) or real_voxel(clouds, n)
    )
    scans, truth = partial_views(3, seed=4)
    stated = FPFHTransformer()
    stated.registration_global_method_ = "consensus"
    stated.registration_points_ = 1500
    result = register_multiway(scans, stated, random_state=0)
    # Three pairs, each screened by the consensus (one the other way too, should its
    # first way fall below the edge fitness).
    assert set(ran) == {ConsensusGlobal} and 3 <= len(ran) <= 6 and sizes == [1500]
    for k in (1, 2):
        assert rotation_error_deg(result.poses[k], truth[k]) < 2.0
    ran.clear()
    register_multiway(scans, FPFHTransformer(), random_state=0)
    # Three pairs, one screened the other way too after failing the first.
    assert set(ran) == {RANSACGlobal} and 3 <= len(ran) <= 6


def test_the_global_step_and_resolution_can_be_chosen():
    """A named step, a configured step and a fixed resolution reach every pair: the
    result's resolution is the one given, a step that finds nothing (RANSAC allowed a
    single draw) leaves the scans unconnected, and a name gives what its default step
    gives."""
    from o3d_rpointhop.registration.steps import RANSACGlobal

    scans, truth = partial_views(3, seed=3)
    auto = register_multiway(scans, random_state=0)
    named = register_multiway(scans, random_state=0, global_method="ransac")
    assert named.edges == auto.edges  # the object model states no step: RANSAC
    for a, b in zip(auto.poses, named.poses, strict=True):
        np.testing.assert_array_equal(a, b)
    fixed = register_multiway(scans, random_state=0, voxel_size=0.05)
    assert fixed.voxel_size == 0.05 and auto.voxel_size != 0.05
    for k in range(3):
        assert rotation_error_deg(fixed.poses[k], truth[k]) < 2.0
    starved = register_multiway(
        scans, random_state=0, global_method=RANSACGlobal(max_iteration=1, confidence=0.5)
    )
    assert len(starved.edges) < len(auto.edges)
    with pytest.raises(ValueError, match="global_method"):
        register_multiway(scans, global_method="magic")


def test_many_scans_pair_each_with_its_nearest_by_pooled_descriptor_and_its_neighbours():
    """Above ALL_PAIRS_UP_TO scans the candidates are the scans in the given order's
    neighbours plus each scan's RETRIEVED_NEIGHBOURS nearest by mean descriptor: here
    scans i and i + 7 share their descriptors and nothing else does."""
    from o3d_rpointhop.registration.multiway import ALL_PAIRS_UP_TO, _candidates

    n = 14
    assert n > ALL_PAIRS_UP_TO
    rng = np.random.default_rng(0)
    codes = np.eye(7) * 10.0 + rng.uniform(0.0, 1.0, (7, 7))
    features = [np.tile(codes[k % 7], (50, 1)) for k in range(n)]
    chain = {(k, k + 1) for k in range(n - 1)}
    twins = {(k, k + 7) for k in range(7)}
    assert _candidates(features, 1, list(range(n))) == sorted(chain | twins)
    # Without a sequence, the retrieved pairs alone.
    assert _candidates(features, 1) == sorted(twins)
    # More neighbours retrieved: a superset, still each pair once, smaller index first.
    wider = _candidates(features, 3, list(range(n)))
    assert set(wider) > chain | twins and len(wider) == len(set(wider))
    assert all(i < j for i, j in wider) and len(wider) < n * (n - 1) // 2
    # Up to the threshold, every pair.
    assert _candidates(features[:ALL_PAIRS_UP_TO], 1) == [
        (i, j) for i in range(ALL_PAIRS_UP_TO) for j in range(i + 1, ALL_PAIRS_UP_TO)
    ]


def test_retrieved_pairs_are_the_nearest_and_scale_to_thousands_of_scans():
    """Each scan's k nearest by pooled descriptor, as a dense search finds them, and
    for 3000 scans at most (k + 1) n pairs in memory far below the n^2 a distance
    matrix takes (here 3000^2 x 32 doubles would be 2.3 GB)."""
    import tracemalloc

    from o3d_rpointhop.registration.multiway import _candidates

    rng = np.random.default_rng(1)
    features = [rng.normal(size=(5, 32)) for _ in range(40)]
    pooled = np.stack([f.mean(axis=0) for f in features])
    pooled /= np.linalg.norm(pooled, axis=1, keepdims=True)
    dense = np.linalg.norm(pooled[:, None] - pooled[None], axis=2)
    np.fill_diagonal(dense, np.inf)
    expected = {
        (min(i, j), max(i, j)) for i in range(40) for j in np.argsort(dense[i])[:4].tolist()
    }
    assert set(_candidates(features, 4)) == expected
    many = [rng.normal(size=(5, 32)) for _ in range(3000)]
    tracemalloc.start()
    pairs = _candidates(many, 6, list(range(3000)))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert len(pairs) <= 7 * 3000 and len(set(pairs)) == len(pairs)
    assert peak < 50e6


def test_a_scan_set_registered_from_retrieved_pairs_is_placed(monkeypatch):
    """The retrieval path end to end (its threshold lowered so that five scans take it):
    fewer pairs tried than all of them, the given order's neighbours among them, and
    every pose recovered."""
    from o3d_rpointhop.registration import multiway

    monkeypatch.setattr(multiway, "ALL_PAIRS_UP_TO", 3)
    monkeypatch.setattr(multiway, "RETRIEVED_NEIGHBOURS", 1)
    scans, truth = partial_views(5, seed=2)
    result = register_multiway(scans, random_state=0, sequential=True)
    assert {(k, k + 1) for k in range(4)} <= set(result.pairs)
    assert len(result.pairs) < 10
    assert result.unconnected == []
    for k in range(1, 5):
        assert rotation_error_deg(result.poses[k], truth[k]) < 2.0


@pytest.mark.slow
@pytest.mark.parametrize("retrieved", [False, True])
def test_the_same_scans_in_any_order_give_the_same_room(retrieved, monkeypatch):
    """Shuffled and reversed, the same scans give the same placed set, edges and
    relative poses (each pair is registered in a direction set by the scans' content,
    not by their positions); poses are in the frame of the scan given first. Also when
    the candidate pairs are retrieved (the all-pairs threshold lowered): by default no
    pair comes from the given order."""
    from o3d_rpointhop.registration import multiway

    if retrieved:
        monkeypatch.setattr(multiway, "ALL_PAIRS_UP_TO", 3)
        monkeypatch.setattr(multiway, "RETRIEVED_NEIGHBOURS", 1)
    scans, truth = partial_views(4, seed=5)
    base = register_multiway(scans, random_state=0)
    for order in ([3, 2, 1, 0], [2, 0, 3, 1]):
        other = register_multiway([scans[k] for k in order], random_state=0)
        assert {tuple(sorted((order[i], order[j]))) for i, j in other.pairs} == set(base.pairs)
        assert other.frame == 0 and other.unconnected == []
        back = {(order[i], order[j]) for i, j in other.edges}
        assert {(min(e), max(e)) for e in back} == set(base.edges)
        for a in range(4):
            for b in range(4):
                # scan order[b] relative to scan order[a], in both results
                mine = np.linalg.inv(other.poses[a]) @ other.poses[b]
                theirs = np.linalg.inv(base.poses[order[a]]) @ base.poses[order[b]]
                np.testing.assert_allclose(mine, theirs, atol=1e-9)


@pytest.mark.slow
def test_a_room_is_rooted_in_its_largest_part_not_in_scan_0():
    """Scan 0 overlaps nothing: the other scans are still placed, in the frame of the
    first of them, and the result says which parts the scans fell into (before, every
    scan but scan 0 was left out)."""
    scans, truth = partial_views(4, seed=5)
    stranger = make_object(2000, shape_seed=30, sample_seed=1) + 40.0
    result = register_multiway([stranger, *scans], random_state=0)
    assert result.unconnected == [0] and result.frame == 1
    assert result.parts == [[1, 2, 3, 4], [0]]
    np.testing.assert_array_equal(result.poses[1], np.eye(4))
    for k in range(2, 5):
        assert rotation_error_deg(result.poses[k], truth[k - 1]) < 2.0
    summary = result.as_dict(["s", "a", "b", "c", "d"])
    assert summary["frame"] == "a" and summary["parts"] == [["a", "b", "c", "d"], ["s"]]


@pytest.mark.slow
def test_a_smaller_part_is_returned_as_its_own_reconstruction(tmp_path):
    """Two views of another object, far away, form a part of their own: they are not
    placed in the room, but reconstructed on their own, in the frame of the first of
    them, and saved and read back with the result."""
    scans, truth = partial_views(4, seed=5)
    # Two samples of another object, far away, the second turned by 40 degrees.
    turn = np.eye(4)
    turn[:3, :3] = Rotation.from_euler("z", 40, degrees=True).as_matrix()
    first = make_object(2000, shape_seed=30, sample_seed=1) + 40.0
    second = apply_transform(make_object(2000, shape_seed=30, sample_seed=2) + 40.0, turn)
    result = register_multiway([first, *scans, second], random_state=0)
    assert result.parts == [[1, 2, 3, 4], [0, 5]]
    assert result.unconnected == [0, 5] and result.frame == 1
    np.testing.assert_array_equal(result.part_poses[0][1], result.poses[1])
    assert len(result.part_poses) == 2
    sub = result.part_poses[1]
    assert [k for k, p in enumerate(sub) if p is not None] == [0, 5]
    np.testing.assert_array_equal(sub[0], np.eye(4))
    assert rotation_error_deg(sub[5], np.linalg.inv(turn)) < 2.0
    result.save(tmp_path / "room.json")
    back = MultiwayResult.load(tmp_path / "room.json")
    np.testing.assert_allclose(back.part_poses[1][5], sub[5], atol=1e-12)
    assert back.part_poses[1][1] is None


def test_a_pair_that_fails_one_way_is_screened_the_other_way(monkeypatch):
    """Every pair's first screening is made to fail: each is screened the other way,
    and those poses, inverted, place every scan."""
    from o3d_rpointhop.registration import multiway

    scans, truth = partial_views(3, seed=5)
    real, calls = multiway._screened, []

    def first_way_fails(context, settings, global_method):
        calls.append(context)
        if len(calls) % 2:  # the canonical direction
            return np.eye(4), 0.0
        return real(context, settings, global_method)

    monkeypatch.setattr(multiway, "_screened", first_way_fails)
    result = register_multiway(scans, random_state=0)
    assert len(calls) == 2 * len(result.pairs) == 6
    assert all(fitness > 0.3 for _, fitness in result.pairs.values())
    for k in (1, 2):
        assert rotation_error_deg(result.poses[k], truth[k]) < 2.0


@pytest.mark.slow
def test_scans_handed_to_workers_as_read_only_memory_maps():
    """joblib passes large arrays to its worker processes as read-only memory maps,
    which Open3D refuses to wrap: the pairs still register (the threshold is lowered so
    that these small scans are mapped too)."""
    from joblib import parallel_config

    scans, truth = partial_views(3, seed=5)
    with parallel_config(max_nbytes="1K"):
        result = register_multiway(scans, n_jobs=2, random_state=0)
    for k in (1, 2):
        assert rotation_error_deg(result.poses[k], truth[k]) < 2.0


def test_every_left_out_scan_is_explained(tmp_path):
    """Each way a scan can be left out gets its own reason, with the pair and the
    number behind it, and the reasons survive a save and a load."""
    eye = np.eye(4)
    result = MultiwayResult(
        poses=[eye, eye, eye, None, None, None, None, None, None],
        pose_graph=None,
        pairs={
            (0, 1): (eye, 0.8),
            (1, 2): (eye, 0.7),
            (0, 3): (eye, 0.1),  # 3: nothing fit
            (2, 3): (eye, 0.2),
            (4, 5): (eye, 0.9),  # 4 and 5: a part of their own
            (0, 6): (eye, 0.6),  # 6: fit, but through free space
            (1, 7): (eye, 0.6),  # 7: fit and kept, then dropped by the optimisation
        },
        edges=[(0, 1), (1, 2)],
        unconnected=[3, 4, 5, 6, 7, 8],
        parts=[[0, 1, 2, 7], [4, 5], [3], [6], [8]],
        free_space={(0, 1): 0.0, (1, 2): 0.01, (4, 5): 0.0, (0, 6): 0.4, (1, 7): 0.02},
        min_fitness=0.3,
        max_violation=0.1,
    )
    why = result.left_out()
    assert set(why) == {3, 4, 5, 6, 7, 8}
    assert why[3].startswith("no pair fit: the best, with scan 2, has edge fitness 0.20")
    assert "0.30 needed" in why[3]
    assert why[4].startswith("in a smaller part (2 scans, with scan 5) than the placed one (4")
    assert "with scan 4" in why[5]
    assert "empty space: the least, with scan 0, 40% (at most 10%)" in why[6]
    assert why[7].startswith("its edges were dropped from the pose graph")
    assert why[8] == "paired with no scan"
    named = result.as_dict([f"f{k}.ply" for k in range(9)])["left_out"]
    assert named["f3.ply"].startswith("no pair fit: the best, with f2.ply")
    path = tmp_path / "result.json"
    result.pose_graph = o3d.pipelines.registration.PoseGraph()
    result.save(path)
    loaded = MultiwayResult.load(path)
    assert (loaded.min_fitness, loaded.max_violation) == (0.3, 0.1)
    assert loaded.left_out() == why


def test_the_screening_can_search_from_a_share_of_the_consensus_cap(monkeypatch):
    """By default a screening step is the one given; with ``SCREENING_QUERIES`` the
    consensus searches, each way, from that share of its cap of matches spread over the
    scan, and a step with its own matcher, or RANSAC (whose matcher keeps every match),
    is still screened as given."""
    from o3d_rpointhop import ConsensusGlobal, RANSACGlobal
    from o3d_rpointhop.registration import Matcher, multiway

    plain = ConsensusGlobal()
    assert multiway._screening_step(plain) is plain
    monkeypatch.setattr(multiway, "SCREENING_QUERIES", 0.5)
    step = multiway._screening_step(ConsensusGlobal(n_seeds=100))
    assert (
        step.matcher.get_params()
        == Matcher(both_directions=True, max_matches=4000, max_queries=2000).get_params()
    )
    assert step.n_seeds == 100
    own = ConsensusGlobal(matcher=Matcher(both_directions=True, max_matches=100))
    assert multiway._screening_step(own) is own
    ransac = RANSACGlobal()
    assert multiway._screening_step(ransac) is ransac


def test_the_screening_can_verify_fewer_hypotheses_with_the_sensors_known(monkeypatch):
    """With ``SCREENING_HYPOTHESES`` set and every scan's sensor known, a consensus
    left to choose its hypotheses screens with that many; one told how many, one
    without sensors, and RANSAC are screened as given, and None (the default) leaves
    every step as it is."""
    from o3d_rpointhop import ConsensusGlobal, RANSACGlobal
    from o3d_rpointhop.registration import multiway

    plain = ConsensusGlobal(n_seeds=100)
    assert multiway._screening_step(plain, sensors=True) is plain
    monkeypatch.setattr(multiway, "SCREENING_HYPOTHESES", 12)
    step = multiway._screening_step(plain, sensors=True)
    assert step.n_hypotheses == 12
    assert step.n_seeds == 100 and plain.n_hypotheses == "auto"
    assert multiway._screening_step(plain, sensors=False) is plain
    told = ConsensusGlobal(n_hypotheses=4)
    assert multiway._screening_step(told, sensors=True) is told
    ransac = RANSACGlobal()
    assert multiway._screening_step(ransac, sensors=True) is ransac
    monkeypatch.setattr(multiway, "SCREENING_HYPOTHESES", None)
    assert multiway._screening_step(plain, sensors=True) is plain
